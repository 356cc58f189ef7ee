"""Scenario files (TOML): validated once on load, then run by ``workbench run``.

A scenario names a motion model, a truth (start state or manoeuvre legs), a sensor plugin, optional
clutter generators and removers, a prior and the filters to compare.  Every key is checked on load:
an unknown key, a wrong unit, a negative standard deviation or a plugin that is not installed gives an
error naming the file, the key and what was expected.  See ``docs/scenarios.md``.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .filtering import run_filter
from .metrics import position_sq_error
from .models import MotionModel, constant_velocity, random_walk_velocity, range_rate_model
from .plugins import PluginHost, UnknownComponent
from .rng import generator
from .trajectory import Leg, piecewise_trajectory, sample_motion
from .types import Gaussian, InputError, Scans, Truth
from .units import parse_quantity

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["Component", "Scenario", "load_scenario", "run_scenario", "ScenarioResult"]

MOTION_MODELS = ("constant_velocity", "random_walk_velocity", "range_rate")
TRACKERS = ("direct", "nearest-neighbour", "multi-target")
DETECTION_FORMATS = ("sonar", "pcl")


@dataclass(frozen=True)
class Component:
    """A plugin reference with its parameters (already converted to SI)."""

    plugin: str
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Scenario:
    path: Path
    name: str
    seed: int
    runs: int
    steps: int
    dt: float
    motion: MotionModel
    initial_state: np.ndarray
    initial_std: np.ndarray
    legs: tuple[Leg, ...]
    sensor: Component
    clutter: tuple[Component, ...]
    removers: tuple[Component, ...]
    prior_mean: np.ndarray
    prior_std: np.ndarray
    filters: tuple[str, ...]
    tracker: str
    gate: float | None = None
    detections: Path | None = None
    detections_format: str = ""


class _Reader:
    """Reads one TOML table, remembering which keys were used so unknown ones can be reported."""

    def __init__(self, path: Path, table: Mapping, name: str):
        if not isinstance(table, Mapping):
            raise InputError(f"{path}: [{name}] must be a table, got {type(table).__name__}")
        self.path, self.table, self.name, self.used = path, table, name, set()

    def where(self, key: str) -> str:
        return f"{self.path}: [{self.name}] {key}"

    def get(self, key: str, default: Any = ...):
        self.used.add(key)
        if key not in self.table:
            if default is ...:
                raise InputError(f"{self.where(key)}: missing (required)")
            return default
        return self.table[key]

    def quantity(self, key: str, dimension: str | None, default: Any = ..., minimum: float | None = None) -> float:
        value = parse_quantity(self.get(key, default), dimension, self.where(key))
        if minimum is not None and value < minimum:
            raise InputError(f"{self.where(key)}: must be >= {minimum}, got {value}")
        return value

    def integer(self, key: str, default: Any = ..., minimum: int = 0) -> int:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise InputError(f"{self.where(key)}: expected an integer >= {minimum}, got {value!r}")
        return value

    def vector(self, key: str, length: int | None, default: Any = ..., nonneg: bool = False,
               dimension: str | None = None) -> np.ndarray:
        value = self.get(key, default)
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{self.where(key)}: expected a list of numbers, got {value!r}")
        arr = np.array([parse_quantity(v, dimension, f"{self.where(key)}[{i}]") for i, v in enumerate(value)])
        if length is not None and arr.shape[0] != length:
            raise InputError(f"{self.where(key)}: expected {length} values (the state dimension), got {arr.shape[0]}")
        if nonneg and np.any(arr < 0):
            raise InputError(f"{self.where(key)}: standard deviations must be >= 0, got {arr.tolist()}")
        return arr

    def done(self) -> None:
        unknown = set(self.table) - self.used
        if unknown:
            raise InputError(f"{self.path}: [{self.name}] unknown key(s) {sorted(unknown)} "
                             f"(expected: {', '.join(sorted(self.used))})")


def _component(path: Path, table: Mapping, name: str, registry: Mapping[str, Any], kind: str) -> Component:
    reader = _Reader(path, table, name)
    plugin = reader.get("plugin")
    if plugin not in registry:
        raise InputError(f"{path}: [{name}] plugin: no {kind} named {plugin!r} is installed "
                         f"(installed: {', '.join(sorted(registry)) or 'none'})")
    defaults = dict(registry[plugin].params)
    params = {}
    for key in table:
        if key == "plugin":
            continue
        if defaults and key not in defaults:
            raise InputError(f"{path}: [{name}] unknown parameter {key!r} for {kind} {plugin!r} "
                             f"(parameters: {', '.join(sorted(defaults))})")
        value = table[key]
        params[key] = parse_quantity(value, None, reader.where(key)) if isinstance(value, str) and \
            not isinstance(defaults.get(key), str) else value
    return Component(plugin, params)


def load_scenario(path: Path, host: PluginHost) -> Scenario:
    """Read and validate a scenario file; every problem is reported with the file and key."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such scenario file") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    known = {"scenario", "motion", "truth", "sensor", "clutter", "remover", "prior", "filters", "detections"}
    unknown = set(raw) - known
    if unknown:
        raise InputError(f"{path}: unknown table(s) {sorted(unknown)} (expected: {', '.join(sorted(known))})")
    recorded = "detections" in raw
    required = ("scenario", "motion", "sensor", "filters") + (() if recorded else ("truth", "prior"))
    for table in required:
        if table not in raw:
            raise InputError(f"{path}: missing table [{table}]")

    sc = _Reader(path, raw["scenario"], "scenario")
    name = sc.get("name")
    if not isinstance(name, str) or not name:
        raise InputError(f"{sc.where('name')}: expected a non-empty string")
    seed, runs, steps = sc.integer("seed", 0), sc.integer("runs", 1, 1), sc.integer("steps", minimum=2)
    dt = sc.quantity("dt", "time", minimum=1e-12)
    tracker = sc.get("tracker", "direct")
    if tracker not in TRACKERS:
        raise InputError(f"{sc.where('tracker')}: expected one of {TRACKERS}, got {tracker!r}")
    gate = sc.quantity("gate", None, None, minimum=1e-12) if "gate" in sc.table else None
    sc.done()

    detections, det_format = None, ""
    if recorded:
        de = _Reader(path, raw["detections"], "detections")
        detections = (path.parent / str(de.get("file"))).resolve()
        det_format = de.get("format")
        if det_format not in DETECTION_FORMATS:
            raise InputError(f"{de.where('format')}: expected one of {DETECTION_FORMATS}, got {det_format!r}")
        if not detections.exists():
            raise InputError(f"{de.where('file')}: no such file {detections}")
        de.done()
        if tracker == "direct":
            raise InputError(f"{sc.where('tracker')}: recorded detections need a tracker that associates "
                             f"('nearest-neighbour' or 'multi-target'), not 'direct'")

    mo = _Reader(path, raw["motion"], "motion")
    kind = mo.get("model")
    if kind not in MOTION_MODELS:
        raise InputError(f"{mo.where('model')}: expected one of {MOTION_MODELS}, got {kind!r}")
    if kind == "range_rate":
        motion = range_rate_model(dt, mo.quantity("sigma_a", "acceleration", minimum=0.0))
    else:
        dims = mo.integer("dims", 2, 1)
        if kind == "constant_velocity":
            motion = constant_velocity(dims, dt, mo.quantity("sigma_a", "acceleration", minimum=0.0))
        else:
            motion = random_walk_velocity(dims, dt, mo.quantity("sigma_v", "speed", minimum=0.0))
    mo.done()
    n = motion.dim

    tr = _Reader(path, raw.get("truth", {"initial_state": [0.0] * n}), "truth")
    x0 = tr.vector("initial_state", n)
    x0_std = tr.vector("initial_std", n, [0.0] * n, nonneg=True)
    legs_raw = tr.get("legs", [])
    legs = []
    for i, leg in enumerate(legs_raw):
        lr = _Reader(path, leg, f"truth.legs[{i}]")
        legs.append(Leg(lr.get("kind"), lr.quantity("duration", "time", minimum=1e-12),
                        lr.quantity("turn_rate", None, 0.0), lr.quantity("climb_rate", "speed", 0.0)))
        lr.done()
    tr.done()

    sensor_raw = raw["sensor"]
    sensor = _component(path, sensor_raw, "sensor", host.components["workbench_sensors"], "sensor")
    clutter = tuple(_component(path, c, f"clutter[{i}]", host.components["workbench_clutter_generators"],
                               "clutter generator") for i, c in enumerate(raw.get("clutter", [])))
    removers = tuple(_component(path, c, f"remover[{i}]", host.components["workbench_clutter_removers"],
                                "clutter remover") for i, c in enumerate(raw.get("remover", [])))

    pr = _Reader(path, raw.get("prior", {}), "prior")
    # Without a prior mean the nearest-neighbour tracker starts on the first scan's strongest detection;
    # the multi-target tracker initiates its own tracks and needs no prior.
    optional = tracker != "direct"
    prior_mean = pr.vector("mean", n) if ("mean" in pr.table or not optional) else np.full(n, np.nan)
    prior_std = pr.vector("std", n, nonneg=True) if ("std" in pr.table or not optional) else np.full(n, np.nan)
    pr.done()
    if tracker == "nearest-neighbour" and np.isnan(prior_std).any():
        raise InputError(f"{pr.where('std')}: the nearest-neighbour tracker needs the prior's standard deviations")

    fl = _Reader(path, raw["filters"], "filters")
    names = fl.get("names")
    if not isinstance(names, list) or not names or not all(isinstance(x, str) for x in names):
        raise InputError(f"{fl.where('names')}: expected a non-empty list of filter names")
    for fname in names:
        try:
            host.filter(fname)
        except UnknownComponent as exc:
            raise InputError(f"{fl.where('names')}: {exc}") from None
    fl.done()
    return Scenario(path, name, seed, runs, steps, dt, motion, x0, x0_std, tuple(legs), sensor, clutter,
                    removers, prior_mean, prior_std, tuple(names), tracker, gate, detections, det_format)


