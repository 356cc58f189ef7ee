"""Paper 001's tasks: the seed blocks of the paper rows, the extension trackers, the remover variants, the grid
values of the declared unknowns, the tuning, the sea-trial surrogate, the Hough demo and the timing, and
:func:`tasks` that lists them for a report's options."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from workbench.metrics import continuity, track_counts
from workbench.params import parse_reference
from workbench.plugins import PluginHost
from workbench.recorded.sonar import load_sonar_csv
from workbench.report.engine import component_failure
from workbench.rng import generator
from workbench.specs import RecipeOptions, Task, TaskContext
from workbench.tracking import CONFIRMED, run_tracker
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import CLUTTER, InputError, Scans

from .scenario import (DT, EXT_FILTER, FIG_ARM, GRID_IN_SIM, HOUGH, HOUGH_PREVIOUS, MATCHED, MIN_SPEED, PAPER_FILTER,
                       PAPER_TRACKER, PINGS, POLAR, REMOVER, SENSOR, SIM_CLUTTER, SONAR, START, SURROGATE_CLUTTER,
                       SURROGATE_FILE, TRACKER, TRACKER_PREVIOUS, TRACKER_SETTINGS, TRUE_FRACTION, TRUE_RADIUS,
                       TUNING_CANDIDATES, TUNING_RULE, TUNING_STREAM, UNKNOWNS, VARIANTS, VARIANTS_IN_SIM, VELOCITY,
                       _counts_arrays, _file_digest, _gospa_arrays, _model_for, _remover_stats, _run_zero, _track,
                       _tracker_config, _unknown_changes, _unknown_key, _unknown_prefix, _warm, motion_model,
                       simulate_scans, target_truth)


def _sim_task(ctx: TaskContext) -> dict:
    """One seed block: the paper, stated-accuracy and previous arms (and any added filter) before and after
    removal, and the remover's statistics; block 0 also keeps run 0 for the x-y figures."""
    p, host = ctx.params, ctx.host
    seed = ctx.seed + int(p["block"])
    scans = simulate_scans(host, seed, "sim", int(p["runs"]))
    remover = host.clutter_remover(REMOVER)
    after = remover.remove(scans, **p["hough"])
    previous = remover.remove(scans, **p["hough_previous"])
    truth_pos = target_truth(scans.batch).states[..., :2]
    out = {"first_output_ping": np.array(_warm(p["hough"])), "runs": np.array(scans.batch)}
    out.update(_remover_stats("rem/main/", scans, after, _warm(p["hough"])))
    out.update(_remover_stats("rem/previous-rule/", scans, previous, _warm(p["hough"])))
    arms = [("paper", PAPER_FILTER, after), ("stated", PAPER_FILTER, after), ("paper-mofn", PAPER_FILTER, after),
            ("two-point", PAPER_FILTER, after), ("previous", PAPER_FILTER, previous)]
    arms += [(f"filter:{name}", name, after) for name in p["filters"] if name != PAPER_FILTER]
    for arm, filt, removed in arms:
        # Each arm alone: a filter that raises loses its own rows (named in the report: error/<arm>), never the
        # other arms' rows, tables, figures and criteria computed on the same detections.
        rows = {}
        try:
            cfg = _tracker_config(host, "paper" if arm.startswith("filter:") else arm)
            for phase, data in (("before", scans), ("after", removed)):
                log, counts, used = _track(host, data, filt, cfg, seed, (arm, phase))
                rows.update(_counts_arrays(f"{arm}/{phase}/", counts))
                rows.update(_gospa_arrays(f"{arm}/{phase}/", log, truth_pos))
                rows[f"{arm}/model_used"] = np.array([used])
                if arm == FIG_ARM and int(p["block"]) == 0:
                    rows.update(_run_zero(f"fig/{phase}/", scans, removed.valid if phase == "after" else scans.valid,
                                          log, truth_pos))
        except Exception as exc:  # noqa: BLE001 - isolated: reported by the report engine, the other arms kept
            out.update(component_failure(arm if arm.startswith("filter:") else f"{arm} arm ({filt})", exc))
            continue
        out.update(rows)
    # the grid of the unknowns that change the tracker only (GRID_IN_SIM): the paper rows with each grid value's
    # tracker settings on these same detections and this same removal (what a grid task of its own computed after
    # simulating and removing them again: the same numbers, bit for bit)
    for prefix, changes in p.get("tracker_grid", {}).items():
        rows = {}
        try:
            cfg = _tracker_config(host, "paper", changes)
            for phase, data in (("before", scans), ("after", after)):
                _, counts, _ = _track(host, data, PAPER_FILTER, cfg, seed, ("paper", phase))
                rows.update(_counts_arrays(f"{prefix}paper/{phase}/", counts))
        except Exception as exc:  # noqa: BLE001 - isolated as the arms are
            out.update(component_failure(f"{prefix.rstrip('/')} paper rows ({PAPER_FILTER})", exc))
            continue
        out.update(rows)
    out["detections_per_ping"] = after.valid.sum(axis=2).mean(axis=0)
    return out


