"""Paper 003's tasks: one per (case, filter, variant) and the grid, delta, changes, tuning and timing tasks.

Scenario (:mod:`.scenario`, brief § 3.2): three paired noise levels L1/L2/L3 in two readings of the bearing unit
(radians, the primary reading, and degrees), the 3 x 3 (sigma_theta, sigma_r) grid, and "unknown noise" read two
ways: *mismatched* (primary: every filter is handed the reading's nominal L2 ``Q`` and ``R`` at every level) and
*matched* (the level's own ``Q`` and ``R``).  Beside the paper's eight filters every level has

- a **near-optimal reference**: the built-in bootstrap PF ``sir`` configured with 5,000 particles and given the
  level's true models, on the first ``reference_runs`` runs (the same truths and measurements), and at L2 and L3
  (where criterion 4 reads it) the same PF with 4 x 5,000 = 20,000 particles on the first
  ``reference_check_runs`` of those runs: the reference's convergence check;
- an **ablation row**: the previous reconstruction of the CRPF (fixed variance, plain norm, absolute delta),
  built by configuring ``crpf-100``.

One task per (case, filter, variant) recomputes independently; a task drives its filter with
:func:`workbench.filtering.run_filter` over batches of runs (all runs at once for Kalman-type filters; for
particle filters as many chunks as fit ``particle_budget`` particles) and stores only summaries (MSE and median
over runs per step, per-run time-averaged error, final error, the lost flags and thresholds) plus the estimates
of the first ``examples`` runs for Figs 2-3.  The tasks at a non-primary value of the declared unknown delta are
declared ``sensitivity=True`` (the confirmation seed does not run them again).  The figures are in
:mod:`.figures`, the tables in :mod:`.tables`, the criteria in :mod:`.judging`; the choices where the paper is
silent in :data:`~.scenario.NOTES` and ``docs/paper003.md``.
"""

from __future__ import annotations

import json
import time
from typing import Mapping

import numpy as np

from workbench.filtering import run_filter
from workbench.metrics import position_sq_error
from workbench.rng import generator
from workbench.specs import RecipeOptions, Task, TaskContext
from workbench.types import InputError, Scans

from .judging import CRPF_FILTERS
from .reading import REFERENCE, REFERENCE_4N, TIMING_TASK, delta_key
from .scenario import (DELTA, LEVELS, NOMINAL, READINGS, STREAM, filter_models, level_sigmas, lost_threshold,
                       make_case, prior, reading_cases, sigmas_of, simulate_chunk, simulate_units, units)

GRID_THETA = (0.01, 0.1, 1.0)
GRID_R = (0.1, 1.0, 10.0)
GRID_SIGMA_A = LEVELS[NOMINAL][2]  # the grid varies the measurement noise only (radians reading)

DEFAULT_FILTERS = ("ekf", "ukf", "cdkf", "sr-ukf", "sr-cdkf", "crpf-100", "crpf-300", "crpf-500")
CRPF_PARTICLES = (100, 300, 500)

#: The levels at which criterion 4 reads the reference, hence where its convergence is checked.
REFERENCE_CHECK_LEVELS = ("L2", "L3")
#: The previous reconstruction of the CRPF (fixed sigma^2 = kappa / N^(2/n) with the dwna shape, the plain norm,
#: delta = 0.01): a labelled ablation row, built by configuring crpf-100.
PREVIOUS = {"label": "crpf-100 previous (ablation)", "filter": "crpf-100",
            "configure": {"variance": "fixed", "kappa": 1.0, "scale": [0.5, 0.5, 1.0, 1.0], "cost": "norm",
                          "delta_mode": "absolute", "delta": 0.01}}
#: CRPF-100 with one reconstruction change undone at a time (the "changes" table), and all three undone.
CHANGES = (
    ("paper setting", {}),
    ("plain norm cost (change 2 undone)", {"cost": "norm"}),
    ("absolute delta = 0.01 (change 3 undone)", {"delta_mode": "absolute", "delta": 0.01}),
    ("fixed variance kappa = 1 (change 1 undone)", {"variance": "fixed", "kappa": 1.0}),
    ("all three undone (the previous CRPF)", PREVIOUS["configure"]),
)