@dataclass(frozen=True)
class ScenarioResult:
    out: Path
    name: str
    rmse: Mapping[str, float]
    diagnostics: Mapping[str, Mapping[str, float]]
    lines: tuple[str, ...] = ()

    def summary_text(self) -> str:
        lines = [f"scenario {self.name}: results in {self.out}"]
        for fname, value in self.rmse.items():
            lines.append(f"  {fname:12s} position RMSE (time-averaged) {value:.4g}")
        lines.extend(f"  {line}" for line in self.lines)
        return "\n".join(lines)


def simulate(scenario: Scenario, host: PluginHost, seed: int) -> tuple[Truth | None, Scans]:
    """Truth and detections (sensor, then clutter, then removers) for all runs; recorded detections
    (no truth) when the scenario names a file."""
    if scenario.detections is not None:
        from .recorded import load_pcl_candidates, load_sonar_csv

        loader = load_sonar_csv if scenario.detections_format == "sonar" else load_pcl_candidates
        scans = loader(scenario.detections)
        for comp in scenario.removers:
            scans = host.clutter_remover(comp.plugin).remove(scans, **comp.params)
        return None, scans
    rng = generator(seed, "scenario", scenario.name)
    if scenario.legs:
        dims = scenario.motion.dim // 2
        one = piecewise_trajectory(scenario.initial_state[:dims], scenario.initial_state[dims:], scenario.legs,
                                   scenario.dt)
        states = np.repeat(one.states, scenario.runs, axis=0)[:, : scenario.steps]
        truth = Truth(states, one.times[: scenario.steps])
    else:
        start = scenario.initial_state + rng.standard_normal((scenario.runs, scenario.motion.dim)) * scenario.initial_std
        truth = sample_motion(start, scenario.motion, scenario.steps, rng)
    sensor = host.sensor(scenario.sensor.plugin)
    scans = sensor.simulate(truth, rng, **scenario.sensor.params)
    for comp in scenario.clutter:
        scans = scans.merge(host.clutter_generator(comp.plugin).generate(truth, rng, **comp.params))
    for comp in scenario.removers:
        scans = host.clutter_remover(comp.plugin).remove(scans, **comp.params)
    return truth, scans


