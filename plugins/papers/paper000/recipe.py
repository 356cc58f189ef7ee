"""Paper 000: radar particle filter for track-before-detect (TBD), L-band, low SNR in heavy clutter.

Pipeline (every Monte Carlo run of a task at once)::

    piecewise path (approach, descent, 90 deg turn, exit) --lband-radar--> target detection
        (3-D position, Doppler, SNR; aspect-dependent fluctuating RCS)
    + radar-clutter (Poisson, Rayleigh amplitude, along the path)  --SNR threshold 5 dB-->
    gate of radius R around the predicted position  -->
        (A) weighted-mean coordinate (eqs 9-11), fixed R_bar  -> "ekf"          (the paper's A)
        (B) the same pseudo-measurement                      -> "sir"          (the paper's B)
        (the 4-vector [p; v_r] reading of A and B as ablations)
        (C) particle weights from every gated detection (eqs 12-15) -> "tbd-pf"
        + our A and B ("ekf-nis", "sir-jm": PDA-like R_bar, clutter term, manoeuvre modes) and ablations of C

The rows are :data:`~.methods.METHODS`; any filter named with ``--filters`` joins them.  The reference RCS and the
clutter rate, which the paper withholds, are declared unknowns (:data:`~.scenario.REFERENCE_RCS`,
:data:`~.scenario.CLUTTER_RATE`): the full report runs the judged rows across their grids on the same draws, judges
criteria 1-3 at every grid point (``Criterion.across``), calibrates both values against Table 3's A and B on a tuning
seed (:data:`~.tuning.CALIBRATION_RULE`) and judges criteria 1-3 again at the calibrated values on the report's runs;
it also replicates the paper's 20-run protocol on independent runs.  Choices where the paper is silent are in
:data:`NOTES` and ``docs/paper000.md``.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from workbench.criteria import criterion_from_runs, judge_across, replication_rate, rows_track, vectorised
from workbench.report.engine import component_failure
from workbench.sensing.radar import RadarParameters, aspect_rcs_db, clutter_pass_fraction, db, from_db, radar_snr
from workbench.specs import Criterion, FigureSpec, RecipeOptions, RecipeSpec, Table, TableSpec, Task, TaskContext
from workbench.types import InputError

from . import tuning
from .methods import CLUTTER_TERM, METHODS, PROPOSED, SIGMA_A, TRACK_THRESHOLD_DB, method_of, rows_for, run_method
from .scenario import (CLUTTER_RATE, PHASES, PRIMARY_CLUTTER_RATE, PRIMARY_RCS, REFERENCE_RCS, SENSITIVITY_RCS,
                       clutter_for, scenario_truth, sensor_for, simulate_scans, tracking_model)

PAPER = "000"
THRESHOLDS_DB = (12.0, 9.0, 7.0, 5.0, 3.0)  # Fig. 5 [S]
TABLE_PARTICLES = 600  # Fig. 13 and Table 3 [S: N ~ 600]
TABLE_RADIUS = 1000.0  # m [U which R]
WIDE_RADIUS = 2500.0  # m [S]
#: the reference RCS of the clutter-rate grid's second slice (dBsm): where the issue found the literal A and B track at
#: 50 candidates per scan
GRID_CORNER_RCS = -15.0
EARLY = slice(1, 101)  # k = 1..100
WHOLE = slice(1, None)  # k = 1..K
#: the paper's number of Monte Carlo runs per averaged value [S]
PROTOCOL_RUNS = 20
#: Repetitions of criterion 5's timing (both radii, in turn, on the protocol's runs) at full size, and the fewest
#: from which its timing part is decided.
TIMING_REPEATS = 7
MIN_TIMING_REPEATS = 5
#: the rows the criteria judge
JUDGED = ("A", "B", "C")
#: Criteria 1-3 compare the rows' tracking errors, so each judged row must track: at most this share of its runs
#: lost (the brief's rule, E_error > 3 km for 5 scans), else the criterion is "not judgeable".  The paper's Table 3
#: means (A 236, B 214, C 124 m whole track over 20 runs) leave no room for a run lost the way ours are (30-46 km
#: whole-track error: one alone adds 1.5-2.3 km to a 20-run mean), so the paper's rows lost none; 10 % (2 of the
#: paper's 20 runs) allows for sampling around a low loss rate, and above it the means compare divergences.
MAX_LOST_SHARE = 0.10
FIELDS = ("error", "m_error", "gated", "lost", "seconds", "cpu_seconds", "path0", "gated0")

PUBLISHED = {
    "table3_k1_100_m": {"A": 332.0, "B": 291.0, "C": 221.0},
    "table3_whole_m": {"A": 236.0, "B": 214.0, "C": 124.0},
    "claims": "C best at low and high SNR; A worst (more than 2x C in the low-SNR part, larger fluctuation); "
              "R = 2.5 km and 1 km give about the same error, 2.5 km costs more; the error converges by N ~ 600",
}


NOTES = """\
Scenario [U, the brief's chosen values]: radar at the origin, f = 1.3 GHz, Pt = 10 kW, tau = 1 us, L = 6 dB,
reference RCS -20 dBsm (top +5, side +3 dB, Table 2), RCS fluctuation 2 dB per scan, Pfa = 1e-6, 300 scans of 1 s.
Path: (56, 2, 3) km at -200 m/s along x for 100 s (front), descent at -40 m/s for 60 s (top), 90 deg turn at
9 deg/s, then +200 m/s along y (side).  SNR at k = 0/50/100/130/160/200/299: 2.3/5.7/9.9/18.1/22.0/19.6/12.6 dB.
Detections: spherical noise sigma_R = c tau/(2 sqrt(2 SNR)), sigma_ang = theta_3dB/(1.6 sqrt(2 SNR)) at the scan's
own SNR, radial-velocity noise 2 m/s; detected iff the fluctuating SNR >= 5 dB.  Clutter: Poisson(1000) per scan in a
10 km cube around the true position, altitude 0-6 km, exponential power with mean 3 dB, Doppler U(-300, 300) m/s.
Declared unknowns (the paper withholds both): the reference RCS (primary -20 dBsm, grid -20, -17.5, -15, -12.5, -10)
and the clutter rate (primary 1000 candidates per scan, grid 50, 200, 1000; run at -20 and at -15 dBsm), every grid
point on the same draws (the RCS changes only the target's strength; a lower rate thins the same clutter).  The full
report judges criteria 1-3 at every grid point (20 runs; at the primary, the 100 pooled runs), where they are "not
judgeable" unless A, B and C track; criteria 4-6 (method C alone) are judged at the primary values only.
Calibration (rule written before its result): on tuning seed 101 (20 runs), the grid point minimising |ln(A/236)| +
|ln(B/214)| of the literal A and B's mean whole-track errors; ties to the primary; criteria 1-3 are judged again at it
on the report's runs (ids 1@calibrated ...).
Rows (Table 3): (A) and (B) are the paper's as it writes them: the weighted-mean coordinate z_bar = sum_m w~_m p_m
(eq 11), the weights of eq 10 from position and Doppler (sigma_g = 500 m, sigma_d = 15 m/s, P_D(snr_m) by Marcum Q),
the Doppler in the weights only, given with h(s) = p and the fixed R_bar = diag(300^2, 300^2, 300^2) (the sensor's
stated pseudo-measurement accuracy: the brief's reading, the paper gives no R_bar) and no clutter term to a plain EKF
('ekf') and a bootstrap particle filter ('sir', N = 600, resampling at N_eff < N/2), both with one CV noise,
sigma_a x 2 (the stationary covariance of C's two-mode noise).  Ablation rows 'A (4-vector reading)' and
'B (4-vector reading)': the brief's earlier z_bar = sum_m w~_m [p_m; vr_m] with R_bar = diag(300^2 x 3, 10^2).  (C) weights the particles by every
gated detection (eqs 12-15, 'tbd-pf').  'A, ours' and 'B, ours' are improvements, not the paper's: the PDA-like R_bar
(SNR-based accuracy + spread + Doppler mismatch), a clutter term b = lambda (1 - P_D) / P_D x the clutter amplitude
law at the strongest gated detection (the PDAF update for the EKF, the mixture b + N(z_bar; h, R_bar) for the PF),
and manoeuvre modes (NIS-switched EKF noise 'ekf-nis', two-mode PF 'sir-jm').  Ablations of C: the previous flat
floor, no floor, the sensor's 2 m/s Doppler kernel.
Method C: eq 13 with sigma_p,m = sqrt(sigma_R^2 + (R sigma_ang)^2) at the detection's SNR and a 15 m/s Doppler kernel
(the eq-10 width; the sensor's 2 m/s, tempered: N(.; 15^2) is N(.; 2^2)^(4/225)); SIS carry-over of
log(eps + sum_m w_m,i) with the amplitude-aware floor eps = 16 lambda max_m P_D(snr_m) (1 - P_D^T) / max(1, l):
lambda the clutter model's intensity in (x, y, z, vr) at 5 dB (3.43e-13 m^-3 (m/s)^-1, carried by each detection),
P_D^T the sensor's detection probability of its design target at the cloud's predicted position, l the amplitude
likelihood ratio of the strongest gated detection (the target's SNR law at the cloud's predicted nominal SNR against
the clutter's exponential power law).  The previous floor ignored signal strength: at 20 dB the position kernel is
~50 m wide and a cloud lagging ~200 m behind the target's detection saw only the floor, so the turn lost tracks.
Systematic resampling at N_eff < N/2 and post-regularisation (0.5 h_opt, Musso, Oudjane and Le Gland).
Manoeuvres: one two-level process noise for every method: quiet sigma_a = (8, 8, 4) m/s^2, manoeuvre x4; the particle
filters carry a jump-Markov mode per particle (P(quiet -> manoeuvre) = 0.05, P(back) = 0.2 per scan), the EKF of
'ours' switches by the NIS (chi2_4 99 %).
Settings found by a search (floor scale 16, the process noise, the regularisations, the clutter term of our A and B)
were chosen on tuning seeds 101-104 by the rule in the table 'table_tuning' and docs/paper000.md; the report's runs
(seed 0 and its replications) never served the search.
Prior N(s_0, diag(500, 500, 300, 30, 30, 10)^2) around the true initial state; gate centred on the predicted
position F s_hat_{k-1|k-1}; an empty gate means predict only.  Errors (eqs 19-21): per run the mean of E_error over
k = 1..100 and k = 1..299, then the mean over runs with lost runs (E_error > 3 km for 5 scans, never re-initialised)
included, beside the median and the mean over the runs not lost.  Criteria: judged on the paper's protocol (20
runs, seed 0) pooled with 80 independent runs (4 replications) for A, B, C and the R = 2.5 km run; bootstrap 95 %
intervals; 'replication' = in how many disjoint 20-run batches the criterion holds.  Criteria 1-3 have the
precondition "the judged rows track": each of A, B, C (criterion 2: A, C) loses at most 10 % of its judged runs
(the paper's Table 3 means leave no room for a lost run); where a row loses more, the criterion is "not
judgeable", with the lost counts.  Run times: one batched call
for all runs of a row, after a 3-scan warm-up that compiles and loads every kernel."""


# -- tasks ------------------------------------------------------------------------------------------------


def _scenario_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    runs = int(ctx.params["runs"])
    truth = scenario_truth(runs)
    scans = simulate_scans(ctx.host, truth, ctx.seed, None)
    sp = sensor_for(ctx.host).params
    rcs_db = aspect_rcs_db(truth.times, sp["rcs_ref_dbsm"], sp["rcs_offsets_db"], sp["aspect_change_times"])
    snr = scans.snr[:, :, 0]  # the target's fluctuating SNR (row 0 is the target)
    thresholds = np.asarray(ctx.params["thresholds"], dtype=float)
    passing = scans.valid[None] & (np.nan_to_num(scans.snr, nan=-np.inf)[None] >= thresholds[:, None, None, None])
    clutter = passing & (scans.origin[None] < 0)
    # run 0's detections at the lowest threshold, for the scatter figures: [k, x, y, z, snr, origin]
    keep = passing[-1, 0]
    k_idx = np.nonzero(keep)[0]
    points = np.column_stack([k_idx, scans.z[0][keep][:, :3], scans.snr[0][keep], scans.origin[0][keep]])
    # expected clutter per scan: rate x P(power >= t) x (fraction of the cube inside the altitude band)
    cp = clutter_for(ctx.host, None).params
    zc = truth.states[0, :, 2]
    inside = np.clip(np.minimum(zc + cp["cube"] / 2, cp["z_max"]) - np.maximum(zc - cp["cube"] / 2, cp["z_min"]),
                     0.0, None) / cp["cube"]
    # the settings the filters use (the tuning table shows them beside the candidates)
    proposed = ctx.host.filter(PROPOSED).params
    ours_b = ctx.host.filter(next(m.filter for m in METHODS if m.key == "B+")).params
    return {
        "truth": truth.states[0],
        "nominal_snr_db": db(radar_snr(np.linalg.norm(truth.states[0, :, :3], axis=-1), from_db(rcs_db))),
        "snr_db": snr,
        "thresholds_db": thresholds,
        "count_per_scan": passing.sum(axis=3).mean(axis=1),  # (thresholds, T), mean over runs
        "clutter_per_scan": clutter.sum(axis=3).mean(axis=(1, 2)),  # (thresholds,)
        "clutter_expected_nocut": cp["rate"] * clutter_pass_fraction(thresholds, cp["mean_power"]),
        "clutter_expected": cp["rate"] * clutter_pass_fraction(thresholds, cp["mean_power"]) * inside.mean(),
        "clutter_density_km3": cp["rate"] * clutter_pass_fraction(thresholds, cp["mean_power"])
        / (cp["cube"] / 1e3) ** 3,
        "points": points,
        "used_floor_scale": np.array(proposed["floor_scale"]),
        "used_sigma_a": np.array(SIGMA_A),
        "used_switching": np.array([proposed["switch_on"], proposed["switch_off"], proposed["manoeuvre_scale"]]),
        "used_regularisation": np.array(proposed["regularisation"]),
        "used_clutter_term": np.array(CLUTTER_TERM),
        "used_regularisation_ours_b": np.array(ours_b["regularisation"]),
    }


def _runs_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """Every ``(filter, particles, radius, row key)`` of ``combos`` on the same scans: ``runs`` runs at reference RCS
    ``rcs`` and clutter rate ``rate`` (the declared unknowns; the rate thins the same clutter draws), drawn from the
    stream ``stream`` ("" for the paper's protocol, "replicate" for its independent replications)."""
    p = ctx.params
    runs, rcs, stream = int(p["runs"]), float(p["rcs"]), str(p["stream"])
    rate = float(p.get("rate", PRIMARY_CLUTTER_RATE))
    truth = scenario_truth(runs)
    scans = simulate_scans(ctx.host, truth, ctx.seed, TRACK_THRESHOLD_DB, rcs, stream=stream,
                           clutter_rate=None if rate == PRIMARY_CLUTTER_RATE else rate)
    model = tracking_model(ctx.host, rcs, TRACK_THRESHOLD_DB)
    out = {"rcs": np.array(rcs), "rate": np.array(rate), "stream": np.array(stream), "runs": np.array(runs)}
    for combo in p["combos"]:
        # [filter, particles, radius] runs the filter's first row (the judged one where it has one), a fourth
        # element names the row (A and its 4-vector ablation share the filter "ekf")
        ref, particles, radius = combo[:3]
        key = combo[3] if len(combo) > 3 else None
        # each row alone: a filter that raises loses its own row (named in the report: error/<row>), never the
        # other rows run on the same scans
        try:
            spec = ctx.host.filter(ref)
            method = method_of(key, ref, spec.capabilities) if key is not None else rows_for(ref,
                                                                                               spec.capabilities)[0]
            res = run_method(ctx.host, method, scans, truth.states, model, radius=float(radius),
                             particles=int(particles), seed=ctx.seed, rng_key=(stream,) if stream else (),
                             clutter_rate=None if rate == PRIMARY_CLUTTER_RATE else rate)
        except Exception as exc:  # noqa: BLE001 - isolated: reported by the report engine, the other rows kept
            row = "" if key is None or key == rows_for(ref)[0].key else f" as {key}"
            out.update(component_failure(f"filter:{ref}{row} (N={int(particles)}, R={float(radius):g} m)", exc))
            continue
        for field in FIELDS:
            out[f"{_combo(method.key, int(particles), float(radius))}__{field}"] = res[field]
    return out


def _timing_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The cost of the gate's radius (criterion 5's "R = 2.5 km takes longer"): method C with N = 600 on the same
    ``runs`` runs at R = 2.5 km and at R = 1 km, ``repeats`` times, the two radii in turn (their order alternating
    from one repetition to the next, so that a load that drifts reaches both alike); each call warmed up and timed
    in this process's CPU time (:func:`run_method`)."""
    p = ctx.params
    runs, repeats, rcs = int(p["runs"]), int(p["repeats"]), float(p["rcs"])
    truth = scenario_truth(runs)
    scans = simulate_scans(ctx.host, truth, ctx.seed, TRACK_THRESHOLD_DB, rcs, stream="timing")
    model = tracking_model(ctx.host, rcs, TRACK_THRESHOLD_DB)
    method = rows_for(p["filter"], ctx.host.filter(p["filter"]).capabilities)[0]
    cpu = {WIDE_RADIUS: [], TABLE_RADIUS: []}
    for r in range(repeats):
        for radius in ((WIDE_RADIUS, TABLE_RADIUS) if r % 2 == 0 else (TABLE_RADIUS, WIDE_RADIUS)):
            res = run_method(ctx.host, method, scans, truth.states, model, radius=radius, particles=TABLE_PARTICLES,
                             seed=ctx.seed, rng_key=("timing",), record=False)
            cpu[radius].append(float(res["cpu_seconds"]))
    return {"runs": np.array(runs), "repeats": np.array(repeats), "rcs": np.array(rcs),
            "cpu_wide": np.array(cpu[WIDE_RADIUS]), "cpu_table": np.array(cpu[TABLE_RADIUS])}


def _combo(key: str, particles: int, radius: float) -> str:
    return f"{key}__N{particles}__R{radius:g}"


def _rcs_tag(rcs: float) -> str:
    return f"{rcs:g}dBsm"


def _row_combos(refs, particles: int, radius: float, keys=None) -> list:
    """``[filter, particles, radius, row key]`` for every row of each filter in ``refs`` (:func:`~.methods.rows_for`:
    ``"ekf"`` is A and its 4-vector ablation), or only the rows with a key in ``keys``."""
    return [[m.filter, int(particles), float(radius), m.key] for ref in refs for m in rows_for(ref)
            if keys is None or m.key in keys]


def grid_points() -> tuple[tuple[float, float], ...]:
    """The ``(reference RCS, clutter rate)`` points the full report runs the judged rows at, the primary first: the
    RCS grid at the primary rate, the rate grid at the primary RCS, and the rate grid at -15 dBsm (where the literal
    A and B meet lower clutter with a stronger target).  They are also the calibration's candidates."""
    points = [(float(r), PRIMARY_CLUTTER_RATE) for r in REFERENCE_RCS.grid]
    points += [(PRIMARY_RCS, float(c)) for c in CLUTTER_RATE.grid if c != PRIMARY_CLUTTER_RATE]
    points += [(GRID_CORNER_RCS, float(c)) for c in CLUTTER_RATE.grid if c != PRIMARY_CLUTTER_RATE]
    return tuple(dict.fromkeys(points))


def _point_tag(rcs: float, rate: float) -> str:
    return _rcs_tag(rcs) + ("" if rate == PRIMARY_CLUTTER_RATE else f"@{rate:g}perscan")


def _calibration_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """The literal A and B at every candidate ``(RCS, rate)`` of ``points`` on the tuning seed ``seed`` (never the
    report's seed: the task reads ``params["seed"]``, not ``ctx.seed``), ``runs`` runs each: per-run early and
    whole-track errors and lost flags, ``(P, runs)``."""
    p = ctx.params
    seed, runs = int(p["seed"]), int(p["runs"])
    truth = scenario_truth(runs)
    out: dict[str, list] = {}
    for rcs, rate in p["points"]:
        scans = simulate_scans(ctx.host, truth, seed, TRACK_THRESHOLD_DB, float(rcs),
                               clutter_rate=None if rate == PRIMARY_CLUTTER_RATE else float(rate))
        model = tracking_model(ctx.host, float(rcs), TRACK_THRESHOLD_DB)
        for key in p["rows"]:
            res = run_method(ctx.host, method_of(key), scans, truth.states, model, radius=TABLE_RADIUS,
                             particles=TABLE_PARTICLES, seed=seed, record=False,
                             clutter_rate=None if rate == PRIMARY_CLUTTER_RATE else float(rate))
            early, whole = per_run_errors(res)
            out.setdefault(f"{key}__early", []).append(early)
            out.setdefault(f"{key}__whole", []).append(whole)
            out.setdefault(f"{key}__lost", []).append(np.asarray(res["lost"]))
    return {"points": np.asarray(p["points"], dtype=float), "seed": np.array(seed), "runs": np.array(runs),
            **{k: np.stack(v) for k, v in out.items()}}


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    runs = int(v["runs"])
    out = [Task("scenario", {"runs": runs, "thresholds": list(THRESHOLDS_DB)}, _scenario_task)]
    rows = list(dict.fromkeys(options.filters))
    proposed = next((m.filter for m in METHODS if m.role == "C"), PROPOSED)

    def runs_task(name: str, rcs: float, n_runs: int, combos: list, stream: str = "",
                  rate: float = PRIMARY_CLUTTER_RATE) -> None:
        if combos:
            params = {"runs": n_runs, "rcs": rcs, "stream": stream, "threshold_db": TRACK_THRESHOLD_DB,
                      "combos": combos}
            if rate != PRIMARY_CLUTTER_RATE:
                params["rate"] = float(rate)
            out.append(Task(f"{name}@{_point_tag(rcs, rate)}", params, _runs_task, runs=n_runs))

    table = _row_combos(rows, TABLE_PARTICLES, TABLE_RADIUS) + [[proposed, TABLE_PARTICLES, WIDE_RADIUS, "C"]]
    runs_task("table", PRIMARY_RCS, runs, table)
    sweep = [[proposed, int(n), TABLE_RADIUS, "C"] for n in v["sweep_particles"] if int(n) != TABLE_PARTICLES]
    sweep += [[proposed, int(n), WIDE_RADIUS, "C"] for n in v["path_particles"] if int(n) != TABLE_PARTICLES]
    runs_task("sweep", PRIMARY_RCS, runs, sweep)
    judged_refs = [m.filter for m in METHODS if m.role in JUDGED and m.filter in rows]
    if v.get("unknowns", False):
        # the declared unknowns' grid: the judged rows only, on the report's seed, the same draws at every point
        for rcs, rate in grid_points()[1:]:
            runs_task("grid", rcs, runs, _row_combos(judged_refs, TABLE_PARTICLES, TABLE_RADIUS, JUDGED), rate=rate)
    calibration = int(v.get("calibration_runs", 0))
    if calibration and all(k in {m.key for ref in rows for m in rows_for(ref)} for k in ("A", "B")):
        out.append(Task("calibration", {"seed": tuning.CALIBRATION_SEED, "runs": calibration,
                                        "points": [list(p) for p in grid_points()], "rows": ["A", "B"],
                                        "rule": tuning.CALIBRATION_RULE, "published": [236.0, 214.0]},
                        _calibration_task, runs=calibration, seeded=False))
    repeats = int(v.get("timing_repeats", 0))
    if repeats:
        out.append(Task(f"timing@{_rcs_tag(PRIMARY_RCS)}", {"runs": runs, "repeats": repeats, "rcs": PRIMARY_RCS,
                                                            "filter": proposed}, _timing_task))
    extra = int(v.get("replicated_runs", 0))
    if extra:
        combos = _row_combos(judged_refs, TABLE_PARTICLES, TABLE_RADIUS, JUDGED)
        combos += [[proposed, TABLE_PARTICLES, WIDE_RADIUS, "C"]]
        runs_task("replicate", PRIMARY_RCS, extra, combos, stream="replicate")
    return out


# -- reading results ----------------------------------------------------------------------------------


def _rate_of(res) -> float:
    """The clutter rate a run task was drawn at (tasks without one: the primary)."""
    return float(res["rate"]) if "rate" in res else PRIMARY_CLUTTER_RATE


def _runs(results, rcs: float = PRIMARY_RCS, stream: str = "",
          rate: float = PRIMARY_CLUTTER_RATE) -> dict[tuple[str, int, float], dict]:
    """``(method key, particles, radius) -> {field: array}`` of every run task at ``rcs`` and clutter rate ``rate``
    from ``stream``."""
    out: dict[tuple[str, int, float], dict] = {}
    for key, res in results.items():
        if "__" in key or "rcs" not in res or "stream" not in res or key == "scenario":
            continue
        if not np.isclose(float(res["rcs"]), rcs) or str(res["stream"]) != stream or \
                not np.isclose(_rate_of(res), rate):
            continue
        for name, value in res.items():
            parts = name.split("__")
            if len(parts) != 4:
                continue
            method, n, r, field = parts
            out.setdefault((method, int(n[1:]), float(r[1:])), {})[field] = np.asarray(value)
    return out


def _rcs_values(results) -> list[float]:
    """The reference RCS values with a Table 3 or grid run at the primary clutter rate, the primary first."""
    found = sorted({float(res["rcs"]) for key, res in results.items()
                    if key.startswith(("table@", "grid@")) and np.isclose(_rate_of(res), PRIMARY_CLUTTER_RATE)})
    return sorted(found, key=lambda r: (not np.isclose(r, PRIMARY_RCS), r))


def _table_runs(results, rcs: float = PRIMARY_RCS) -> dict[str, dict]:
    """The Table 3 / Fig. 13 runs at ``rcs``: every row at R = 1 km, N = 600, in the rows' order."""
    runs = {m: res for (m, n, r), res in _runs(results, rcs).items() if n == TABLE_PARTICLES and r == TABLE_RADIUS}
    order = {m.key: j for j, m in enumerate(METHODS)}
    return dict(sorted(runs.items(), key=lambda kv: (order.get(kv[0], len(order)), kv[0])))


def _get(results, key: str, particles: int, radius: float, rcs: float = PRIMARY_RCS, stream: str = "",
         rate: float = PRIMARY_CLUTTER_RATE):
    return _runs(results, rcs, stream, rate).get((key, particles, radius))


def _label(key: str) -> str:
    return next((m.label for m in METHODS if m.key == key), key)


def _role(key: str) -> str:
    return next((m.role for m in METHODS if m.key == key), "extra")


def mean_over_runs(values) -> np.ndarray:
    """Mean over runs (axis 0) of the finite entries; NaN where no run has one (eq 19 with empty gates)."""
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v)
    n = ok.sum(axis=0)
    return np.where(n > 0, np.where(ok, v, 0.0).sum(axis=0) / np.maximum(n, 1), np.nan)


def per_run_errors(res: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Each run's E_error averaged over k = 1..100 and over k = 1..K (eq 21 before the mean over runs): ``(R,)``
    twice."""
    e = np.asarray(res["error"], dtype=float)
    return e[:, EARLY].mean(axis=1), e[:, WHOLE].mean(axis=1)


def average_errors(res: Mapping[str, np.ndarray]) -> tuple[float, float]:
    """(E_avg over k = 1..100, E_avg over k = 1..K), each the mean over runs of eq 21 (lost runs included)."""
    early, whole = per_run_errors(res)
    return float(early.mean()), float(whole.mean())


def error_summary(values: np.ndarray, lost: np.ndarray) -> tuple[float, float, float]:
    """``(mean, median, mean over the runs not lost)`` of per-run values; the last is NaN when every run is lost."""
    values = np.asarray(values, dtype=float)
    lost = np.asarray(lost, dtype=bool)
    kept = values[~lost]
    return float(values.mean()), float(np.median(values)), float(kept.mean()) if kept.size else float("nan")


def _sweep(results, rcs: float = PRIMARY_RCS) -> tuple[np.ndarray, list[np.ndarray]]:
    """The particle counts of the method-C sweep at R = 1 km and each count's per-run whole-track errors."""
    rows = sorted((n, res) for (m, n, r), res in _runs(results, rcs).items() if m == "C" and r == TABLE_RADIUS)
    return np.array([n for n, _ in rows], dtype=int), [per_run_errors(res)[1] for _, res in rows]


# -- figures ----------------------------------------------------------------------------------------------


def _scenario(results) -> Mapping[str, np.ndarray]:
    if "scenario" not in results:
        raise InputError("paper 000: the scenario task has no result")
    return results["scenario"]


def _phase_colours():
    return {"front": "tab:blue", "top": "tab:orange", "side": "tab:green"}


def fig2_data(results):
    return {"truth_km": np.asarray(_scenario(results)["truth"])[:, :3] / 1e3,
            "phase_start": np.array([a for _, a, _ in PHASES]), "phase_end": np.array([b for _, _, b in PHASES])}


def draw_fig2(data, fig):
    ax = fig.add_subplot(projection="3d")
    p = data["truth_km"]
    for (name, a, b), colour in zip(PHASES, _phase_colours().values()):
        ax.plot(p[a:b + 1, 0], p[a:b + 1, 1], p[a:b + 1, 2], color=colour, lw=2, label=f"{name} (k={a}..{b})")
    ax.scatter([0], [0], [0], color="k", marker="^", s=40, label="radar")
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_zlabel("z (km)")
    ax.legend(loc="upper left", fontsize=8)


def fig3_data(results):
    s = _scenario(results)
    return {"k": np.arange(np.asarray(s["snr_db"]).shape[1]), "snr_run0_db": np.asarray(s["snr_db"])[0],
            "nominal_snr_db": np.asarray(s["nominal_snr_db"]), "thresholds_db": np.asarray(s["thresholds_db"])}


def draw_fig3(data, fig):
    ax = fig.add_subplot()
    ax.plot(data["k"], data["snr_run0_db"], "r.", ms=3, label="SNR with RCS fluctuation (run 0)")
    ax.plot(data["k"], data["nominal_snr_db"], "k-", lw=1, label="radar equation, nominal RCS")
    for t in data["thresholds_db"]:
        ax.axhline(t, color="grey", lw=0.8, ls="--")
        ax.text(data["k"][-1], t, f" {t:g} dB", va="center", fontsize=7)
    ax.set_xlabel("time index k")
    ax.set_ylabel("SNR (dB)")
    ax.legend(fontsize=8)


def _scatter_points(results, every: int = 10):
    s = _scenario(results)
    pts = np.asarray(s["points"])
    clutter = pts[:, 5] < 0
    keep = ~clutter | (pts[:, 0] % every == 0)  # every target detection, clutter of every 10th scan
    return pts[keep]


def fig4_data(results):
    pts = _scatter_points(results)
    return {"points_km": pts[:, 1:4] / 1e3, "snr_db": pts[:, 4], "is_target": pts[:, 5] >= 0,
            "truth_km": np.asarray(_scenario(results)["truth"])[:, :3] / 1e3}


def draw_fig4(data, fig):
    ax = fig.add_subplot(projection="3d")
    p, t = data["points_km"], data["is_target"]
    ax.scatter(p[~t, 0], p[~t, 1], p[~t, 2], s=1, c="grey", alpha=0.4, label="clutter (every 10th scan)")
    ax.scatter(p[t, 0], p[t, 1], p[t, 2], s=3, c="r", label="target detections")
    tr = data["truth_km"]
    ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "k-", lw=1.5, label="true path")
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_zlabel("z (km)")
    ax.set_title("all detections >= 3 dB", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")


def fig5_data(results):
    d = fig4_data(results)
    d["thresholds_db"] = np.asarray(_scenario(results)["thresholds_db"])
    return d


def draw_fig5(data, fig):
    tr = data["truth_km"]
    ax = fig.add_subplot(2, 3, 1, projection="3d")
    ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "g-")
    ax.set_title("(a) true path", fontsize=9)
    p, t, snr = data["points_km"], data["is_target"], data["snr_db"]
    for j, thr in enumerate(data["thresholds_db"]):
        ax = fig.add_subplot(2, 3, j + 2, projection="3d")
        keep = snr >= thr
        c = keep & ~t
        g = keep & t
        ax.scatter(p[c, 0], p[c, 1], p[c, 2], s=1, c="grey", alpha=0.4)
        ax.scatter(p[g, 0], p[g, 1], p[g, 2], s=2, c="r")
        ax.set_title(f"({'bcdef'[j]}) SNR >= {thr:g} dB: {int(g.sum())} target", fontsize=9)
    for ax in fig.axes:
        ax.set_xlim(tr[:, 0].min() - 6, tr[:, 0].max() + 6)
        ax.set_ylim(tr[:, 1].min() - 6, tr[:, 1].max() + 6)
        ax.set_zlim(0, 6)
        ax.set_xlabel("x (km)", fontsize=7)
        ax.set_ylabel("y (km)", fontsize=7)
        ax.set_zlabel("z (km)", fontsize=7)
        ax.tick_params(labelsize=6)


def fig5_counts_data(results):
    s = _scenario(results)
    return {"k": np.arange(np.asarray(s["count_per_scan"]).shape[1]), "count_per_scan": s["count_per_scan"],
            "thresholds_db": s["thresholds_db"]}


def draw_fig5_counts(data, fig):
    ax = fig.add_subplot()
    for thr, row in zip(data["thresholds_db"], data["count_per_scan"]):
        ax.semilogy(data["k"], np.maximum(row, 1e-2), label=f">= {thr:g} dB")
    ax.set_xlabel("time index k")
    ax.set_ylabel("detections per scan (mean over runs)")
    ax.legend(fontsize=8)


def fig6_data(results):
    s = _scenario(results)
    pts = np.asarray(s["points"])
    k = 60
    centre = np.asarray(s["truth"])[k, :3]
    at = pts[(pts[:, 0] == k) & (pts[:, 4] >= TRACK_THRESHOLD_DB)]
    d = np.linalg.norm(at[:, 1:4] - centre, axis=1)
    return {"k": np.array(k), "centre_km": centre / 1e3, "points_km": at[:, 1:4] / 1e3, "distance_km": d / 1e3,
            "is_target": at[:, 5] >= 0, "radii_km": np.array([2.5, 1.0])}


def draw_fig6(data, fig):
    ax = fig.add_subplot()
    c, p, d = data["centre_km"], data["points_km"], data["distance_km"]
    from matplotlib.patches import Circle

    for r, ls in zip(data["radii_km"], ("-", "--")):
        ax.add_patch(Circle((c[0], c[1]), r, fill=False, ls=ls, color="b", label=f"R = {r:g} km"))
    inside = d <= data["radii_km"].max()
    ax.scatter(p[~inside, 0], p[~inside, 1], s=6, c="grey", label="outside the gate")
    ax.scatter(p[inside, 0], p[inside, 1], s=10, c="k", label="inside (processed)")
    t = data["is_target"]
    ax.scatter(p[t, 0], p[t, 1], s=40, facecolors="none", edgecolors="r", label="target")
    ax.plot(c[0], c[1], "b+", ms=10, label="predicted position")
    ax.set_aspect("equal")
    ax.set_xlim(c[0] - 5, c[0] + 5)
    ax.set_ylim(c[1] - 5, c[1] + 5)
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_title(f"gate at scan k = {int(data['k'])}, detections >= 5 dB (x-y projection)", fontsize=9)
    ax.legend(fontsize=7)




def fig7_data(results):
    out = {"truth_km": np.asarray(_scenario(results)["truth"])[:, :3] / 1e3}
    for r in (WIDE_RADIUS, TABLE_RADIUS):
        res = _get(results, "C", TABLE_PARTICLES, r)
        if res is None:
            raise InputError(f"paper 000 Fig. 7 needs the method-C run with N={TABLE_PARTICLES}, R={r:g} m")
        g = np.asarray(res["gated0"])
        out[f"gated_km_R{r:g}"] = g[:, 1:4] / 1e3
        out[f"gated_target_R{r:g}"] = g[:, 5] >= 0
    return out


def draw_fig7(data, fig):
    tr = data["truth_km"]
    for j, r in enumerate((2500, 1000)):
        ax = fig.add_subplot(1, 2, j + 1, projection="3d")
        g, t = data[f"gated_km_R{r}"], data[f"gated_target_R{r}"]
        ax.scatter(g[~t, 0], g[~t, 1], g[~t, 2], s=1, c="grey", label=f"clutter ({int((~t).sum())})")
        ax.scatter(g[t, 0], g[t, 1], g[t, 2], s=2, c="r", label=f"target ({int(t.sum())})")
        ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "g-", lw=1)
        ax.set_title(f"({'ab'[j]}) gated detections, R = {r / 1e3:g} km, 5 dB", fontsize=9)
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
        ax.set_zlabel("z (km)")
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=6)


def _paths_data(results, particles: int):
    out = {"truth_km": np.asarray(_scenario(results)["truth"])[:, :3] / 1e3}
    for r in (WIDE_RADIUS, TABLE_RADIUS):
        res = _get(results, "C", particles, r)
        if res is None:
            raise InputError(f"paper 000 needs the method-C run with N={particles}, R={r:g} m")
        out[f"estimate_km_R{r:g}"] = np.asarray(res["path0"]) / 1e3
        out[f"lost_R{r:g}"] = np.asarray(res["lost"])
    return out


def _draw_paths(data, fig, particles: int):
    tr = data["truth_km"]
    for j, r in enumerate((2500, 1000)):
        ax = fig.add_subplot(1, 2, j + 1, projection="3d")
        est = data[f"estimate_km_R{r}"]
        ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "g-", lw=2, label="true path")
        ax.plot(est[:, 0], est[:, 1], est[:, 2], "b-", lw=1, label="estimate (run 0)")
        lost = data[f"lost_R{r}"]
        ax.set_title(f"({'ab'[j]}) R = {r / 1e3:g} km, N = {particles}; lost {int(lost.sum())}/{lost.size}",
                     fontsize=9)
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
        ax.set_zlabel("z (km)")
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=6)


def fig10_data(results):
    out = {}
    for r in (WIDE_RADIUS, TABLE_RADIUS):
        res = _get(results, "C", TABLE_PARTICLES, r)
        if res is None:
            raise InputError(f"paper 000 Fig. 10 needs the method-C run with N={TABLE_PARTICLES}, R={r:g} m")
        out[f"m_error_R{r:g}"] = mean_over_runs(res["m_error"])
        out[f"e_error_R{r:g}"] = np.asarray(res["error"]).mean(axis=0)
    out["k"] = np.arange(out["e_error_R1000"].size)
    return out


def draw_fig10(data, fig):
    ax = fig.add_subplot()
    for r, ls in ((2500, "-"), (1000, "--")):
        ax.semilogy(data["k"], data[f"m_error_R{r}"], ls, color="grey", label=f"M_error, R = {r / 1e3:g} km")
        ax.semilogy(data["k"], data[f"e_error_R{r}"], ls, color="b", label=f"E_error, R = {r / 1e3:g} km")
    ax.set_xlabel("time index k")
    ax.set_ylabel("error (m), mean over runs")
    ax.set_title(f"measurement vs estimation error, method C, N = {TABLE_PARTICLES}, 5 dB", fontsize=9)
    ax.legend(fontsize=8)


def fig11_data(results):
    rows = sorted((n, res) for (m, n, r), res in _runs(results).items() if m == "C" and r == TABLE_RADIUS)
    if not rows:
        raise InputError("paper 000 Fig. 11 has no particle-count sweep")
    return {"particles": np.array([n for n, _ in rows]),
            "e_error": np.stack([np.asarray(res["error"]).mean(axis=0) for _, res in rows])}


def draw_fig11(data, fig):
    ax = fig.add_subplot()
    k = np.arange(data["e_error"].shape[1])
    for n, row in zip(data["particles"], data["e_error"]):
        ax.semilogy(k, row, lw=1, label=f"N = {n}")
    ax.set_xlabel("time index k")
    ax.set_ylabel("E_error (m), mean over runs")
    ax.set_title(f"estimation error per particle count, method C, R = {TABLE_RADIUS / 1e3:g} km", fontsize=9)
    ax.legend(fontsize=7, ncol=2)


def fig12_data(results):
    ns, per_run = _sweep(results)
    if not ns.size:
        raise InputError("paper 000 Fig. 12 has no particle-count sweep")
    return {"particles": ns, "e_avg_mean": np.array([x.mean() for x in per_run]),
            "e_avg_median": np.array([np.median(x) for x in per_run]),
            "e_avg_std": np.array([x.std(ddof=1) if x.size > 1 else 0.0 for x in per_run]),
            "runs": np.array(per_run[0].size)}


def draw_fig12(data, fig):
    ax = fig.add_subplot()
    n, m, s = data["particles"], data["e_avg_mean"], data["e_avg_std"]
    ax.plot(n, m, "bo-", label=f"mean over {int(data['runs'])} runs (lost runs included)")
    ax.plot(n, data["e_avg_median"], "k^--", label="median over runs")
    ax.fill_between(n, np.maximum(m - s, 0.0), m + s, color="b", alpha=0.15, label="mean +- 1 std (clipped at 0)")
    ax.set_yscale("log")
    ax.set_xlabel("number of particles N")
    ax.set_ylabel("E_error,avg over k = 1..K (m)")
    ax.legend(fontsize=8)


def fig13_data(results):
    runs = _table_runs(results)
    if not runs:
        raise InputError("paper 000 Fig. 13 has no method runs")
    keys = list(runs)
    return {"methods": np.array(keys), "labels": np.array([_label(k) for k in keys]),
            "roles": np.array([_role(k) for k in keys]),
            "e_error": np.stack([np.asarray(runs[k]["error"]).mean(axis=0) for k in keys])}


def draw_fig13(data, fig):
    ax = fig.add_subplot()
    k = np.arange(data["e_error"].shape[1])
    styles = {"A": "-", "B": "-", "C": "-", "ours": "--", "ablation": ":", "extra": "-."}
    for label, role, row in zip(data["labels"], data["roles"], data["e_error"]):
        ax.semilogy(k, row, styles.get(str(role), "-"), lw=1.2 if role in JUDGED else 1.0, label=str(label))
    ax.set_xlabel("time index k")
    ax.set_ylabel("E_error (m), mean over runs")
    ax.set_title(f"estimation error per method, N = {TABLE_PARTICLES}, R = {TABLE_RADIUS / 1e3:g} km", fontsize=9)
    ax.legend(fontsize=7)


def fig14_data(results):
    values = _rcs_values(results)
    if not values:
        raise InputError("paper 000 Fig. 14 has no method runs")
    keys = [m.key for m in METHODS if m.role in (*JUDGED, "ours") and all(m.key in _table_runs(results, r)
                                                                           for r in values)]
    mean = np.array([[average_errors(_table_runs(results, r)[k])[1] for r in values] for k in keys])
    median = np.array([[float(np.median(per_run_errors(_table_runs(results, r)[k])[1])) for r in values]
                       for k in keys])
    lost = np.array([[int(np.sum(_table_runs(results, r)[k]["lost"])) for r in values] for k in keys])
    return {"rcs_dbsm": np.array(values), "methods": np.array(keys), "labels": np.array([_label(k) for k in keys]),
            "whole_mean": mean, "whole_median": median, "lost": lost}


def draw_fig14(data, fig):
    ax = fig.add_subplot()
    x = data["rcs_dbsm"]
    for j, label in enumerate(data["labels"]):
        line, = ax.semilogy(x, data["whole_mean"][j], "o-", label=f"{label}: mean")
        ax.semilogy(x, data["whole_median"][j], "^--", color=line.get_color(), alpha=0.7)
    for value, ref in ((PUBLISHED["table3_whole_m"][m], m) for m in JUDGED):
        ax.axhline(value, color="grey", lw=0.6, ls=":")
        # A (236 m) and B (214 m) lie close: A's label above its line, B's below
        ax.text(x.max(), value, f" paper {ref}", fontsize=7, va={"A": "bottom", "B": "top"}.get(ref, "center"))
    ax.set_xlabel("reference (front-aspect) RCS (dBsm)")
    ax.set_ylabel("whole-track E_error,avg (m): mean (o), median (^)")
    ax.set_title("sensitivity to the withheld reference RCS, N = 600, R = 1 km", fontsize=9)
    ax.legend(fontsize=7)


# -- tables -------------------------------------------------------------------------------------------------


def make_table2(results) -> Table:
    r = RadarParameters()
    sens = ", ".join(f"{v:g}" for v in SENSITIVITY_RCS)
    rows = (
        ("operating frequency f", "L-band", f"{r.frequency / 1e9:g} GHz (lambda = {r.wavelength:.4f} m)"),
        ("transmit peak power Pt", "-", f"{r.peak_power / 1e3:g} kW"),
        ("pulse width tau", "-", f"{r.pulse_width * 1e6:g} us (B = 1/tau)"),
        ("number of pulses N", "100", f"{r.pulses}"),
        ("Tx / Rx antenna gain", "35 dBi", f"{r.gain_tx_db:g} / {r.gain_rx_db:g} dBi (theta_3dB = "
                                           f"{np.rad2deg(r.beamwidth):.2f} deg)"),
        ("system noise figure F", "10 dB", f"{r.noise_figure_db:g} dB"),
        ("system loss L", "-", f"{r.loss_db:g} dB"),
        ("RCS front / top / side", "Ref / Ref+5 / Ref+3 dBsm",
         f"Ref = {PRIMARY_RCS:g} dBsm (sensitivity: {sens}), 2 dB fluctuation per scan"),
        ("false-alarm probability", "(Pfa <= 1e-6, introduction)", f"{r.pfa:g}"),
        ("clutter rate", "- (shown in Figs 4, 5 and 7, not given)",
         f"{PRIMARY_CLUTTER_RATE:g} candidates per scan in a 10 km cube, mean CNR 3 dB (sensitivity: "
         + ", ".join(f"{v:g}" for v in CLUTTER_RATE.grid if v != PRIMARY_CLUTTER_RATE) + ")"),
    )
    return Table(("parameter", "paper (Table 2)", "this reproduction"), rows)


TABLE3_COLUMNS = ("method", "role", "runs", "k=1..100: mean (m)", "k=1..100: median (m)",
                  "k=1..100: mean of runs not lost (m)", "whole: mean (m)", "whole: median (m)",
                  "whole: mean of runs not lost (m)", "lost runs", "paper k=1..100 (m)", "paper whole (m)",
                  "run time, all runs (s)", "CPU time, all runs (s)")


def _table3_rows(runs: Mapping[str, Mapping[str, np.ndarray]]) -> tuple:
    rows = []
    for key, res in runs.items():
        early, whole = per_run_errors(res)
        lost = np.asarray(res["lost"], dtype=bool)
        e, w = error_summary(early, lost), error_summary(whole, lost)
        role = _role(key)
        cell = lambda v: round(v, 1) if np.isfinite(v) else "all lost"  # noqa: E731
        rows.append((_label(key), role, int(lost.size), *(cell(v) for v in e), *(cell(v) for v in w),
                     f"{int(lost.sum())}/{lost.size}", PUBLISHED["table3_k1_100_m"].get(role, ""),
                     PUBLISHED["table3_whole_m"].get(role, ""), round(float(np.sum(res["seconds"])), 2),
                     round(float(np.sum(res.get("cpu_seconds", res["seconds"]))), 2)))
    return tuple(rows)


def make_table3(results, rcs: float = PRIMARY_RCS) -> Table:
    runs = _table_runs(results, rcs)
    if not runs:
        raise InputError(f"paper 000 Table 3 has no method runs at {rcs:g} dBsm")
    return Table(TABLE3_COLUMNS, _table3_rows(runs))


def make_table3_all_runs(results) -> Table:
    """The judged rows over the paper's protocol and its independent replications together."""
    rows = {}
    for key in JUDGED:
        parts = [r for r in (_get(results, key, TABLE_PARTICLES, TABLE_RADIUS),
                             _get(results, key, TABLE_PARTICLES, TABLE_RADIUS, stream="replicate")) if r is not None]
        if parts:
            rows[key] = {"error": np.concatenate([np.asarray(p["error"]) for p in parts]),
                         "lost": np.concatenate([np.asarray(p["lost"]) for p in parts]),
                         "seconds": sum(float(p["seconds"]) for p in parts),
                         "cpu_seconds": sum(float(p.get("cpu_seconds", p["seconds"])) for p in parts)}
    if not rows:
        raise InputError("paper 000: no runs of methods A, B and C")
    return Table(TABLE3_COLUMNS, _table3_rows(rows))


def make_table_clutter(results) -> Table:
    s = _scenario(results)
    rows = []
    for j, t in enumerate(np.asarray(s["thresholds_db"])):
        dens = float(s["clutter_density_km3"][j])
        rows.append((f"{t:g}", round(float(s["clutter_expected_nocut"][j]), 1),
                     round(float(s["clutter_expected"][j]), 1), round(float(s["clutter_per_scan"][j]), 1), round(dens, 3),
                     round(dens * 4 / 3 * np.pi * 2.5**3, 2), round(dens * 4 / 3 * np.pi * 1.0**3, 2)))
    return Table(("threshold (dB)", "expected / scan, whole cube", "expected / scan, 0-6 km band", "simulated / scan",
                  "density (km^-3)", "expected in a 2.5 km gate", "expected in a 1 km gate"), tuple(rows))


def _candidates_text(step) -> str:
    def one(c: dict) -> str:
        return "(" + ", ".join(f"{k}={v}" if not isinstance(v, tuple) else f"{k}=({', '.join(f'{x:g}' for x in v)})"
                               for k, v in c.items()) + ")" if len(c) > 1 else f"{next(iter(c.values()))}"
    return "; ".join(one(c) for c in step.candidates)


def make_table_tuning(results) -> Table:
    """The settings chosen by a search: candidates, tuning seeds, the rule, and the values the filters use."""
    s = _scenario(results)
    used = {
        tuning.STEPS[0].name: f"{float(s['used_floor_scale']):g}",
        tuning.STEPS[1].name: "sigma_a = ({}) m/s^2, on {:g}, off {:g}, x{:g}".format(
            ", ".join(f"{v:g}" for v in np.asarray(s["used_sigma_a"])), *np.asarray(s["used_switching"])),
        tuning.STEPS[2].name: f"{float(s['used_regularisation']):g}",
        tuning.STEPS[3].name: str(s["used_clutter_term"]),
        tuning.STEPS[4].name: str(s["used_clutter_term"]),
        tuning.STEPS[5].name: f"{float(s['used_regularisation_ours_b']):g}",
    }
    seeds = ", ".join(str(v) for v in tuning.TUNING_SEEDS)
    rows = tuple((step.name, _label(step.method), _candidates_text(step), seeds, used.get(step.name, ""))
                 for step in tuning.STEPS)
    return Table(("setting", "scored on", "candidates", "tuning seeds (20 runs each)", "value used"),
                 rows + (("rule", "", tuning.RULE, seeds, ""),))


# -- criteria -----------------------------------------------------------------------------------------------


def _fmt(values: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {v:.0f}" for k, v in values.items())


# Each statistic below is declared with its form over a batch of resamples (workbench.criteria.vectorised): the
# same numbers, from the means over each resample's runs (given="means"), the resample counts ("counts") or the
# resampled runs on axis 1 ("resamples"), so that the bootstrap evaluates its 2,000 resamples at once.

def _first_min(*values):
    """Python's ``min`` of the arguments, element-wise over resamples (the first smallest; NaN as ``min`` reads it)."""
    out = values[0]
    for v in values[1:]:
        out = np.where(v < out, v, out)
    return out


def _ordering_one(ea, eb, ec, wa, wb, wc) -> float:
    # min(B/C, A/B) over both averages: > 1 iff C < B < A for both
    return float(min(eb.mean() / ec.mean(), ea.mean() / eb.mean(), wb.mean() / wc.mean(), wa.mean() / wb.mean()))


def _ordering_many(ea, eb, ec, wa, wb, wc):  # the means over each resample's runs
    return _first_min(eb / ec, ea / eb, wb / wc, wa / wb)


_ordering = vectorised(_ordering_one, _ordering_many, given="means")


def _a_over_c_one(wa, wc) -> float:
    return float(wa.mean() / wc.mean())


_a_over_c = vectorised(_a_over_c_one, lambda wa, wc: wa / wc, given="means")


def _early_over_whole_one(ea, eb, ec, wa, wb, wc) -> float:
    return float(min(ea.mean() / wa.mean(), eb.mean() / wb.mean(), ec.mean() / wc.mean()))


def _early_over_whole_many(ea, eb, ec, wa, wb, wc):  # the means over each resample's runs
    return _first_min(ea / wa, eb / wb, ec / wc)


_early_over_whole = vectorised(_early_over_whole_one, _early_over_whole_many, given="means")


#: N_conv of a sweep that is not non-increasing within noise (outside every passing range)
NOT_MONOTONE = 0


def _n_conv(ns: np.ndarray):
    def statistic(*per_n) -> float:
        mean = np.array([x.mean() for x in per_n])
        se = np.array([x.std(ddof=1) / np.sqrt(x.size) if x.size > 1 else 0.0 for x in per_n])
        monotone = all(mean[j + 1] <= mean[j] + 2.0 * max(se[j], se[j + 1]) for j in range(len(per_n) - 1))
        if not monotone:
            return float(NOT_MONOTONE)
        within = np.abs(mean - mean[-1]) <= 0.05 * mean[-1]
        return float(next(int(ns[j]) for j in range(len(per_n)) if within[j:].all()))

    def many(*per_n):
        mean = np.stack([x.mean(axis=1) for x in per_n], axis=1)  # (resamples, N values)
        runs = per_n[0].shape[1]
        se = np.stack([x.std(axis=1, ddof=1) / np.sqrt(runs) if runs > 1 else np.zeros(x.shape[0])
                       for x in per_n], axis=1)
        monotone = np.all(mean[:, 1:] <= mean[:, :-1] + 2.0 * np.maximum(se[:, :-1], se[:, 1:]), axis=1)
        last = mean[:, -1:]
        within = np.abs(mean - last) <= 0.05 * last
        tail = np.flip(np.logical_and.accumulate(np.flip(within, axis=1), axis=1), axis=1)  # within[j:].all()
        first = np.argmax(tail, axis=1)
        n_conv = np.where(tail.any(axis=1), np.asarray(ns, dtype=float)[first].astype(int), np.nan)
        return np.where(monotone, n_conv, float(NOT_MONOTONE))
    return vectorised(statistic, many)


def _radius_difference_one(w25, w1) -> float:
    return float(abs(w25.mean() - w1.mean()) / w1.mean())


_radius_difference = vectorised(_radius_difference_one, lambda w25, w1: np.abs(w25 - w1) / w1, given="means")


def _below_measurement_one(e25, m25, e1, m1) -> float:
    fracs = []
    for e, m in ((e25, m25), (e1, m1)):
        with np.errstate(invalid="ignore"):
            m_mean = mean_over_runs(m)
        ok = np.isfinite(m_mean)
        fracs.append(float(np.mean(e.mean(axis=0)[ok] < m_mean[ok])) if ok.any() else float("nan"))
    return float(min(fracs))


def _below_measurement_many(counts, e25, m25, e1, m1):
    # counts (resamples, runs): the means over the resampled runs as weighted sums, without copying the
    # (runs, scans) rows once per resample
    runs = counts.shape[1]
    fracs = []
    for e, m in ((e25, m25), (e1, m1)):
        finite = np.isfinite(m)
        count = counts @ finite.astype(float)  # mean_over_runs over the resampled runs
        with np.errstate(invalid="ignore"):
            m_mean = np.where(count > 0, (counts @ np.where(finite, m, 0.0)) / np.maximum(count, 1), np.nan)
        ok = np.isfinite(m_mean)
        e_finite = np.isfinite(e)  # a non-finite error counts only where its run is drawn (then no scan is below)
        with np.errstate(invalid="ignore"):
            e_mean = np.where(counts @ (~e_finite).astype(float) > 0, np.nan,
                              (counts @ np.where(e_finite, e, 0.0)) / runs)
            below = (e_mean < m_mean) & ok
        scans = ok.sum(axis=1)
        fracs.append(np.where(scans > 0, below.sum(axis=1) / np.maximum(scans, 1), np.nan))
    return _first_min(*fracs)


_below_measurement = vectorised(_below_measurement_one, _below_measurement_many, given="counts")


def _pooled(results, key: str, particles: int, radius: float, rcs: float, rate: float = PRIMARY_CLUTTER_RATE):
    """A row's runs of the paper's protocol and, at the primary values, its independent replications."""
    parts = [_get(results, key, particles, radius, rcs, rate=rate)]
    if np.isclose(rcs, PRIMARY_RCS) and np.isclose(rate, PRIMARY_CLUTTER_RATE):
        parts.append(_get(results, key, particles, radius, rcs, stream="replicate"))
    parts = [p for p in parts if p is not None]
    if not parts:
        return None
    out = {f: np.concatenate([np.asarray(p[f]) for p in parts]) for f in ("error", "m_error", "lost")
           if all(f in p for p in parts)}
    out["seconds"] = np.array([float(p["seconds"]) for p in parts])
    out["cpu_seconds"] = np.array([float(p.get("cpu_seconds", p["seconds"])) for p in parts])
    return out


def _with_ours(results, rcs: float, statistic, pairs: str, rate: float = PRIMARY_CLUTTER_RATE) -> str:
    """The same statistic with our A and B (the improvement rows) in place of the paper's, on the paper's protocol
    (their runs, with C's same runs); ``pairs`` picks the arguments: ``"six"`` (early and whole of A, B, C) or
    ``"ac"`` (whole of A and C)."""
    rows = [_get(results, k, TABLE_PARTICLES, TABLE_RADIUS, rcs, rate=rate) for k in ("A+", "B+", "C")]
    if any(r is None for r in rows):
        return ""
    (ea, wa), (eb, wb), (ec, wc) = (per_run_errors(r) for r in rows)
    value = statistic(ea, eb, ec, wa, wb, wc) if pairs == "six" else statistic(wa, wc)
    medians = statistic(*(np.array([np.median(x)]) for x in (ea, eb, ec, wa, wb, wc))) if pairs == "six" else \
        statistic(np.array([np.median(wa)]), np.array([np.median(wc)]))
    return (f"; with our A and B instead (improvements, the paper's {wa.size} runs): {value:.2f} from the means, "
            f"{medians:.2f} from the medians")


def _cpu_ratio_one(wide, table) -> float:
    # CPU time at R = 2.5 km / at R = 1 km
    return float(np.mean(wide) / np.mean(table))


_cpu_ratio = vectorised(_cpu_ratio_one, lambda wide, table: wide / table, given="means")


def _with_timing(crit: Criterion, results) -> Criterion:
    """Criterion 5 with its timing part: "R = 2.5 km takes longer" judged on the repeated timing task (the CPU-time
    ratio of the two radii, bootstrap over the repetitions, at least :data:`MIN_TIMING_REPEATS`), combined with the
    accuracy part: met only where both are met, not met where either is not met, else inconclusive."""
    from dataclasses import replace

    task = results.get(f"timing@{_rcs_tag(PRIMARY_RCS)}")
    if task is None:
        return replace(crit, verdict="inconclusive" if crit.verdict == "met" else crit.verdict,
                       detail=crit.detail + "; timing not measured at this size (the full report repeats it "
                                            f"{TIMING_REPEATS} times): the criterion cannot be met")
    wide, table = np.asarray(task["cpu_wide"], dtype=float), np.asarray(task["cpu_table"], dtype=float)
    timing = criterion_from_runs("5-time", "R = 2.5 km takes longer", (wide, table), _cpu_ratio, 1.0, ">",
                                 min_n=MIN_TIMING_REPEATS, threshold_text="CPU(R = 2.5 km) / CPU(R = 1 km) > 1")
    lo, hi = timing.interval
    verdicts = {crit.verdict, timing.verdict}
    verdict = "not met" if "not met" in verdicts else "met" if verdicts == {"met"} else "inconclusive"
    text = (f"timing: CPU time at R = 2.5 km / at R = 1 km = {timing.ours:.3f}, 95 % interval [{lo:.3f}, {hi:.3f}] "
            f"over {wide.size} repetitions in turn on the same {int(task['runs'])} runs at {float(task['rcs']):g} dBsm "
            f"(method C, N = {TABLE_PARTICLES}; {np.mean(wide):.2f} vs {np.mean(table):.2f} s; needs >= "
            f"{MIN_TIMING_REPEATS}): "
            f"{timing.verdict}")
    if verdict != crit.verdict:
        text += f"; the accuracy part alone: {crit.verdict}"
    return replace(crit, verdict=verdict, detail=f"{crit.detail}; {text}",
                   extra={**crit.extra, "timing": {"ratio": timing.ours, "interval": [lo, hi], "n": int(wide.size),
                                                   "verdict": timing.verdict}})


def _replication(samples, holds) -> tuple[int, int] | None:
    n = np.asarray(samples[0]).shape[0]
    if n < 2 * PROTOCOL_RUNS:
        return None
    return replication_rate(samples, PROTOCOL_RUNS, holds, replications=n // PROTOCOL_RUNS)


def calibration(results) -> dict | None:
    """The calibration's outcome (:data:`tuning.CALIBRATION_RULE` on the calibration task's tuning-seed runs):
    ``{"points", "whole_a", "whole_b", "lost_a", "lost_b", "scores", "chosen" (index), "point", "seed", "runs"}``, or
    None where the task did not run."""
    res = results.get("calibration")
    if res is None or "A__whole" not in res:
        return None
    points = [tuple(float(v) for v in p) for p in np.asarray(res["points"])]
    whole_a, whole_b = np.asarray(res["A__whole"]).mean(axis=1), np.asarray(res["B__whole"]).mean(axis=1)
    chosen = tuning.calibrate(points, whole_a, whole_b, (PRIMARY_RCS, PRIMARY_CLUTTER_RATE),
                              (PUBLISHED["table3_whole_m"]["A"], PUBLISHED["table3_whole_m"]["B"]))
    return {"points": points, "whole_a": whole_a, "whole_b": whole_b,
            "lost_a": np.asarray(res["A__lost"]).sum(axis=1), "lost_b": np.asarray(res["B__lost"]).sum(axis=1),
            "scores": tuning.calibration_scores(whole_a, whole_b, (PUBLISHED["table3_whole_m"]["A"],
                                                                    PUBLISHED["table3_whole_m"]["B"])),
            "chosen": chosen, "point": points[chosen], "seed": int(res["seed"]), "runs": int(res["runs"])}


def criteria(results) -> list[Criterion]:
    """Criteria 1-6 at the primary values (criteria 1-3 carry their verdicts across the declared unknowns' grids,
    ``Criterion.across``, where the grid ran) and, where the calibration ran, criteria 1-3 at the calibrated values
    on the report's runs (ids ``1@calibrated`` ...)."""
    from dataclasses import replace

    out = _criteria_at(results, PRIMARY_RCS)
    ordering = {c.id: j for j, c in enumerate(out) if c.id in ("1", "2", "3")}
    for unknown, points in ((REFERENCE_RCS, {v: (float(v), PRIMARY_CLUTTER_RATE) for v in REFERENCE_RCS.grid}),
                            (CLUTTER_RATE, {v: (PRIMARY_RCS, float(v)) for v in CLUTTER_RATE.grid})):
        at = {}
        for value, (rcs, rate) in points.items():
            if (rcs, rate) == (PRIMARY_RCS, PRIMARY_CLUTTER_RATE):
                at[value] = {c.id: c for c in out}
                continue
            judged = _ordering_criteria(results, rcs, rate, "", "")
            if judged is None:
                at = {}
                break
            at[value] = {c.id: c for c in judged}
        if not at or not ordering:
            continue
        notes = {v: ("the paper's protocol and its replications" if points[v] == (PRIMARY_RCS, PRIMARY_CLUTTER_RATE)
                     else f"{PROTOCOL_RUNS} runs of the paper's protocol, the same draws") for v in unknown.grid}
        for cid, j in ordering.items():
            out[j] = replace(out[j], across=out[j].across + judge_across(
                unknown, {v: at[v][cid] for v in unknown.grid}, notes))
    cal = calibration(results)
    if cal is not None:
        rcs, rate = cal["point"]
        where = (f" [calibrated values: reference RCS {rcs:g} dBsm, clutter rate {rate:g} per scan, chosen on tuning "
                 f"seed {cal['seed']}]")
        judged = _ordering_criteria(results, rcs, rate, "@calibrated", where)
        if judged is not None:
            out += judged
        else:
            out += [Criterion(f"{cid}@calibrated", "needs the judged rows at the calibrated values" + where,
                              "inconclusive", "not run: the grid task of the calibrated point is missing")
                    for cid in ("1", "2", "3")]
    return out


def _ordering_criteria(results, rcs: float, rate: float, tag: str, where: str) -> list[Criterion] | None:
    """Criteria 1-3 on the judged rows at ``(rcs, rate)``; None where a judged row did not run there."""
    rows = {k: _pooled(results, k, TABLE_PARTICLES, TABLE_RADIUS, rcs, rate) for k in JUDGED}
    if any(r is None for r in rows.values()):
        return None
    return _judged_criteria(results, rows, rcs, tag, where, rate)


def _criteria_at(results, rcs: float) -> list[Criterion]:
    primary = np.isclose(rcs, PRIMARY_RCS)
    tag = "" if primary else f"@{rcs:g}dBsm"
    where = "" if primary else f" [reference RCS {rcs:g} dBsm]"
    out = []
    rows = {k: _pooled(results, k, TABLE_PARTICLES, TABLE_RADIUS, rcs) for k in JUDGED}
    if all(r is not None for r in rows.values()):
        out += _judged_criteria(results, rows, rcs, tag, where)
    else:
        missing = [k for k, r in rows.items() if r is None]
        for cid in ("1", "2", "3"):
            out.append(Criterion(f"{cid}{tag}", "needs methods A, B and C" + where, "inconclusive",
                                 f"not run: {', '.join(missing)}"))
    return out + _method_c_criteria(results, rcs, tag, where)


def _judged_criteria(results, rows, rcs: float, tag: str, where: str,
                     rate: float = PRIMARY_CLUTTER_RATE) -> list[Criterion]:
    """Criteria 1-3 (the ordering, A/C, early > whole) on the judged rows ``rows`` (key -> pooled runs)."""
    out = []
    (ea, wa), (eb, wb), (ec, wc) = (per_run_errors(rows[k]) for k in JUDGED)
    six = (ea, eb, ec, wa, wb, wc)
    lost = {k: f"{int(rows[k]['lost'].sum())}/{rows[k]['lost'].size}" for k in JUDGED}
    tracks = rows_track({k: np.asarray(rows[k]["lost"], dtype=bool) for k in JUDGED}, MAX_LOST_SHARE)
    tracks_ac = rows_track({k: np.asarray(rows[k]["lost"], dtype=bool) for k in ("A", "C")}, MAX_LOST_SHARE)
    means = (f"k=1..100: {_fmt(dict(A=ea.mean(), B=eb.mean(), C=ec.mean()))} m; whole: "
             f"{_fmt(dict(A=wa.mean(), B=wb.mean(), C=wc.mean()))} m; medians whole: "
             f"{_fmt(dict(A=np.median(wa), B=np.median(wb), C=np.median(wc)))} m; lost A {lost['A']}, "
             f"B {lost['B']}, C {lost['C']}; statistic min(B/C, A/B) over both averages"
             + _with_ours(results, rcs, _ordering, "six", rate))
    out.append(criterion_from_runs(
        f"1{tag}", "Ordering C < B < A for both averages (mean over runs)" + where, six, _ordering, 1.0, ">",
        min_n=PROTOCOL_RUNS, published="C < B < A (221 < 291 < 332 m, 124 < 214 < 236 m)",
        detail=means, threshold_text="min(B/C, A/B) > 1 for k = 1..100 and whole",
        replication=_replication(six, lambda *a: _ordering(*a) > 1.0), preconditions=(tracks,)))
    out.append(criterion_from_runs(
        f"2{tag}", "A/C >= 1.3 on the whole track" + where, (wa, wc), _a_over_c, 1.3, ">=", min_n=PROTOCOL_RUNS,
        published=1.90, detail=(f"whole: A {wa.mean():.0f} m, C {wc.mean():.0f} m; medians "
                                f"{np.median(wa):.0f} / {np.median(wc):.0f} m; lost A {lost['A']}, "
                                f"C {lost['C']}" + _with_ours(results, rcs, _a_over_c, "ac", rate)),
        replication=_replication((wa, wc), lambda a, c: _a_over_c(a, c) >= 1.3), preconditions=(tracks_ac,)))
    out.append(criterion_from_runs(
        f"3{tag}", "Every method's k = 1..100 average is larger than its whole-track average" + where, six,
        _early_over_whole, 1.0, ">", min_n=PROTOCOL_RUNS, published="A 332/236, B 291/214, C 221/124 m",
        detail=(", ".join(f"{k}: {e.mean():.0f} vs {w.mean():.0f} m" for k, e, w in
                          (("A", ea, wa), ("B", eb, wb), ("C", ec, wc)))
                + "; statistic min over methods of (k=1..100 mean / whole mean)"
                + _with_ours(results, rcs, _early_over_whole, "six", rate)),
        threshold_text="min over A, B, C of early / whole > 1",
        replication=_replication(six, lambda *a: _early_over_whole(*a) > 1.0), preconditions=(tracks,)))
    return out


def _method_c_criteria(results, rcs: float, tag: str, where: str) -> list[Criterion]:
    """Criteria 4-6 (method C alone: the N sweep, the gate radius, E_error < M_error) at ``rcs``."""
    primary = np.isclose(rcs, PRIMARY_RCS)
    out = []
    ns, per_n = _sweep(results, rcs)
    if ns.size >= 2:
        stat = _n_conv(ns)
        out.append(criterion_from_runs(
            f"4{tag}", f"N sweep non-increasing within noise (2 standard errors) and N_conv (within 5 % of "
            f"N = {int(ns[-1])}) in 300..800" + where, tuple(per_n), stat, (300.0, 800.0), "within",
            min_n=PROTOCOL_RUNS, published="N_conv ~ 600",
            detail=("E_avg (mean over runs): " + ", ".join(f"N={n}: {x.mean():.0f}" for n, x in
                                                             zip(ns, per_n))
                    + "; medians: " + ", ".join(f"{np.median(x):.0f}" for x in per_n)
                    + f"; the statistic is N_conv, {NOT_MONOTONE} when the sweep is not monotone within "
                      "noise; the sweep is run on the paper's protocol only (no replications)"),
            threshold_text="N_conv in [300, 800] and monotone"))
    elif primary:
        out.append(Criterion("4", "N sweep converges by N_conv in 300..800", "inconclusive", "no particle-count sweep"))
    r25 = _pooled(results, "C", TABLE_PARTICLES, WIDE_RADIUS, rcs)
    r1 = _pooled(results, "C", TABLE_PARTICLES, TABLE_RADIUS, rcs)
    if r25 is not None and r1 is not None and r25["error"].shape[0] == r1["error"].shape[0]:
        w25, w1 = per_run_errors(r25)[1], per_run_errors(r1)[1]
        g25 = np.mean(_get(results, "C", TABLE_PARTICLES, WIDE_RADIUS, rcs)["gated"])
        g1 = np.mean(_get(results, "C", TABLE_PARTICLES, TABLE_RADIUS, rcs)["gated"])
        crit = criterion_from_runs(
            f"5{tag}", "|E_avg(R=2.5) - E_avg(R=1)| / E_avg(R=1) < 15 % and R = 2.5 km takes longer" + where,
            (w25, w1), _radius_difference, 0.15, "<", min_n=PROTOCOL_RUNS, published="negligible difference; 2.5 km "
            "costs more",
            detail=(f"whole E_avg {w25.mean():.0f} vs {w1.mean():.0f} m (medians {np.median(w25):.0f} / "
                    f"{np.median(w1):.0f} m, lost {int(r25['lost'].sum())} / {int(r1['lost'].sum())}); "
                    f"gated per scan {g25:.1f} vs {g1:.1f}; the replications judge the accuracy part"),
            replication=_replication((w25, w1), lambda a, b: _radius_difference(a, b) < 0.15))
        out.append(_with_timing(crit, results))
        e25, m25 = np.asarray(r25["error"]), np.asarray(r25["m_error"])
        e1, m1 = np.asarray(r1["error"]), np.asarray(r1["m_error"])
        frac = _below_measurement(e25, m25, e1, m1)
        out.append(criterion_from_runs(
            f"6{tag}", "E_error < M_error at almost every k (>= 90 % of the scans with gated detections; N = 600)"
            + where, (e25, m25, e1, m1), _below_measurement, 0.9, ">=", min_n=PROTOCOL_RUNS,
            published="E_error below M_error throughout (Fig. 10)",
            detail=(f"fraction of scans with E < M (both curves means over runs): min over R = 2.5, 1 km "
                    f"= {frac:.2f}; whole-track E_avg {w25.mean():.0f} / {w1.mean():.0f} m (50-400 m "
                    "acceptable)"),
            replication=_replication((e25, m25, e1, m1), lambda *a: _below_measurement(*a) >= 0.9)))
    else:
        for cid in ("5", "6"):
            out.append(Criterion(f"{cid}{tag}", "needs the N = 600 runs with R = 2.5 and 1 km" + where,
                                 "inconclusive", "not run"))
    return out


UNKNOWNS_COLUMNS = ("reference RCS (dBsm)", "clutter rate (per scan)", "method", "runs", "k=1..100: mean (m)",
                    "whole: mean (m)", "whole: median (m)", "lost runs", "paper whole (m)", "criteria 1 / 2 / 3")


def make_table_unknowns(results) -> Table:
    """The judged rows at every point of the declared unknowns' grid (:func:`grid_points`), the paper's protocol on
    the report's seed (the same draws at every point), with criteria 1-3 judged there on those runs."""
    rows = []
    for rcs, rate in grid_points():
        runs = {k: _get(results, k, TABLE_PARTICLES, TABLE_RADIUS, rcs, rate=rate) for k in JUDGED}
        if any(r is None for r in runs.values()):
            rows.append((rcs, rate, "not run at this size (the full report runs the grid)", *("",) * 7))
            continue
        judged = _judged_criteria(results, runs, rcs, "", "", rate)
        verdicts = " / ".join(c.verdict for c in judged)
        for key, res in runs.items():
            early, whole = per_run_errors(res)
            lost = np.asarray(res["lost"], dtype=bool)
            rows.append((rcs, rate, _label(key), int(lost.size), round(float(early.mean()), 1),
                         round(float(whole.mean()), 1), round(float(np.median(whole)), 1),
                         f"{int(lost.sum())}/{lost.size}", PUBLISHED["table3_whole_m"].get(key, ""), verdicts))
    return Table(UNKNOWNS_COLUMNS, tuple(rows))


CALIBRATION_COLUMNS = ("reference RCS (dBsm)", "clutter rate (per scan)", "A whole: mean (m)", "B whole: mean (m)",
                       "lost A", "lost B", "score |ln(A/236)| + |ln(B/214)|", "chosen")


def make_table_calibration(results) -> Table:
    """The calibration of the withheld values against Table 3's A and B: every candidate's tuning-seed numbers, its
    score and the choice, with the rule written down before the result."""
    cal = calibration(results)
    rule = ("rule", "", "", "", "", "", tuning.CALIBRATION_RULE, "")
    if cal is None:
        return Table(CALIBRATION_COLUMNS, (("not run at this size: the full report calibrates on tuning seed "
                                            f"{tuning.CALIBRATION_SEED}", *("",) * 7), rule))
    rows = tuple((rcs, rate, round(float(a), 1), round(float(b), 1), f"{int(la)}/{cal['runs']}",
                  f"{int(lb)}/{cal['runs']}", round(float(sc), 3) if np.isfinite(sc) else "inf",
                  "chosen" if j == cal["chosen"] else "")
                 for j, ((rcs, rate), a, b, la, lb, sc) in enumerate(zip(cal["points"], cal["whole_a"], cal["whole_b"],
                                                                           cal["lost_a"], cal["lost_b"], cal["scores"])))
    return Table(CALIBRATION_COLUMNS, rows + (rule,))


RECIPE = RecipeSpec(
    paper=PAPER,
    title="Radar particle filter for track-before-detect (L-band, low SNR, heavy clutter)",
    sizes={
        "quick": {"runs": 2, "path_particles": [100, 600], "sweep_particles": [100, 600], "unknowns": False,
                  "calibration_runs": 0, "replicated_runs": 0},
        "full": {"runs": PROTOCOL_RUNS, "path_particles": [100, 600],
                 "sweep_particles": [50, 100, 200, 300, 400, 500, 600, 800, 1000],
                 "unknowns": True, "calibration_runs": tuning.CALIBRATION_RUNS, "replicated_runs": 80,
                 "timing_repeats": TIMING_REPEATS},
    },
    tasks=tasks,
    figures=(
        FigureSpec("fig2", "True 3-D path, radar at the origin; front / top / side aspect phases.", fig2_data,
                   draw_fig2),
        FigureSpec("fig3", "Target SNR along the path (red: with 2 dB RCS fluctuation, run 0; black: nominal) and "
                   "the thresholds 12/9/7/5/3 dB.", fig3_data, draw_fig3, size=(7.0, 4.2)),
        FigureSpec("fig4", "Scenario with radar clutter: all detections >= 3 dB of run 0 (clutter of every 10th "
                   "scan) and the true path.", fig4_data, draw_fig4),
        FigureSpec("fig5", "(a) true path; (b)-(f) detections kept at the thresholds 12, 9, 7, 5 and 3 dB (run 0, "
                   "clutter of every 10th scan).", fig5_data, draw_fig5, size=(10.0, 6.5)),
        FigureSpec("fig5_counts", "Detections per scan passing each threshold (target + clutter, mean over runs).",
                   fig5_counts_data, draw_fig5_counts, size=(7.0, 4.2)),
        FigureSpec("fig6", "Gating: detections >= 5 dB of one scan around the predicted position, R = 2.5 and 1 km.",
                   fig6_data, draw_fig6, size=(6.0, 6.0)),
        FigureSpec("fig7", "Detections >= 5 dB inside the gate, accumulated over k (run 0 of the N = 600 method-C "
                   "runs), (a) R = 2.5 km, (b) R = 1 km.", fig7_data, draw_fig7, size=(10.0, 4.8)),
        FigureSpec("fig8", "True (green) vs estimated (blue) path, method C, N = 100, (a) R = 2.5 km, (b) R = 1 km.",
                   lambda r: _paths_data(r, 100), lambda d, f: _draw_paths(d, f, 100), size=(10.0, 4.8)),
        FigureSpec("fig9", "True (green) vs estimated (blue) path, method C, N = 600, (a) R = 2.5 km, (b) R = 1 km.",
                   lambda r: _paths_data(r, 600), lambda d, f: _draw_paths(d, f, 600), size=(10.0, 4.8)),
        FigureSpec("fig10", "Measurement error M_error(k) (eq 19, gated detections) vs estimation error E_error(k) "
                   "(eq 20), method C, N = 600, R = 2.5 and 1 km.", fig10_data, draw_fig10, size=(7.0, 4.2)),
        FigureSpec("fig11", "E_error(k) per particle count N (method C, R = 1 km, mean over runs).", fig11_data,
                   draw_fig11, size=(7.0, 4.2)),
        FigureSpec("fig12", "Average estimation error E_error,avg (eq 21) vs N: mean over runs (lost runs "
                   "included) +- 1 std, and the median.", fig12_data, draw_fig12, size=(6.0, 4.2)),
        FigureSpec("fig13", "E_error(k) per method: the paper's A and B (fixed R), C, our A and B (dashed) and the "
                   "ablations of C (dotted); N = 600, R = 1 km, mean over runs.", fig13_data, draw_fig13,
                   size=(8.0, 4.8)),
        FigureSpec("fig14", "Not in the paper: whole-track error of A, B, C and our A, B against the withheld "
                   "reference RCS (mean and median over runs; the paper's Table 3 as dotted lines).", fig14_data,
                   draw_fig14, size=(7.0, 4.2)),
    ),
    tables=(
        TableSpec("table2", "Radar parameters: the paper's Table 2 and the values chosen here.", make_table2),
        TableSpec("table3", f"Average estimation error per method (k = 1..100 and whole track), reference RCS "
                  f"{PRIMARY_RCS:g} dBsm, the paper's protocol (20 runs, N = 600, R = 1 km): mean over runs with "
                  "lost runs included, the median, the mean over the runs not lost, the lost count; published values "
                  "beside ours; warmed-up wall and CPU time of all runs in one batched call.", make_table3),
        TableSpec("table3_all_runs", "Methods A, B and C over the paper's protocol and its independent replications "
                  "together (the runs the criteria are judged on).", make_table3_all_runs),
        TableSpec("table_unknowns", "The judged rows A, B and C at every point of the declared unknowns' grid (reference "
                  "RCS at the primary clutter rate; clutter rate at -20 and at -15 dBsm), the paper's protocol (20 "
                  "runs, N = 600, R = 1 km) on the report's seed with the same draws at every point, and criteria 1-3 "
                  "judged on those runs.", make_table_unknowns),
        TableSpec("table_calibration", "Calibration of the withheld reference RCS and clutter rate against the "
                  "paper's Table 3 (A 236 m, B 214 m, whole track) on a tuning seed, by the rule written down before "
                  "the result; criteria 1-3 are judged again at the chosen values on the report's runs "
                  "(1@calibrated ...).", make_table_calibration),
        TableSpec("table_clutter", "Clutter passing each threshold: expected (amplitude law) vs simulated.",
                  make_table_clutter),
        TableSpec("table_tuning", "Settings chosen by a search on tuning seeds the report never uses: the "
                  "candidates, the seeds, the rule and the values the filters use (docs/paper000.md).",
                  make_table_tuning),
    ),
    criteria=criteria,
    default_filters=tuple(m.filter for m in METHODS),
    published=PUBLISHED,
    notes=NOTES,
    unknowns=(REFERENCE_RCS, CLUTTER_RATE),
)
