"""Benchmark group ``dask``: the paper-003 Monte Carlo in-process against a local Dask cluster.

Both runs start from an empty cache, use the same seed and compare every array of every task
bit for bit.  Quick mode runs the quick size; full mode the paper scale (3,000 runs per level).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from .plugins import load_host
from .report.cache import load_arrays
from .report.engine import dask_executor, run_recipe

WORKERS = 2


def _arrays(out: Path) -> dict[str, dict[str, np.ndarray]]:
    return {p.name.rsplit("-", 1)[0]: load_arrays(p) for p in sorted((out / "cache" / "paper003").glob("*.npz"))}


def bench(quick: bool) -> dict:
    host = load_host()
    try:
        recipe = host.recipe("003")
    except KeyError:
        return {"status": "paper 003 recipe not installed"}
    size = "quick" if quick else "full"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        inproc = run_recipe(recipe, host, tmp / "inproc", size=size, seed=1, progress=False)
        t_in = time.perf_counter() - t0
        try:
            executor = dask_executor(host, workers=WORKERS)
        except Exception as exc:  # distributed not installed
            return {"size": size, "in_process_s": t_in, "dask": f"not available: {exc}"}
        try:
            t0 = time.perf_counter()
            remote = run_recipe(recipe, host, tmp / "dask", size=size, seed=1, progress=False, executor=executor)
            t_dask = time.perf_counter() - t0
        finally:
            executor.close()
        a, b = _arrays(tmp / "inproc"), _arrays(tmp / "dask")
        # Wall-clock measurements differ by nature; every other array must be bit-identical.
        measured = lambda name: "seconds" in name or name.endswith("_s")  # noqa: E731
        identical = a.keys() == b.keys() and all(
            a[k].keys() == b[k].keys() and all(np.array_equal(a[k][n], b[k][n]) for n in a[k] if not measured(n))
            for k in a)
    return {
        "size": size,
        "tasks": len(inproc.tasks),
        "in_process_s": t_in,
        f"dask_{WORKERS}_workers_s": t_dask,
        "dask_over_in_process": t_dask / t_in,
        "identical_results": bool(identical),
        "errors": len(inproc.errors) + len(remote.errors),
    }
