"""Paper 003: EKF, UKF, CDKF, SR-UKF, SR-CDKF and the cost-reference particle filter, range-bearing, unknown noise.

Scenario (brief § 3.2): a 2-D target with a random-walk velocity (``r_t = r_{t-1} + T v_{t-1}``,
``v_t = v_{t-1} + a_t``, ``a_t ~ N(0, sigma_a^2 I)``), seen in range and bearing from a sensor at the
origin.  Three paired noise levels L1/L2/L3, the full 3 x 3 (sigma_theta, sigma_r) grid, and "unknown
noise" read two ways: *mismatched* (primary: every filter is handed the nominal L2 ``Q`` and ``R`` at
every level) and *matched* (the level's own ``Q`` and ``R``).  Common random numbers: the truths and
measurements of chunk ``c`` of a case come from ``generator(seed, "paper003", case, c)`` alone, so every
filter, and every task, sees the same data.

One task per (case, filter, variant) recomputes independently; a task drives its filter with
:func:`workbench.filtering.run_filter` over batches of runs (all runs at once for Kalman-type filters;
for particle filters as many chunks as fit ``particle_budget`` particles, which keeps the arrays in
cache) and stores only summaries (MSE and median over runs per step, per-run time-averaged error, final
error, lost flags) plus the estimates of the first ``examples`` runs for Figs 2-3.  Choices where the
paper is silent are in :data:`NOTES` and ``docs/paper003.md``.
"""

from __future__ import annotations

import time
from typing import Mapping

import numpy as np

from workbench.filtering import run_filter
from workbench.metrics import position_sq_error
from workbench.models import random_walk_velocity
from workbench.rng import chunk_bounds, generator
from workbench.specs import Criterion, FigureSpec, RecipeOptions, RecipeSpec, Table, TableSpec, Task, TaskContext
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, InputError, Scans, Truth

PAPER = "003"
DT = 1.0  # s [U]
X0 = (100.0, 50.0, -1.0, 1.0)  # true start [x, y, vx, vy] (m, m/s) [U]
XHAT0 = (110.0, 40.0, 0.0, 0.0)  # initial estimate [U]
P0 = (10.0 ** 2, 10.0 ** 2, 2.0 ** 2, 2.0 ** 2)  # initial covariance (diagonal) [U]
SENSOR = "range-bearing"

#: level -> (sigma_theta rad, sigma_r m, sigma_a m/s per step) [U: paired levels]
LEVELS: dict[str, tuple[float, float, float]] = {
    "L1": (0.01, 0.1, 0.01),
    "L2": (0.1, 1.0, 0.1),
    "L3": (1.0, 10.0, 1.0),
}
NOMINAL = "L2"  # the noise statistics handed to every filter in the mismatched (primary) variant
GRID_THETA = (0.01, 0.1, 1.0)
GRID_R = (0.1, 1.0, 10.0)
GRID_SIGMA_A = LEVELS[NOMINAL][2]  # the grid varies the measurement noise only

DEFAULT_FILTERS = ("ekf", "ukf", "cdkf", "sr-ukf", "sr-cdkf", "crpf-100", "crpf-300", "crpf-500")
KALMAN_TYPE = ("ekf", "ukf", "cdkf", "sr-ukf", "sr-cdkf")
CRPF_FILTERS = ("crpf-100", "crpf-300", "crpf-500")
CRPF_PARTICLES = (100, 300, 500)
#: CRPF-100 ablations (registered by the crpf plugin): the jitter sweep with the paper's plain norm,
#: kappa in {0.1, 1, 10} x shape {iso, vel0.1, dwna}, then the arc-length cost ({iso, dwna} shapes).
#: "crpf-100" itself is the dwna shape with kappa 1 (the default chosen by SWEEP_RULE); "crpf-100-iso" is
#: the brief's literal default.
ABLATION_FILTERS = tuple(
    "crpf-100" + arc + ("" if shape == "dwna" else f"-{shape}") + ("" if k == "1" else f"-k{k}")
    for arc, shapes in (("", ("iso", "vel0.1", "dwna")), ("-arc", ("iso", "dwna")))
    for shape in shapes for k in ("0.1", "1", "10"))
LITERAL_DEFAULT = "crpf-100-iso"
SWEEP_RULE = ("one setting for every level: the plain-norm row with the smallest geometric mean over L1-L3 of "
              "the time-averaged MSE")
SR_PAIRS = (("ukf", "sr-ukf"), ("cdkf", "sr-cdkf"))

SIZES = {
    "quick": {"runs": 40, "steps": 100, "chunk": 20, "examples": 20, "grid_runs": 6, "ablation_runs": 12,
              "timing_runs": 3, "particle_budget": 131072, "lost_m": 50.0},
    "full": {"runs": 3000, "steps": 100, "chunk": 250, "examples": 100, "grid_runs": 300, "ablation_runs": 300,
             "timing_runs": 200, "particle_budget": 131072, "lost_m": 50.0},
}

PUBLISHED = {
    "source": "Shin & Hong, J. Korea Soc. for Simulation (MATLAB); every curve value was lost, claims only",
    "runs_per_level": 3000,
    "claim_noise": "MSE increases with the bearing and range noise, for every filter",
    "claim_cdkf": "within the EKF family CDKF and SR-CDKF are best in most cases; SR-CDKF best in speed and accuracy",
    "claim_sr": "the SR forms give the same accuracy as the non-SR forms with much lower processing time",
    "claim_crpf_accuracy": "CRPF accuracy grows with N; CRPF-100 already beats the Kalman-type filters",
    "claim_crpf_time": "CRPF time grows with N; CRPF-300/500 are slower than the Kalman-type filters",
    "claim_lost": "Fig. 3: the target is sometimes lost",
}

