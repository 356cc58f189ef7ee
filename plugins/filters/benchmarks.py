"""Benchmark group ``core``: the bootstrap particle filter against Stone Soup and its floor, and the batched UKF
against FilterPy; and group ``motion`` (:func:`bench_motion`, at the end): the same filters with the nonlinear
coordinated turn (rate in the state) against FilterPy's UKF and Stone Soup's ``ConstantTurn`` particle filter.

:func:`bench` measures, in one process and one run (paper 003's problem: a 2-D random-walk-velocity
target, ``random_walk_velocity(2, 1.0, 0.1)``, one range-bearing measurement per step from the origin,
``range_bearing(1.0, 0.1)``):

- ``pf_ns_per_particle_step_N<N>``: our bootstrap particle filter (the built-in ``"sir"`` filter from
  the plugin host, with ``N`` particles and systematic resampling at every step, its ``backend`` the policy's
  choice, reported as ``pf_backend``), batch of one: wall time of predict + update (likelihood, normalisation,
  resampling) + estimate per particle and step, through the filter's fused ``step`` (one call, as the time loop runs
  it; the three calls' numbers bit for bit) where it gives one;
- ``pf_floor_ns_per_particle_step_N<N>``: a lower limit for any filter that draws its noise from a NumPy
  ``Generator``: the two normals per particle a step needs plus one read and one write of the particle states
  (``copyto`` of ``(4, N)`` numbers), the draws made the fastest way known here (the smaller of NumPy's
  ``standard_normal`` call, ``pf_floor_numpy_draws_ns...``, and the same numbers drawn by a compiled loop,
  ``pf_floor_compiled_draws_ns...``); ``pf_over_floor_N<N>`` is our time / the floor, timed alternately;
- ``stonesoup_*``: Stone Soup's ``ParticlePredictor`` + ``ParticleUpdater`` with
  ``SystematicResampler`` (every step) on the same truth, measurements, prior and models
  (``LinearGaussianTimeInvariantTransitionModel`` with our ``F`` and ``Q``,
  ``CartesianToBearingRange``), its mean and covariance computed each step as ours are; the ratio
  ``pf_over_stonesoup_N<N>`` (our time / theirs) and the speed-up (theirs / ours) come from the same run.
  Without Stone Soup every ``stonesoup_*`` figure is the string ``"not installed"``;
- ``ukf_ns_per_run_step_B<B>``: the host's ``"ukf"`` batched over ``B`` Monte Carlo runs, per run and
  step (predict + update + estimate); ``"ukf not installed"`` when no ``ukf`` filter is installed;
  ``filterpy_ukf_ns_per_run_step``: FilterPy's ``UnscentedKalmanFilter`` (same sigma-point parameters) one run
  at a time, per run-step (it does not batch, so its cost per run-step does not depend on ``B``);
- the targets (:mod:`workbench.bench.targets`): ``pf_over_floor_N100000 <= 1.5`` (issue 26's, for the fused step;
  issue 18 had 2 for the three calls) and ``pf_speedup_vs_stonesoup_N100000 >= 10``;
- ``curves``: throughput against ``N`` (ours, Stone Soup, the floor) and against ``B`` (ours, FilterPy), drawn by
  ``workbench bench --plot``.

Timings are medians after a warm-up (:func:`workbench.bench.median_time`) of whole multi-step runs
from a fixed initial state.  Where two things are compared (ours and Stone Soup, ours and the floor) they
are timed alternately and the ratio is the median of the per-pair ratios (:func:`paired_times`), so a machine
load that drifts during the measurement affects both alike.  Position RMSEs of the timed runs show that both
particle filters did the same job.  The figures are described in ``docs/benchmarks.md``.
"""

from __future__ import annotations

import math
import os

import numpy as np

from workbench import hookimpl
from workbench.bench import median_time
from workbench.bench.peers import filterpy_range_bearing_ukf
from workbench.linalg import wrap_angle
from workbench.models import random_walk_velocity, range_bearing
from workbench.plugins import UnknownComponent, load_host
from workbench.rng import generator
from workbench.specs import BenchmarkSpec
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, Scans

__all__ = ["PF_SIZES", "PEER_SIZES", "UKF_BATCHES", "SPEEDUP_TARGET", "FLOOR_TARGET", "TARGET_N", "NOT_INSTALLED",
           "bench", "problem", "sir_every_step", "filter_runner", "pf_runner", "stonesoup_runner", "paired_times",
           "time_pf", "time_stonesoup", "time_ukf", "floor_runner", "floor_time", "stonesoup_version",
           "filterpy_ukf_time", "curves", "MOTION_SIZES", "KERNEL_STATES", "UKF_CT_TARGET", "PF_CT_TARGET",
           "ct_problem", "filterpy_ct_ukf", "filterpy_ct_runner", "ct_stonesoup_runner", "kernel_figures",
           "bench_motion"]

#: Particle counts of our filter (full, quick), the counts Stone Soup is run at, and the UKF batches.
PF_SIZES = {"full": (1_000, 10_000, 100_000, 1_000_000), "quick": (1_000, 100_000)}
PEER_SIZES = {"full": (1_000, 10_000, 100_000), "quick": (1_000, 100_000)}
UKF_BATCHES = {"full": (1, 10, 100, 1000, 3000), "quick": (1, 3000)}
#: The particle count of the targets, and the targets: Stone Soup time / ours at least SPEEDUP_TARGET, our
#: time (the fused step) / the floor at most FLOOR_TARGET.
TARGET_N = 100_000
SPEEDUP_TARGET = 10.0
FLOOR_TARGET = 1.5
NOT_INSTALLED = "not installed"

