"""Paper 002's scenario: its constants, the declared unknown (the false-alarm rate), the drone's flights, the
detection level's candidates, and the notes on every choice where the paper is silent ([S]: stated by the paper or
the brief, [U]: ours; docs/paper002.md)."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from workbench.criteria import DeclaredUnknown
from workbench.rng import generator
from workbench.types import InputError, Scans, Truth

from .signal import PCLConfig

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
#: Task keys: the detection level at the primary false-alarm rate, and at the brief's (a sensitivity task), + filter
DETECTION, BRIEF = "detection-", "brief-false-alarms-"
ECA_TAPS_BRIEF = 16  # the benign scene's ECA span (0-450 m), also run on the demanding scene to show its failure


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
        f"workbench_papers.paper002.scenario.write_synthetic_candidates(seed={seed}, frames={frames}).",
        "Sign convention: range-rate = -wavelength * doppler_hz (positive Doppler = approaching).",
    ), frequency_hz=freq)


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
-14, -18 dB); the reference cleaned by a delayed linear predictor (128 taps over lags 8-135, i.e. 240 m - 4.0 km,
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