NOTES = """\
Choices where the paper is silent (brief § 3.2-3.4; details in docs/paper003.md):
- Motion: random-walk velocity, T = 1 s, Q = blockdiag(0, sigma_a^2 I). Truth starts at x0 = [100, 50, -1, 1]
  in every run; each run draws its own acceleration sequence and measurement noise (100 steps, a measurement
  at every step including t = 0). Filters start from x^0 = [110, 40, 0, 0], P0 = diag(10^2, 10^2, 2^2, 2^2).
- Levels (sigma_theta rad, sigma_r m, sigma_a): L1 (0.01, 0.1, 0.01), L2 (0.1, 1, 0.1), L3 (1, 10, 1).
  The 3 x 3 grid varies (sigma_theta, sigma_r) with sigma_a = 0.1 fixed, mismatched variant only.
- Unknown noise: primary = mismatched (every filter gets the nominal L2 Q and R at every level); matched
  (the level's own Q and R) reported beside it. At L2 both variants coincide and share one computation.
  The CRPF reads no noise statistics (capability ignores_noise_statistics): its matched result is its
  mismatched one.
- Measured bearings are wrapped to (-pi, pi]; ranges are left as drawn (Gaussian, may be < 0 near the origin).
- UKF alpha = 1, beta = 2, kappa = 0; CDKF h = sqrt(3). SR forms: QR + cholupdate (downdates counted).
- CRPF: lam = 0.95, q = 2, beta = 2, delta = 0.01, the paper's plain norm cost, uniform initial box +-10 m,
  +-2 m/s; systematic selection every step. Jitter x ~ N(F x_parent, sigma^2 diag(s^2)), sigma^2 = kappa / N^(2/4),
  kappa = 1 with the per-component scale s = (T^2/2, T^2/2, T, T) = (0.5, 0.5, 1, 1) (the "dwna" shape).
  Chosen from a sweep: kappa in {0.1, 1, 10} x s in {iso = (1,1,1,1), pos = (1,1,0,0), vel0.1 = (1,1,0.1,0.1),
  vel0.01, dwna} (the ablation table recomputes iso, vel0.1 and dwna; pos makes the particle covariance
  singular and is recorded in docs/paper003.md only), CRPF-100, plain norm, 300 runs per level, seed 0, by one rule for every
  level (never per level): the smallest geometric mean over L1-L3 of the time-averaged MSE. (The mean rank
  over the levels, shown beside it, is not the rule: ranks ignore the size of the differences, and at L3
  every variant loses > 90 % of the tracks, so its ranks are noise.) The brief's literal default (kappa 1, isotropic) is the ablation row
  crpf-100-iso. No jitter setting stops the plain-norm CRPF from diverging: the cost ||y - h(x)||^2 adds
  m^2 and rad^2, so the bearing hardly enters and the cross-range error random-walks; the arc-length cost
  rows show that the cost scaling, not the jitter, is what loses the track. Every CRPF filter runs the fused
  kernel workbench.kernels.crpf_step (Numba on the CPU, else Taichi) for the range-bearing sensor; its
  propagation normals are counter-based (workbench.kernels.counter_normals, keyed by one draw of the
  filter's generator per step), the same numbers in the kernel and the array code, so both give the
  same particles up to float round-off.
- MSE(t) = mean over runs of the squared position error; the scalar is its mean over t. RMSE = sqrt(MSE).
  "Median" = the median over runs of each run's time-averaged squared error. Lost track: final position
  error > 50 m (the brief's "10 x the nominal cross-range noise, or > 50 m": with the nominal
  sigma_theta = 0.1 rad at ranges >= 100 m the first is >= 100 m, so 50 m binds). Runs whose true path
  comes within 10 m of the sensor are kept and counted in the scenario table.
- Processing time (Fig 7): mean wall time per run of un-batched runs (B = 1, L2 data, through run_filter,
  time.perf_counter), 200 runs at full size, with the median and the process CPU time beside it (the
  machine may be shared); the batched time per run is the Monte Carlo task's filtering time divided by
  its runs (mean over the three levels).
- Criterion 2 takes the UKF family as min(UKF, SR-UKF) and the CDKF family as min(CDKF, SR-CDKF);
  5 % tolerance. Criterion 5 calls time "about linear in N" when a straight-line fit of the un-batched
  CRPF times against N has R^2 >= 0.9 and a positive slope.
"""


# -- scenario -------------------------------------------------------------------------------------------


def nominal_models(host, case_sigmas: tuple[float, float, float], variant: str):
    """The motion and measurement models handed to the filters for a case's (sigma_theta, sigma_r, sigma_a)."""
    st, sr, sa = LEVELS[NOMINAL] if variant == "mismatched" else case_sigmas
    return random_walk_velocity(2, DT, sa), host.sensor(SENSOR).measurement_model(sigma_r=sr, sigma_theta=st)


def prior(batch: int) -> Gaussian:
    return Gaussian.broadcast(XHAT0, np.diag(P0), batch)


def simulate_chunk(host, seed: int, case: str, sigmas: tuple[float, float, float], chunk: int, runs: int,
                   steps: int) -> tuple[Truth, Scans]:
    """Truths and measurements of one chunk of ``runs`` runs: ``generator(seed, "paper003", case, chunk)``."""
    st, sr, sa = sigmas
    rng = generator(seed, "paper" + PAPER, case, chunk)
    truth = sample_motion(np.tile(X0, (runs, 1)), random_walk_velocity(2, DT, sa), steps, rng)
    scans = host.sensor(SENSOR).simulate(truth, rng, sigma_r=sr, sigma_theta=st)
    return truth, scans


def _units(cases: list[dict], runs: int, chunk: int) -> list[tuple[int, int, int]]:
    """Every (case index, chunk index, runs in the chunk) of a task, case by case."""
    bounds = chunk_bounds(runs, chunk)
    return [(c, k, stop - start) for c in range(len(cases)) for k, (start, stop) in enumerate(bounds)]