# Paper 003's scenario (workbench_papers.paper003.scenario: X0, XHAT0, P0, level L2).
X0 = (100.0, 50.0, -1.0, 1.0)
XHAT0 = (110.0, 40.0, 0.0, 0.0)
P0 = (10.0**2, 10.0**2, 2.0**2, 2.0**2)
SIGMA_A, SIGMA_R, SIGMA_THETA = 0.1, 1.0, 0.1


def problem(batch: int, steps: int, seed: int = 0):
    """Truth, scans, prior and models of paper 003's range-bearing problem for ``batch`` runs."""
    rng = generator(seed, "bench", "core", batch, steps)
    motion = random_walk_velocity(2, 1.0, SIGMA_A)
    model = range_bearing(SIGMA_R, SIGMA_THETA)
    truth = sample_motion(np.tile(X0, (batch, 1)), motion, steps, rng)
    # z = h(x) + v, v ~ N(0, R), bearing wrapped to (-pi, pi]
    z = model.h(truth.states) + rng.standard_normal((batch, steps, 2)) @ np.linalg.cholesky(model.R).T
    z[..., 1] = wrap_angle(z[..., 1])
    scans = Scans(z[:, :, None, :], np.ones((batch, steps, 1), dtype=bool), truth.times)
    prior = Gaussian.broadcast(np.array(XHAT0), np.diag(P0), batch)
    return truth, scans, prior, motion, model


def sir_every_step(host, particles: int):
    """The host's ``"sir"`` with ``particles`` particles, resampling at every update (a threshold above one)."""
    return host.filter("sir").configure(particles=particles, threshold=2.0, name="sir")


