"""Paper 003's scenario: the target, the sensor, the noise levels in two readings, the data streams, the lost rule.

A 2-D target with a random-walk velocity (``r_t = r_{t-1} + T v_{t-1}``, ``v_t = v_{t-1} + a_t``,
``a_t ~ N(0, sigma_a^2 I)``) is seen in range and bearing from a sensor at the origin.  Three paired noise
levels L1/L2/L3; the paper gives the bearing noise as "0.01, 0.1, 1" with no unit, so it is read two ways:
radians (the primary reading) and degrees, each a scenario of its own.  Common random numbers: the truths and
measurements of chunk ``c`` of a case come from ``generator(seed, stream, case, c)`` alone, so every filter,
and every task, sees the same data.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

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
#: The lost-track rule: final position error > LOST_FACTOR x the level's own single-measurement error.
LOST_FACTOR = 10.0


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


def lost_threshold(final_truth: np.ndarray, sigmas: Sequence[float]) -> np.ndarray:
    """Per run, the final position error beyond which the track is lost: ``LOST_FACTOR`` x the rms error of one
    measurement at the final true position (:func:`measurement_error_rms`), the level's own ``sigma_r``,
    ``sigma_theta``.  ``final_truth (B, n)`` -> ``(B,)`` metres."""
    r = np.hypot(final_truth[:, 0], final_truth[:, 1])  # the sensor is at the origin
    return LOST_FACTOR * measurement_error_rms(r, sigmas[1], sigmas[0])
