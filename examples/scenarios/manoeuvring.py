"""The manoeuvring scenario, clean (``manoeuvring.toml``) and in clutter (``manoeuvring_clutter.toml``), and the
comparison of single-model filters with the IMM on it.

Why a Python module besides the scenario files: a file's prior mean is the same in every run and its legs fly the
same path in every run (a NEES study needs each run's prior drawn around its truth, and a truth with the quiet model's
random acceleration on it), and a file's filters share one motion model (the CT-only filter runs a coordinated turn).
Everything else (the legs, the sensor, the quiet motion model, the prior's spread, the clutter, the tracker and its
gate) is read from the files, so the study and ``workbench run`` never disagree.

- :func:`load`: a scenario file, validated (``clutter=True``: the cluttered one).
- :func:`simulate`: ``runs`` noisy range-bearing scans of the two-turn truth (each run flies the file's legs with the
  quiet model's random acceleration added, so that a filter's NEES on the straight legs can be judged) plus the
  file's ``[[clutter]]`` (``uniform-clutter``: Poisson, uniform in range and bearing over a sector around the
  track), each run's prior drawn from ``N(truth_0, P0)``.
- :func:`filters`: the compared filters, each with the motion model it runs with: the CV EKF and CV UKF (the quiet
  model of the file), a CT-only EKF (the known turn at +turn_rate of the imm, the IMM's turn noise), and the
  registered ``imm`` as the file configures it (the quiet model and its turn modes at
  ``+-turn_rate * k / turn_modes``).
- :func:`evaluate`: position RMSE overall and in the turns, the mean NEES, the mean NEES on the straight legs and in
  the turns, and the share of scans whose run-averaged NEES lies in its chi-square 95 % band; the file's tracker
  (direct, or nearest neighbour with the file's gate).

``scripts/manoeuvring_study.py`` runs it over 500 runs; ``docs/imm.md`` shows the numbers.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import stats

from workbench.models import MotionModel, coordinated_turn
from workbench.plugins import PluginHost, load_host
from workbench.rng import generator
from workbench.scenario import Scenario, load_scenario
from workbench.tracking import Direct, NearestNeighbour, run
from workbench.trajectory import piecewise_trajectory, sample_motion
from workbench.types import Gaussian, InputError, Scans, Truth

SCENARIO_FILE = Path(__file__).with_name("manoeuvring.toml")
CLUTTER_FILE = Path(__file__).with_name("manoeuvring_clutter.toml")
#: A run whose position error at the last scan exceeds this is counted as lost.
LOST_M = 200.0
#: The label of the IMM in the results.
IMM = "IMM (CV + CT turn modes, EKF)"


def load(host: PluginHost | None = None, clutter: bool = False) -> Scenario:
    """The clean scenario file (or, with ``clutter``, the cluttered one), validated."""
    return load_scenario(CLUTTER_FILE if clutter else SCENARIO_FILE, host or load_host())


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


def simulate(scenario: Scenario, runs: int, seed: int, steps: int | None = None, host: PluginHost | None = None):
    """``(states (B, T, 4), scans, prior, turning (T,))``: the sensor's detections of the truth plus the file's
    clutter, each run's prior mean drawn from ``N(truth_0, diag(std^2))``."""
    host = host or load_host()
    states, turning = truth(scenario, steps)
    T = states.shape[0]
    times = scenario.dt * np.arange(T)
    rng = generator(seed, "manoeuvring", "clutter" if scenario.clutter else "clean")
    # each run flies the legs with the quiet model's random acceleration on top: d_k = F d_{k-1} + w_k, d_0 = 0
    deviation = sample_motion(np.zeros((runs, 4)), scenario.motion, T, rng).states
    tr = Truth(states[None] + deviation, times)
    sensor = host.sensor(scenario.sensor.plugin).configure(**scenario.sensor.params)
    parts = [sensor.simulate(tr, rng)]
    parts += [host.clutter_generator(c.plugin).configure(**c.params).generate(tr, rng) for c in scenario.clutter]
    scans = parts[0] if len(parts) == 1 else Scans.merge_all(parts)
    std = scenario.prior_std
    means = states[0] + rng.standard_normal((runs, 4)) * std
    prior = Gaussian(means, np.broadcast_to(np.diag(std**2), (runs, 4, 4)).copy())
    return tr.states, scans, prior, turning


def filters(scenario: Scenario, host: PluginHost | None = None) -> dict[str, tuple]:
    """``{label: (FilterSpec, MotionModel)}`` of the compared filters."""
    host = host or load_host()
    imm = host.filter(next(c.label for c in scenario.filters if c.plugin == "imm"))  # as the file configures it
    rate = imm.params["turn_rate"]
    ct: MotionModel = coordinated_turn(scenario.dt, rate, imm.params["turn_sigma_a"])
    return {"CV EKF": (host.filter("ekf"), scenario.motion), "CV UKF": (host.filter("ukf"), scenario.motion),
            f"CT-only EKF (+{math.degrees(rate):g} deg/s)": (host.filter("ekf"), ct), IMM: (imm, scenario.motion)}