def _position_dims(motion: MotionModel) -> int:
    return motion.dim // 2


def _track_single(scenario, spec, model, scans, seed):
    """Direct (one detection per scan) or nearest-neighbour tracking of one target, batched over runs."""
    rng = generator(seed, "filter", spec.name)
    B = scans.batch
    if scenario.tracker == "direct":
        prior = Gaussian.broadcast(scenario.prior_mean, np.diag(scenario.prior_std**2), B)
        return run_filter(spec, prior, scenario.motion, model, scans, rng)
    from .tracking import NearestNeighbour, run, strongest_candidate_prior

    cov0 = np.diag(scenario.prior_std**2)
    if np.isnan(scenario.prior_mean).any():
        if scans.snr is None or model.H is None or model.dim != scenario.motion.dim:
            raise InputError(f"{scenario.path}: [prior] mean is needed: starting on the strongest detection "
                             "needs detection strengths and a measurement of the whole state")
        prior, index = strongest_candidate_prior(scans.scan(0), cov0, np.zeros(scenario.motion.dim))
    else:
        prior, index = Gaussian.broadcast(scenario.prior_mean, cov0, B), None
    track = run(spec, scans, scenario.motion, model, association=NearestNeighbour(scenario.gate, prior_index=index),
                prior=prior, rng=rng)
    updated = track.records["updated"]
    return track.__class__(track.filter, track.mean, track.cov, track.predicted_mean, {
        "frames_updated": float(updated.sum()), "frames_coasted": float((~updated[:, 1:]).sum())}, track.records,
        track.seconds)


