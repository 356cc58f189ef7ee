"""Paper 001's scenario: the constants, the declared unknowns, the simulation of the sonar detections and the
trackers' settings (the building blocks every task shares)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Mapping

import numpy as np

from workbench.criteria import DeclaredUnknown
from workbench.metrics import TrackCounts, track_counts, track_gospa, track_truth_match
from workbench.models import MeasurementModel, constant_velocity
from workbench.plugins import PluginHost
from workbench.recorded.sonar import write_sonar_csv
from workbench.rng import generator
from workbench.tracking import CONFIRMED, TrackerConfig, run_tracker
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import CLUTTER, Gaussian, InputError, Scan, Scans, Truth

PAPER = "001"


START = (100.0, 100.0)  # [S]


VELOCITY = (4.0, 2.0)  # per ping [S]


PINGS = 20  # [S]


DT = 1.0  # one ping [U]


Q_INTENSITY = 0.01  # CMKF-L process noise q [S]


SENSOR = "active-sonar"


CLUTTER_GEN = "sonar-poisson"


REMOVER = "hough"


PAPER_FILTER = "cmkf-l"


SONAR = {"pd": 0.8, "sigma_pos": 2.0, "level_db": 20.0, "sigma_level": 0.1}  # [S]


POLAR = {"frame": "polar", "sigma_r": 0.5, "sigma_b_deg": 1.0}  # the paper's R: 0.5, 1 degree [S/U]


MATCHED = {"frame": "cartesian"}  # position model with the sensor's stated accuracy (filters without polar input)


SIM_CLUTTER = {"pfa": 5e-4, "area": [0.0, 250.0, 0.0, 250.0], "cell_area": 1.0, "mean_snr_db": 10.0}  # [S/U]


SURROGATE_CLUTTER = {**SIM_CLUTTER, "rate_scale": 2.0, "persistent_sites": 5, "persistent_pd": 0.7,
                     "persistent_sigma": 2.0}


#: the remover as the brief reconstructs it, with the local latest-support rule (docs/paper001.md)
HOUGH = {"window": 5, "shift": 1, "v_max": 8.0, "dt": DT, "gate_gap": 2, "d_rho": 1.0, "d_theta_deg": 1.0,
         "v_min": 3, "sim_rho": 3.0, "sim_theta_deg": 3.0, "eps": 4.0, "support": "local", "support_reach": None,
         "vel_gate": 9.21, "sigma_pos": SONAR["sigma_pos"], "require_chain": False,
         "new_measurements": "detections", "warmup": "drop"}


#: remover variants: name -> changes to HOUGH
VARIANTS: dict[str, dict] = {
    "main": {},
    "previous-rule": {"support": "latest"},
    "any": {"support": "any"},
    "no-velocity-check": {"vel_gate": None},
    "chain": {"require_chain": True},
    "projected": {"new_measurements": "projected"},
    "dtheta2": {"d_theta_deg": 2.0},
    "dtheta3": {"d_theta_deg": 3.0},
    "halves": {"window": 3, "shift": 3, "v_min": 2},
}


#: Remover variants whose rows the sim blocks compute already: the main remover (the block's removal, its statistics
#: ``rem/main/`` and the paper and stated rows after it, ``paper/after/``, ``stated/after/``).  The variants task does
#: not run it again; the variants table reads it from ``sim/<block>``.
VARIANTS_IN_SIM = ("main",)


VARIANT_LABELS = {
    "main": "local latest support within v_max T max(gap, 2), velocity check (main)",
    "previous-rule": "latest support anywhere on the line, within 2 v_max T (the previous rule)",
    "any": "any earlier support within 2 v_max T",
    "no-velocity-check": "as main, without the velocity-consistency check",
    "chain": "as main, the velocity check needs the support's own earlier support (3-point chain)",
    "projected": "as main, kept detections projected onto the nearest similar line",
    "dtheta2": "as main, d_theta = 2 deg",
    "dtheta3": "as main, d_theta = 3 deg",
    "halves": "as main, non-overlapping halves W'=3, V_min=2",
}


#: the brief's track-management defaults [U] (the primary rows): confirm 3 of 5 after initiation, delete
#: after 3 misses, gate 9.21 (chi2_2, 99 %) with the filter's own R; the paper's initial covariance: the speed-course
#: prior with its "speed error" sigma_v = 1 and "course error" sigma_c = 1 (rad) [S values, brief § 1.3]
TRACKER = {"gate": 9.21, "v_max": 8.0, "confirm_hits": 3, "confirm_window": 5, "delete_misses": 3,
           "initiation_hits": 0, "prior": "speed-course", "sigma_v": 1.0, "sigma_c": 1.0}


#: the paper's M-of-N as it describes it: accumulate initiation detections, then M-of-N (brief § 1.3, revised): the
#: two initiation detections count as hits; this row also has R matched to the sensor (its stated accuracy)
PAPER_MOFN = {"initiation_hits": 2}


#: the row Figs 5, 6, 9 and 10 draw: the paper's M-of-N with R matched to the sensor, the row with the paper's
#: clutter tracks (the paper rows have few; their means are drawn beside it in Figs 9 and 10)
FIG_ARM = "paper-mofn"


#: the previous round's primary initial covariance, kept as a labelled ablation of the paper rows: the standard
#: two-point prior from the two initiation detections' covariances instead of the paper's speed-course sigma_v, sigma_c
TWO_POINT = {"prior": "two-point"}


#: the settings of the previous version (an ablation that keeps its numbers reproducible)
TRACKER_PREVIOUS = {"gate": 9.21, "v_max": 8.0, "confirm_hits": 3, "confirm_window": 5, "delete_misses": 4,
                    "initiation_hits": 2, "prior": "speed-course", "sigma_v": 1.0, "sigma_c": 1.0,
                    "gate_sigma": 2.0}


HOUGH_PREVIOUS = {**HOUGH, "support": "latest"}


#: the stationary-clutter extension: a track slower than this is not confirmed [U]: the 99 % point of the
#: speed estimate of a stationary object from 5 detections at the stated accuracy 2.0 is about 1.9
MIN_SPEED = 2.0


#: tuning: candidates (closest to the brief's defaults first), and the rule, fixed before any result
TUNING_CANDIDATES = tuple({"gate_sigma": g, "delete_misses": d} for g in (None, 1.0, 2.0, 3.0) for d in (3, 4, 5))


TUNING_RULE = ("maximise, on the tuning runs only, the share of runs in which the target holds a confirmed track "
               "for >= 80 % of the pings after initiation after removal (the statistic of criterion 2); equal "
               "counts go to the candidate listed first (closest to the brief's defaults)")


TUNING_STREAM = "tuning"


TRUE_RADIUS = 6.0  # 3 sigma


TRUE_FRACTION = 0.8


#: GOSPA beside the paper's counts (the standard multi-target distance, alpha = 2): cut-off c = 10 (5 sigma of the
#: sensor's stated position accuracy: a track farther than that is as bad as a missed target plus a false one)
#: and order p = 2, on the confirmed tracks at every ping after the Hough warm-up.
GOSPA_C, GOSPA_P = 10.0, 2.0


PROTOCOL_RUNS = 20  # the paper's own protocol: 20 pings, averaged as a 20-run Monte Carlo [U]


SURROGATE_SEED = 20240201


SURROGATE_FILE = Path(__file__).resolve().parents[3] / "examples" / "data" / "sonar_sea_trial_surrogate.csv"


SURROGATE_LABEL = "SYNTHETIC SURROGATE - not sea-trial data"


#: The multi-target trackers paper 001 compares (issue 25), ``RecipeSpec.default_trackers``; ``--trackers`` adds,
#: removes or replaces them.  ``"mofn"`` as declared (no values) stands for the paper's own M-of-N rows (the judged
#: ``paper`` arm, and beside it the ``stated`` arm), never rerun: M-of-N is the paper's method.  Every other reference
#: (``gnn``, ``jipda``, ``gm-phd``, a configured ``mofn(...)``, an installed third-party tracker) is an EXTENSION row,
#: run by the ``trackers/<block>`` tasks on the same detections as the paper rows (common random numbers), before and
#: after the Hough remover.
DEFAULT_TRACKERS = ("mofn", "gnn", "jipda", "gm-phd")


PAPER_TRACKER = "mofn"


#: The extension rows' filter and measurement model: the linear Kalman filter on the Cartesian detections with the
#: sensor's stated accuracy (R = 2.0^2 I, the ``stated`` arm's R).  CMKF-L takes range-bearing only, and the JIPDA
#: and GM-PHD take detections in the measurement model's own frame (GM-PHD's adaptive birth needs a linear model).
EXT_FILTER = "kf"


#: The built-in trackers' settings on this scenario (a reference's own values override them; a third-party tracker
#: runs with its own defaults and the values its reference gives): M-of-N and GNN take the brief's track management
#: (TRACKER; GNN's gate_probability default 0.99 is the same chi2_2 gate 9.21), the JIPDA, JPDA and GM-PHD the
#: sensor's P_D = 0.8; the clutter density is left to each tracker's own per-scan estimate (it changes by an order
#: of magnitude with the remover), every other value is the tracker's declared default.
TRACKER_SETTINGS = {
    "mofn": dict(TRACKER),
    "gnn": {k: v for k, v in TRACKER.items() if k != "gate"},
    "jipda": {"p_detection": SONAR["pd"]},
    "jpda": {"p_detection": SONAR["pd"]},
    "gm-phd": {"p_detection": SONAR["pd"]},
}


SIZES = {"quick": {"runs": 10, "seeds": 1, "tuning_runs": 10, "variant_seeds": 1},
         "full": {"runs": 50, "seeds": 4, "tuning_runs": 100, "variant_seeds": 2}}


#: the criteria's sample sizes: fewer runs give "inconclusive"
MIN_RUNS = {"1": 50, "2": 200, "3": 50}


#: criterion 1's population: the fewest false tracks before removal, summed over the judged runs and pings 6-20
#: (a false track counts once per ping of its confirmed life), from which its removal rate may be decided.  Why
#: 150: the exact (Clopper-Pearson) 95 % interval of the published 78 % lies inside the passing band [60 %, 95 %]
#: only from about 30 independent false tracks (29: [60.3 %, 92.0 %]); a confirmed false track is counted at
#: every ping of its life (3 to 5 pings or more under the paper rows' management), so its per-ping counts are
#: not independent, and 30 tracks of up to 5 pings are 150 counts.  Set from this argument alone (issue 24 had
#: already given the full size's 61.4 % and 0.13 per ping; the full verdict does not hinge on it: 396 >= 150);
#: below it criterion 1 is not judgeable (never met, never not met), whatever its interval says.
MIN_FALSE_BEFORE = 150


#: The values paper 001 withholds that the criteria hinge on, judged across small grids (issue 24 item 2): every
#: criterion of the paper rows is judged again at each grid value on the same runs (the same target detections:
#: the clutter is drawn after them from each run's own stream), the primary verdicts at the primary values.
CLUTTER_PER_PING = DeclaredUnknown(
    "clutter per ping", "points per ping", 31.25, (15.625, 31.25, 62.5),
    "The paper gives Pfa = 0.05 % and the target's P_D but not the surveillance area or its resolution cells, so "
    "the mean clutter count per ping is ours: [0, 250]^2 in unit cells gives 5e-4 x 62 500 = 31.25 (the brief's "
    "choice, primary). The grid halves and doubles it (cells of 2 and 0.5 square units): the paper's Fig 5 shows "
    "many clutter tracks before removal, our primary scene few.")


MOFN_WINDOW = DeclaredUnknown(
    "M-of-N confirmation", "", "3 of 5", ("2 of 4", "3 of 5", "4 of 6"),
    "The paper confirms and deletes tracks by an M-of-N rule without giving M and N; 3 of 5 is the brief's "
    "choice (primary); the grid takes one hit fewer and one more in a window one ping shorter and longer.")


UNKNOWNS = (CLUTTER_PER_PING, MOFN_WINDOW)


def _unknown_changes(unknown: DeclaredUnknown, value) -> dict:
    """The simulation and tracker settings of one grid value: ``{"cell_area": .., "tracker": {..}}``."""
    if unknown is CLUTTER_PER_PING:
        x0, x1, y0, y1 = SIM_CLUTTER["area"]
        lam = SIM_CLUTTER["pfa"] * (x1 - x0) * (y1 - y0) / SIM_CLUTTER["cell_area"]
        return {"clutter": {**SIM_CLUTTER, "cell_area": SIM_CLUTTER["cell_area"] * lam / float(value)},
                "tracker_changes": {}}
    m, n = (int(v) for v in str(value).split(" of "))
    return {"clutter": SIM_CLUTTER, "tracker_changes": {"confirm_hits": m, "confirm_window": n}}


def _unknown_prefix(unknown: DeclaredUnknown, value) -> str:
    label = f"{value:g}" if isinstance(value, float) else str(value).replace(" ", "")
    return f"unknown/{'clutter' if unknown is CLUTTER_PER_PING else 'mofn'}/{label}/"


def _unknown_key(unknown: DeclaredUnknown, value, block: int) -> str:
    """The task of one grid value and seed block (an unknown of :data:`GRID_IN_SIM` has none: see there)."""
    return f"{_unknown_prefix(unknown, value)}{block}"


#: The unknowns whose grid values change the tracker only, not the detections or the remover: their rows are tracked
#: inside the sim blocks on the block's own detections and removal (common random numbers: the same scans feed every
#: grid value), as extra rows ``unknown/mofn/<value>/paper/<phase>/`` of ``sim/<block>``, instead of tasks that
#: simulated and removed the same detections again.  The clutter per ping changes the detections: its grid values
#: keep tasks of their own (the target's detections are still the same, drawn first from each run's stream).
GRID_IN_SIM = (MOFN_WINDOW,)


PUBLISHED = {
    "removal_rate_simulation": 0.78,
    "removal_rate_sea_trial": 0.84,
    "definition": "false-track removal rate over 20 pings, from the per-ping track counts before and after removal "
                  "(the paper gives no formula; ours: the ratio of sums over runs and pings 6-20, docs/paper001.md)",
    "claim_before": "before removal: frequent false tracks and an unstable target track",
    "claim_after": "after removal: a few clutter tracks remain but the target track is continuous and stable",
}


NOTES = """\
Choices where paper 001 is silent (brief § 1.2-1.7; details, measured effects and the tuning rule in
docs/paper001.md):
- Scenario: target from (100, 100) at (4, 2) per ping, 20 pings, one straight leg; detections with
  P_D = 0.8, position noise 2.0, level 20 dB +- 0.1; clutter Poisson(5e-4 x 62 500 unit cells) = 31.25
  per ping, uniform on [0, 250]^2, Rayleigh levels with mean power 10 dB (stored, never thresholded).
  Sensor at the origin, T = 1 ping. Runs: quick 10; full 4 seed blocks of 50 (seeds s .. s+3) = 200.
