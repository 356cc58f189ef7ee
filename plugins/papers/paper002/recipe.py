"""Paper 002: bistatic range / range-rate Kalman tracking of a drone with a DTV passive radar.

Pipeline (detection level, every Monte Carlo run at once)::

    drone truth (ENU) --dtv-pbr--> target candidate [R, Rdot] with P_D
                      --pbr-false-alarms--> zero-Doppler residue + false alarms
                      --pbr-zero-doppler--> drop |f_D| < 1 bin
                      --NN tracker + filter ("kf" by default) on [R, Rdot]--> track

and the ablation: the same candidates read as a monostatic radial velocity ``v = lambda f_D / 2`` in a
range-velocity model.  One signal-level frame (reference + surveillance samples, ECA, CAF, CA-CFAR)
gives the cross-ambiguity map; the full size also tracks through a whole signal-level series.
Choices where the paper is silent are in :data:`NOTES` (and ``docs/paper002.md``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Mapping

import numpy as np

from workbench.sensing.bistatic import monostatic_velocity, range_and_rate, range_rate_to_doppler
from workbench.models import MeasurementModel, constant_velocity, linear_measurement, range_rate_model
from workbench.metrics import association_log
from workbench.sensing.bistatic import wavelength
from workbench.tracking import GATE_99, NearestNeighbour, Track, run, strongest_candidate_prior
from .signal import PCLConfig, SignalScene, caf_batches, cfar_candidates, eca, frame_signals, simulate_scans
from workbench.rng import generator
from workbench.specs import Criterion, FigureSpec, RecipeOptions, RecipeSpec, Table, TableSpec, Task, TaskContext
from workbench.types import InputError, Scans, Truth

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
DOPPLER_BIN_DETECTION = 2.0  # Hz = 1 / CPI at the detection level (CPI 0.5 s, as the brief's R_cov)
REINIT_AFTER = 6  # gated tracker: restart on the strongest candidate after 6 frames (3 s) with no update [U]
ON_TRACK_M = 100.0  # |R_hat - R| within this counts as "on the target" (about 3 range bins)
NIS_95 = 5.991  # chi-square(2) 0.95 quantile
VARIANTS = ("rr-nogate", "rr-gate", "rv-nogate", "rv-gate")


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


def detection_scans(host, truth: Truth, seed: int) -> Scans:
    """Target candidates + map clutter with the zero-Doppler bins removed (common random numbers)."""
    target = host.sensor("dtv-pbr").simulate(truth, generator(seed, "paper002", "sensor"))
    clutter = host.clutter_generator("pbr-false-alarms").generate(truth, generator(seed, "paper002", "clutter"))
    return host.clutter_remover("pbr-zero-doppler").remove(target.merge(clutter),
                                                           doppler_bin_hz=DOPPLER_BIN_DETECTION)


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
                 variants=VARIANTS, wavelength_m: float = 0.0) -> dict[str, tuple[Track, Scans]]:
    """NN tracks of one filter for each variant (model x gate) on the same candidates.

    ``rr``: state ``[R, Rdot]``, :func:`~workbench.models.range_rate_model`, the sensor's model.
    ``rv``: state ``[R, v]``, a constant-velocity model with the same ``sigma_a``, candidates read as
    ``v = -lambda f_D / 2``.  ``gate``: ``d2 <= 9.21`` with coasting and a restart after
    :data:`REINIT_AFTER` frames without an update; ``nogate``: always the nearest candidate.
    """
    scans_rv = as_monostatic_velocity(scans, wavelength_m)
    setups = {"rr": (scans, range_rate_model(dt, sigma_a), model, np.diag(np.square(P0))),
              "rv": (scans_rv, constant_velocity(1, dt, sigma_a), mismatched_model(model),
                     np.diag(np.square([P0[0], P0[1] / 2.0])))}
    out = {}
    for name in variants:
        kind, gated = name.split("-")
        sc, motion, meas, cov0 = setups[kind]
        prior, index = strongest_candidate_prior(sc.scan(0), cov0, FALLBACK)
        gate, reinit = (GATE_99, REINIT_AFTER) if gated == "gate" else (None, None)
        out[name] = (track_nearest_neighbour(spec, prior, motion, meas, sc, generator(seed, "paper002", "filter", name),
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


def write_synthetic_candidates(path, host, seed: int = 2002, frames: int = 120):
    """Write the shipped example ``examples/data/pcl_candidates_synthetic.csv``: one detection-level run.

    The candidates are those the tracker sees (target, residue and false alarms after the zero-Doppler
    notch), labelled SYNTHETIC in the header comments.
    """
    from workbench.recorded.pcl import write_pcl_candidates

    truth = drone_truth(generator(seed, "paper002", "truth"), 1, frames, FRAME_DT)
    scans = detection_scans(host, truth, seed)
    freq = host.sensor("dtv-pbr").params["frequency_hz"]
    return write_pcl_candidates(path, scans, comments=(
        "SYNTHETIC: not measured data. Detection-level simulation of the paper-002 scenario (DTV passive radar,",
        "701 MHz, Tx (0, -8400, 420) m, Rx (0, 0, 60) m, one drone, P_D 0.9, Poisson(3) zero-Doppler residue and",
        "Poisson(4) false alarms per frame, |f_D| < 2 Hz removed), written by "
        f"workbench_papers.paper002.recipe.write_synthetic_candidates(seed={seed}, frames={frames}).",
        "Sign convention: range-rate = -wavelength * doppler_hz (positive Doppler = approaching).",
    ), frequency_hz=freq)


# -- tasks ------------------------------------------------------------------------------------------------


def _detection_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    prm = ctx.params
    host = ctx.host
    sensor = host.sensor("dtv-pbr")
    tx, rx = np.asarray(sensor.params["tx"], dtype=float), np.asarray(sensor.params["rx"], dtype=float)
    truth = drone_truth(generator(ctx.seed, "paper002", "truth"), int(prm["runs"]), int(prm["frames"]), FRAME_DT)
    scans = detection_scans(host, truth, ctx.seed)
    model = sensor.measurement_model()
    lam = wavelength(sensor.params["frequency_hz"])
    tracks = run_variants(host.filter(prm["filter"]), scans, model, FRAME_DT, float(prm["sigma_a"]), ctx.seed,
                          wavelength_m=lam)
    res: dict[str, np.ndarray] = {"truth_rr": range_and_rate(truth.states, tx, rx), "times": truth.times,
                                  "tx": tx, "rx": rx, "wavelength": np.array(lam)}
    for name, (track, sc) in tracks.items():
        log = association_log(track, sc)
        scale = np.array([1.0, 2.0]) if name.startswith("rv") else np.ones(2)  # rv: report v as 2 v = Rdot
        res[f"{name}/est"] = (track.mean * scale).astype(np.float32)
        res[f"{name}/chosen"] = (track.records["chosen_z"] * scale).astype(np.float32)
        res[f"{name}/pred"] = (track.records["predicted_z"][0] * scale)  # run 0 only, for the figure
        res[f"{name}/white"] = whitened_innovations(track).astype(np.float32)
        for flag in ("correct", "target_present", "jump", "coasted"):
            res[f"{name}/{flag}"] = getattr(log, flag)
        res[f"{name}/restarted"] = track.records["restarted"]
    res["run0/cand_z"] = np.where(scans.valid[0, ..., None], scans.z[0], np.nan)
    res["run0/cand_origin"] = scans.origin[0]
    res["run0/xyz"] = truth.states[0, :, :3]
    return res


def _signal_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """One signal-level frame (CAF before/after ECA, CFAR); with ``frames > 1`` an NN track through a series."""
    prm = ctx.params
    host = ctx.host
    sensor = host.sensor("dtv-pbr")
    tx, rx = sensor.params["tx"], sensor.params["rx"]
    config, scene = PCLConfig(), SignalScene()
    frames = int(prm["frames"])
    truth = drone_truth(generator(ctx.seed, "paper002", "truth"), 1, max(frames, 2), FRAME_DT)
    x_true = range_and_rate(truth.states, tx, rx)[:, :frames]
    ref, surv = frame_signals(x_true[0, 0][None], generator(ctx.seed, "paper002", "signal"), config, scene)
    raw = caf_batches(surv, ref, config)
    clean, _ = eca(surv, ref, config.eca_taps)
    caf = caf_batches(clean, ref, config)
    cands, _ = cfar_candidates(caf, config)
    k = np.arange(caf.doppler_hz.size) - caf.doppler_hz.size // 2
    # mean noise power away from zero Doppler: median / ln 2 for exponential cells
    floor = np.median(caf.power[:, np.abs(k) >= config.zero_doppler_bins]) / np.log(2.0)
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
        scans = simulate_scans(x_true, truth.times[:frames], generator(ctx.seed, "paper002", "signal-series"),
                               config, scene)
        tracks = run_variants(host.filter(prm["filter"]), scans, sensor.measurement_model(), FRAME_DT, SIGMA_A,
                              ctx.seed, variants=("rr-nogate", "rr-gate"),
                              wavelength_m=wavelength(sensor.params["frequency_hz"]))
        res["series/truth_rr"] = x_true[0]
        res["series/candidates"] = scans.valid[0].sum(axis=1)
        for name, (track, sc) in tracks.items():
            log = association_log(track, sc)
            res[f"series/{name}/est"] = track.mean[0]
            res[f"series/{name}/correct"] = log.correct[0]
            res[f"series/{name}/target_present"] = log.target_present[0]
    return res


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    filters = tuple(options.filters) or ("kf",)
    out = [Task(f"detection-{name}", {"runs": int(v["runs"]), "frames": int(v["frames"]), "filter": name,
                                      "sigma_a": SIGMA_A}, _detection_task) for name in filters]
    out.append(Task("signal", {"frames": int(v["signal_frames"]), "filter": filters[0]}, _signal_task))
    return out


# -- metrics ---------------------------------------------------------------------------------------------


def _lag1(e: np.ndarray, pair: np.ndarray) -> float:
    """Lag-1 correlation of a whitened innovation component over the consecutive frame pairs ``pair``."""
    a, b = e[:, 1:][pair], e[:, :-1][pair]
    return float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b))) if a.size else float("nan")


def variant_metrics(res: Mapping[str, np.ndarray], variant: str) -> dict[str, float]:
    """The brief's 'reproduced if' quantities for one variant of one detection task (frames k >= 1)."""
    truth = np.asarray(res["truth_rr"], dtype=float)
    est = np.asarray(res[f"{variant}/est"], dtype=float)
    chosen = np.asarray(res[f"{variant}/chosen"], dtype=float)
    correct = np.asarray(res[f"{variant}/correct"], dtype=bool)
    present = np.asarray(res[f"{variant}/target_present"], dtype=bool)
    white = np.asarray(res[f"{variant}/white"], dtype=float)
    nis = np.sum(white ** 2, axis=-1)
    err, merr = est - truth, chosen - truth
    later = np.zeros(correct.shape, dtype=bool)
    later[:, 1:] = True
    on = np.abs(err[..., 0]) <= ON_TRACK_M
    picked = np.isfinite(chosen[..., 0]) & later & ~np.asarray(res[f"{variant}/restarted"], dtype=bool)
    # consistency is judged where the filter tracks the target: NN chose the target and the track is on it
    good = correct & on
    pair = good[:, 1:] & good[:, :-1]
    # smoothness: consecutive frames whose NN choices were both the target candidate
    both = correct[:, 1:] & correct[:, :-1]
    return {
        "nn_correct": float(correct[present].mean()) if present.any() else float("nan"),
        "on_track": float(on[:, 1:].mean()),
        "final_on_track": float(on[:, -1].mean()),
        "coast_rate": float(np.mean(res[f"{variant}/coasted"][:, 1:])),
        "jump_rate": float(np.mean(res[f"{variant}/jump"][:, 1:])),
        "restarts_per_run": float(np.mean(np.sum(res[f"{variant}/restarted"], axis=1))),
        # RMSE on the frames where NN picked the target: KF estimate vs that (selected) measurement
        "rmse_r_kf": float(np.sqrt(np.mean(err[..., 0][correct] ** 2))),
        "rmse_r_meas": float(np.sqrt(np.mean(merr[..., 0][correct] ** 2))),
        "rmse_rdot_kf": float(np.sqrt(np.mean(err[..., 1][correct] ** 2))),
        "rmse_rdot_meas": float(np.sqrt(np.mean(merr[..., 1][correct] ** 2))),
        # the same over every frame with a selected measurement (clutter picks included)
        "rmse_r_kf_all": float(np.sqrt(np.mean(err[..., 0][picked] ** 2))),
        "rmse_r_meas_all": float(np.sqrt(np.mean(merr[..., 0][picked] ** 2))),
        "smooth_ratio": float(np.std(np.diff(est[..., 0], axis=1)[both]) /
                              np.std(np.diff(chosen[..., 0], axis=1)[both])),
        "nis_mean": float(np.mean(nis[good])),
        "nis_over_95": float(np.mean(nis[good] > NIS_95)),
        "nis_samples": int(good.sum()),
        "lag1_r": _lag1(white[..., 0], pair),
        "lag1_rdot": _lag1(white[..., 1], pair),
    }


