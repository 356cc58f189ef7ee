#!/usr/bin/env python3
"""The Python half of ``scripts/gpu-check.sh``: compare the two reports into a JSON verdict, time the CRPF step on
an arch, and gather the steps' records into ``gpu-check.json``.

    python scripts/gpu_check_compare.py compare A B --rtol 1e-6 --json compare.json
    python scripts/gpu_check_compare.py crpf-step --arch cuda --json crpf-cuda.json
    python scripts/gpu_check_compare.py method-c --arch cuda --json method-c-cuda.json
    python scripts/gpu_check_compare.py summary --out DIR --work WORK --arch cuda --size quick --rtol 1e-6

``compare`` runs ``scripts/compare_reports.py`` on the two folders and writes its lines with a verdict: ``agree``
(exit 0), ``differ`` (exit 1) or ``error`` (exit 2: a folder without a ``summary.json``, say).  ``summary`` needs
the standard library only, so that the JSON is written even where the project does not import.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: One line of compare_reports.py per table or figure: ``  table ID: identical (max relative difference 0...)``.
ITEM = re.compile(r"^\s+(table|figure) (\S+): (identical|agrees|DIFFERS|missing)[^(]*(?:\(max relative difference "
                  r"([^,)]+))?")


def compare(first: Path, second: Path, rtol: float) -> dict:
    """The verdict of ``compare_reports.py first second --rtol rtol`` as a dict (see the module docstring)."""
    sys.path.insert(0, str(HERE))
    import compare_reports

    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            code = compare_reports.main([str(first), str(second), "--rtol", repr(rtol)])
    except (OSError, ValueError, KeyError) as exc:  # a missing or unreadable report folder
        return {"rtol": rtol, "atol": 1e-12, "verdict": "error", "exit": 2,
                "error": f"{type(exc).__name__}: {exc}", "lines": buf.getvalue().splitlines()}
    lines = buf.getvalue().splitlines()
    items, worst, paper = {}, 0.0, ""
    for line in lines:
        if line.startswith("paper "):
            paper = line[len("paper "):].rstrip(":")
        m = ITEM.match(line)
        if m:
            kind, name, status, rel = m.groups()
            items[f"paper{paper} {kind} {name}"] = {"identical": "identical", "agrees": "agrees"}.get(status, "differs")
            if rel is not None:
                with contextlib.suppress(ValueError):
                    worst = max(worst, float(rel))
    return {"rtol": rtol, "atol": 1e-12, "verdict": "agree" if code == 0 else "differ", "exit": int(code),
            "max_relative_difference": worst, "items": items, "lines": lines}


def crpf_step(arch: str, repeat: int) -> dict:
    """The CRPF step cost (ns per particle; the ``crpf`` filter's ``crpf-step`` group) with the kernels on ``arch``,
    and which backend ran."""
    from workbench.kernels.backend import using
    from workbench_filters.crpf.bench import crpf_step_cost

    with using(arch):
        out = crpf_step_cost(repeat=repeat)  # its "step_backend" is the backend that ran on this arch
        out["arch"] = arch
    return out


#: The method-C kernel's sizes timed on each arch: N = 10^5 and 10^6 particles by M = 10^3 and 10^4 measurements.
METHOD_C_SIZES = ((100_000, 1_000), (100_000, 10_000), (1_000_000, 1_000), (1_000_000, 10_000))


def method_c(arch: str, repeat: int, sizes=METHOD_C_SIZES) -> dict:
    """The method-C weight kernel's throughput (particle-measurement pairs per second) with the kernels on ``arch``,
    in float64 and float32, at each of ``sizes``: the best of ``repeat`` calls after one warm-up call (compilation),
    each call the public ``tbd_log_weight_sums`` (its packing and, on a GPU, the transfers included).  Each size's
    float32 and float64 results are checked against each other (``max_abs_difference``, log-weight sums).  Where
    Taichi runs the kernel, the call's parts too (:func:`_taichi_parts`)."""
    import time

    import numpy as np
    from workbench.kernels.backend import resolve, using
    from workbench_filters.tbd.reference import kernel_inputs
    from workbench_filters.tbd.tbd_weights import tbd_log_weight_sums

    rows = []
    with using(arch):
        backend = resolve("auto", arch)
        for n, m in sizes:
            inputs = kernel_inputs(n, m)
            row = {"N": n, "M": m}
            results = {}
            for precision in ("float64", "float32"):
                best = float("inf")
                for i in range(repeat + 1):
                    start = time.perf_counter()
                    results[precision] = tbd_log_weight_sums(*inputs, backend=backend, precision=precision)
                    if i:  # the first call compiles
                        best = min(best, time.perf_counter() - start)
                row[f"{precision}_seconds"] = best
                row[f"{precision}_pairs_per_s"] = n * m / best
                if backend == "taichi":  # where the call's time goes: the packing, and the kernel alone
                    row.update(_taichi_parts(inputs, precision, repeat))
            row["float32_over_float64"] = row["float32_pairs_per_s"] / row["float64_pairs_per_s"]
            row["max_abs_difference"] = float(np.max(np.abs(results["float32"] - results["float64"])))
            rows.append(row)
            print(f"N {n:>9,d} M {m:>6,d}  float64 {row['float64_pairs_per_s']:.3e} pairs/s  "
                  f"float32 {row['float32_pairs_per_s']:.3e} pairs/s  f32/f64 {row['float32_over_float64']:.2f}  "
                  f"max |f32 - f64| {row['max_abs_difference']:.2e}", flush=True)
    return {"arch": arch, "backend": backend, "repeat": repeat, "cpu_count": os.cpu_count(), "rows": rows}


def _taichi_parts(inputs, precision: str, repeat: int) -> dict:
    """The Taichi method-C call in parts (best of ``repeat`` after a warm-up each): the host-side packing of the
    inputs, and the kernel alone on inputs already on the device (Taichi ndarrays, synchronised), as pairs/s."""
    import numpy as np
    import taichi as ti
    from workbench_filters.tbd.bench import _best_time  # a warm-up call, then the best of ``repeat``
    from workbench_filters.tbd.tbd_weights import LOG2E, _pack_points, pack_measurements
    from workbench_filters.tbd.tbd_weights_taichi import _taichi_kernel

    points, z, valid, log_pd, sigma_p, sigma_vr = inputs

    def pack():
        pts, origin = _pack_points(points, sigma_vr, precision)  # as the call packs them
        return (pts, *pack_measurements(z, valid, log_pd, sigma_p, sigma_vr, precision, origin))

    pts, meas, counts = pack()
    real = ti.f64 if precision == "float64" else ti.f32
    on_device = []
    for array, dtype in ((pts, real), (meas, real), (counts, ti.i32)):
        nd = ti.ndarray(dtype, shape=array.shape)
        nd.from_numpy(np.ascontiguousarray(array))
        on_device.append(nd)
    out = ti.ndarray(ti.f64, shape=(pts.shape[0], pts.shape[2]))
    kernel = _taichi_kernel(precision)
    beta2 = 0.5 / float(sigma_vr) ** 2 * LOG2E

    def run():
        kernel(*on_device, beta2, out)
        ti.sync()

    pairs = pts.shape[0] * pts.shape[2] * int(counts.max())
    pack_s, kernel_s = _best_time(pack, repeat), _best_time(run, repeat)
    return {f"{precision}_pack_seconds": pack_s, f"{precision}_kernel_seconds": kernel_s,
            f"{precision}_kernel_pairs_per_s": pairs / kernel_s}


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _pytest_result(log: Path) -> str | None:
    """pytest's closing line (``12 passed, 1 warning in 30.1s``), if the log has one."""
    try:
        lines = log.read_text(errors="replace").splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        if re.search(r"\d+ (passed|failed|error|skipped|deselected)", line) or "no tests ran" in line:
            return line.strip("= ")
    return None


def _device() -> dict:
    out = {"host": platform.node(), "machine": platform.machine(), "cpu_count": os.cpu_count(),
           "python": platform.python_version()}
    from importlib import metadata

    versions = {}
    for name in ("numpy", "numba", "llvmlite", "taichi", "scipy", "matplotlib"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    out["packages"] = versions
    with contextlib.suppress(OSError):  # the CPU model, where Linux says
        out["cpu_model"] = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                                 if line.startswith("model name")), None)
    if shutil.which("nvidia-smi"):
        with contextlib.suppress(OSError, subprocess.SubprocessError):
            out["gpu"] = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total,driver_version",
                                         "--format=csv,noheader"], capture_output=True, text=True,
                                        timeout=20).stdout.strip()
    return out


