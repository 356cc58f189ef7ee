"""Paper 001: Hough-transform clutter removal and CMKF-L multi-target tracking, active sonar, heavy clutter.

Pipeline (brief § 1.1-1.4): the ``active-sonar`` sensor and the ``sonar-poisson`` clutter generator make
Cartesian detections ping by ping; the ``hough`` remover narrows them (or not: "before removal"); the
multi-target tracker :func:`workbench.tracking.run_tracker` runs the chosen filter (``cmkf-l`` by default,
fed the sensor's polar range-bearing view) with M-of-N track management; :mod:`workbench.metrics`
scores confirmed / false tracks, removal rates, continuity and RMSE against the truth.

Rows (*arms*), every one before and after removal on the same detections:

- ``paper`` (primary, judged): the brief's defaults (gate 9.21 with the filter's R, confirm 3 of 5 after
  initiation, delete after 3 misses), the paper's speed-course initial covariance with sigma_v = sigma_c = 1,
  CMKF-L with the paper's R;
- ``paper-mofn``: the paper's M-of-N as it describes it (the two initiation detections count as hits) with R
  matched to the sensor (its stated accuracy): the row with the paper's clutter tracks, drawn in Figs 5, 6, 9
  and 10;
- ``stated`` (principled variant): the same with every detection carrying the sensor's stated accuracy
  (``TrackerConfig.detection_sigma``, read from the sensor's declared model), so CMKF-L's R is that of the
  sensor (the brief's matched-R ablation, done through declared fields);
- ``tuned``: the gate and the deletion rule chosen on tuning runs only, by :data:`TUNING_RULE`;
- ``previous``: the previous settings (global latest-support rule, gate with sigma 2, deletion after 4 misses,
  speed-course prior, initiation detections counted as hits), kept reproducible as an ablation;
- ``min-speed`` (extension, sea-trial surrogate): the paper arm with a minimum-speed test on the tracks.

Runs: ``seeds`` blocks of ``runs`` runs, block ``j`` from seed ``seed + j``; run ``b`` of a block is drawn from
``generator(seed + j, "paper001", scenario, b)`` alone, so every arm, remover variant and size sees the same
detections (quick runs are the first runs of block 0).  Tuning runs come from the stream ``"tuning"``, which
no reported row uses.  The sea trial is not reproducible (data unavailable):
``examples/data/sonar_sea_trial_surrogate.csv`` is a SYNTHETIC SURROGATE written by :func:`write_surrogate`.
Choices where the paper is silent are in :data:`NOTES` and ``docs/paper001.md``.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import replace
from pathlib import Path
from typing import Mapping

import numpy as np

from workbench.criteria import DeclaredUnknown, Precondition, binomial_interval, \
    bootstrap_interval, criterion_from_counts, criterion_from_runs, judge_across, replication_rate, vectorised
from workbench.metrics import track_gospa

from workbench.metrics import (TrackCounts, continuity, false_track_sums, pooled_rmse, removal_rate_pooled_per_ping,
                               removal_ratio, track_counts, track_truth_match)
from workbench.models import MeasurementModel, constant_velocity
from workbench.params import parse_reference
from workbench.plugins import PluginHost
from workbench.report.engine import component_errors, component_failure
from workbench.recorded.sonar import load_sonar_csv, write_sonar_csv
from workbench.rng import generator
from workbench.specs import Criterion, FigureSpec, RecipeOptions, RecipeSpec, Table, TableSpec, Task, TaskContext
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


def _unknown_rows(results: Mapping, unknown: DeclaredUnknown, value, block: int) -> tuple[Mapping | None, str]:
    """Where the paper rows of one grid value and seed block are: ``(result, prefix)`` (``None`` where missing)."""
    if unknown in GRID_IN_SIM:
        return results.get(f"sim/{block}"), _unknown_prefix(unknown, value)
    return results.get(_unknown_key(unknown, value, block)), ""

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


# -- building blocks --------------------------------------------------------------------------------


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
        "Generated by workbench_papers.paper001.recipe.write_surrogate(seed=%d): active-sonar target from (100,100) at "
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


# -- tasks ------------------------------------------------------------------------------------------


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
                             f"(regenerate it with workbench_papers.paper001.recipe.write_surrogate())")
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
                                 **_unknown_changes(unknown, value)}, _unknown_task))
    out.append(Task("tuning", {**common, "seeds": seeds, "tuning_runs": int(v["tuning_runs"]),
                               "candidates": list(TUNING_CANDIDATES), "rule": TUNING_RULE}, _tuning_task))
    out.append(Task("surrogate", {**common, "source": "surrogate", "clutter": SURROGATE_CLUTTER,
                                  "min_speed": MIN_SPEED}, _surrogate_task))
    out.append(Task("file", {**common, "source": "file", "file": str(SURROGATE_FILE),
                             "digest": _file_digest(SURROGATE_FILE), "min_speed": MIN_SPEED}, _surrogate_task))
    out.append(Task("timing", {"hough": HOUGH, "tracker": TRACKER, "repeats": 5}, _timing_task))
    return out


# -- summaries from results -------------------------------------------------------------------------


def _blocks(results: Mapping) -> list[str]:
    keys = sorted((k for k in results if k.startswith("sim/")), key=lambda k: int(k.split("/")[1]))
    if not keys:
        raise InputError("paper 001: no simulation results (task sim/0 missing)")
    return keys


def _arm_counts(results: Mapping, arm: str, phase: str, blocks: list[str] | None = None) -> TrackCounts | None:
    """An arm's counts pooled over the seed blocks (``None`` if absent)."""
    parts = []
    for key in (blocks if blocks is not None else _blocks(results)):
        res = results[key]
        if arm == "tuned":
            block = key.split("/")[1]
            res, name = results.get("tuning", {}), f"block{block}/tuned/{phase}/"
        else:
            name = f"{arm}/{phase}/"
        if f"{name}confirmed" not in res:
            return None
        parts.append(TrackCounts.from_arrays(res, name))
    return TrackCounts(*(np.concatenate([getattr(c, f) for c in parts]) for f in FIELDS))


def _variant_keys(results: Mapping, variant: str) -> tuple[list[str], str]:
    """The results that hold a remover variant's rows, over the blocks with variant results, and the prefix of its
    rows there (its counts ``{prefix}{arm}/after/``, ``{prefix}first_output_ping``): the ``variants/<block>`` tasks,
    or the ``sim/<block>`` tasks for a variant of :data:`VARIANTS_IN_SIM`."""
    keys = sorted((k for k in results if k.startswith("variants/")), key=lambda k: int(k.split("/")[1]))
    if variant in VARIANTS_IN_SIM:
        return [f"sim/{k.split('/')[1]}" for k in keys], ""
    return keys, f"{variant}/"


def _variant_counts(results: Mapping, variant: str, arm: str) -> tuple[TrackCounts, TrackCounts, list[str], str] | None:
    """Before (the blocks' ``arm``) and after (the variant, tracked by ``arm``) over the blocks with variant
    results; the results that hold the variant's rows and their prefix (:func:`_variant_keys`)."""
    keys, prefix = _variant_keys(results, variant)
    if not keys or any(k not in results for k in keys) or f"{prefix}{arm}/after/confirmed" not in results[keys[0]]:
        return None
    blocks = [f"sim/{k.split('/')[1]}" for k in keys]
    before = _arm_counts(results, arm, "before", blocks)
    after = [TrackCounts.from_arrays(results[k], f"{prefix}{arm}/after/") for k in keys]
    after = TrackCounts(*(np.concatenate([getattr(c, f) for c in after]) for f in FIELDS))
    return before, after, keys, prefix


def _post(results: Mapping, T: int, key: str | None = None) -> np.ndarray:
    res = results[key or _blocks(results)[0]]
    return np.arange(T) >= int(res["first_output_ping"])


