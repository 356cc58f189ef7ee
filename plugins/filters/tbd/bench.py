"""Benchmark group ``tbd-weights``: the ``tbd-pf`` filter's weight kernel (paper 000's method C) against its limit.

:func:`bench` measures, in one run:

- the throughput (particle-measurement pairs per second) of the weight kernel
  :func:`workbench_filters.tbd.tbd_weights.tbd_log_weight_sums` for N = 10^3..10^6 particles and
  M = 10..10^3 measurements, per backend (on the CPU: Taichi and Numba when installed; on a GPU arch,
  ``workbench bench --arch cuda``: Taichi there) and per precision (float64, float32), against the
  chunked NumPy reference and a naive NumPy broadcast (the whole (N, M) array at once), as ratios
  (:func:`kernel_throughput`);
- the kernel's compute limit in each precision, a limit that bounds it: the measured peak rate of the instructions
  every pair needs, multiplies and fused multiply-adds (:func:`fma_peak`: a small FMA-throughput kernel, twelve
  independent accumulators per vector lane group, on every thread the kernel uses, beside it in the same run; on a
  GPU arch the same loop in Taichi, :func:`taichi_fma_peak`), divided by the number of them per pair, read from the
  kernel's own source (:func:`multiplies_per_pair`: 18 in float64, 14 in float32).  A multiply or a multiply-add
  runs on the FMA pipes of every x86 CPU (additions may not: AMD's Zen runs them on pipes of their own, so they are
  not counted), and each ``*`` of the source is one such instruction per pair whatever the compiler fuses, so no
  kernel can run faster than the limit.  A measured share above 100 % means the limit is wrong (the peak was
  measured under a load the kernel did not see, or the count no longer matches the kernel): the figure then reads
  ``"limit invalid"``, never a number above 100;
- the targets, at N = 10^5 and M = 10^3 on the policy's backend for the arch (Numba on the CPU): float64 and
  float32 each at >= 60 % of their limit (issue 26), float32 at >= 2.5x the float64 throughput, and >= 50x the
  naive broadcast (an earlier target), the kernel calls and the peak loops timed in turn
  (:func:`paired_target_rates`); ``curves``: the throughput against N and against M, beside the NumPy reference,
  the naive broadcast and the two limits.

NumPy timings on more than :data:`NUMPY_PAIR_CAP` pairs are taken on a slice of the particles (the rate per pair
does not depend on N at these sizes); the result says so.  Kernel rates are the best of ``repeats`` timed calls
after a warm-up call (compilation, caches).  Paper 000's own group (``paper000``) times the whole method-C
scenario, the update's memory and the report.
"""

from __future__ import annotations

import ast
import inspect
import os
import time

import numpy as np

from workbench.kernels.backend import current_arch, numba_available, resolve

from .reference import kernel_inputs, naive_log_weight_sums, tbd_log_weight_sums_reference
from .tbd_weights import PRECISIONS, tbd_log_weight_sums

__all__ = ["NUMPY_PAIR_CAP", "LIMIT_TARGET_PERCENT", "FLOAT32_TARGET", "NAIVE_TARGET", "TARGET_SIZE",
           "PEAK_ACCUMULATORS", "LIMIT_INVALID", "bench", "multiplies_per_pair", "fma_peak", "taichi_fma_peak",
           "share_of_limit", "kernel_throughput", "paired_target_rates", "kernel_targets", "kernel_curves"]

