"""Speed of paper 000's method-C weights and of a whole method-C scenario (a benchmark, not a test).

:func:`bench` measures, in one run:

- the throughput (particle-measurement pairs per second) of the weight kernel
  :func:`workbench.kernels.tbd_weights.tbd_log_weight_sums` for N = 10^3..10^6 particles and
  M = 10..10^3 measurements, per backend (Taichi on the CPU, Numba when installed), against the
  chunked NumPy reference and a naive NumPy broadcast (the whole (N, M) array at once), as ratios;
- an estimate of the machine limit for this kernel: the measured peak double-precision rate
  divided by the kernel's essential arithmetic per pair (:data:`FLOPS_PER_PAIR`), and each backend's
  share of it;
- a whole 300-scan method-C scenario with N = 10^5 particles, a 2.5 km gate and the 3 dB threshold
  (target: under 30 s).

NumPy timings on more than :data:`NUMPY_PAIR_CAP` pairs are taken on a slice of the particles (the
rate per pair does not depend on N at these sizes); the result says so.
"""

from __future__ import annotations

import os
import time

import numpy as np

from workbench.kernels.backend import numba_available
from workbench.kernels.reference import kernel_inputs, naive_log_weight_sums, tbd_log_weight_sums_reference
from workbench.kernels.tbd_weights import tbd_log_weight_sums

__all__ = ["FLOPS_PER_PAIR", "NUMPY_PAIR_CAP", "bench", "naive_log_weight_sums", "peak_flops", "kernel_inputs"]

#: Essential double-precision operations per (particle, measurement) pair, FMA counted as 2: residuals
#: 4, squared distance 5, Doppler term and log-weight 5, exp (range reduction 6, degree-11 Horner 22,
#: scaling 1) 29, accumulation 1 -> 44.
FLOPS_PER_PAIR = 44
#: The issue's rough figure for the machine limit, pairs/s in float64 on 2 cores (for comparison).
ISSUE_LIMIT_PAIRS_PER_S = 3e9
NUMPY_PAIR_CAP = 10_000_000


def _best_time(fn, repeats: int) -> float:
    fn()  # warm-up (compilation, caches)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def peak_flops(repeats: int = 3) -> dict:
    """Measured peak float64 rate of this machine (FLOP/s, FMA = 2): the best of BLAS ``dgemm`` and, when
    Numba is installed, a register-resident FMA loop vectorised by LLVM for this CPU."""
    n = 1500
    a, b = np.random.default_rng(0).random((2, n, n))
    dgemm = 2.0 * n**3 / _best_time(lambda: a @ b, repeats)
    out = {"dgemm_flops": dgemm, "fma_loop_flops": float("nan")}
    if numba_available():
        import numba

        @numba.njit(parallel=True, fastmath=True)
        def fma_loop(x, out, rounds):
            for i in numba.prange(x.shape[0]):
                v = x[i]
                a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = v
                for _ in range(rounds):  # 8 independent FMA chains per element
                    a0 = a0 * 0.999999 + 1e-7
                    a1 = a1 * 0.999998 + 2e-7
                    a2 = a2 * 0.999997 + 3e-7
                    a3 = a3 * 0.999996 + 4e-7
                    a4 = a4 * 0.999995 + 5e-7
                    a5 = a5 * 0.999994 + 6e-7
                    a6 = a6 * 0.999993 + 7e-7
                    a7 = a7 * 0.999992 + 8e-7
                out[i] = a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7

        x = np.random.default_rng(1).random(1 << 14)
        y = np.empty_like(x)
        rounds = 2000
        seconds = _best_time(lambda: fma_loop(x, y, rounds), repeats)
        out["fma_loop_flops"] = 2.0 * 8 * rounds * x.size / seconds
    out["peak_flops"] = float(np.nanmax([out["dgemm_flops"], out["fma_loop_flops"]]))
    return out


def _rate(fn, pairs: int, repeats: int) -> float:
    return pairs / _best_time(fn, repeats)