def _masked_sq(b: TrackCounts, a: TrackCounts) -> tuple[np.ndarray, np.ndarray]:
    """Squared errors before and after on the (run, ping) pairs held in both (NaN elsewhere)."""
    both = b.held & a.held
    return np.where(both, b.sq_error, np.nan), np.where(both, a.sq_error, np.nan)


def _rmse_diff_one(sq_b: np.ndarray, sq_a: np.ndarray) -> float:
    """Pooled RMSE after minus before (pairs held in both); NaN when no pair."""
    return pooled_rmse(sq_a) - pooled_rmse(sq_b)


def _rmse_diff_many(counts: np.ndarray, sq_b: np.ndarray, sq_a: np.ndarray) -> np.ndarray:
    """:func:`_rmse_diff_one` of every resample, from each run's sum and count of finite squared errors weighted by
    the resample counts ``(resamples, runs)`` (no copy of the runs x pings arrays per resample)."""
    rmse = []
    for sq in (sq_a, sq_b):
        sq = sq.reshape(sq.shape[0], -1)
        finite = np.isfinite(sq)
        total = counts @ np.where(finite, sq, 0.0).sum(axis=1)
        held = counts @ finite.sum(axis=1).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            rmse.append(np.where(held > 0, np.sqrt(total / np.maximum(held, 1.0)), np.nan))
    return rmse[0] - rmse[1]


#: The statistic of criterion 3 and the rows table, declared with its batched form for the bootstrap.
_rmse_diff = vectorised(_rmse_diff_one, _rmse_diff_many, given="counts")


def _removal_ratio_many(counts: np.ndarray, sum_before: np.ndarray, sum_after: np.ndarray) -> np.ndarray:
    """:func:`removal_ratio` of every resample: the resampled sums as counts-weighted sums (exact for counts)."""
    den = counts @ np.asarray(sum_before, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, 1.0 - (counts @ np.asarray(sum_after, dtype=float)) / den, np.nan)


#: :func:`removal_ratio` declared with its batched form for the bootstrap.
_removal_ratio = vectorised(removal_ratio, _removal_ratio_many, given="counts")


def summary(before: TrackCounts, after: TrackCounts, post: np.ndarray) -> dict:
    """Removal rates, continuity and RMSE of one before/after pair, per run and pooled.

    The removal rates are held as their paired per-run sums ``(before (B,), after (B,))`` (see
    :func:`workbench.metrics.false_track_sums`): ``rate`` (false tracks, pings in ``post``), ``rate_all`` (all
    pings) and ``rate_total`` (confirmed tracks, pings in ``post``); ``false_before_runs (B,)`` is each run's mean
    number of false tracks per ping before removal over ``post``.
    """
    rate = false_track_sums(before.false, after.false, post)
    cont_b, cont_a = continuity(before.held), continuity(after.held)
    sq_b, sq_a = _masked_sq(before, after)
    return {
        "rate": rate, "rate_all": false_track_sums(before.false, after.false),
        "rate_total": false_track_sums(before.confirmed, after.confirmed, post),
        "false_before_runs": before.false[:, post].mean(axis=1), "false_before_sum": int(rate[0].sum()),
        "cont_before": cont_b, "cont_after": cont_a,
        "held80_before": int(np.sum(cont_b >= TRUE_FRACTION)), "held80_after": int(np.sum(cont_a >= TRUE_FRACTION)),
        "rmse_before": pooled_rmse(sq_b), "rmse_after": pooled_rmse(sq_a), "pairs": int(np.isfinite(sq_a).sum()),
        "sq_before": sq_b, "sq_after": sq_a,
        "false_after": float(after.false[:, post].mean()),
        "runs": int(before.false.shape[0]),
    }


def _rate_text(sums: tuple[np.ndarray, np.ndarray]) -> str:
    """The ratio of sums of a paired per-run sample ``(before, after)`` with its bootstrap interval over runs."""
    value = removal_ratio(*sums)
    if not np.isfinite(value):
        return "n/a (no false track before removal)"
    lo, hi = bootstrap_interval(sums, _removal_ratio)
    if not np.isfinite(lo):
        return f"{100 * value:.1f} %"
    return f"{100 * value:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def _per_ping_text(per_run: np.ndarray) -> str:
    """The mean over runs of per-run values (false tracks per ping) with its bootstrap interval over runs."""
    if per_run.size == 0:
        return "n/a"
    lo, hi = bootstrap_interval(per_run)
    if not np.isfinite(lo):
        return f"{per_run.mean():.2f}"
    return f"{per_run.mean():.2f} [{lo:.2f}, {hi:.2f}]"


def _share_text(k: int, n: int) -> str:
    if n == 0:
        return "n/a"
    lo, hi = binomial_interval(k, n)
    return f"{100 * k / n:.0f} % ({k}/{n}) [{100 * lo:.0f}, {100 * hi:.0f}]"


def _f(x, digits=2) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _kept_text(res: Mapping, prefix: str, name: str) -> str:
    n, k = res.get(f"{prefix}{name}_n"), res.get(f"{prefix}{name}_kept")
    if n is None or int(np.sum(n)) == 0:
        return "n/a"
    return f"{100 * np.sum(k) / np.sum(n):.1f} % (n={int(np.sum(n))})"


def _pooled_stats(results: Mapping, keys: list[str], prefix: str) -> dict:
    out: dict = {}
    for key in keys:
        for name, value in results[key].items():
            if name.startswith(prefix):
                out[name] = np.concatenate([out[name], np.atleast_1d(value)]) if name in out else np.atleast_1d(value)
    return out


# -- figures ----------------------------------------------------------------------------------------


def _fig3_data(results):
    d = results["hough-demo"]
    return {"points": d["points"], "point_ping": d["point_ping"], "point_target": d["point_target"],
            "line": _demo_line(d), "true_line": d["true_line"]}


def _demo_line(d) -> np.ndarray:
    """The similar line closest to the true line, ``(rho, theta)`` (NaNs if none)."""
    sim = np.asarray(d["similar"]).reshape(-1, 2)
    if sim.shape[0] == 0:
        return np.array([np.nan, np.nan])
    rho0, th0 = d["true_line"]
    dth = np.abs(sim[:, 1] - th0)
    flip = dth > np.pi / 2
    dr = np.where(flip, np.abs(sim[:, 0] + rho0), np.abs(sim[:, 0] - rho0))
    dth = np.where(flip, np.pi - dth, dth)
    return sim[np.argmin(dr + np.rad2deg(dth))]


def _draw_line(ax, rho, theta, **kw):
    # points on x cos(theta) + y sin(theta) = rho
    c, s = np.cos(theta), np.sin(theta)
    foot = np.array([rho * c, rho * s])
    t = np.linspace(-200, 200, 2)
    ax.plot(foot[0] - t * s, foot[1] + t * c, **kw)


def _fig3_draw(data, fig):
    ax = fig.add_subplot(1, 1, 1)
    pts, tgt = data["points"], data["point_target"].astype(bool)
    ax.scatter(pts[~tgt, 0], pts[~tgt, 1], s=12, c="0.6", label="clutter")
    ax.scatter(pts[tgt, 0], pts[tgt, 1], s=30, c="C3", label="target (5 pings)")
    rho, theta = data["line"]
    if np.isfinite(rho):
        _draw_line(ax, rho, theta, color="C0", lw=1.2, label=f"line rho={rho:.0f}, theta={np.rad2deg(theta):.0f} deg")
        ax.plot([0, rho * np.cos(theta)], [0, rho * np.sin(theta)], "C0--", lw=0.8)
        ax.annotate("rho", (0.5 * rho * np.cos(theta), 0.5 * rho * np.sin(theta)), color="C0")
    ax.set(xlim=(0, 250), ylim=(0, 250), xlabel="x (units)", ylabel="y (units)", aspect="equal",
           title="Fig 3: x-y space; rho = x cos(theta) + y sin(theta)")
    ax.legend(fontsize=7, loc="upper left")