def simulate_units(host, seed: int, cases: list[dict], units, steps: int) -> tuple[Truth, Scans]:
    """The truths and measurements of ``units`` (from :func:`_units`) concatenated into one batch."""
    parts = [simulate_chunk(host, seed, cases[c]["case"], _sigmas(cases[c]), k, n, steps) for c, k, n in units]
    truth = Truth(np.concatenate([t.states for t, _ in parts]), parts[0][0].times)
    scans = Scans(np.concatenate([s.z for _, s in parts]), np.concatenate([s.valid for _, s in parts]),
                  parts[0][1].times, origin=np.concatenate([s.origin for _, s in parts]))
    return truth, scans


def _sigmas(case: Mapping) -> tuple[float, float, float]:
    return case["sigma_theta"], case["sigma_r"], case["sigma_a"]


def _case(name: str, sigmas) -> dict:
    return {"case": name, "sigma_theta": sigmas[0], "sigma_r": sigmas[1], "sigma_a": sigmas[2]}


def _batches(units, particles: int, budget: int) -> list[list[int]]:
    """Groups of consecutive units: all at once for a Gaussian filter, about ``budget`` particles for a PF
    (small enough for the particle arrays to stay in cache)."""
    if particles <= 1:
        return [list(range(len(units)))]
    groups, current, count = [], [], 0
    for i, (_, _, n) in enumerate(units):
        if current and count + n * particles > budget:
            groups.append(current)
            current, count = [], 0
        current.append(i)
        count += n * particles
    return groups + [current]


# -- tasks ----------------------------------------------------------------------------------------------


def _monte_carlo(ctx: TaskContext, cases: list[dict], variant: str, examples: int) -> list[dict] | None:
    """Run ``ctx.params["filter"]`` over every case of ``cases`` (one batch where the models allow);
    one summary dict per case, or None when a matched variant would repeat the mismatched one."""
    p = ctx.params
    spec = ctx.host.filter(p["filter"])
    if variant == "matched" and "ignores_noise_statistics" in spec.capabilities:
        return None
    motion, model = nominal_models(ctx.host, _sigmas(cases[0]), variant)
    units = _units(cases, p["runs"], p["chunk"])
    groups = _batches(units, int(spec.params.get("particles", 1)), p["particle_budget"])
    sq, est_xy, seconds, diag = [], [], 0.0, {}
    for g, members in enumerate(groups):
        truth, scans = simulate_units(ctx.host, ctx.seed, cases, [units[i] for i in members], p["steps"])
        first = units[members[0]]
        rng = generator(ctx.seed, "paper" + PAPER, cases[first[0]]["case"], "filter", p["filter"], first[1])
        t0 = time.perf_counter()
        est = run_filter(spec, prior(truth.batch), motion, model, scans, rng)
        seconds += time.perf_counter() - t0
        sq.append(position_sq_error(truth.states, est.mean))  # (B, T)
        est_xy.append(est.mean[:, :, :2])
        for k, v in est.diagnostics.items():
            diag[k] = diag.get(k, 0.0) + float(v)
        ctx.progress((g + 1) / len(groups))
    sq = np.concatenate(sq).reshape(len(cases), p["runs"], -1)
    est_xy = np.concatenate(est_xy).reshape(len(cases), p["runs"], -1, 2)
    out = []
    for c in range(len(cases)):
        final = np.sqrt(sq[c, :, -1])
        out.append({
            "mse_t": sq[c].mean(axis=0),
            "median_t": np.median(sq[c], axis=0),
            "run_mse": sq[c].mean(axis=1),
            "final_err": final,
            "lost": final > p["lost_m"],
            "est_xy": est_xy[c, :examples],
            "seconds": np.array(seconds / len(cases)),
            "runs": np.array(p["runs"]),
            "diag_names": np.array(sorted(diag), dtype=str),
            "diag_values": np.array([diag[k] / len(cases) for k in sorted(diag)], dtype=float),
        })
    return out


def run_monte_carlo(ctx: TaskContext) -> dict:
    """One filter on one level and one variant: summaries over all runs (see :func:`_monte_carlo`)."""
    p = ctx.params
    out = _monte_carlo(ctx, [_case(p["case"], (p["sigma_theta"], p["sigma_r"], p["sigma_a"]))], p["variant"],
                       p["examples"])
    return {"same_as_mismatched": np.array(True)} if out is None else out[0]


def run_cases(ctx: TaskContext) -> dict:
    """One filter over several cases (grid cells or levels) in one batch, mismatched models; the arrays of
    case ``i`` are prefixed ``"{case}:"``."""
    p = ctx.params
    out = _monte_carlo(ctx, [dict(c) for c in p["cases"]], "mismatched", 0)
    spec = ctx.host.filter(p["filter"]).params
    about = {"cost": np.array(str(spec.get("cost", "-"))), "jitter": np.array(_jitter_label(spec)),
             "kappa": np.array(f"{spec['kappa']:g}" if "kappa" in spec else "-")}
    return {**about, **{f"{case['case']}:{k}": v for case, res in zip(p["cases"], out) for k, v in res.items()}}


def run_scenario(ctx: TaskContext) -> dict:
    """The truths and measurements of a level's first ``examples`` runs, and every run's closest range."""
    p = ctx.params
    sigmas = (p["sigma_theta"], p["sigma_r"], p["sigma_a"])
    bounds = chunk_bounds(p["runs"], p["chunk"])
    min_range, truth_xy, z = [], [], []
    for c, (start, stop) in enumerate(bounds):
        truth, scans = simulate_chunk(ctx.host, ctx.seed, p["case"], sigmas, c, stop - start, p["steps"])
        min_range.append(np.hypot(truth.states[:, :, 0], truth.states[:, :, 1]).min(axis=1))
        if start < p["examples"]:
            truth_xy.append(truth.states[:, :, :2])
            z.append(scans.z[:, :, 0, :])
    return {
        "min_range": np.concatenate(min_range),
        "truth_xy": np.concatenate(truth_xy)[:p["examples"]],
        "z": np.concatenate(z)[:p["examples"]],
    }


