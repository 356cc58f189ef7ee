"""Paper 002: bistatic range / range-rate Kalman tracking of a drone with a DTV passive radar.

Pipeline (detection level, every Monte Carlo run at once)::

    drone truth (ENU) --dtv-pbr--> target candidate [R, Rdot] with P_D
                      --pbr-false-alarms--> zero-Doppler residue + CFAR false alarms (density from the Pfa)
                      --pbr-zero-doppler--> drop |f_D| < 1 bin
                      --NN tracker + filter ("kf" by default) on [R, Rdot]--> track

and the ablation: the same candidates read as a monostatic radial velocity ``v = lambda f_D / 2`` in a
range-velocity model.  The signal level (reference + surveillance samples, ECA, CAF, CA-CFAR) runs two scenes:
the brief's benign one (the paper's row) and a demanding one (ATSC 8-VSB illuminator, direct path +60 dB,
clutter to 17.5 km, reference multipath and its cleaning, a CPI of 0.5 s as at the detection level).  Choices where the paper is silent are in :data:`NOTES` and
``docs/paper002.md``; the criteria, their statistics and the tuning rule are fixed there before the results.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from typing import Mapping

import numpy as np

from workbench import plot as wbplot
from workbench.criteria import (Criterion, DeclaredUnknown, Precondition, criterion_from_runs, judge_across,
                                replication_rate)
from workbench.metrics import association_log
from workbench.models import MeasurementModel, constant_velocity, linear_measurement, range_rate_model
from workbench.rng import generator
from workbench.sensing.bistatic import monostatic_velocity, range_and_rate, range_rate_to_doppler, wavelength
from workbench.specs import FigureSpec, RecipeOptions, RecipeSpec, Table, TableSpec, Task, TaskContext
from workbench.tracking import GATE_99, NearestNeighbour, Track, run, strongest_candidate_prior
from workbench.types import InputError, Scans, Truth

from .signal import (BENIGN_SCENE, DEMANDING_SCENE, PCLConfig, caf_batches, cfar_candidates, clean_reference,
                     demanding_config, eca, frame_signals, process_frame, simulate_scans_multi)

PAPER = "002"
FRAME_DT = 0.5  # s between frames [S]
SIGMA_A = 1.0  # m/s^2, white-noise acceleration of the [R, Rdot] model [U]
P0 = (50.0, 5.0)  # initial standard deviations of R (m) and Rdot (m/s) [U]
FALLBACK = (1500.0, 0.0)  # prior mean of a run whose first frame holds no candidate (mid-map)
START = (250.0, 150.0, 60.0)  # drone start, local ENU (m) [U]
SECTOR_DEG = 60.0  # surveillance sector, centred on east [U]
SECTOR_CENTRE_DEG = 0.0  # east, counter-clockwise from +x
SECTOR_RANGES = (150.0, 700.0)  # horizontal distance from Rx of the drone's waypoints (m) [U]
LEG_SECONDS = (10.0, 15.0)  # [U]
LEG_SPEEDS = (4.0, 10.0)  # m/s [U]
MAX_ACCEL = 1.0  # m/s^2: the drone turns onto a new leg at no more than this acceleration [U]
CPI_DETECTION = 0.5  # s: the detection level's coherent interval (the brief's R_cov: half a bin at CPI 0.5 s)
DOPPLER_BIN_DETECTION = 1.0 / CPI_DETECTION  # Hz
PFA = 1e-4  # the CA-CFAR's false-alarm probability (signal level and detection level alike)
MAP_RANGE_MAX = 3000.0  # m
MAP_RANGE_RATE_MAX = 50.0  # m/s
ON_TARGET_SIGMAS = 3.0  # the chosen candidate is "on target" within 3 sigma of the truth in R and in Rdot
NIS_95 = 5.991  # chi-square(2) 0.95 quantile
VARIANTS = ("rr-nogate", "rr-gate", "rv-nogate", "rv-gate")
MIN_RUNS = 200  # the fewest Monte Carlo runs from which a criterion may be decided
#: Criterion 4 is decided only when the range / range-rate model's NIS tail (5 % expected) lies in this range.
CONSISTENT_TAIL = (0.025, 0.10)
REPLICATIONS = 500  # single-run replications of the paper's protocol (one ~1-minute flight)
#: The tuned setting and its rule (docs/paper002.md, "Tuning"; :func:`choose_restart`): the restart delay of the gated
#: tracker, scored by criterion 1's track statistic (:func:`stat_track_share`).  The grid was widened from 4-12 to
#: 4-24 frames (2-12 s) before the track statistic was computed on any run (12 frames had the lowest track RMSE
#: on the tuning runs under the old rule, at the edge of the old grid); 2 frames joined after the first look at
#: the tuning runs (80 of them picked 4, the lower edge; on 200, delays 1, 2, 3 scored 85.8, 91.2, 91.7 % against
#: 91.8 % for 4 and 92.0 % for 6), so that the report shows the lower side of the optimum.  Tuning runs only.
RESTART_CANDIDATES = (2, 4, 6, 8, 12, 16, 24)  # frames without an update before a restart
TUNING_SEED = 7002  # with the stream key "tuning": never a stream of a reported run, whatever --seed is
TUNING_RUNS = {"quick": 200, "full": 500}
TUNING_TIE = 0.001  # track shares within 0.1 percentage point tie; a tie goes to the shorter delay
#: Criterion 1 on the track: the estimate within 3 sigma of the truth (45 m and 1.5 m/s) in >= 90 % of the frames
TRACK_SHARE_MIN = 0.9
ECA_TAPS_BRIEF = 16  # the benign scene's ECA span (0-450 m), also run on the demanding scene to show its failure


# -- scenario ---------------------------------------------------------------------------------------------


def drone_truth(rng: np.random.Generator, runs: int, frames: int, dt: float = FRAME_DT, *, start=START,
                sector_deg: float = SECTOR_DEG, centre_deg: float = SECTOR_CENTRE_DEG, ranges=SECTOR_RANGES,
                leg_seconds=LEG_SECONDS, speeds=LEG_SPEEDS, max_accel: float = MAX_ACCEL,
                substeps: int = 10) -> Truth:
    """Drone paths ``[x, y, z, vx, vy, vz]`` (ENU, m and m/s) for ``runs`` runs, one sample per frame.

    Each run flies legs of ``U(leg_seconds)`` s towards random waypoints inside the surveillance sector
    (bearing ``centre +- sector/2`` from the receiver, horizontal distance in ``ranges``) at the speed
    ``|waypoint - p| / duration`` (kept in ``speeds``), at constant height.  The drone is already on
    its first leg at frame 0; between legs the velocity turns towards the new command at no more than
    ``max_accel`` (integrated with ``substeps`` per frame).  Vectorised over runs; the loop is over time.

    Shapes: ``states (runs, frames, 6)``, ``times (frames,)``.
    """
    if runs < 1 or frames < 2:
        raise InputError(f"drone_truth needs runs >= 1 and frames >= 2, got runs={runs}, frames={frames}")
    h = dt / substeps
    p = np.broadcast_to(np.asarray(start, dtype=float), (runs, 3)).copy()
    v = np.zeros((runs, 3))
    cmd = np.zeros((runs, 3))
    left = np.zeros(runs)  # seconds left in the current leg
    half = np.radians(sector_deg) / 2.0
    centre = np.radians(centre_deg)
    tries = 32

    def new_legs(who: np.ndarray) -> None:
        k = who.size
        duration = rng.uniform(*leg_seconds, k)
        bearing = centre + rng.uniform(-half, half, (k, tries))
        dist = rng.uniform(*ranges, (k, tries))
        dx = dist * np.cos(bearing) - p[who, 0:1]
        dy = dist * np.sin(bearing) - p[who, 1:2]
        speed = np.hypot(dx, dy) / duration[:, None]
        # the first waypoint reachable at an allowed speed, else the one needing the closest speed
        miss = np.maximum(speeds[0] - speed, 0.0) + np.maximum(speed - speeds[1], 0.0)
        j = np.argmin(miss, axis=1)
        rows = np.arange(k)
        s = np.clip(speed[rows, j], *speeds)
        norm = np.maximum(np.hypot(dx[rows, j], dy[rows, j]), 1e-9)
        cmd[who, 0] = s * dx[rows, j] / norm
        cmd[who, 1] = s * dy[rows, j] / norm
        left[who] = duration

    new_legs(np.arange(runs))
    v[:] = cmd
    states = np.empty((runs, frames, 6))
    states[:, 0] = np.concatenate([p, v], axis=1)
    for k in range(1, frames):
        for _ in range(substeps):
            due = np.flatnonzero(left <= 0.0)
            if due.size:
                new_legs(due)
            dv = cmd - v
            # |dv| <= a_max h per substep
            scale = np.minimum(1.0, max_accel * h / np.maximum(np.linalg.norm(dv, axis=1), 1e-12))
            v_new = v + dv * scale[:, None]
            p = p + 0.5 * (v + v_new) * h
            v = v_new
            left -= h
        states[:, k] = np.concatenate([p, v], axis=1)
    return Truth(states, dt * np.arange(frames))


def cfar_false_alarms(pfa: float = PFA, cpi: float = CPI_DETECTION, range_max: float = MAP_RANGE_MAX,
                      range_rate_max: float = MAP_RANGE_RATE_MAX, frequency_hz: float = 701e6,
                      sample_rate: float = 10e6) -> tuple[float, int]:
    """False alarms per frame a CA-CFAR with false-alarm probability ``pfa`` gives on the range-Doppler map.

    The map has ``L = ceil(range_max / (c / f_s)) + 1`` range bins and ``2K + 1`` Doppler bins of ``1 / CPI``
    covering ``+-range_rate_max`` (``K = ceil(range_rate_max / (lambda / CPI))``); the expected number of
    noise cells over the threshold is ``Pfa * L * (2K + 1)`` (those in the zero-Doppler bin are removed later,
    with the rest of that bin).  At the detection level (CPI 0.5 s): 102 x 119 cells, 1.21 per frame.

    Returns ``(rate per frame, cells)``.
    """
    cfg = PCLConfig(sample_rate=sample_rate, cpi=cpi, frequency_hz=frequency_hz, range_max=range_max,
                    range_rate_max=range_rate_max, pfa=pfa)
    cells = cfg.lags * (2 * cfg.doppler_half + 1)
    # E[false alarms] = Pfa x cells
    return pfa * cells, cells


FA_RATE, FA_CELLS = cfar_false_alarms()
#: The map's false alarms, consistent with the CFAR's Pfa (the primary rows).
CLUTTER_PFA = {"false_alarm_rate": FA_RATE, "false_alarm_range_rate_max": MAP_RANGE_RATE_MAX,
               "false_alarm_pfa": PFA}
#: The brief's false alarms, Poisson(4) per frame on +-20 m/s: a density 8.2 times ours near the target.
CLUTTER_BRIEF = {"false_alarm_rate": 4.0, "false_alarm_range_rate_max": 20.0, "false_alarm_pfa": PFA}

#: The value paper 002 withholds that criterion 1 hinges on (issue 24 item 7): the false alarms per frame.  Every
#: criterion is judged at both grid values on the same runs (the same truth and the same target candidates: the
#: sensor's stream does not depend on the clutter; the clutter of both maps comes from one stream key).
FALSE_ALARMS = DeclaredUnknown(
    "false alarms per frame", "per frame", FA_RATE, (FA_RATE, CLUTTER_BRIEF["false_alarm_rate"]),
    f"The paper gives no detector settings, CPI or map. Primary: the CA-CFAR's own rate at our Pfa of 1e-4 (our "
    f"choice) over the detection-level map (0-3 km x +-50 m/s at CPI 0.5 s, {FA_CELLS} cells): {FA_RATE:g} per "
    f"frame, uniform on the map. The other grid value is the brief's Poisson(4) per frame uniform on +-20 m/s, "
    f"{CLUTTER_BRIEF['false_alarm_rate'] * MAP_RANGE_RATE_MAX / CLUTTER_BRIEF['false_alarm_range_rate_max'] / FA_RATE:.1f}"
    " times our density near the target; it gives a Pfa of about 8e-4 on a +-20 m/s map.")
#: The clutter parameters and the saved-variant prefix of each grid value of :data:`FALSE_ALARMS`.
FALSE_ALARM_MAPS = {FA_RATE: (CLUTTER_PFA, ""), CLUTTER_BRIEF["false_alarm_rate"]: (CLUTTER_BRIEF, "brief/")}


def false_alarm_density(params: Mapping[str, float], range_max: float = MAP_RANGE_MAX) -> float:
    """False alarms per frame per unit of ``R x Rdot`` (1 / (m m/s)): rate / (range_max x 2 Rdot_max)."""
    return params["false_alarm_rate"] / (range_max * 2.0 * params["false_alarm_range_rate_max"])


def detection_scans(host, truth: Truth, seed: int, clutter=CLUTTER_PFA, stream: tuple = ()) -> Scans:
    """Target candidates + map clutter with the zero-Doppler bins removed (common random numbers).

    ``clutter``: parameters of the ``pbr-false-alarms`` generator; ``stream``: extra key parts (the tuning
    runs use ``("tuning",)``).
    """
    # merge_all releases each field's inputs as it goes (3,000 full-size runs: the report's peak memory)
    merged = Scans.merge_all([host.sensor("dtv-pbr").simulate(truth, generator(seed, "paper002", *stream, "sensor")),
                              host.clutter_generator("pbr-false-alarms").generate(
                                  truth, generator(seed, "paper002", *stream, "clutter"), **clutter)])
    return host.clutter_remover("pbr-zero-doppler").remove(merged, doppler_bin_hz=DOPPLER_BIN_DETECTION)


def as_monostatic_velocity(scans: Scans, wavelength_m: float) -> Scans:
    """The ablation's reading of the candidates: ``z = [R, v]`` with ``v = -lambda f_D / 2`` (monostatic)."""
    if scans.doppler is None:
        raise InputError("as_monostatic_velocity needs scans with a doppler field")
    v = monostatic_velocity(np.nan_to_num(scans.doppler), wavelength_m)
    return replace(scans, z=np.stack([scans.z[..., 0], np.where(scans.valid, v, 0.0)], axis=-1))


