"""Paper 003's reading helpers: where the tasks put their results and how the figures, tables and criteria read
them (the result keys, the filters present, a filter's Monte Carlo summaries, its diagnostics and timings, the
near-optimal reference's configuration).

:mod:`.recipe` (the tasks that write the results) and :mod:`.judging` (the criteria that read them) both import
this module, and it imports neither.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .scenario import LEVELS, NOMINAL, case_name

#: The near-optimal reference: the built-in bootstrap PF with 5,000 particles and the level's true models.
REFERENCE = {"label": "pf-5000 (true noise)", "filter": "sir", "configure": {"particles": 5000}}
#: The reference's convergence check: the same PF with 4 x the particles, on the same runs (common random numbers).
REFERENCE_4N = {"label": "pf-20000 (true noise)", "filter": "sir",
                "configure": {"particles": 4 * REFERENCE["configure"]["particles"]}}


def cases_of(reading: str) -> list[str]:
    return [case_name(reading, lv) for lv in LEVELS]


def filters_in(results: Mapping, reading: str = "rad") -> list[str]:
    """Filter names with a mismatched result at every level of ``reading``, in task order."""
    names = []
    for key in results:
        parts = key.split("/")
        if parts[0] == "mc" and len(parts) == 4 and parts[3] == "mismatched" and parts[2] not in names:
            names.append(parts[2])
    return [n for n in names if all(f"mc/{c}/{n}/mismatched" in results for c in cases_of(reading))]


def mc(results: Mapping, case: str, name: str, variant: str = "mismatched") -> Mapping[str, np.ndarray]:
    """A filter's summaries on a case; ``variant="matched"`` falls back to the mismatched result where the two
    coincide (L2, or a filter that reads no noise statistics)."""
    if variant == "matched" and not case.endswith(NOMINAL):
        res = results.get(f"mc/{case}/{name}/matched")
        if res is not None and "same_as_mismatched" not in res:
            return res
    return results[f"mc/{case}/{name}/mismatched"]


def mse(results, case, name, variant="mismatched") -> float:
    return float(np.mean(mc(results, case, name, variant)["mse_t"]))


def diag(res: Mapping, key: str) -> float:
    names = [str(n) for n in res.get("diag_names", [])]
    return float(res["diag_values"][names.index(key)]) if key in names else 0.0


#: The task that times every filter of the report, interleaved (:func:`.tasks.run_timing`).
TIMING_TASK = "timing"
TIMING_ARRAYS = ("per_run_s", "per_run_cpu_s", "batched_per_run_s")


def timing_arrays(results, name) -> dict | None:
    """Filter ``name``'s arrays of the timing task (``per_run_s``, ``per_run_cpu_s``, ``batched_per_run_s``), or
    ``None`` where it was not timed."""
    res = results.get(TIMING_TASK)
    if res is None or f"{name}:per_run_s" not in res:
        return None
    return {k: res[f"{name}:{k}"] for k in TIMING_ARRAYS if f"{name}:{k}" in res}


def timing(results, name) -> tuple[float, float]:
    """(un-batched median seconds per run, batched median seconds per run) of the warmed-up timing task."""
    res = timing_arrays(results, name)
    if res is None:
        return np.nan, np.nan
    return float(np.median(res["per_run_s"])), float(np.median(res["batched_per_run_s"]))


def delta_key(reading: str, value: float, name: str) -> str:
    """The task key of ``name`` (a CRPF) with delta = ``value`` on the first ``delta_runs`` runs of ``reading``."""
    return f"delta/{reading}/{value:g}/{name}"
