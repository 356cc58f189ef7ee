"""Paper 000's tasks: what the report computes, and the helpers that read it back.

Every task draws its runs from the scenario (:mod:`.scenario`) and runs the rows of :data:`~.methods.METHODS` on
them (:func:`~.methods.run_method`); one simulation per task is shared by every row it runs (common random numbers).

- ``scenario``: the SNR along the path, the detections per threshold and run 0's detections (Figs 2-6);
- ``table@<point>``: what the verdicts read at the primary values: the judged rows A, B and C (N = 600, R = 1 km),
  C at R = 2.5 km (criteria 5 and 6) and our A and B (the criteria's detail), on the paper's protocol (20 runs);
- ``ablations@<point>``: the rows only Table 3 and Fig. 13 show (the ablations, any ``--filters`` extra) and the
  path figure's N = 100 at R = 2.5 km, on the same draws; no criterion reads them, so the confirmation seed does
  not run them again;
- ``sweep@<point>``: method C at the other particle counts (criterion 4, Figs 11 and 12);
- ``replicate@<point>``: A, B and C at both radii on 80 independent runs (the stream ``"replicate"``), C in batches of
  the paper's 20 runs with the two radii in turn, each batch one repetition of criterion 5's timing;
- ``grid@<point>``: the judged rows at every other point of the declared unknowns' grid (:func:`grid_points`), on
  the same draws; declared ``sensitivity`` (they feed ``Criterion.across`` only) except the calibrated point
  (:data:`~.tuning.CALIBRATED_POINT`), where criteria 1-3 are judged again;
- ``calibration``: the literal A and B at every grid point on the tuning seed (``seeded=False``).

A run task's arrays are ``<row key>__N<particles>__R<radius>__<field>`` (:data:`FIELDS`); :func:`runs_of` reads
them back by task key (never by looking into another task's arrays, so that the criteria read only what they need).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from workbench.report.engine import component_failure
from workbench.sensing.radar import aspect_rcs_db, clutter_pass_fraction, db, from_db, radar_snr
from workbench.specs import RecipeOptions, Task, TaskContext
from workbench.types import InputError

from . import tuning
from .methods import CLUTTER_TERM, METHODS, PROPOSED, SIGMA_A, TRACK_THRESHOLD_DB, method_of, rows_for, run_method
from .scenario import (CLUTTER_RATE, PRIMARY_CLUTTER_RATE, PRIMARY_RCS, REFERENCE_RCS, clutter_for, scenario_truth,
                       sensor_for, simulate_scans, tracking_model)

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
#: the rows the criteria judge
JUDGED = ("A", "B", "C")
#: the roles of the rows the ``table`` task runs (what the criteria read); every other row goes to ``ablations``
VERDICT_ROLES = (*JUDGED, "ours")
#: the run tasks the criteria read (``ablations`` is for Table 3 and Fig. 13 alone)
JUDGED_TASKS = ("table", "sweep", "grid")
#: every run task on the paper's protocol's stream
PROTOCOL_TASKS = ("table", "ablations", "sweep", "grid")
FIELDS = ("error", "m_error", "gated", "lost", "seconds", "cpu_seconds", "cpu_batches", "path0", "gated0")


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



def _one_row(ctx: TaskContext, combo, scans, truth, model, rng_key: tuple, rate: float):
    """One row ``[filter, particles, radius(, row key)]`` on ``scans``: its :func:`~.methods.run_method` arrays."""
    # [filter, particles, radius] runs the filter's first row (the judged one where it has one), a fourth element
    # names the row (A and its 4-vector ablation share the filter "ekf")
    ref, particles, radius = combo[:3]
    key = combo[3] if len(combo) > 3 else None
    spec = ctx.host.filter(ref)
    method = method_of(key, ref, spec.capabilities) if key is not None else rows_for(ref, spec.capabilities)[0]
    res = run_method(ctx.host, method, scans, truth, model, radius=float(radius), particles=int(particles),
                     seed=ctx.seed, rng_key=rng_key, clutter_rate=None if rate == PRIMARY_CLUTTER_RATE else rate)
    return method, {**res, "cpu_batches": np.atleast_1d(res["cpu_seconds"]).astype(float)}


def _joined(parts: list[dict]) -> dict:
    """The arrays of one row run in batches of runs, as one run over them all: per-run arrays joined along the runs,
    times summed (``cpu_batches``: each batch's CPU time), the path and gated points of the first batch's run 0."""
    first = parts[0]
    out = {f: np.concatenate([np.asarray(p[f]) for p in parts]) for f in ("error", "m_error", "gated", "lost")}
    out.update(seconds=np.array(sum(float(p["seconds"]) for p in parts)),
               cpu_seconds=np.array(sum(float(p["cpu_seconds"]) for p in parts)),
               cpu_batches=np.array([float(p["cpu_seconds"]) for p in parts]), path0=first["path0"],
               gated0=first["gated0"])
    return out


def _runs_task(ctx: TaskContext) -> dict[str, np.ndarray]:
    """Every ``(filter, particles, radius, row key)`` of ``combos`` on the same scans: ``runs`` runs at reference RCS
    ``rcs`` and clutter rate ``rate`` (the declared unknowns; the rate thins the same clutter draws), drawn from the
    stream ``stream`` ("" for the paper's protocol, "replicate" for its independent replications).

    The rows of ``timed`` (the two radii of method C) run after the others in batches of ``batch_runs`` runs, the
    rows in turn within each batch and their order alternating from batch to batch (batch ``j`` is repetition
    ``first_repetition + j`` of criterion 5's timing; an even repetition runs them as listed): each batch's CPU time
    is one repetition of "R = 2.5 km takes longer", on the batch's own runs."""
    p = ctx.params
    runs, rcs, stream = int(p["runs"]), float(p["rcs"]), str(p["stream"])
    rate = float(p.get("rate", PRIMARY_CLUTTER_RATE))
    truth = scenario_truth(runs)
    scans = simulate_scans(ctx.host, truth, ctx.seed, TRACK_THRESHOLD_DB, rcs, stream=stream,
                           clutter_rate=None if rate == PRIMARY_CLUTTER_RATE else rate)
    model = tracking_model(ctx.host, rcs, TRACK_THRESHOLD_DB)
    out = {"rcs": np.array(rcs), "rate": np.array(rate), "stream": np.array(stream), "runs": np.array(runs)}
    base = (stream,) if stream else ()

    def failed(combo, exc):
        ref, particles, radius = combo[:3]
        key = combo[3] if len(combo) > 3 else None
        row = "" if key is None or key == rows_for(ref)[0].key else f" as {key}"
        out.update(component_failure(f"filter:{ref}{row} (N={int(particles)}, R={float(radius):g} m)", exc))

    def store(method, combo, res):
        for field in FIELDS:
            out[f"{_combo(method.key, int(combo[1]), float(combo[2]))}__{field}"] = res[field]

    for combo in p["combos"]:
        # each row alone: a filter that raises loses its own row (named in the report: error/<row>), never the
        # other rows run on the same scans
        try:
            method, res = _one_row(ctx, combo, scans, truth.states, model, base, rate)
        except Exception as exc:  # noqa: BLE001 - isolated: reported by the report engine, the other rows kept
            failed(combo, exc)
            continue
        store(method, combo, res)
    timed = [list(c) for c in p.get("timed", [])]
    if timed:
        size = int(p["batch_runs"])
        first = int(p.get("first_repetition", 0))
        parts: dict[int, list] = {j: [] for j in range(len(timed))}
        broken: set[int] = set()
        methods = {}
        for b, start in enumerate(range(0, runs, size)):
            index = np.arange(start, min(runs, start + size))
            order = range(len(timed)) if (first + b) % 2 == 0 else reversed(range(len(timed)))
            for j in order:
                if j in broken:
                    continue
                try:
                    methods[j], res = _one_row(ctx, timed[j], scans.take(index), truth.states[index], model,
                                               (*base, "batch", b), rate)
                except Exception as exc:  # noqa: BLE001 - isolated as above
                    broken.add(j)
                    failed(timed[j], exc)
                    continue
                parts[j].append(res)
        for j, combo in enumerate(timed):
            if j not in broken:
                store(methods[j], combo, _joined(parts[j]))
    return out


def _combo(key: str, particles: int, radius: float) -> str:
    return f"{key}__N{particles}__R{radius:g}"


def _rcs_tag(rcs: float) -> str:
    return f"{rcs:g}dBsm"


def point_tag(rcs: float, rate: float = PRIMARY_CLUTTER_RATE) -> str:
    """The part of a run task's key that names its point of the declared unknowns (``-20dBsm``,
    ``-15dBsm@50perscan``)."""
    return _rcs_tag(rcs) + ("" if rate == PRIMARY_CLUTTER_RATE else f"@{rate:g}perscan")


def task_key(name: str, rcs: float = PRIMARY_RCS, rate: float = PRIMARY_CLUTTER_RATE) -> str:
    """The key of the run task ``name`` (``table``, ``ablations``, ``sweep``, ``grid``, ``replicate``) at
    ``(rcs, rate)``."""
    return f"{name}@{point_tag(rcs, rate)}"


def _row_combos(refs, particles: int, radius: float, keys=None, roles=None) -> list:
    """``[filter, particles, radius, row key]`` for every row of each filter in ``refs`` (:func:`~.methods.rows_for`:
    ``"ekf"`` is A and its 4-vector ablation), or only the rows with a key in ``keys`` / a role in ``roles``."""
    return [[m.filter, int(particles), float(radius), m.key] for ref in refs for m in rows_for(ref)
            if (keys is None or m.key in keys) and (roles is None or m.role in roles)]


def grid_points() -> tuple[tuple[float, float], ...]:
    """The ``(reference RCS, clutter rate)`` points the full report runs the judged rows at, the primary first: the
    RCS grid at the primary rate, the rate grid at the primary RCS, and the rate grid at -15 dBsm (where the literal
    A and B meet lower clutter with a stronger target).  They are also the calibration's candidates."""
    points = [(float(r), PRIMARY_CLUTTER_RATE) for r in REFERENCE_RCS.grid]
    points += [(PRIMARY_RCS, float(c)) for c in CLUTTER_RATE.grid if c != PRIMARY_CLUTTER_RATE]
    points += [(GRID_CORNER_RCS, float(c)) for c in CLUTTER_RATE.grid if c != PRIMARY_CLUTTER_RATE]
    return tuple(dict.fromkeys(points))


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
                  rate: float = PRIMARY_CLUTTER_RATE, timed: list | None = None, first_repetition: int = 0,
                  sensitivity: bool = False) -> None:
        if combos or timed:
            params = {"runs": n_runs, "rcs": rcs, "stream": stream, "threshold_db": TRACK_THRESHOLD_DB,
                      "combos": combos}
            if rate != PRIMARY_CLUTTER_RATE:
                params["rate"] = float(rate)
            if timed:
                params.update(timed=timed, batch_runs=min(n_runs, PROTOCOL_RUNS), first_repetition=first_repetition)
            out.append(Task(task_key(name, rcs, rate), params, _runs_task, runs=n_runs, sensitivity=sensitivity))

    # what the verdicts read at the primary values: A, B, C at R = 1 km, C at 2.5 km right after C (criterion 5's
    # timing, repetition 0: R = 1 km first), our A and B (the criteria's detail)
    judged = _row_combos(rows, TABLE_PARTICLES, TABLE_RADIUS, roles=("A", "B"))
    c = _row_combos(rows, TABLE_PARTICLES, TABLE_RADIUS, roles=("C",))
    wide = [[proposed, TABLE_PARTICLES, WIDE_RADIUS, "C"]] if c else []
    table = judged + c + wide + _row_combos(rows, TABLE_PARTICLES, TABLE_RADIUS, roles=("ours",))
    runs_task("table", PRIMARY_RCS, runs, table)
    others = [c for c in _row_combos(rows, TABLE_PARTICLES, TABLE_RADIUS) if c not in table]
    others += [[proposed, int(n), WIDE_RADIUS, "C"] for n in v["path_particles"] if int(n) != TABLE_PARTICLES]
    runs_task("ablations", PRIMARY_RCS, runs, others)
    sweep = [[proposed, int(n), TABLE_RADIUS, "C"] for n in v["sweep_particles"] if int(n) != TABLE_PARTICLES]
    runs_task("sweep", PRIMARY_RCS, runs, sweep)
    judged_refs = [m.filter for m in METHODS if m.role in JUDGED and m.filter in rows]
    if v.get("unknowns", False):
        # the declared unknowns' grid: the judged rows only, on the report's seed, the same draws at every point;
        # a sensitivity (Criterion.across only) except the calibrated point, where criteria 1-3 are judged again
        for rcs, rate in grid_points()[1:]:
            runs_task("grid", rcs, runs, _row_combos(judged_refs, TABLE_PARTICLES, TABLE_RADIUS, JUDGED), rate=rate,
                      sensitivity=(rcs, rate) != tuple(tuning.CALIBRATED_POINT))
    calibration = int(v.get("calibration_runs", 0))
    if calibration and all(k in {m.key for ref in rows for m in rows_for(ref)} for k in ("A", "B")):
        out.append(Task("calibration", {"seed": tuning.CALIBRATION_SEED, "runs": calibration,
                                        "points": [list(p) for p in grid_points()], "rows": ["A", "B"],
                                        "rule": tuning.CALIBRATION_RULE, "published": [236.0, 214.0]},
                        _calibration_task, runs=calibration, seeded=False))
    extra = int(v.get("replicated_runs", 0))
    if extra:
        # A and B in one batch; C at both radii in batches of the protocol's 20 runs, repetitions 1, 2, ... of
        # criterion 5's timing
        combos = _row_combos(judged_refs, TABLE_PARTICLES, TABLE_RADIUS, ("A", "B"))
        timed = _row_combos(judged_refs, TABLE_PARTICLES, TABLE_RADIUS, ("C",))
        timed += [[proposed, TABLE_PARTICLES, WIDE_RADIUS, "C"]] if timed else []
        runs_task("replicate", PRIMARY_RCS, extra, combos, stream="replicate", timed=timed, first_repetition=1)
    return out


# -- reading results ----------------------------------------------------------------------------------


def runs_of(results, rcs: float = PRIMARY_RCS, stream: str = "", rate: float = PRIMARY_CLUTTER_RATE,
            names=PROTOCOL_TASKS) -> dict[tuple[str, int, float], dict]:
    """``(method key, particles, radius) -> {field: array}`` of the run tasks ``names`` at ``rcs`` and clutter rate
    ``rate`` (stream ``"replicate"``: the ``replicate`` task).  Only those tasks are read (by key: the criteria read
    only the tasks they judge, which is what the confirmation seed runs again)."""
    out: dict[tuple[str, int, float], dict] = {}
    for name in (("replicate",) if stream == "replicate" else names):
        key = task_key(name, rcs, rate)
        if key not in results:
            continue
        for field, value in results[key].items():
            parts = field.split("__")
            if len(parts) != 4:
                continue
            method, n, r, what = parts
            out.setdefault((method, int(n[1:]), float(r[1:])), {})[what] = np.asarray(value)
    return out


def rcs_values(results) -> list[float]:
    """The reference RCS values with a Table 3 or grid run at the primary clutter rate, the primary first."""
    return [float(r) for r in REFERENCE_RCS.grid
            if task_key("table", r) in results or task_key("grid", r) in results]


def table_runs(results, rcs: float = PRIMARY_RCS) -> dict[str, dict]:
    """The Table 3 / Fig. 13 runs at ``rcs``: every row at R = 1 km, N = 600, in the rows' order."""
    runs = {m: res for (m, n, r), res in runs_of(results, rcs).items() if n == TABLE_PARTICLES and r == TABLE_RADIUS}
    order = {m.key: j for j, m in enumerate(METHODS)}
    return dict(sorted(runs.items(), key=lambda kv: (order.get(kv[0], len(order)), kv[0])))


def get_run(results, key: str, particles: int, radius: float, rcs: float = PRIMARY_RCS, stream: str = "",
            rate: float = PRIMARY_CLUTTER_RATE, names=PROTOCOL_TASKS):
    """One row's arrays (``key``, ``particles``, ``radius``) at ``(rcs, rate)`` from the tasks ``names``; None where
    it did not run."""
    return runs_of(results, rcs, stream, rate, names).get((key, particles, radius))


def label_of(key: str) -> str:
    return next((m.label for m in METHODS if m.key == key), key)


def role_of(key: str) -> str:
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


def sweep_of(results, rcs: float = PRIMARY_RCS) -> tuple[np.ndarray, list[np.ndarray]]:
    """The particle counts of the method-C sweep at R = 1 km and each count's per-run whole-track errors."""
    rows = sorted((n, res) for (m, n, r), res in runs_of(results, rcs, names=("table", "sweep")).items()
                  if m == "C" and r == TABLE_RADIUS)
    return np.array([n for n, _ in rows], dtype=int), [per_run_errors(res)[1] for _, res in rows]


def scenario_of(results) -> Mapping[str, np.ndarray]:
    if "scenario" not in results:
        raise InputError("paper 000: the scenario task has no result")
    return results["scenario"]