def summary(out_dir: Path, work: Path, arch: str, size: str, rtol: float) -> dict:
    """``gpu-check.json``'s content from the steps' records (``work/steps.tsv``) and their JSON outputs."""
    steps = []
    tsv = work / "steps.tsv"
    lines = tsv.read_text().splitlines() if tsv.exists() else []
    for line in lines:
        name, status, code, seconds, command = (line.split("\t") + [""] * 5)[:5]
        step = {"name": name, "status": status, "exit": int(code), "seconds": float(seconds),
                "log": f"{name}.log", "command": command}
        if name == "tests":
            step["result"] = _pytest_result(out_dir / "tests.log")
        steps.append(step)
    bench = {}
    for path in sorted(work.glob("bench-*.json")):
        bench[path.stem[len("bench-"):]] = _read_json(path)
    crpf = {path.stem[len("crpf-"):]: _read_json(path) for path in sorted(work.glob("crpf-*.json"))}
    kernel = {path.stem[len("method-c-"):]: _read_json(path) for path in sorted(work.glob("method-c-*.json"))}
    reports = {}
    for folder in sorted(work.glob("report-*")):
        outcome = _read_json(folder / "paper000" / "outcome.json")
        if isinstance(outcome, dict):
            times = outcome.get("task_times") or {}
            reports[folder.name[len("report-"):]] = {
                "size": outcome.get("size"), "seconds": outcome.get("seconds"),
                "computed_task_seconds": times.get("computed_seconds"), "counts": times.get("counts"),
                "tasks": [{k: row.get(k) for k in ("task", "runs", "seconds")} for row in times.get("rows", [])]}
    comparison = _read_json(work / "compare.json") or {"rtol": rtol, "verdict": "not run"}
    failed = [s["name"] for s in steps if s["status"] != "ok" and s["status"] != "skipped"]
    return {"arch": arch, "size": size, "out": str(out_dir), "work": str(work), "device": _device(),
            "ok": not failed and comparison.get("verdict") == "agree", "failed_steps": failed, "steps": steps,
            "compare": comparison, "bench": bench, "crpf_step": crpf, "method_c": kernel, "reports": reports}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("compare", help="compare two report folders into a JSON verdict")
    p.add_argument("first", type=Path)
    p.add_argument("second", type=Path)
    p.add_argument("--rtol", type=float, required=True)
    p.add_argument("--json", type=Path, required=True)
    p = sub.add_parser("crpf-step", help="time the CRPF step on an arch")
    p.add_argument("--arch", required=True)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--json", type=Path, required=True)
    p = sub.add_parser("method-c", help="time the method-C weight kernel on an arch at N = 1e5, 1e6 x M = 1e3, 1e4")
    p.add_argument("--arch", required=True)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--json", type=Path, required=True)
    p = sub.add_parser("summary", help="write gpu-check.json")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--work", type=Path, required=True)
    p.add_argument("--arch", required=True)
    p.add_argument("--size", required=True)
    p.add_argument("--rtol", type=float, required=True)
    args = parser.parse_args(argv)
    if args.command == "compare":
        result = compare(args.first, args.second, args.rtol)
        args.json.write_text(json.dumps(result, indent=1))
        print("\n".join(result["lines"] + ([result["error"]] if "error" in result else [])))
        print(f"verdict: {result['verdict']} (rtol {args.rtol:g})")
        return result["exit"]
    if args.command == "crpf-step":
        result = crpf_step(args.arch, args.repeat)
        args.json.write_text(json.dumps(result, indent=1, default=str))
        for key, value in result.items():
            print(f"{key:60s} {value}")
        return 0
    if args.command == "method-c":
        result = method_c(args.arch, args.repeat)
        args.json.write_text(json.dumps(result, indent=1))
        return 0
    result = summary(args.out, args.work, args.arch, args.size, args.rtol)
    (args.out / "gpu-check.json").write_text(json.dumps(result, indent=1, default=str))
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
