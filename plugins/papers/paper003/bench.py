"""Benchmarks for paper 003 (not timed tests): the paper-scale Monte Carlo, and our batched UKF vs FilterPy.

:func:`bench` measures

(a) the wall time of the paper's Monte Carlo: the recipe's primary (mismatched) tasks, 3 levels x 8 filters,
    at the full size (3,000 runs, 100 steps) or the quick size, in this process (the ``dask`` group runs the
    same tasks on a local Dask cluster);
(b) the cost per run-step (one predict + update) of our UKF batched over ``batch`` runs, against FilterPy's
    ``UnscentedKalmanFilter`` (an optional ``bench`` extra; skipped when it is not installed) on the same
    range-bearing problem with the same (alpha, beta, kappa), angle-aware residual and mean; the ratio is
    measured in one call.  FilterPy is also run once with redrawn sigma points (the brief's algorithm)
    to cross-check our estimates against it;
(c) the compute time of every quick-size task of the recipe in this process (the quick report minus drawing).

Everything is returned as a flat dict of numbers (seconds, microseconds) for ``workbench bench``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from workbench.bench import median_time
from workbench.plugins import load_host
from workbench.report.engine import InProcess
from workbench.kernels.crpf_step import resolve_backend
from . import recipe
from workbench.specs import RecipeOptions, TaskContext

__all__ = ["bench", "monte_carlo_wall_time", "ukf_vs_filterpy", "quick_tasks_time"]

_HOST = None
#: The issue's target for the full primary Monte Carlo in one process on 2 cores (seconds).
MC_TARGET_S = 60.0


def _host():
    global _HOST
    if _HOST is None:
        _HOST = load_host()
    return _HOST


def primary_tasks(size: str = "full", seed: int = 0) -> list:
    """The recipe's primary Monte Carlo tasks (mismatched noise, every level, the 8 default filters),
    largest first (by particle count) so that parallel workers finish together."""
    options = RecipeOptions(size=size, values=recipe.SIZES[size], seed=seed, filters=recipe.DEFAULT_FILTERS)
    tasks = [t for t in recipe.tasks(options) if t.key.startswith("mc/") and t.key.endswith("/mismatched")]
    return sorted(tasks, key=lambda t: -int(_host().filter(t.params["filter"]).params.get("particles", 1)))


def run_primary(size: str = "full", seed: int = 0, executor=None) -> tuple[float, dict]:
    """Run the primary Monte Carlo through a report executor (default: in-process); returns the wall time
    and every task's arrays."""
    tasks = primary_tasks(size, seed)
    executor = executor if executor is not None else InProcess(_host())
    results = {}
    t0 = time.perf_counter()
    for task, arrays, _seconds, error in executor.execute(tasks, seed, "cpu"):
        if error is not None:
            raise RuntimeError(f"{task.key}: {error[0]}")
        results[task.key] = arrays
    return time.perf_counter() - t0, results


def _warm_up_kernels() -> None:
    """Load (or, on a fresh install, compile and cache) every filter's compiled kernels outside the timed
    run: the quick-size Monte Carlo runs each of them once (a few seconds)."""
    run_primary("quick")


def monte_carlo_wall_time(size: str = "full", seed: int = 0) -> dict:
    """Wall time of the primary Monte Carlo in this process, with each filter's own filtering time (the
    compiled kernels loaded first: a fresh install compiles them once, into Numba's on-disk cache)."""
    values = recipe.SIZES[size]
    _warm_up_kernels()
    wall, results = run_primary(size, seed)
    out = {"mc_size": size, "mc_runs_per_level": values["runs"], "mc_steps": values["steps"],
           "mc_levels": len(recipe.LEVELS), "mc_filters": len(recipe.DEFAULT_FILTERS), "mc_wall_s": wall,
           "mc_crpf_backend": resolve_backend("auto", "cpu")}
    if size == "full":
        out.update({"mc_target_s": MC_TARGET_S, "mc_target_met": bool(wall < MC_TARGET_S)})
    for name in recipe.DEFAULT_FILTERS:
        out[f"mc_filter_s[{name}]"] = sum(float(r["seconds"]) for k, r in results.items() if k.split("/")[2] == name)
    return out


