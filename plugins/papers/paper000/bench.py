"""Speed of paper 000's method-C weights and of a whole method-C scenario (a benchmark, not a test).

:func:`bench` measures, in one run:

- the throughput (particle-measurement pairs per second) of the weight kernel
  :func:`workbench.kernels.tbd_weights.tbd_log_weight_sums` for N = 10^3..10^6 particles and
  M = 10..10^3 measurements, per backend (on the CPU: Taichi and Numba when installed; on a GPU arch,
  ``workbench bench --arch cuda``: Taichi there) and per precision (float64, float32), against the
  chunked NumPy reference and a naive NumPy broadcast (the whole (N, M) array at once), as ratios
  (:func:`kernel_throughput`);
- an estimate of the machine limit for this kernel: the measured peak double-precision rate
  divided by the kernel's essential arithmetic per pair (:data:`FLOPS_PER_PAIR`), and each backend's
  share of it (:func:`peak_flops` on the CPU; :func:`taichi_peak_flops` on a GPU arch);
- the targets, at N = 10^5 and M = 10^3 on the policy's backend for the arch (Numba on the CPU):
  float64 at >= 50 % of the limit, float32 at >= 2.5x the float64 throughput, and >= 50x the naive
  broadcast (an earlier target); ``curves``: the throughput against N and against M, beside the NumPy
  reference and the naive broadcast (the peers) and the float64 limit;
- a whole 300-scan method-C scenario with N = 10^5 particles, a 2.5 km gate and the 3 dB threshold
  (target: under 30 s);
- the memory of one method-C update (kernel sum, amplitude-aware floor, normalising, resampling) with N = 10^5
  particles and M = 10^3 detections, against the ``(B, N, M)`` float64 array a naive evaluation holds (target: at
  most 5 % of it: the weights stay ``O(B N + M)``; :func:`weights_memory`);
- the whole paper-000 report at the benchmark's size (full: the paper's protocol at three reference RCS values, its
  replications and the N sweep; target: under 3 minutes on 2 cores), in this process into a temporary folder without
  a cache, with the machine's load average before and after (:func:`report_time`).

NumPy timings on more than :data:`NUMPY_PAIR_CAP` pairs are taken on a slice of the particles (the
rate per pair does not depend on N at these sizes); the result says so.  Kernel rates are the best of
``repeats`` timed calls after a warm-up call (compilation, caches).
"""

from __future__ import annotations

import os
import time

import numpy as np

from workbench.kernels.backend import current_arch, numba_available, resolve
from workbench.kernels.reference import kernel_inputs, naive_log_weight_sums, tbd_log_weight_sums_reference
from workbench.kernels.tbd_weights import PRECISIONS, tbd_log_weight_sums

__all__ = ["FLOPS_PER_PAIR", "NUMPY_PAIR_CAP", "LIMIT_TARGET_PERCENT", "FLOAT32_TARGET", "NAIVE_TARGET", "bench",
           "naive_log_weight_sums", "peak_flops", "taichi_peak_flops", "kernel_inputs", "kernel_throughput",
           "kernel_targets", "kernel_curves", "paired_target_rates", "scenario_run", "weights_memory", "report_time"]

#: Essential double-precision operations per (particle, measurement) pair, FMA counted as 2: residuals
#: 4, squared distance 5, Doppler term and log-weight 5, exp (range reduction 6, degree-11 Horner 22,
#: scaling 1) 29, accumulation 1 -> 44.  The yardstick of the limit; the float64 kernel itself now spends
#: fewer (its log-weight is five multiply-adds and its exponential needs no range-reduction multiplies,
#: :mod:`workbench.kernels.tbd_weights_numpy`), which the share of the limit does not correct for.
FLOPS_PER_PAIR = 44
#: The issue's rough figure for the machine limit, pairs/s in float64 on 2 cores (for comparison).
ISSUE_LIMIT_PAIRS_PER_S = 3e9
NUMPY_PAIR_CAP = 10_000_000
#: The kernel targets at N = 10^5, M = 10^3: float64 share of the limit (%), float32 / float64 throughput, and
#: the float64 kernel / the naive NumPy broadcast.
LIMIT_TARGET_PERCENT = 50.0
FLOAT32_TARGET = 2.5
NAIVE_TARGET = 50.0
TARGET_SIZE = (100_000, 1_000)


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


