"""``workbench bench``: run the benchmark groups and print one table.

Benchmark groups come from plugins through the ``workbench_benchmarks`` hook, as report recipes do: each is a
:class:`~workbench.specs.BenchmarkSpec` whose ``run(quick: bool) -> dict`` returns flat figures (numbers or short
strings).  A group runs in its own fresh Python process (which finds it again through its own plugin host) so its
peak memory (``peak_rss_mib``) is its own and one group's warm caches do not flatter another's.
Timing figures inside a group are medians of repeated runs after a warm-up; every comparison with a
peer library is a ratio measured in the same process and run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["discover_groups", "run_group", "run_bench", "median_time"]

_CHILD = """
import json, resource, sys
from workbench.plugins import load_host
spec = load_host(block={block!r}).benchmark({group!r})
out = dict(spec.run({quick}))
out["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print("@@BENCH@@" + json.dumps(out, default=float))
"""


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


def run_group(name: str, quick: bool, timeout: float = 1800, block: tuple[str, ...] = ()) -> dict:
    code = _CHILD.format(group=name, quick=bool(quick), block=list(block))
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
    """Nested figures as ``(dotted.name, value)`` rows; a list of dicts is indexed ``name[i]``."""
    if isinstance(value, dict):
        rows = []
        for k, v in value.items():
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


def run_bench(host, quick: bool, json_path: Path, only: list[str] | None = None, block: tuple[str, ...] = ()) -> int:
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
        print(f"running benchmark group {g} ({'quick' if quick else 'full'})...", file=sys.stderr, flush=True)
        results[g] = run_group(g, quick, block=tuple(block))
    rows = [row for g, r in results.items() for row in flatten(g, r)]
    width = max([len(name) for name, _ in rows] + [10])
    print(f"{'figure'.ljust(width)}  value")
    for name, value in rows:
        print(f"{name.ljust(width)}  {_fmt(value)}")
    json_path = Path(json_path)
    json_path.write_text(json.dumps({"quick": quick, "groups": results}, indent=2, default=str))
    print(f"written: {json_path}")
    return 1 if any("error" in r for r in results.values()) else 0