NUMPY_PAIR_CAP = 10_000_000
#: The kernel targets at N = 10^5, M = 10^3: each precision's share of its limit (%), float32 / float64
#: throughput, and the float64 kernel / the naive NumPy broadcast.
LIMIT_TARGET_PERCENT = 60.0
FLOAT32_TARGET = 2.5
NAIVE_TARGET = 50.0
TARGET_SIZE = (100_000, 1_000)
#: Independent FMA chains per thread of the peak loop, each a vector wide: more than an FMA's latency times the
#: FMA pipes on the CPUs here (Zen 2: 5 cycles x 2 pipes; Skylake-SP and later: 4 x 2), few enough to stay in
#: the 16 vector registers of AVX2 (16 chains spilled and ran 23 % slower on a Zen 2).
PEAK_ACCUMULATORS = 12
#: What a share of the limit reads when the measured rate exceeds the limit.
LIMIT_INVALID = "limit invalid"
#: The kernels whose per-pair loop :func:`multiplies_per_pair` reads, per precision.
KERNEL_FUNCTIONS = {"float64": "kernel", "float32": "kernel32"}
#: The function giving one pair's log-weight in each kernel: its call sites in the loop are the pairs per iteration.
PAIR_FUNCTIONS = {"float64": "log2_weight", "float32": "log2_weight32"}


def multiplies_per_pair(precision: str, source: str | None = None) -> int:
    """Multiplications per particle-measurement pair in the Numba kernel of ``precision``, read from its source
    (``source``: the text of :mod:`.tbd_weights_numba` unless given): every ``*`` in the loop over particles that
    sits inside the loop over measurements, and every ``*`` of the module functions that loop calls, at each call
    site, and of those they call (the inlined log-weight, ``2^x`` and sum update), divided by the pairs one
    iteration takes: the call sites of the kernel's pair function (:data:`PAIR_FUNCTIONS`, the log-weight of one
    pair; one where the loop calls none).  Each ``*`` is one multiply or multiply-add instruction per pair (per
    vector lane), the instructions :func:`fma_peak` measures."""
    if source is None:
        from . import tbd_weights_numba

        source = inspect.getsource(tbd_weights_numba)
    tree = ast.parse(source)
    functions = {node.name: node for node in tree.body if isinstance(node, ast.FunctionDef)}
    kernel = functions[KERNEL_FUNCTIONS[precision]]

    def calls(node) -> list[str]:
        return [c.func.id for c in ast.walk(node)
                if isinstance(c, ast.Call) and isinstance(c.func, ast.Name) and c.func.id in functions]

    def multiplies(node, seen=()) -> int:
        own = sum(isinstance(n, ast.BinOp) and isinstance(n.op, ast.Mult) for n in ast.walk(node))
        for name in calls(node):
            if name in seen:
                raise ValueError(f"{kernel.name}: {name} calls itself; cannot count its multiplies")
            own += multiplies(functions[name], seen + (name,))
        return own

    pair_loops = []

    def visit(node, depth):  # loops three deep: tiles (prange), measurements, particles
        for child in ast.iter_child_nodes(node):
            inner = depth + isinstance(child, ast.For)
            if isinstance(child, ast.For) and inner == 3:
                pair_loops.append(child)
            visit(child, inner)

    visit(kernel, 0)
    if len(pair_loops) != 1:
        raise ValueError(f"{kernel.name}: expected one loop over particles inside the loop over measurements, "
                         f"found {len(pair_loops)}")
    (loop,) = pair_loops
    count = sum(multiplies(stmt) for stmt in loop.body)
    pairs = max(1, sum(name == PAIR_FUNCTIONS[precision] for stmt in loop.body for name in calls(stmt)))
    if count % pairs:
        raise ValueError(f"{kernel.name}: {count} multiplies in a loop taking {pairs} pairs per iteration")
    return count // pairs


_PEAK_KERNEL = None