def _unknown_task(ctx: TaskContext) -> dict:
    """One seed block of the paper rows at one grid value of a declared unknown: the clutter and tracker settings
    of that value (``p["clutter"]``, ``p["tracker_changes"]``), before and after removal, and the remover's
    statistics."""
    p, host = ctx.params, ctx.host
    seed = ctx.seed + int(p["block"])
    scans = simulate_scans(host, seed, "sim", int(p["runs"]), clutter=p["clutter"])
    after = host.clutter_remover(REMOVER).remove(scans, **p["hough"])
    out = {"first_output_ping": np.array(_warm(p["hough"])), "runs": np.array(scans.batch),
           "clutter_per_ping": np.array(float(scans.valid.sum(axis=2).mean()))}
    out.update(_remover_stats("rem/main/", scans, after, _warm(p["hough"])))
    cfg = _tracker_config(host, "paper", p["tracker_changes"])
    for phase, data in (("before", scans), ("after", after)):
        _, counts, _ = _track(host, data, PAPER_FILTER, cfg, seed, ("paper", phase))
        out.update(_counts_arrays(f"paper/{phase}/", counts))
    return out


def _variants_task(ctx: TaskContext) -> dict:
    """One seed block through every remover variant of ``p["variants"]``, then the paper and the stated-accuracy
    arms' trackers (after removal only; the before-removal counts are the block's ``paper/before`` and
    ``stated/before``).  The main remover is not among them: its rows are the sim block's (:data:`VARIANTS_IN_SIM`)."""
    p, host = ctx.params, ctx.host
    seed = ctx.seed + int(p["block"])
    scans = simulate_scans(host, seed, "sim", int(p["runs"]))
    remover = host.clutter_remover(REMOVER)
    out = {}
    for name, change in p["variants"].items():
        hough = {**p["hough"], **change}
        after = remover.remove(scans, **hough)
        out.update(_remover_stats(f"rem/{name}/", scans, after, _warm(hough)))
        for arm in ("paper", "stated"):
            _, counts, _ = _track(host, after, PAPER_FILTER, _tracker_config(host, arm), seed, (arm, "after"))
            out.update(_counts_arrays(f"{name}/{arm}/after/", counts))
        out[f"{name}/first_output_ping"] = np.array(_warm(hough))
    return out