def _fig4_data(results):
    d = results["hough-demo"]
    theta = d["theta_axis"]
    pts = d["points"]
    # eq 1 for every point: its sinusoid rho(theta)
    sinus = pts[:, :1] * np.cos(theta) + pts[:, 1:2] * np.sin(theta)
    peak = _demo_line(d)
    ra = np.asarray(d["rho_axis"])
    centre = peak[0] if np.isfinite(peak[0]) else 0.0
    rows = np.flatnonzero(np.abs(ra - centre) <= 80.0)  # the accumulator around the peak
    lo, hi = rows.min(), rows.max() + 1
    return {"theta_deg": np.rad2deg(theta), "sinusoids": sinus, "point_target": d["point_target"],
            "rho_axis": ra[lo:hi], "support": d["support"][lo:hi], "peak": peak}


def _fig4_draw(data, fig):
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    th = data["theta_deg"]
    tgt = data["point_target"].astype(bool)
    for curve, is_t in zip(data["sinusoids"], tgt):
        ax1.plot(th, curve, color="C3" if is_t else "0.7", lw=1.2 if is_t else 0.6)
    rho, theta = data["peak"]
    for ax in (ax1, ax2):
        if np.isfinite(rho):
            ax.plot(np.rad2deg(theta), rho, "o", mfc="none", mec="C0", ms=12, mew=1.5)
    ax1.set(xlabel="theta (deg)", ylabel="rho (units)", title="sinusoids (target red, clutter grey)")
    ra = data["rho_axis"]
    im = ax2.imshow(data["support"], aspect="auto", origin="lower", cmap="viridis",
                    extent=(th[0], th[-1] + (th[1] - th[0]), ra[0], ra[-1]))
    fig.colorbar(im, ax=ax2, label="distinct pings voting (group B)")
    ax2.set(xlabel="theta (deg)", ylabel="rho (units)", title="accumulator; circle = similar peak")
    fig.suptitle("Fig 4: Hough parameter space", fontsize=10)


def _xy_data(task: str, phase: str):
    def data(results):
        d = results[task]
        p = f"fig/{phase}/"
        out = {k: d[p + k] for k in ("det_xy", "det_ping", "det_target", "det_kept", "trk_ping", "trk_id", "trk_xy",
                                     "trk_true", "truth_xy")}
        out["removed"] = np.array(phase == "after")
        return out
    return data


def _xy_draw(title: str):
    def draw(data, fig):
        ax = fig.add_subplot(1, 1, 1)
        xy, kept = data["det_xy"], data["det_kept"].astype(bool)
        if (~kept).any():
            ax.scatter(xy[~kept, 0], xy[~kept, 1], s=3, c="0.85", label="removed detections")
        ax.scatter(xy[kept, 0], xy[kept, 1], s=4, c="0.35", label="detections (all pings)")
        txy, true = data["trk_xy"], data["trk_true"].astype(bool)
        ax.scatter(txy[~true, 0], txy[~true, 1], s=22, facecolors="none", edgecolors="C0", lw=0.8,
                   label="confirmed false tracks")
        ax.scatter(txy[true, 0], txy[true, 1], s=30, facecolors="none", edgecolors="C3", lw=1.2,
                   label="confirmed target track")
        ax.plot(data["truth_xy"][:, 0], data["truth_xy"][:, 1], "k-", lw=0.8, label="truth")
        ax.set(xlim=(0, 250), ylim=(0, 250), xlabel="x (units)", ylabel="y (units)", aspect="equal", title=title)
        ax.legend(fontsize=7, loc="upper left")
    return draw


def _count_data(source: str, phase: str):
    def data(results):
        if source == "sim":
            blocks = _blocks(results)[:1]
            c = _arm_counts(results, FIG_ARM, phase, blocks)
            others = {arm: _arm_counts(results, arm, phase, blocks) for arm in ("paper", "stated", "previous")}
        else:
            c, others = TrackCounts.from_arrays(results[source], f"paper/{phase}/"), {}
        out = {"ping": np.arange(1, c.confirmed.shape[1] + 1), "run0": c.confirmed[0],
               "run0_false": c.false[0], "mean": c.confirmed.mean(axis=0),
               "q10": np.quantile(c.confirmed, 0.1, axis=0), "q90": np.quantile(c.confirmed, 0.9, axis=0),
               "false_mean": c.false.mean(axis=0), "runs": np.array(c.confirmed.shape[0])}
        for arm, counts in others.items():
            if counts is not None:
                out[f"{arm}_mean"] = counts.confirmed.mean(axis=0)
        return out
    return data


def _count_draw(title: str):
    def draw(data, fig):
        ax = fig.add_subplot(1, 1, 1)
        ax.bar(data["ping"], data["run0"], color="0.75", label="run 0: confirmed tracks")
        ax.bar(data["ping"], data["run0_false"], color="C0", width=0.4, label="run 0: false tracks")
        runs = int(data["runs"])
        if runs > 1:
            ax.fill_between(data["ping"], data["q10"], data["q90"], color="C3", alpha=0.15, step="mid",
                            label=f"10-90 % of {runs} runs")
            ax.plot(data["ping"], data["mean"], "C3.-", lw=1, label=f"mean over {runs} runs (drawn row)")
        for arm, style, label in (("paper", "C4-.", "mean, paper rows (judged)"),
                                  ("stated", "C2--", "mean, R from the stated accuracy"),
                                  ("previous", "C1:", "mean, previous settings")):
            if f"{arm}_mean" in data:
                ax.plot(data["ping"], data[f"{arm}_mean"], style, lw=1, label=label)
        ax.set(xlabel="ping", ylabel="confirmed tracks (count)", title=title, xticks=data["ping"])
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
    return draw


SUR = "[SYNTHETIC SURROGATE, not sea-trial data] "
FIGURES = (
    FigureSpec("fig3", "A line in x-y space and its normal form (rho, theta); demo scene of 5 pings.",
               _fig3_data, _fig3_draw, size=(6.0, 6.0)),
    FigureSpec("fig4", "Hough space: sinusoids of the target points meet at one (rho, theta); clutter does not.",
               _fig4_data, _fig4_draw, size=(11.0, 4.5)),
    FigureSpec("fig5", "Simulation, run 0, before clutter removal: detections of 20 pings and confirmed tracks of the "
               "row 'M-of-N as the paper describes it (initiation detections counted), R matched to the sensor', the "
               "row with the paper's clutter tracks (the judged paper rows have few).", _xy_data("sim/0", "before"),
               _xy_draw("Fig 5: simulation, before removal (paper's M-of-N, matched R)"), size=(6.4, 6.4)),
    FigureSpec("fig6", "Simulation, run 0, after Hough clutter removal (removed detections light grey); the same row "
               "as Fig 5 (M-of-N as the paper describes it, initiation detections counted, R matched to the sensor).",
               _xy_data("sim/0", "after"), _xy_draw("Fig 6: simulation, after removal (paper's M-of-N, matched R)"),
               size=(6.4, 6.4)),
    FigureSpec("fig7", SUR + "Sea-trial surrogate file, before clutter removal.",
               _xy_data("file", "before"), _xy_draw("Fig 7: SURROGATE (synthetic), before removal"), size=(6.4, 6.4)),
    FigureSpec("fig8", SUR + "Sea-trial surrogate file, after clutter removal.",
               _xy_data("file", "after"), _xy_draw("Fig 8: SURROGATE (synthetic), after removal"), size=(6.4, 6.4)),
    FigureSpec("fig9", "Confirmed tracks per ping, simulation, before removal, row 'M-of-N as the paper describes it "
               "(initiation detections counted), R matched to the sensor' (run 0 bars; mean and 10-90 % band over the first seed "
               "block; the judged paper rows' and the other rows' means for comparison).", _count_data("sim", "before"),
               _count_draw("Fig 9: simulation, before removal (paper's M-of-N, matched R)")),
    FigureSpec("fig10", "Confirmed tracks per ping, simulation, after removal, the same row as Fig 9 (pings 1-5 are the "
               "warm-up).", _count_data("sim", "after"),
               _count_draw("Fig 10: simulation, after removal (paper's M-of-N, matched R)")),
    FigureSpec("fig11", SUR + "Confirmed tracks per ping, surrogate file, before removal.",
               _count_data("file", "before"), _count_draw("Fig 11: SURROGATE (synthetic), before removal")),
    FigureSpec("fig12", SUR + "Confirmed tracks per ping, surrogate file, after removal.",
               _count_data("file", "after"), _count_draw("Fig 12: SURROGATE (synthetic), after removal")),
)