def taichi_peak_flops(arch: str | None = None, repeats: int = 3, elements: int = 1 << 20, rounds: int = 500) -> dict:
    """Measured peak float64 rate of the device Taichi runs on (FLOP/s, FMA = 2): eight independent FMA chains
    per element in registers, one element per parallel iteration.  The limit's peak on a GPU arch, where
    ``dgemm`` on the host says nothing about the device."""
    from workbench.kernels.runtime import ensure_taichi

    ensure_taichi(current_arch() if arch is None else arch)
    import taichi as ti

    def fma_loop(x, y, rounds):
        for i in x:
            v = x[i]
            a0, a1, a2, a3, a4, a5, a6, a7 = v, v, v, v, v, v, v, v
            for _ in range(rounds):
                a0 = a0 * ti.f64(0.999999) + ti.f64(1e-7)
                a1 = a1 * ti.f64(0.999998) + ti.f64(2e-7)
                a2 = a2 * ti.f64(0.999997) + ti.f64(3e-7)
                a3 = a3 * ti.f64(0.999996) + ti.f64(4e-7)
                a4 = a4 * ti.f64(0.999995) + ti.f64(5e-7)
                a5 = a5 * ti.f64(0.999994) + ti.f64(6e-7)
                a6 = a6 * ti.f64(0.999993) + ti.f64(7e-7)
                a7 = a7 * ti.f64(0.999992) + ti.f64(8e-7)
            y[i] = a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7

    # annotations as objects (this module's are strings, under ``from __future__ import annotations``)
    fma_loop.__annotations__ = {"x": ti.types.ndarray(dtype=ti.f64, ndim=1), "y": ti.types.ndarray(dtype=ti.f64, ndim=1),
                                "rounds": ti.i32}
    fma_loop = ti.kernel(fma_loop)
    x = np.random.default_rng(1).random(elements)
    y = np.empty_like(x)

    def run():
        fma_loop(x, y, rounds)
        ti.sync()

    seconds = _best_time(run, repeats)
    flops = 2.0 * 8 * rounds * elements / seconds
    return {"taichi_fma_loop_flops": flops, "peak_flops": flops}


def _rate(fn, pairs: int, repeats: int) -> float:
    return pairs / _best_time(fn, repeats)


#: Seconds to wait after a BLAS product before the next timed call: OpenBLAS's worker threads keep spinning for a
#: while after a product returns and take the cores from whatever runs next (the float64 kernel measured 1.0e9
#: pairs/s right after the 1500 x 1500 dgemm, 1.4-1.5e9 after a pause or after another kernel call).
BLAS_SETTLE_S = 0.2


def _interleaved_best(fns: dict, repeats: int, settle_after=()) -> dict:
    """Best wall time of each callable over ``repeats`` rounds, one call of each per round in turn after one
    warm-up call each: a load that drifts during the measurement reaches every callable alike.  After the calls
    named in ``settle_after`` (BLAS products) the next call waits :data:`BLAS_SETTLE_S`, untimed."""
    for fn in fns.values():
        fn()
    best = dict.fromkeys(fns, np.inf)
    for _ in range(repeats):
        for key, fn in fns.items():
            start = time.perf_counter()
            fn()
            best[key] = min(best[key], time.perf_counter() - start)
            if key in settle_after:
                time.sleep(BLAS_SETTLE_S)
    return best


def _key(backend: str, precision: str) -> str:
    return backend if precision == "float64" else f"{backend}_{precision}"


