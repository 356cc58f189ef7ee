"""Benchmark group ``dask``: the paper-003 primary Monte Carlo in-process against a local Dask cluster.

The same tasks (3 levels x 8 filters, mismatched noise) run through the report engine's in-process
executor and through a 2-worker local cluster; every array except wall-clock measurements must be
bit-identical.  Quick mode runs the quick size, full mode the paper scale (3,000 runs per level).
"""

from __future__ import annotations

import os

import numpy as np

from .bench import _host, _warm_up_kernels, run_primary
from workbench.report.engine import dask_executor

WORKERS = 2
#: The target: a local cluster of WORKERS workers costs at most this much over one process.
TARGET_RATIO = 1.2


def _measured(name: str) -> bool:
    """Wall-clock measurements differ by nature."""
    return "seconds" in name or name.endswith("_s")


def bench(quick: bool) -> dict:
    size = "quick" if quick else "full"
    _warm_up_kernels()  # both sides timed warm: the compiled kernels loaded here, and on the workers below
    t_in, inproc = run_primary(size, seed=1)
    try:
        executor = dask_executor(_host(), workers=WORKERS)
    except Exception as exc:  # distributed not installed
        return {"size": size, "in_process_s": t_in, "dask": f"not available: {exc}"}
    try:
        run_primary("quick", executor=executor)
        t_dask, remote = run_primary(size, seed=1, executor=executor)
    finally:
        executor.close()
    identical = inproc.keys() == remote.keys() and all(
        inproc[k].keys() == remote[k].keys()
        and all(np.array_equal(inproc[k][n], remote[k][n]) for n in inproc[k] if not _measured(n))
        for k in inproc)
    return {
        "size": size,
        "tasks": len(inproc),
        "in_process_s": t_in,
        f"dask_{WORKERS}_workers_s": t_dask,
        "dask_over_in_process": t_dask / t_in,
        "identical_results": bool(identical),
        "target_dask_over_in_process": f"<= {TARGET_RATIO:g}",
        "measured_dask_over_in_process": t_dask / t_in,
        "met_dask_over_in_process": bool(t_dask / t_in <= TARGET_RATIO and identical),
        "note_dask_over_in_process": (f"{size} size, {WORKERS} single-threaded workers against one process on "
                                      f"{os.cpu_count()} cores; met only with bit-identical results"),
    }