# -- tables -----------------------------------------------------------------------------------------


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


def _arms_in(results: Mapping, tuned: bool = True) -> list[str]:
    """The arms with rows in every seed block (an arm whose filter raised in any block is left out here and
    marked FAILED by :func:`_failed_rows`): the paper's own arms (the tuned one only with ``tuned``), then any
    added ``filter:`` arm."""
    arms = [a for a in ARM_LABELS if (tuned or a != "tuned") and _arm_counts(results, a, "after") is not None]
    added = {k.split("/")[0] for key in _blocks(results) for k in results[key]
             if k.startswith("filter:") and k.endswith("/after/confirmed")}
    arms += sorted(a for a in added if _arm_counts(results, a, "after") is not None)
    return arms


def _failed_arms(results: Mapping) -> dict[str, str]:
    """``{arm: "RuntimeError: ..."}`` of the arms whose filter raised in a simulation block (their rows are left
    out; the report names the failure in the paper's errors too)."""
    failed: dict[str, str] = {}
    for key in (k for k in results if k.startswith("sim/")):
        for arm, message in component_errors(results[key]):
            failed.setdefault(arm, f"{key}: {message}")
    return failed


def _failed_rows(results: Mapping, width: int, lead: tuple = ()) -> list[tuple]:
    """One marked row per failed arm: ``lead``, the arm, ``FAILED: <error>``, blanks up to ``width`` columns."""
    return [(*lead, arm, f"FAILED, no rows: {msg}", *([""] * (width - len(lead) - 2)))
            for arm, msg in sorted(_failed_arms(results).items())]


def _tuned_label(results: Mapping) -> str:
    t = results.get("tuning")
    if t is None:
        return ARM_LABELS["tuned"]
    cand = TUNING_CANDIDATES[int(t["tuning/chosen"])]
    gate = "filter's R" if cand["gate_sigma"] is None else f"sigma {cand['gate_sigma']:g}"
    return f"tuned (tuning runs only): gate with {gate}, delete after {cand['delete_misses']} misses"


def _removal_table(results) -> Table:
    rows = []
    blocks = _blocks(results)
    T = results[blocks[0]]["paper/before/false"].shape[1]
    post = _post(results, T)
    for arm in _arms_in(results):
        s = summary(_arm_counts(results, arm, "before"), _arm_counts(results, arm, "after"), post)
        label = _tuned_label(results) if arm == "tuned" else ARM_LABELS.get(arm, f"{arm}, brief's defaults")
        rows.append(("simulation", label, f"{100 * PUBLISHED['removal_rate_simulation']:.0f} %", _rate_text(s["rate"]),
                     _rate_text(s["rate_all"]), _rate_text(s["rate_total"]), _per_ping_text(s["false_before_runs"]),
                     _f(s["false_after"], 2), s["false_before_sum"], s["runs"]))
    rows += _failed_rows(results, 10, ("simulation",))
    for task, label in (("surrogate", "sea-trial surrogate, Monte Carlo (SYNTHETIC)"),
                        ("file", "sea-trial surrogate file, one run (SYNTHETIC)")):
        if task not in results:
            continue
        res = results[task]
        post_s = np.arange(T) >= int(res["first_output_ping"])
        b = TrackCounts.from_arrays(res, "paper/before/")
        for arm, arm_label in (("paper", ARM_LABELS["paper"]),
                               ("min-speed", f"EXTENSION: paper + minimum-speed test ({MIN_SPEED:g} units/ping)")):
            s = summary(b, TrackCounts.from_arrays(res, f"{arm}/after/"), post_s)
            rows.append((label, arm_label, f"{100 * PUBLISHED['removal_rate_sea_trial']:.0f} %", _rate_text(s["rate"]),
                         _rate_text(s["rate_all"]), _rate_text(s["rate_total"]), _per_ping_text(s["false_before_runs"]),
                         _f(s["false_after"], 2), s["false_before_sum"], s["runs"]))
    return Table(("case", "row", "published removal rate",
                  "ours: 1 - sum F_after / sum F_before (false tracks, runs x pings 6-20) [95 % CI]",
                  "ours incl. warm-up pings", "ours, total tracks", "false tracks/ping before (pings 6-20) [95 % CI]",
                  "false tracks/ping after", "false tracks before, summed", "runs"), tuple(rows))


def _per_ping_table(results) -> Table:
    b, a = _arm_counts(results, "paper", "before"), _arm_counts(results, "paper", "after")
    r = removal_rate_pooled_per_ping(b.false, a.false)
    none_before = b.false == 0
    rows = []
    for k in range(b.false.shape[1]):
        n = int(np.sum(b.false[:, k] > 0))
        rows.append((k + 1, _f(b.false[:, k].mean()), _f(a.false[:, k].mean()),
                     "n/a" if not np.isfinite(r[k]) else f"{100 * r[k]:.1f} %", n,
                     int(np.sum(a.false[:, k][none_before[:, k]]))))
    post = _post(results, b.false.shape[1])
    s = summary(b, a, post)
    rows.append(("pings 6-20", _per_ping_text(s["false_before_runs"]), _f(a.false[:, post].mean()),
                 _rate_text(s["rate"]), int(np.sum(b.false[:, post] > 0)),
                 int(np.sum(a.false[:, post][none_before[:, post]]))))
    return Table(("ping", "false tracks before (mean per run)", "false tracks after (mean per run)",
                  "removal rate 1 - sum F_after / sum F_before over the runs",
                  "runs with a false track before (last row: run-pings)",
                  "false tracks after removal in runs with none before at that ping (they lower the rate)"), tuple(rows))


def _rows_table(results) -> Table:
    """Every arm: removal rate, criterion 2's share and criterion 3's RMSE, with intervals."""
    blocks = _blocks(results)
    T = results[blocks[0]]["paper/before/false"].shape[1]
    post = _post(results, T)
    rows = []
    for arm in _arms_in(results):
        s = summary(_arm_counts(results, arm, "before"), _arm_counts(results, arm, "after"), post)
        diff_ci = bootstrap_interval((s["sq_before"], s["sq_after"]), _rmse_diff)
        label = _tuned_label(results) if arm == "tuned" else ARM_LABELS.get(arm, arm)
        rows.append((label, _rate_text(s["rate"]), _per_ping_text(s["false_before_runs"]),
                     _share_text(s["held80_before"], s["runs"]),
                     _share_text(s["held80_after"], s["runs"]),
                     f"{_f(s['rmse_before'])} / {_f(s['rmse_after'])}",
                     f"{_f(s['rmse_after'] - s['rmse_before'])} [{_f(diff_ci[0])}, {_f(diff_ci[1])}]",
                     s["pairs"], s["runs"]))
    rows += _failed_rows(results, 9)
    return Table(("row", "removal rate, ratio of sums [95 % CI] (criterion 1)",
                  "false tracks/ping before removal [95 % CI]", "runs holding the target >= 80 %, before [CI]",
                  "after removal [CI] (criterion 2)", "RMSE before / after (paired pings)",
                  "RMSE after - before [CI] (criterion 3)", "paired pings", "runs"), tuple(rows))