def _peak_kernel():
    """The FMA-throughput loop (compiled once): per thread, :data:`PEAK_ACCUMULATORS` rows of accumulators, the
    loop over a row's elements vectorised at the CPU's full width, eight dependent multiply-adds per element and
    round; the rows' chains are independent, so the FMA pipes, not the latency, set the pace."""
    global _PEAK_KERNEL
    if _PEAK_KERNEL is None:
        import numba

        from workbench.kernels.vector_width import wide_vectors

        @numba.njit(parallel=True, fastmath={"contract"})
        def fma_loop(acc, m, c, rounds):
            for t in numba.prange(acc.shape[0]):
                wide_vectors()
                a = acc[t]
                for _ in range(rounds):
                    for k in range(a.shape[1]):
                        v0, v1, v2, v3 = a[0, k], a[1, k], a[2, k], a[3, k]
                        v4, v5, v6, v7 = a[4, k], a[5, k], a[6, k], a[7, k]
                        v8, v9, v10, v11 = a[8, k], a[9, k], a[10, k], a[11, k]
                        for _ in range(8):
                            v0 = v0 * m + c
                            v1 = v1 * m + c
                            v2 = v2 * m + c
                            v3 = v3 * m + c
                            v4 = v4 * m + c
                            v5 = v5 * m + c
                            v6 = v6 * m + c
                            v7 = v7 * m + c
                            v8 = v8 * m + c
                            v9 = v9 * m + c
                            v10 = v10 * m + c
                            v11 = v11 * m + c
                        a[0, k], a[1, k], a[2, k], a[3, k] = v0, v1, v2, v3
                        a[4, k], a[5, k], a[6, k], a[7, k] = v4, v5, v6, v7
                        a[8, k], a[9, k], a[10, k], a[11, k] = v8, v9, v10, v11

        _PEAK_KERNEL = fma_loop
    return _PEAK_KERNEL


def _fma_runner(precision: str, threads: int | None = None, lanes: int = 256, rounds: int = 400):
    """``(run, fmas)``: a call of the peak loop on ``threads`` rows (default: Numba's thread count, the threads the
    kernel uses) and the multiply-adds (per lane) it executes."""
    import numba

    threads = numba.get_num_threads() if threads is None else threads
    dtype = np.dtype(precision).type
    acc = np.ones((threads, PEAK_ACCUMULATORS, lanes), dtype)
    m, c = dtype(0.999999), dtype(1e-7)
    loop = _peak_kernel()
    return (lambda: loop(acc, m, c, rounds)), threads * PEAK_ACCUMULATORS * lanes * 8 * rounds


def fma_peak(precision: str = "float64", repeats: int = 20, threads: int | None = None) -> float:
    """Measured peak multiply-add rate of this CPU (per second, counted per vector lane: one 8-wide float64 FMA is
    8) in ``precision``, on ``threads`` threads: the best of ``repeats`` short calls of the peak loop."""
    run, fmas = _fma_runner(precision, threads)
    return fmas / _best_time(run, repeats)


def taichi_fma_peak(precision: str = "float64", arch: str | None = None, repeats: int = 3, elements: int = 1 << 20,
                    rounds: int = 4096) -> float:
    """Measured peak multiply-add rate (per second) of the device Taichi runs on, in ``precision``: eight
    independent FMA chains per element in registers, one element per parallel iteration, the elements in Taichi
    ndarrays that stay on the device (no copy in the timed calls).  The limit's peak on a GPU arch, where the host
    CPU says nothing about the device.  (With NumPy arrays, each call copied them to the GPU and back, which took
    longer than the 500 rounds of arithmetic it then ran: on an H100 the peak read 4 % of the device's and the
    method-C kernel ran above its "limit"; and an affine step read twice the device's, see the loop.)"""
    from workbench.kernels.runtime import ensure_taichi

    ensure_taichi(current_arch() if arch is None else arch)
    import taichi as ti

    real = ti.f64 if precision == "float64" else ti.f32

    def fma_loop(x, y, rounds):
        for i in x:
            v = x[i]
            a0, a1, a2, a3, a4, a5, a6, a7 = v, v, v, v, v, v, v, v
            # a <- a^2 + c: one multiply-add per step that no reassociation can merge across steps (an affine
            # a <- a c + d can be: two steps are a c^2 + (c d + d), so fast-math code may run half the steps and
            # the rate read twice the device's); with c in [-0.6, -0.4] and |a| < 1 it stays in [-0.6, 0.4]
            for _ in range(rounds):
                a0 = a0 * a0 + real(-0.40)
                a1 = a1 * a1 + real(-0.43)
                a2 = a2 * a2 + real(-0.46)
                a3 = a3 * a3 + real(-0.49)
                a4 = a4 * a4 + real(-0.52)
                a5 = a5 * a5 + real(-0.55)
                a6 = a6 * a6 + real(-0.58)
                a7 = a7 * a7 + real(-0.60)
            y[i] = a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7

    # annotations as objects (this module's are strings, under ``from __future__ import annotations``)
    fma_loop.__annotations__ = {"x": ti.types.ndarray(dtype=real, ndim=1), "y": ti.types.ndarray(dtype=real, ndim=1),
                                "rounds": ti.i32}
    fma_loop = ti.kernel(fma_loop)
    x = ti.ndarray(real, shape=elements)
    x.from_numpy(np.random.default_rng(1).random(elements).astype(precision))
    y = ti.ndarray(real, shape=elements)

    def run():
        fma_loop(x, y, rounds)
        ti.sync()

    return 8.0 * rounds * elements / _best_time(run, repeats)


