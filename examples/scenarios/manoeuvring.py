"""The manoeuvring scenario (``manoeuvring.toml``), clean and in clutter, and the comparison of single-model filters
with the IMM on it.

Why a Python module besides the scenario file: no installed clutter generator publishes range-bearing clutter (a
scenario file's clutter must share the sensor's frame), a file's prior mean is the same in every run (a NEES study
needs each run's prior drawn around the truth) and a file cannot name a coordinated-turn motion model for a
single filter.  Everything else (the legs, the sensor, the quiet motion model, the prior's spread) is read from
``manoeuvring.toml``, so the two never disagree.

- :func:`simulate`: ``runs`` noisy range-bearing scans of the two-turn truth (each run flies the file's legs with the
  quiet model's random acceleration added, so that a filter's NEES on the straight legs can be judged), each run's
  prior drawn from ``N(truth_0, P0)``; with ``clutter=True`` also Poisson clutter (:data:`CLUTTER_RATE` per scan)
  uniform in range and bearing over :data:`CLUTTER_REGION`, and the filters associate by nearest neighbour (gated)
  instead.
- :func:`filters`: the compared filters, each with the motion model it runs with: the CV EKF and CV UKF (the quiet
  model of the file), a CT-only EKF (the known turn at +3 deg/s, the IMM's turn noise), and the registered ``imm``
  as the file configures it (the quiet model and turns at +-3 deg/s).
- :func:`evaluate`: position RMSE overall and in the turns, the mean NEES and the share of scans whose run-averaged
  NEES lies in its chi-square 95 % band.

``scripts/manoeuvring_study.py`` runs it over 500 runs; ``docs/imm.md`` shows the numbers.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import stats

from workbench.linalg import wrap_angle
from workbench.models import MotionModel, coordinated_turn
from workbench.plugins import PluginHost, load_host
from workbench.rng import generator
from workbench.scenario import Scenario, load_scenario
from workbench.tracking import Direct, NearestNeighbour, run
from workbench.trajectory import piecewise_trajectory, sample_motion
from workbench.types import Gaussian, Scans, Truth

SCENARIO_FILE = Path(__file__).with_name("manoeuvring.toml")
#: Clutter: mean count per scan, uniform over range (m) and bearing (rad): a sector around the track.
CLUTTER_RATE = 20.0
CLUTTER_REGION = ((1000.0, 4500.0), (-1.3, 0.5))
#: The nearest-neighbour gate (chi-square, 2 dof, P = 0.999).
GATE = 13.8
#: A run whose position error at the last scan exceeds this is counted as lost.
LOST_M = 200.0
#: The CT-only filter's turn: the IMM's turn rate, one direction.
CT_RATE = math.radians(3.0)


def load(host: PluginHost | None = None) -> Scenario:
    """The scenario file, validated."""
    return load_scenario(SCENARIO_FILE, host or load_host())


def truth(scenario: Scenario, steps: int | None = None):
    """The two-turn truth ``(T, 4)`` and the mask of the scans inside a turn ``(T,)``."""
    T = steps or scenario.steps
    one = piecewise_trajectory(scenario.initial_state[:2], scenario.initial_state[2:], scenario.legs, scenario.dt)
    turning = np.zeros(one.states.shape[1], dtype=bool)
    k = 0
    for leg in scenario.legs:
        count = int(round(leg.duration / scenario.dt))
        if leg.kind == "turn":
            turning[k + 1:k + 1 + count] = True  # sample k + i is the state after i steps of the leg
        k += count
    return one.states[0, :T], turning[:T]


def simulate(scenario: Scenario, runs: int, seed: int, clutter: bool = False, steps: int | None = None,
             host: PluginHost | None = None):
    """``(states (B, T, 4), scans, prior, turning (T,))``: the sensor's detections of the truth (plus clutter), each
    run's prior mean drawn from ``N(truth_0, diag(std^2))``."""
    host = host or load_host()
    states, turning = truth(scenario, steps)
    T = states.shape[0]
    times = scenario.dt * np.arange(T)
    rng = generator(seed, "manoeuvring", "clutter" if clutter else "clean")
    # each run flies the legs with the quiet model's random acceleration on top: d_k = F d_{k-1} + w_k, d_0 = 0
    deviation = sample_motion(np.zeros((runs, 4)), scenario.motion, T, rng).states
    tr = Truth(states[None] + deviation, times)
    sensor = host.sensor(scenario.sensor.plugin).configure(**scenario.sensor.params)
    scans = sensor.simulate(tr, rng)
    if clutter:
        counts = rng.poisson(CLUTTER_RATE, size=(runs, T))
        M = int(counts.max())
        (r0, r1), (b0, b1) = CLUTTER_REGION
        z = np.stack([rng.uniform(r0, r1, (runs, T, M)), rng.uniform(b0, b1, (runs, T, M))], axis=-1)
        valid = np.arange(M)[None, None, :] < counts[..., None]
        z[..., 1] = wrap_angle(z[..., 1])
        scans = Scans.merge_all([scans, Scans(z, valid, times, origin=np.full((runs, T, M), -1))])
    std = scenario.prior_std
    means = states[0] + rng.standard_normal((runs, 4)) * std
    prior = Gaussian(means, np.broadcast_to(np.diag(std**2), (runs, 4, 4)).copy())
    return tr.states, scans, prior, turning