def _detection_results(results) -> list[tuple[str, Mapping[str, np.ndarray]]]:
    return [(k[len("detection-"):], r) for k, r in results.items() if k.startswith("detection-")]


def criteria(results) -> list[Criterion]:
    out = []
    for filt, res in _detection_results(results):
        runs = res["truth_rr"].shape[0]
        for gated in ("nogate", "gate"):
            tag = f"{filt}, {'gate d2<=9.21' if gated == 'gate' else 'no gate, as the paper'}"
            m = variant_metrics(res, f"rr-{gated}")
            mv = variant_metrics(res, f"rv-{gated}")
            out.append(Criterion(
                f"C1 persistence ({tag})",
                "The track persists over all frames without locking onto clutter: NN picks the true-target "
                "candidate in >= 90 % of the frames where it exists",
                m["nn_correct"] >= 0.9,
                f"NN correct {100 * m['nn_correct']:.1f} % ({runs} runs x {res['truth_rr'].shape[1]} frames); "
                f"track on the target (|dR| <= {ON_TRACK_M:.0f} m) in {100 * m['on_track']:.1f} % of frames and "
                f"{100 * m['final_on_track']:.1f} % of runs at the last frame; coasting {100 * m['coast_rate']:.1f} %, "
                f"range jumps > 3 sigma {100 * m['jump_rate']:.1f} % of frames, {m['restarts_per_run']:.2f} restarts/run"))
            out.append(Criterion(
                f"C2 RMSE ({tag})",
                "RMSE(R_hat) < RMSE(R_meas) and RMSE(Rdot_hat) < RMSE(Rdot_meas) against truth",
                m["rmse_r_kf"] < m["rmse_r_meas"] and m["rmse_rdot_kf"] < m["rmse_rdot_meas"],
                f"frames where NN picked the target: R {m['rmse_r_kf']:.2f} m vs {m['rmse_r_meas']:.2f} m, "
                f"Rdot {m['rmse_rdot_kf']:.3f} vs {m['rmse_rdot_meas']:.3f} m/s; all frames with a selection: "
                f"R {m['rmse_r_kf_all']:.1f} m vs {m['rmse_r_meas_all']:.1f} m"))
            out.append(Criterion(
                f"C3 smoothness ({tag})",
                "std of the first difference of R_hat <= 0.5 x that of the selected measurements",
                m["smooth_ratio"] <= 0.5,
                f"ratio {m['smooth_ratio']:.3f} (consecutive frames whose NN choices were the target)"))
            out.append(Criterion(
                f"C4 ablation NIS ({tag})",
                "Doppler read as a monostatic radial velocity (v = lambda f_D / 2) in a range-velocity model gives "
                "a worse innovation consistency than the range / range-rate model",
                (abs(mv["nis_over_95"] - 0.05) > abs(m["nis_over_95"] - 0.05)) and
                (abs(mv["lag1_r"]) > abs(m["lag1_r"])),
                f"on-target updates: NIS > 5.99 in {100 * m['nis_over_95']:.1f} % (range-rate) vs "
                f"{100 * mv['nis_over_95']:.1f} % (monostatic), 5 % expected; mean NIS {m['nis_mean']:.2f} vs "
                f"{mv['nis_mean']:.2f} (2 expected); lag-1 correlation of the range innovations "
                f"{m['lag1_r']:.2f} vs {mv['lag1_r']:.2f} (0 expected); RMSE R {m['rmse_r_kf']:.1f} vs "
                f"{mv['rmse_r_kf']:.1f} m"))
    return out