def run_timing(ctx: TaskContext) -> dict:
    """Un-batched timing: ``timing_runs`` runs of L2 data one at a time (B = 1), mismatched models."""
    p = ctx.params
    spec = ctx.host.filter(p["filter"])
    sigmas = LEVELS[NOMINAL]
    motion, model = nominal_models(ctx.host, sigmas, "mismatched")
    truth, scans = simulate_chunk(ctx.host, ctx.seed, "timing", sigmas, 0, p["timing_runs"], p["steps"])
    per_run = np.empty(p["timing_runs"])
    per_run_cpu = np.empty(p["timing_runs"])
    one_prior = prior(1)
    for r in range(p["timing_runs"]):
        one = Scans(scans.z[r:r + 1], scans.valid[r:r + 1], scans.times)
        rng = generator(ctx.seed, "paper" + PAPER, "timing", p["filter"], r)
        t0, c0 = time.perf_counter(), time.process_time()
        run_filter(spec, one_prior, motion, model, one, rng)
        per_run[r], per_run_cpu[r] = time.perf_counter() - t0, time.process_time() - c0
        ctx.progress((r + 1) / p["timing_runs"])
    # wall time is the brief's measure; the process CPU time is shown beside it (the machine may be shared)
    return {"per_run_s": per_run, "per_run_cpu_s": per_run_cpu}


def _mc_params(values: Mapping, name: str, runs: int, examples: int, **extra) -> dict:
    return {"filter": name, "runs": runs, "steps": values["steps"], "chunk": min(values["chunk"], runs),
            "examples": examples, "lost_m": values["lost_m"], "particle_budget": values["particle_budget"], **extra}


def grid_case(st: float, sr: float) -> str:
    return f"grid-t{st:g}-r{sr:g}"


GRID_CASES = tuple(_case(grid_case(st, sr), (st, sr, GRID_SIGMA_A)) for st in GRID_THETA for sr in GRID_R)
LEVEL_CASES = tuple(_case(level, sig) for level, sig in LEVELS.items())


def tasks(options: RecipeOptions) -> list[Task]:
    v = options.values
    for key in SIZES["full"]:
        if key not in v:
            raise InputError(f"paper 003: size {options.size!r} lacks the value {key!r}")
    out = []
    for case in LEVEL_CASES:
        level = case["case"]
        out.append(Task(f"scenario/{level}", {**case, "runs": v["runs"], "steps": v["steps"], "chunk": v["chunk"],
                                              "examples": v["examples"]}, run_scenario))
        for name in options.filters:
            variants = ("mismatched",) if level == NOMINAL else ("mismatched", "matched")
            for variant in variants:
                out.append(Task(f"mc/{level}/{name}/{variant}",
                                _mc_params(v, name, v["runs"], v["examples"], variant=variant, **case),
                                run_monte_carlo))
    for name in options.filters:
        out.append(Task(f"grid/{name}", _mc_params(v, name, v["grid_runs"], 0, cases=list(GRID_CASES)), run_cases))
    for name in ABLATION_FILTERS:
        out.append(Task(f"ablation/{name}", _mc_params(v, name, v["ablation_runs"], 0, cases=list(LEVEL_CASES)),
                        run_cases))
    for name in options.filters:
        out.append(Task(f"timing/{name}", {"filter": name, "timing_runs": v["timing_runs"], "steps": v["steps"]},
                        run_timing))
    return out


# -- reading results ------------------------------------------------------------------------------------


def _filters_in(results: Mapping) -> list[str]:
    """Filter names with a mismatched result at every level, in task order."""
    names = []
    for key in results:
        parts = key.split("/")
        if parts[0] == "mc" and parts[3] == "mismatched" and parts[2] not in names:
            names.append(parts[2])
    return [n for n in names if all(f"mc/{lv}/{n}/mismatched" in results for lv in LEVELS)]


def _mc(results: Mapping, level: str, name: str, variant: str = "mismatched") -> Mapping[str, np.ndarray]:
    if variant == "matched" and level != NOMINAL:
        res = results.get(f"mc/{level}/{name}/matched")
        if res is not None and "same_as_mismatched" not in res:
            return res
    return results[f"mc/{level}/{name}/mismatched"]


def _mse(results, level, name, variant="mismatched") -> float:
    return float(np.mean(_mc(results, level, name, variant)["mse_t"]))


def _diag(res: Mapping, key: str) -> float:
    names = [str(n) for n in res.get("diag_names", [])]
    return float(res["diag_values"][names.index(key)]) if key in names else 0.0


def _timing(results, name) -> tuple[float, float]:
    """(un-batched seconds per run, batched seconds per run averaged over the levels)."""
    unbatched = float(np.mean(results[f"timing/{name}"]["per_run_s"])) if f"timing/{name}" in results else np.nan
    per = [float(_mc(results, lv, name)["seconds"]) / float(_mc(results, lv, name)["runs"]) for lv in LEVELS]
    return unbatched, float(np.mean(per))


# -- figures --------------------------------------------------------------------------------------------


def _example_table(results, level, names):
    """Per example run: lost flags ``(F, E)`` and time-averaged errors ``(F, E)`` at ``level``."""
    lost = np.array([_mc(results, level, n)["lost"][: len(_mc(results, level, n)["est_xy"])] for n in names])
    err = np.array([_mc(results, level, n)["run_mse"][: len(_mc(results, level, n)["est_xy"])] for n in names])
    return lost, err


def _example_data(results, level, run, names, why) -> dict:
    scen = results[f"scenario/{level}"]
    z = scen["z"][run]
    return {
        "level": np.array(level), "run": np.array(run), "why": np.array(why),
        "filters": np.array(names, dtype=str),
        "truth_xy": scen["truth_xy"][run],
        "meas_xy": np.stack([z[:, 0] * np.cos(z[:, 1]), z[:, 0] * np.sin(z[:, 1])], axis=-1),
        "est_xy": np.stack([_mc(results, level, n)["est_xy"][run] for n in names]),
        "lost": np.array([bool(_mc(results, level, n)["lost"][run]) for n in names]),
    }