def _gospa_stats(results: Mapping, arm: str, phase: str) -> dict | None:
    """Per-run means over the pings after the warm-up of GOSPA and its terms, pooled over the seed blocks."""
    blocks = _blocks(results)
    if any(f"{arm}/{phase}/gospa" not in results[key] for key in blocks):  # the arm failed in some block
        return None
    out = {}
    for term in ("gospa", "gospa_loc", "gospa_missed", "gospa_false"):
        runs = []
        for key in blocks:
            values = np.asarray(results[key][f"{arm}/{phase}/{term}"], dtype=float)
            post = _post(results, values.shape[1], key)
            runs.append(values[:, post].mean(axis=1))
        out[term] = np.concatenate(runs)
    return out


def _gospa_table(results) -> Table:
    """GOSPA (c = 10, p = 2) of every arm before and after removal: the distance (mean over runs and pings after the
    warm-up, 95 % bootstrap interval over runs) and its terms (localisation, missed, false; in units^2)."""
    rows = []
    for arm in _arms_in(results):
        label = _tuned_label(results) if arm == "tuned" else ARM_LABELS.get(arm, arm)
        for phase in ("before", "after"):
            g = _gospa_stats(results, arm, phase)
            if g is None:
                continue
            lo, hi = bootstrap_interval(g["gospa"])
            rows.append((label, phase, f"{_f(g['gospa'].mean())} [{_f(lo)}, {_f(hi)}]", _f(g["gospa_loc"].mean()),
                         _f(g["gospa_missed"].mean()), _f(g["gospa_false"].mean()), g["gospa"].size))
    return Table(("row", "removal", "GOSPA [95 % CI]", "localisation", "missed", "false", "runs"), tuple(rows))


def _gospa_data(results):
    """GOSPA per ping (mean over runs) of the paper rows before and after removal, with its false-track term."""
    blocks = _blocks(results)
    out = {}
    for phase in ("before", "after"):
        stack = np.concatenate([np.asarray(results[k][f"paper/{phase}/gospa"], dtype=float) for k in blocks])
        false = np.concatenate([np.asarray(results[k][f"paper/{phase}/gospa_false"], dtype=float) for k in blocks])
        out[f"gospa_{phase}"] = stack.mean(axis=0)
        out[f"false_{phase}"] = np.sqrt(np.maximum(false.mean(axis=0), 0.0))
    out["ping"] = np.arange(out["gospa_before"].size)
    out["first_output_ping"] = np.array(int(results[blocks[0]]["first_output_ping"]))
    out["c"] = np.array(GOSPA_C)
    return out


def _gospa_draw(data, fig):
    ax = fig.add_subplot()
    ax.plot(data["ping"], data["gospa_before"], "o-", color="tab:red", label="GOSPA before removal")
    ax.plot(data["ping"], data["gospa_after"], "s-", color="tab:blue", label="GOSPA after removal")
    ax.plot(data["ping"], data["false_before"], ":", color="tab:red", label="its false-track part (root), before")
    ax.plot(data["ping"], data["false_after"], ":", color="tab:blue", label="its false-track part (root), after")
    ax.axvline(float(data["first_output_ping"]) - 0.5, color="0.6", lw=0.8)
    ax.axhline(float(data["c"]) / np.sqrt(2.0), color="0.3", ls="--", lw=0.8, label="one missed target (c / sqrt 2)")
    ax.set_xlabel("ping")
    ax.set_ylabel("GOSPA (c = 10, p = 2), position units")
    ax.legend(fontsize=7)


FIGURES = FIGURES + (
    FigureSpec("gospa-per-ping", "GOSPA of the confirmed tracks per ping (mean over runs), paper rows, before and after Hough "
               "removal; the dotted lines are its false-track part (the line marks the end of the warm-up).",
               _gospa_data, _gospa_draw),
)


# -- the trackers compared (issue 25): the paper's M-of-N rows and the extension rows ------------------------------


def _tracker_blocks(results: Mapping) -> list[str]:
    return sorted((k for k in results if k.startswith("trackers/")), key=lambda k: int(k.split("/")[1]))


def tracker_order(results: Mapping) -> list[str]:
    """The trackers compared, in ``RecipeOptions.trackers`` order (empty when the report compares none)."""
    keys = _tracker_blocks(results)
    return [str(t) for t in np.atleast_1d(results[keys[0]]["order"])] if keys else []


def comparison_rows(results: Mapping) -> list[tuple[str, str, str, tuple[str, str]]]:
    """``(reference, label, kind, source)`` of every row of the tracker comparison: the paper's ``"mofn"`` gives
    two rows read from the simulation blocks' arms (``("arm", "paper")``: the judged rows; ``("arm", "stated")``:
    the same M-of-N with the extension rows' R), any other reference one EXTENSION row from the ``trackers/``
    blocks (``("tracker", reference)``)."""
    rows = []
    for ref in tracker_order(results):
        if ref == PAPER_TRACKER:
            rows.append((ref, "M-of-N, " + ARM_LABELS["paper"], "paper's method (judged rows)", ("arm", "paper")))
            rows.append((ref, "M-of-N, " + ARM_LABELS["stated"] + ": the extension rows' R", "paper's method, "
                         "principled R (not judged)", ("arm", "stated")))
        else:
            rows.append((ref, f"{ref}, Kalman filter with R from the sensor's stated accuracy (sigma 2.0)",
                         "EXTENSION (not in the paper)", ("tracker", ref)))
    return rows


def comparison_series(results: Mapping, source: tuple[str, str], phase: str) -> tuple[TrackCounts, np.ndarray] | None:
    """A comparison row's counts and GOSPA ``(B, T)`` at ``phase``, pooled over the seed blocks (``None`` where the
    row failed in a block or is absent)."""
    kind, name = source
    keys, prefix = ((_blocks(results), f"{name}/{phase}/") if kind == "arm"
                    else (_tracker_blocks(results), _tracker_prefix(name, phase)))
    if not keys or any(f"{prefix}gospa" not in results[k] or f"{prefix}confirmed" not in results[k] for k in keys):
        return None
    parts = [TrackCounts.from_arrays(results[k], prefix) for k in keys]
    counts = TrackCounts(*(np.concatenate([getattr(c, f) for c in parts]) for f in FIELDS))
    return counts, np.concatenate([np.asarray(results[k][f"{prefix}gospa"], dtype=float) for k in keys])


def _tracker_post(results: Mapping, T: int) -> np.ndarray:
    """The pings after the Hough warm-up (the paper rows' and the extension rows' warm-up are the same)."""
    keys = [k for k in results if k.startswith("sim/")] or _tracker_blocks(results)
    return np.arange(T) >= int(results[keys[0]]["first_output_ping"])


def _failed_trackers(results: Mapping) -> dict[str, str]:
    failed: dict[str, str] = {}
    for key in _tracker_blocks(results):
        for what, message in component_errors(results[key]):
            if what.startswith("tracker:"):
                failed.setdefault(what[len("tracker:"):], f"{key}: {message}")
    return failed


def _mean_text(per_run: np.ndarray, scale: float = 1.0, digits: int = 2, unit: str = "") -> str:
    """The mean over runs of per-run values with its 95 % bootstrap interval over runs."""
    if per_run.size == 0:
        return "n/a"
    lo, hi = bootstrap_interval(per_run) if per_run.size > 1 else (np.nan, np.nan)
    mean = f"{scale * per_run.mean():.{digits}f}{unit}"
    return mean if not np.isfinite(lo) else f"{mean} [{scale * lo:.{digits}f}, {scale * hi:.{digits}f}]"


def tracker_stats(counts: TrackCounts, gospa: np.ndarray, post: np.ndarray) -> dict:
    """Per run over the pings in ``post``: mean GOSPA, false tracks per ping and the share of pings at which a
    confirmed true track holds the target; and each run's continuity (criterion 2's statistic)."""
    return {"gospa": gospa[:, post].mean(axis=1), "false": counts.false[:, post].mean(axis=1),
            "held": counts.held[:, post].mean(axis=1), "continuity": continuity(counts.held)}