def run_scenario(scenario: Scenario, host: PluginHost, out: Path, seed: int | None = None) -> ScenarioResult:
    """Run every filter of the scenario on the same truth and detections; write NPZ, JSON and plots."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    from tqdm.auto import tqdm

    seed = scenario.seed if seed is None else seed
    truth, scans = simulate(scenario, host, seed)
    sensor = host.sensor(scenario.sensor.plugin)
    model = sensor.measurement_model(**scenario.sensor.params)
    dims = _position_dims(scenario.motion)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"times": scans.times, "z": scans.z, "valid": scans.valid}
    if truth is not None:
        arrays["truth"] = truth.states
    rmse, diag, lines = {}, {}, []
    fig = Figure(figsize=(10, 4.5), layout="constrained")
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    shown = scans.valid[0]
    ax1.plot(scans.z[0][shown][:, 0], scans.z[0][shown][:, 1 if scans.z.shape[-1] > 1 else 0], ".",
             color="0.7", ms=3, label="detections")
    if truth is not None:
        ax1.plot(truth.states[0, :, 0], truth.states[0, :, 1 if dims > 1 else 0], "k-", label="truth")
    for fname in tqdm(scenario.filters, desc=f"scenario {scenario.name}", unit="filter", leave=False,
                      disable=None):
        spec = host.filter(fname)
        try:
            if scenario.tracker == "multi-target":
                from .tracking import CONFIRMED, TrackerConfig, run_tracker

                config = TrackerConfig(gate=scenario.gate) if scenario.gate else TrackerConfig()
                log = run_tracker(scans, spec, scenario.motion, model, config, seed=seed, key=("tracker", fname))
                arrays.update(log.to_arrays(prefix=f"{fname}_"))
                counts = log.confirmed_counts()
                lines.append(f"{fname:12s} confirmed tracks per scan (run 0): {counts[0].tolist()}")
                conf = (log.status == CONFIRMED) & (log.run == 0)
                ax1.plot(log.mean[conf, 0], log.mean[conf, 1], "o", mfc="none", ms=5, label=f"{fname} confirmed")
                ax2.step(np.arange(scans.steps), counts.mean(axis=0), where="mid", label=fname)
                continue
            est = _track_single(scenario, spec, model, scans, seed)
        except InputError as exc:
            raise InputError(f"{scenario.path}: filter {fname!r}: {exc}") from None
        arrays[f"mean_{fname}"] = est.mean
        arrays[f"cov_{fname}"] = est.cov
        diag[fname] = {k: float(v) for k, v in est.diagnostics.items()}
        ax1.plot(est.mean[0, :, 0], est.mean[0, :, 1 if dims > 1 else 0], label=fname)
        if truth is not None:
            err = position_sq_error(truth.states, est.mean, dims)
            arrays[f"sq_error_{fname}"] = err
            rmse[fname] = float(np.sqrt(err.mean(axis=0)).mean())
            ax2.semilogy(truth.times, np.sqrt(err.mean(axis=0)), label=fname)
        else:
            ax2.plot(scans.times, est.mean[0, :, 0], label=fname)
    np.savez_compressed(out / "results.npz", **arrays)
    (out / "summary.json").write_text(json.dumps({
        "scenario": scenario.name, "seed": seed, "runs": scans.batch, "steps": scans.steps,
        "tracker": scenario.tracker, "detections": str(scenario.detections or "simulated"),
        "position_rmse": rmse, "diagnostics": diag, "notes": lines}, indent=2))
    ax1.set(title="run 0", xlabel="z[0]", ylabel="z[1]")
    if scenario.tracker == "multi-target":
        ax2.set(title="confirmed tracks per scan (mean over runs)", xlabel="scan", ylabel="tracks")
    elif truth is not None:
        ax2.set(title=f"position RMSE over {scans.batch} runs", xlabel="time (s)", ylabel="RMSE")
    else:
        ax2.set(title="estimated state[0] (no truth: recorded data)", xlabel="time (s)", ylabel="state[0]")
    ax1.legend(fontsize=7)
    ax2.legend(fontsize=7)
    fig.savefig(out / "tracks.png", dpi=110)
    return ScenarioResult(out, scenario.name, rmse, diag, tuple(lines))