def kernel_throughput(sizes_n, sizes_m, backends, limit: float, repeats: int = 3,
                      precisions=PRECISIONS, numpy_cap: int = NUMPY_PAIR_CAP) -> list[dict]:
    """One row per ``(N, M)``: pairs/s of every backend in every precision (``<backend>_pairs_per_s`` for float64,
    ``<backend>_float32_pairs_per_s``; their calls interleaved, :func:`_interleaved_best`), of the NumPy reference
    and of the naive broadcast (on at most ``numpy_cap`` pairs), and each backend's ratios to them and share of
    ``limit`` (pairs/s)."""
    rows = []
    for n in sizes_n:
        for m in sizes_m:
            inputs = kernel_inputs(n, m)
            pairs = n * m
            row = {"N": n, "M": m}
            fns = {_key(be, pr): (lambda be=be, pr=pr: tbd_log_weight_sums(*inputs, backend=be, precision=pr))
                   for be in backends for pr in precisions}
            for k, t in _interleaved_best(fns, repeats).items():
                row[f"{k}_pairs_per_s"] = pairs / t
            sub = max(1, min(n, numpy_cap // m))
            small = (inputs[0][:, :sub],) + inputs[1:]
            row["numpy_subset_particles"] = sub
            row["reference_pairs_per_s"] = _rate(lambda: tbd_log_weight_sums_reference(*small), sub * m, 1)
            row["naive_pairs_per_s"] = _rate(lambda: naive_log_weight_sums(*small), sub * m, 1)
            for be in backends:
                for pr in precisions:
                    k = _key(be, pr)
                    row[f"{k}_vs_naive"] = row[f"{k}_pairs_per_s"] / row["naive_pairs_per_s"]
                    row[f"{k}_vs_reference"] = row[f"{k}_pairs_per_s"] / row["reference_pairs_per_s"]
                    row[f"{k}_percent_of_limit"] = 100.0 * row[f"{k}_pairs_per_s"] / limit
                if "float32" in precisions and "float64" in precisions:
                    row[f"{be}_float32_over_float64"] = row[f"{be}_float32_pairs_per_s"] / row[f"{be}_pairs_per_s"]
            rows.append(row)
    return rows


def paired_target_rates(backend: str, repeats: int = 7, size=None) -> dict:
    """The target case measured for the targets: ``backend``'s float64 and float32 calls and the peak-rate
    measurement (BLAS ``dgemm`` of 1500 x 1500 on the CPU arch) timed in turn, ``repeats`` rounds, best of each, so
    that the share of the limit and the float32 / float64 ratio compare timings taken under the same load (with a
    pause after each product, :data:`BLAS_SETTLE_S`, so that BLAS's spinning threads do not slow the next call)."""
    n, m = size or TARGET_SIZE
    inputs = kernel_inputs(n, m)
    a, b = np.random.default_rng(0).random((2, 1500, 1500))
    fns = {"float64": lambda: tbd_log_weight_sums(*inputs, backend=backend, precision="float64"),
           "float32": lambda: tbd_log_weight_sums(*inputs, backend=backend, precision="float32"),
           "dgemm": lambda: a @ b}
    best = _interleaved_best(fns, repeats, settle_after=("dgemm",))
    out = {"N": n, "M": m, "backend": backend, "rounds": repeats,
           "float64_pairs_per_s": n * m / best["float64"], "float32_pairs_per_s": n * m / best["float32"],
           "dgemm_flops": 2.0 * 1500**3 / best["dgemm"]}
    out["limit_pairs_per_s"] = out["dgemm_flops"] / FLOPS_PER_PAIR
    return out


def kernel_targets(rows: list[dict], backend: str, paired: dict | None = None) -> dict:
    """The kernel's targets (:mod:`workbench.bench.targets`) at N = 10^5, M = 10^3 on ``backend``: float64 share of
    the limit and float32 over float64 (from ``paired``, :func:`paired_target_rates`, where given, else from the
    row), float64 over the naive broadcast (from the row)."""
    row = next((r for r in rows if (r["N"], r["M"]) == TARGET_SIZE), None)
    if row is None or f"{backend}_pairs_per_s" not in row:
        return {}
    if paired is not None:
        percent = 100.0 * paired["float64_pairs_per_s"] / paired["limit_pairs_per_s"]
        ratio = paired["float32_pairs_per_s"] / paired["float64_pairs_per_s"]
        how = f"{backend}, N = 10^5, M = 10^3, timed in turn with the peak-rate dgemm ({paired['rounds']} rounds)"
    else:
        percent = row[f"{backend}_percent_of_limit"]
        ratio = row.get(f"{backend}_float32_over_float64")
        how = f"{backend}, N = 10^5, M = 10^3"
    out = {"backend": backend, "pairs_per_s": row[f"{backend}_pairs_per_s"]}
    out["target_float64_percent_of_limit"] = f">= {LIMIT_TARGET_PERCENT:g}"
    out["measured_float64_percent_of_limit"] = percent
    out["met_float64_percent_of_limit"] = bool(percent >= LIMIT_TARGET_PERCENT)
    out["note_float64_percent_of_limit"] = f"{how}; limit = peak FLOP/s / {FLOPS_PER_PAIR} flops per pair"
    if ratio is not None:
        out["target_float32_over_float64"] = f">= {FLOAT32_TARGET:g}"
        out["measured_float32_over_float64"] = ratio
        out["met_float32_over_float64"] = bool(ratio >= FLOAT32_TARGET)
    out["target_float64_vs_naive"] = f">= {NAIVE_TARGET:g}"
    out["measured_float64_vs_naive"] = row[f"{backend}_vs_naive"]
    out["met_float64_vs_naive"] = bool(row[f"{backend}_vs_naive"] >= NAIVE_TARGET)
    return out


def kernel_curves(rows: list[dict], backends, limit: float, precisions=PRECISIONS) -> list[dict]:
    """Throughput against N (at the largest M) and against M (at N = 10^5, or the largest N), every backend and
    precision beside the NumPy reference, the naive broadcast and the float64 limit."""
    if not rows:
        return []
    figs = []
    m_fix = max(r["M"] for r in rows)
    ns = sorted({r["N"] for r in rows})
    n_fix = 100_000 if 100_000 in ns else max(ns)
    for axis, fixed, label, unit_label in (("N", ("M", m_fix), "particles N", f"M = {m_fix} measurements"),
                                           ("M", ("N", n_fix), "measurements M", f"N = {n_fix} particles")):
        sel = sorted((r for r in rows if r[fixed[0]] == fixed[1]), key=lambda r: r[axis])
        x = [r[axis] for r in sel]
        series = []
        for be in backends:
            for pr in precisions:
                k = f"{_key(be, pr)}_pairs_per_s"
                series.append({"label": f"{be} {pr}", "role": "ours", "x": x, "y": [r[k] for r in sel]})
        series.append({"label": "NumPy reference (chunked, SciPy)", "role": "peer", "x": x,
                       "y": [r["reference_pairs_per_s"] for r in sel]})
        series.append({"label": "naive NumPy broadcast", "role": "reference", "x": x,
                       "y": [r["naive_pairs_per_s"] for r in sel]})
        series.append({"label": f"float64 limit (peak / {FLOPS_PER_PAIR} flops)", "role": "limit", "x": [x[0]],
                       "y": [limit]})
        figs.append({"id": f"kernel_vs_{axis}", "title": f"Method-C weight kernel, {unit_label}",
                     "x_label": label, "x_unit": "", "y_label": "throughput", "y_unit": "pairs/s",
                     "series": series})
    return figs


def scenario_run(particles: int = 100_000, radius: float = 2500.0, threshold_db: float = 3.0, seed: int = 1) -> dict:
    """One 300-scan method-C run (batch of one) through the recipe's scenario; warmed-up wall time of the tracking."""
    from workbench.models import constant_velocity
    from workbench.plugins import load_host
    from workbench.rng import generator
    from workbench.types import Gaussian

    from .methods import PRIOR_SD, SIGMA_A, with_particles
    from .pipeline import estimation_error, run_gated
    from .scenario import DT, scenario_truth, simulate_scans, tracking_model

    host = load_host()
    truth = scenario_truth(1)
    scans = simulate_scans(host, truth, seed, threshold_db)
    spec = with_particles(host.filter("tbd-pf"), particles)
    model = tracking_model(host, threshold_db=threshold_db)
    prior = Gaussian.broadcast(truth.states[0, 0], np.diag(np.square(PRIOR_SD)), 1)
    motion = constant_velocity(3, DT, SIGMA_A)
    run_gated(spec, prior, motion, model, scans.head(3), radius, generator(seed, "bench-warm"))  # compile first
    out = run_gated(spec, prior, motion, model, scans, radius, generator(seed, "bench"), truth=truth.states)
    err = estimation_error(out.mean, truth.states)
    return {"particles": particles, "radius_m": radius, "threshold_db": threshold_db, "scans": truth.steps,
            "gated_per_scan": float(out.gated_count.mean()), "pairs": float(particles * out.gated_count.sum()),
            "mean_error_m": float(err.mean()),
            "target_seconds": "< 30 s", "measured_seconds": out.seconds,
            "note_seconds": "one warmed-up batched call (B = 1) after a 3-scan warm-up"}


def weights_memory(particles: int = 100_000, detections: int = 1_000) -> dict:
    """Peak traced memory of one method-C update (kernel sum, amplitude floor, normalising, resampling) against
    the ``(B, N, M)`` float64 array of a naive evaluation."""
    import tracemalloc

    from workbench.plugins import load_host
    from workbench.rng import generator
    from workbench.types import Gaussian, Scan

    from .scenario import tracking_model

    host = load_host()
    model = tracking_model(host)
    spec = host.filter("tbd-pf").configure(particles=particles)
    rng = np.random.default_rng(0)
    mean = np.array([30e3, 2e3, 2e3, -200.0, 0.0, 0.0])
    state = spec.init(Gaussian(mean[None], np.diag([500.0, 500, 300, 30, 30, 10])[None] ** 2), generator(0, "mem"))
    z = np.concatenate([mean[:3] + rng.normal(size=(1, detections, 3)) * 800,
                        rng.uniform(-300, 300, (1, detections, 1))], axis=2)
    scan = Scan(z, np.ones((1, detections), bool), snr=rng.uniform(5, 12, (1, detections)),
                clutter_density=np.full((1, detections), 3.4e-13))
    spec.update(state, scan, model, generator(1, "mem"))  # compile and warm up
    tracemalloc.start()
    spec.update(state, scan, model, generator(1, "mem"))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    naive = 8.0 * particles * detections
    return {"particles": particles, "detections": detections, "peak_mib": peak / 2**20,
            "naive_array_mib": naive / 2**20, "target_memory_ratio": "<= 0.05", "measured_memory_ratio": peak / naive,
            "note_memory_ratio": "peak traced allocation of one tbd-pf update over the (B, N, M) float64 array a "
                                 "naive evaluation holds"}


def report_time(quick: bool = False) -> dict:
    """The whole paper-000 report (full size unless ``quick``) into a temporary folder, no cache, in this process."""
    import tempfile
    from pathlib import Path

    from workbench.plugins import load_host
    from workbench.report.engine import run_recipe

    host = load_host()
    size = "quick" if quick else "full"
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        outcome = run_recipe(host.recipe("000"), host, Path(tmp), size=size, progress=False)
        seconds = time.perf_counter() - t0
    load_after = os.getloadavg()[0]
    return {"size": size, "tasks": len(outcome.tasks), "errors": len(outcome.errors),
            "load_average_before": load_before, "load_average_after": load_after,
            "target_seconds": "< 180 s", "measured_seconds": seconds,
            "note_seconds": f"workbench report --paper 000 --{size} in one process on {os.cpu_count()} cores, no "
                            f"cache; 1-minute load average {load_before:.1f} before and {load_after:.1f} after (other "
                            "jobs on the machine slow it down)"}


def bench(quick: bool = False) -> dict:
    """Weight-kernel throughput per backend and precision vs NumPy, the machine limit, the targets, the scaling
    curves, and a whole scenario.

    Returns a JSON-serialisable dict: ``kernel`` (one row per (N, M)), ``machine``, ``kernel_targets``, ``curves``,
    ``weights_memory`` (the method-C update's peak memory), ``scenario`` and ``report`` (the whole paper-000 report).
    """
    sizes_n = (1_000, 100_000) if quick else (1_000, 10_000, 100_000, 1_000_000)
    sizes_m = (10, 1_000) if quick else (10, 100, 1_000)
    repeats = 2 if quick else 3
    arch = current_arch()
    if arch == "cpu":
        backends = ["taichi"] + (["numba"] if numba_available() else [])
        machine = peak_flops(repeats)
    else:  # a GPU arch: Taichi there, and the device's own peak
        backends = ["taichi"]
        machine = taichi_peak_flops(arch, repeats)
    limit = machine["peak_flops"] / FLOPS_PER_PAIR
    load = [os.getloadavg()[0]] if hasattr(os, "getloadavg") else [float("nan")]
    rows = kernel_throughput(sizes_n, sizes_m, backends, limit, repeats)
    # the targets' case again, the kernel and the peak-rate measurement timed in turn (CPU arch)
    paired = paired_target_rates(resolve("auto", arch), 3 if quick else 7) if arch == "cpu" else None
    load.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
    return {
        "cores": os.cpu_count(),
        "kernel_arch": arch,
        "backends": backends,
        "load_avg_1min": max(load),
        "machine": {**machine, "flops_per_pair": FLOPS_PER_PAIR, "limit_pairs_per_s": limit,
                    "issue_limit_pairs_per_s": ISSUE_LIMIT_PAIRS_PER_S},
        "kernel": rows,
        "kernel_target_case": paired or {},
        "kernel_targets": kernel_targets(rows, resolve("auto", arch), paired),
        "curves": kernel_curves(rows, backends, limit),
        "weights_memory": weights_memory(20_000 if quick else 100_000),
        "scenario": scenario_run(20_000 if quick else 100_000),
        "report": report_time(quick),
    }


if __name__ == "__main__":  # pragma: no cover - manual use
    import json
    import sys

    print(json.dumps(bench(quick="--quick" in sys.argv), indent=1, default=float))