def share_of_limit(rate: float, limit: float):
    """``rate`` as a percentage of ``limit``, or :data:`LIMIT_INVALID` where it exceeds 100 % (a limit the
    measured rate beats does not bound it; nothing is clipped)."""
    percent = 100.0 * rate / limit
    return percent if percent <= 100.0 else LIMIT_INVALID


def _best_time(fn, repeats: int) -> float:
    fn()  # warm-up (compilation, caches)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def _rate(fn, pairs: int, repeats: int) -> float:
    return pairs / _best_time(fn, repeats)


def _interleaved_best(fns: dict, repeats: int) -> dict:
    """Best wall time of each callable over ``repeats`` rounds, one call of each per round in turn after one
    warm-up call each: a load that drifts during the measurement reaches every callable alike.  A callable that
    returns a float has timed itself (the peak loops: the best of several short calls); that number counts."""
    for fn in fns.values():
        fn()
    best = dict.fromkeys(fns, np.inf)
    for _ in range(repeats):
        for key, fn in fns.items():
            start = time.perf_counter()
            own = fn()
            seconds = own if isinstance(own, float) else time.perf_counter() - start
            best[key] = min(best[key], seconds)
    return best


def _key(backend: str, precision: str) -> str:
    return backend if precision == "float64" else f"{backend}_{precision}"


def kernel_throughput(sizes_n, sizes_m, backends, limits: dict, repeats: int = 3,
                      precisions=PRECISIONS, numpy_cap: int = NUMPY_PAIR_CAP) -> list[dict]:
    """One row per ``(N, M)``: pairs/s of every backend in every precision (``<backend>_pairs_per_s`` for float64,
    ``<backend>_float32_pairs_per_s``; their calls interleaved, :func:`_interleaved_best`), of the NumPy reference
    and of the naive broadcast (on at most ``numpy_cap`` pairs), and each backend's ratios to them and share of
    its precision's limit (``limits``: precision -> pairs/s; :func:`share_of_limit`)."""
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
                    row[f"{k}_percent_of_limit"] = share_of_limit(row[f"{k}_pairs_per_s"], limits[pr])
                if "float32" in precisions and "float64" in precisions:
                    row[f"{be}_float32_over_float64"] = row[f"{be}_float32_pairs_per_s"] / row[f"{be}_pairs_per_s"]
            rows.append(row)
    return rows