# -- table -----------------------------------------------------------------------------------------------


_ROWS = (
    ("NN picks the target candidate (% of frames where it exists)", "nn_correct", 100.0, ">= 90"),
    ("track on the target, |dR| <= 100 m (% of frames)", "on_track", 100.0, "all frames"),
    ("frames coasted (%)", "coast_rate", 100.0, "-"),
    ("frames with a range jump > 3 sigma (%)", "jump_rate", 100.0, "-"),
    ("restarts per run", "restarts_per_run", 1.0, "-"),
    ("RMSE R, KF (m)", "rmse_r_kf", 1.0, "< selected measurement"),
    ("RMSE R, selected measurement (m)", "rmse_r_meas", 1.0, "-"),
    ("RMSE Rdot, KF (m/s)", "rmse_rdot_kf", 1.0, "< selected measurement"),
    ("RMSE Rdot, selected measurement (m/s)", "rmse_rdot_meas", 1.0, "-"),
    ("std dR_hat / std dR_meas", "smooth_ratio", 1.0, "<= 0.5"),
    ("mean NIS (on-target updates)", "nis_mean", 1.0, "2"),
    ("NIS > 5.99 (%)", "nis_over_95", 100.0, "5"),
    ("lag-1 correlation of range innovations", "lag1_r", 1.0, "0"),
)


