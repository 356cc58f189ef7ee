"""Benchmark group ``trackers``: the JIPDA and GM-PHD trackers against Stone Soup's JPDA and GM-PHD on the issue-25
scene, and every built-in tracker's cost against the number of targets and the clutter density.

The scene (:func:`scene`): ``B`` Monte Carlo runs of 10 constant-velocity targets in a 2,000 m square, each
detected with probability 0.9 and position accuracy 2 m (the active sonar's Cartesian model), and 200 uniform
clutter detections per scan (full: 100 runs of 20 scans; quick: 10 runs of 5).

- ``jipda_s_per_run_scan``: the whole ``jipda`` tracker (the Kalman filter, the declared clutter density) on all
  ``B`` runs at once, per run and scan: gating, exact / belief-propagation marginals, the mixture update, existence,
  one-point initiation of a tentative track from every unclaimed detection (some 200 per scan), deletion;
- ``stonesoup_jpda_s_per_run_scan``: Stone Soup's ``JPDA`` data associator with a ``PDAHypothesiser`` (the same
  P_D, P_G and clutter density), its ``KalmanPredictor`` / ``KalmanUpdater`` with our ``F``, ``Q``, ``H``, ``R``, and
  the reduction of each track's Gaussian mixture (``gm_reduce_single``), on the 10 true tracks handed to it at the
  first scan (no initiation: Stone Soup's JPDA enumerates every joint event of all tracks at once, without
  clusters, so 200 tentative tracks a scan would not finish), over ``stonesoup_runs`` runs of the same scene;
- the target ``jipda_speedup_vs_stonesoup_jpda >= 20``: Stone Soup's time per run-scan over ours.  Ours does more
  work (initiation and every tentative track), so the ratio is conservative;
- ``jipda_confirmed_per_scan``: the mean number of confirmed tracks per run at the last scan (10 targets);
- ``gmphd_s_per_run_scan``: the whole ``gm-phd`` tracker on all ``B`` runs at once, per run and scan, with the
  parameters :data:`GMPHD` (P_S 0.99, P_D 0.9, the scene's clutter intensity, one fixed birth component over the
  box the targets start in, gate 0.9999, prune 1e-5, merge 4, at most 100 components, extraction at 0.5);
- ``stonesoup_gmphd_s_per_run_scan``: Stone Soup's GM-PHD as its tutorial composes it and as its
  ``PointProcessMultiTargetTracker`` runs it (:func:`stonesoup_gmphd`): ``KalmanPredictor`` / ``KalmanUpdater``
  with our ``F``, ``Q``, ``H``, ``R``, a ``GaussianMixtureHypothesiser`` over a ``DistanceHypothesiser`` (the
  Mahalanobis gate of the same probability), the ``PHDUpdater`` (the same P_S, P_D and clutter intensity), the
  ``GaussianMixtureReducer`` (the same prune, merge and maximum) and the same birth component, on the first
  ``stonesoup_gmphd_scans`` scans of ``stonesoup_gmphd_runs`` runs (full: 8 scans of 1 run, quick: 3; its first
  scans, with fewer components, are its cheapest, so the ratio is conservative).  Differences of Stone Soup's
  own: its pruning hands the pruned weight to the components kept, its merging measures each candidate against
  the running merged component (Vo and Ma's Table II, and ours, against the heaviest one) and merges at
  ``d2 < U`` (ours at ``d2 <= U``); on a small scene the two find the same targets, their estimates within 3 m
  (``tests/test_tracker_bench.py``);
- the target ``gmphd_speedup_vs_stonesoup_gmphd >= 20``; ``gmphd_extracted_per_scan``: the mean number of
  extracted targets per run at our last scan (10 targets); ``stonesoup_gmphd_extracted_per_scan`` and
  ``gmphd_extracted_at_stonesoup_last_scan``: Stone Soup's and ours on its runs at its last scan;
- ``curves``: the cost (ms per run and scan) of ``jipda``, ``gm-phd``, ``gnn`` and ``mofn`` against the number of
  targets and against the clutter density (the grid :data:`COST_TARGETS`, :data:`COST_CLUTTER`, :data:`COST_AT`),
  each point the median of a few runs of :data:`COST_SIZES` after an untimed one (:func:`cost_grid`,
  :func:`cost_curves`); ``workbench bench --plot DIR`` draws them.

Timings are wall times of whole runs after a warm-up on a smaller scene; one process, one run.
"""

from __future__ import annotations

import os
import time

import numpy as np