def paired_target_rates(backend: str, repeats: int = 7, size=None, peak_repeats: int = 10) -> dict:
    """The target case measured for the targets: ``backend``'s float64 and float32 calls and the peak loop in each
    precision (:func:`fma_peak`'s loop, on the kernel's threads, the best of ``peak_repeats`` short calls per
    round) timed in turn, ``repeats`` rounds, best of each, so that each share of the limit compares timings taken
    under the same load.  The limits are the peaks over :func:`multiplies_per_pair`."""
    n, m = size or TARGET_SIZE
    inputs = kernel_inputs(n, m)
    peaks = {pr: _fma_runner(pr) for pr in PRECISIONS}

    def peak_call(run):
        def call():  # the best of several short calls (its own time, see _interleaved_best)
            best = float("inf")
            for _ in range(peak_repeats):
                start = time.perf_counter()
                run()
                best = min(best, time.perf_counter() - start)
            return best
        return call

    fns = {"float64": lambda: tbd_log_weight_sums(*inputs, backend=backend, precision="float64"),
           "float32": lambda: tbd_log_weight_sums(*inputs, backend=backend, precision="float32"),
           **{f"peak_{pr}": peak_call(run) for pr, (run, _) in peaks.items()}}
    best = _interleaved_best(fns, repeats)
    out = {"N": n, "M": m, "backend": backend, "rounds": repeats}
    for pr in PRECISIONS:
        fmas = peaks[pr][1]
        out[f"{pr}_pairs_per_s"] = n * m / best[pr]
        out[f"{pr}_fma_per_s"] = fmas / best[f"peak_{pr}"]
        out[f"{pr}_multiplies_per_pair"] = multiplies_per_pair(pr)
        out[f"{pr}_limit_pairs_per_s"] = out[f"{pr}_fma_per_s"] / out[f"{pr}_multiplies_per_pair"]
    return out


def kernel_targets(rows: list[dict], backend: str, paired: dict | None = None) -> dict:
    """The kernel's targets (:mod:`workbench.bench.targets`) at N = 10^5, M = 10^3 on ``backend``: each precision's
    share of its limit and float32 over float64 (from ``paired``, :func:`paired_target_rates`, where given, else
    from the row), float64 over the naive broadcast (from the row).  A share above 100 % is reported as
    :data:`LIMIT_INVALID` (measured and verdict), never as a number."""
    row = next((r for r in rows if (r["N"], r["M"]) == TARGET_SIZE), None)
    if row is None or f"{backend}_pairs_per_s" not in row:
        return {}
    if paired is not None:
        percents = {pr: share_of_limit(paired[f"{pr}_pairs_per_s"], paired[f"{pr}_limit_pairs_per_s"])
                    for pr in PRECISIONS}
        ratio = paired["float32_pairs_per_s"] / paired["float64_pairs_per_s"]
        how = (f"{backend}, N = 10^5, M = 10^3, timed in turn with the FMA peak loop ({paired['rounds']} rounds); "
               f"limit = peak multiply-adds/s / ")
        counts = {pr: paired[f"{pr}_multiplies_per_pair"] for pr in PRECISIONS}
    else:
        percents = {pr: row.get(f"{_key(backend, pr)}_percent_of_limit") for pr in PRECISIONS}
        ratio = row.get(f"{backend}_float32_over_float64")
        how = f"{backend}, N = 10^5, M = 10^3; limit = peak multiply-adds/s / "
        counts = {pr: multiplies_per_pair(pr) for pr in PRECISIONS}
    out = {"backend": backend, "pairs_per_s": row[f"{backend}_pairs_per_s"]}
    for pr, percent in percents.items():
        if percent is None:
            continue
        name = f"{pr}_percent_of_limit"
        out[f"target_{name}"] = f">= {LIMIT_TARGET_PERCENT:g}"
        out[f"measured_{name}"] = percent
        out[f"met_{name}"] = LIMIT_INVALID if percent == LIMIT_INVALID else bool(percent >= LIMIT_TARGET_PERCENT)
        out[f"note_{name}"] = how + f"{counts[pr]} multiplies per pair ({pr} kernel)"
    if ratio is not None:
        out["target_float32_over_float64"] = f">= {FLOAT32_TARGET:g}"
        out["measured_float32_over_float64"] = ratio
        out["met_float32_over_float64"] = bool(ratio >= FLOAT32_TARGET)
    out["target_float64_vs_naive"] = f">= {NAIVE_TARGET:g}"
    out["measured_float64_vs_naive"] = row[f"{backend}_vs_naive"]
    out["met_float64_vs_naive"] = bool(row[f"{backend}_vs_naive"] >= NAIVE_TARGET)
    return out