def make_table(results) -> Table:
    cols = ("quantity", "filter", "model", "no gate", "gate d2 <= 9.21", "required", "published")
    rows = []
    for filt, res in _detection_results(results):
        for kind, label in (("rr", "range / range-rate"), ("rv", "monostatic range-velocity (ablation)")):
            m = {g: variant_metrics(res, f"{kind}-{g}") for g in ("nogate", "gate")}
            for name, key, scale, req in _ROWS:
                rows.append((name, filt, label, round(scale * m["nogate"][key], 3), round(scale * m["gate"][key], 3),
                             req if kind == "rr" else "-",
                             "no numbers; claims a continuous, smoothed R / Rdot track" if kind == "rr" else
                             "claims the range-rate state keeps the model physically consistent"))
    sig = results.get("signal")
    if sig is not None and "series/truth_rr" in sig:
        truth = sig["series/truth_rr"]
        vals = {}
        for g in ("nogate", "gate"):
            present = sig[f"series/rr-{g}/target_present"].astype(bool)
            err = sig[f"series/rr-{g}/est"][1:] - truth[1:]
            vals[g] = (float(100 * sig[f"series/rr-{g}/correct"][present].mean()),
                       float(np.sqrt(np.mean(err[:, 0] ** 2))), float(np.sqrt(np.mean(err[:, 1] ** 2))))
        frames = truth.shape[0]
        rows.append((f"signal level, 1 run x {frames} frames: NN picks the target (%)", "", "range / range-rate",
                     round(vals["nogate"][0], 1), round(vals["gate"][0], 1), ">= 90", "-"))
        rows.append(("signal level: RMSE R (m) / Rdot (m/s)", "", "range / range-rate",
                     f"{vals['nogate'][1]:.2f} / {vals['nogate'][2]:.3f}", f"{vals['gate'][1]:.2f} / {vals['gate'][2]:.3f}",
                     "-", "-"))
        rows.append(("signal level: candidates per frame (mean)", "", "", round(float(np.mean(sig["series/candidates"])), 2),
                     "", "-", "-"))
    return Table(cols, tuple(rows))


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