#: The tuning of the paper CRPF's setting (docs/paper003.md, "The CRPF setting"): candidates, seed, stream, rule.
TUNING_SEED = 20031
TUNING_STREAM = "paper003-tuning"
TUNE_SIGMA0 = (0.1, 0.3, 1.0, 3.0)
TUNE_DELTA = DELTA.grid  # the declared unknown's grid: the tuning searched it, the criteria are judged across it
TUNING_RULE = ("one setting for every level and both readings: the candidate (sigma0, delta) with the smallest "
               "geometric mean over the six (reading, level) cases of CRPF-100's time-averaged MSE on the tuning runs")

SIZES = {
    "quick": {"runs": 40, "steps": 100, "chunk": 20, "examples": 20, "grid_runs": 6, "change_runs": 12,
              "tuning_runs": 6, "reference_runs": 6, "reference_check_runs": 6, "timing_runs": 3,
              "timing_repeats": 2, "particle_budget": 131072, "delta_runs": 12},
    "full": {"runs": 3000, "steps": 100, "chunk": 250, "examples": 100, "grid_runs": 300, "change_runs": 300,
             "tuning_runs": 200, "reference_runs": 100, "reference_check_runs": 100, "timing_runs": 100,
             "timing_repeats": 5, "particle_budget": 131072, "delta_runs": 1000},
}


# -- tasks ----------------------------------------------------------------------------------------------


def _spec(host, p: Mapping):
    """The filter of a task: ``p["filter"]``, configured with ``p["configure"]`` under the name ``p["label"]``."""
    spec = host.filter(p["filter"])
    cfg = p.get("configure") or {}
    return spec.configure(name=p.get("label") or None, **cfg) if cfg else spec


def _batches(chosen, particles: int, budget: int) -> list[list[int]]:
    """Groups of consecutive units: all at once for a Gaussian filter, about ``budget`` particles for a PF
    (small enough for the particle arrays to stay in cache)."""
    if particles <= 1:
        return [list(range(len(chosen)))]
    groups, current, count = [], [], 0
    for i, unit in enumerate(chosen):
        n = unit[3]
        if current and count + n * particles > budget:
            groups.append(current)
            current, count = [], 0
        current.append(i)
        count += n * particles
    return groups + [current]


def _warm_up(spec, motion, model, scans, rng) -> None:
    """Run the filter once on two runs and three steps, outside any clock: compiled kernels are loaded (or compiled
    into the on-disk cache) here, not in the timed section."""
    few = Scans(scans.z[:2, :3], scans.valid[:2, :3], scans.times[:3])
    run_filter(spec, prior(few.z.shape[0]), motion, model, few, rng)