def mismatched_model(model_rr: MeasurementModel) -> MeasurementModel:
    """Measurement model of the range-velocity ablation: ``z = [R, v]``, velocity noise = range-rate noise / 2."""
    sigma_r, sigma_rdot = model_rr.stated_std
    sigma_v = sigma_rdot / 2.0
    return linear_measurement(np.eye(2), np.diag([sigma_r ** 2, sigma_v ** 2]),
                              name="range-velocity (monostatic reading)")


def track_nearest_neighbour(spec, prior, motion, model, scans: Scans, rng, *, gate=None, prior_index=None,
                            reinit_after=None) -> Track:
    """The core loop with the nearest-neighbour role (:class:`workbench.tracking.NearestNeighbour`)."""
    return run(spec, scans, motion, model, association=NearestNeighbour(gate, prior_index, reinit_after),
               prior=prior, rng=rng)


def run_variants(spec, scans: Scans, model: MeasurementModel, dt: float, sigma_a: float, seed: int,
                 variants=VARIANTS, wavelength_m: float = 0.0, restart_after: int = 6,
                 stream: tuple = ()) -> dict[str, tuple[Track, Scans]]:
    """NN tracks of one filter for each variant (model x gate) on the same candidates.

    ``rr``: state ``[R, Rdot]``, :func:`~workbench.models.range_rate_model`, the sensor's model.
    ``rv``: state ``[R, v]``, a constant-velocity model with the same ``sigma_a``, candidates read as
    ``v = -lambda f_D / 2``.  ``gate``: ``d2 <= 9.21`` with coasting and a restart after ``restart_after``
    frames without an update (the tuned setting); ``nogate``: always the nearest candidate.
    """
    setups = {"rr": (scans, range_rate_model(dt, sigma_a), model, np.diag(np.square(P0)))}
    if any(v.startswith("rv") for v in variants):
        setups["rv"] = (as_monostatic_velocity(scans, wavelength_m), constant_velocity(1, dt, sigma_a),
                        mismatched_model(model), np.diag(np.square([P0[0], P0[1] / 2.0])))
    out = {}
    for name in variants:
        kind, gated = name.split("-")
        sc, motion, meas, cov0 = setups[kind]
        prior, index = strongest_candidate_prior(sc.scan(0), cov0, FALLBACK)
        gate, reinit = (GATE_99, int(restart_after)) if gated == "gate" else (None, None)
        out[name] = (track_nearest_neighbour(spec, prior, motion, meas, sc,
                                             generator(seed, "paper002", *stream, "filter", name),
                                             gate=gate, prior_index=index, reinit_after=reinit), sc)
    return out


def whitened_innovations(track: Track) -> np.ndarray:
    """``e_k = L_k^-1 (z_k - z^_k)`` with ``S_k = L_k L_k^T`` where updated (NaN elsewhere); ``NIS = |e|^2``.

    Shapes: ``(B, T, m)``.
    """
    rec = track.records
    nu = np.nan_to_num(rec["chosen_z"] - rec["predicted_z"])
    e = np.linalg.solve(np.linalg.cholesky(rec["innovation_cov"]), nu[..., None])[..., 0]
    return np.where(rec["updated"][..., None], e, np.nan)


def on_target(chosen: np.ndarray, truth: np.ndarray, sigma) -> np.ndarray:
    """``(B, T)``: the chosen measurement lies within :data:`ON_TARGET_SIGMAS` sigma of the truth in every
    component (``|z_i - x_i| <= 3 sigma_i``; False where nothing was chosen).  Shapes: ``(B, T, 2)`` twice."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(np.asarray(chosen, float) - truth) <= ON_TARGET_SIGMAS * np.asarray(sigma), axis=-1)


def on_track(est: np.ndarray, truth: np.ndarray, sigma) -> np.ndarray:
    """``(B, T)``: the track's estimate lies within :data:`ON_TARGET_SIGMAS` sigma of the truth in every component
    (``|x_hat_i - x_i| <= 3 sigma_i``: 45 m and 1.5 m/s with the sensor's stated 15 m and 0.5 m/s; False where the
    estimate is not finite).  Criterion 1's frame test.  Shapes: ``(B, T, 2)`` twice."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(np.asarray(est, float) - truth) <= ON_TARGET_SIGMAS * np.asarray(sigma), axis=-1)


def write_synthetic_candidates(path, host, seed: int = 2002, frames: int = 120):
    """Write the shipped example ``examples/data/pcl_candidates_synthetic.csv``: one detection-level run.

    The candidates are those the tracker sees (target, residue and the brief's Poisson(4) false alarms after the
    zero-Doppler notch), labelled SYNTHETIC in the header comments.
    """
    from workbench.recorded.pcl import write_pcl_candidates

    truth = drone_truth(generator(seed, "paper002", "truth"), 1, frames, FRAME_DT)
    scans = detection_scans(host, truth, seed, CLUTTER_BRIEF)
    sensor = host.sensor("dtv-pbr").params
    freq = sensor["frequency_hz"]
    return write_pcl_candidates(path, scans, transmitter_m=sensor["tx"], receiver_m=sensor["rx"], comments=(
        "SYNTHETIC: not measured data. Detection-level simulation of the paper-002 scenario (DTV passive radar,",
        "701 MHz, Tx (0, -8400, 420) m, Rx (0, 0, 60) m, one drone, P_D 0.9, Poisson(3) zero-Doppler residue and",
        "Poisson(4) false alarms per frame, |f_D| < 2 Hz removed), written by "
        f"workbench_papers.paper002.recipe.write_synthetic_candidates(seed={seed}, frames={frames}).",
        "Sign convention: range-rate = -wavelength * doppler_hz (positive Doppler = approaching).",
    ), frequency_hz=freq)


# -- per-run statistics -------------------------------------------------------------------------------------


def run_sums(truth: np.ndarray, est: np.ndarray, chosen: np.ndarray, present: np.ndarray, white: np.ndarray,
             sigma) -> dict[str, np.ndarray]:
    """Per-run sums behind every criterion (frames ``k >= 1``; frame 0 holds the prior).

    ``on = present & on_target(chosen)``: the target's candidate exists and the chosen one lies within 3 sigma
    of the truth.  Returned, each ``(runs,)``:

    - ``track_in``, ``frames``: frames whose track estimate lies within 3 sigma of the truth in R and in Rdot
      (:func:`on_track`), and all frames ``k >= 1`` (criterion 1: the track share);
    - ``present``, ``on``: frames with the target's candidate, and those whose chosen candidate is on target (the
      candidate-choice share, a diagnostic);
    - ``track_se_r``, ``track_se_rd``: squared track errors over all frames (track RMSE);
    - ``kf_se_r``, ``meas_se_r``, ``kf_se_rd``, ``meas_se_rd``: squared errors of the estimate and of the chosen
      measurement over the ``on`` frames (criterion 2);
    - ``d_n, d_est, d_est2, d_meas, d_meas2``: count, sum and sum of squares of the first differences of
      ``R_hat`` and of the chosen ``R`` over consecutive ``on`` frames (criterion 3);
    - ``nis_n``, ``nis_over``: on-target updates and those with NIS > 5.99; ``lag_ab, lag_aa, lag_bb``: sums
      of products of the whitened range innovations of consecutive on-target updates (criterion 4).

    Shapes: ``truth, est, chosen, white (B, T, 2)``; ``present (B, T)``.
    """
    truth = np.asarray(truth, float)
    est = np.asarray(est, float)
    chosen = np.asarray(chosen, float)
    white = np.asarray(white, float)
    later = np.zeros(present.shape, dtype=bool)
    later[:, 1:] = True
    on = np.asarray(present, bool) & on_target(chosen, truth, sigma) & later
    err, merr = est - truth, chosen - truth
    err_on = np.where(on[..., None], err, 0.0)
    merr_on = np.where(on[..., None], np.nan_to_num(merr), 0.0)
    pair = on[:, 1:] & on[:, :-1]
    d_est = np.where(pair, np.diff(est[..., 0], axis=1), 0.0)
    d_meas = np.where(pair, np.diff(np.nan_to_num(chosen[..., 0]), axis=1), 0.0)
    nis = np.sum(white ** 2, axis=-1)
    good = on & np.isfinite(nis)
    lag = good[:, 1:] & good[:, :-1]
    a = np.where(lag, np.nan_to_num(white[:, 1:, 0]), 0.0)
    b = np.where(lag, np.nan_to_num(white[:, :-1, 0]), 0.0)
    return {
        "track_in": np.sum(on_track(est, truth, sigma) & later, axis=1),
        "present": np.sum(present & later, axis=1), "on": np.sum(on, axis=1),
        "track_se_r": np.sum(err[:, 1:, 0] ** 2, axis=1), "track_se_rd": np.sum(err[:, 1:, 1] ** 2, axis=1),
        "frames": np.full(est.shape[0], est.shape[1] - 1),
        "kf_se_r": np.sum(err_on[..., 0] ** 2, axis=1), "meas_se_r": np.sum(merr_on[..., 0] ** 2, axis=1),
        "kf_se_rd": np.sum(err_on[..., 1] ** 2, axis=1), "meas_se_rd": np.sum(merr_on[..., 1] ** 2, axis=1),
        "d_n": np.sum(pair, axis=1), "d_est": d_est.sum(axis=1), "d_est2": np.sum(d_est ** 2, axis=1),
        "d_meas": d_meas.sum(axis=1), "d_meas2": np.sum(d_meas ** 2, axis=1),
        "nis_n": np.sum(good, axis=1), "nis_over": np.sum(good & (nis > NIS_95), axis=1),
        "nis_sum": np.sum(np.where(good, nis, 0.0), axis=1),
        "lag_ab": np.sum(a * b, axis=1), "lag_aa": np.sum(a * a, axis=1), "lag_bb": np.sum(b * b, axis=1),
    }


