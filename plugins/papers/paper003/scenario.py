"""Paper 003's scenario: the target, the sensor, the noise levels in two readings, the data streams, the lost rule.

A 2-D target with a random-walk velocity (``r_t = r_{t-1} + T v_{t-1}``, ``v_t = v_{t-1} + a_t``,
``a_t ~ N(0, sigma_a^2 I)``) is seen in range and bearing from a sensor at the origin.  Three paired noise
levels L1/L2/L3; the paper gives the bearing noise as "0.01, 0.1, 1" with no unit, so it is read two ways:
radians (the primary reading) and degrees, each a scenario of its own.  Common random numbers: the truths and
measurements of chunk ``c`` of a case come from ``generator(seed, stream, case, c)`` alone, so every filter,
and every task, sees the same data.  The lost rule (:data:`LOST_FACTOR`, :func:`lost_threshold`) and the declared
unknown delta (:data:`DELTA`) are here too.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from workbench.criteria import DeclaredUnknown
from workbench.models import random_walk_velocity
from workbench.rng import chunk_bounds, generator
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, Scans, Truth

PAPER = "003"
STREAM = "paper003"  # the key of the reported runs' data streams
DT = 1.0  # s [U]
X0 = (100.0, 50.0, -1.0, 1.0)  # true start [x, y, vx, vy] (m, m/s) [U]
XHAT0 = (110.0, 40.0, 0.0, 0.0)  # initial estimate [U]
P0 = (10.0 ** 2, 10.0 ** 2, 2.0 ** 2, 2.0 ** 2)  # initial covariance (diagonal) [U]
SENSOR = "range-bearing"

#: level -> (sigma_theta in the paper's unit, sigma_r m, sigma_a m/s per step) [U: paired levels]
LEVELS: dict[str, tuple[float, float, float]] = {
    "L1": (0.01, 0.1, 0.01),
    "L2": (0.1, 1.0, 0.1),
    "L3": (1.0, 10.0, 1.0),
}
#: reading of the bearing noise's unit -> radians per unit.  "rad" is the primary reading.
READINGS: dict[str, float] = {"rad": 1.0, "deg": math.pi / 180.0}
NOMINAL = "L2"  # the noise statistics handed to every filter in the mismatched (primary) variant

#: The lost-track rule (written down, with its reason, before looking at which runs it marks; issue 24).  A run is
#: lost when the filter's final position error exceeds the SMALLER of two scales of the level's own noise:
#:
#: (a) ``LOST_FACTOR`` x the rms error of ONE raw measurement converted to x-y at the final true position
#:     (:func:`measurement_error_rms`, the level's own sigma_r and sigma_theta).  A filter that follows the target
#:     averages many measurements and ends below that error; for an error as large as one raw measurement's (a
#:     2-D error with rms rho, Rayleigh-like), exceeding 3 rho happens once in exp(9) ~ 8,000 runs, so a run beyond
#:     it is not a noisy track but one that has left the target.
#: (b) the rms position error of a filter that used NO measurement at all: the prior N(x^0, P0) carried through the
#:     level's own true motion to the final step (:func:`no_measurement_rms`).  A filter farther from the target
#:     than that has lost every gain the measurements gave it.
#:
#: (a) is the binding scale where the measurements are precise (L1, L2, and the degrees reading); (b) where one
#: measurement says little: at L3 in radians (sigma_theta = 1 rad) one measurement only places the target on its
#: range ring, rho ~ 0.9 r, so (a) alone (the former 10 x rho, about 6 km) could not mark even a filter stuck at
#: its start.  Both scales are the level's own (its noise, its motion, the declared prior), so the rule can mark a
#: run lost at every level; it depends on no filter's result.
LOST_FACTOR = 3.0


def case_name(reading: str, level: str) -> str:
    """``"L1"`` for the radians reading (the primary one), ``"deg-L1"`` for the degrees reading."""
    return level if reading == "rad" else f"{reading}-{level}"


def level_sigmas(reading: str, level: str) -> tuple[float, float, float]:
    """``(sigma_theta rad, sigma_r m, sigma_a m/s)`` of a level under a reading of the bearing unit."""
    st, sr, sa = LEVELS[level]
    return st * READINGS[reading], sr, sa


def make_case(name: str, sigmas: Sequence[float]) -> dict:
    return {"case": name, "sigma_theta": float(sigmas[0]), "sigma_r": float(sigmas[1]), "sigma_a": float(sigmas[2])}


def reading_cases(reading: str) -> tuple[dict, ...]:
    return tuple(make_case(case_name(reading, lv), level_sigmas(reading, lv)) for lv in LEVELS)


def sigmas_of(case: Mapping) -> tuple[float, float, float]:
    return case["sigma_theta"], case["sigma_r"], case["sigma_a"]


def filter_models(host, true_sigmas: Sequence[float], variant: str, reading: str = "rad"):
    """The motion and measurement models handed to a filter: the reading's nominal L2 statistics
    (``"mismatched"``), or the case's own (``"matched"``)."""
    st, sr, sa = level_sigmas(reading, NOMINAL) if variant == "mismatched" else true_sigmas
    return random_walk_velocity(2, DT, sa), host.sensor(SENSOR).measurement_model(sigma_r=sr, sigma_theta=st)