def fig2_data(results) -> dict:
    """A run where every filter tracks: the example run (L1, then L2) with the smallest worst-filter error
    among runs where no filter is lost (or the fewest filters lost)."""
    names = _filters_in(results)
    best = None
    for level in ("L1", "L2"):
        lost, err = _example_table(results, level, names)
        score = lost.sum(axis=0) * 1e12 + err.max(axis=0)
        run = int(np.argmin(score))
        cand = (float(score[run]), level, run)
        if best is None or cand[0] < best[0]:
            best = cand
    _, level, run = best
    return _example_data(results, level, run, names, "all filters track (smallest worst-filter error)")


def fig3_data(results) -> dict:
    """A run where a filter loses the target: EKF lost while another filter tracks (L2, L3, L1), else
    any filter lost while another tracks, else the run with the largest spread of final errors."""
    names = _filters_in(results)
    fallback = None
    for level in ("L2", "L3", "L1"):
        lost, err = _example_table(results, level, names)
        some_track = ~lost.all(axis=0)
        if "ekf" in names:
            ekf_lost = lost[names.index("ekf")] & some_track
            if ekf_lost.any():
                # most filters still tracking, then the largest EKF error
                tracking = (~lost).sum(axis=0)
                score = np.where(ekf_lost, tracking * 1e12 + np.minimum(err[names.index("ekf")], 1e11), -np.inf)
                run = int(np.argmax(score))
                return _example_data(results, level, run, names, "EKF loses the target")
        any_lost = lost.any(axis=0) & some_track
        if any_lost.any() and fallback is None:
            spread = np.where(any_lost, err.max(axis=0) / np.maximum(err.min(axis=0), 1e-12), -np.inf)
            run = int(np.argmax(spread))
            who = ", ".join(n for n, flag in zip(names, lost[:, run]) if flag)
            fallback = (level, run, f"{who} lose(s) the target")
    if fallback is None:
        lost, err = _example_table(results, "L3", names)
        run = int(np.argmax(err.max(axis=0) / np.maximum(err.min(axis=0), 1e-12)))
        fallback = ("L3", run, "no example run with a lost track: largest spread of errors")
    level, run, why = fallback
    return _example_data(results, level, run, names, why)


def _draw_example(data, fig) -> None:
    ax = fig.add_subplot()
    ax.plot(data["meas_xy"][:, 0], data["meas_xy"][:, 1], ".", color="0.7", ms=3, label="measurements")
    ax.plot(data["truth_xy"][:, 0], data["truth_xy"][:, 1], "k-", lw=2, label="truth")
    for name, xy, lost in zip(data["filters"], data["est_xy"], data["lost"]):
        ax.plot(xy[:, 0], xy[:, 1], "-", lw=1, label=f"{name}{' (lost)' if lost else ''}")
    ax.plot([0], [0], "k^", ms=8, label="sensor")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{data['level']} run {int(data['run'])}: {data['why']}", fontsize=9)
    truth = data["truth_xy"]
    span = np.ptp(np.concatenate([truth, [[0.0, 0.0]]]), axis=0).max()
    centre = truth.mean(axis=0)
    ax.set_xlim(centre[0] - span, centre[0] + span)
    ax.set_ylim(centre[1] - span, centre[1] + span)
    ax.set_aspect("equal", adjustable="box")
    ax.legend(fontsize=7, ncol=2)


def mse_data(level: str):
    def data(results) -> dict:
        names = _filters_in(results)
        return {"level": np.array(level), "filters": np.array(names, dtype=str),
                "time": np.arange(len(_mc(results, level, names[0])["mse_t"])) * DT,
                "mse_t": np.stack([_mc(results, level, n)["mse_t"] for n in names]),
                "mse_t_matched": np.stack([_mc(results, level, n, "matched")["mse_t"] for n in names])}
    return data


def _draw_mse(data, fig) -> None:
    ax = fig.add_subplot()
    for name, curve in zip(data["filters"], data["mse_t"]):
        ax.semilogy(data["time"], curve, label=str(name), lw=1.2,
                    ls="--" if str(name).startswith("sr-") else "-")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position MSE (m$^2$)")
    ax.set_title(f"{data['level']}: mismatched noise statistics (nominal L2 Q, R)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)


def fig7_data(results) -> dict:
    names = _filters_in(results)
    times = np.array([_timing(results, n) for n in names])
    runs = np.array([len(results[f"timing/{n}"]["per_run_s"]) if f"timing/{n}" in results else 0 for n in names])
    return {"filters": np.array(names, dtype=str), "unbatched_s_per_run": times[:, 0],
            "batched_s_per_run": times[:, 1], "timing_runs": runs}


def _draw_time(data, fig) -> None:
    ax = fig.add_subplot()
    x = np.arange(len(data["filters"]))
    ax.bar(x - 0.2, data["unbatched_s_per_run"] * 1e3, 0.4, label="un-batched (B = 1)")
    ax.bar(x + 0.2, data["batched_s_per_run"] * 1e3, 0.4, label="batched Monte Carlo", hatch="//")
    ax.set_yscale("log")
    ax.set_xticks(x, [str(n) for n in data["filters"]], rotation=30, ha="right")
    ax.set_ylabel("wall time per run of 100 steps (ms)")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8)


# -- tables ---------------------------------------------------------------------------------------------


def _fmt(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}" if np.isfinite(x) else "n/a"