def _tuning_task(ctx: TaskContext) -> dict:
    """Choose the gate and the deletion rule on the tuning runs by :data:`TUNING_RULE`, then run the chosen
    setting on the reported blocks (before and after removal)."""
    p, host = ctx.params, ctx.host
    remover = host.clutter_remover(REMOVER)
    tune = simulate_scans(host, ctx.seed, TUNING_STREAM, int(p["tuning_runs"]))
    tune_after = remover.remove(tune, **p["hough"])
    held = []
    for i, cand in enumerate(p["candidates"]):
        cfg = _tracker_config(host, "paper", cand)
        _, counts, _ = _track(host, tune_after, PAPER_FILTER, cfg, ctx.seed, ("tuning", i))
        held.append(int(np.sum(continuity(counts.held) >= TRUE_FRACTION)))
    held = np.array(held)
    chosen = int(np.argmax(held))  # the first of the best: candidates are listed closest to the defaults first
    out = {"tuning/held": held, "tuning/runs": np.array(tune.batch), "tuning/chosen": np.array(chosen)}
    cfg = _tracker_config(host, "paper", p["candidates"][chosen])
    for block in range(int(p["seeds"])):
        seed = ctx.seed + block
        scans = simulate_scans(host, seed, "sim", int(p["runs"]))
        after = remover.remove(scans, **p["hough"])
        for phase, data in (("before", scans), ("after", after)):
            _, counts, _ = _track(host, data, PAPER_FILTER, cfg, seed, ("tuned", phase))
            out.update(_counts_arrays(f"block{block}/tuned/{phase}/", counts))
    return out


def _surrogate_task(ctx: TaskContext) -> dict:
    """The sea-trial surrogate, Monte Carlo (``source="surrogate"``) or the shipped file (``"file"``): the paper
    arm and the minimum-speed extension, before and after removal."""
    p, host = ctx.params, ctx.host
    if p["source"] == "file":
        path = Path(p["file"])
        if not path.is_file():
            raise InputError(f"paper 001: the sea-trial surrogate file {path} is missing "
                             f"(regenerate it with workbench_papers.paper001.scenario.write_surrogate())")
        scans, sites = load_sonar_csv(path, dt=DT, pings=PINGS), None
    else:
        scans, sites = simulate_scans(host, ctx.seed, "surrogate", int(p["runs"]), sites=True)
    after = host.clutter_remover(REMOVER).remove(scans, **p["hough"])
    truth_pos = target_truth(scans.batch).states[..., :2]
    out = {"first_output_ping": np.array(_warm(p["hough"])), "runs": np.array(scans.batch)}
    if scans.origin is not None:
        out.update(_remover_stats("rem/main/", scans, after, _warm(p["hough"]), sites))
    for arm in ("paper", "min-speed"):
        cfg = _tracker_config(host, arm)
        for phase, data in (("before", scans), ("after", after)):
            log, counts, _ = _track(host, data, PAPER_FILTER, cfg, ctx.seed, (p["source"], arm, phase))
            out.update(_counts_arrays(f"{arm}/{phase}/", counts))
            if arm == "paper":
                out.update(_run_zero(f"fig/{phase}/", scans, after.valid if phase == "after" else scans.valid, log,
                                     truth_pos))
    return out


def _demo_task(ctx: TaskContext) -> dict:
    """Figs 3-4: a target line over 6 pings among uniform clutter, through the Hough remover (ping 5)."""
    rng = generator(ctx.seed, "paper001", "hough-demo")
    hough = ctx.params["hough"]
    pings = hough["window"] + hough["shift"]
    one = piecewise_trajectory(START, VELOCITY, [Leg("straight", (pings - 1) * DT)], DT)
    tgt = one.states[0, :, :2] + 0.7 * rng.standard_normal((pings, 2))
    clutter = rng.uniform(0.0, 250.0, (pings, 6, 2))
    z = np.concatenate([tgt[:, None, :], clutter], axis=1)[None]
    valid = np.ones(z.shape[:3], dtype=bool)
    origin = np.concatenate([np.zeros((pings, 1), int), np.full((pings, 6), CLUTTER)], axis=1)[None]
    scans = Scans(z, valid, one.times, origin=origin)
    trace: list = []
    kept = ctx.host.clutter_remover(REMOVER).remove(scans, trace=trace, **hough)
    rec = trace[-1]
    # the true line in normal form: theta in [0, pi), rho may be negative
    direction = np.asarray(VELOCITY) / np.hypot(*VELOCITY)
    theta0 = np.mod(np.arctan2(direction[0], -direction[1]), np.pi)
    rho0 = START[0] * np.cos(theta0) + START[1] * np.sin(theta0)
    group = slice(pings - hough["window"], pings)
    return {"points": z[0, group].reshape(-1, 2), "point_ping": np.repeat(np.arange(pings)[group], z.shape[2]),
            "point_target": (origin[0, group] == 0).ravel(), "kept_last": kept.valid[0, -1],
            "rho_axis": rec["rho"], "theta_axis": rec["theta"], "support": rec["support_b"],
            "similar": rec["similar"], "peaks_b": rec["peaks_b"], "true_line": np.array([rho0, theta0])}