from workbench import hookimpl
from workbench.models import constant_velocity
from workbench.rng import generator
from workbench.specs import BenchmarkSpec
from workbench.types import Scans

__all__ = ["scene", "bench", "GMPHD", "gmphd_tracker", "stonesoup_gmphd", "cost_grid", "cost_curves", "COST_TRACKERS",
           "COST_TARGETS", "COST_CLUTTER", "COST_AT", "COST_SIZES", "COST_REPEATS"]

SPEEDUP_TARGET = 20.0
NOT_INSTALLED = "not installed"
TARGETS, CLUTTER, SIDE, PD, SIGMA = 10, 200, 2000.0, 0.9, 2.0

#: The GM-PHD's parameters in both trackers (ours: ``gm-phd``'s; Stone Soup's: see :func:`stonesoup_gmphd`); the
#: clutter intensity is the scene's (``CLUTTER / SIDE**2``).  One fixed birth component, since Stone Soup's
#: point-process tracker takes one birth component: over the box the targets start in, any course.
GMPHD = dict(p_survival=0.99, p_detection=PD, birth="fixed", birth_rate=0.1, birth_mean=[1000.0, 1000.0, 0.0, 0.0],
             birth_std=[400.0, 400.0, 10.0, 10.0], gate_probability=0.9999, prune=1e-5, merge=4.0,
             max_components=100, extract=0.5)

#: The cost figures: the trackers drawn, the grid (targets per run, at COST_AT[1] clutter detections per scan;
#: clutter detections per scan, at COST_AT[0] targets), the size of each timed run (runs, scans) and the timings
#: per point, per mode.
COST_TRACKERS = ("jipda", "gm-phd", "gnn", "mofn")
COST_TARGETS = {"quick": (2, 5, 10, 20), "full": (2, 5, 10, 20, 40)}
COST_CLUTTER = {"quick": (25, 50, 100, 200), "full": (25, 50, 100, 200, 400)}
COST_AT = {"quick": (10, 100), "full": (10, 200)}  # (targets while clutter varies, clutter while targets vary)
COST_SIZES = {"quick": (3, 4), "full": (20, 10)}
COST_REPEATS = {"quick": 1, "full": 3}


def scene(runs: int, steps: int, seed: int = 0, targets: int = TARGETS, clutter: int = CLUTTER):
    """``(scans, truth (runs, steps, targets, 4), motion, model)``: ``targets`` (10) targets from a box in the middle
    at 5-15 m/s, detected with probability ``PD``, and ``clutter`` (200) uniform false detections per scan over the
    square."""
    from workbench.plugins import load_host

    rng = generator(seed, "bench trackers")
    motion = constant_velocity(2, 1.0, 0.05)
    model = load_host().sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=SIGMA)
    speed = rng.uniform(5.0, 15.0, (runs, targets))
    course = rng.uniform(0.0, 2 * np.pi, (runs, targets))
    x = np.concatenate([rng.uniform(600.0, 1400.0, (runs, targets, 2)),
                        np.stack([speed * np.cos(course), speed * np.sin(course)], axis=-1)], axis=-1)
    truth = np.empty((runs, steps, targets, 4))
    for k in range(steps):
        truth[:, k] = x
        x = x @ motion.F.T
    z_t = truth[..., :2] + SIGMA * rng.standard_normal((runs, steps, targets, 2))
    detected = rng.uniform(size=(runs, steps, targets)) < PD
    false = rng.uniform(0.0, SIDE, (runs, steps, clutter, 2))
    z = np.concatenate([z_t, false], axis=2)
    valid = np.concatenate([detected, np.ones((runs, steps, clutter), dtype=bool)], axis=2)
    return Scans(z, valid, np.arange(float(steps))), truth, motion, model