def _trackers_table(results) -> Table:
    """Every tracker compared, before and after removal on the same runs: GOSPA, false tracks per ping, the share of
    pings the target is held (each a mean over runs of per-run means over the pings after the warm-up, 95 %
    bootstrap interval over runs), runs holding the target >= 80 % (exact binomial interval) and the removal rate
    (ratio of sums, paired bootstrap)."""
    rows = []
    for ref, label, kind, source in comparison_rows(results):
        got = {phase: comparison_series(results, source, phase) for phase in ("before", "after")}
        if got["before"] is None or got["after"] is None:
            continue
        post = _tracker_post(results, got["before"][1].shape[1])
        for phase in ("before", "after"):
            counts, gospa = got[phase]
            st = tracker_stats(counts, gospa, post)
            rate = ("-" if phase == "before" else
                    _rate_text(false_track_sums(got["before"][0].false, counts.false, post)))
            rows.append((ref, label, kind, phase, _mean_text(st["gospa"]), _mean_text(st["false"]),
                         _mean_text(st["held"], 100.0, 1, " %"),
                         _share_text(int(np.sum(st["continuity"] >= TRUE_FRACTION)), st["continuity"].size), rate,
                         st["gospa"].size))
    rows += [(ref, f"FAILED, no rows: {msg}", "EXTENSION (not in the paper)", *([""] * 7))
             for ref, msg in sorted(_failed_trackers(results).items())]
    return Table(("tracker", "row", "kind", "removal", "GOSPA (c = 10, p = 2) per ping [95 % CI]",
                  "false tracks/ping [95 % CI]", "share of pings the target is held [95 % CI]",
                  "runs holding the target >= 80 % of the pings after initiation [CI]",
                  "removal rate, ratio of sums [95 % CI]", "runs"), tuple(rows))


def _trackers_gospa_data(results):
    """GOSPA per ping (mean over runs) of every comparison row, before and after removal: ``rows`` (the row
    labels: the reference, ``mofn`` twice as ``mofn (paper rows)`` and ``mofn (stated R)``), ``gospa_before`` and
    ``gospa_after`` ``(rows, T)``."""
    names, before, after = [], [], []
    T = None
    for ref, _, _, source in comparison_rows(results):
        b, a = comparison_series(results, source, "before"), comparison_series(results, source, "after")
        if b is None or a is None:
            continue
        names.append(ref if source[0] == "tracker" else f"{ref} ({'paper rows' if source[1] == 'paper' else 'stated R'})")
        before.append(b[1].mean(axis=0))
        after.append(a[1].mean(axis=0))
        T = b[1].shape[1]
    if T is None:
        T = np.asarray(results[_blocks(results)[0]]["paper/before/gospa"]).shape[1] if any(
            k.startswith("sim/") for k in results) else PINGS
    keys = [k for k in results if k.startswith("sim/")] or _tracker_blocks(results)
    first = int(results[keys[0]]["first_output_ping"]) if keys else _warm(HOUGH)
    return {"rows": np.array(names, dtype=str), "ping": np.arange(T),
            "gospa_before": np.array(before, dtype=float).reshape(len(names), T),
            "gospa_after": np.array(after, dtype=float).reshape(len(names), T),
            "first_output_ping": np.array(first), "c": np.array(GOSPA_C)}


def _trackers_gospa_draw(data, fig):
    axes = fig.subplots(1, 2, sharey=True)
    for ax, phase in zip(axes, ("before", "after")):
        for i, name in enumerate(data["rows"]):
            paper = str(name).startswith(PAPER_TRACKER + " (")
            ax.plot(data["ping"], data[f"gospa_{phase}"][i], "o-" if paper else ".--", color=f"C{i % 10}", lw=1.2 if
                    paper else 0.9, label=str(name) + ("" if paper else " (extension)"))
        ax.axvline(float(data["first_output_ping"]) - 0.5, color="0.6", lw=0.8)
        ax.axhline(float(data["c"]) / np.sqrt(2.0), color="0.3", ls=":", lw=0.8, label="one missed target (c / sqrt 2)")
        ax.set(xlabel="ping", title=f"{phase} Hough removal")
    axes[0].set_ylabel("GOSPA (c = 10, p = 2), position units")
    axes[0].legend(fontsize=7)


FIGURES = FIGURES + (
    FigureSpec("gospa-trackers", "GOSPA of the confirmed tracks per ping (mean over runs) of every tracker compared, "
               "before (left) and after (right) Hough removal on the same runs: the paper's M-of-N rows (solid) and "
               "the EXTENSION rows (dashed: trackers the paper does not have, each with the Kalman filter and R from "
               "the sensor's stated accuracy); the grey line marks the end of the warm-up.",
               _trackers_gospa_data, _trackers_gospa_draw, size=(11.0, 4.5)),
)


def _seed_table(results) -> Table:
    """Criterion 2 (paper rows) seed block by seed block."""
    rows = []
    for key in _blocks(results):
        a = TrackCounts.from_arrays(results[key], "paper/after/")
        k = int(np.sum(continuity(a.held) >= TRUE_FRACTION))
        rows.append((key.split("/")[1], _share_text(k, a.held.shape[0])))
    return Table(("seed block (seed = report seed + block)", "runs holding the target >= 80 % after removal [CI]"),
                 tuple(rows))


def _variant_table(results) -> Table:
    rows = []
    for name in VARIANTS:
        got = {arm: _variant_counts(results, name, arm) for arm in ("paper", "stated")}
        if got["paper"] is None or got["stated"] is None:
            continue
        keys, prefix = got["paper"][2], got["paper"][3]
        post = np.arange(got["paper"][0].false.shape[1]) >= int(results[keys[0]][f"{prefix}first_output_ping"])
        s = {arm: summary(got[arm][0], got[arm][1], post) for arm in got}
        st = _pooled_stats(results, keys, f"rem/{name}/")
        rows.append((VARIANT_LABELS[name], _kept_text(st, f"rem/{name}/", "hit"),
                     _kept_text(st, f"rem/{name}/", "miss"), _kept_text(st, f"rem/{name}/", "clutter"),
                     _rate_text(s["paper"]["rate"]), _share_text(s["paper"]["held80_after"], s["paper"]["runs"]),
                     _rate_text(s["stated"]["rate"]), _share_text(s["stated"]["held80_after"], s["stated"]["runs"]),
                     s["paper"]["runs"]))
    return Table(("remover", "target kept, detected at k-1", "target kept after a miss at k-1", "clutter kept",
                  "paper rows: removal rate (ratio of sums) [CI]", "paper rows: runs holding the target >= 80 % [CI]",
                  "R from stated accuracy: removal rate (ratio of sums) [CI]",
                  "R from stated accuracy: runs holding >= 80 % [CI]",
                  "runs"), tuple(rows))


def _tuning_table(results) -> Table:
    t = results.get("tuning")
    if t is None:
        return Table(("candidate",), ())
    n = int(t["tuning/runs"])
    chosen = int(t["tuning/chosen"])
    rows = []
    for i, cand in enumerate(TUNING_CANDIDATES):
        gate = "filter's R" if cand["gate_sigma"] is None else f"sigma {cand['gate_sigma']:g}"
        rows.append((gate, cand["delete_misses"], _share_text(int(t["tuning/held"][i]), n),
                     "chosen" if i == chosen else ""))
    rows.append(("rule: " + TUNING_RULE, "", f"tuning runs: stream '{TUNING_STREAM}', runs 0..{n - 1} (never "
                 "reported)", ""))
    return Table(("gate computed with", "delete after misses", "tuning runs holding the target >= 80 % [CI]",
                  "chosen"), tuple(rows))