- Primary rows (judged): CMKF-L with the paper's R (sigma_r = 0.5, sigma_b = 1 deg, math bearing) fed the
  polar view of each Cartesian detection; q = 0.01; the brief's track management: gate d2 <= 9.21 with the
  filter's R, greedy nearest neighbour, confirmation at 3 hits in 5 pings counted after initiation (the two
  initiation detections do not count), deletion after 3 misses; the paper's initial covariance P0 =
  blockdiag(R_c(z1), J diag(sigma_v^2, sigma_c^2) J^T) with its sigma_v = 1 (speed) and sigma_c = 1 rad (course).
  The previous round's two-point prior is an ablation row.
- The paper's M-of-N as it describes it (initiation detections counted as hits) with R matched to the sensor is
  a labelled row: the one with the paper's clutter tracks, drawn in Figs 5, 6, 9 and 10 (the judged paper
  rows have few).
- Declared unknowns (judged across their grids on the same runs): the clutter per ping (15.6, 31.25 primary,
  62.5) and the M-of-N confirmation (2 of 4, 3 of 5 primary, 4 of 6).
- Criterion 2's cap: the remover drops target detections after a missed ping (numbers in its detail).
- Hough remover: groups A = pings k-5..k-1, B = k-4..k; rectangular gate v_max = 8 per ping, reach 2 pings;
  bins 1 unit x 1 deg; peaks >= 3 distinct pings + 3x3 NMS; B peak needs a ping-k vote; similarity 3 units /
  3 deg modulo (rho, theta) = (-rho, theta + pi); a ping-k detection within 4 units of a similar line is kept
  when its latest LOCAL support on that line (a gated detection of the most recent earlier ping of B within
  v_max T max(gap, 2) of it) passes a velocity-consistency check (chi2_2 99 % with the stated accuracy 2.0).
  New measurements = the kept detections themselves (the paper: the extracted, clutter-removed
  measurements); projection onto the line is an ablation.