def _steps_for(particles: int) -> int:
    """Steps per timed run: about 3 * 10^5 particle-steps, between 3 and 50."""
    return int(min(50, max(3, 300_000 // particles)))


def _repeats(quick: bool) -> int:
    return 3 if quick else 5


def _rmse(truth, means: list) -> float:
    est = np.stack(means, axis=1)[..., :2]
    return float(np.sqrt(np.mean(np.sum((est - truth.states[:, : est.shape[1], :2]) ** 2, axis=-1))))


def filter_runner(spec, batch: int, steps: int, seed: int = 0):
    """A function running ``spec`` over ``steps`` steps of a batch from a fixed initial state (predict +
    update + estimate each step, through the filter's fused ``step`` where it gives one, as the time loop runs it),
    and one returning the position RMSE (m) of its last run."""
    return _problem_runner(spec, problem(batch, steps, seed), seed, "core")


def pf_runner(host, particles: int, seed: int = 0):
    """Our bootstrap PF (batch of one) as a timed run: ``(run, steps, rmse)``."""
    steps = _steps_for(particles)
    run, rmse = filter_runner(sir_every_step(host, particles), 1, steps, seed)
    return run, steps, rmse


def time_pf(host, particles: int, repeats: int = 5, seed: int = 0) -> tuple[float, float]:
    """Our bootstrap PF: ns per particle-step and the position RMSE (m) of the timed run."""
    run, steps, rmse = pf_runner(host, particles, seed)
    return median_time(run, repeat=repeats, warmup=1) / steps / particles * 1e9, rmse()


def floor_runner(particles: int, compiled: bool = False, dim: int = 4, noise_dim: int = 2):
    """The unavoidable work of a step as a timed run of the same number of steps as :func:`pf_runner`: two normals
    per particle from a NumPy ``Generator`` and one read + write of the states (``copyto`` of ``(dim, N)``).
    ``compiled``: the normals drawn by the compiled loop the filter's propagation uses
    (:func:`workbench.kernels.particle_numba.fill_normals`, the same numbers as NumPy's call), else by
    ``rng.standard_normal``.  Returns ``(run, steps)``."""
    rng = generator(0, "bench", "core", "floor")
    src = np.ones((dim, particles))
    dst = np.empty_like(src)
    steps = _steps_for(particles)
    if compiled:
        from workbench.kernels.particle_numba import fill_normals

        def run():
            for _ in range(steps):
                fill_normals(rng, np.empty((particles, noise_dim)))
                np.copyto(dst, src)
    else:
        def run():
            for _ in range(steps):
                rng.standard_normal((1, particles, noise_dim))
                np.copyto(dst, src)

    return run, steps


def floor_time(particles: int, repeats: int = 5, dim: int = 4, noise_dim: int = 2, compiled: bool = False) -> float:
    """ns per particle-step of the unavoidable work (:func:`floor_runner`)."""
    run, steps = floor_runner(particles, compiled, dim, noise_dim)
    return median_time(run, repeat=repeats, warmup=1) / steps / particles * 1e9


def stonesoup_version() -> str | None:
    try:
        import stonesoup
    except ImportError:
        return None
    return str(getattr(stonesoup, "__version__", "unknown"))


def stonesoup_runner(particles: int, seed: int = 0):
    """Stone Soup's particle filter on the same problem as a timed run: ``(run, steps, rmse)``."""
    import datetime

    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.resampler.particle import SystematicResampler
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import ParticleState, StateVectors
    from stonesoup.updater.particle import ParticleUpdater

    steps = _steps_for(particles)
    truth, scans, prior, motion, model = problem(1, steps, seed)
    transition = LinearGaussianTimeInvariantTransitionModel(transition_matrix=motion.F, covariance_matrix=motion.Q)
    # Stone Soup orders the measurement [bearing, range]
    measurement = CartesianToBearingRange(ndim_state=4, mapping=(0, 1),
                                          noise_covar=np.diag([SIGMA_THETA**2, SIGMA_R**2]))
    predictor = ParticlePredictor(transition)
    updater = ParticleUpdater(measurement, resampler=SystematicResampler())
    t0 = datetime.datetime(2020, 1, 1)
    times = [t0 + datetime.timedelta(seconds=float(t)) for t in scans.times]
    detections = [Detection(np.array([[scans.z[0, k, 0, 1]], [scans.z[0, k, 0, 0]]]), timestamp=times[k],
                            measurement_model=measurement) for k in range(steps)]
    rng = generator(seed, "bench", "core", "stonesoup-init")
    cloud = prior.mean[0][:, None] + np.linalg.cholesky(prior.cov[0]) @ rng.standard_normal((4, particles))
    start = ParticleState(StateVectors(cloud), log_weight=np.full(particles, -np.log(particles)), timestamp=times[0])
    means = []

    def run():
        np.random.seed(seed)  # Stone Soup draws from NumPy's global generator
        state = start
        means.clear()
        for k in range(steps):
            if k > 0:
                state = predictor.predict(state, timestamp=times[k])
            state = updater.update(SingleHypothesis(state, detections[k]))
            means.append(np.asarray(state.mean, dtype=float)[:, 0][None, :])
            state.covar  # noqa: B018 - the estimate's covariance, as ours computes it

    return run, steps, lambda: _rmse(truth, means)


def time_stonesoup(particles: int, repeats: int = 5, seed: int = 0) -> tuple[float, float]:
    """Stone Soup's particle filter: ns per particle-step and the position RMSE (m) of the timed run."""
    run, steps, rmse = stonesoup_runner(particles, seed)
    return median_time(run, repeat=repeats, warmup=1) / steps / particles * 1e9, rmse()


def paired_times(run_a, run_b, repeats: int) -> tuple[float, float, float]:
    """Median seconds of ``run_a`` and ``run_b`` timed alternately (one warm-up each), and the median of
    the per-pair ratios a / b: a load that drifts during the measurement affects both alike."""
    median_time(run_a, repeat=1, warmup=0)
    median_time(run_b, repeat=1, warmup=0)
    a, b = [], []
    for _ in range(repeats):
        a.append(median_time(run_a, repeat=1, warmup=0))
        b.append(median_time(run_b, repeat=1, warmup=0))
    ratios = np.array(a) / np.array(b)
    return float(np.median(a)), float(np.median(b)), float(np.median(ratios))


def time_ukf(host, batch: int, repeats: int = 5, seed: int = 0) -> float:
    """The host's ``"ukf"``: ns per run-step over a batch of ``batch`` runs."""
    steps = int(min(50, max(5, 30_000 // batch)))
    run, _ = filter_runner(host.filter("ukf"), batch, steps, seed)
    return median_time(run, repeat=repeats, warmup=1) / steps / batch * 1e9


def _filterpy_ukf(prior: Gaussian, motion, model, alpha: float, beta: float, kappa: float):
    """FilterPy's UKF at the first item of ``prior`` (:func:`workbench.bench.peers.filterpy_range_bearing_ukf`)."""
    return filterpy_range_bearing_ukf(prior.mean[0], prior.cov[0], motion, model, alpha, beta, kappa)


def filterpy_ukf_time(host, runs: int = 10, steps: int = 50, repeats: int = 5, seed: int = 0) -> float | str:
    """FilterPy's UKF, one run at a time, on ``runs`` runs of the same problem: ns per run-step (predict + update),
    with the sigma-point parameters of the host's ``"ukf"``; ``"not installed"`` without FilterPy."""
    try:
        import filterpy  # noqa: F401
    except ImportError:
        return NOT_INSTALLED
    params = host.filter("ukf").params
    truth, scans, prior, motion, model = problem(runs, steps, seed)
    z = scans.z[:, :, 0, :]

    def run():
        for r in range(runs):
            ukf = _filterpy_ukf(prior, motion, model, params["alpha"], params["beta"], params["kappa"])
            ukf.update(z[r, 0])
            for k in range(1, steps):
                ukf.predict()
                ukf.update(z[r, k])

    return median_time(run, repeat=repeats, warmup=1) / (runs * steps) * 1e9


#: Single-track latency targets (one predict + update, B = 1) against FilterPy in the same run (issue 26).
EKF_ONE_TARGET, UKF_ONE_TARGET = 0.5, 0.1


def one_track_runners(host, steps: int = 400, seed: int = 0):
    """One track (B = 1) step by step on the range-bearing problem: our EKF and UKF (each predict + update
    through the filter's four functions, as a user writes it) and FilterPy's EKF and UKF on the same measurements.
    Returns ``{name: run}``, each ``run()`` doing ``steps`` steps (FilterPy runs missing without FilterPy)."""
    truth, scans, prior, motion, model = problem(1, steps, seed)
    rng = np.random.default_rng(seed)
    one = [scans.scan(k).for_filter() for k in range(steps)]

    def ours(name):
        spec = host.filter(name)

        def run():
            state = spec.init(prior, rng)
            for scan in one:
                state = spec.update(spec.predict(state, motion, rng), scan, model, rng)
            return spec.estimate(state)
        return run

    runners = {"ekf": ours("ekf"), "ukf": ours("ukf")}
    try:
        from filterpy.kalman import ExtendedKalmanFilter
    except ImportError:
        return runners
    z = scans.z[0, :, 0, :]
    params = host.filter("ukf").params
    jac = lambda x: model.jacobian(x[None])[0]  # noqa: E731
    hx = lambda x: model.h(x)  # noqa: E731
    res = lambda a, b: model.residual(a, b)  # noqa: E731

    def fp_ekf():
        ekf = ExtendedKalmanFilter(4, 2)
        ekf.x, ekf.P = prior.mean[0].copy(), prior.cov[0].copy()
        ekf.F, ekf.Q, ekf.R = motion.F, motion.Q, model.R
        for k in range(steps):
            ekf.predict()
            ekf.update(z[k], jac, hx, residual=res)
        return ekf.x

    def fp_ukf():
        ukf = _filterpy_ukf(prior, motion, model, params["alpha"], params["beta"], params["kappa"])
        for k in range(steps):
            ukf.predict()
            ukf.update(z[k])
        return ukf.x

    runners.update({"filterpy_ekf": fp_ekf, "filterpy_ukf": fp_ukf})
    return runners


def one_track_latency(host, repeats: int, steps: int = 400) -> dict:
    """Microseconds per step (predict + update) at B = 1, ours against FilterPy's timed alternately, and the
    targets ``ekf <= 0.5 x FilterPy's EKF`` and ``ukf <= 0.1 x FilterPy's UKF`` (warmed up: each runner once
    before the clock)."""
    runs = one_track_runners(host, steps)
    out: dict = {}
    for name, target in (("ekf", EKF_ONE_TARGET), ("ukf", UKF_ONE_TARGET)):
        peer = runs.get(f"filterpy_{name}")
        if peer is None:
            out[f"{name}_one_track_us_per_step"] = median_time(runs[name], repeat=repeats, warmup=1) / steps * 1e6
            out[f"filterpy_{name}_us_per_step"] = NOT_INSTALLED
            continue
        t_ours, t_peer, ratio = paired_times(runs[name], peer, repeats)
        out[f"{name}_one_track_us_per_step"] = t_ours / steps * 1e6
        out[f"filterpy_{name}_us_per_step"] = t_peer / steps * 1e6
        out[f"target_{name}_one_track_over_filterpy"] = f"<= {target:g}"
        out[f"measured_{name}_one_track_over_filterpy"] = ratio
        out[f"met_{name}_one_track_over_filterpy"] = bool(ratio <= target)
        out[f"note_{name}_one_track_over_filterpy"] = (
            f"one track (B = 1), {steps} predict + update steps through the filter's functions, timed alternately "
            f"with FilterPy's {name.upper()} on the same measurements, median of {repeats} pairs")
    return out


def curves(out: dict, size: str) -> list[dict]:
    """The scaling figures of this group (:mod:`workbench.bench.plots`) from its figures ``out``."""
    def num(key):
        v = out.get(key)
        return v if isinstance(v, (int, float)) and not isinstance(v, bool) else None

    pf_n = [n for n in PF_SIZES[size] if num(f"pf_ns_per_particle_step_N{n}")]
    peer_n = [n for n in PEER_SIZES[size] if num(f"stonesoup_ns_per_particle_step_N{n}")]
    series = [
        {"label": f"workbench sir ({out.get('pf_backend', '?')})", "role": "ours", "x": pf_n,
         "y": [1e9 / out[f"pf_ns_per_particle_step_N{n}"] for n in pf_n]},
        {"label": "floor: the draws (fastest known) + one state read/write", "role": "limit", "x": pf_n,
         "y": [1e9 / out[f"pf_floor_ns_per_particle_step_N{n}"] for n in pf_n]},
        {"label": "floor with NumPy's standard_normal call (issue 18's)", "role": "reference", "x": pf_n,
         "y": [1e9 / out[f"pf_floor_numpy_draws_ns_per_particle_step_N{n}"] for n in pf_n]},
    ]
    if peer_n:
        series.insert(1, {"label": f"Stone Soup {out.get('stonesoup_version', '')}", "role": "peer", "x": peer_n,
                          "y": [1e9 / out[f"stonesoup_ns_per_particle_step_N{n}"] for n in peer_n]})
    figs = [{"id": "pf_vs_particles", "title": "Bootstrap particle filter (range-bearing, batch of one)",
             "x_label": "particles N", "x_unit": "", "y_label": "throughput", "y_unit": "particle-steps/s",
             "series": series}]
    b = [b for b in UKF_BATCHES[size] if num(f"ukf_ns_per_run_step_B{b}")]
    if b:
        ukf = [{"label": "workbench ukf (batched)", "role": "ours", "x": b,
                "y": [1e9 / out[f"ukf_ns_per_run_step_B{k}"] for k in b]}]
        if num("filterpy_ukf_ns_per_run_step"):
            ukf.append({"label": "FilterPy UKF (one run at a time)", "role": "peer", "x": b,
                        "y": [1e9 / out["filterpy_ukf_ns_per_run_step"]] * len(b)})
        figs.append({"id": "ukf_vs_batch", "title": "Unscented Kalman filter (range-bearing)",
                     "x_label": "runs in the batch B", "x_unit": "", "y_label": "throughput",
                     "y_unit": "run-steps/s", "series": ukf})
    return figs


def bench(quick: bool = False) -> dict:
    """Every figure of group ``core`` (see the module docstring), as a flat dict of numbers and strings."""
    from workbench.kernels.backend import numba_available, resolve

    size = "quick" if quick else "full"
    repeats = _repeats(quick)
    host = load_host()
    version = stonesoup_version()
    loads = [os.getloadavg()[0]] if hasattr(os, "getloadavg") else [float("nan")]
    pf_backend = resolve(host.filter("sir").params.get("backend", "auto"))
    out: dict = {"cpu_count": os.cpu_count() or 0, "numpy_version": np.__version__,
                 "stonesoup_version": version or NOT_INSTALLED, "pf_backend": pf_backend}
    compiled_floor = numba_available()
    for n in sorted(set(PF_SIZES[size]) | set(PEER_SIZES[size])):
        ours, steps, rmse = pf_runner(host, n)
        if n in PEER_SIZES[size] and version is not None:
            theirs, peer_steps, peer_rmse = stonesoup_runner(n)
            t_ours, t_theirs, ratio = paired_times(ours, theirs, repeats)
            ns_ours = t_ours / steps / n * 1e9
            out[f"stonesoup_ns_per_particle_step_N{n}"] = t_theirs / peer_steps / n * 1e9
            out[f"stonesoup_pos_rmse_m_N{n}"] = peer_rmse()
            # both runs have the same steps and particles, so the time ratio is the per-particle-step ratio
            out[f"pf_over_stonesoup_N{n}"] = ratio
            out[f"pf_speedup_vs_stonesoup_N{n}"] = 1.0 / ratio
        else:
            ns_ours = median_time(ours, repeat=repeats, warmup=1) / steps / n * 1e9
            if n in PEER_SIZES[size]:
                for key in ("stonesoup_ns_per_particle_step", "stonesoup_pos_rmse_m", "pf_over_stonesoup",
                            "pf_speedup_vs_stonesoup"):
                    out[f"{key}_N{n}"] = NOT_INSTALLED
        if n in PF_SIZES[size]:
            out[f"pf_ns_per_particle_step_N{n}"] = ns_ours
            # the floor, timed alternately with the filter: NumPy's draw call and the compiled draw of the same
            # numbers; the floor is the faster
            floor_numpy, f_steps = floor_runner(n)
            _, t_np, r_np = paired_times(ours, floor_numpy, repeats)
            out[f"pf_floor_numpy_draws_ns_per_particle_step_N{n}"] = t_np / f_steps / n * 1e9
            floor_ns, ratio = t_np / f_steps / n * 1e9, r_np
            if compiled_floor:
                floor_fast, _ = floor_runner(n, compiled=True)
                _, t_c, r_c = paired_times(ours, floor_fast, repeats)
                out[f"pf_floor_compiled_draws_ns_per_particle_step_N{n}"] = t_c / f_steps / n * 1e9
                if t_c < t_np:
                    floor_ns, ratio = t_c / f_steps / n * 1e9, r_c
            out[f"pf_floor_ns_per_particle_step_N{n}"] = floor_ns
            out[f"pf_over_floor_N{n}"] = ratio
            out[f"pf_over_numpy_draws_floor_N{n}"] = r_np
            out[f"pf_pos_rmse_m_N{n}"] = rmse()
    loads.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
    # the targets (workbench.bench.targets)
    n = TARGET_N
    out[f"target_pf_over_floor_N{n}"] = f"<= {FLOOR_TARGET:g}"
    out[f"measured_pf_over_floor_N{n}"] = out[f"pf_over_floor_N{n}"]
    out[f"met_pf_over_floor_N{n}"] = bool(out[f"pf_over_floor_N{n}"] <= FLOOR_TARGET)
    out[f"note_pf_over_floor_N{n}"] = (
        f"floor {out[f'pf_floor_ns_per_particle_step_N{n}']:.3g} ns = the fastest known draw of the step's normals "
        f"+ one state read/write; against NumPy's own standard_normal call as the floor the ratio is "
        f"{out[f'pf_over_numpy_draws_floor_N{n}']:.3g}")
    out[f"target_pf_speedup_vs_stonesoup_N{n}"] = f">= {SPEEDUP_TARGET:g}"
    out[f"measured_pf_speedup_vs_stonesoup_N{n}"] = out[f"pf_speedup_vs_stonesoup_N{n}"]
    out[f"met_pf_speedup_vs_stonesoup_N{n}"] = (NOT_INSTALLED if version is None
                                                else bool(out[f"pf_speedup_vs_stonesoup_N{n}"] >= SPEEDUP_TARGET))
    try:
        host.filter("ukf")
    except UnknownComponent:
        ukf = None
    else:
        ukf = True
    for b in UKF_BATCHES[size]:
        out[f"ukf_ns_per_run_step_B{b}"] = time_ukf(host, b, repeats) if ukf else "ukf not installed"
    out["filterpy_ukf_ns_per_run_step"] = (filterpy_ukf_time(host, runs=3 if quick else 10, repeats=repeats)
                                           if ukf else "ukf not installed")
    if ukf:
        out.update(one_track_latency(host, repeats, steps=100 if quick else 400))
    loads.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
    out["load_avg_1min"] = max(loads)
    out["load_avg_1min_start_pf_end"] = loads
    out["curves"] = curves(out, size)
    return out


# -- group motion: the nonlinear coordinated turn (rate in the state) ---------------------------------------------

#: The coordinated-turn problem of group ``motion``: the truth starts 1.5 km out at 20 m/s turning at 3 deg/s, the
#: ct-rate model with sigma_a = 0.5 m/s^2 and sigma_omega = 0.01 rad/s/sqrt(s), range-bearing from the origin
#: (5 m, 0.005 rad), the prior offset from the start and spread as CT_P0.
CT_X0 = (1500.0, 300.0, 0.0, 20.0, math.radians(3.0))
CT_PRIOR_OFFSET = (10.0, -10.0, 1.0, -1.0, 0.01)
CT_P0 = (10.0**2, 10.0**2, 2.0**2, 2.0**2, 0.02**2)
CT_SIGMA_A, CT_SIGMA_OMEGA, CT_SIGMA_R, CT_SIGMA_THETA = 0.5, 0.01, 5.0, 0.005
#: Sizes of group ``motion`` (full, quick): the UKF's batch and steps, FilterPy's runs, the PF's particles and steps.
MOTION_SIZES = {"full": {"batch": 3000, "ukf_steps": 20, "filterpy_runs": 10, "particles": 100_000, "pf_steps": 5},
                "quick": {"batch": 300, "ukf_steps": 4, "filterpy_runs": 2, "particles": 10_000, "pf_steps": 3}}
#: The state counts at which the compiled ct-rate f and Jacobian are timed against their NumPy twins: a UKF step
#: at B = 3,000 (11 sigma points each) and a PF step at N = 10^5 (both modes).
KERNEL_STATES = (3000 * 11, 100_000)
#: The targets of issue 23: the batched UKF >= 100 x FilterPy's per run-step, the bootstrap PF >= 10 x Stone Soup's.
UKF_CT_TARGET, PF_CT_TARGET = 100.0, 10.0
#: Stone Soup orders the state [x, vx, y, vy, omega]; ours is [x, y, vx, vy, omega].
STONESOUP_ORDER = (0, 2, 1, 3, 4)


def ct_motion():
    """The ct-rate model of group ``motion`` over 1 s steps (sigma_a, sigma_omega as :data:`CT_SIGMA_A`,
    :data:`CT_SIGMA_OMEGA`)."""
    from workbench.models import coordinated_turn_rate

    return coordinated_turn_rate(1.0, CT_SIGMA_A, CT_SIGMA_OMEGA)


def ct_problem(batch: int, steps: int, seed: int = 0):
    """Truth (sampled from the ct-rate model itself), scans, prior and models of group ``motion`` for ``batch``
    runs: ``(truth, scans, prior, motion, model)``."""
    rng = generator(seed, "bench", "motion", batch, steps)
    motion = ct_motion()
    model = range_bearing(CT_SIGMA_R, CT_SIGMA_THETA)
    truth = sample_motion(np.tile(CT_X0, (batch, 1)), motion, steps, rng)
    z = model.h(truth.states) + rng.standard_normal((batch, steps, 2)) @ np.linalg.cholesky(model.R).T
    z[..., 1] = wrap_angle(z[..., 1])
    scans = Scans(z[:, :, None, :], np.ones((batch, steps, 1), dtype=bool), truth.times)
    prior = Gaussian.broadcast(np.add(CT_X0, CT_PRIOR_OFFSET), np.diag(CT_P0), batch)
    return truth, scans, prior, motion, model


def _problem_runner(spec, prob, seed: int, tag: str):
    """``spec`` run over a problem ``(truth, scans, prior, motion, model)`` as a timed run (init, then per step:
    predict from the second step on, update, estimate; through the filter's fused ``step`` where it gives one), and a
    function returning the position RMSE (m) of its last run; the means of the last run stay in ``run.means``
    ``(B, steps, n)`` once it ran."""
    truth, scans, prior, motion, model = prob
    steps = scans.steps
    scan_list = [scans.scan(k).for_filter() for k in range(steps)]
    start = spec.init(prior, generator(seed, "bench", tag, "init"))
    means: list = []

    def run():
        rng = generator(seed, "bench", tag, "run")
        state = start
        means.clear()
        for k in range(steps):
            if k > 0 and spec.step is not None:
                state, est, _ = spec.step(state, motion, scan_list[k], model, rng)
                means.append(est.mean)
                continue
            if k > 0:
                state = spec.predict(state, motion, rng)
            state = spec.update(state, scan_list[k], model, rng)
            means.append(spec.estimate(state).mean)
        run.means = np.stack(means, axis=1)

    return run, lambda: _rmse(truth, means)


def filterpy_ct_ukf(mean, cov, motion, model, alpha: float, beta: float, kappa: float):
    """FilterPy's ``UnscentedKalmanFilter`` (``MerweScaledSigmaPoints``) for the nonlinear ``motion``: its ``fx`` is
    the model's own ``f`` (``fx(x, dt) = motion.f(x, None, dt)``), the rest as
    :func:`workbench.bench.peers.filterpy_range_bearing_ukf` (``Q``, ``R``, a wrapped bearing residual, an
    angle-aware measurement mean)."""
    ukf = filterpy_range_bearing_ukf(mean, cov, motion, model, alpha, beta, kappa)
    ukf.fx = lambda x, dt: motion.f(x, None, dt)
    return ukf


def filterpy_ct_runner(host, prob, runs: int):
    """FilterPy's UKF on the first ``runs`` runs of the problem ``prob`` (:func:`ct_problem`), one run at a time, as
    a timed run (the ``ukf``'s alpha, beta, kappa); ``run.means`` ``(runs, steps, 5)`` holds its posterior means
    once it ran."""
    params = host.filter("ukf").params
    truth, scans, prior, motion, model = prob
    steps = scans.steps
    z = scans.z[:runs, :, 0, :]

    def run():
        out = np.empty((runs, steps, motion.dim))
        for r in range(runs):
            ukf = filterpy_ct_ukf(prior.mean[r], prior.cov[r], motion, model, params["alpha"], params["beta"],
                                  params["kappa"])
            ukf.update(z[r, 0])
            out[r, 0] = ukf.x
            for k in range(1, steps):
                ukf.predict()
                ukf.update(z[r, k])
                out[r, k] = ukf.x
        run.means = out

    return run


class _StoneSoupTurn:
    """Stone Soup's ``ConstantTurn`` with the process noise of our ct-rate model (its ``covar`` would be the
    continuous white-noise form; ours is the discrete one): the same function, the same ``Q``, in its state order."""

    @staticmethod
    def build(motion):
        from stonesoup.models.transition.nonlinear import ConstantTurn
        from stonesoup.types.array import CovarianceMatrix

        order = list(STONESOUP_ORDER)
        Q = CovarianceMatrix(np.asarray(motion.Q)[np.ix_(order, order)])

        class SameNoiseConstantTurn(ConstantTurn):
            def covar(self, time_interval, **kwargs):
                return Q

        return SameNoiseConstantTurn(linear_noise_coeffs=np.array([0.0, 0.0]), turn_noise_coeff=0.0)


def ct_stonesoup_runner(particles: int, steps: int, seed: int = 0):
    """Stone Soup's particle filter on :func:`ct_problem` (one run): ``ParticlePredictor`` with its
    ``ConstantTurn`` (our ``Q``), ``ParticleUpdater`` with ``CartesianToBearingRange`` and ``SystematicResampler``
    (every step), its mean and covariance each step.  Returns ``(run, rmse)``."""
    import datetime

    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.resampler.particle import SystematicResampler
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import ParticleState, StateVectors
    from stonesoup.updater.particle import ParticleUpdater

    truth, scans, prior, motion, model = ct_problem(1, steps, seed)
    measurement = CartesianToBearingRange(ndim_state=5, mapping=(0, 2),
                                          noise_covar=np.diag([CT_SIGMA_THETA**2, CT_SIGMA_R**2]))
    predictor = ParticlePredictor(_StoneSoupTurn.build(motion))
    updater = ParticleUpdater(measurement, resampler=SystematicResampler())
    t0 = datetime.datetime(2020, 1, 1)
    times = [t0 + datetime.timedelta(seconds=float(t)) for t in scans.times]
    detections = [Detection(np.array([[scans.z[0, k, 0, 1]], [scans.z[0, k, 0, 0]]]), timestamp=times[k],
                            measurement_model=measurement) for k in range(steps)]
    rng = generator(seed, "bench", "motion", "stonesoup-init")
    cloud = prior.mean[0][:, None] + np.linalg.cholesky(prior.cov[0]) @ rng.standard_normal((5, particles))
    start = ParticleState(StateVectors(cloud[list(STONESOUP_ORDER)]),
                          log_weight=np.full(particles, -np.log(particles)), timestamp=times[0])
    means: list = []
    back = np.argsort(STONESOUP_ORDER)

    def run():
        np.random.seed(seed)  # Stone Soup draws from NumPy's global generator
        state = start
        means.clear()
        for k in range(steps):
            if k > 0:
                state = predictor.predict(state, timestamp=times[k])
            state = updater.update(SingleHypothesis(state, detections[k]))
            means.append(np.asarray(state.mean, dtype=float)[back, 0][None, :])
            state.covar  # noqa: B018 - the estimate's covariance, as ours computes it

    return run, lambda: _rmse(truth, means)


def kernel_figures(repeats: int) -> dict:
    """The ct-rate model's ``f`` and Jacobian on ``(K, 5)`` states (K in :data:`KERNEL_STATES`, turn rates on both
    sides of 0): the NumPy twins against the policy's path (the compiled loops where it runs Numba), timed
    alternately, ns per state, and the speed-up (median of the per-pair ratios)."""
    from workbench.kernels.backend import resolve

    model = ct_motion()
    backend = resolve("auto")
    out: dict = {"ct_rate_backend": "numba" if backend == "numba" else f"numpy (the policy's {backend})"}
    rng = generator(0, "bench", "motion", "kernel")
    for K in KERNEL_STATES:
        x = np.column_stack([rng.uniform(-3e3, 3e3, (K, 2)), rng.uniform(-30, 30, (K, 2)),
                             rng.uniform(-0.2, 0.2, K)])
        for name, twin, routed in (("f", model.f_numpy, model.f), ("jacobian", model.jacobian_numpy, model.jacobian)):
            t_twin, t_routed, ratio = paired_times(lambda: twin(x), lambda: routed(x), repeats)
            out[f"ct_rate_{name}_numpy_ns_per_state_K{K}"] = t_twin / K * 1e9
            out[f"ct_rate_{name}_ns_per_state_K{K}"] = t_routed / K * 1e9
            out[f"ct_rate_{name}_speedup_over_numpy_K{K}"] = ratio  # NumPy's time / the policy's, per pair
    return out


def bench_motion(quick: bool = False) -> dict:
    """Group ``motion``: the batched UKF with the ct-rate model against FilterPy's UKF with the same ``fx`` per
    run-step, and the bootstrap PF ``sir`` with it against Stone Soup's particle filter with its ``ConstantTurn`` per
    step, each pair warmed up and timed alternately on the same problem (:func:`ct_problem`); the compiled ct-rate
    ``f`` and Jacobian against their NumPy twins.  Figures and targets in ``docs/benchmarks.md``."""
    from workbench.kernels.backend import resolve

    size = "quick" if quick else "full"
    sizes = MOTION_SIZES[size]
    repeats = _repeats(quick)
    host = load_host()
    version = stonesoup_version()
    loads = [os.getloadavg()[0]] if hasattr(os, "getloadavg") else [float("nan")]
    B, steps, runs = sizes["batch"], sizes["ukf_steps"], sizes["filterpy_runs"]
    N, pf_steps = sizes["particles"], sizes["pf_steps"]
    out: dict = {"cpu_count": os.cpu_count() or 0, "numpy_version": np.__version__,
                 "stonesoup_version": version or NOT_INSTALLED, "ukf_batch": B, "ukf_steps": steps,
                 "filterpy_runs": runs, "pf_particles": N, "pf_steps": pf_steps,
                 "pf_backend": resolve(host.filter("sir").params.get("backend", "auto"))}
    out.update(kernel_figures(repeats))
    try:
        import filterpy  # noqa: F401
    except ImportError:
        filterpy_ok = False
    else:
        filterpy_ok = True
    # the UKF: ours batched over B runs, FilterPy's on `runs` of the same runs
    prob = ct_problem(B, steps)
    ours, ukf_rmse = _problem_runner(host.filter("ukf"), prob, 0, "motion-ukf")
    key = "ukf_ct_speedup_vs_filterpy"
    out[f"target_{key}"] = f">= {UKF_CT_TARGET:g}"
    if filterpy_ok:
        theirs = filterpy_ct_runner(host, prob, runs)
        t_ours, t_theirs, ratio = paired_times(ours, theirs, repeats)
        speedup = (B / runs) / ratio  # (their time / run-step) / (ours / run-step), per pair
        out["ukf_ct_ns_per_run_step"] = t_ours / (B * steps) * 1e9
        out["filterpy_ukf_ct_ns_per_run_step"] = t_theirs / (runs * steps) * 1e9
        out["ukf_ct_max_abs_difference_vs_filterpy"] = float(np.max(np.abs(ours.means[:runs] - theirs.means)))
        out[f"measured_{key}"] = speedup
        out[f"met_{key}"] = bool(speedup >= UKF_CT_TARGET)
        out[f"note_{key}"] = (f"ukf at B = {B} against FilterPy's UnscentedKalmanFilter (MerweScaledSigmaPoints, fx = "
                              f"the model's f) on {runs} of the same runs, {steps} steps, timed alternately, median of "
                              f"{repeats} pairs; estimates agree to "
                              f"{out['ukf_ct_max_abs_difference_vs_filterpy']:.2g}")
    else:
        ours()
        out["ukf_ct_ns_per_run_step"] = median_time(ours, repeat=repeats, warmup=0) / (B * steps) * 1e9
        for name in ("filterpy_ukf_ct_ns_per_run_step", "ukf_ct_max_abs_difference_vs_filterpy", f"measured_{key}",
                     f"met_{key}"):
            out[name] = NOT_INSTALLED
    out["ukf_ct_pos_rmse_m"] = ukf_rmse()
    # the bootstrap PF: ours and Stone Soup's, one run of N particles each
    pf_problem = ct_problem(1, pf_steps)
    pf, pf_rmse = _problem_runner(sir_every_step(host, N), pf_problem, 0, "motion-sir")
    # the step's one compiled pass (turn, noise, likelihood), as the model declares it and the policy runs Numba
    fused = out["pf_backend"] == "numba" and ct_motion().fused_particle_propagator("range-bearing") is not None
    key = "sir_ct_speedup_vs_stonesoup"
    out[f"target_{key}"] = f">= {PF_CT_TARGET:g}"
    if version is not None:
        theirs, ss_rmse = ct_stonesoup_runner(N, pf_steps)
        t_ours, t_theirs, ratio = paired_times(pf, theirs, repeats)
        out["sir_ct_ns_per_particle_step"] = t_ours / (N * pf_steps) * 1e9
        out["stonesoup_ct_ns_per_particle_step"] = t_theirs / (N * pf_steps) * 1e9
        out["stonesoup_ct_pos_rmse_m"] = ss_rmse()
        out[f"measured_{key}"] = 1.0 / ratio
        out[f"met_{key}"] = bool(1.0 / ratio >= PF_CT_TARGET)
        out[f"note_{key}"] = (f"sir and Stone Soup's ParticlePredictor (ConstantTurn with our Q) + ParticleUpdater "
                              f"(SystematicResampler), N = {N}, {pf_steps} steps, resampling every step"
                              f"{', ours in one fused pass per tile' if fused else ''}, timed "
                              f"alternately, median of {repeats} pairs; position RMSE {pf_rmse():.3g} m (ours) and "
                              f"{out['stonesoup_ct_pos_rmse_m']:.3g} m (Stone Soup)")
    else:
        pf()
        out["sir_ct_ns_per_particle_step"] = median_time(pf, repeat=repeats, warmup=0) / (N * pf_steps) * 1e9
        for name in ("stonesoup_ct_ns_per_particle_step", "stonesoup_ct_pos_rmse_m", f"measured_{key}",
                     f"met_{key}"):
            out[name] = NOT_INSTALLED
    out["sir_ct_pos_rmse_m"] = pf_rmse()
    loads.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
    out["load_avg_1min"] = max(loads)
    return out


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("core", "the built-in filters: bootstrap PF against Stone Soup, batched UKF per run-step",
                          bench),
            BenchmarkSpec("motion", "coordinated turn (rate in the state): batched UKF against FilterPy's UKF, "
                                    "bootstrap PF against Stone Soup's ConstantTurn particle filter", bench_motion)]