def _surrogate_table(results) -> Table:
    rows = []
    for task in ("surrogate", "file"):
        if task not in results:
            continue
        res = results[task]
        T = res["paper/before/false"].shape[1]
        post = np.arange(T) >= int(res["first_output_ping"])
        b = TrackCounts.from_arrays(res, "paper/before/")
        for arm in ("paper", "min-speed"):
            for phase in ("before", "after"):
                c = TrackCounts.from_arrays(res, f"{arm}/{phase}/")
                cont = continuity(c.held)
                rate = _rate_text(summary(b, c, post)["rate"]) if (arm, phase) != ("paper", "before") else "-"
                rows.append((f"{task} (SYNTHETIC)", arm if arm == "paper" else "EXTENSION: min-speed test",
                             phase, _f(c.false[:, post].mean(), 2), rate,
                             _share_text(int(np.sum(cont >= TRUE_FRACTION)), cont.size)))
        if "rem/main/site_n" in res:
            rows.append((f"{task} (SYNTHETIC)", "remover", "after",
                         "persistent-site detections kept " + _kept_text(res, "rem/main/", "site"),
                         "uniform clutter kept " + _kept_text(res, "rem/main/", "clutter"),
                         "target kept " + _kept_text(res, "rem/main/", "hit")))
    return Table(("case", "row", "removal", "false tracks/ping (pings 6-20)", "removal rate (ratio of sums) vs paper before",
                  "runs holding the target >= 80 % [CI]"), tuple(rows))


def _timing_table(results) -> Table:
    t = results.get("timing")
    if t is None:
        return Table(("stage",), ())
    how = (f"one run of the paper's scenario ({_f(float(t['detections_per_ping']), 1)} detections per ping), warmed "
           f"up (one untimed call first), median of {int(t['repeats'])} timed calls / 20 pings")
    rows = tuple((name, f"{1e3 * float(t[f'{name}_cpu_s']):.2f}", f"{1e3 * float(t[f'{name}_wall_s']):.2f}", how)
                 for name in ("remover", "tracker_before", "tracker_after"))
    return Table(("stage", "ms per ping (process CPU)", "ms per ping (wall)", "how timed"), rows)


TABLES = (
    TableSpec("removal-rate", "False-track removal rate: published (20-ping average) beside ours (ratio of sums over "
              "the runs and pings 6-20, 95 % paired bootstrap interval over runs), with the false tracks per ping "
              "before removal it is judged on (mean over runs and pings 6-20, bootstrap interval over runs) and their "
              "sum, every row. Sea-trial rows are a SYNTHETIC SURROGATE.", _removal_table),
    TableSpec("rows", "Every row before and after removal: removal rate (criterion 1) beside the false tracks per ping "
              "before removal, criterion 2 (share of runs holding the "
              "target >= 80 % of the pings after initiation, exact binomial interval) and criterion 3 (paired "
              "RMSE, bootstrap interval over runs).", _rows_table),
    TableSpec("seed-blocks", "Criterion 2 of the paper rows on each seed block separately.", _seed_table),
    TableSpec("removal-per-ping", "Simulation, paper rows: false tracks per ping before/after removal and the "
              "removal rate at each ping as a ratio of sums over the runs (pings 1-5 are the Hough warm-up: no "
              "detections after removal).", _per_ping_table),
    TableSpec("remover-variants", "Remover variants (support rule, new measurements, angle bins, grouping), each "
              "with the paper's tracker; target detections kept after a miss at the previous ping.", _variant_table),
    TableSpec("tuning", "The tuned row's search: candidates, their score on the tuning runs and the rule (fixed "
              "in docs/paper001.md before the search).", _tuning_table),
    TableSpec("surrogate", "Sea-trial SYNTHETIC SURROGATE: paper rows and the minimum-speed extension against "
              "its stationary clutter.", _surrogate_table),
    TableSpec("timing", "Per-ping time of the remover and the tracker, paper scenario, warmed up.", _timing_table),
    TableSpec("gospa", "GOSPA (alpha 2, c = 10, p = 2) of the confirmed tracks beside the paper's counts, every row "
              "before and after removal, over the pings after the Hough warm-up.", _gospa_table),
    TableSpec("trackers", "The trackers compared (--trackers; default M-of-N, GNN, JIPDA, GM-PHD), before and after "
              "Hough removal on the same runs: the paper's M-of-N rows and the EXTENSION rows (not in the paper: the "
              "Kalman filter with R from the sensor's stated accuracy, each tracker's scenario settings in "
              "docs/paper001.md). GOSPA, false tracks and the share of pings held are per-run means over pings 6-20 "
              "with 95 % bootstrap intervals over runs; runs holding >= 80 % with exact binomial intervals.",
              _trackers_table),
)


# -- criteria ---------------------------------------------------------------------------------------


