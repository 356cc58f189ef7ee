"""``workbench bench``: run the benchmark groups and print one table.

Benchmark groups come from plugins through the ``workbench_benchmarks`` hook, as report recipes do: each is a
:class:`~workbench.specs.BenchmarkSpec` whose ``run(quick: bool) -> dict`` returns flat figures (numbers or short
strings).  A group runs in its own fresh Python process (which finds it again through its own plugin host) so its
peak memory (``peak_rss_mib``) is its own and one group's warm caches do not flatter another's.  The process
runs the group with the kernels on ``arch`` (:func:`workbench.kernels.backend.using`: ``--arch cuda`` puts the
Taichi kernels on the GPU) and records the arch as ``kernel_arch``.
Timing figures inside a group are medians of repeated runs after a warm-up; every comparison with a
peer library is a ratio measured in the same process and run.

Repeats.  Each group runs ``repeats`` times (3 at full size, 1 with ``--quick``), each run in its own fresh
process, one after another; :func:`combine_runs` reads the runs against each other: every numeric figure becomes
its median (where readers expect a number: ``groups`` of the JSON, the plots) with its spread beside it
(``spread[group][figure] = {"min", "median", "max", "runs"}``), and every target is judged on the median of its
``measured_X`` (:func:`workbench.bench.targets.median_verdict`).  The header and the JSON's ``machine`` say where
it ran (:func:`machine_info`: CPU model, usable cores, Python / NumPy / Numba versions) and the load average
before and after each group's runs.

After the figures the runner prints the target table (:mod:`.targets`: every ``target_X`` / ``measured_X`` /
``met_X`` a group declares, one line each with min / median / max, "indicative" in quick mode), and with
``plot_dir`` draws every group's ``curves`` (:mod:`.plots`, from the medians).
"""

from __future__ import annotations

import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

from ..types import InputError
from .targets import NOT_UNDERSTOOD, collect_targets, format_targets, median_verdict, parse_goal

__all__ = ["discover_groups", "run_group", "run_bench", "median_time", "flatten", "child_main", "own_peak_kib",
           "combine_runs", "machine_info", "cpu_identity", "cpu_identity_text", "load_average",
           "default_repeats"]

_CHILD = """
import sys
from workbench.bench import child_main
child_main({group!r}, {quick}, {block!r}, {arch!r})
"""