def filters(scenario: Scenario, host: PluginHost | None = None) -> dict[str, tuple]:
    """``{label: (FilterSpec, MotionModel)}`` of the compared filters."""
    host = host or load_host()
    imm = host.filter(next(c.label for c in scenario.filters if c.plugin == "imm"))  # as the file configures it
    ct: MotionModel = coordinated_turn(scenario.dt, CT_RATE, imm.params["turn_sigma_a"])
    return {"CV EKF": (host.filter("ekf"), scenario.motion), "CV UKF": (host.filter("ukf"), scenario.motion),
            "CT-only EKF (+3 deg/s)": (host.filter("ekf"), ct), "IMM (CV + CT +-3 deg/s, EKF)":
            (imm, scenario.motion)}


def nees_band(runs: int, n: int = 4, level: float = 0.95) -> tuple[float, float]:
    """The two-sided ``level`` band of the mean of ``runs`` NEES values of an ``n``-state consistent filter."""
    a = (1.0 - level) / 2.0
    return float(stats.chi2.ppf(a, n * runs) / runs), float(stats.chi2.ppf(1.0 - a, n * runs) / runs)


def evaluate(scenario: Scenario, runs: int, seed: int, clutter: bool = False, steps: int | None = None,
             host: PluginHost | None = None, only: tuple[str, ...] | None = None) -> dict[str, dict]:
    """``{label: figures}`` of each filter over ``runs`` runs: ``rmse_m``, ``rmse_turns_m``, ``mean_nees``,
    ``nees_in_band`` (share of scans whose run-averaged NEES is inside its 95 % band), ``band``, ``lost`` (share of
    runs ending more than :data:`LOST_M` off) and, in clutter, ``updated`` (share of scans updated with a
    detection)."""
    host = host or load_host()
    states, scans, prior, turning = simulate(scenario, runs, seed, clutter, steps, host)
    model = host.sensor(scenario.sensor.plugin).configure(**scenario.sensor.params).measurement_model()
    lo, hi = nees_band(runs)
    out = {}
    for label, (spec, motion) in filters(scenario, host).items():
        if only is not None and label not in only:
            continue
        association = NearestNeighbour(GATE) if clutter else Direct()
        track = run(spec, scans, motion, model, association=association, prior=prior,
                    rng=generator(seed, "manoeuvring-filter", label))
        err = track.mean - states
        sq = np.sum(err[..., :2] ** 2, axis=-1)
        e = np.linalg.solve(track.cov, err[..., None])[..., 0]
        nees = np.einsum("btn,btn->bt", err, e)
        per_scan = nees.mean(axis=0)
        figures = {"rmse_m": float(np.sqrt(sq.mean())), "rmse_turns_m": float(np.sqrt(sq[:, turning].mean())),
                   "mean_nees": float(nees.mean()), "nees_in_band": float(np.mean((per_scan >= lo) & (per_scan <= hi))),
                   "band": (lo, hi)}
        figures["lost"] = float(np.mean(np.sqrt(sq[:, -1]) > LOST_M))
        if clutter:
            figures["updated"] = float(track.records["updated"][:, 1:].mean())
        out[label] = figures
    return out