def _stonesoup_jpda(scans: Scans, truth: np.ndarray, motion, model, runs: int, rho: float) -> float:
    """Seconds Stone Soup's JPDA takes on the first ``runs`` runs of ``scans`` from the true initial states."""
    from datetime import datetime, timedelta

    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.functions import gm_reduce_single
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.types.update import GaussianStateUpdate
    from stonesoup.updater.kalman import KalmanUpdater

    order = [0, 2, 1, 3]  # ours [x, y, vx, vy] -> Stone Soup's [x, vx, y, vy]
    transition = LinearGaussianTimeInvariantTransitionModel(motion.F[np.ix_(order, order)],
                                                            motion.Q[np.ix_(order, order)])
    measurement = LinearGaussian(4, [0, 2], model.R)
    predictor, updater = KalmanPredictor(transition), KalmanUpdater(measurement)
    jpda = JPDA(PDAHypothesiser(predictor, updater, clutter_spatial_density=rho, prob_detect=PD, prob_gate=0.99))
    t0 = datetime(2024, 1, 1)
    start = time.perf_counter()
    for b in range(runs):
        P0 = np.diag([SIGMA**2, 4.0, SIGMA**2, 4.0])
        tracks = {Track([GaussianState(truth[b, 0, i][order][:, None], P0, timestamp=t0)]) for i in range(TARGETS)}
        for k in range(1, scans.steps):
            t = t0 + timedelta(seconds=float(scans.times[k]))
            dets = {Detection(zz[:, None], timestamp=t, measurement_model=measurement)
                    for zz in scans.z[b, k][scans.valid[b, k]]}
            hyps = jpda.associate(tracks, dets, t)
            for track in tracks:
                means, covs, weights = [], [], []
                for h in hyps[track]:
                    post = updater.update(h) if h.measurement else h.prediction
                    means.append(np.asarray(post.state_vector, dtype=float))
                    covs.append(np.asarray(post.covar, dtype=float))
                    weights.append(float(h.probability))
                m, c = gm_reduce_single(np.hstack(means), np.stack(covs, axis=2), np.array(weights))
                track.append(GaussianStateUpdate(m, c, hyps[track], timestamp=t))
    return time.perf_counter() - start


def gmphd_tracker(host, rho: float):
    """Our ``gm-phd`` with :data:`GMPHD` and the clutter intensity ``rho``."""
    return host.tracker("gm-phd").configure(clutter_density=rho, **GMPHD)


def stonesoup_gmphd(scans: Scans, motion, model, runs: int, steps: int, rho: float) -> tuple[float, list]:
    """Stone Soup's GM-PHD on the first ``steps`` scans of the first ``runs`` runs of ``scans``, with :data:`GMPHD`
    and the clutter intensity ``rho``: ``(seconds, [the extracted states (E, 4) of each run at its last scan, in
    our [x, y, vx, vy] order]``).  The parts its GM-PHD tutorial composes, run by its
    ``PointProcessMultiTargetTracker`` one scan at a time (``update_tracker``)."""
    from datetime import datetime, timedelta

    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.tracker.pointprocess import PointProcessMultiTargetTracker
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.pointprocess import PHDUpdater

    from workbench.tracking.gate import chi2_gate

    g = GMPHD
    order = [0, 2, 1, 3]  # ours [x, y, vx, vy] -> Stone Soup's [x, vx, y, vy]
    transition = LinearGaussianTimeInvariantTransitionModel(motion.F[np.ix_(order, order)],
                                                            motion.Q[np.ix_(order, order)])
    measurement = LinearGaussian(4, [0, 2], model.R)
    predictor, updater = KalmanPredictor(transition), KalmanUpdater(measurement)
    t0 = datetime(2024, 1, 1)
    birth_mean = np.asarray(g["birth_mean"], float)[order]
    birth_cov = np.diag(np.asarray(g["birth_std"], float)[order] ** 2)
    extracted = []
    start = time.perf_counter()
    for b in range(runs):
        # Stone Soup's Mahalanobis is the distance itself, not its square: the gate d2 <= G is d <= sqrt(G)
        hypothesiser = GaussianMixtureHypothesiser(
            DistanceHypothesiser(predictor, updater, measure=Mahalanobis(),
                                 missed_distance=float(np.sqrt(chi2_gate(g["gate_probability"], 2)))),
            order_by_detection=True)
        tracker = PointProcessMultiTargetTracker(
            detector=None, hypothesiser=hypothesiser,
            updater=PHDUpdater(updater, clutter_spatial_density=rho, prob_detection=g["p_detection"],
                               prob_survival=g["p_survival"]),
            reducer=GaussianMixtureReducer(prune_threshold=g["prune"], merge_threshold=g["merge"],
                                           max_number_components=g["max_components"]),
            extraction_threshold=g["extract"],
            birth_component=TaggedWeightedGaussianState(birth_mean[:, None], birth_cov, weight=g["birth_rate"],
                                                        tag=TaggedWeightedGaussianState.BIRTH, timestamp=t0))
        for k in range(steps):
            t = t0 + timedelta(seconds=float(scans.times[k]))
            tracker.update_tracker(t, {Detection(zz[:, None], timestamp=t, measurement_model=measurement)
                                       for zz in scans.z[b, k][scans.valid[b, k]]})
        states = [np.asarray(c.state_vector, float).ravel()[order] for c in tracker.extracted_target_states]
        extracted.append(np.array(states).reshape(-1, 4))
    return time.perf_counter() - start, extracted