- Extra rows: the paper's M-of-N with matched R (above); the two-point prior (ablation); R from the sensor's
  stated accuracy (principled; the matched-R ablation); tuned gate and
  deletion (tuning runs only, rule in docs); the previous settings (ablation); a minimum-speed test (2 units
  per ping) against the surrogate's stationary clutter (extension).
- Warm-up: the first 5 pings (group A incomplete) produce no detections after removal. The removal rate is
  a ratio of sums over the runs and pings 6-20: 1 - (false tracks after) / (false tracks before), every
  false track counted (one after removal on a ping with none before lowers it); its interval is a paired
  bootstrap over runs. False tracks per ping before removal stand beside it (the population it is judged
  on); criterion 1 needs >= 150 false tracks before removal summed over the runs, else it is not judged.
  The variant over all 20 pings is shown beside it.
- True track: within 6 units of the truth for >= 80 % of its confirmed life. Continuity: share of pings
  from the first ping with a confirmed true track to ping 20 at which one is confirmed. RMSE: nearest
  confirmed true track; criterion 3 compares before/after on the (run, ping) pairs held in both.
- Every criterion: n runs, a 95 % interval (bootstrap over runs, or exact binomial) and a three-way verdict;
  the paper's 20-run protocol is repeated on disjoint batches of the reported runs (replications).