def mse_table(results) -> Table:
    names = _filters_in(results)
    rows = []
    for level in LEVELS:
        for n in names:
            row = [n, level]
            for variant in ("mismatched", "matched"):
                res = _mc(results, level, n, variant)
                mse = float(np.mean(res["mse_t"]))
                row += [_fmt(mse), _fmt(np.sqrt(mse)), _fmt(float(np.median(res["run_mse"]))),
                        f"{100 * float(np.mean(res['lost'])):.1f}"]
            res = _mc(results, level, n)
            events = {k: v for k, v in zip([str(s) for s in res["diag_names"]], res["diag_values"])
                      if k in ("downdate_fallbacks", "cholesky_jitter")}
            row.append(", ".join(f"{k}={int(v)}" for k, v in events.items()) or "-")
            rows.append(tuple(row))
    cols = ("filter", "level", "MSE (m^2)", "RMSE (m)", "median run MSE", "lost %", "MSE matched", "RMSE matched",
            "median matched", "lost % matched", "fallbacks / jitter (mismatched)")
    return Table(cols, tuple(rows))


def grid_table(results) -> Table:
    names = [n for n in _filters_in(results) if f"grid/{n}" in results]
    rows = []
    for st in GRID_THETA:
        for sr in GRID_R:
            case = grid_case(st, sr)
            rows.append((f"{st:g}", f"{sr:g}",
                         *[_fmt(float(np.mean(results[f"grid/{n}"][f"{case}:mse_t"]))) for n in names]))
    return Table(("sigma_theta (rad)", "sigma_r (m)", *[f"MSE {n}" for n in names]), tuple(rows))


def _jitter_label(params: Mapping) -> str:
    scale = params.get("scale")
    return "iso" if scale is None else "(" + ", ".join(f"{v:g}" for v in scale) + ")"


def ablation_table(results) -> Table:
    """CRPF-100 sweep: per variant the MSE and lost rate per level, the geometric mean of the MSE over the
    levels and the mean rank among the plain-norm rows; the rule's choice and the defaults are marked."""
    names = [n for n in ABLATION_FILTERS if f"ablation/{n}" in results]
    mse = {n: [float(np.mean(results[f"ablation/{n}"][f"{lv}:mse_t"])) for lv in LEVELS] for n in names}
    plain = [n for n in names if "-arc" not in n]
    geo = {n: float(np.exp(np.mean(np.log(mse[n])))) for n in names}
    ranks = {}
    if plain:
        table = np.array([mse[n] for n in plain])
        r = np.argsort(np.argsort(table, axis=0), axis=0) + 1
        ranks = {n: float(r[i].mean()) for i, n in enumerate(plain)}
    chosen = min(plain, key=lambda n: geo[n]) if plain else None
    rows = []
    for name in names:
        res = results[f"ablation/{name}"]
        row = [name, str(res.get("cost", np.array("?"))), str(res.get("jitter", np.array("?"))),
               str(res.get("kappa", np.array("?")))]
        for i, lv in enumerate(LEVELS):
            row += [_fmt(mse[name][i]), f"{100 * float(np.mean(res[f'{lv}:lost'])):.1f}"]
        marks = [m for m, ok in (("paper default", name == "crpf-100"), ("brief's literal default",
                                                                         name == LITERAL_DEFAULT),
                                 ("chosen by the rule here", name == chosen)) if ok]
        row += [_fmt(geo[name]), f"{ranks[name]:.2f}" if name in ranks else "-", "; ".join(marks) or "-"]
        rows.append(tuple(row))
    best_kf = []
    for lv in LEVELS:
        kf = [n for n in KALMAN_TYPE if f"mc/{lv}/{n}/mismatched" in results]
        best_kf += [_fmt(min(_mse(results, lv, n) for n in kf)) if kf else "n/a", ""]
    rows.append(("best Kalman-type (main runs)", "", "", "", *best_kf, "", "", ""))
    cols = ["CRPF-100 variant", "cost", "jitter scale", "kappa"]
    for lv in LEVELS:
        cols += [f"MSE {lv}", f"lost % {lv}"]
    cols += ["geometric mean MSE", "mean rank (plain norm)", "rule: " + SWEEP_RULE]
    return Table(tuple(cols), tuple(rows))


def timing_table(results) -> Table:
    data = fig7_data(results)
    rows = []
    claims = {"sr-ukf": "faster than UKF (MATLAB)", "sr-cdkf": "fastest of the EKF family",
              "crpf-100": "faster than SR-CDKF", "crpf-300": "slower than the Kalman-type filters",
              "crpf-500": "slower than the Kalman-type filters"}
    for n, ub, b, r in zip(data["filters"], data["unbatched_s_per_run"], data["batched_s_per_run"],
                           data["timing_runs"]):
        res = results.get(f"timing/{n}", {})
        med = float(np.median(res["per_run_s"])) if "per_run_s" in res else np.nan
        cpu = float(np.mean(res["per_run_cpu_s"])) if "per_run_cpu_s" in res else np.nan
        rows.append((str(n), _fmt(ub * 1e3), _fmt(med * 1e3), _fmt(cpu * 1e3), int(r), _fmt(b * 1e6),
                     _fmt(ub / b if b > 0 else np.nan, 3), claims.get(str(n), "-")))
    return Table(("filter", "un-batched ms / run (mean wall)", "un-batched ms / run (median wall)",
                  "un-batched ms / run (mean CPU)", "timed runs", "batched us / run", "speed-up of batching",
                  "paper's claim"), tuple(rows))


def scenario_table(results) -> Table:
    rows = []
    for level, (st, sr, sa) in LEVELS.items():
        mr = results[f"scenario/{level}"]["min_range"]
        rows.append((level, st, sr, sa, len(mr), _fmt(float(np.median(mr))), int(np.sum(mr < 10.0))))
    return Table(("level", "sigma_theta (rad)", "sigma_r (m)", "sigma_a (m/s per step)", "runs",
                  "median closest range (m)", "runs within 10 m of the sensor (kept, flagged)"), tuple(rows))