def draw_trajectory(data, fig) -> None:
    lam = float(data["wavelength"])
    cands = data["candidates"].reshape(-1, 2)
    for i, (g, title) in enumerate((("nogate", "no gate (paper)"), ("gate", "gate d2 <= 9.21"))):
        ax = fig.add_subplot(1, 2, i + 1)
        ax.plot(cands[:, 0], cands[:, 1], ".", color="0.8", ms=2, label="all candidates")
        ax.plot(data["truth"][:, 0], data["truth"][:, 1], color="0.55", lw=3, alpha=0.5, label="truth")
        ax.plot(*data[f"{g}/chosen"].T, ":", color="k", marker=".", ms=3, lw=0.8, label="selected (NN) measurements")
        ax.plot(*data[f"{g}/est"].T, "-", color="tab:red", lw=1.3, label="KF estimate")
        ax.plot(*data[f"{g}/pred"].T, ":", color="purple", lw=1.3, label="one-step prediction")
        span = data["truth"]
        ax.set_xlim(max(span[:, 0].min() - 150, -50), span[:, 0].max() + 150)
        ax.set_ylim(span[:, 1].min() - 4, span[:, 1].max() + 4)
        ax.set_xlabel("bistatic range R (m)")
        ax.set_ylabel("bistatic range-rate Rdot (m/s)")
        sec = ax.secondary_yaxis("right", functions=(lambda r: -r / lam, lambda f: -f * lam))
        sec.set_ylabel("Doppler f_D = -Rdot / lambda (Hz)")
        ax.set_title(f"{data['filter'][0]}, run 0, {title}", fontsize=9)
        if i == 0:
            ax.legend(fontsize=6, loc="best")