def prior(batch: int) -> Gaussian:
    return Gaussian.broadcast(XHAT0, np.diag(P0), batch)


def simulate_chunk(host, seed: int, case: str, sigmas: Sequence[float], chunk: int, runs: int, steps: int,
                   stream: str = STREAM) -> tuple[Truth, Scans]:
    """Truths and measurements of one chunk of ``runs`` runs: ``generator(seed, stream, case, chunk)``."""
    st, sr, sa = sigmas
    rng = generator(seed, stream, case, chunk)
    truth = sample_motion(np.tile(X0, (runs, 1)), random_walk_velocity(2, DT, sa), steps, rng)
    scans = host.sensor(SENSOR).simulate(truth, rng, sigma_r=sr, sigma_theta=st)
    return truth, scans


def units(cases: Sequence[Mapping], runs: int, chunk: int,
          of_runs: int | None = None) -> list[tuple[int, int, int, int]]:
    """The ``(case index, chunk index, chunk size, runs taken)`` of the first ``runs`` runs of each case, whose
    ``of_runs`` runs (default ``runs``) are cut into chunks of ``chunk``: a task on a prefix of the runs sees
    exactly the data of the same runs in a task on all of them."""
    of = runs if of_runs is None else max(int(of_runs), runs)
    out = []
    for c in range(len(cases)):
        for k, (start, stop) in enumerate(chunk_bounds(of, chunk)):
            if start >= runs:
                break
            out.append((c, k, stop - start, min(stop, runs) - start))
    return out


def simulate_units(host, seed: int, cases: Sequence[Mapping], chosen, steps: int,
                   stream: str = STREAM) -> tuple[Truth, Scans]:
    """The truths and measurements of ``chosen`` units (from :func:`units`) concatenated into one batch."""
    parts = []
    for c, k, size, take in chosen:
        truth, scans = simulate_chunk(host, seed, cases[c]["case"], sigmas_of(cases[c]), k, size, steps, stream)
        parts.append((truth.states[:take], scans.z[:take], scans.valid[:take], scans.origin[:take],
                      truth.times, scans.times))
    truth = Truth(np.concatenate([p[0] for p in parts]), parts[0][4])
    scans = Scans(np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]), parts[0][5],
                  origin=np.concatenate([p[3] for p in parts]))
    return truth, scans


def measurement_error_rms(true_range: np.ndarray, sigma_r: float, sigma_theta: float) -> np.ndarray:
    """The rms position error of one measurement converted to x-y at ``true_range``, with the level's own noise.

    For ``z = (r + sigma_r e1, theta + sigma_theta e2)``: ``E|p(z) - p|^2 = sigma_r^2 + 2 E[r_z r] (1 - E cos e)``
    with ``E cos(sigma_theta e2) = exp(-sigma_theta^2 / 2)``, i.e. ``sigma_r^2 + 2 r^2 (1 - exp(-sigma_theta^2 / 2))``
    (about ``sigma_r^2 + r^2 sigma_theta^2`` for a small bearing noise).
    """
    r = np.asarray(true_range, dtype=float)
    # rho^2 = sigma_r^2 + 2 r^2 (1 - exp(-sigma_theta^2 / 2))
    return np.sqrt(sigma_r ** 2 + 2.0 * r * r * -np.expm1(-0.5 * sigma_theta ** 2))