def _cost_tracker(host, name: str, rho: float):
    """``name`` as the cost figures run it: the scene's clutter intensity where the tracker takes one, the
    M-of-N initiation box wide enough for the scene's 15 m/s."""
    if name == "jipda":
        return host.tracker("jipda").configure(clutter_density=rho, velocity_sigma=10.0, survival=0.99)
    if name == "gm-phd":
        return gmphd_tracker(host, rho)
    return host.tracker(name).configure(v_max=20.0)


def cost_grid(size: str, trackers=COST_TRACKERS) -> dict:
    """Each tracker's cost in ms per run and scan on the scene with ``targets`` from :data:`COST_TARGETS` (at
    ``COST_AT[size][1]`` clutter detections per scan) and with ``clutter`` from :data:`COST_CLUTTER` (at
    ``COST_AT[size][0]`` targets): ``{"targets": {"x": [...], name: [...]}, "clutter": {...}}``.  Each point is
    the median of :data:`COST_REPEATS` timed runs of :data:`COST_SIZES` after one untimed run of the same scene (a
    first run compiles what the point's sizes need)."""
    from workbench.bench import median_time
    from workbench.plugins import load_host

    host = load_host()
    kf = host.filter("kf")
    runs, steps = COST_SIZES[size]
    at_targets, at_clutter = COST_AT[size]
    points = {"targets": [(t, at_clutter) for t in COST_TARGETS[size]],
              "clutter": [(at_targets, c) for c in COST_CLUTTER[size]]}
    grid = {axis: {"x": [p[0] if axis == "targets" else p[1] for p in pts]} for axis, pts in points.items()}
    for name in trackers:
        for axis, pts in points.items():
            ms = []
            for targets, clutter in pts:
                scans, _, motion, model = scene(runs, steps, seed=2, targets=targets, clutter=clutter)
                spec = _cost_tracker(host, name, clutter / SIDE**2)
                seconds = median_time(lambda: spec.run(scans, kf, motion, model, seed=0),
                                      repeat=COST_REPEATS[size], warmup=1)
                ms.append(1e3 * seconds / (runs * steps))
            grid[axis][name] = ms
    return grid


def cost_curves(grid: dict, size: str) -> list[dict]:
    """The two cost figures of :func:`cost_grid`'s ``grid``: ms per run and scan against the number of targets and
    against the clutter density (detections per km² and scan; the square is ``SIDE`` m wide)."""
    runs, steps = COST_SIZES[size]
    at_targets, at_clutter = COST_AT[size]
    km2 = (SIDE / 1000.0) ** 2
    caption = (f"per point: {runs} Monte Carlo runs x {steps} scans, the median of {COST_REPEATS[size]} timing(s) "
               f"after a warm-up; Kalman filter; P_D {PD}, {SIDE / 1000:g} km square")
    names = [k for k in grid["targets"] if k != "x"]
    return [
        {"id": "cost_vs_targets", "title": f"tracker cost against targets ({at_clutter} clutter detections per scan)",
         "x_label": "targets per run", "x_unit": "", "y_label": "cost", "y_unit": "ms per run-scan",
         "log_x": False, "log_y": True, "caption": caption,
         "series": [{"label": name, "role": "ours", "x": list(grid["targets"]["x"]), "y": list(grid["targets"][name])}
                    for name in names]},
        {"id": "cost_vs_clutter", "title": f"tracker cost against clutter density ({at_targets} targets)",
         "x_label": "clutter density", "x_unit": "detections per km² per scan", "y_label": "cost",
         "y_unit": "ms per run-scan", "log_x": False, "log_y": True, "caption": caption,
         "series": [{"label": name, "role": "ours", "x": [c / km2 for c in grid["clutter"]["x"]],
                     "y": list(grid["clutter"][name])} for name in names]},
    ]


#: (runs, scans) of the timed scene, Stone Soup's JPDA runs, Stone Soup's GM-PHD (runs, scans), per mode.
SIZES = {"quick": ((10, 5), 1, (1, 3)), "full": ((100, 20), 2, (1, 8))}
GMPHD_KEY = "gmphd_speedup_vs_stonesoup_gmphd"
JPDA_KEY = "jipda_speedup_vs_stonesoup_jpda"