def nees_band(runs: int, n: int = 4, level: float = 0.95) -> tuple[float, float]:
    """The two-sided ``level`` band of the mean of ``runs`` NEES values of an ``n``-state consistent filter."""
    a = (1.0 - level) / 2.0
    return float(stats.chi2.ppf(a, n * runs) / runs), float(stats.chi2.ppf(1.0 - a, n * runs) / runs)


#: How the IMM is gated in clutter: on its modes' own predictions (the file's nearest neighbour, which gates every
#: IMM so: it declares ``FilterSpec.gate_candidates``) or on its moment-matched mixture
#: (``NearestNeighbour(gate, filter_candidates=False)``).
IMM_GATES = ("mixture", "modes")


def association(scenario: Scenario, imm_gates: str = "mixture"):
    """The file's tracker: every scan's one detection (``direct``) or gated nearest neighbour; with
    ``imm_gates="mixture"`` the nearest neighbour gated on a filter's moment-matched prediction (for an IMM its
    mixture), with ``"modes"`` the file's own nearest neighbour (an IMM gated on its modes; any other filter the
    same as ``"mixture"``)."""
    if imm_gates not in IMM_GATES:
        raise InputError(f"imm_gates must be one of {', '.join(IMM_GATES)}, got {imm_gates!r}")
    if scenario.tracker == "direct":
        return Direct()
    if scenario.tracker == "nearest-neighbour":
        return NearestNeighbour(scenario.gate, filter_candidates=imm_gates == "modes")
    raise InputError(f"{scenario.path}: the manoeuvring study runs the direct or nearest-neighbour tracker, not "
                     f"{scenario.tracker!r}")


def evaluate(scenario: Scenario, runs: int, seed: int, steps: int | None = None, host: PluginHost | None = None,
             only: tuple[str, ...] | None = None, imm=None, imm_gates: str = "mixture") -> dict[str, dict]:
    """``{label: figures}`` of each filter over ``runs`` runs: ``rmse_m``, ``rmse_turns_m``, ``mean_nees``,
    ``nees_straight`` and ``nees_turns`` (the mean NEES over the scans on the straight legs and in the turns),
    ``nees_in_band`` (share of scans whose run-averaged NEES is inside its 95 % band), ``per_scan_nees (T,)``,
    ``band``, ``lost`` (share of runs ending more than :data:`LOST_M` off) and, with a gated tracker, ``updated``
    (share of scans updated with a detection).  ``imm``: another IMM spec to run instead of the file's (tuning);
    ``imm_gates``: how the IMM (only) is gated in clutter (:data:`IMM_GATES`; the single-model filters keep the
    file's nearest neighbour).  The default ``"mixture"`` is the gate scripts/imm_tuning.py's recorded rule v2 ran
    with; scripts/manoeuvring_study.py passes ``"modes"`` (the file's nearest neighbour) unless told otherwise."""
    host = host or load_host()
    states, scans, prior, turning = simulate(scenario, runs, seed, steps, host)
    model = host.sensor(scenario.sensor.plugin).configure(**scenario.sensor.params).measurement_model()
    lo, hi = nees_band(runs)
    compared = filters(scenario, host)
    if imm is not None:
        compared[IMM] = (imm, scenario.motion)
    out = {}
    for label, (spec, motion) in compared.items():
        if only is not None and label not in only:
            continue
        gates = imm_gates if label == IMM else "mixture"
        track = run(spec, scans, motion, model, association=association(scenario, gates), prior=prior,
                    rng=generator(seed, "manoeuvring-filter", label))
        err = track.mean - states
        sq = np.sum(err[..., :2] ** 2, axis=-1)
        e = np.linalg.solve(track.cov, err[..., None])[..., 0]
        nees = np.einsum("btn,btn->bt", err, e)
        per_scan = nees.mean(axis=0)
        figures = {"rmse_m": float(np.sqrt(sq.mean())), "rmse_turns_m": float(np.sqrt(sq[:, turning].mean())),
                   "mean_nees": float(nees.mean()), "nees_straight": float(nees[:, ~turning].mean()),
                   "nees_turns": float(nees[:, turning].mean()), "per_scan_nees": per_scan,
                   "nees_in_band": float(np.mean((per_scan >= lo) & (per_scan <= hi))), "band": (lo, hi)}
        figures["lost"] = float(np.mean(np.sqrt(sq[:, -1]) > LOST_M))
        if scenario.tracker != "direct":
            figures["updated"] = float(track.records["updated"][:, 1:].mean())
        out[label] = figures
    return out