def _timing_task(ctx: TaskContext) -> dict:
    """Per-ping times of the remover and the tracker on the paper's scenario, warmed up: one untimed call
    first (it compiles and loads the kernels), then ``repeats`` timed calls of one run of 20 pings; the
    median divided by 20."""
    p, host = ctx.params, ctx.host
    scans = simulate_scans(host, ctx.seed, "timing", 1)
    remover = host.clutter_remover(REMOVER)
    after = remover.remove(scans, **p["hough"])
    cfg = _tracker_config(host, "paper")
    model, _ = _model_for(host, PAPER_FILTER)
    filt = host.filter(PAPER_FILTER)
    jobs = {"remover": lambda: remover.remove(scans, **p["hough"]),
            "tracker_before": lambda: run_tracker(scans, filt, motion_model(), model, cfg),
            "tracker_after": lambda: run_tracker(after, filt, motion_model(), model, cfg)}
    out = {"repeats": np.array(int(p["repeats"]))}
    for name, job in jobs.items():
        job()  # warm-up
        wall, cpu = [], []
        for _ in range(int(p["repeats"])):
            t0, c0 = time.perf_counter(), time.process_time()
            job()
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out[f"{name}_wall_s"] = np.array(np.median(wall) / scans.steps)
        out[f"{name}_cpu_s"] = np.array(np.median(cpu) / scans.steps)
    out["detections_per_ping"] = np.array(scans.valid.sum(axis=2).mean())
    return out


def extension_tracker(host: PluginHost, reference: str):
    """The installed tracker of ``reference`` (``"gnn"``, ``"gm-phd(prune=1e-4)"``) configured for this scenario:
    :data:`TRACKER_SETTINGS` of its base name, then the reference's own values (checked against its declarations,
    refused by name), named by the reference."""
    base, values = parse_reference(reference, f"paper 001: tracker {reference!r}")
    return host.tracker(base).configure(name=reference, **{**TRACKER_SETTINGS.get(base, {}), **values})


def _tracker_prefix(reference: str, phase: str) -> str:
    return f"tracker:{reference}/{phase}/"