def _monte_carlo(ctx: TaskContext, cases: list[dict], variant: str, examples: int) -> list[dict] | None:
    """Run the task's filter over every case of ``cases`` (one batch where the models allow); one summary dict
    per case, or None when a matched variant would repeat the mismatched one."""
    p = ctx.params
    spec = _spec(ctx.host, p)
    if variant == "matched" and "ignores_noise_statistics" in spec.capabilities:
        return None
    reading = p.get("reading", "rad")
    motion, model = filter_models(ctx.host, sigmas_of(cases[0]), variant, reading)
    seed = p.get("data_seed", ctx.seed)
    stream = p.get("stream", STREAM)
    chosen = units(cases, p["runs"], p["chunk"], p.get("of_runs"))
    groups = _batches(chosen, int(spec.params.get("particles", 1)), p["particle_budget"])
    sq, est_xy, thresholds, seconds, diag = [], [], [], 0.0, {}
    for g, members in enumerate(groups):
        truth, scans = simulate_units(ctx.host, seed, cases, [chosen[i] for i in members], p["steps"], stream)
        first = chosen[members[0]]
        rng = generator(seed, stream, cases[first[0]]["case"], "filter", p.get("label") or p["filter"], first[1])
        if g == 0:
            _warm_up(spec, motion, model, scans, generator(seed, stream, "warm-up"))
        t0 = time.perf_counter()
        est = run_filter(spec, prior(truth.batch), motion, model, scans, rng)
        seconds += time.perf_counter() - t0
        sq.append(position_sq_error(truth.states, est.mean))  # (B, T)
        est_xy.append(est.mean[:, :, :2])
        start = 0
        for i in members:
            c, _, _, take = chosen[i]
            thresholds.append(lost_threshold(truth.states[start:start + take, -1], sigmas_of(cases[c]), p["steps"]))
            start += take
        for k, v in est.diagnostics.items():
            diag[k] = diag.get(k, 0.0) + float(v)
        ctx.progress((g + 1) / len(groups))
    sq = np.concatenate(sq).reshape(len(cases), p["runs"], -1)
    est_xy = np.concatenate(est_xy).reshape(len(cases), p["runs"], -1, 2)
    thresholds = np.concatenate(thresholds).reshape(len(cases), p["runs"])
    out = []
    for c in range(len(cases)):
        final = np.sqrt(sq[c, :, -1])
        out.append({
            "mse_t": sq[c].mean(axis=0),
            "median_t": np.median(sq[c], axis=0),
            "run_mse": sq[c].mean(axis=1),
            "final_err": final,
            "lost_threshold": thresholds[c],
            "lost": final > thresholds[c],
            "est_xy": est_xy[c, :examples],
            "seconds": np.array(seconds / len(cases)),
            "runs": np.array(p["runs"]),
            "filter_params": np.array(json.dumps(spec.params, default=str)),
            "diag_names": np.array(sorted(diag), dtype=str),
            "diag_values": np.array([diag[k] / len(cases) for k in sorted(diag)], dtype=float),
        })
    return out


def run_monte_carlo(ctx: TaskContext) -> dict:
    """One filter on one case and one variant: summaries over its runs (see :func:`_monte_carlo`)."""
    p = ctx.params
    out = _monte_carlo(ctx, [make_case(p["case"], (p["sigma_theta"], p["sigma_r"], p["sigma_a"]))], p["variant"],
                       p["examples"])
    return {"same_as_mismatched": np.array(True)} if out is None else out[0]


def run_cases(ctx: TaskContext) -> dict:
    """One filter over several cases in one batch (mismatched models, or the variant given); the arrays of case
    ``i`` are prefixed ``"{case}:"``."""
    p = ctx.params
    out = _monte_carlo(ctx, [dict(c) for c in p["cases"]], p.get("variant", "mismatched"), 0)
    return {f"{case['case']}:{k}": v for case, res in zip(p["cases"], out) for k, v in res.items()}


def run_scenario(ctx: TaskContext) -> dict:
    """The truths and measurements of a case's first ``examples`` runs, and every run's closest range and
    lost threshold."""
    p = ctx.params
    sigmas = (p["sigma_theta"], p["sigma_r"], p["sigma_a"])
    min_range, truth_xy, z, thresholds = [], [], [], []
    for c, k, size, take in units([p], p["runs"], p["chunk"]):
        truth, scans = simulate_chunk(ctx.host, ctx.seed, p["case"], sigmas, k, size, p["steps"])
        min_range.append(np.hypot(truth.states[:, :, 0], truth.states[:, :, 1]).min(axis=1))
        thresholds.append(lost_threshold(truth.states[:, -1], sigmas, p["steps"]))
        if k * p["chunk"] < p["examples"]:
            truth_xy.append(truth.states[:, :, :2])
            z.append(scans.z[:, :, 0, :])
    return {
        "size": np.array(p["size"]),
        "min_range": np.concatenate(min_range),
        "lost_threshold": np.concatenate(thresholds),
        "truth_xy": np.concatenate(truth_xy)[:p["examples"]],
        "z": np.concatenate(z)[:p["examples"]],
    }