- Trackers compared (EXTENSION, not in the paper): GNN, JIPDA and GM-PHD (--trackers adds or removes any
  installed tracker) beside the paper's M-of-N rows, on the same runs before and after removal, each with the
  Kalman filter and R from the sensor's stated accuracy, P_D 0.8 where the tracker takes one, clutter density
  estimated per scan; scored by GOSPA, false tracks per ping and the share of pings the target is held.
- Sea trial: SYNTHETIC SURROGATE only (clutter x 2 plus 5 persistent sites re-detected w.p. 0.7), shipped as
  examples/data/sonar_sea_trial_surrogate.csv (one run, Figs 7-8, 11-12) and drawn as Monte Carlo runs.
"""


FIELDS = ("confirmed", "false", "held", "sq_error")


def motion_model():
    """CMKF-L motion: constant velocity, ``Q = q blockdiag([[T^4/4, T^3/2], [T^3/2, T^2]])``, q = 0.01."""
    return constant_velocity(2, DT, np.sqrt(Q_INTENSITY))


def target_truth(runs: int) -> Truth:
    """The paper's target for ``runs`` runs: start (100, 100), velocity (4, 2) per ping, 20 pings."""
    one = piecewise_trajectory(START, VELOCITY, [Leg("straight", (PINGS - 1) * DT)], DT)
    return Truth(np.repeat(one.states, runs, axis=0), one.times)