def no_measurement_rms(sigma_a: float, steps: int) -> float:
    """The rms position error at the last of ``steps`` states (``steps - 1`` motion steps) of a filter that used
    no measurement: the trace of the position block of ``F^k P0 F^k' + sum_j F^j Q F^j'`` (the prior ``N(x^0, P0)``
    carried through the random-walk-velocity motion with the level's own ``sigma_a``).  Metres."""
    if int(steps) < 1:
        raise ValueError(f"steps must be >= 1, got {steps!r}")
    F = np.array([[1.0, 0.0, DT, 0.0], [0.0, 1.0, 0.0, DT], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    Q = np.diag([0.0, 0.0, sigma_a ** 2, sigma_a ** 2])
    P = np.diag(P0)
    for _ in range(int(steps) - 1):
        P = F @ P @ F.T + Q
    return float(np.sqrt(P[0, 0] + P[1, 1]))


def lost_threshold(final_truth: np.ndarray, sigmas: Sequence[float], steps: int) -> np.ndarray:
    """Per run, the final position error beyond which the track is lost (the rule above :data:`LOST_FACTOR`):
    ``min(LOST_FACTOR x rho, no_measurement_rms)`` with ``rho`` the rms error of one measurement at the final true
    position (the level's own ``sigma_r``, ``sigma_theta``) and the no-measurement spread after ``steps`` states
    (the level's own ``sigma_a``).  ``final_truth (B, n)`` -> ``(B,)`` metres."""
    r = np.hypot(final_truth[:, 0], final_truth[:, 1])  # the sensor is at the origin
    one = LOST_FACTOR * measurement_error_rms(r, sigmas[1], sigmas[0])
    return np.minimum(one, no_measurement_rms(sigmas[2], steps))


def is_lost(final_error: np.ndarray, final_truth: np.ndarray, sigmas: Sequence[float], steps: int) -> np.ndarray:
    """Per run, whether the track is lost: ``final_error (B,)`` beyond :func:`lost_threshold`."""
    return np.asarray(final_error, dtype=float) > lost_threshold(final_truth, sigmas, steps)


#: delta, the offset of the CRPF's selection PMF: a value the paper withholds.  Judged across its grid (the
#: criteria whose rows include the CRPF: C1, C4-L2, C4-L3, C4-N), on the same truths and measurements.
DELTA = DeclaredUnknown(
    name="delta", unit="x the mean gap of the risks above their minimum", primary=0.1, grid=(0.1, 0.3, 1.0),
    why=("Table 6 keeps the offset delta of the selection PMF (R - min R + delta)^-beta but its value did not "
         "survive, and its plain cost ||z - h||^q with a constant delta is not what we run: the relative delta (a "
         "multiple of the mean gap of the risks) and the arc-length cost are our reconstructions. The primary 0.1 "
         "is the pre-registered tuning rule's pick (seed 20031, tuning runs only; docs/paper003.md), at the edge of "
         "its grid {0.1, 0.3, 1}, which was fixed before the tuning ran and is the grid judged here."))


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
Choices where the paper is silent (brief § 3.2-3.4; details and the Table-6 fragments in docs/paper003.md):
- Motion: random-walk velocity, T = 1 s, Q = blockdiag(0, sigma_a^2 I). Truth starts at x0 = [100, 50, -1, 1]
  in every run; each run draws its own acceleration sequence and measurement noise (100 steps, a measurement
  at every step including t = 0). Filters start from x^0 = [110, 40, 0, 0], P0 = diag(10^2, 10^2, 2^2, 2^2).
- Levels (sigma_theta, sigma_r m, sigma_a m/s): L1 (0.01, 0.1, 0.01), L2 (0.1, 1, 0.1), L3 (1, 10, 1). The paper
  gives the bearing noise without a unit: read in radians (primary) and in degrees (a second scenario with its
  own table and criteria). The 3 x 3 grid varies (sigma_theta rad, sigma_r) with sigma_a = 0.1, mismatched.
- Unknown noise: primary = mismatched (every filter gets the reading's nominal L2 Q and R at every level);
  matched (the level's own Q and R) beside it. At L2 both coincide. The CRPF reads no noise statistics.
- Reference: the bootstrap PF sir with 5,000 particles given the level's true Q and R, on the first
  reference_runs runs of every level (common random numbers); how far each filter is from it is a paired ratio
  on those runs. At L2 and L3 the same PF with 20,000 particles runs on the same first reference_check_runs runs
  (100 at full size): the reference has converged when MSE(5,000) / MSE(20,000), paired, has its 95 % interval
  within [0.95, 1.05].
- CRPF (Table 6 of the paper, which gives the plain cost ||z - h||^q and a constant delta; the arc-length cost and
  the relative delta below are our reconstructions, not Table 6's): cost C_t = lam C_{t-1} + dC with the
  arc-length residual dC = (dr^2 + (r_meas dtheta)^2) (q = 2), risk with the noise-free prediction, selection PMF
  (R - min R + delta_R)^-beta with a relative offset delta_R = delta x the mean gap of the risks above their
  minimum (the same for the estimate's PMF), lam = 0.95, beta = 2, systematic selection every step, uniform initial
  box +-10 m, +-2 m/s, and Table 6's adaptive per-particle variance sigma_t^2 = ((t-1)/t) sigma_{t-1}^2 +
  |x_t - f(x_{t-1})|^2 / (t dim), carried through selection, from sigma_0 = sigma0 (isotropic). sigma0 and delta
  are chosen once for every level and both readings on tuning runs (seed 20031, stream paper003-tuning, never used
  by a reported run) by the rule written in docs/paper003.md before the tuning ran: the smallest geometric mean
  over the six cases of CRPF-100's time-averaged MSE. The previous reconstruction (fixed sigma^2 = kappa /
  N^(2/dim) with kappa 1 and the dwna shape, the plain norm, delta = 0.01) is the ablation row; the changes
  table undoes one change at a time. Every CRPF runs the fused kernel workbench_filters.crpf.crpf_step (Numba on the
  CPU, else Taichi) for the range-bearing sensor, with counter-based propagation normals.
- MSE(t) = mean over runs of the squared position error; the scalar is its mean over t. RMSE = sqrt(MSE).
  "Median" = the median over runs of each run's time-averaged squared error; "MSE not lost" = the mean over the
  runs the filter did not lose. Lost track (rule written down before seeing which runs it marks): final position
  error > min(3 rho, s0), rho = the rms error of one measurement converted to x-y at the final true position with
  the level's own noise, sqrt(sigma_r^2 + 2 r^2 (1 - exp(-sigma_theta^2 / 2))) (a filter as bad as one raw
  measurement exceeds 3 rho once in ~8,000 runs), s0 = the rms error of a filter that used no measurement (the
  prior carried through the level's own motion to the last step). The former 10 rho (about 6 km at L3, where one
  measurement only places the target on its range ring) could not mark even a filter stuck at its start. Runs
  whose true path comes within 10 m of the sensor are kept and counted in the scenario table.
- Processing time (Fig 7, criteria C5 and C6), on warmed-up code (each filter runs once before any clock starts,
  so compiled kernels are loaded): un-batched = each of timing_runs runs of L2 data (radians, mismatched) timed
  alone (B = 1), the median per run; batched = the same runs as one batch, timed timing_repeats times, the median
  per run. The Monte Carlo tasks' own filtering times are also warm (their filter runs once on two runs first).
- Criteria carry n, a 95 % interval (percentile bootstrap over runs, paired where filters share runs) and a
  three-way verdict; below 1,000 runs (timing: 100 timed runs, 5 repetitions) a criterion is inconclusive.
  Criterion 4 at L2 and L3: "not attainable" only where CRPF-100 is not shown to beat the best Kalman-type filter
  and the converged near-optimal reference is equivalent to it (90 % interval of MSE_ref / MSE_best-Kalman inside
  [1/1.05, 1.05], TOST): that filter is then already optimal. A converged reference worse than it beyond 5 %, or
  degenerate (95 % interval above 2), is no bound and CRPF-100's own verdict stands; where the reference is not
  shown to beat the Kalman filters and has not converged the verdict is "not judgeable", with the N / 4N ratio and
  its interval. L2 is matched by construction: the Kalman-type filters are handed the nominal L2 statistics, which
  are the true ones at L2.
- Declared unknown delta (the CRPF's PMF offset; the paper withholds its value): primary 0.1 (the tuning rule's
  pick), grid {0.1, 0.3, 1} (the tuning grid). C1, C4-L2, C4-L3 and C4-N (their rows include the CRPF) are judged
  again at every grid value on the first delta_runs runs of every level (1,000 of the 3,000 at full size; 12 of
  the 40 at quick size: the whole grid, fewer runs), with the same truths and measurements; only the CRPF's delta
  changes (table "delta", and the report's "declared unknowns" section).  Those tasks are declared sensitivity
  tasks: the confirmation seed, which judges the primary values only, does not run them again.
- Criterion 3 of the brief (the SR forms equal the full forms) is an identity that holds to round-off whenever
  the code is right: it is shown as a check in the table "checks", not as a criterion.
"""