def scenario_run(particles: int = 100_000, radius: float = 2500.0, threshold_db: float = 3.0, seed: int = 1) -> dict:
    """One 300-scan method-C run (batch of one) through the recipe's scenario; wall time of the tracking."""
    from workbench.models import constant_velocity
    from workbench.plugins import load_host
    from .pipeline import estimation_error, run_gated
    from .recipe import DT, PRIOR_SD, SIGMA_A, scenario_truth, simulate_scans, with_particles
    from workbench.rng import generator
    from workbench.types import Gaussian

    host = load_host()
    truth = scenario_truth(1)
    scans = simulate_scans(host, truth, seed, threshold_db)
    spec = with_particles(host.filter("tbd-pf"), particles)
    model = host.sensor("lband-radar").measurement_model()
    prior = Gaussian.broadcast(truth.states[0, 0], np.diag(np.square(PRIOR_SD)), 1)
    tbd_log_weight_sums(*kernel_inputs(8, 4))  # compile before timing
    out = run_gated(spec, prior, constant_velocity(3, DT, SIGMA_A), model, scans, radius, generator(seed, "bench"),
                    truth=truth.states)
    err = estimation_error(out.mean, truth.states)
    return {"particles": particles, "radius_m": radius, "threshold_db": threshold_db, "scans": truth.steps,
            "seconds": out.seconds, "gated_per_scan": float(out.gated_count.mean()),
            "pairs": float(particles * out.gated_count.sum()), "mean_error_m": float(err.mean()),
            "target_seconds": 30.0, "met": out.seconds < 30.0}


def bench(quick: bool = False) -> dict:
    """Weight-kernel throughput per backend vs NumPy, the machine limit, and a whole scenario.

    Returns a JSON-serialisable dict: ``kernel`` (one row per (N, M)), ``machine``, ``scenario``.
    """
    sizes_n = (1_000, 100_000) if quick else (1_000, 10_000, 100_000, 1_000_000)
    sizes_m = (10, 1_000) if quick else (10, 100, 1_000)
    repeats = 2 if quick else 3
    backends = ["taichi"] + (["numba"] if numba_available() else [])
    machine = peak_flops(repeats)
    limit = machine["peak_flops"] / FLOPS_PER_PAIR
    rows = []
    for n in sizes_n:
        for m in sizes_m:
            inputs = kernel_inputs(n, m)
            pairs = n * m
            row = {"N": n, "M": m}
            for be in backends:
                row[f"{be}_pairs_per_s"] = _rate(lambda: tbd_log_weight_sums(*inputs, backend=be), pairs, repeats)
            sub = max(1, min(n, NUMPY_PAIR_CAP // m))
            small = (inputs[0][:, :sub],) + inputs[1:]
            row["numpy_subset_particles"] = sub
            row["reference_pairs_per_s"] = _rate(lambda: tbd_log_weight_sums_reference(*small), sub * m, 1)
            row["naive_pairs_per_s"] = _rate(lambda: naive_log_weight_sums(*small), sub * m, 1)
            best = max(row[f"{be}_pairs_per_s"] for be in backends)
            for be in backends:
                row[f"{be}_vs_naive"] = row[f"{be}_pairs_per_s"] / row["naive_pairs_per_s"]
                row[f"{be}_vs_reference"] = row[f"{be}_pairs_per_s"] / row["reference_pairs_per_s"]
                row[f"{be}_percent_of_limit"] = 100.0 * row[f"{be}_pairs_per_s"] / limit
            row["best_percent_of_issue_limit"] = 100.0 * best / ISSUE_LIMIT_PAIRS_PER_S
            rows.append(row)
    target = next((r for r in rows if r["N"] == 100_000 and r["M"] == 1_000), None)
    summary = {}
    if target is not None:
        best_be = max(backends, key=lambda be: target[f"{be}_pairs_per_s"])
        summary = {"backend": best_be, "pairs_per_s": target[f"{best_be}_pairs_per_s"],
                   "vs_naive": target[f"{best_be}_vs_naive"], "percent_of_limit": target[f"{best_be}_percent_of_limit"],
                   "goal_vs_naive": 50.0, "goal_percent_of_limit": 40.0,
                   "met": bool(target[f"{best_be}_vs_naive"] >= 50.0 and target[f"{best_be}_percent_of_limit"] >= 40.0)}
    return {
        "cores": os.cpu_count(),
        "backends": backends,
        "machine": {**machine, "flops_per_pair": FLOPS_PER_PAIR, "limit_pairs_per_s": limit,
                    "issue_limit_pairs_per_s": ISSUE_LIMIT_PAIRS_PER_S},
        "kernel": rows,
        "target_N1e5_M1e3": summary,
        "scenario": scenario_run(20_000 if quick else 100_000),
    }


if __name__ == "__main__":  # pragma: no cover - manual use
    import json
    import sys

    print(json.dumps(bench(quick="--quick" in sys.argv), indent=1, default=float))