def simulate_scans(host: PluginHost, seed: int, scenario: str, runs: int, sites: bool = False,
                   clutter: Mapping | None = None):
    """Sensor plus clutter detections, run ``b`` from ``generator(seed, "paper001", scenario, b)``.

    With ``sites=True`` also returns the mask ``(runs, T, M)`` of the persistent clutter sites' detections (the
    clutter generator appends them after the uniform clutter of each run), for the metrics only.  ``clutter``
    replaces the scenario's clutter settings (a declared unknown's grid value); the target's detections of a run
    are drawn first from its stream, so they are the same whatever the clutter.
    """
    if clutter is None:
        clutter = SURROGATE_CLUTTER if scenario.startswith("surrogate") else SIM_CLUTTER
    sensor = host.sensor(SENSOR)
    gen = host.clutter_generator(CLUTTER_GEN)
    one = target_truth(1)
    parts, site_cols = [], []
    for b in range(runs):
        rng = generator(seed, "paper001", scenario, b)
        target = sensor.simulate(one, rng, **SONAR)
        cl = gen.generate(one, rng, **clutter)
        n_sites = int(clutter.get("persistent_sites", 0))
        first = target.z.shape[2] + cl.z.shape[2] - n_sites
        site_cols.append((first, first + n_sites))
        parts.append(target.merge(cl))
    M = max(p.z.shape[2] for p in parts)

    def pad(a, fill):
        return np.concatenate([a, np.full(a.shape[:2] + (M - a.shape[2],) + a.shape[3:], fill)], axis=2)

    scans = Scans(np.concatenate([pad(p.z, 0.0) for p in parts]),
                  np.concatenate([pad(p.valid, False) for p in parts]), one.times,
                  snr=np.concatenate([pad(p.snr, np.nan) for p in parts]),
                  origin=np.concatenate([pad(p.origin, CLUTTER) for p in parts]))
    if not sites:
        return scans
    mask = np.zeros(scans.valid.shape, dtype=bool)
    for b, (lo, hi) in enumerate(site_cols):
        mask[b, :, lo:hi] = True
    return scans, mask & scans.valid


