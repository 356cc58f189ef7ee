"""Speed of paper 000's method C as a whole: a whole method-C scenario, one update's memory and the report (a
benchmark, not a test).

:func:`bench` measures, in one run:

- a whole 300-scan method-C scenario with N = 10^5 particles, a 2.5 km gate and the 3 dB threshold
  (target: under 30 s);
- the memory of one method-C update (kernel sum, amplitude-aware floor, normalising, resampling) with N = 10^5
  particles and M = 10^3 detections, against the ``(B, N, M)`` float64 array a naive evaluation holds (target: at
  most 5 % of it: the weights stay ``O(B N + M)``; :func:`weights_memory`);
- the whole paper-000 report at the benchmark's size (full: the paper's protocol at the primary values, the judged
  rows across the declared unknowns' grid, the calibration on a tuning seed, the replications and the N sweep;
  target: under 3 minutes on 2 cores), in this process into a temporary folder without
  a cache, with the machine's load average before and after (:func:`report_time`).

The method-C weight kernel itself (throughput per backend and precision, its limit and its targets) is the ``tbd-pf``
filter's own benchmark group, ``tbd-weights`` (:mod:`workbench_filters.tbd.bench`): the kernel lives with the filter
that runs it, and this package reaches that filter only through the plugin host.
"""

from __future__ import annotations

import os
import time

import numpy as np

__all__ = ["bench", "scenario_run", "weights_memory", "report_time"]


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
    """A whole method-C scenario, the method-C update's peak memory and the whole paper-000 report.

    Returns a JSON-serialisable dict: ``cores``, ``weights_memory``, ``scenario`` and ``report``.
    """
    return {
        "cores": os.cpu_count(),
        "weights_memory": weights_memory(20_000 if quick else 100_000),
        "scenario": scenario_run(20_000 if quick else 100_000),
        "report": report_time(quick),
    }


if __name__ == "__main__":  # pragma: no cover - manual use
    import json
    import sys

    print(json.dumps(bench(quick="--quick" in sys.argv), indent=1, default=float))