def _trackers_task(ctx: TaskContext) -> dict:
    """One seed block of the extension trackers (every reference of ``p["trackers"]`` but the paper's own
    ``"mofn"``), each before and after the Hough remover, on the detections of the block's paper rows (the same
    seed and stream: common random numbers): GOSPA and its terms, the paper's counts per run and ping, and the
    confirmed tracks' log (``.../log/``, for recomputing).  A tracker that raises loses its own rows only (named
    in the report: ``error/tracker:<reference>``)."""
    p, host = ctx.params, ctx.host
    seed = ctx.seed + int(p["block"])
    refs = [str(t) for t in p["trackers"]]
    out = {"order": np.array(refs, dtype=str), "first_output_ping": np.array(_warm(p["hough"]))}
    extensions = [t for t in refs if t != PAPER_TRACKER]
    if not extensions:
        return out
    scans = simulate_scans(host, seed, "sim", int(p["runs"]))
    after = host.clutter_remover(REMOVER).remove(scans, **p["hough"])
    truth_pos = target_truth(scans.batch).states[..., :2]
    model = host.sensor(SENSOR).measurement_model(**p["sonar"], **p["model"])
    out["runs"] = np.array(scans.batch)
    for ref in extensions:
        rows = {}
        try:
            spec = extension_tracker(host, ref)
            filt = host.filter(p["filter"])
            for phase, data in (("before", scans), ("after", after)):
                log = spec.run(data, filt, motion_model(), model, seed=seed, key=("paper001", "tracker", ref, phase))
                prefix = _tracker_prefix(ref, phase)
                rows.update(_counts_arrays(prefix, track_counts(log, truth_pos, TRUE_RADIUS, TRUE_FRACTION)))
                rows.update(_gospa_arrays(prefix, log, truth_pos))
                rows.update(log.select(log.status == CONFIRMED).to_arrays(prefix + "log/"))
        except Exception as exc:  # noqa: BLE001 - isolated: reported by the report engine, the other rows kept
            out.update(component_failure(f"tracker:{ref}", exc))
            continue
        out.update(rows)
    return out


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    runs, seeds = int(v["runs"]), int(v["seeds"])
    filters = tuple(options.filters) or (PAPER_FILTER,)
    common = {"runs": runs, "hough": HOUGH, "sonar": SONAR, "polar": POLAR, "tracker": TRACKER,
              "clutter": SIM_CLUTTER}
    out = [Task("hough-demo", {"hough": HOUGH}, _demo_task)]
    tracker_grid = {_unknown_prefix(u, value): _unknown_changes(u, value)["tracker_changes"]
                    for u in GRID_IN_SIM for value in u.grid if value != u.primary}
    for block in range(seeds):
        out.append(Task(f"sim/{block}", {**common, "block": block, "hough_previous": HOUGH_PREVIOUS,
                                          "tracker_previous": TRACKER_PREVIOUS, "filters": list(filters),
                                          "tracker_grid": tracker_grid}, _sim_task))
    # the trackers compared (options.trackers: DEFAULT_TRACKERS with --trackers applied; empty: none compared)
    if options.trackers:
        for block in range(seeds):
            out.append(Task(f"trackers/{block}", {"runs": runs, "block": block, "hough": HOUGH, "sonar": SONAR,
                                                   "clutter": SIM_CLUTTER, "model": MATCHED, "filter": EXT_FILTER,
                                                   "trackers": list(options.trackers),
                                                   "settings": TRACKER_SETTINGS}, _trackers_task))
    for block in range(min(int(v["variant_seeds"]), seeds)):
        out.append(Task(f"variants/{block}", {**common, "block": block,
                                               "variants": {k: v for k, v in VARIANTS.items()
                                                            if k not in VARIANTS_IN_SIM}}, _variants_task))
    for unknown in UNKNOWNS:
        if unknown in GRID_IN_SIM:  # tracked inside the sim blocks
            continue
        for value in unknown.grid:
            if value == unknown.primary:  # the primary value's rows are the sim blocks' paper rows
                continue
            for block in range(seeds):
                out.append(Task(_unknown_key(unknown, value, block),
                                {**common, "block": block, "unknown": unknown.name, "value": value,
                                 **_unknown_changes(unknown, value)}, _unknown_task,
                                sensitivity=True))  # a non-primary grid value: the confirmation seed reuses it
    out.append(Task("tuning", {**common, "seeds": seeds, "tuning_runs": int(v["tuning_runs"]),
                               "candidates": list(TUNING_CANDIDATES), "rule": TUNING_RULE}, _tuning_task))
    out.append(Task("surrogate", {**common, "source": "surrogate", "clutter": SURROGATE_CLUTTER,
                                  "min_speed": MIN_SPEED}, _surrogate_task))
    out.append(Task("file", {**common, "source": "file", "file": str(SURROGATE_FILE),
                             "digest": _file_digest(SURROGATE_FILE), "min_speed": MIN_SPEED}, _surrogate_task))
    out.append(Task("timing", {"hough": HOUGH, "tracker": TRACKER, "repeats": 5}, _timing_task,
                    timed=True))  # wall-clock times: taken apart from the batch's other tasks (Task.timed)
    return out