def draw_time(data, fig) -> None:
    t = data["times"]
    labels = (("bistatic range R (m)", 0), ("range-rate Rdot (m/s)", 1))
    for i, (label, c) in enumerate(labels):
        ax = fig.add_subplot(2, 1, i + 1)
        ax.plot(t, data["truth"][:, c], color="0.6", lw=3, alpha=0.6, label="truth")
        ax.plot(t, data["nogate/chosen"][:, c], ".", color="k", ms=3, label="selected measurement (no gate)")
        ax.plot(t, data["nogate/est"][:, c], "-", color="tab:red", lw=1.2, label="KF, no gate")
        ax.plot(t, data["gate/est"][:, c], "--", color="tab:blue", lw=1.2, label="KF, gate")
        lo, hi = data["truth"][:, c].min(), data["truth"][:, c].max()
        pad = 0.5 * (hi - lo) + (50 if c == 0 else 2)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(label)
        if i == 1:
            ax.set_xlabel("time (s)")
        else:
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
    for v in VARIANTS:
        white = np.asarray(res[f"{v}/white"], dtype=float)
        good = np.asarray(res[f"{v}/correct"], dtype=bool) & \
            (np.abs(np.asarray(res[f"{v}/est"], dtype=float)[..., 0] - res["truth_rr"][..., 0]) <= ON_TRACK_M)
        nis = np.sum(white ** 2, axis=-1)[good]
        out[f"{v}/density"] = np.histogram(np.minimum(nis, edges[-1] - 1e-9), edges, density=True)[0]
    return out


def draw_nis(data, fig) -> None:
    edges = data["edges"]
    mid = 0.5 * (edges[1:] + edges[:-1])
    for i, g in enumerate(("nogate", "gate")):
        ax = fig.add_subplot(1, 2, i + 1)
        ax.step(mid, data[f"rr-{g}/density"], where="mid", color="tab:red", label="range / range-rate")
        ax.step(mid, data[f"rv-{g}/density"], where="mid", color="tab:orange", ls="--", label="monostatic velocity")
        ax.plot(mid, 0.5 * np.exp(-mid / 2), color="k", lw=0.8, label="chi-square, 2 dof")
        ax.set_yscale("log")
        ax.set_xlabel("NIS (on-target updates; last bin: >= 19.5)")
        ax.set_ylabel("density")
        ax.set_title("no gate (paper)" if g == "nogate" else "gate d2 <= 9.21", fontsize=9)
        ax.legend(fontsize=6)


# -- recipe ----------------------------------------------------------------------------------------------