def run_timing(ctx: TaskContext) -> dict:
    """Warmed-up timing on ``timing_runs`` runs of L2 data (radians, mismatched models) of every filter of the
    report, interleaved so that they are compared in one run: each run alone (B = 1) by every filter in turn (the
    order rotated by one filter per run), then all runs as one batch by every filter in turn, ``timing_repeats``
    times.  A drift of the machine's load (the other worker's tasks, the VM's neighbours) then falls on every filter
    alike instead of on whichever filter's task ran at the time.  Arrays ``"{filter}:per_run_s"``,
    ``"{filter}:per_run_cpu_s"`` and ``"{filter}:batched_per_run_s"`` (:func:`.reading.timing_arrays`)."""
    p = ctx.params
    names = [str(n) for n in p["filters"]]
    specs = [ctx.host.filter(n) for n in names]
    sigmas = level_sigmas("rad", NOMINAL)
    motion, model = filter_models(ctx.host, sigmas, "mismatched")
    truth, scans = simulate_chunk(ctx.host, ctx.seed, "timing", sigmas, 0, p["timing_runs"], p["steps"])
    R, F = p["timing_runs"], len(names)
    one_prior = prior(1)

    def one(r):
        return Scans(scans.z[r:r + 1], scans.valid[r:r + 1], scans.times)

    # warm-up outside the clock: one un-batched run and one batched call of every filter load the compiled kernels
    for name, spec in zip(names, specs):
        run_filter(spec, one_prior, motion, model, one(0), generator(ctx.seed, STREAM, "timing", "warm-up", name))
        run_filter(spec, prior(R), motion, model, scans, generator(ctx.seed, STREAM, "timing", "warm-up-batch", name))
    per_run = np.empty((F, R))
    per_run_cpu = np.empty((F, R))
    for r in range(R):
        for j in range(F):
            i = (j + r) % F  # rotated: no filter always runs right after the same one
            rng = generator(ctx.seed, STREAM, "timing", names[i], r)
            t0, c0 = time.perf_counter(), time.process_time()
            run_filter(specs[i], one_prior, motion, model, one(r), rng)
            per_run[i, r], per_run_cpu[i, r] = time.perf_counter() - t0, time.process_time() - c0
        ctx.progress(0.8 * (r + 1) / R)
    batched = np.empty((F, p["timing_repeats"]))
    for k in range(p["timing_repeats"]):
        for j in range(F):
            i = (j + k) % F
            rng = generator(ctx.seed, STREAM, "timing", names[i], "batch", k)
            t0 = time.perf_counter()
            run_filter(specs[i], prior(R), motion, model, scans, rng)
            batched[i, k] = (time.perf_counter() - t0) / R
    # wall time is the brief's measure; the process CPU time is shown beside it (the machine may be shared)
    out = {}
    for i, name in enumerate(names):
        out[f"{name}:per_run_s"] = per_run[i]
        out[f"{name}:per_run_cpu_s"] = per_run_cpu[i]
        out[f"{name}:batched_per_run_s"] = batched[i]
    return out


def _mc_params(values: Mapping, runs: int, examples: int, **extra) -> dict:
    return {"runs": runs, "steps": values["steps"], "chunk": min(values["chunk"], runs), "examples": examples,
            "particle_budget": values["particle_budget"], **extra}


def grid_case(st: float, sr: float) -> str:
    return f"grid-t{st:g}-r{sr:g}"


def tuning_label(sigma0: float, delta: float) -> str:
    return f"crpf-100 sigma0={sigma0:g} delta={delta:g}"