def claims_table(results) -> Table:
    crit = {c.id: c for c in criteria(results)}
    pairs = (("claim_noise", "C1"), ("claim_cdkf", "C2"), ("claim_sr", "C3"), ("claim_crpf_accuracy", "C4"),
             ("claim_crpf_time", "C5"), ("claim_sr", "C6"))
    rows = tuple((PUBLISHED[p], c, "met" if crit[c].met else "not met", crit[c].detail) for p, c in pairs)
    return Table(("paper's claim", "criterion", "ours", "computed from"), rows)


# -- criteria -------------------------------------------------------------------------------------------


def _missing(results, names) -> list[str]:
    have = _filters_in(results)
    return [n for n in names if n not in have]


def criteria(results) -> list[Criterion]:
    out = []
    names = _filters_in(results)
    mse = {(lv, n): _mse(results, lv, n) for lv in LEVELS for n in names}

    # 1. MSE(L1) < MSE(L2) < MSE(L3) for every filter
    bad = [n for n in names if not (mse["L1", n] < mse["L2", n] < mse["L3", n])]
    out.append(Criterion("C1", "MSE(L1) < MSE(L2) < MSE(L3) for every filter (mismatched)", not bad and bool(names),
                         "holds for all " + str(len(names)) + " filters" if not bad else "fails for " + ", ".join(
                             f"{n} ({mse['L1', n]:.3g}, {mse['L2', n]:.3g}, {mse['L3', n]:.3g})" for n in bad)))

    # 2. min(CDKF, SR-CDKF) <= UKF family <= EKF at >= 2 of 3 levels, 5 % tolerance
    miss = _missing(results, ("ekf", "ukf", "sr-ukf", "cdkf", "sr-cdkf"))
    if miss:
        out.append(Criterion("C2", "min(MSE_CDKF, MSE_SR-CDKF) <= MSE_UKF-family <= MSE_EKF at >= 2 of 3 levels",
                             False, "not evaluable: missing " + ", ".join(miss)))
    else:
        held, parts = 0, []
        for lv in LEVELS:
            cd = min(mse[lv, "cdkf"], mse[lv, "sr-cdkf"])
            uk = min(mse[lv, "ukf"], mse[lv, "sr-ukf"])
            ek = mse[lv, "ekf"]
            ok = cd <= 1.05 * uk and uk <= 1.05 * ek
            held += ok
            parts.append(f"{lv}: CDKF {cd:.4g}, UKF {uk:.4g}, EKF {ek:.4g} {'ok' if ok else 'no'}")
        out.append(Criterion("C2", "min(MSE_CDKF, MSE_SR-CDKF) <= MSE_UKF-family <= MSE_EKF at >= 2 of 3 levels "
                                   "(5 % tolerance)", held >= 2, f"{held}/3 levels; " + "; ".join(parts)))

    # 3. SR-X vs X relative MSE difference < 1e-6 with no fallbacks, else < 1 %
    miss = _missing(results, ("ukf", "sr-ukf", "cdkf", "sr-cdkf"))
    if miss:
        out.append(Criterion("C3", "SR-X vs X relative MSE difference < 1e-6 (no fallbacks) or < 1 %", False,
                             "not evaluable: missing " + ", ".join(miss)))
    else:
        ok_all, parts = True, []
        for lv in LEVELS:
            for base, sr in SR_PAIRS:
                events = _diag(_mc(results, lv, sr), "downdate_fallbacks") + _diag(_mc(results, lv, base),
                                                                                   "cholesky_jitter")
                rel = abs(mse[lv, sr] - mse[lv, base]) / mse[lv, base]
                limit = 1e-6 if events == 0 else 1e-2
                ok_all &= rel < limit
                parts.append(f"{lv} {sr}: {rel:.2g} (limit {limit:g}, {int(events)} fallback/jitter events)")
        out.append(Criterion("C3", "SR-X vs X relative MSE difference < 1e-6 with no fallbacks, otherwise < 1 %",
                             ok_all, "; ".join(parts)))

    # 4. CRPF-100 <= best Kalman-type at L2 and L3; MSE decreases 100 -> 300 -> 500
    miss = _missing(results, CRPF_FILTERS + KALMAN_TYPE)
    if miss:
        out.append(Criterion("C4", "MSE_CRPF-100 <= best Kalman-type at L2, L3; MSE decreases with N", False,
                             "not evaluable: missing " + ", ".join(miss)))
    else:
        fails, parts = [], []
        for lv in ("L2", "L3"):
            best = min(mse[lv, n] for n in KALMAN_TYPE)
            ok = mse[lv, "crpf-100"] <= best
            parts.append(f"{lv}: CRPF-100 {mse[lv, 'crpf-100']:.4g} vs best Kalman-type {best:.4g}")
            if not ok:
                fails.append(f"{lv} (CRPF-100 vs Kalman)")
        for lv in LEVELS:
            seq = [mse[lv, n] for n in CRPF_FILTERS]
            ok = seq[0] > seq[1] > seq[2]
            parts.append(f"{lv}: N=100/300/500 {seq[0]:.4g} / {seq[1]:.4g} / {seq[2]:.4g}")
            if not ok:
                fails.append(f"{lv} (monotone in N)")
        note = ""
        if fails and all(f.startswith("L1") for f in fails):
            note = " Fails only at L1: a documented deviation (kappa and cost scaling)."
        out.append(Criterion("C4", "MSE_CRPF-100 <= the best Kalman-type MSE at L2 and L3; MSE decreases from "
                                   "N = 100 to 300 to 500", not fails,
                             ("fails: " + ", ".join(fails) + "." if fails else "holds.") + note + " "
                             + "; ".join(parts)))

    # 5. CRPF time about linear in N; CRPF-300/500 slower than every Kalman-type filter (un-batched)
    miss = _missing(results, CRPF_FILTERS + KALMAN_TYPE)
    if miss or any(f"timing/{n}" not in results for n in CRPF_FILTERS + KALMAN_TYPE):
        out.append(Criterion("C5", "CRPF time about linear in N; CRPF-300/500 slower than every Kalman-type filter",
                             False, "not evaluable: missing timings"))
    else:
        t = {n: _timing(results, n)[0] for n in CRPF_FILTERS + KALMAN_TYPE}
        y = np.array([t[n] for n in CRPF_FILTERS])
        x = np.array(CRPF_PARTICLES, dtype=float)
        slope, icpt = np.polyfit(x, y, 1)
        r2 = 1.0 - np.sum((y - (slope * x + icpt)) ** 2) / max(np.sum((y - y.mean()) ** 2), 1e-300)
        linear = slope > 0 and r2 >= 0.9
        slowest_kf = max(t[n] for n in KALMAN_TYPE)
        slower = t["crpf-300"] > slowest_kf and t["crpf-500"] > slowest_kf
        # the same test on the batched times, for the record (not the brief's measure)
        tb = {n: _timing(results, n)[1] for n in CRPF_FILTERS + KALMAN_TYPE}
        yb = np.array([tb[n] for n in CRPF_FILTERS])
        sb, ib = np.polyfit(x, yb, 1)
        r2b = 1.0 - np.sum((yb - (sb * x + ib)) ** 2) / max(np.sum((yb - yb.mean()) ** 2), 1e-300)
        slower_b = min(tb["crpf-300"], tb["crpf-500"]) > max(tb[n] for n in KALMAN_TYPE)
        out.append(Criterion(
            "C5", "CRPF time about linear in N (straight-line fit R^2 >= 0.9), and CRPF-300/500 slower than every "
                  "Kalman-type filter (un-batched)", bool(linear and slower),
            f"un-batched ms/run CRPF-100/300/500 = {1e3 * y[0]:.3g} / {1e3 * y[1]:.3g} / {1e3 * y[2]:.3g} "
            f"(fit R^2 {r2:.3f}, {1e6 * slope:.3g} us per particle per run, intercept {1e3 * icpt:.3g} ms/run = "
            f"{100 * icpt / y[0]:.0f} % of CRPF-100's time: the per-call overhead that does not depend on N"
            f"{' dominates' if icpt > 0.5 * y[0] else ''}); slowest Kalman-type {1e3 * slowest_kf:.3g} ms/run; "
            f"CRPF-300/500 slower than it: {'yes' if slower else 'no'}. Batched Monte Carlo (the same test where "
            f"the overhead is shared by the runs): {1e6 * yb[0]:.3g} / {1e6 * yb[1]:.3g} / {1e6 * yb[2]:.3g} us/run, "
            f"fit R^2 {r2b:.3f}, {1e3 * sb:.3g} ns per particle per run, intercept {1e6 * ib:.3g} us/run; linear: "
            f"{'yes' if sb > 0 and r2b >= 0.9 else 'no'}; CRPF-300/500 slower than every Kalman-type filter: "
            f"{'yes' if slower_b else 'no'}"))

    # 6. SR vs non-SR timing: reported, not required
    if any(f"timing/{n}" not in results for pair in SR_PAIRS for n in pair):
        out.append(Criterion("C6", "SR vs non-SR timing (reported only, not required)", False,
                             "not evaluable: missing timings"))
    else:
        ratios = {sr: _timing(results, sr)[0] / _timing(results, base)[0] for base, sr in SR_PAIRS}
        out.append(Criterion("C6", "SR forms faster than non-SR forms (reported only; not required in NumPy)",
                             all(r < 1.0 for r in ratios.values()),
                             "; ".join(f"{sr}/{base} un-batched time ratio {ratios[sr]:.3g}" for base, sr in SR_PAIRS)))
    return out


