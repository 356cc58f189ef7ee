"""Benchmark group ``crpf-step``: the CRPF's fused step kernel (:func:`.crpf_step.crpf_step`) per particle.

:func:`crpf_step_cost` times one fused step per particle (the kernel only, medians of repeated warm calls) for two
configurations of the same kernel: the previous one (fixed variance, plain norm, absolute delta = 0.01) and paper
003's (Table 6: adaptive variance, arc-length cost, relative delta), at N = 100, 300, 500 particles with
``budget / N`` runs per call (the batches of paper 003's Monte Carlo), on a 2-D random-walk-velocity target
(``q = 0.1``) measured in range and bearing.  Target: the paper step at most :data:`STEP_TARGET_RATIO` times the
previous one per particle, judged on one thread (the two-thread figures are printed beside).  The group lives with
the filter whose kernel it times; ``scripts/gpu_check_compare.py crpf-step`` runs the same function with the
kernels on another arch.
"""

from __future__ import annotations

import os
import time

import numpy as np

from workbench.models import random_walk_velocity

from .crpf_step import crpf_step, resolve_backend

__all__ = ["STEP_PARTICLES", "STEP_TARGET_RATIO", "crpf_step_cost", "bench"]

#: The particle counts timed (the ``crpf-100``, ``crpf-300`` and ``crpf-500`` filters of paper 003).
STEP_PARTICLES = (100, 300, 500)
#: The target for the paper CRPF step's cost per particle against the previous step's.
STEP_TARGET_RATIO = 1.2


def _step_times(budget: int, repeat: int, seed: int) -> dict:
    """Median ns per particle of the two configurations at N = 100, 300, 500 (interleaved warm calls)."""
    F = random_walk_velocity(2, 1.0, 0.1).F
    rng = np.random.default_rng(seed)
    out = {}
    for N in STEP_PARTICLES:
        B = max(1, budget // N)
        x = np.array([100.0, 50.0, -1.0, 1.0]) + rng.normal(size=(B, N, 4)) * [1.0, 1.0, 0.2, 0.2]
        c = rng.exponential(2.0, (B, N))
        z = np.stack([np.full(B, 111.0), np.full(B, 0.46)], axis=1)
        u0 = rng.random(B)
        t = np.full(B, 5.0)
        configs = {
            "previous": dict(s2=np.full((B, N), 1.0 / N ** 0.5), shape=np.array([0.5, 0.5, 1.0, 1.0]), delta=0.01,
                             arc=False, adaptive=False, relative=False),
            "paper": dict(s2=np.full((B, N), 0.09), shape=np.ones(4), delta=0.1, arc=True, adaptive=True,
                          relative=True),
        }

        def call(cfg, key):
            crpf_step(x, c, cfg["s2"], t, F, z, key, u0, cfg["shape"], 0.95, 2.0, cfg["delta"], 2.0, cfg["arc"],
                      (0.0, 0.0), cfg["adaptive"], cfg["relative"])

        times = {k: [] for k in configs}
        for cfg in configs.values():
            call(cfg, 0)  # warm-up: loads the compiled kernel
        for r in range(repeat):
            for k, cfg in configs.items():
                t0 = time.perf_counter()
                call(cfg, r + 1)
                times[k].append(time.perf_counter() - t0)
        out[N] = {k: 1e9 * float(np.median(v)) / (B * N) for k, v in times.items()}
    return out


def crpf_step_cost(repeat: int = 15, seed: int = 0, budget: int = 131072) -> dict:
    """Nanoseconds per particle of one fused CRPF step (the kernel only), for the previous configuration (fixed
    variance, plain norm, absolute delta = 0.01) and the paper configuration (adaptive variance, arc-length cost,
    relative delta), at N = 100, 300, 500 with ``budget / N`` runs per call (the Monte Carlo's batches); each the
    median of ``repeat`` warm calls, the two configurations interleaved so that both see the same machine load.

    The target is judged on one thread: the step's own work per particle.  With two threads on a shared machine a
    parallel region waits at its barrier for a thread the scheduler has put aside, which adds the same stall to
    both configurations and hides the difference; the two-thread figures are printed beside, for information."""
    load = os.getloadavg()[0]
    out = {"step_backend": resolve_backend("auto"), "step_load_average_1min": load}
    threads = None
    if out["step_backend"] == "numba":
        import numba

        threads = numba.get_num_threads()
        numba.set_num_threads(1)
    try:
        one = _step_times(budget, repeat, seed)
    finally:
        if threads is not None:
            numba.set_num_threads(threads)
    many = _step_times(budget, repeat, seed + 1) if threads and threads > 1 else None
    ratios = []
    for N in STEP_PARTICLES:
        prev, paper = one[N]["previous"], one[N]["paper"]
        out[f"step_ns_per_particle[previous, N={N}]"] = prev
        out[f"step_ns_per_particle[paper, N={N}]"] = paper
        ratios.append(paper / prev)
        out[f"step_ratio_paper_over_previous[N={N}]"] = ratios[-1]
        if many is not None:
            out[f"step_ns_per_particle_{threads}_threads[previous, N={N}]"] = many[N]["previous"]
            out[f"step_ns_per_particle_{threads}_threads[paper, N={N}]"] = many[N]["paper"]
    out.update({"target_crpf_step_ratio": f"<= {STEP_TARGET_RATIO:g}", "measured_crpf_step_ratio": max(ratios),
                "met_crpf_step_ratio": bool(max(ratios) <= STEP_TARGET_RATIO),
                "note_crpf_step_ratio": (f"paper step (adaptive variance, arc-length cost, relative delta) over the "
                                         f"previous step per particle, one thread, the largest over N = 100, 300, "
                                         f"500; medians of {repeat} interleaved warm calls; 1-min load average "
                                         f"{load:.2f}")})
    return out


def bench(quick: bool = False, *, seed: int = 0) -> dict:
    """The step cost per particle (:func:`crpf_step_cost`), with fewer repeats in ``quick`` mode."""
    return crpf_step_cost(repeat=5 if quick else 15, seed=seed)