def write_surrogate(path: Path = SURROGATE_FILE, seed: int = SURROGATE_SEED, host: PluginHost | None = None) -> Path:
    """Write the sea-trial SYNTHETIC SURROGATE CSV (one run) that ships in ``examples/data``."""
    if host is None:
        from workbench.plugins import load_host

        host = load_host()
    scans = simulate_scans(host, seed, "surrogate-file", 1)
    scans = Scans(scans.z, scans.valid, scans.times, snr=scans.snr)  # a recording has no origin labels
    comments = [
        f"{SURROGATE_LABEL}: a stand-in for the paper-001 sea trial (data unavailable).",
        "Generated by workbench_papers.paper001.scenario.write_surrogate(seed=%d): active-sonar target from (100,100) at "
        "(4,2) per ping, 20 pings, P_D 0.8, position noise 2.0, level 20 dB;" % seed,
        "clutter Poisson rate doubled (2 x 5e-4 x 62500 cells) uniform on [0,250]^2 with Rayleigh levels (10 dB), "
        "plus 5 persistent point-clutter sites re-detected with probability 0.7 per ping.",
        "Format: docs/recorded-data.md (section 'Active sonar detections'). Units: generic (same as x, y).",
    ]
    return write_sonar_csv(path, scans, comments=comments, digits=3)


def _file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16] if Path(path).is_file() else "missing"


def stated_accuracy(host: PluginHost) -> float:
    """The sensor's stated position accuracy per axis, as its declared Cartesian model publishes it (``std``)."""
    model = host.sensor(SENSOR).measurement_model(**SONAR, **MATCHED)
    return float(model.stated_std[0])


def _model_for(host: PluginHost, name: str) -> tuple[MeasurementModel, str]:
    """The sensor's polar model, unless the filter cannot take it (then its Cartesian model with the stated
    accuracy, recorded as ``model_used``)."""
    sensor = host.sensor(SENSOR)
    polar = sensor.measurement_model(**SONAR, **POLAR)
    filt = host.filter(name)
    probe = Gaussian(np.array([[100.0, 100.0, 4.0, 2.0]]), np.diag([10.0, 10.0, 4.0, 4.0])[None])
    try:
        rng = generator(0, "paper001", "probe")
        filt.update(filt.init(probe, rng), Scan(polar.h(probe.mean)[:, None, :], np.ones((1, 1), dtype=bool)),
                    polar, rng)
    except InputError:
        return sensor.measurement_model(**SONAR, **MATCHED), "cartesian, stated accuracy (no range-bearing input)"
    return polar, "polar (sigma_r=0.5, sigma_b=1 deg)"


def _tracker_config(host: PluginHost, arm: str, extra: Mapping | None = None) -> TrackerConfig:
    """The tracker settings of an arm (see the module docstring)."""
    base = TRACKER_PREVIOUS if arm == "previous" else TRACKER
    cfg = {**base, **(extra or {})}
    if arm in ("stated", "paper-mofn"):
        cfg["detection_sigma"] = stated_accuracy(host)
    if arm == "paper-mofn":
        cfg.update(PAPER_MOFN)
    if arm == "two-point":
        cfg.update(TWO_POINT)
    if arm == "min-speed":
        cfg["min_speed"] = MIN_SPEED
    return TrackerConfig(**cfg)