FIGURES = (
    FigureSpec("fig2", "A run where every filter tracks: truth, estimates, measurements converted to x-y.",
               fig2_data, _draw_example, size=(6.4, 6.0)),
    FigureSpec("fig3", "A run where a filter loses the target (EKF divergence where one occurs).",
               fig3_data, _draw_example, size=(6.4, 6.0)),
    FigureSpec("fig4", "Position MSE vs time at L1 (sigma_theta 0.01, sigma_r 0.1, sigma_a 0.01), mismatched.",
               mse_data("L1"), _draw_mse),
    FigureSpec("fig5", "Position MSE vs time at L2 (sigma_theta 0.1, sigma_r 1, sigma_a 0.1), matched = mismatched.",
               mse_data("L2"), _draw_mse),
    FigureSpec("fig6", "Position MSE vs time at L3 (sigma_theta 1, sigma_r 10, sigma_a 1), mismatched.",
               mse_data("L3"), _draw_mse),
    FigureSpec("fig7", "Processing time per run per filter: un-batched (B = 1) and batched Monte Carlo.",
               fig7_data, _draw_time),
)

TABLES = (
    TableSpec("mse", "Time-averaged position MSE, RMSE, median run and lost-track rate per filter and level "
                     "(mismatched = primary; matched beside it). The paper's values were lost (curves only).",
              mse_table),
    TableSpec("grid", "Time-averaged MSE over the 3 x 3 (sigma_theta, sigma_r) grid, sigma_a = 0.1, mismatched.",
              grid_table),
    TableSpec("ablation", "CRPF-100 sweep: jitter kappa x per-component scale with the paper's plain norm, and the "
                          "arc-length cost; one setting for every level (no per-level tuning).",
              ablation_table),
    TableSpec("timing", "Processing time per run (100 steps) per filter.", timing_table),
    TableSpec("scenario", "Noise levels and closest approach of the simulated truths.", scenario_table),
    TableSpec("claims", "The paper's qualitative claims beside the criteria computed from our numbers.",
              claims_table),
)

RECIPE = RecipeSpec(
    paper=PAPER,
    title="EKF, UKF, CDKF, SR-UKF, SR-CDKF and the cost-reference particle filter under unknown noise",
    sizes=SIZES,
    tasks=tasks,
    figures=FIGURES,
    tables=TABLES,
    criteria=criteria,
    default_filters=DEFAULT_FILTERS,
    published=PUBLISHED,
    notes=NOTES,
)