def _ratio(num, den) -> float:
    den = float(np.sum(den))
    return float(np.sum(num)) / den if den > 0 else float("nan")


# The pooled statistics of the criteria, each a function of per-run sums (resampled together by the bootstrap).
def stat_track_share(track_in, frames) -> float:
    """Criterion 1: frames whose track estimate is within 3 sigma of the truth in R and Rdot / all frames ``k >= 1``
    (pooled over runs: the ratio of sums)."""
    return _ratio(track_in, frames)


def stat_on_target(on, present) -> float:
    """The candidate-choice share (a diagnostic, criterion 1's former stand-in): on-target frames / frames with a
    target candidate."""
    return _ratio(on, present)


def stat_rmse(se, n) -> float:
    """``sqrt(sum se / sum n)``."""
    return float(np.sqrt(_ratio(se, n)))


def stat_rmse_ratio(se_kf, se_meas) -> float:
    """Criterion 2: ``RMSE(estimate) / RMSE(chosen measurement)`` over the same frames."""
    return float(np.sqrt(_ratio(se_kf, se_meas)))


def stat_smoothness(n, s_e, ss_e, s_m, ss_m) -> float:
    """Criterion 3: ``std(dR_hat) / std(dR_meas)`` over consecutive on-target frames."""
    n = float(np.sum(n))
    if n < 2:
        return float("nan")
    var_e = np.sum(ss_e) / n - (np.sum(s_e) / n) ** 2
    var_m = np.sum(ss_m) / n - (np.sum(s_m) / n) ** 2
    return float(np.sqrt(var_e / var_m)) if var_m > 0 else float("nan")


def _tail(over, n) -> float:
    return _ratio(over, n)


def _lag1(ab, aa, bb) -> float:
    den = float(np.sqrt(np.sum(aa) * np.sum(bb)))
    return float(np.sum(ab)) / den if den > 0 else float("nan")


def stat_ablation(over_rr, n_rr, ab_rr, aa_rr, bb_rr, over_rv, n_rv, ab_rv, aa_rv, bb_rv) -> float:
    """Criterion 4: ``min(|tail_rv - 5 %| - |tail_rr - 5 %|, |lag1_rv| - |lag1_rr|)``, > 0 when the monostatic
    reading is further from chi-square consistency on both counts."""
    d_tail = abs(_tail(over_rv, n_rv) - 0.05) - abs(_tail(over_rr, n_rr) - 0.05)
    d_lag = abs(_lag1(ab_rv, aa_rv, bb_rv)) - abs(_lag1(ab_rr, aa_rr, bb_rr))
    return float(min(d_tail, d_lag))


def _sigma(res) -> np.ndarray:
    return np.asarray(res["model_std"], dtype=float)


def variant_sums(res: Mapping[str, np.ndarray], variant: str) -> dict[str, np.ndarray]:
    """:func:`run_sums` of one saved variant of a detection task (``variant`` may carry a prefix such as
    ``"brief/"``)."""
    return run_sums(res["truth_rr"], res[f"{variant}/est"], res[f"{variant}/chosen"], res[f"{variant}/target_present"],
                    res[f"{variant}/white"], _sigma(res))


def metrics_from_sums(s: Mapping[str, np.ndarray]) -> dict[str, float]:
    """The pooled quantities of the table from :func:`run_sums`."""
    return {
        "track_share": stat_track_share(s["track_in"], s["frames"]),
        "on_target": stat_on_target(s["on"], s["present"]),
        "track_rmse_r": stat_rmse(s["track_se_r"], s["frames"]),
        "track_rmse_rd": stat_rmse(s["track_se_rd"], s["frames"]),
        "rmse_r_kf": stat_rmse(s["kf_se_r"], s["on"]), "rmse_r_meas": stat_rmse(s["meas_se_r"], s["on"]),
        "rmse_rd_kf": stat_rmse(s["kf_se_rd"], s["on"]), "rmse_rd_meas": stat_rmse(s["meas_se_rd"], s["on"]),
        "smooth_ratio": stat_smoothness(s["d_n"], s["d_est"], s["d_est2"], s["d_meas"], s["d_meas2"]),
        "nis_mean": _ratio(s["nis_sum"], s["nis_n"]), "nis_over_95": _tail(s["nis_over"], s["nis_n"]),
        "nis_samples": float(np.sum(s["nis_n"])), "lag1_r": _lag1(s["lag_ab"], s["lag_aa"], s["lag_bb"]),
    }


def variant_metrics(res: Mapping[str, np.ndarray], variant: str) -> dict[str, float]:
    """The table's quantities of one variant of one detection task: :func:`metrics_from_sums` plus the
    association log's rates (NN chose the target's own candidate, coasts, jumps, restarts, final frame)."""
    m = metrics_from_sums(variant_sums(res, variant))
    correct = np.asarray(res[f"{variant}/correct"], bool)
    present = np.asarray(res[f"{variant}/target_present"], bool)
    truth, est = np.asarray(res["truth_rr"], float), np.asarray(res[f"{variant}/est"], float)
    m.update({
        "nn_correct": float(correct[present].mean()) if present.any() else float("nan"),
        "final_on_track": float(np.mean(on_track(est[:, -1:], truth[:, -1:], _sigma(res)))),
        "coast_rate": float(np.mean(res[f"{variant}/coasted"][:, 1:])) if f"{variant}/coasted" in res else float("nan"),
        "jump_rate": float(np.mean(res[f"{variant}/jump"][:, 1:])) if f"{variant}/jump" in res else float("nan"),
        "restarts_per_run": float(np.mean(np.sum(res[f"{variant}/restarted"], axis=1))),
    })
    return m


# -- tuning (docs/paper002.md, "Tuning": the rule was written before the result) ---------------------------------


def choose_restart(candidates, scores, tie: float = TUNING_TIE) -> int:
    """The tuning rule (written down before any result): the delay with the highest score wins; scores within
    ``tie`` of the best tie, and a tie goes to the shortest delay.  Non-finite scores never win; all non-finite
    is refused by name.

    ``candidates``: delays (frames), in any order; ``scores``: one per candidate (criterion 1's track share).
    """
    candidates = np.asarray(candidates, dtype=int)
    scores = np.asarray(scores, dtype=float)
    if candidates.ndim != 1 or candidates.shape != scores.shape or not candidates.size:
        raise InputError(f"choose_restart needs one score per candidate delay, got delays of shape "
                         f"{candidates.shape} and scores of shape {scores.shape}")
    if not np.isfinite(scores).any():
        raise InputError("choose_restart: no candidate delay has a finite score (no tuning frames?)")
    best = np.nanmax(scores)
    tied = np.isfinite(scores) & (scores >= best - tie)
    return int(candidates[tied].min())