def _replication(samples, holds) -> tuple[int, int] | None:
    n = np.asarray(samples[0] if isinstance(samples, tuple) else samples).shape[0]
    if n < 2 * PROTOCOL_RUNS:
        return None
    return replication_rate(samples, PROTOCOL_RUNS, holds, replications=n // PROTOCOL_RUNS)


def _c1_holds(sum_before, sum_after) -> bool:
    r = removal_ratio(sum_before, sum_after)
    return bool(np.isfinite(r) and 0.60 <= r <= 0.95)


def c1_criterion(before_false: np.ndarray, after_false: np.ndarray, post: np.ndarray, prefix: str = "",
                 suffix: str = "", min_false: int = MIN_FALSE_BEFORE) -> Criterion:
    """Criterion 1 from the false-track counts ``(B, T)`` before and after removal and the judged pings ``post``.

    Ours: the ratio of sums ``1 - sum F_after / sum F_before`` over the runs and the pings in ``post``; its 95 %
    interval a percentile bootstrap over runs (each run's two sums resampled together), judged within
    [0.60, 0.95] from at least ``MIN_RUNS["1"]`` runs.  Beside it: the false tracks per ping before removal (mean
    over runs and pings, bootstrap interval over runs) and their sum.  The population precondition: with fewer
    than ``min_false`` false tracks before removal summed over the runs and pings, the verdict is not judgeable
    (never met, never not met), the reason in the detail and ``extra["precondition"]``.
    """
    sums = false_track_sums(before_false, after_false, post)
    judged = np.flatnonzero(post) + 1
    pings = f"pings {judged[0]}-{judged[-1]}" if judged.size else "no pings"
    per_run = np.asarray(before_false, dtype=float)[:, np.asarray(post, dtype=bool)].mean(axis=1)
    total = int(sums[0].sum())
    held = total >= min_false
    lo, hi = bootstrap_interval(per_run) if per_run.size > 1 else (np.nan, np.nan)
    interval = f" [{lo:.3g}, {hi:.3g}]" if np.isfinite(lo) else ""
    mean = float(per_run.mean()) if per_run.size else float("nan")
    population = (f"false tracks per ping before removal {mean:.3g}{interval} (mean over {per_run.size} runs x "
                  f"{pings}, bootstrap over runs); {total} false tracks before removal summed, "
                  f"{int(sums[1].sum())} after")
    pre = (f"population precondition: >= {min_false} false tracks before removal summed over the runs "
           f"({'holds' if held else 'FAILS'}: {total})")
    text = (prefix + f"; rate = 1 - sum F_after / sum F_before over the runs and {pings}; " + population + "; " + pre
            + suffix)
    name = "false tracks before removal, summed"
    # a failed precondition makes the verdict "not judgeable"
    population_holds = Precondition(name, held, f"{total} summed over {per_run.size} runs x {pings}; needs >= "
                                    f"{min_false}", {"needs": min_false, "has": total})
    crit = criterion_from_runs(
        "1", "mean false-track removal rate in simulation is in 60-95 % (paper 78 %)", sums, _removal_ratio,
        (0.60, 0.95), "within", min_n=MIN_RUNS["1"], published="78 %", detail=text,
        threshold_text="removal rate (ratio of sums) within [0.60, 0.95]",
        replication=_replication(sums, _c1_holds), preconditions=(population_holds,))
    extra = dict(crit.extra, false_per_ping_before=mean if np.isfinite(mean) else None,
                 false_per_ping_before_interval=(float(lo), float(hi)) if np.isfinite(lo) else None,
                 precondition={"name": name, "needs": min_false, "has": total, "holds": held})
    if held:
        return replace(crit, extra=extra)
    reason = (f"; NOT JUDGEABLE: {total} false tracks before removal summed over the runs, fewer than the "
              f"{min_false} the rate needs (verdict {crit.verdict_if_judged!r} from the interval alone set aside)")
    return replace(crit, detail=crit.detail + reason, extra=extra)


def _c2_holds(cont) -> bool:
    return bool(np.mean(cont >= TRUE_FRACTION) >= 0.90)


def _c3_holds(sq_b, sq_a) -> bool:
    d = _rmse_diff(sq_b, sq_a)
    return bool(np.isfinite(d) and d <= 0.0)


def _others(results, post, what: str) -> str:
    """The same statistic on the extra rows of the simulation blocks, for the detail text (the tuned row is in the
    rows table: the criteria never read the tuning task, so the confirmation seed does not rerun it)."""
    parts = []
    for arm in _arms_in(results, tuned=False):
        if arm == "paper":
            continue
        s = summary(_arm_counts(results, arm, "before"), _arm_counts(results, arm, "after"), post)
        label = {"stated": "R from stated accuracy", "previous": "previous settings",
                 "paper-mofn": "paper's M-of-N (initiation counted) with matched R",
                 "two-point": "two-point initial covariance"}.get(arm, arm)
        if what == "rate":
            parts.append(f"{label} {_rate_text(s['rate'])}")
        elif what == "held":
            parts.append(f"{label} {_share_text(s['held80_after'], s['runs'])}")
        else:
            parts.append(f"{label} {_f(s['rmse_after'] - s['rmse_before'])}")
    return "; other rows (not judged): " + ", ".join(parts) if parts else ""


def remover_cap(stats: Mapping) -> dict:
    """What the remover costs criterion 2: the target's detections at the pings after the warm-up that it drops,
    split by whether the target was detected at the previous ping (``miss``: it was not), pooled over the runs.

    ``stats``: the ``rem/main/`` arrays (``miss_n, miss_kept, hit_n, hit_kept`` per run).  Returns
    ``{"miss_n", "miss_dropped", "hit_n", "hit_dropped"}`` (counts)."""
    out = {}
    for name in ("miss", "hit"):
        n = int(np.sum(stats.get(f"rem/main/{name}_n", 0)))
        out[f"{name}_n"] = n
        out[f"{name}_dropped"] = n - int(np.sum(stats.get(f"rem/main/{name}_kept", 0)))
    return out


def _cap_text(results, s: Mapping) -> str:
    """Criterion 2's cap in words, with numbers: the target detections the remover drops after a missed ping and
    otherwise, and the runs holding the target before against after removal."""
    cap = remover_cap(_pooled_stats(results, _blocks(results), "rem/main/"))
    pct = lambda k, n: f"{100 * k / n:.1f} % ({k} of {n})" if n else "n/a (none)"  # noqa: E731
    lost = s["held80_before"] - s["held80_after"]
    return (f"; the cap on it: the remover drops {pct(cap['miss_dropped'], cap['miss_n'])} of the target's "
            f"detections at a ping after a missed ping and {pct(cap['hit_dropped'], cap['hit_n'])} after a "
            f"detected one (pings after the warm-up); runs holding the target >= 80 % go from "
            f"{s['held80_before']} of {s['runs']} before removal to {s['held80_after']} after ({lost:+d} "
            f"runs lost to the remover: {100 * lost / max(s['runs'], 1):.1f} points)")


def _judge(b: TrackCounts, a: TrackCounts, post: np.ndarray, label: str, others: tuple = ("", "", ""),
           cap: str = "") -> list[Criterion]:
    """Criteria 1-3 of one row from its counts before and after removal (``label`` names the row and runs)."""
    s = summary(b, a, post)
    out = [c1_criterion(b.false, a.false, post, label, others[0])]
    cont = s["cont_after"]
    out.append(criterion_from_counts(
        "2", "after removal the target holds a confirmed track for >= 80 % of the pings after initiation in >= 90 % "
             "of runs", s["held80_after"], s["runs"], 0.90, ">=", min_n=MIN_RUNS["2"], published=">= 90 % of runs",
        detail=f"{label}; before removal {_share_text(s['held80_before'], s['runs'])}" + cap + others[1],
        threshold_text="share of runs >= 0.90", replication=_replication(cont, _c2_holds)))
    sq = (s["sq_before"], s["sq_after"])
    out.append(criterion_from_runs(
        "3", "target-track RMSE after removal <= RMSE before", sq, _rmse_diff, 0.0, "<=", min_n=MIN_RUNS["3"],
        published="after <= before",
        detail=f"{label}; RMSE after minus before on the {s['pairs']} (run, ping) pairs "
               f"held in both ({_f(s['rmse_after'])} vs {_f(s['rmse_before'])})" + others[2],
        threshold_text="RMSE after - RMSE before <= 0", replication=_replication(sq, _c3_holds)))
    return out


def _unknown_counts(results: Mapping, unknown: DeclaredUnknown, value, phase: str) -> TrackCounts | None:
    """The paper rows at one grid value, pooled over the seed blocks (None where a block's task is missing)."""
    parts = []
    for block in range(len(_blocks(results))):
        res, prefix = _unknown_rows(results, unknown, value, block)
        if res is None or f"{prefix}paper/{phase}/confirmed" not in res:
            return None
        parts.append(TrackCounts.from_arrays(res, f"{prefix}paper/{phase}/"))
    return TrackCounts(*(np.concatenate([getattr(c, f) for c in parts]) for f in FIELDS))


def _across_unknowns(results: Mapping, judged: list[Criterion], b: TrackCounts, post: np.ndarray) -> list[Criterion]:
    """``judged`` (the paper rows' criteria at the primary values) with their verdicts at every grid value of
    :data:`UNKNOWNS` (``Criterion.across``); an unknown whose grid tasks are missing is left out."""
    out = list(judged)
    for unknown in UNKNOWNS:
        at: dict = {}
        for value in unknown.grid:
            if value == unknown.primary:
                at[value] = judged
                continue
            bv, av = _unknown_counts(results, unknown, value, "before"), _unknown_counts(results, unknown, value,
                                                                                          "after")
            if bv is None or av is None:
                at = {}
                break
            at[value] = _judge(bv, av, post, unknown.label(value))
        if not at:
            continue
        note = f"paper rows, the same {b.false.shape[0]} runs (the same target detections) at every value"
        out = [replace(c, across=c.across + judge_across(unknown, {v: at[v][i] for v in unknown.grid},
                                                         {v: note for v in unknown.grid}))
               for i, c in enumerate(out)]
    return out


def criteria(results) -> list[Criterion]:
    blocks = _blocks(results)
    b, a = _arm_counts(results, "paper", "before"), _arm_counts(results, "paper", "after")
    post = _post(results, b.false.shape[1])
    s = summary(b, a, post)
    label = f"paper rows, {len(blocks)} seed block(s) of {b.false.shape[0] // len(blocks)} runs"
    others = tuple(_others(results, post, what) for what in ("rate", "held", "rmse"))
    judged = _judge(b, a, post, label, others, _cap_text(results, s))
    return _across_unknowns(results, judged, b, post)


RECIPE = RecipeSpec(
    paper=PAPER,
    title="Hough-transform clutter removal and CMKF-L tracking of an active-sonar target in heavy clutter",
    sizes=SIZES,
    tasks=tasks,
    figures=FIGURES,
    tables=TABLES,
    criteria=criteria,
    default_filters=(PAPER_FILTER,),
    default_trackers=DEFAULT_TRACKERS,
    published=PUBLISHED,
    notes=NOTES,
    unknowns=UNKNOWNS,
)
