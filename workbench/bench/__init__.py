"""``workbench bench``: run the benchmark groups and print one table.

Benchmark groups come from plugins through the ``workbench_benchmarks`` hook, as report recipes do: each is a
:class:`~workbench.specs.BenchmarkSpec` whose ``run(quick: bool) -> dict`` returns flat figures (numbers or short
strings).  A group runs in its own fresh Python process (which finds it again through its own plugin host) so its
peak memory (``peak_rss_mib``) is its own and one group's warm caches do not flatter another's.  The process
runs the group with the kernels on ``arch`` (:func:`workbench.kernels.backend.using`: ``--arch cuda`` puts the
Taichi kernels on the GPU) and records the arch as ``kernel_arch``.
Timing figures inside a group are medians of repeated runs after a warm-up; every comparison with a
peer library is a ratio measured in the same process and run.

After the figures the runner prints the target table (:mod:`.targets`: every ``target_X`` / ``measured_X`` /
``met_X`` a group declares, one line each, "indicative" in quick mode), and with ``plot_dir`` draws every
group's ``curves`` (:mod:`.plots`).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from .targets import collect_targets, format_targets

__all__ = ["discover_groups", "run_group", "run_bench", "median_time", "flatten", "child_main", "own_peak_kib"]

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
    from ..plugins import load_host

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


def print_results(results: dict, quick: bool, out=print) -> None:
    """The figures, one per line, then the target table."""
    rows = [row for g, r in results.items() for row in flatten(g, r)]
    width = max([len(name) for name, _ in rows] + [10])
    out(f"{'figure'.ljust(width)}  value")
    for name, value in rows:
        out(f"{name.ljust(width)}  {_fmt(value)}")
    out("")
    out(format_targets(collect_targets(results, quick), quick))


def run_bench(host, quick: bool, json_path: Path, only: list[str] | None = None, block: tuple[str, ...] = (),
              arch: str = "cpu", plot_dir: Path | None = None) -> int:
    groups = discover_groups(host)
    if only:
        unknown = set(only) - set(groups)
        if unknown:
            print(f"workbench: error: unknown benchmark group(s) {sorted(unknown)} (groups: {', '.join(groups)})",
                  file=sys.stderr)
            return 2
        groups = [g for g in groups if g in only]
    results = {}
    for g in groups:
        print(f"running benchmark group {g} ({'quick' if quick else 'full'}, kernels on {arch})...", file=sys.stderr,
              flush=True)
        results[g] = run_group(g, quick, block=tuple(block), arch=arch)
    print_results(results, quick)
    targets = [t.__dict__ for t in collect_targets(results, quick)]
    json_path = Path(json_path)
    json_path.write_text(json.dumps({"quick": quick, "arch": arch, "groups": results, "targets": targets},
                                    indent=2, default=str))
    print(f"written: {json_path}")
    if plot_dir is not None:
        from .plots import save_curves

        for path in save_curves(results, plot_dir):
            print(f"written: {path} (+ .svg, .csv)")
    if arch == "cpu":
        print("note: kernels ran on the CPU; GPU figures need 'workbench bench --arch cuda' on a machine with a GPU")
    return 1 if any("error" in r for r in results.values()) else 0


def replot(json_path: Path, plot_dir: Path) -> int:
    """Draw the curves of a saved ``workbench bench`` JSON again (no benchmark is run)."""
    from .plots import save_curves

    data = json.loads(Path(json_path).read_text(encoding="utf-8"))
    for path in save_curves(data.get("groups", {}), plot_dir):
        print(f"written: {path} (+ .svg, .csv)")
    return 0
