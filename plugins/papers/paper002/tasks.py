"""Paper 002's tasks: the detection level at each false-alarm rate (the primary and, as a sensitivity task, the
brief's), and the signal level's two scenes, each a single frame and a tracked series; :func:`tasks` lists them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from workbench.metrics import association_log
from workbench.rng import generator
from workbench.sensing.bistatic import range_and_rate, range_rate_to_doppler, wavelength
from workbench.specs import RecipeOptions, Task, TaskContext
from workbench.tracking import Track
from workbench.types import Scans

from .methods import on_target, run_variants, whitened_innovations
from .scenario import (BRIEF, CLUTTER_BRIEF, CLUTTER_PFA, DETECTION, ECA_TAPS_BRIEF, FRAME_DT, PFA,
                       RESTART_CANDIDATES, SIGMA_A, TUNING_RUNS, detection_scans, drone_truth, false_alarm_density)
from .signal import (BENIGN_SCENE, DEMANDING_SCENE, PCLConfig, caf_batches, cfar_candidates, clean_reference,
                     demanding_config, eca, frame_signals, process_frame, simulate_scans_multi)
from .tuning import tune_restart

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


def _detection_setup(ctx: TaskContext) -> tuple:
    """What both detection tasks start from: the filter, the tuned restart delay (with the tuning's figures), the
    truth of the reported runs (stream key ``"truth"``), the sensor's model and the wavelength."""
    prm = ctx.params
    host = ctx.host
    sensor = host.sensor("dtv-pbr")
    tx, rx = np.asarray(sensor.params["tx"], dtype=float), np.asarray(sensor.params["rx"], dtype=float)
    tuning = tune_restart(host, prm["filter"], int(prm["tuning_runs"]), int(prm["frames"]), float(prm["sigma_a"]))
    truth = drone_truth(generator(ctx.seed, "paper002", "truth"), int(prm["runs"]), int(prm["frames"]), FRAME_DT)
    return (host.filter(prm["filter"]), tuning, truth, tx, rx, sensor.measurement_model(),
            wavelength(sensor.params["frequency_hz"]))


def _detection_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The Monte Carlo runs of one filter at the primary value of :data:`FALSE_ALARMS` (the Pfa-consistent map):
    the four variants, and the restart delay tuned on tuning runs (on the primary map).  The other grid value is
    :func:`_brief_task`'s (a sensitivity task), on the same truth and target candidates."""
    prm = ctx.params
    spec, (restart, tuning_share, tuning_rmse, tuning_chosen_on), truth, tx, rx, model, lam = _detection_setup(ctx)
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
    scans = detection_scans(ctx.host, truth, ctx.seed, CLUTTER_PFA)
    for name, (track, sc) in run_variants(spec, scans, model, FRAME_DT, float(prm["sigma_a"]), ctx.seed,
                                          wavelength_m=lam, restart_after=restart).items():
        _save_variant(res, name, track, sc)
    res["run0/cand_z"] = np.where(scans.valid[0, ..., None], scans.z[0], np.nan)
    res["run0/cand_origin"] = scans.origin[0]
    res["run0/xyz"] = truth.states[0, :, :3]
    res["candidates_per_frame"] = np.array(scans.valid[:, 1:].sum(axis=2).mean())
    return res


def _brief_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The same Monte Carlo runs of one filter at the other grid value of :data:`FALSE_ALARMS` (the brief's denser
    false alarms): the same truth and target candidates as :func:`_detection_task` (the sensor's stream does not
    depend on the clutter), the restart delay tuned by the same rule on the same tuning runs (the primary map).
    Every array carries the ``brief/`` prefix, besides ``brief/truth_rr`` and ``brief/tuning_chosen`` (which the
    criteria check against the primary task's).  A sensitivity task: no primary verdict reads it."""
    prm = ctx.params
    spec, (restart, *_), truth, tx, rx, model, lam = _detection_setup(ctx)
    res: dict[str, np.ndarray] = {"brief/truth_rr": range_and_rate(truth.states, tx, rx),
                                  "brief/tuning_chosen": np.array(restart)}
    brief = detection_scans(ctx.host, truth, ctx.seed, CLUTTER_BRIEF)
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


def _series(res: dict, prefix: str, host, prm, ctx, scans: Scans, truth_rr: np.ndarray) -> None:
    """NN tracks through a signal-level series: without the gate, and with it at every candidate restart delay of
    :data:`RESTART_CANDIDATES` (one run: milliseconds each; the table shows the delay the tuning rule chose on the
    detection level's tuning runs, so that this task needs no tuning of its own).  Saves the per-frame flags and
    estimates under ``{prefix}/rr-nogate/...`` and ``{prefix}/rr-gate-{delay}/...``."""
    sensor = host.sensor("dtv-pbr")
    model, lam = sensor.measurement_model(), wavelength(sensor.params["frequency_hz"])
    spec = host.filter(prm["filter"])
    tracks = dict(run_variants(spec, scans, model, FRAME_DT, SIGMA_A, ctx.seed, variants=("rr-nogate",),
                               wavelength_m=lam))
    for delay in RESTART_CANDIDATES:
        (gated,) = run_variants(spec, scans, model, FRAME_DT, SIGMA_A, ctx.seed, variants=("rr-gate",),
                                wavelength_m=lam, restart_after=delay).values()
        tracks[f"rr-gate-{delay}"] = gated
    sigma = np.asarray(model.stated_std, float)
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
        "wavelength": np.array(config.wavelength), "filter": np.array(str(prm["filter"])),
    }
    if frames > 1:
        scans, = simulate_scans_multi(x_true, truth.times[:frames], generator(ctx.seed, "paper002", "signal-series"),
                                      [config], scene)
        res["series/truth_rr"] = x_true[0]
        _series(res, "series", host, prm, ctx, scans, x_true)
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
    against the float64 reference on that frame; with ``frames > 1`` a series with 600 taps (detections, NN
    tracks).  The series does not repeat the ``L``-tap processing: the single frame shows its floor (about 48 dB
    over the 600-tap floor, the target's echo about 40 dB over it), and each further frame would cost 0.37 s of
    CPU to show the same loss again."""
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
        "filter": np.array(str(prm["filter"])),
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
        scans_f, = simulate_scans_multi(x_true, truth.times[:frames],
                                        generator(ctx.seed, "paper002", "demanding-series"), [full], scene)
        res["series/truth_rr"] = x_true[0]
        res["series/full/detected"] = ((scans_f.origin == 0) & scans_f.valid)[0].any(axis=1)
        res["series/full/candidates"] = scans_f.valid[0].sum(axis=1)
        _series(res, "series/track", host, prm, ctx, scans_f, x_true)
    return res


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    filters = tuple(options.filters) or ("kf",)
    tuning_runs = int(v.get("tuning_runs", TUNING_RUNS["quick"]))
    out = []
    for name in filters:
        prm = {"runs": int(v["runs"]), "frames": int(v["frames"]), "filter": name, "sigma_a": SIGMA_A,
               "tuning_runs": tuning_runs}
        out.append(Task(DETECTION + name, prm, _detection_task, runs=int(v["runs"])))
        # the brief's false alarms: a non-primary grid value of FALSE_ALARMS only (the confirmation skips it)
        out.append(Task(BRIEF + name, prm, _brief_task, runs=int(v["runs"]), sensitivity=True))
    # the signal-level series: tracked with every candidate restart delay; the table shows the one tuned for the
    # first filter (the same rule, read from its detection task)
    out.append(Task("signal", {"frames": int(v["signal_frames"]), "filter": filters[0]}, _signal_task))
    out.append(Task("signal-demanding", {"frames": int(v["demanding_frames"]), "filter": filters[0]},
                    _demanding_task))
    return out