def _timed(fn):
    """``(seconds, fn())``: the wall time of one call."""
    start = time.perf_counter()
    result = fn()
    return time.perf_counter() - start, result


def _has_stonesoup() -> bool:
    try:
        import stonesoup  # noqa: F401
    except ImportError:
        return False
    return True


def bench(quick: bool) -> dict:
    from workbench.plugins import load_host

    size = "quick" if quick else "full"
    (runs, steps), ss_runs, (gm_runs, gm_steps) = SIZES[size]
    host = load_host()
    rho = CLUTTER / SIDE**2
    spec = host.tracker(f"jipda(clutter_density={rho}, velocity_sigma=10, survival=0.99)")
    phd = gmphd_tracker(host, rho)
    kf = host.filter("kf")
    scans, truth, motion, model = scene(runs, steps)
    warm, _, _, _ = scene(2, 3, seed=1)
    out: dict = {"runs": runs, "scans": steps, "targets": TARGETS, "clutter_per_scan": CLUTTER}
    logs = {}
    for name, tracker in (("jipda", spec), ("gmphd", phd)):
        tracker.run(warm, kf, motion, model, seed=0)
        seconds, logs[name] = _timed(lambda: tracker.run(scans, kf, motion, model, seed=0))
        out[f"{name}_s_per_run_scan"] = seconds / (runs * steps)
        out[f"{name}_{'confirmed' if name == 'jipda' else 'extracted'}_per_scan"] = float(
            logs[name].confirmed_counts()[:, -1].mean())
    for key in (JPDA_KEY, GMPHD_KEY):
        out[f"target_{key}"] = f">= {SPEEDUP_TARGET:g}"
    if not _has_stonesoup():
        for key, peer in ((JPDA_KEY, "stonesoup_jpda"), (GMPHD_KEY, "stonesoup_gmphd")):
            out[f"{peer}_s_per_run_scan"] = out[f"measured_{key}"] = out[f"met_{key}"] = NOT_INSTALLED
    else:
        theirs = _stonesoup_jpda(scans, truth, motion, model, ss_runs, rho) / (ss_runs * (steps - 1))
        out["stonesoup_jpda_s_per_run_scan"] = theirs
        out[f"measured_{JPDA_KEY}"] = theirs / out["jipda_s_per_run_scan"]
        out[f"met_{JPDA_KEY}"] = bool(out[f"measured_{JPDA_KEY}"] >= SPEEDUP_TARGET)
        out[f"note_{JPDA_KEY}"] = (f"ours: the whole jipda tracker on {runs} runs x {steps} scans (initiation of every "
                                   f"unclaimed detection included); Stone Soup: JPDA + PDAHypothesiser + Kalman update "
                                   f"+ mixture reduction of the 10 true tracks on {ss_runs} run(s), per run-scan")
        seconds, extracted = stonesoup_gmphd(scans, motion, model, gm_runs, gm_steps, rho)
        out["stonesoup_gmphd_runs"], out["stonesoup_gmphd_scans"] = gm_runs, gm_steps
        out["stonesoup_gmphd_s_per_run_scan"] = seconds / (gm_runs * gm_steps)
        out["stonesoup_gmphd_extracted_per_scan"] = float(np.mean([len(e) for e in extracted]))
        # ours on the same runs at the same scan: the two trackers' outputs side by side
        out["gmphd_extracted_at_stonesoup_last_scan"] = float(
            logs["gmphd"].confirmed_counts()[:gm_runs, gm_steps - 1].mean())
        out[f"measured_{GMPHD_KEY}"] = out["stonesoup_gmphd_s_per_run_scan"] / out["gmphd_s_per_run_scan"]
        out[f"met_{GMPHD_KEY}"] = bool(out[f"measured_{GMPHD_KEY}"] >= SPEEDUP_TARGET)
        out[f"note_{GMPHD_KEY}"] = (f"ours: the whole gm-phd tracker on {runs} runs x {steps} scans; Stone Soup: its "
                                    f"PointProcessMultiTargetTracker with the same parameters on {gm_runs} run(s) x "
                                    f"its first {gm_steps} scans (its cheapest), per run-scan")
    out["curves"] = cost_curves(cost_grid(size), size)
    out["load_avg_1min"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return out


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("trackers", "JIPDA and GM-PHD on 10 targets in 200 clutter detections per scan against "
                                      "Stone Soup's JPDA and GM-PHD; tracker cost against targets and clutter", bench)]