def kernel_curves(rows: list[dict], backends, limits: dict, precisions=PRECISIONS) -> list[dict]:
    """Throughput against N (at the largest M) and against M (at N = 10^5, or the largest N), every backend and
    precision beside the NumPy reference, the naive broadcast and each precision's limit."""
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
        for pr in precisions:
            series.append({"label": f"{pr} limit (FMA peak / {multiplies_per_pair(pr)} multiplies)", "role": "limit",
                           "x": [x[0]], "y": [limits[pr]]})
        figs.append({"id": f"kernel_vs_{axis}", "title": f"Method-C weight kernel, {unit_label}",
                     "x_label": label, "x_unit": "", "y_label": "throughput", "y_unit": "pairs/s",
                     "series": series})
    return figs


def bench(quick: bool = False) -> dict:
    """Weight-kernel throughput per backend and precision vs NumPy, the limits, the targets and the scaling curves.

    Returns a JSON-serialisable dict: ``kernel`` (one row per (N, M)), ``machine`` (the peaks, the multiplies per
    pair, the limits), ``kernel_target_case`` (the targets' case timed in turn with the peak loops, CPU arch),
    ``kernel_targets`` and ``curves``.
    """
    sizes_n = (1_000, 100_000) if quick else (1_000, 10_000, 100_000, 1_000_000)
    sizes_m = (10, 1_000) if quick else (10, 100, 1_000)
    repeats = 2 if quick else 3
    arch = current_arch()
    counts = {pr: multiplies_per_pair(pr) for pr in PRECISIONS}
    if arch == "cpu":
        backends = ["taichi"] + (["numba"] if numba_available() else [])
        peaks = {pr: fma_peak(pr) for pr in PRECISIONS} if numba_available() else {}
        source = "Numba FMA loop on the kernel's threads"
    else:  # a GPU arch: Taichi there, and the device's own peak
        backends = ["taichi"]
        peaks = {pr: taichi_fma_peak(pr, arch, repeats) for pr in PRECISIONS}
        source = f"Taichi FMA loop on {arch}"
    if not peaks:
        return {"kernel_arch": arch, "backends": backends, "kernel_targets": {},
                "note": "no limit without Numba on the CPU arch (the peak loop is a Numba kernel)"}
    limits = {pr: peaks[pr] / counts[pr] for pr in PRECISIONS}
    load = [os.getloadavg()[0]] if hasattr(os, "getloadavg") else [float("nan")]
    rows = kernel_throughput(sizes_n, sizes_m, backends, limits, repeats)
    # the targets' case again, the kernel and the peak loops timed in turn (CPU arch)
    paired = paired_target_rates(resolve("auto", arch), 3 if quick else 7) if arch == "cpu" else None
    load.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
    machine = {"peak_source": source, "load_avg_1min": max(load)}
    for pr in PRECISIONS:
        machine.update({f"{pr}_fma_per_s": peaks[pr], f"{pr}_multiplies_per_pair": counts[pr],
                        f"{pr}_limit_pairs_per_s": limits[pr]})
    return {
        "cores": os.cpu_count(),
        "kernel_arch": arch,
        "backends": backends,
        "load_avg_1min": max(load),
        "machine": machine,
        "kernel": rows,
        "kernel_target_case": paired or {},
        "kernel_targets": kernel_targets(rows, resolve("auto", arch), paired),
        "curves": kernel_curves(rows, backends, limits),
    }