NOTES = """\
Synthetic substitute for the measured PNU / Hwangryeongsan data (not available). Geometry: Tx (0, -8400, 420) m,
Rx (0, 0, 60) m, local ENU, 701 MHz (lambda = 0.42766 m). Sign convention everywhere: f_D = -Rdot / lambda
(positive Doppler = approaching); bistatic range = excess path |p-Tx| + |p-Rx| - |Tx-Rx| in truth, CAF and KF.
Drone: starts at (250, 150, 60) m already flying its first leg; legs of U(10, 15) s towards random waypoints in a
60 deg sector centred on east (150-700 m from Rx) at 4-10 m/s; velocity changes between legs at <= 1 m/s^2 (the
brief's "piecewise-constant" legs with a finite turn; sigma_a = 1 m/s^2 matches this level).
Detection level: target candidate with P_D = 0.9, noise N(0, 15^2) m and N(0, 0.4^2) m/s, strength N(18, 2^2) dB;
zero-Doppler residue Poisson(3) (Rdot ~ N(0, 0.3^2), ~25 dB) and false alarms Poisson(4) per frame uniform on
[0, 3000] m x [-20, 20] m/s with strength 10 log10(ln(1/Pfa) + Exp(1)) dB (an exponential cell above the CFAR
threshold, Pfa = 1e-4); candidates with |f_D| < 1 bin (2 Hz for the 0.5 s CPI) are removed before association.
KF: x = [R, Rdot], F = [[1, 0.5], [0, 1]], Q white-noise acceleration sigma_a = 1 m/s^2, H = I, R = diag(15^2, 0.5^2),
P0 = diag(50^2, 5^2) at the strongest non-zero-Doppler candidate of frame 0 (mid-map if frame 0 is empty).
NN: Mahalanobis d2 with S = H P- H^T + R. Variants: no gate (the paper: always the nearest candidate) and gate
d2 <= 9.21 with coasting; the gated tracker restarts on the strongest candidate after 6 frames (3 s) without an
update (otherwise a track started on a false alarm coasts for ever).
Ablation: the same candidates read as v = -lambda f_D / 2 (the monostatic two-way formula, sign kept so that only the
factor 1/2 differs) in a [R, v] constant-velocity model with sigma_v = 0.25 m/s; its velocity is reported as 2 v.
Metrics (frames k >= 1; frame 0 holds the prior): NN correct = chosen candidate is the target's / frames where a
target candidate exists after the notch; RMSE on the frames where NN chose the target (KF estimate vs that
measurement); smoothness over consecutive frames with target choices; NIS, its 95 % tail and the lag-1
correlation of the whitened range innovations over on-target updates (NN chose the target, |dR| <= 100 m).
Signal level: f_s = 10 MHz, 6 MHz noise-like DTV surrogate, CPI 0.25 s (2.5 M samples), direct path +30 dB,
5 static clutter patches (5-20 dB) and the echo at -20 dB relative to the surveillance noise; ECA with 16 taps
(least squares, FFT correlations); CAF by the batches algorithm (250 batches of 10,000 samples, Hamming across
batches), 0-3 km (102 range bins of 29.98 m), +-30 Doppler bins of 4 Hz (+-51 m/s); CA-CFAR guard 2 x 2 and
training 8 x 8 cells on each side, Pfa = 1e-4, training cells taken outside the zero-Doppler bin, 3 x 3 local maxima,
parabolic refinement of range and Doppler."""

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
    sizes={"quick": {"runs": 500, "frames": 120, "signal_frames": 1},
           "full": {"runs": 3000, "frames": 120, "signal_frames": 120}},
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
        FigureSpec("fig3", "Cross-ambiguity map of one signal-level frame (|chi|^2 in dB over the noise floor) "
                   "before and after ECA, with the CA-CFAR candidates (zero-Doppler bin excluded) and the true "
                   "target.", fig_caf_data, draw_caf, size=(10.0, 4.2)),
        FigureSpec("fig4", "Ablation: NIS histograms of the range / range-rate model and of the monostatic "
                   "range-velocity model on on-target updates, against the chi-square(2) density.",
                   fig_nis_data, draw_nis, size=(9.0, 3.8)),
    ),
    tables=(TableSpec("table1", "Reproduced-if quantities over the Monte Carlo runs, without and with the gate "
                      "(the paper publishes no numbers).", make_table),),
    criteria=criteria,
    default_filters=("kf",),
    published=PUBLISHED,
    notes=NOTES,
)