def _filterpy_ukf(prior_mean, prior_cov, motion, model, alpha, beta, kappa):
    """FilterPy's UKF on the range-bearing problem, with light one-point angle-aware mean and residual."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    two_pi = 2.0 * np.pi

    def wrap(a):
        return a - two_pi * np.ceil((a - np.pi) / two_pi)

    def residual_z(a, b):
        d = np.subtract(a, b)
        d[1] = wrap(d[1])
        return d

    def z_mean(sigmas, wm):
        # y_0 + sum w wrap(y_i - y_0) for the bearing, as MeasurementModel.mean
        r = wm @ sigmas[:, 0]
        ref = sigmas[0, 1]
        return np.array([r, wrap(ref + wm @ wrap(sigmas[:, 1] - ref))])

    def hx(x):  # the sensor's h (range, bearing from the origin) for one state, without array overhead
        return np.array([math.hypot(x[0], x[1]), math.atan2(x[1], x[0])])

    if (model.sensor_position or (0.0, 0.0)) != (0.0, 0.0):
        raise ValueError("the FilterPy comparison assumes the sensor at the origin")
    F = np.asarray(motion.F)
    points = MerweScaledSigmaPoints(motion.dim, alpha=alpha, beta=beta, kappa=kappa)
    ukf = UnscentedKalmanFilter(motion.dim, model.dim, motion.dt, hx=hx, fx=lambda x, dt: F @ x,
                                points=points, z_mean_fn=z_mean, residual_z=residual_z)
    ukf.x = np.array(prior_mean, dtype=float)
    ukf.P = np.array(prior_cov, dtype=float)
    ukf.Q = np.array(motion.Q, dtype=float)
    ukf.R = np.array(model.R, dtype=float)
    ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)  # the first update comes before any predict
    return ukf


def ukf_vs_filterpy(batch: int = 3000, filterpy_runs: int = 30, steps: int = 100, seed: int = 0,
                    repeat: int = 5) -> dict:
    """Per run-step cost (one predict + update) of our UKF over ``batch`` runs vs FilterPy's UKF, one run
    at a time; both are medians of ``repeat`` timings after a warm-up (:func:`workbench.bench.median_time`)."""
    host = _host()
    sig = recipe.LEVELS[recipe.NOMINAL]
    case = [recipe._case("bench", sig)]
    units = recipe._units(case, batch, 250)
    truth, scans = recipe.simulate_units(host, seed, case, units, steps)
    motion, model = recipe.nominal_models(host, sig, "mismatched")
    spec = host.filter("ukf")
    prior = recipe.prior(batch)
    steps_scans = [scans.scan(k).for_filter() for k in range(steps)]  # built outside the clock

    def ours():
        state = spec.init(prior, None)
        for k in range(steps):
            if k:
                state = spec.predict(state, motion, None)
            state = spec.update(state, steps_scans[k], model, None)
        return spec.estimate(state).mean

    seconds = median_time(ours, repeat=repeat, warmup=1)
    final_mean = ours()
    out = {"ukf_batch": batch, "ukf_steps": steps, "ukf_us_per_run_step": 1e6 * seconds / (batch * steps)}
    try:
        import filterpy  # noqa: F401
    except ImportError:
        out["filterpy"] = "not installed (pip install -e .[bench])"
        return out
    params = spec.params
    z = scans.z[:, :, 0, :]
    runs = min(filterpy_runs, batch)

    def theirs(redraw: bool = False, count: int = runs):
        finals = []
        for r in range(count):
            ukf = _filterpy_ukf(recipe.XHAT0, np.diag(recipe.P0), motion, model, params["alpha"], params["beta"],
                                params["kappa"])
            ukf.update(z[r, 0])
            for k in range(1, steps):
                ukf.predict()
                if redraw:  # the brief's algorithm (and ours) redraws the points from (x-, P-) before update
                    ukf.sigmas_f = ukf.points_fn.sigma_points(ukf.x, ukf.P)
                ukf.update(z[r, k])
            finals.append(ukf.x.copy())
        return np.array(finals)

    fp_seconds = median_time(theirs, repeat=max(1, repeat // 2), warmup=1)
    check = theirs(redraw=True, count=min(runs, 5))
    per_step = 1e6 * fp_seconds / (runs * steps)
    out.update({"filterpy_runs": runs, "filterpy_us_per_step": per_step,
                "filterpy_ratio": per_step / out["ukf_us_per_run_step"],
                "filterpy_redrawn_max_abs_state_diff": float(np.max(np.abs(check - final_mean[: len(check)])))})
    return out


def quick_tasks_time(seed: int = 0) -> dict:
    """Compute time of every quick-size task of the recipe (default filters), in this process."""
    host = _host()
    options = RecipeOptions(size="quick", values=recipe.SIZES["quick"], seed=seed, filters=recipe.DEFAULT_FILTERS)
    tasks = recipe.RECIPE.tasks(options)
    t0 = time.perf_counter()
    for t in tasks:
        t.run(TaskContext(params=t.params, seed=seed, host=host))
    return {"quick_tasks": len(tasks), "quick_tasks_s": time.perf_counter() - t0}


def bench(quick: bool = False, *, seed: int = 0) -> dict:
    """All three measurements: ``quick`` uses the quick Monte Carlo size and fewer FilterPy runs."""
    out = {}
    out.update(monte_carlo_wall_time("quick" if quick else "full", seed=seed))
    out.update(ukf_vs_filterpy(batch=3000, filterpy_runs=5 if quick else 30, seed=seed))
    out.update(quick_tasks_time(seed=seed))
    return out


if __name__ == "__main__":  # pragma: no cover - manual use: python -m workbench.bench_paper003 [--full]
    import sys

    for key, value in bench(quick="--full" not in sys.argv).items():
        print(f"{key:40s} {value:.4g}" if isinstance(value, float) else f"{key:40s} {value}")