def _track(host: PluginHost, scans: Scans, filt: str, config: TrackerConfig, seed: int, key: tuple):
    model, used = _model_for(host, filt)
    log = run_tracker(scans, host.filter(filt), motion_model(), model, config, seed=seed, key=("paper001",) + key)
    truth_pos = target_truth(scans.batch).states[..., :2]
    return log, track_counts(log, truth_pos, TRUE_RADIUS, TRUE_FRACTION), used


def _gospa_arrays(prefix: str, log, truth_pos: np.ndarray) -> dict:
    """GOSPA (and its terms) of the confirmed tracks against the target, per run and ping, ``(B, T)`` each."""
    g = track_gospa(log, truth_pos, GOSPA_C, GOSPA_P)
    return {f"{prefix}gospa": g.distance, f"{prefix}gospa_loc": g.localisation, f"{prefix}gospa_missed": g.missed,
            f"{prefix}gospa_false": g.false}


def _counts_arrays(prefix: str, counts: TrackCounts) -> dict:
    return counts.to_arrays(prefix)


def _remover_stats(prefix: str, before: Scans, after: Scans, warm: int, sites: np.ndarray | None = None) -> dict:
    """Per run: target detections at pings >= ``warm`` and how many were kept, split by whether the target was
    detected at the previous ping; clutter (and persistent-site) detections and how many were kept."""
    o, v, kept = before.origin, before.valid, after.valid
    post = (np.arange(before.steps) >= warm)[None, :]
    tgt = (v & (o == 0)).any(axis=2)
    tgt_kept = (kept & (o == 0)).any(axis=2)
    prev = np.zeros_like(tgt)
    prev[:, 1:] = tgt[:, :-1]
    out = {}
    for name, sel in (("miss", tgt & post & ~prev), ("hit", tgt & post & prev)):
        out[f"{prefix}{name}_n"] = sel.sum(axis=1)
        out[f"{prefix}{name}_kept"] = (sel & tgt_kept).sum(axis=1)
    clu = v & (o == CLUTTER) & post[..., None]
    if sites is not None:
        out[f"{prefix}site_n"] = (sites & post[..., None]).sum(axis=(1, 2))
        out[f"{prefix}site_kept"] = (sites & kept & post[..., None]).sum(axis=(1, 2))
        clu &= ~sites
    out[f"{prefix}clutter_n"] = clu.sum(axis=(1, 2))
    out[f"{prefix}clutter_kept"] = (clu & kept).sum(axis=(1, 2))
    return out


def _run_zero(prefix: str, scans: Scans, kept: np.ndarray, log, truth_pos: np.ndarray) -> dict:
    """Detections and confirmed tracks of run 0 for the x-y figures."""
    v = scans.valid[0]
    ping = np.nonzero(v)[0]
    origin = scans.origin[0][v] if scans.origin is not None else np.full(ping.size, CLUTTER)
    runs, ids, _, is_true = track_truth_match(log, truth_pos, TRUE_RADIUS, TRUE_FRACTION)
    true_ids = ids[(runs == 0) & is_true]
    sel = (log.run == 0) & (log.status == CONFIRMED)
    return {f"{prefix}det_xy": scans.z[0][v], f"{prefix}det_ping": ping, f"{prefix}det_kept": kept[0][v],
            f"{prefix}det_target": origin == 0, f"{prefix}trk_ping": log.ping[sel], f"{prefix}trk_id": log.track_id[sel],
            f"{prefix}trk_xy": log.mean[sel, :2], f"{prefix}trk_true": np.isin(log.track_id[sel], true_ids),
            f"{prefix}truth_xy": truth_pos[0]}


def _warm(hough: Mapping) -> int:
    return int(hough["window"]) - 1 + int(hough["shift"])


ARM_LABELS = {
    "paper": "paper (brief's defaults, CMKF-L with the paper's R)",
    "stated": "principled: R from the sensor's stated accuracy (sigma 2.0)",
    "paper-mofn": "M-of-N as the paper describes it (initiation detections counted), R matched to the sensor "
                  "(sigma 2.0)",
    "two-point": "two-point initial covariance instead of the paper's sigma_v = sigma_c = 1 (ablation of the paper "
                 "rows)",
    "tuned": "tuned gate and deletion (tuning runs only)",
    "previous": "previous settings (global latest support, gate sigma 2, 4 misses, speed-course prior, "
                "initiation counted)",
}