GRID_CASES = tuple(make_case(grid_case(st, sr), (st, sr, GRID_SIGMA_A)) for st in GRID_THETA for sr in GRID_R)
CASES = {reading: reading_cases(reading) for reading in READINGS}


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    for key in SIZES["full"]:
        if key not in v:
            raise InputError(f"paper 003: size {options.size!r} lacks the value {key!r}")
    out = []
    for reading, cases in CASES.items():
        for case, level in zip(cases, LEVELS):
            name = case["case"]
            out.append(Task(f"scenario/{name}", {**case, "runs": v["runs"], "steps": v["steps"], "chunk": v["chunk"],
                                                 "examples": v["examples"], "size": options.size}, run_scenario))
            common = dict(reading=reading, **case)
            for filt in options.filters:
                for variant in ("mismatched",) if level == NOMINAL else ("mismatched", "matched"):
                    out.append(Task(f"mc/{name}/{filt}/{variant}",
                                    _mc_params(v, v["runs"], v["examples"], filter=filt, variant=variant, **common),
                                    run_monte_carlo))
            out.append(Task(f"ablation/{name}", _mc_params(v, v["runs"], 0, variant="mismatched", **PREVIOUS,
                                                           **common), run_monte_carlo))
            ref_runs = min(v["reference_runs"], v["runs"])
            out.append(Task(f"reference/{name}",
                            _mc_params(v, ref_runs, 0, variant="matched", of_runs=v["runs"], **REFERENCE, **common)
                            | {"chunk": min(v["chunk"], v["runs"])}, run_monte_carlo))
            if level in REFERENCE_CHECK_LEVELS:  # the same first runs: a paired convergence check
                out.append(Task(f"reference4n/{name}",
                                _mc_params(v, min(v["reference_check_runs"], ref_runs), 0, variant="matched",
                                           of_runs=v["runs"], **REFERENCE_4N, **common)
                                | {"chunk": min(v["chunk"], v["runs"])}, run_monte_carlo))
    # the declared unknown delta: every CRPF of the report at each non-primary grid value, on the first delta_runs
    # runs of every level (the same truths and measurements as the main rows: same seed, stream and chunks; only
    # the filter's delta changes), the three levels of a reading as one batch
    for reading, cases in CASES.items():
        for value in DELTA.grid:
            if value == DELTA.primary:
                continue  # the main rows are the primary value
            for filt in [f for f in options.filters if f in CRPF_FILTERS]:
                out.append(Task(delta_key(reading, value, filt),
                                _mc_params(v, min(v["delta_runs"], v["runs"]), 0, filter=filt,
                                           configure={"delta": value}, label=f"{filt} delta={value:g}",
                                           reading=reading, cases=list(cases), of_runs=v["runs"])
                                | {"chunk": min(v["chunk"], v["runs"])}, run_cases,
                                sensitivity=True))  # a non-primary delta: read only by the criteria's `across`
    for filt in options.filters:
        out.append(Task(f"grid/{filt}", _mc_params(v, v["grid_runs"], 0, filter=filt, cases=list(GRID_CASES)),
                        run_cases))
    for reading, cases in CASES.items():
        for label, cfg in CHANGES:
            out.append(Task(f"changes/{reading}/{label}",
                            _mc_params(v, v["change_runs"], 0, filter="crpf-100", configure=cfg,
                                       label=f"crpf-100 {label}" if cfg else "", reading=reading, cases=list(cases)),
                            run_cases))
        for s0 in TUNE_SIGMA0:
            for d in TUNE_DELTA:
                out.append(Task(f"tune/{reading}/{tuning_label(s0, d)}",
                                _mc_params(v, v["tuning_runs"], 0, filter="crpf-100",
                                           configure={"sigma0": s0, "delta": d}, label=tuning_label(s0, d),
                                           reading=reading, cases=list(cases), data_seed=TUNING_SEED,
                                           stream=TUNING_STREAM), run_cases,
                                seeded=False))  # its own tuning seed: the confirmation reuses it
    # every filter's timing in one task, interleaved run by run (compared in one run, :func:`run_timing`)
    out.append(Task(TIMING_TASK, {"filters": list(options.filters), "timing_runs": v["timing_runs"],
                                  "steps": v["steps"], "timing_repeats": v["timing_repeats"]}, run_timing,
                    timed=True))  # wall-clock times: taken apart from the batch's other tasks (Task.timed)
    return out