def own_peak_kib() -> float:
    """This process's own peak resident set size (KiB): ``VmHWM`` of ``/proc/self/status``, the high-water mark of
    the memory this program mapped.  ``getrusage(RUSAGE_SELF).ru_maxrss`` would also count the image the process
    was forked (or vfork-ed) from, i.e. its parent's peak; it is the fallback where ``/proc`` is missing."""
    try:
        with open("/proc/self/status") as f:
            return float(next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")))
    except (OSError, StopIteration, ValueError, IndexError):
        import resource

        return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def child_main(group: str, quick: bool, block=(), arch: str = "cpu") -> None:
    """The body of a group's process: run it with the kernels on ``arch`` and print its figures as one JSON line."""
    from ..kernels.backend import using
    from ..memory import keep_freed_memory
    from ..plugins import load_host

    keep_freed_memory()  # as the command line's own processes run (workbench.memory)
    spec = load_host(block=list(block)).benchmark(group)
    with using(arch):
        out = dict(spec.run(quick))
    out.setdefault("kernel_arch", arch)
    out["peak_rss_mib"] = own_peak_kib() / 1024.0
    print("@@BENCH@@" + json.dumps(out, default=float), flush=True)


def median_time(fn, repeat: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` over ``repeat`` runs after ``warmup`` untimed runs (seconds)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[len(times) // 2]


def discover_groups(host) -> list[str]:
    """The benchmark groups the installed plugins provide, sorted."""
    return sorted(host.benchmarks)


def run_group(name: str, quick: bool, timeout: float = 1800, block: tuple[str, ...] = (), arch: str = "cpu") -> dict:
    code = _CHILD.format(group=name, quick=bool(quick), block=list(block), arch=arch)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)
    lines = [l for l in proc.stdout.splitlines() if l.startswith("@@BENCH@@")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return {"error": f"benchmark group {name!r} failed: " + " | ".join(tail)}
    out = json.loads(lines[-1][len("@@BENCH@@"):])
    out["group_wall_s"] = time.perf_counter() - t0
    return out


def default_repeats(quick: bool) -> int:
    """Runs per group when ``--repeats`` is not given: 3 at full size, 1 with ``--quick``."""
    return 1 if quick else 3


def load_average() -> list[float] | None:
    """The 1, 5 and 15 minute load averages (``os.getloadavg``), ``None`` where the platform has none."""
    try:
        return [float(v) for v in os.getloadavg()]
    except (AttributeError, OSError):
        return None


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


#: The vector extensions named in ``/proc/cpuinfo``'s flags (x86) or features (Arm), widest first.
_VECTOR_ISAS = (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"), ("sse4_2", "SSE4.2"), ("sve2", "SVE2"),
                ("sve", "SVE"), ("asimd", "NEON"))


def cpu_identity(text: str | None = None) -> dict:
    """What tells two CPUs of one "model name" apart (a cloud VM's "AMD EPYC" is a Zen 1 or a Zen 4): the first
    processor's ``vendor`` (``vendor_id``, or ``CPU implementer`` on Arm), ``family``, ``model`` and ``stepping``
    as ``/proc/cpuinfo`` gives them (``CPU architecture``, ``CPU part``, ``CPU variant`` on Arm), and
    ``vector_isa``, the widest vector extension among its flags (``"AVX-512"``, ``"AVX2"``, ...; ``"unknown"``).
    ``text``: the file's contents (read from ``/proc/cpuinfo`` when ``None``); ``{}`` where there is none."""
    if text is None:
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
                text = f.read()
        except OSError:
            return {}
    fields: dict[str, str] = {}
    for line in text.splitlines():
        if not line.strip():
            if fields:
                break  # the first processor's block only
            continue
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip().lower(), value.strip())
    if not fields:
        return {}
    out = {}
    for name, keys in (("vendor", ("vendor_id", "cpu implementer")), ("family", ("cpu family", "cpu architecture")),
                       ("model", ("model", "cpu part")), ("stepping", ("stepping", "cpu variant"))):
        for key in keys:
            if fields.get(key):
                out[name] = fields[key]
                break
    flags = set((fields.get("flags") or fields.get("features") or "").split())
    out["vector_isa"] = next((label for flag, label in _VECTOR_ISAS if flag in flags), "unknown")
    return out


def cpu_identity_text(machine: dict) -> str:
    """``"AuthenticAMD family 25 model 17 stepping 1, AVX-512"`` from :func:`machine_info`'s ``cpu``."""
    ident = machine.get("cpu") or {}
    parts = [ident.get("vendor", "")] + [f"{k} {ident[k]}" for k in ("family", "model", "stepping") if ident.get(k)]
    text = " ".join(p for p in parts if p)
    isa = ident.get("vector_isa")
    return ", ".join(t for t in (text, isa) if t)


def _version(module: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(module)
    except metadata.PackageNotFoundError:
        return "not installed"


def machine_info() -> dict:
    """Where the figures were measured: ``cpu_model`` (``/proc/cpuinfo``'s "model name", else
    ``platform.processor()``), ``usable_cores`` (``os.sched_getaffinity`` where present, else ``os.cpu_count()``),
    ``logical_cores``, ``platform``, ``cpu`` (:func:`cpu_identity`: vendor, family, model, stepping and the widest
    vector extension), and the ``python`` / ``numpy`` / ``numba`` versions ("not installed" where absent).  The
    runner adds ``load_avg``: the load averages before and after each group's runs."""
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count() or 1
    return {"cpu_model": _cpu_model(), "cpu": cpu_identity(), "usable_cores": int(usable),
            "logical_cores": int(os.cpu_count() or usable), "platform": platform.platform(),
            "python": platform.python_version(), "numpy": _version("numpy"), "numba": _version("numba")}


_ABSENT = object()


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _join(path: str, key) -> str:
    return f"{path}.{key}" if path else str(key)


def _merge(path: str, values: list, spread: dict):
    """The median reading of one figure over the runs (``values``, one per run, ``_ABSENT`` where a run lacks it);
    records its spread in ``spread[path]``."""
    present = [v for v in values if v is not _ABSENT]
    if present and all(isinstance(v, dict) for v in present):
        keys = list(dict.fromkeys(k for v in present for k in v))
        return {k: _merge(_join(path, k), [v.get(k, _ABSENT) if isinstance(v, dict) else _ABSENT for v in values],
                          spread) for k in keys}
    complete = len(present) == len(values)
    if complete and all(isinstance(v, list) and v and all(isinstance(e, dict) for e in v) for v in values) \
            and len({len(v) for v in values}) == 1:
        return [_merge(f"{path}[{i}]", [v[i] for v in values], spread) for i in range(len(values[0]))]
    if complete and all(_is_number(v) for v in values):
        if all(math.isfinite(v) for v in values):
            spread[path] = {"min": min(values), "median": statistics.median(values), "max": max(values),
                            "runs": list(values)}
            return spread[path]["median"]
        spread[path] = {"runs": list(values)}  # a nan or inf in some run: no median; the first run's value
        return values[0]
    if complete and all(isinstance(v, list) and v and all(_is_number(e) and math.isfinite(e) for e in v)
                        for v in values) and len({len(v) for v in values}) == 1:
        return [statistics.median(col) for col in zip(*values)]  # a curve's points: the median point by point
    if complete and all(v == values[0] for v in values):
        return values[0]
    spread[path] = {"runs": [None if v is _ABSENT else v for v in values]}  # differs in kind over the runs
    return present[0]


def _closest_run(values: list, median) -> int:
    return min(range(len(values)), key=lambda k: abs(values[k] - median))


def _rejudge(path: str, merged: dict, runs: list, problems: list, group: str = "") -> None:
    """Judge every target declared in ``merged`` (and below it) on the median of its ``measured_X`` over ``runs``
    (the runs' dicts at the same place): ``met_X`` becomes the median's verdict, ``note_X`` the note of the run
    nearest the median."""
    for key, value in list(merged.items()):
        if isinstance(value, dict):
            _rejudge(_join(path, key), value, [r.get(key) if isinstance(r, dict) else None for r in runs], problems,
                     group)
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            sub = [r.get(key) if isinstance(r, dict) else None for r in runs]
            for i, item in enumerate(value):
                _rejudge(f"{_join(path, key)}[{i}]", item,
                         [s[i] if isinstance(s, list) and len(s) > i else None for s in sub], problems, group)
        if not (key.startswith("target_") and isinstance(value, str)):
            continue
        name = key[len("target_"):]
        label = _join(group, _join(path, name))
        try:
            parse_goal(value, label)
        except InputError as exc:
            problems.append(str(exc))
            if f"met_{name}" in merged:
                merged[f"met_{name}"] = NOT_UNDERSTOOD
            continue
        measured = [r.get(f"measured_{name}", _ABSENT) if isinstance(r, dict) else _ABSENT for r in runs]
        met = [r.get(f"met_{name}") if isinstance(r, dict) else None for r in runs]
        if all(_is_number(m) and math.isfinite(m) for m in measured):
            verdict, remark = median_verdict(label, value, measured, met)
            if f"met_{name}" in merged:
                merged[f"met_{name}"] = verdict
            if len(runs) > 1 and f"note_{name}" in merged:
                best = runs[_closest_run(measured, statistics.median(measured))]
                if isinstance(best.get(f"note_{name}"), str):
                    merged[f"note_{name}"] = best[f"note_{name}"]
            if remark:
                merged[f"note_{name}"] = (str(merged.get(f"note_{name}") or "") + "; " + remark).lstrip("; ")
        elif f"met_{name}" in merged and any(m != met[0] for m in met):
            merged[f"met_{name}"] = "varies over the runs: " + ", ".join(
                "absent" if m is _ABSENT else str(m) for m in measured)


def combine_runs(runs: list[dict], group: str = "") -> tuple[dict, dict, list[str]]:
    """One group's figures from its runs (each run's dict of figures, in order): ``(figures, spread, problems)``.

    ``figures`` has the runs' shape with every numeric figure replaced by its median over the runs (a number where
    readers expect one); a figure that is not a number takes the runs' common value, or where the runs differ the
    first run's (its values are then in ``spread``); curve points are medians point by point.  ``spread`` maps each
    figure's dotted name (as in the table, without the group) to ``{"min", "median", "max", "runs"}`` (numbers) or
    ``{"runs"}`` (a figure that differs in kind over the runs).  Every declared target is judged on the median of
    its measured value (:func:`~workbench.bench.targets.median_verdict`); ``problems`` are the one-line refusals
    of goals that are not comparisons with a number (naming ``group`` and the target)."""
    if not runs:
        raise ValueError("combine_runs needs at least one run")
    spread: dict = {}
    problems: list[str] = []
    merged = _merge("", list(runs), spread)
    _rejudge("", merged, list(runs), problems, group)
    return merged, spread, problems


def flatten(prefix: str, value) -> list[tuple[str, object]]:
    """Nested figures as ``(dotted.name, value)`` rows; a list of dicts is indexed ``name[i]``.  A group's
    ``curves`` (the data of its figures) are one row saying how many there are."""
    if isinstance(value, dict):
        rows = []
        for k, v in value.items():
            if k == "curves" and isinstance(v, list):
                rows.append((f"{prefix}.curves", f"{len(v)} scaling figure(s) (--plot DIR draws them)"))
                continue
            rows += flatten(f"{prefix}.{k}", v)
        return rows
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        rows = []
        for i, v in enumerate(value):
            rows += flatten(f"{prefix}[{i}]", v)
        return rows
    return [(prefix, value)]


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def machine_lines(machine: dict, repeats: int) -> list[str]:
    """The header of the table: the machine, the repeats, and the load before and after each group's runs."""
    ident = cpu_identity_text(machine)
    lines = [f"machine: {machine.get('cpu_model', 'unknown')}" + (f" ({ident})" if ident else "")
             + f", {machine.get('usable_cores', '?')} usable of "
             f"{machine.get('logical_cores', '?')} cores; Python {machine.get('python', '?')}, NumPy "
             f"{machine.get('numpy', '?')}, Numba {machine.get('numba', '?')}",
             f"repeats: {repeats} run(s) per group, each in its own fresh process, one after another; figures are "
             f"medians" + (" [min .. max] over the runs" if repeats > 1 else "")]
    loads = machine.get("load_avg") or {}
    if loads:
        def one(v):
            return "n/a" if not v else f"{v[0]:.2f}"
        lines.append("load average (1 min) before -> after each group's runs: " + "; ".join(
            f"{g} {one(v.get('before'))} -> {one(v.get('after'))}" for g, v in loads.items()))
    return lines


def print_results(results: dict, quick: bool, out=print, spread: dict | None = None, machine: dict | None = None,
                  repeats: int = 1) -> None:
    """The header (``machine``), the figures one per line (the median, and ``[min .. max]`` where the runs
    differ), then the target table judged on the medians."""
    spread = spread or {}
    if machine is not None:
        for line in machine_lines(machine, repeats):
            out(line)
        out("")
    rows = [(g, name, value) for g, r in results.items() for name, value in flatten(g, r)]
    width = max([len(name) for _, name, _ in rows] + [10])
    out(f"{'figure'.ljust(width)}  value" + ("  [min .. max]" if repeats > 1 else ""))
    for g, name, value in rows:
        sp = (spread.get(g) or {}).get(name[len(g) + 1:]) or {}
        extra = ""
        if "min" in sp and sp["min"] != sp["max"]:
            extra = f"  [{_fmt(sp['min'])} .. {_fmt(sp['max'])}]"
        elif "runs" in sp and "min" not in sp:
            extra = "  (differs over the runs: " + ", ".join(_fmt(v) for v in sp["runs"]) + ")"
        out(f"{name.ljust(width)}  {_fmt(value)}{extra}")
    out("")
    out(format_targets(collect_targets(results, quick, spread), quick))


def run_bench(host, quick: bool, json_path: Path, only: list[str] | None = None, block: tuple[str, ...] = (),
              arch: str = "cpu", plot_dir: Path | None = None, repeats: int | None = None) -> int:
    """Run the groups (``repeats`` runs each, :func:`default_repeats` when ``None``), print the header, figures
    and target table, write the JSON; 0 when every group ran and every goal was understood, 1 otherwise, 2 for an
    unknown group."""
    if repeats is None:
        repeats = default_repeats(quick)
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise InputError(f"bench --repeats: expected a whole number >= 1, got {repeats!r}")
    groups = discover_groups(host)
    if only:
        unknown = set(only) - set(groups)
        if unknown:
            print(f"workbench: error: unknown benchmark group(s) {sorted(unknown)} (groups: {', '.join(groups)})",
                  file=sys.stderr)
            return 2
        groups = [g for g in groups if g in only]
    machine = machine_info()
    machine["load_avg"] = {}
    results, spread, problems = {}, {}, []
    for g in groups:
        before = load_average()
        runs, error = [], None
        for k in range(repeats):
            print(f"running benchmark group {g} ({'quick' if quick else 'full'}, kernels on {arch}), run {k + 1} of "
                  f"{repeats}...", file=sys.stderr, flush=True)
            r = run_group(g, quick, block=tuple(block), arch=arch)
            if "error" in r:
                error = r["error"] + (f" (run {k + 1} of {repeats})" if repeats > 1 else "")
                break
            runs.append(r)
        machine["load_avg"][g] = {"before": before, "after": load_average()}
        if error is not None:
            results[g], spread[g] = {"error": error}, {}
            continue
        results[g], spread[g], found = combine_runs(runs, g)
        problems += found
    print_results(results, quick, spread=spread, machine=machine, repeats=repeats)
    targets = [t.__dict__ for t in collect_targets(results, quick, spread)]
    json_path = Path(json_path)
    json_path.write_text(json.dumps({"quick": quick, "arch": arch, "repeats": repeats, "machine": machine,
                                     "groups": results, "spread": spread, "targets": targets},
                                    indent=2, default=str))
    print(f"written: {json_path}")
    for problem in problems:
        print(f"workbench: error: {problem}", file=sys.stderr)
    if plot_dir is not None:
        from .plots import save_curves

        for path in save_curves(results, plot_dir):
            print(f"written: {path} (+ .svg, .csv)")
    if arch == "cpu":
        print("note: kernels ran on the CPU; GPU figures need 'workbench bench --arch cuda' on a machine with a GPU")
    return 1 if problems or any("error" in r for r in results.values()) else 0


def replot(json_path: Path, plot_dir: Path) -> int:
    """Draw the curves of a saved ``workbench bench`` JSON again (no benchmark is run)."""
    from .plots import save_curves

    data = json.loads(Path(json_path).read_text(encoding="utf-8"))
    for path in save_curves(data.get("groups", {}), plot_dir):
        print(f"written: {path} (+ .svg, .csv)")
    return 0