def tune_restart(host, filter_name: str, runs: int, frames: int, sigma_a: float = SIGMA_A
                 ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The restart delay of the gated tracker, chosen by the documented rule on tuning runs only.

    Rule (docs/paper002.md, "Tuning"; fixed before the result): over ``runs`` runs drawn from seed
    :data:`TUNING_SEED` under the stream key ``"tuning"`` (no reported run uses that key, whatever the report's
    seed), on the primary false-alarm map, run the gated range / range-rate tracker with each delay of
    :data:`RESTART_CANDIDATES`; score each by criterion 1's statistic, the share of frames ``k >= 1`` whose track
    estimate lies within 3 sigma of the truth in R and Rdot (:func:`stat_track_share`); the highest share wins,
    shares within :data:`TUNING_TIE` of the best tie, and a tie goes to the shortest delay
    (:func:`choose_restart`).

    Returns the chosen delay and, per candidate ``(len(RESTART_CANDIDATES),)``: the track share (the rule's
    score) and, for information only (the rule reads neither), the track range RMSE over all frames and the
    candidate-choice share (the former score).
    """
    sensor = host.sensor("dtv-pbr")
    tx, rx = sensor.params["tx"], sensor.params["rx"]
    truth = drone_truth(generator(TUNING_SEED, "paper002", "tuning", "truth"), runs, frames, FRAME_DT)
    scans = detection_scans(host, truth, TUNING_SEED, CLUTTER_PFA, stream=("tuning",))
    truth_rr = range_and_rate(truth.states, tx, rx)
    model = sensor.measurement_model()
    shares, rmse, chosen_on = [], [], []
    for delay in RESTART_CANDIDATES:
        (track, sc), = run_variants(host.filter(filter_name), scans, model, FRAME_DT, sigma_a, TUNING_SEED,
                                    variants=("rr-gate",), restart_after=delay, stream=("tuning",)).values()
        log = association_log(track, sc)
        inside = on_track(track.mean, truth_rr, model.stated_std)[:, 1:]
        shares.append(stat_track_share(inside.sum(axis=1), np.full(runs, frames - 1)))
        on = log.target_present & on_target(track.records["chosen_z"], truth_rr, model.stated_std)
        chosen_on.append(stat_on_target(on[:, 1:].sum(axis=1), log.target_present[:, 1:].sum(axis=1)))
        rmse.append(float(np.sqrt(np.mean((track.mean[:, 1:, 0] - truth_rr[:, 1:, 0]) ** 2))))
    shares = np.asarray(shares)
    return choose_restart(RESTART_CANDIDATES, shares), shares, np.asarray(rmse), np.asarray(chosen_on)


# -- tasks ------------------------------------------------------------------------------------------------


def _save_variant(res: dict, name: str, track: Track, sc: Scans, full: bool = True) -> None:
    log = association_log(track, sc)
    scale = np.array([1.0, 2.0]) if name.split("/")[-1].startswith("rv") else np.ones(2)  # rv: report 2 v = Rdot
    res[f"{name}/est"] = (track.mean * scale).astype(np.float32)
    res[f"{name}/chosen"] = (track.records["chosen_z"] * scale).astype(np.float32)
    res[f"{name}/white"] = whitened_innovations(track).astype(np.float32)
    res[f"{name}/restarted"] = track.records["restarted"]
    flags = ("correct", "target_present", "jump", "coasted") if full else ("correct", "target_present")
    for flag in flags:
        res[f"{name}/{flag}"] = getattr(log, flag)
    if full:
        res[f"{name}/pred"] = track.records["predicted_z"][0] * scale  # run 0 only, for the figure


def _detection_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The Monte Carlo runs of one filter: the four variants at each grid value of :data:`FALSE_ALARMS` (the
    Pfa-consistent map, the primary, and the brief's denser false alarms) on the same truth and target candidates,
    and the restart delay tuned on tuning runs (on the primary map)."""
    prm = ctx.params
    host = ctx.host
    sensor = host.sensor("dtv-pbr")
    tx, rx = np.asarray(sensor.params["tx"], dtype=float), np.asarray(sensor.params["rx"], dtype=float)
    spec = host.filter(prm["filter"])
    restart, tuning_share, tuning_rmse, tuning_chosen_on = tune_restart(
        host, prm["filter"], int(prm["tuning_runs"]), int(prm["frames"]), float(prm["sigma_a"]))
    truth = drone_truth(generator(ctx.seed, "paper002", "truth"), int(prm["runs"]), int(prm["frames"]), FRAME_DT)
    model = sensor.measurement_model()
    lam = wavelength(sensor.params["frequency_hz"])
    res: dict[str, np.ndarray] = {"truth_rr": range_and_rate(truth.states, tx, rx), "times": truth.times,
                                  "tx": tx, "rx": rx, "wavelength": np.array(lam),
                                  "model_std": np.asarray(model.stated_std, dtype=float),
                                  "tuning/candidates": np.asarray(RESTART_CANDIDATES),
                                  "tuning/track_share": tuning_share, "tuning/track_rmse": tuning_rmse,
                                  "tuning/on_target": tuning_chosen_on,
                                  "tuning/chosen": np.array(restart),
                                  "tuning/runs": np.array(int(prm["tuning_runs"])),
                                  "fa/rate": np.array([CLUTTER_PFA["false_alarm_rate"], CLUTTER_BRIEF["false_alarm_rate"]]),
                                  "fa/density": np.array([false_alarm_density(CLUTTER_PFA),
                                                          false_alarm_density(CLUTTER_BRIEF)])}
    scans = detection_scans(host, truth, ctx.seed, CLUTTER_PFA)
    for name, (track, sc) in run_variants(spec, scans, model, FRAME_DT, float(prm["sigma_a"]), ctx.seed,
                                          wavelength_m=lam, restart_after=restart).items():
        _save_variant(res, name, track, sc)
    res["run0/cand_z"] = np.where(scans.valid[0, ..., None], scans.z[0], np.nan)
    res["run0/cand_origin"] = scans.origin[0]
    res["run0/xyz"] = truth.states[0, :, :3]
    res["candidates_per_frame"] = np.array(scans.valid[:, 1:].sum(axis=2).mean())
    del scans, track, sc  # what was kept is in res; the brief's scans follow (the report's peak memory)
    brief = detection_scans(host, truth, ctx.seed, CLUTTER_BRIEF)
    for name, (track, sc) in run_variants(spec, brief, model, FRAME_DT, float(prm["sigma_a"]), ctx.seed,
                                          wavelength_m=lam, restart_after=restart).items():
        _save_variant(res, f"brief/{name}", track, sc, full=False)
    res["brief/candidates_per_frame"] = np.array(brief.valid[:, 1:].sum(axis=2).mean())
    return res


def _floor(caf, config: PCLConfig) -> float:
    """Mean noise power of a map away from zero Doppler: median / ln 2 (exponential cells)."""
    k = np.arange(caf.doppler_hz.size) - caf.doppler_hz.size // 2
    return float(np.median(caf.power[:, np.abs(k) >= config.zero_doppler_bins]) / np.log(2.0))


def _near(cands, true_range: float, true_doppler: float, config: PCLConfig) -> bool:
    """A candidate within 1.5 range and 1.5 Doppler bins of the truth (the target is detected)."""
    return bool(np.any((np.abs(cands.range_m - true_range) <= 1.5 * config.range_bin) &
                       (np.abs(cands.doppler_hz - true_doppler) <= 1.5 * config.doppler_bin)))


def _series(res: dict, prefix: str, host, prm, ctx, scans: Scans, truth_rr: np.ndarray, restart: int) -> None:
    """NN tracks (no gate and gate) through a signal-level series; saves the per-frame flags and estimates."""
    sensor = host.sensor("dtv-pbr")
    tracks = run_variants(host.filter(prm["filter"]), scans, sensor.measurement_model(), FRAME_DT, SIGMA_A,
                          ctx.seed, variants=("rr-nogate", "rr-gate"),
                          wavelength_m=wavelength(sensor.params["frequency_hz"]), restart_after=restart)
    sigma = np.asarray(sensor.measurement_model().stated_std, float)
    res[f"{prefix}/candidates"] = scans.valid[0].sum(axis=1)
    for name, (track, sc) in tracks.items():
        log = association_log(track, sc)
        res[f"{prefix}/{name}/est"] = track.mean[0]
        res[f"{prefix}/{name}/correct"] = log.correct[0]
        res[f"{prefix}/{name}/target_present"] = log.target_present[0]
        res[f"{prefix}/{name}/on"] = (log.target_present & on_target(track.records["chosen_z"], truth_rr, sigma))[0]


def _signal_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The benign scene (the paper's row): one frame's CAF before and after ECA with its candidates; with
    ``frames > 1`` a signal-level series tracked by NN."""
    prm = ctx.params
    host = ctx.host
    sensor = host.sensor("dtv-pbr")
    tx, rx = sensor.params["tx"], sensor.params["rx"]
    config, scene = PCLConfig(pfa=PFA), BENIGN_SCENE
    frames = int(prm["frames"])
    truth = drone_truth(generator(ctx.seed, "paper002", "truth"), 1, max(frames, 2), FRAME_DT)
    x_true = range_and_rate(truth.states, tx, rx)[:, :frames]
    ref, surv = frame_signals(x_true[0, 0][None], generator(ctx.seed, "paper002", "signal"), config, scene)
    raw = process_frame(ref, surv, config, cancel=False)[0]
    caf, cands, _ = process_frame(ref, surv, config)
    floor = _floor(caf, config)
    res = {
        "caf_db": (10 * np.log10(caf.power / floor)).astype(np.float32),
        "caf_raw_db": (10 * np.log10(raw.power / floor)).astype(np.float32),
        "range_m": caf.range_m, "doppler_hz": caf.doppler_hz,
        "det_range": cands.range_m, "det_doppler": cands.doppler_hz, "det_strength": cands.strength_db,
        "true_range": np.array(x_true[0, 0, 0]),
        "true_doppler": np.array(range_rate_to_doppler(x_true[0, 0, 1], config.wavelength)),
        "wavelength": np.array(config.wavelength),
    }
    if frames > 1:
        scans, = simulate_scans_multi(x_true, truth.times[:frames], generator(ctx.seed, "paper002", "signal-series"),
                                      [config], scene)
        res["series/truth_rr"] = x_true[0]
        _series(res, "series", host, prm, ctx, scans, x_true, int(prm["restart"]))
    return res


def _ghosts(cands, true_range: float, true_doppler: float, config: PCLConfig) -> int:
    """Candidates on the target's Doppler (within 1.5 bins) but away from its range (more than 1.5 bins): the
    ghosts that reference multipath makes (an echo correlated with a delayed copy in the reference), or the
    echo's range sidelobes."""
    on_row = np.abs(cands.doppler_hz - true_doppler) <= 1.5 * config.doppler_bin
    return int(np.sum(on_row & (np.abs(cands.range_m - true_range) > 1.5 * config.range_bin)))


def _ghost_level(caf, true_range: float, true_doppler: float, paths, config: PCLConfig) -> float:
    """The strongest multipath ghost relative to the target (dB): the largest ``|chi|^2`` within one cell of
    ``(R - path, f_D)`` over the reference's multipath ``paths`` whose ghost falls on the map, over the largest
    within one cell of the target's own ``(R, f_D)``; NaN when no ghost falls on the map (``R - path < 1`` bin)."""
    P = caf.power
    di = int(np.argmin(np.abs(caf.doppler_hz - true_doppler)))
    d = slice(max(di - 1, 0), di + 2)

    def cell(r: float) -> float:
        li = int(round(r / config.range_bin))
        return float(P[max(li - 1, 0):li + 2, d].max())

    ghosts = [cell(true_range - p) for p in paths if true_range - p >= config.range_bin]
    return 10 * np.log10(max(ghosts) / cell(true_range)) if ghosts else float("nan")


def _demanding_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The demanding scene (CPI 0.5 s, clutter to 17.5 km, reference multipath): one frame processed without ECA,
    with the brief's 16 taps, with taps to the map's edge (``L`` = 102) and with taps past the farthest clutter
    (600); without the reference cleaning; without the pilot removal; the folded single-precision chain checked
    against the float64 reference on that frame; with ``frames > 1`` a series (detections with ``L`` and 600
    taps, NN tracks on the 600-tap candidates)."""
    prm = ctx.params
    host = ctx.host
    sensor = host.sensor("dtv-pbr")
    tx, rx = sensor.params["tx"], sensor.params["rx"]
    full = demanding_config(PCLConfig(pfa=PFA))
    brief = replace(full, eca_taps=ECA_TAPS_BRIEF)
    edge = replace(full, eca_taps=full.lags)
    uncleaned = replace(full, cleaning_taps=0)
    scene = DEMANDING_SCENE
    frames = int(prm["frames"])
    truth = drone_truth(generator(ctx.seed, "paper002", "truth"), 1, max(frames, 2), FRAME_DT)
    x_true = range_and_rate(truth.states, tx, rx)[:, :frames]
    true_range, true_doppler = x_true[0, 0, 0], float(range_rate_to_doppler(x_true[0, 0, 1], full.wavelength))
    ref, surv = frame_signals(x_true[0, 0][None], generator(ctx.seed, "paper002", "demanding"), full, scene)
    raw = process_frame(ref, surv, full, cancel=False)[0]
    caf_b, cands_b, _ = process_frame(ref, surv, brief)
    caf_e, cands_e, _ = process_frame(ref, surv, edge)
    caf_f, cands_f, _ = process_frame(ref, surv, full)
    caf_u, cands_u, _ = process_frame(ref, surv, uncleaned)
    nopilot = process_frame(ref, surv, replace(full, pilot_removal=False))[1]
    # the NumPy twin in double precision: the reference cleaned by a full-length convolution, ECA on the whole
    # CPI, then the batches CAF
    ref64 = clean_reference(ref.astype(np.complex128), full)
    clean, _ = eca(surv.astype(np.complex128), ref64, full.eca_taps, full.eca_loading)
    ref_caf = caf_batches(clean, ref64, full)
    del clean, ref64
    ref_cands, _ = cfar_candidates(ref_caf, full)
    floor = _floor(caf_f, full)
    same = len(ref_cands.range_m) == len(cands_f.range_m) and np.allclose(
        np.c_[ref_cands.range_m, ref_cands.doppler_hz], np.c_[cands_f.range_m, cands_f.doppler_hz], atol=1e-2)
    res = {
        "range_m": caf_f.range_m, "doppler_hz": caf_f.doppler_hz, "wavelength": np.array(full.wavelength),
        "true_range": np.array(true_range), "true_doppler": np.array(true_doppler),
        "taps": np.array([0, brief.eca_taps, edge.eca_taps, full.eca_taps]),
        "cpi": np.array(full.cpi), "clutter_max": np.array(max(scene.clutter_ranges)),
        "cleaning_taps": np.array(full.cleaning_taps), "eca_reach": np.array((full.eca_taps - 1) * full.range_bin),
        "caf_raw_db": (10 * np.log10(raw.power / floor)).astype(np.float32),
        "caf_edge_db": (10 * np.log10(caf_e.power / floor)).astype(np.float32),
        "caf_full_db": (10 * np.log10(caf_f.power / floor)).astype(np.float32),
        "edge/det_range": cands_e.range_m, "edge/det_doppler": cands_e.doppler_hz,
        "full/det_range": cands_f.range_m, "full/det_doppler": cands_f.doppler_hz,
        "full/det_strength": cands_f.strength_db,
        # target detected with 16, L and 600 taps
        "detected": np.array([_near(c, true_range, true_doppler, full) for c in (cands_b, cands_e, cands_f)]),
        # how far the floor of 16 / L taps / no cleaning lies above the 600-tap cleaned floor (dB)
        "floor_rise_db": np.array([10 * np.log10(_floor(c, full) / floor) for c in (caf_b, caf_e, caf_u)]),
        "ghosts": np.array([_ghosts(cands_f, true_range, true_doppler, full),
                            _ghosts(cands_u, true_range, true_doppler, full)]),
        # the strongest multipath ghost relative to the target (dB): with / without the cleaning
        "ghost_db": np.array([_ghost_level(c, true_range, true_doppler, scene.reference_multipath_ranges, full)
                              for c in (caf_f, caf_u)]),
        "uncleaned/candidates": np.array(len(cands_u.range_m)),
        "uncleaned/detected": np.array(_near(cands_u, true_range, true_doppler, full)),
        "nopilot/candidates": np.array(len(nopilot.range_m)),
        "nopilot/on_target_row": np.array(int(np.sum(np.abs(nopilot.doppler_hz - true_doppler) <= 1.5 * full.doppler_bin))),
        # |chi_folded - chi_reference|^2 over the noise floor (dB), worst cell; the same candidates?
        "accuracy/max_err_db": np.array(10 * np.log10(np.max(np.abs(caf_f.chi - ref_caf.chi) ** 2) / floor)),
        "accuracy/same_candidates": np.array(bool(same)),
        "accuracy/max_strength_diff_db": np.array(float(np.max(np.abs(ref_cands.strength_db - cands_f.strength_db)))
                                                  if same and len(cands_f.range_m) else 0.0),
    }
    del ref, surv
    if frames > 1:
        scans_f, scans_e = simulate_scans_multi(x_true, truth.times[:frames],
                                                generator(ctx.seed, "paper002", "demanding-series"), [full, edge],
                                                scene)
        res["series/truth_rr"] = x_true[0]
        for tag, sc in (("edge", scans_e), ("full", scans_f)):
            res[f"series/{tag}/detected"] = ((sc.origin == 0) & sc.valid)[0].any(axis=1)
            res[f"series/{tag}/candidates"] = sc.valid[0].sum(axis=1)
        _series(res, "series/track", host, prm, ctx, scans_f, x_true, int(prm["restart"]))
    return res


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    filters = tuple(options.filters) or ("kf",)
    tuning_runs = int(v.get("tuning_runs", TUNING_RUNS["quick"]))
    out = [Task(f"detection-{name}", {"runs": int(v["runs"]), "frames": int(v["frames"]), "filter": name,
                                      "sigma_a": SIGMA_A, "tuning_runs": tuning_runs}, _detection_task)
           for name in filters]
    # the signal-level series use the gated tracker's restart delay tuned for the first filter (the same rule)
    restart = {"restart_rule": "tuned on the detection-level tuning runs", "tuning_runs": tuning_runs}
    out.append(Task("signal", {"frames": int(v["signal_frames"]), "filter": filters[0], **restart},
                    _with_restart(_signal_task)))
    out.append(Task("signal-demanding", {"frames": int(v["demanding_frames"]), "filter": filters[0], **restart},
                    _with_restart(_demanding_task)))
    return out


def _run_with_restart(task, ctx: TaskContext):
    """Run ``task`` with ``params["restart"]`` set by :func:`tune_restart` (cheap next to a signal series)."""
    prm = dict(ctx.params)
    if int(prm["frames"]) > 1:
        prm["restart"] = tune_restart(ctx.host, prm["filter"], int(prm["tuning_runs"]), 120, SIGMA_A)[0]
    else:
        prm["restart"] = RESTART_CANDIDATES[0]  # no series: the delay is never used
    return task(replace(ctx, params=prm))


def _with_restart(task):
    """``task`` run by :func:`_run_with_restart`: a partial of module-level functions, so that the report can
    send it to a worker process (a closure cannot be pickled)."""
    return partial(_run_with_restart, task)


# -- criteria ----------------------------------------------------------------------------------------------


def _detection_results(results) -> list[tuple[str, Mapping[str, np.ndarray]]]:
    return [(k[len("detection-"):], r) for k, r in results.items() if k.startswith("detection-")]


def _replicate(samples: tuple, statistic, holds) -> tuple[int, int]:
    """In how many single runs (the paper's protocol: one flight of ~1 minute) the criterion holds."""
    def one(*arrays) -> bool:
        value = statistic(*arrays)
        return bool(np.isfinite(value) and holds(value))
    return replication_rate(samples, 1, one, replications=REPLICATIONS, seed=0)


def _criterion(cid, text, samples, statistic, threshold, direction, holds, detail_extra="", **kw) -> Criterion:
    return criterion_from_runs(cid, text, samples, statistic, threshold, direction, min_n=MIN_RUNS,
                               replication=_replicate(samples, statistic, holds), detail=detail_extra, **kw)


def _judge_map(res: Mapping[str, np.ndarray], filt: str, gated: str, restart: int, prefix: str = "",
               where: str = "") -> list[Criterion]:
    """Criteria 1-4 of one gate variant on one false-alarm map (``prefix``: ``""`` for the primary map,
    ``"brief/"`` for the brief's), in a fixed order: C1 on track, C1 track RMSE, C2 R, C2 Rdot, C3, C4."""
    tag = f"{filt}, " + ("gate d2<=9.21, restart " + str(restart) if gated == "gate" else "no gate, as the paper")
    s = variant_sums(res, f"{prefix}rr-{gated}")
    sv = variant_sums(res, f"{prefix}rv-{gated}")
    m = variant_metrics(res, f"{prefix}rr-{gated}")
    mv = metrics_from_sums(sv)
    sigma = _sigma(res)
    where = f"{where}; " if where else ""
    out = [_criterion(
        f"C1 on track ({tag})",
        "The track persists over all frames without locking onto clutter: the track estimate lies within 3 sigma "
        f"of the truth (|R_hat - R| <= {ON_TARGET_SIGMAS * sigma[0]:g} m and |Rdot_hat - Rdot| <= "
        f"{ON_TARGET_SIGMAS * sigma[1]:g} m/s) in >= {100 * TRACK_SHARE_MIN:g} % of the frames (all frames k >= 1, "
        "the target's candidate present or not; frame 0 holds the prior)",
        (s["track_in"], s["frames"]), stat_track_share, TRACK_SHARE_MIN, ">=", lambda v: v >= TRACK_SHARE_MIN,
        f"{where}diagnostics, not judged: the chosen candidate within 3 sigma of the truth in "
        f"{100 * m['on_target']:.1f} % of the frames with a target candidate (the former stand-in), NN chose the "
        f"target's own candidate in {100 * m['nn_correct']:.1f} %; track within 3 sigma at the last frame in "
        f"{100 * m['final_on_track']:.1f} % of runs; {m['restarts_per_run']:.2f} restarts/run",
        published="no numbers; claims a continuous track")]
    out.append(_criterion(
        f"C1 track RMSE ({tag})",
        f"The track stays on the target: range RMSE of the estimate over all frames <= {sigma[0]:g} m "
        "(one measurement's sigma)",
        (s["track_se_r"], s["frames"]), stat_rmse, float(sigma[0]), "<=", lambda v: v <= sigma[0],
        f"{where}range-rate RMSE over all frames {m['track_rmse_rd']:.3f} m/s", published="no numbers"))
    for comp, key, unit in (("R", "r", "m"), ("Rdot", "rd", "m/s")):
        out.append(_criterion(
            f"C2 RMSE {comp} ({tag})",
            f"RMSE({comp}_hat) < RMSE({comp}_meas) against truth (frames where the chosen candidate is on "
            "target): the ratio < 1",
            (s[f"kf_se_{key}"], s[f"meas_se_{key}"]), stat_rmse_ratio, 1.0, "<", lambda v: v < 1.0,
            f"{where}RMSE {comp}: KF {m[f'rmse_{key}_kf']:.3g} {unit} vs chosen measurement "
            f"{m[f'rmse_{key}_meas']:.3g} {unit}",
            published="claims a temporally smoothed trajectory"))
    out.append(_criterion(
        f"C3 smoothness ({tag})",
        "std of the first difference of R_hat <= 0.5 x that of the selected measurements (consecutive "
        "on-target frames)",
        (s["d_n"], s["d_est"], s["d_est2"], s["d_meas"], s["d_meas2"]), stat_smoothness, 0.5, "<=",
        lambda v: v <= 0.5, where.rstrip("; "), published="claims a continuous, smoothed trajectory"))
    lo, hi = CONSISTENT_TAIL
    tail = m["nis_over_95"]
    # precondition (docs/paper002.md): which of two models is 'worse' says nothing about the state choice when the
    # range / range-rate model is itself inconsistent on the judged updates
    consistent = Precondition(
        "range / range-rate model consistent", bool(lo <= tail <= hi),
        f"NIS > 5.99 in {100 * tail:.1f} % of its on-target updates (5 % expected); the comparison is judged only "
        f"within [{100 * lo:g}, {100 * hi:g}] %", {"nis_over_95": tail, "band": [lo, hi]})
    out.append(_criterion(
        f"C4 ablation NIS ({tag})",
        "Doppler read as a monostatic radial velocity (v = lambda f_D / 2) in a range-velocity model gives a "
        "worse innovation consistency: min(|tail_mono - 5 %| - |tail_rr - 5 %|, |lag1_mono| - |lag1_rr|) > 0",
        (s["nis_over"], s["nis_n"], s["lag_ab"], s["lag_aa"], s["lag_bb"],
         sv["nis_over"], sv["nis_n"], sv["lag_ab"], sv["lag_aa"], sv["lag_bb"]),
        stat_ablation, 0.0, ">", lambda v: v > 0.0,
        f"{where}on-target updates: NIS > 5.99 in {100 * m['nis_over_95']:.1f} % (range-rate) vs "
        f"{100 * mv['nis_over_95']:.1f} % (monostatic), 5 % expected; mean NIS {m['nis_mean']:.2f} vs "
        f"{mv['nis_mean']:.2f} (2 expected); lag-1 correlation of the whitened range innovations "
        f"{m['lag1_r']:.2f} vs {mv['lag1_r']:.2f} (0 expected)",
        published="claims the range-rate state keeps the model physically consistent",
        preconditions=(consistent,)))
    return out


def criteria(results) -> list[Criterion]:
    """The brief's 'reproduced if' criteria (docs/paper002.md, "Criteria"), each with n, a 95 % bootstrap
    interval over runs, a three-way verdict and its replication over single runs (the paper's one flight).

    The verdicts are those at the primary false-alarm rate; every criterion also carries its verdicts across
    :data:`FALSE_ALARMS` (``Criterion.across``), judged on the same runs at each grid value."""
    out = []
    for filt, res in _detection_results(results):
        restart = int(res["tuning/chosen"])
        n = int(np.asarray(res["truth_rr"]).shape[0])
        for gated in ("nogate", "gate"):
            at = {}
            for value in FALSE_ALARMS.grid:
                _, prefix = FALSE_ALARM_MAPS[value]
                at[value] = _judge_map(res, filt, gated, restart, prefix,
                                       "" if value == FALSE_ALARMS.primary else FALSE_ALARMS.label(value))
            note = (f"the same {n} runs (truth and target candidates) at every value; restart delay tuned on the "
                    "primary map")
            primary = at[FALSE_ALARMS.primary]
            out.extend(replace(c, across=c.across + judge_across(
                FALSE_ALARMS, {v: at[v][i] for v in FALSE_ALARMS.grid}, {v: note for v in FALSE_ALARMS.grid}))
                for i, c in enumerate(primary))
    return out


# -- tables ----------------------------------------------------------------------------------------------


_ROWS = (
    ("C1: track estimate within 3 sigma of the truth, 45 m and 1.5 m/s (% of frames k >= 1)", "track_share", 100.0,
     ">= 90"),
    ("track range RMSE over all frames (m)", "track_rmse_r", 1.0, "<= 15"),
    ("track range-rate RMSE over all frames (m/s)", "track_rmse_rd", 1.0, "-"),
    ("diagnostic (C1's former stand-in): chosen candidate within 3 sigma (% of frames with a target candidate)",
     "on_target", 100.0, "-"),
    ("diagnostic: NN chose the target's own candidate (%)", "nn_correct", 100.0, "-"),
    ("track within 3 sigma (45 m, 1.5 m/s) at the last frame (% of runs)", "final_on_track", 100.0, "-"),
    ("frames coasted (%)", "coast_rate", 100.0, "-"),
    ("frames with a range jump > 3 sigma (%)", "jump_rate", 100.0, "-"),
    ("restarts per run", "restarts_per_run", 1.0, "-"),
    ("RMSE R on target, KF (m)", "rmse_r_kf", 1.0, "< selected measurement"),
    ("RMSE R on target, selected measurement (m)", "rmse_r_meas", 1.0, "-"),
    ("RMSE Rdot on target, KF (m/s)", "rmse_rd_kf", 1.0, "< selected measurement"),
    ("RMSE Rdot on target, selected measurement (m/s)", "rmse_rd_meas", 1.0, "-"),
    ("std dR_hat / std dR_meas", "smooth_ratio", 1.0, "<= 0.5"),
    ("mean NIS (on-target updates)", "nis_mean", 1.0, "2"),
    ("NIS > 5.99 (%)", "nis_over_95", 100.0, "5"),
    ("lag-1 correlation of range innovations", "lag1_r", 1.0, "0"),
)
_ABLATION_ROWS = ("track_share", "track_rmse_r", "on_target", "nn_correct", "final_on_track", "restarts_per_run")


def make_table(results) -> Table:
    """Table 1: the detection level, without and with the gate, for the range-rate model and the ablation, on the
    Pfa-consistent map (the primary value of :data:`FALSE_ALARMS`) and (range-rate only) on the brief's denser false
    alarms (its other grid value)."""
    cols = ("quantity", "filter", "model / false alarms", "no gate (paper)", "gate d2 <= 9.21", "required",
            "published")
    rows = []
    for filt, res in _detection_results(results):
        for kind, label in (("rr", "range / range-rate"), ("rv", "monostatic range-velocity (ablation)")):
            m = {g: variant_metrics(res, f"{kind}-{g}") for g in ("nogate", "gate")}
            for name, key, scale, req in _ROWS:
                rows.append((name, filt, label, round(scale * m["nogate"][key], 3), round(scale * m["gate"][key], 3),
                             req if kind == "rr" else "-",
                             "no numbers; claims a continuous, smoothed R / Rdot track" if kind == "rr" else
                             "claims the range-rate state keeps the model physically consistent"))
        mb = {g: variant_metrics(res, f"brief/rr-{g}") for g in ("nogate", "gate")}
        label = f"range / range-rate, brief's false alarms ({float(res['fa/rate'][1]):g}/frame on +-20 m/s)"
        for name, key, scale, req in _ROWS:
            if key in _ABLATION_ROWS:
                rows.append((name, filt, label, round(scale * mb["nogate"][key], 3), round(scale * mb["gate"][key], 3),
                             req, "-"))
    return Table(cols, tuple(rows))


def make_scene_table(results) -> Table:
    """Table 2: the false-alarm models, the tuning of the restart delay, and the signal level (both scenes)."""
    cols = ("quantity", "value", "note")
    rows = []
    found = _detection_results(results)
    if found:
        filt, res = found[0]
        rate, density = res["fa/rate"], res["fa/density"]
        rows.append(("false alarms per frame (a declared unknown): from the CFAR's Pfa (primary) / the brief's",
                     f"{rate[0]:.3f} / {rate[1]:g}",
                     f"Pfa {PFA:g} x {FA_CELLS} cells (102 range x 119 Doppler bins, CPI 0.5 s); the brief's count is "
                     f"{rate[1] / rate[0]:.1f} x ours"))
        rows.append(("false-alarm density near the target (1 / (m m/s)): ours / the brief's",
                     f"{density[0]:.3g} / {density[1]:.3g}",
                     f"the brief's is {density[1] / density[0]:.1f} x ours (uniform on +-20 m/s, not +-50 m/s)"))
        rows.append(("candidates per frame after the zero-Doppler notch: ours / the brief's",
                     f"{float(res['candidates_per_frame']):.2f} / {float(res['brief/candidates_per_frame']):.2f}",
                     "target (P_D 0.9) + false alarms + residue leaking through the notch"))
        for name, _ in found:
            r = dict(found)[name]
            rows.append((f"tuning ({name}): restart delay chosen (frames)", int(r["tuning/chosen"]),
                         f"rule (docs/paper002.md): the highest C1 track share (estimate within 45 m and 1.5 m/s, "
                         f"frames k >= 1) wins, shares within {100 * TUNING_TIE:g} point tie, a tie goes to the "
                         f"shorter delay; {int(r['tuning/runs'])} tuning runs (seed {TUNING_SEED}, key 'tuning', the "
                         f"primary map); per candidate delay: track share (the rule's score) and, not read by the "
                         f"rule, track range RMSE and chosen-candidate share: " + ", ".join(
                             f"{d}: {100 * v:.2f} %, {e:.0f} m, {100 * c:.2f} %" for d, v, e, c in
                             zip(r["tuning/candidates"], r["tuning/track_share"], r["tuning/track_rmse"],
                                 r["tuning/on_target"]))))
    sig = results.get("signal")
    if sig is not None:
        rows.append(("benign scene, one frame: candidates / target detected", f"{len(sig['det_range'])} / "
                     f"{_near_arrays(sig['det_range'], sig['det_doppler'], sig)}", "noise-like reference, direct path "
                     "+30 dB, clutter within 390 m, ECA 16 taps"))
        _series_rows(rows, sig, "series", "benign scene")
    dem = results.get("signal-demanding")
    if dem is not None:
        taps = dem["taps"]
        rise = dem["floor_rise_db"]
        rows.append((f"demanding scene, one {float(dem['cpi']):g} s frame: target detected with {taps[1]} / "
                     f"{taps[2]} / {taps[3]} ECA taps",
                     " / ".join(str(bool(d)) for d in dem["detected"]),
                     f"the floor over the {taps[3]}-tap floor: {float(rise[0]):.1f} dB with {taps[1]} taps (0-450 m), "
                     f"{float(rise[1]):.1f} dB with {taps[2]} (the map's 0-3 km edge: the clutter beyond it is left); "
                     f"{taps[3]} taps reach {float(dem['eca_reach']) / 1e3:.2f} km, past the farthest "
                     f"clutter at {float(dem['clutter_max']) / 1e3:g} km"))
        rows.append((f"demanding scene, one frame: candidates with {taps[3]} taps", len(dem["full/det_range"]),
                     f"ATSC 8-VSB, direct path +60 dB, clutter 30 m - {float(dem['clutter_max']) / 1e3:g} km at "
                     f"+50..+30 dB, reference multipath cleaned"))
        rows.append(("demanding scene: reference multipath (300 m, 750 m, 1.5 km at -10, -14, -18 dB) without / with "
                     f"the cleaning stage ({int(dem['cleaning_taps'])} taps): candidates on the target's Doppler row away "
                     "from it; the strongest ghost (at the echo's range minus a path) relative to the target (dB); "
                     "target detected; floor over the cleaned floor (dB)",
                     f"{int(dem['ghosts'][1])} / {int(dem['ghosts'][0])}; {float(dem['ghost_db'][1]):.1f} / "
                     f"{float(dem['ghost_db'][0]):.1f}; {bool(dem['uncleaned/detected'])} / "
                     f"{bool(dem['detected'][2])}; {float(rise[2]):+.1f} / 0",
                     "the uncleaned reference correlates the echo with its delayed copies (ghosts at the echo's range "
                     "minus each path) and leaves ECA fitting the clutter with a distorted reference; the cleaned one "
                     "is coloured a little by the predictor (range sidelobes of a strong echo about 23 dB down, 3 "
                     "bins off, can pass the CFAR)"))
        rows.append(("demanding scene: candidates without the pilot removal (on the target's Doppler)",
                     f"{int(dem['nopilot/candidates'])} ({int(dem['nopilot/on_target_row'])})",
                     "the 8-VSB pilot carrier makes a ridge over every range at the target's Doppler"))
        rows.append(("folded single-precision ECA + CAF vs the float64 reference: worst cell error over the noise "
                     "floor (dB); same candidates", f"{float(dem['accuracy/max_err_db']):.1f}; "
                     f"{bool(dem['accuracy/same_candidates'])}",
                     f"candidate strengths within {float(dem['accuracy/max_strength_diff_db']):.1e} dB"))
        if "series/truth_rr" in dem:
            n = dem["series/truth_rr"].shape[0]
            for tag, k in (("edge", taps[2]), ("full", taps[3])):
                rows.append((f"demanding scene, {n} frames: target detected with {k} taps (% of frames)",
                             round(100 * float(np.mean(dem[f"series/{tag}/detected"])), 1),
                             f"{float(np.mean(dem[f'series/{tag}/candidates'])):.2f} candidates per frame"))
            _series_rows(rows, dem, "series/track", f"demanding scene ({taps[3]} taps)")
    return Table(cols, tuple(rows))


def _near_arrays(ranges, dopplers, sig) -> bool:
    """A candidate within 1.5 bins of the true cell of a saved signal frame."""
    dr = abs(sig["range_m"][1] - sig["range_m"][0])
    dd = abs(sig["doppler_hz"][1] - sig["doppler_hz"][0])
    return bool(np.any((np.abs(ranges - sig["true_range"]) <= 1.5 * dr) &
                       (np.abs(dopplers - sig["true_doppler"]) <= 1.5 * dd)))


def _series_rows(rows: list, sig, prefix: str, label: str) -> None:
    if f"{prefix}/candidates" not in sig:
        return
    truth = sig["series/truth_rr"]
    n = truth.shape[0]
    for g, gl in (("nogate", "no gate"), ("gate", "gate")):
        present = sig[f"{prefix}/rr-{g}/target_present"].astype(bool)
        on = sig[f"{prefix}/rr-{g}/on"].astype(bool)
        err = sig[f"{prefix}/rr-{g}/est"][1:] - truth[1:]
        rows.append((f"{label}, 1 run x {n} frames, {gl}: on target (%) / track RMSE R (m) / Rdot (m/s)",
                     f"{100 * on.sum() / max(present.sum(), 1):.1f} / {np.sqrt(np.mean(err[:, 0] ** 2)):.2f} / "
                     f"{np.sqrt(np.mean(err[:, 1] ** 2)):.3f}",
                     f"target candidate in {100 * present[1:].mean():.1f} % of frames; "
                     f"{float(np.mean(sig[f'{prefix}/candidates'])):.2f} candidates per frame"))


# -- figures ---------------------------------------------------------------------------------------------


def _first(results) -> tuple[str, Mapping[str, np.ndarray]]:
    found = _detection_results(results)
    if not found:
        raise InputError("paper 002: the results hold no detection task")
    return found[0]


def fig_geometry_data(results) -> dict[str, np.ndarray]:
    _, res = _first(results)
    return {"tx": res["tx"], "rx": res["rx"], "path": res["run0/xyz"],
            "sector": np.array([SECTOR_CENTRE_DEG, SECTOR_DEG, SECTOR_RANGES[1] * 1.3])}


def draw_geometry(data, fig) -> None:
    tx, rx, path = data["tx"], data["rx"], data["path"]
    centre, width, reach = data["sector"]
    ref_dir = np.degrees(np.arctan2(tx[1] - rx[1], tx[0] - rx[0]))
    for i, (title, lim) in enumerate((("layout (local ENU)", None), ("surveillance area", reach * 1.15))):
        ax = fig.add_subplot(1, 2, i + 1)
        ax.plot([tx[0], rx[0]], [tx[1], rx[1]], color="0.5", lw=1, label="baseline")
        ax.plot(*tx[:2], "^", color="tab:red", ms=9, label="Tx (DTV, 701 MHz)")
        ax.plot(*rx[:2], "s", color="tab:blue", ms=7, label="Rx")
        angles = np.radians(np.linspace(centre - width / 2, centre + width / 2, 40))
        wedge = np.vstack([rx[:2], rx[:2] + reach * np.c_[np.cos(angles), np.sin(angles)], rx[:2]])
        ax.fill(wedge[:, 0], wedge[:, 1], color="tab:green", alpha=0.15, label="surveillance sector")
        arrow = 0.25 * (reach if lim else np.hypot(*(tx[:2] - rx[:2])))
        ax.annotate("", xy=rx[:2] + arrow * np.array([np.cos(np.radians(centre)), np.sin(np.radians(centre))]),
                    xytext=rx[:2], arrowprops={"arrowstyle": "->", "color": "tab:green"})
        ax.annotate("", xy=rx[:2] + arrow * np.array([np.cos(np.radians(ref_dir)), np.sin(np.radians(ref_dir))]),
                    xytext=rx[:2], arrowprops={"arrowstyle": "->", "color": "tab:red"})
        ax.plot(path[:, 0], path[:, 1], color="k", lw=1.2, label="drone path (run 0)")
        ax.plot(path[0, 0], path[0, 1], "o", color="k", ms=4)
        if lim:
            ax.set_xlim(-0.3 * lim, lim)
            ax.set_ylim(-0.65 * lim, 0.65 * lim)
        ax.set_aspect("equal", adjustable="box" if lim else "datalim")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_title(title + ("\narrows: reference antenna (red, to Tx), surveillance (green)" if i == 0 else ""),
                     fontsize=8)
        if i == 0:
            ax.legend(fontsize=6, loc="center left")


def fig_trajectory_data(results) -> dict[str, np.ndarray]:
    filt, res = _first(results)
    out = {"filter": np.array([filt]), "truth": res["truth_rr"][0], "times": res["times"],
           "candidates": res["run0/cand_z"], "wavelength": res["wavelength"]}
    for g in ("nogate", "gate"):
        out[f"{g}/chosen"] = res[f"rr-{g}/chosen"][0]
        out[f"{g}/est"] = res[f"rr-{g}/est"][0]
        out[f"{g}/pred"] = res[f"rr-{g}/pred"]
    return out


#: The [R, Rdot] state the figures draw: its declared names and units label the axes (workbench.plot).
_RR_MOTION = range_rate_model(FRAME_DT, SIGMA_A)
#: The measurement dimension of both models' NIS ([R, Rdot] and [R, v]): the chi-square's degrees of freedom.
_NIS_DOF = 2


def _truth_rr(data) -> Truth:
    """Run 0's [R, Rdot] truth as a one-run ``Truth`` over the frame times, for ``workbench.plot``."""
    return Truth(np.asarray(data["truth"], dtype=float)[None], np.asarray(data["times"], dtype=float))


def draw_trajectory(data, fig) -> None:
    lam = float(data["wavelength"])
    cands = data["candidates"].reshape(-1, 2)
    for i, (g, title) in enumerate((("nogate", "no gate (paper)"), ("gate", "gate d2 <= 9.21"))):
        ax = fig.add_subplot(1, 2, i + 1)
        ax.plot(cands[:, 0], cands[:, 1], ".", color="0.8", ms=2, label="all candidates", gid="candidates")
        wbplot.truth(ax, _truth_rr(data), motion=_RR_MOTION, color="0.55")
        ax.plot(*data[f"{g}/chosen"].T, ":", color="k", marker=".", ms=3, lw=0.8, label="selected (NN) measurements",
                gid="selected")
        wbplot.estimate(ax, data[f"{g}/est"][None], motion=_RR_MOTION, color="tab:red", label="KF estimate",
                        linewidth=1.3)
        wbplot.estimate(ax, data[f"{g}/pred"][None], motion=_RR_MOTION, color="purple", linestyle=":",
                        label="one-step prediction", linewidth=1.3)
        span = data["truth"]
        ax.set_xlim(max(span[:, 0].min() - 150, -50), span[:, 0].max() + 150)
        ax.set_ylim(span[:, 1].min() - 4, span[:, 1].max() + 4)
        ax.set_xlabel(f"bistatic range {wbplot.state_label(_RR_MOTION, 0)}")
        ax.set_ylabel(f"bistatic range-rate {wbplot.state_label(_RR_MOTION, 1)}")
        sec = ax.secondary_yaxis("right", functions=(lambda r: -r / lam, lambda f: -f * lam))
        sec.set_ylabel("Doppler f_D = -Rdot / lambda (Hz)")
        ax.set_title(f"{data['filter'][0]}, run 0, {title}", fontsize=9)
        if i == 0:
            ax.legend(fontsize=6, loc="best")


def draw_time(data, fig) -> None:
    t = data["times"]
    labels = (("bistatic range", 0), ("range-rate", 1))
    for i, (label, c) in enumerate(labels):
        ax = fig.add_subplot(2, 1, i + 1)
        wbplot.truth(ax, _truth_rr(data), dims=c, motion=_RR_MOTION, color="0.6")
        ax.plot(t, data["nogate/chosen"][:, c], ".", color="k", ms=3, label="selected measurement (no gate)",
                gid="selected")
        wbplot.estimate(ax, data["nogate/est"][None], dims=c, times=t, motion=_RR_MOTION, color="tab:red",
                        label="KF, no gate")
        wbplot.estimate(ax, data["gate/est"][None], dims=c, times=t, motion=_RR_MOTION, color="tab:blue",
                        linestyle="--", label="KF, gate")
        lo, hi = data["truth"][:, c].min(), data["truth"][:, c].max()
        pad = 0.5 * (hi - lo) + (50 if c == 0 else 2)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(f"{label} {wbplot.state_label(_RR_MOTION, c)}")
        if i == 1:
            ax.set_xlabel("time (s)")
        else:
            ax.set_xlabel("")
            ax.legend(fontsize=6, ncol=2)


def fig_caf_data(results) -> dict[str, np.ndarray]:
    sig = results["signal"]
    keys = ("caf_db", "caf_raw_db", "range_m", "doppler_hz", "det_range", "det_doppler", "det_strength",
            "true_range", "true_doppler", "wavelength")
    return {k: sig[k] for k in keys}


def draw_caf(data, fig) -> None:
    r, f = data["range_m"], data["doppler_hz"]
    lam = float(data["wavelength"])
    for i, (key, title) in enumerate((("caf_raw_db", "before ECA"), ("caf_db", "after ECA, with CA-CFAR detections"))):
        ax = fig.add_subplot(1, 2, i + 1)
        dr, df = r[1] - r[0], f[1] - f[0]
        im = ax.imshow(data[key].T, origin="lower", aspect="auto", cmap="viridis", vmin=-5, vmax=45,
                       extent=(r[0] - dr / 2, r[-1] + dr / 2, f[0] - df / 2, f[-1] + df / 2), interpolation="nearest")
        if i == 1:
            ax.plot(data["det_range"], data["det_doppler"], "o", mfc="none", mec="w", ms=8, label="CFAR candidates")
            ax.plot(data["true_range"], data["true_doppler"], "x", color="tab:red", ms=7, label="true target")
            ax.legend(fontsize=6, loc="lower right")
            fig.colorbar(im, ax=ax, label="|chi|^2 (dB over noise)")
        ax.set_xlabel("bistatic range (m)")
        ax.set_ylabel("Doppler (Hz)")
        sec = ax.secondary_yaxis("right", functions=(lambda x: -x * lam, lambda v: -v / lam))
        sec.set_ylabel("range-rate (m/s)" if i == 1 else "")
        ax.set_title(title, fontsize=9)


def fig_nis_data(results) -> dict[str, np.ndarray]:
    _, res = _first(results)
    edges = np.linspace(0.0, 20.0, 41)
    out = {"edges": edges}
    sigma = _sigma(res)
    for v in VARIANTS:
        white = np.asarray(res[f"{v}/white"], dtype=float)
        # on-target updates: the target's candidate exists and the chosen one is within 3 sigma of the truth
        good = np.asarray(res[f"{v}/target_present"], bool) & on_target(res[f"{v}/chosen"], res["truth_rr"], sigma)
        nis = np.sum(white ** 2, axis=-1)[good & np.isfinite(white[..., 0])]
        out[f"{v}/density"] = np.histogram(np.minimum(nis, edges[-1] - 1e-9), edges, density=True)[0]
        out[f"{v}/samples"] = np.array(nis.size)
    return out


def draw_nis(data, fig) -> None:
    for i, g in enumerate(("nogate", "gate")):
        ax = fig.add_subplot(1, 2, i + 1)
        wbplot.nis_density(ax, data[f"rr-{g}/density"], data["edges"], _NIS_DOF, label="range / range-rate",
                           color="tab:red")
        wbplot.nis_density(ax, data[f"rv-{g}/density"], data["edges"], _NIS_DOF, label="monostatic velocity",
                           color="tab:orange", linestyle="--", reference=False)
        ax.set_xlabel(f"NIS ({_NIS_DOF} dof; on-target updates; last bin: >= {data['edges'][-2]:g})")
        ax.set_title("no gate (paper)" if g == "nogate" else "gate d2 <= 9.21", fontsize=9)
        ax.legend(fontsize=6)


def fig_demanding_data(results) -> dict[str, np.ndarray]:
    dem = results["signal-demanding"]
    keys = ("caf_raw_db", "caf_edge_db", "caf_full_db", "range_m", "doppler_hz", "wavelength", "true_range",
            "true_doppler", "taps", "edge/det_range", "edge/det_doppler", "full/det_range", "full/det_doppler",
            "detected", "clutter_max")
    return {k: dem[k] for k in keys}


def draw_demanding(data, fig) -> None:
    r, f = data["range_m"], data["doppler_hz"]
    lam = float(data["wavelength"])
    taps = data["taps"]
    reach = float(data["clutter_max"]) / 1e3
    panels = (("caf_raw_db", None, "no ECA"), ("caf_edge_db", "edge", f"ECA {taps[2]} taps (the map, 0-3 km)"),
              ("caf_full_db", "full", f"ECA {taps[3]} taps (past the clutter's {reach:g} km)"))
    dr, df = r[1] - r[0], f[1] - f[0]
    for i, (key, det, title) in enumerate(panels):
        ax = fig.add_subplot(1, 3, i + 1)
        img = data[key]
        floor = float(np.median(img[:, np.abs(f) > df]))  # this panel's floor over the full-tap floor
        im = ax.imshow(img.T, origin="lower", aspect="auto", cmap="viridis", vmin=floor - 5, vmax=floor + 50,
                       extent=(r[0] - dr / 2, r[-1] + dr / 2, f[0] - df / 2, f[-1] + df / 2), interpolation="nearest")
        if det is not None:
            ax.plot(data[f"{det}/det_range"], data[f"{det}/det_doppler"], "o", mfc="none", mec="w", ms=8,
                    label="CFAR candidates")
            found = bool(data["detected"][i])
            title += f"; target {'detected' if found else 'lost'}"
        title += f"\nnoise floor {floor:+.0f} dB (colour scale: floor -5 to +50 dB)"
        ax.plot(data["true_range"], data["true_doppler"], "x", color="tab:red", ms=7, label="true target")
        ax.set_xlabel("bistatic range (m)")
        ax.set_ylabel("Doppler (Hz)")
        sec = ax.secondary_yaxis("right", functions=(lambda x: -x * lam, lambda v: -v / lam))
        sec.set_ylabel("range-rate (m/s)")
        ax.set_title(title, fontsize=7)
        fig.colorbar(im, ax=ax, pad=0.18, label=f"|chi|^2 (dB over the {taps[3]}-tap noise floor)")
        if i == 2:
            ax.legend(fontsize=6, loc="lower right")


# -- recipe ----------------------------------------------------------------------------------------------


NOTES = f"""\
Synthetic substitute for the measured PNU / Hwangryeongsan data (not available). Geometry: Tx (0, -8400, 420) m,
Rx (0, 0, 60) m, local ENU, 701 MHz (lambda = 0.42766 m). Sign convention everywhere: f_D = -Rdot / lambda
(positive Doppler = approaching); bistatic range = excess path |p-Tx| + |p-Rx| - |Tx-Rx| in truth, CAF and KF.
Drone: starts at (250, 150, 60) m already flying its first leg; legs of U(10, 15) s towards random waypoints in a
60 deg sector centred on east (150-700 m from Rx) at 4-10 m/s; velocity changes between legs at <= 1 m/s^2.
Detection level: target candidate with P_D = 0.9, noise N(0, 15^2) m and N(0, 0.4^2) m/s, strength N(18, 2^2) dB;
zero-Doppler residue Poisson(3) per frame; false alarms consistent with the CA-CFAR: Poisson(Pfa x cells) =
Poisson({FA_RATE:.2f}) per frame (Pfa 1e-4, {FA_CELLS} cells of the 0-3 km, +-50 m/s map at CPI 0.5 s), uniform on the
map, strength 10 log10(ln(1/Pfa) + Exp(1)) dB. The false-alarm rate is a declared unknown (the paper gives no
detector settings): every criterion is also judged at the brief's Poisson(4) on +-20 m/s ({false_alarm_density(CLUTTER_BRIEF) / false_alarm_density(CLUTTER_PFA):.1f} x our
density) on the same runs. Candidates with |f_D| < 1 bin (2 Hz) are removed before association.
KF: x = [R, Rdot], F = [[1, 0.5], [0, 1]], Q white-noise acceleration sigma_a = 1 m/s^2, H = I, R = diag(15^2, 0.5^2),
P0 = diag(50^2, 5^2) at the strongest candidate of frame 0 (mid-map if frame 0 is empty).
NN: Mahalanobis d2 with S = H P- H^T + R. Variants: no gate (the paper: always the nearest candidate) and gate
d2 <= 9.21 with coasting and a restart on the strongest candidate after a delay tuned by a fixed rule on tuning
runs only (candidates {', '.join(map(str, RESTART_CANDIDATES))} frames; the highest C1 track share over the tuning runs of
seed {TUNING_SEED}, key 'tuning', primary map; shares within {100 * TUNING_TIE:g} point tie, a tie goes to the shortest).
Ablation: the same candidates read as v = -lambda f_D / 2 in a [R, v] constant-velocity model, sigma_v = 0.25 m/s;
its velocity is reported as 2 v.
Criteria (frames k >= 1): C1 on track = the track estimate within 3 sigma of the truth (45 m and 1.5 m/s) in >= 90 %
of all frames k >= 1 (the chosen candidate's share, the former stand-in, is a diagnostic in table 1); C1 track RMSE
= range RMSE of the estimate over all frames <= 15 m; C2 / C3 / C4 on the frames whose chosen candidate is on
target; C4 is not judgeable where the range / range-rate model's own NIS tail is outside [2.5, 10] %. Every criterion: n = Monte Carlo runs, a 95 % percentile bootstrap over runs, a
three-way verdict (>= {MIN_RUNS} runs to decide), and how many of {REPLICATIONS} single runs (the paper's protocol: one
flight) it holds in.
Signal level, benign scene (the paper's row): f_s = 10 MHz, noise-like 6 MHz reference, CPI 0.25 s, direct path +30 dB,
5 clutter patches within 390 m, echo -20 dB; ECA 16 taps; CAF: 250 batches of 10,000 samples, 0-3 km x +-30
Doppler bins of 4 Hz. Demanding scene: CPI 0.5 s (the detection level's; 500 batches, +-59 Doppler bins of 2 Hz),
ATSC 8-VSB reference (pilot, segment and field syncs; Korea's terrestrial HD standard), direct path +60 dB, 23
clutter patches 30 m - 17.5 km at +50 to +30 dB (beyond the 3 km map as well), reference SNR 70 dB, and the
reference antenna receiving the transmitter over three more paths (300 m, 750 m, 1.5 km of excess path at -10,
-14, -18 dB); the reference cleaned by a delayed linear predictor (64 taps over lags 8-71, i.e. 240 m - 2.1 km,
fitted by least squares on the CPI's own autocorrelation with the pilot's share taken out; Kinoshita et al., IEEE
TASLP 2009); ECA over 600 taps (0-17.96 km: the rule 'cancel every lag at which the scene holds clutter'); the
pilot carrier is removed from the reference batches (frequency refined per CPI). Cleaning and ECA are folded into
the batches CAF in single precision (checked against the float64 reference on the demanding frame). Hamming
across batches; CA-CFAR guard 2 x 2, training 8 x 8, Pfa 1e-4, zero-Doppler bin excluded, 3 x 3 local maxima,
parabolic refinement."""

PUBLISHED = {
    "numbers": "none (2-page conference paper on measured data)",
    "claims": "individual measurements fluctuate discontinuously; the KF gives a continuous, temporally smoothed "
              "bistatic range / range-rate trajectory; using range-rate instead of velocity keeps the state model "
              "physically consistent with the Doppler measurement",
    "figures": "Fig. 1 experiment layout; Fig. 2 range-Doppler trajectory (black dotted: selected measurements, "
               "red: KF estimates, purple dotted: predictions)",
}

RECIPE = RecipeSpec(
    paper=PAPER,
    title="Bistatic range / range-rate Kalman filter tracking, DTV passive radar (synthetic substitute)",
    # demanding_frames: the demanding scene's series (0.5 s CPIs of 5 M samples; its synthesis is the dearest part)
    sizes={"quick": {"runs": 500, "frames": 120, "signal_frames": 1, "demanding_frames": 1,
                     "tuning_runs": TUNING_RUNS["quick"]},
           "full": {"runs": 3000, "frames": 120, "signal_frames": 120, "demanding_frames": 60,
                    "tuning_runs": TUNING_RUNS["full"]}},
    tasks=tasks,
    figures=(
        FigureSpec("fig1", "Experiment layout (local ENU): Tx, Rx, baseline, reference and surveillance antenna "
                   "directions, surveillance sector and the drone path of run 0.", fig_geometry_data, draw_geometry,
                   size=(10.0, 4.6)),
        FigureSpec("fig2", "Range-Doppler trajectory of run 0 (x: bistatic range in m; y: range-rate in m/s, right "
                   "axis Doppler in Hz): selected NN measurements black dotted, KF estimates red, one-step "
                   "predictions purple dotted; grey: all candidates and truth.", fig_trajectory_data,
                   draw_trajectory, size=(10.0, 4.6)),
        FigureSpec("fig2b", "Bistatic range R(t) and range-rate Rdot(t) of run 0 against truth (grey).",
                   fig_trajectory_data, draw_time, size=(7.0, 5.5)),
        FigureSpec("fig3", "Benign scene (the paper's row): cross-ambiguity map of one signal-level frame "
                   "(|chi|^2 in dB over the noise floor) before and after ECA, with the CA-CFAR candidates "
                   "(zero-Doppler bin excluded) and the true target.", fig_caf_data, draw_caf, size=(10.0, 4.2)),
        FigureSpec("fig4", "Ablation: NIS histograms of the range / range-rate model and of the monostatic "
                   "range-velocity model on on-target updates, against the chi-square(2) density.",
                   fig_nis_data, draw_nis, size=(9.0, 3.8)),
        FigureSpec("fig5", "Demanding scene (ATSC 8-VSB, direct path +60 dB, clutter to 17.5 km, reference multipath "
                   "cleaned, CPI 0.5 s): one frame without ECA, with taps over the map's 0-3 km (102: the clutter "
                   "beyond the map buries the target) and with 600 taps (0-18 km: the target is back), with the "
                   "CA-CFAR candidates and the true target.",
                   fig_demanding_data, draw_demanding, size=(15.0, 4.4)),
    ),
    tables=(TableSpec("table1", "Reproduced-if quantities over the Monte Carlo runs, without and with the gate, on "
                      "the Pfa-consistent map and on the brief's denser false alarms (the paper publishes no "
                      "numbers).", make_table),
            TableSpec("table2", "False-alarm models, the tuning of the restart delay (on tuning runs only), and the "
                      "signal level: the benign scene (the paper's row) and the demanding scene (16 / 102 / 600 ECA "
                      "taps, reference multipath with and without cleaning, the 8-VSB pilot, the folded "
                      "single-precision chain against the float64 reference).",
                      make_scene_table)),
    criteria=criteria,
    unknowns=(FALSE_ALARMS,),
    default_filters=("kf",),
    published=PUBLISHED,
    notes=NOTES,
)
