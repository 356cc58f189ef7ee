"""Scenario files (TOML): validated once on load, then run by ``workbench run``.

A scenario names a motion model, a truth (start state or manoeuvre legs), a sensor plugin, optional
clutter generators and removers, a prior and the filters to compare (each with its own parameters).  Every key
is checked on load: an unknown key, a wrong type or unit, a NaN, a value out of its declared range, a plugin
that is not installed, components whose measurement frames do not match, or a request that would not fit in
memory gives an error naming the file, the key and what was expected.  With recorded detections, every key that
the file also supplies (steps, dt, runs, the carrier, the geometry, the sensor's position) is either honoured or
must agree with the file, else the error names both; any other ``[sensor]`` key that the recorded run would not
use (by the sensor's declared :attr:`~workbench.params.Param.affects`) is refused.  ``run_scenario`` lists what it
wrote in ``--out`` in :data:`MANIFEST` and removes an earlier run's files that it does not write again.  See
``docs/scenarios.md``.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .filtering import run_filter
from .frames import FRAMES, check_same_frame
from .metrics import position_sq_error
from .models import MotionModel, constant_velocity, random_walk_velocity, range_rate_model
from .params import memory_limit, when_text
from .plugins import PluginHost
from .rng import generator
from .trajectory import Leg, piecewise_trajectory, sample_motion
from .truth import BirthProcess, MultiTruth, ObjectSpec, simulate_objects
from .types import Gaussian, InputError, Scans, Truth
from .textfields import ImplausibleValueWarning
from .units import parse_quantity

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["Component", "Scenario", "load_scenario", "run_scenario", "ScenarioResult"]

MOTION_MODELS = ("constant_velocity", "random_walk_velocity", "range_rate")
TRACKERS = ("direct", "nearest-neighbour", "multi-target")
#: :attr:`Scenario.tracker` of a scenario with several objects: the installed trackers of ``[trackers]`` run.
INSTALLED_TRACKERS = "installed-trackers"
DETECTION_FORMATS = ("sonar", "pcl")
#: The measurement frame of each recorded-detection format.
FORMAT_FRAMES = {"sonar": "cartesian-2d", "pcl": "bistatic-range-rate"}
#: A scenario may ask for at most this share of the machine's memory (truth, detections and estimates).
MEMORY_SHARE = 0.5
#: A recorded file that gives its own scan times: ``[scenario] dt`` must lie within its shortest and longest
#: interval, widened by this share (``dt`` is then not used: every step's model is built from the actual interval).
DT_TOLERANCE = 0.01
#: ``workbench run`` lists the files it wrote in this file of its ``--out`` folder, so that a later run into the
#: same folder removes those it does not write again (and touches nothing else).
MANIFEST = "workbench-run.json"
#: The names ``workbench run`` writes (besides ``tracks-<filter>.csv``).
OUTPUT_NAMES = ("results.npz", "summary.json", "tracks.npz", "tracks.png")


@dataclass(frozen=True)
class Component:
    """A plugin reference with its parameters (checked against its declarations, converted to SI).

    ``label`` is how reports and results name it: the plugin name, or ``name(key=value, ...)`` when parameters
    are set (filters).
    """

    plugin: str
    params: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            object.__setattr__(self, "label", self.plugin)


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
    filters: tuple[Component, ...]
    tracker: str
    gate: float | None = None
    detections: Path | None = None
    detections_format: str = ""
    frame: str = ""
    #: the recorded file as read and checked on load (:class:`Recorded`), or None
    recorded: Any = field(default=None, compare=False, repr=False)
    #: warnings about the scenario's inputs (implausible recorded values), with the numbers
    notes: tuple[str, ...] = ()
    #: the truth's own motion model (``[truth] motion``), or None: the truth moves as :attr:`motion` says
    truth_motion: MotionModel | None = None
    #: several objects per run (:mod:`workbench.truth`): the listed ``[[targets]]`` and the ``[births]`` process
    targets: tuple[ObjectSpec, ...] = ()
    births: BirthProcess | None = None
    #: the installed trackers of ``[trackers]`` (each run with every filter of ``[filters]``), and the GOSPA / OSPA
    #: cut-off (m) and order that score them
    trackers: tuple[Component, ...] = ()
    cutoff: float = 10.0
    order: float = 2.0

    @property
    def multi(self) -> bool:
        """Whether the scenario has several objects per run (``[[targets]]`` or ``[births]``)."""
        return bool(self.targets) or self.births is not None

    @property
    def filter_names(self) -> tuple[str, ...]:
        """The filters' labels, in order."""
        return tuple(f.label for f in self.filters)


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


def _component(path: Path, table: Mapping, name: str, lookup: Callable[[str], Any], kind: str) -> Component:
    """``plugin = "..."`` and that component's parameters, checked against its declarations (type, unit, range).
    ``lookup`` is the host's getter for the kind (``host.sensor``): the name is found, or refused, as on the command
    line (a filter named as a sensor is called a filter)."""
    from .plugins import UnknownComponent

    reader = _Reader(path, table, name)
    plugin = reader.get("plugin")
    if not isinstance(plugin, str):
        raise InputError(f"{reader.where('plugin')}: expected a {kind} name, got {plugin!r}")
    try:
        spec = lookup(plugin)
    except UnknownComponent as exc:
        raise InputError(f"{path}: [{name}] plugin: {exc}") from None
    values = {key: value for key, value in table.items() if key != "plugin"}
    try:
        params = spec.check(**values)
    except InputError as exc:
        raise InputError(f"{path}: [{name}] {exc}") from None
    return Component(plugin, params)


def _filters(path: Path, table: Mapping, host: PluginHost) -> tuple[Component, ...]:
    """``names = ["kf", {name = "sir", particles = 2000}, "ukf(alpha=0.5)"]``: each checked against its filter's
    declared parameters, by the same rules (and with the same messages) as ``--filters``
    (:mod:`workbench.references`)."""
    from .references import FILTER_FORMS, filter_list

    fl = _Reader(path, table, "filters")
    names = fl.get("names")
    fl.done()
    if not isinstance(names, list):
        raise InputError(f"{fl.where('names')}: expected a list of filters ({FILTER_FORMS}, or a table "
                         f"{{name = \"sir\", particles = 2000}}), got {names!r}")
    refs = filter_list(host, names, fl.where("names"), lambda i, entry: f"{fl.where('names')}[{i}]")
    return tuple(Component(r.base, dict(r.changed), r.key) for r in refs)


def _older_motion(mo: _Reader, kind: str, dt: float) -> MotionModel:
    """The scenario's older motion keys (still read): ``model = "constant_velocity"`` with ``dims`` and ``sigma_a``,
    ``"random_walk_velocity"`` with ``dims`` and ``sigma_v``, ``"range_rate"`` with ``sigma_a``."""
    if kind == "range_rate":
        return range_rate_model(dt, mo.quantity("sigma_a", "acceleration", minimum=0.0))
    dims = mo.integer("dims", 2, 1)
    if kind == "constant_velocity":
        return constant_velocity(dims, dt, mo.quantity("sigma_a", "acceleration", minimum=0.0))
    return random_walk_velocity(dims, dt, mo.quantity("sigma_v", "speed", minimum=0.0))


def _motion_model(host: PluginHost, where: str, entry: Any, dt: float, keys: Mapping[str, Any],
                  key_where: Callable[[str], str]) -> tuple[MotionModel, int | None]:
    """An installed motion model named by ``entry`` (``"name"`` or ``"name(key=value, ...)"``, read as
    ``--filters`` reads a filter), its parameters also given as ``keys`` beside it; built for steps of ``dt``.
    Returns the model and its declared number of position axes."""
    from .params import parse_reference
    from .plugins import UnknownComponent

    installed = sorted(host.motion_models)
    forms = (f"one of the installed motion models ({', '.join(installed) or 'none'}), written as a name or "
             f"'name(key=value, ...)', or one of the older forms {', '.join(MOTION_MODELS)}")
    if not isinstance(entry, str) or not entry.strip():
        raise InputError(f"{where}: expected {forms}; got {entry!r}")
    base, values = parse_reference(entry, where)
    if base not in host.motion_models:
        try:
            host.motion_model_spec(base)
        except UnknownComponent as exc:
            other = str(exc).split(" (installed")[0] if " is a " in str(exc) else ""
            raise InputError(f"{where}: expected {forms}; got {entry!r}" + (f" ({other})" if other else "")) from None
    both = sorted(set(values) & set(keys))
    if both:
        raise InputError(f"{key_where(both[0])}: given twice, here and in the reference {entry!r}; give it once")
    spec = host.motion_models[base]
    try:
        configured = spec.configure(**values, **keys)
        return configured.model(dt), spec.dims
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


def check_request_size(path: Path, runs: int, steps: int, n: int, filters: int, detections: int = 1) -> None:
    """Refuse a scenario whose arrays would not fit: truth, detections and every filter's means and covariances,
    ``8 x runs x steps x (n + 4 detections + filters (n + n^2))`` bytes, against half the machine's memory."""
    need = 8.0 * runs * steps * (n + 5 * detections + filters * (n + n * n))
    limit = MEMORY_SHARE * memory_limit()
    if need > limit:
        raise InputError(f"{path}: [scenario] runs = {runs} x steps = {steps} needs about {need / 2**30:.3g} GiB for the "
                         f"truth, detections and estimates; this machine allows {limit / 2**30:.3g} GiB (half its "
                         f"memory): ask for fewer runs or steps")


def _check_multi_tables(path: Path, raw: Mapping, multi: bool) -> None:
    """Which tables go with several objects per run: ``[[targets]]`` and / or ``[births]`` with ``[trackers]``,
    and neither ``[truth]`` (one object), ``[prior]`` (the trackers start their own tracks) nor recorded
    ``[detections]``."""
    if "trackers" in raw and not multi:
        raise InputError(f"{path}: [trackers] runs installed trackers on several objects per run; list the objects "
                         f"in [[targets]] or declare a [births] process (or remove [trackers])")
    if not multi:
        return
    given = "[[targets]]" if "targets" in raw else "[births]"
    for table, why in (("truth", "holds one object; list every object in [[targets]] instead"),
                       ("prior", "is not used: the trackers initiate their own tracks"),
                       ("detections", "replaces the simulation, which has no truth to list objects in")):
        if table in raw:
            raise InputError(f"{path}: [{table}] {why}; it cannot go with {given}: remove [{table}]")
    if "targets" in raw and (not isinstance(raw["targets"], list) or not raw["targets"]):
        raise InputError(f"{path}: [[targets]] must be one or more tables (write each as [[targets]]), got "
                         f"{raw['targets']!r}")


def _probability(reader: _Reader, key: str) -> float | None:
    if key not in reader.table:
        reader.used.add(key)
        return None
    value = reader.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= float(value) <= 1.0:
        raise InputError(f"{reader.where(key)}: expected a probability in [0, 1], got {value!r}")
    return float(value)


def _targets(path: Path, tables, host: PluginHost, motion: MotionModel, dt: float, steps: int
             ) -> tuple[ObjectSpec, ...]:
    """``[[targets]]``: each with ``initial_state`` (at its first scan), optional ``initial_std``, ``motion`` (an
    installed motion model, default ``[motion]``'s), ``p_d`` (default the sensor's), ``first`` and ``last`` scans
    (default 0 and the last) and ``label``."""
    n = motion.dim
    out = []
    for i, table in enumerate(tables):
        tr = _Reader(path, table, f"targets[{i}]")
        x0 = tr.vector("initial_state", n)
        std = tr.vector("initial_std", n, nonneg=True) if "initial_std" in tr.table else None
        tr.used.add("initial_std")
        own = None
        if "motion" in tr.table:
            entry = tr.get("motion")
            if not isinstance(entry, str):
                raise InputError(f"{tr.where('motion')}: expected a motion model such as \"ct-rate\", got {entry!r}")
            own, _ = _motion_model(host, tr.where("motion"), entry, dt, {}, tr.where)
            if own.dim != n:
                raise InputError(f"{tr.where('motion')}: {entry!r} has a state of {own.dim} components, but [motion] "
                                 f"model {motion.name!r} has {n}: the filters estimate every object's state, so they "
                                 f"must share it")
        tr.used.add("motion")
        p_d = _probability(tr, "p_d")
        first = tr.integer("first", 0, 0)
        last = tr.integer("last", steps - 1, 0) if "last" in tr.table else None
        tr.used.add("last")
        for key, value in (("first", first), ("last", last)):
            if value is not None and value >= steps:
                raise InputError(f"{tr.where(key)}: scan {value} is past the run's last scan ({steps - 1}; [scenario] "
                                 f"steps = {steps})")
        if last is not None and last < first:
            raise InputError(f"{tr.where('last')}: scan {last} comes before first = {first}")
        label = tr.get("label", f"target {i}")
        if not isinstance(label, str):
            raise InputError(f"{tr.where('label')}: expected a name, got {label!r}")
        tr.done()
        out.append(ObjectSpec(x0, std, own, p_d, first, last, label))
    return tuple(out)


def _births(path: Path, table, motion: MotionModel) -> BirthProcess:
    """``[births]``: ``rate`` (births per scan), ``region`` (one ``[low, high]`` pair per position axis),
    ``velocity_std`` (and optional ``velocity_mean``), ``max_objects``, optional ``survival`` and ``p_d``."""
    br = _Reader(path, table, "births")
    rate = br.get("rate")
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (np.isfinite(rate) and rate >= 0):
        raise InputError(f"{br.where('rate')}: expected a number of births per scan >= 0, got {rate!r}")
    region = br.get("region")
    d = motion.dim // 2
    if not isinstance(region, list) or not all(isinstance(r, list) and len(r) == 2 for r in region):
        raise InputError(f"{br.where('region')}: expected one [low, high] pair per position axis, e.g. "
                         f"[[\"0 m\", \"1 km\"], [\"0 m\", \"1 km\"]], got {region!r}")
    if len(region) != d or motion.dim != 2 * d:
        raise InputError(f"{br.where('region')}: {len(region)} axes, but born objects take the state [p, v] of "
                         f"[motion] model {motion.name!r} ({motion.dim} components: {d} position axes)")
    box = [[parse_quantity(v, "length", f"{br.where('region')}[{a}][{j}]") for j, v in enumerate(pair)]
           for a, pair in enumerate(region)]
    for a, (lo, hi) in enumerate(box):
        if not lo < hi:
            raise InputError(f"{br.where('region')}[{a}]: expected low < high, got [{lo:g}, {hi:g}] m")

    def speeds(key: str, default):
        value = br.get(key, default)
        if isinstance(value, list):
            return br.vector(key, d, nonneg=key == "velocity_std", dimension="speed")
        v = parse_quantity(value, "speed", br.where(key))
        if key == "velocity_std" and v < 0:
            raise InputError(f"{br.where(key)}: must be >= 0, got {v}")
        return v

    vstd, vmean = speeds("velocity_std", ...), speeds("velocity_mean", 0.0)
    max_objects = br.integer("max_objects", minimum=1)
    survival = br.get("survival", 1.0)
    if isinstance(survival, bool) or not isinstance(survival, (int, float)) or not 0.0 < survival <= 1.0:
        raise InputError(f"{br.where('survival')}: expected a probability in (0, 1] of living on from one scan to "
                         f"the next, got {survival!r}")
    p_d = _probability(br, "p_d")
    br.done()
    try:
        return BirthProcess(float(rate), box, vstd, max_objects, vmean, float(survival), p_d)
    except InputError as exc:
        raise InputError(f"{path}: [births] {exc}") from None


def _trackers(path: Path, table, host: PluginHost) -> tuple[tuple[Component, ...], float, float]:
    """``[trackers]``: ``names`` (installed trackers: ``"gnn"``, ``"gnn(gate_probability=0.95)"`` or a table
    ``{name = "gnn", gate_probability = 0.95}``), each checked against its declared parameters; ``cutoff`` (the
    GOSPA / OSPA cut-off, default 10 m) and ``order`` (default 2)."""
    from .params import parse_reference
    from .plugins import UnknownComponent

    tk = _Reader(path, table, "trackers")
    names = tk.get("names")
    cutoff = tk.quantity("cutoff", "length", "10 m")
    order = tk.get("order", 2.0)
    tk.done()
    if not cutoff > 0 or not np.isfinite(cutoff):
        raise InputError(f"{tk.where('cutoff')}: must be a finite length > 0, got {cutoff}")
    if isinstance(order, bool) or not isinstance(order, (int, float)) or not (np.isfinite(order) and order >= 1):
        raise InputError(f"{tk.where('order')}: the GOSPA / OSPA order must be a number >= 1, got {order!r}")
    forms = "a tracker name, 'name(key=value, ...)' or a table {name = \"gnn\", gate_probability = 0.95}"
    if not isinstance(names, list) or not names:
        raise InputError(f"{tk.where('names')}: expected a list of installed trackers ({forms}), got {names!r}")
    out, seen = [], set()
    for i, entry in enumerate(names):
        where = f"{tk.where('names')}[{i}]"
        if isinstance(entry, str):
            base, values = parse_reference(entry, where)
        elif isinstance(entry, Mapping) and isinstance(entry.get("name"), str):
            base, values = entry["name"], {k: v for k, v in entry.items() if k != "name"}
        else:
            raise InputError(f"{where}: expected {forms}, got {entry!r}")
        try:
            spec = host.tracker(base)
            checked = spec.check(**values)
        except UnknownComponent as exc:
            raise InputError(f"{where}: {exc}") from None
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        changed = spec.changed(checked)
        label = spec.configure(**changed).name if changed else base
        if label in seen:
            raise InputError(f"{where}: tracker {label!r} is listed twice")
        seen.add(label)
        out.append(Component(base, changed, label))
    return tuple(out), float(cutoff), float(order)


def load_scenario(path: Path, host: PluginHost) -> Scenario:
    """Read and validate a scenario file; every problem is reported with the file and key."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give the scenario's .toml file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such scenario file") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); save it as UTF-8") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    known = {"scenario", "motion", "truth", "sensor", "clutter", "remover", "prior", "filters", "detections",
             "targets", "births", "trackers"}
    unknown = set(raw) - known
    if unknown:
        raise InputError(f"{path}: unknown table(s) {sorted(unknown)} (expected: {', '.join(sorted(known))})")
    recorded = "detections" in raw
    multi = "targets" in raw or "births" in raw
    _check_multi_tables(path, raw, multi)
    required = ("scenario", "motion", "sensor", "filters") + (
        ("trackers",) if multi else () if recorded else ("truth", "prior"))
    for table in required:
        if table not in raw:
            raise InputError(f"{path}: missing table [{table}]")

    sc = _Reader(path, raw["scenario"], "scenario")
    name = sc.get("name")
    if not isinstance(name, str) or not name:
        raise InputError(f"{sc.where('name')}: expected a non-empty string")
    seed, runs, steps = sc.integer("seed", 0), sc.integer("runs", 1, 1), sc.integer("steps", minimum=2)
    dt = sc.quantity("dt", "time", minimum=1e-12)
    if multi:
        for key in ("tracker", "gate"):
            if key in sc.table:
                raise InputError(f"{sc.where(key)}: with [[targets]] or [births] the trackers named in [trackers] "
                                 f"track the objects (each with its own parameters there); remove {key}")
    tracker = sc.get("tracker", "direct")
    if tracker not in TRACKERS:
        raise InputError(f"{sc.where('tracker')}: expected one of {TRACKERS}, got {tracker!r}")
    if multi:
        tracker = INSTALLED_TRACKERS
    gate = sc.quantity("gate", "gate", None, minimum=1e-12) if "gate" in sc.table else None
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
        if detections.is_dir():
            raise InputError(f"{de.where('file')}: {detections} is a folder, not a detection file")
        de.done()
        who = f"the recorded file {detections}"
        if "truth" in raw:
            raise InputError(f"{path}: [truth] is not used with recorded detections ([detections] file: {who} "
                             f"replaces the simulation and has no truth); remove [truth]")
        if raw.get("clutter"):
            raise InputError(f"{path}: [[clutter]] adds simulated clutter, but with recorded detections nothing is "
                             f"simulated ({who} holds the detections, clutter included); remove [[clutter]]")
        if "runs" in sc.table and runs != 1:
            raise InputError(f"{path}: [scenario] runs = {runs}, but {who} holds one run; remove runs (or set it "
                             f"to 1)")
        if tracker == "direct":
            raise InputError(f"{sc.where('tracker')}: recorded detections need a tracker that associates "
                             f"('nearest-neighbour' or 'multi-target'), not 'direct'")

    mo = _Reader(path, raw["motion"], "motion")
    kind = mo.get("model")
    if kind in MOTION_MODELS:
        motion, axes = _older_motion(mo, kind, dt), None
    else:
        motion, axes = _motion_model(host, mo.where("model"), kind, dt,
                                     {k: v for k, v in mo.table.items() if k != "model"}, mo.where)
        mo.used.update(mo.table)
    mo.done()
    n = motion.dim

    tr = _Reader(path, raw.get("truth", {"initial_state": [0.0] * n}), "truth")
    truth_motion, truth_axes = None, axes
    if "motion" in tr.table:
        entry = tr.get("motion")
        if not isinstance(entry, str):
            raise InputError(f"{tr.where('motion')}: expected a motion model such as \"ct-rate\" or "
                             f"\"ct-rate(sigma_omega=0.01)\", got {entry!r}")
        truth_motion, truth_axes = _motion_model(host, tr.where("motion"), entry, dt, {}, tr.where)
        if truth_motion.dim != n:
            raise InputError(f"{tr.where('motion')}: the truth's motion model {entry!r} has a state of "
                             f"{truth_motion.dim} components ({', '.join(truth_motion.state_names) or 'unnamed'}), "
                             f"but [motion] model {kind!r} has {n} ({', '.join(motion.state_names) or 'unnamed'}): the "
                             f"filters estimate the truth's state, so the two must share it")
    x0 = tr.vector("initial_state", n)
    x0_std = tr.vector("initial_std", n, [0.0] * n, nonneg=True)
    legs_raw = tr.get("legs", [])
    if legs_raw:
        moved_by = truth_motion or motion
        d = truth_axes if truth_axes is not None else moved_by.dim // 2
        if moved_by.dim != 2 * d:
            raise InputError(f"{tr.where('legs')}: legs make states of {d} positions and {d} velocities, but the "
                             f"truth's motion model {moved_by.name!r} has the state "
                             f"({', '.join(moved_by.state_names) or f'{moved_by.dim} components'}); use a "
                             f"constant-velocity model (cv2d, cv3d) with legs, or drop the legs")
    legs = []
    for i, leg in enumerate(legs_raw):
        lr = _Reader(path, leg, f"truth.legs[{i}]")
        legs.append(Leg(lr.get("kind"), lr.quantity("duration", "time", minimum=1e-12),
                        lr.quantity("turn_rate", "angular_rate", 0.0), lr.quantity("climb_rate", "speed", 0.0)))
        lr.done()
    tr.done()

    sensor_raw = raw["sensor"]
    sensor = _component(path, sensor_raw, "sensor", host.sensor, "sensor")
    clutter = tuple(_component(path, c, f"clutter[{i}]", host.clutter_generator,
                               "clutter generator") for i, c in enumerate(raw.get("clutter", [])))
    removers = tuple(_component(path, c, f"remover[{i}]", host.clutter_remover,
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

    filters = _filters(path, raw["filters"], host)
    targets, births, trackers, cutoff, order = (), None, (), 10.0, 2.0
    if multi:
        targets = _targets(path, raw.get("targets", []), host, motion, dt, steps)
        births = _births(path, raw["births"], motion) if "births" in raw else None
        trackers, cutoff, order = _trackers(path, raw["trackers"], host)
        declared = {q.name for q in host.sensor(sensor.plugin).declared}
        own = [(f"[targets[{i}]] p_d", t.p_d) for i, t in enumerate(targets) if t.p_d is not None]
        own += [("[births] p_d", births.p_d)] if births is not None and births.p_d is not None else []
        if own and "pd" not in declared:
            raise InputError(f"{path}: {own[0][0]} = {own[0][1]:g}, but sensor {sensor.plugin!r} declares no parameter "
                             f"'pd' that sets its detection probability, so an object's own p_d cannot be honoured; "
                             f"remove it or use a sensor with one")
    frame = _check_frames(path, host, sensor, clutter, removers, tracker, det_format,
                          tuple(host.tracker(c.plugin) for c in trackers))
    data, notes = None, ()
    if recorded:
        data, notes = _read_recorded(path, detections, det_format, dt, steps, host, sensor)
        for note in notes:  # kept in Scenario.notes too; the command line prints them as its own warning lines
            warnings.warn(note, ImplausibleValueWarning, stacklevel=2)
    elif multi:
        objects = len(targets) + (births.max_objects if births is not None else 0)
        check_request_size(path, runs, steps, n * objects, len(filters) * len(trackers), objects + len(clutter))
    else:
        check_request_size(path, runs, steps, n, len(filters), 1 + len(clutter))
    return Scenario(path, name, seed, runs, steps, dt, motion, x0, x0_std, tuple(legs), sensor, clutter,
                    removers, prior_mean, prior_std, filters, tracker, gate, detections, det_format, frame, data,
                    tuple(notes), truth_motion, targets, births, trackers, cutoff, order)


@dataclass(frozen=True)
class Recorded:
    """A recorded file as a scenario reads it: the detections and, for sonar files that give one, the own ship."""

    scans: Scans
    own_ship: Any = None


def _said(path: Path, plugin: str, given: Mapping, key: str, text: str) -> str:
    how = "given" if key in given else f"the default of sensor {plugin!r}"
    return f"{path}: [sensor] {key} = {text} ({how})"


def _read_recorded(path: Path, file: Path, fmt: str, dt: float, steps: int, host: PluginHost, sensor: Component
                   ) -> tuple[Recorded, tuple[str, ...]]:
    """Read the recorded file and hold it to the scenario: every key the file also supplies is either passed to
    the reader (honoured) or must agree with the file, else an error names both (the scenario's key and the file's
    value), and a ``[sensor]`` key that nothing would use is refused (:func:`_check_sensor_keys`).  Returns the data
    and the readers' warnings about implausible values."""
    from .recorded import load_pcl_candidates, load_sonar_recording, pcl_metadata
    from .recorded.pcl import check_carrier

    spec = host.sensor(sensor.plugin)
    given = dict(sensor.params)
    effective = {**dict(spec.params or {}), **given}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ImplausibleValueWarning)
        if fmt == "sonar":
            # a ping-numbered file takes its times from [scenario] dt (honoured); a polar file without own-ship
            # columns is measured from the sensor's position (honoured)
            position = effective.get("sensor")
            rec = load_sonar_recording(file, dt=dt)
            if rec.own_ship is None and rec.frame == "polar" and position is not None and \
                    tuple(float(v) for v in position) != (0.0, 0.0):
                del caught[:]  # the second read gives the first one's warnings again
                rec = load_sonar_recording(file, dt=dt, sensor=tuple(position))
            data, time_column, unit = Recorded(rec.scans, rec.own_ship), ("time" if rec.key == "time" else ""), "pings"
            # the reader places a polar file's detections from the sensor's position, or holds it to the own ship
            reader_keys = {"sensor"} if rec.own_ship is not None or rec.frame == "polar" else set()
            accuracy = ("sigma_x", "sigma_y") if rec.frame == "xy" else ("sigma_range", "sigma_bearing")
            model = spec.measurement_model(**given)
            fixed = model.sensor_position if model.sensor_position is not None else \
                (position if "sensor" in given else None)
            if rec.own_ship is not None and fixed is not None:
                where = np.asarray(fixed, dtype=float)[:2]
                off = np.hypot(*(rec.own_ship.position - where).T)
                k = int(np.argmax(off))
                if off[k] > 1e-6 * max(1.0, float(np.hypot(*where))):
                    text = "(" + ", ".join(f"{v:g}" for v in where) + ")"
                    at = ", ".join(f"{v:g}" for v in rec.own_ship.position[k])
                    raise InputError(f"{_said(path, sensor.plugin, given, 'sensor', text)} places the sensor at one "
                                     f"point, but {file} gives the own ship's position per ping, ({at}) at ping {k}: "
                                     f"the file's own ship is used for the detections, so the sensor's position must "
                                     f"agree with it (or use a model without one, frame = \"cartesian\")")
        else:
            meta = pcl_metadata(file)
            freq = effective.get("frequency_hz")
            if freq is not None:
                freq = check_carrier(float(freq), f"{path}: [sensor] frequency_hz")
                if meta.carrier_hz is not None and abs(freq - meta.carrier_hz) > 1e-9 * meta.carrier_hz:
                    raise InputError(f"{_said(path, sensor.plugin, given, 'frequency_hz', f'{freq / 1e6:g} MHz')}, "
                                     f"but {file} declares carrier_hz {meta.carrier_hz:g} Hz "
                                     f"({meta.carrier_hz / 1e6:g} MHz): one of the two is wrong; make them agree")
            for key, declared in (("tx", meta.transmitter_m), ("rx", meta.receiver_m)):
                if key in effective and effective[key] is not None and declared is not None:
                    mine = np.asarray(effective[key], dtype=float)
                    m = min(mine.size, len(declared))
                    if not np.allclose(mine[:m], declared[:m], rtol=1e-9, atol=1e-6):
                        name = "transmitter_m" if key == "tx" else "receiver_m"
                        text = "(" + ", ".join(f"{v:g}" for v in mine) + ") m"
                        raise InputError(f"{_said(path, sensor.plugin, given, key, text)}, but {file} declares "
                                         f"{name} ({', '.join(f'{v:g}' for v in declared)}) m: make them agree")
            scans = load_pcl_candidates(file, frequency_hz=freq if meta.carrier_hz is None else None)
            data, time_column, unit = Recorded(scans), "time_s", "frames"
            # the reader converts Doppler with the carrier (or holds it to the file's), and holds tx, rx to the file's
            reader_keys = {"frequency_hz"} | {key for key, declared in (("tx", meta.transmitter_m),
                                                                        ("rx", meta.receiver_m)) if declared}
            accuracy = ("sigma_range_m", "sigma_range_rate_mps")
    for w in caught:
        if not issubclass(w.category, ImplausibleValueWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    notes = tuple(str(w.message) for w in caught if issubclass(w.category, ImplausibleValueWarning))
    scans = data.scans
    if not scans.valid.any():
        raise InputError(f"{file}: holds no detection (a header without rows?); nothing to track")
    if scans.steps != steps:
        raise InputError(f"{path}: [scenario] steps = {steps}, but {file} holds {scans.steps} {unit}: every scan "
                         f"of the file is tracked, so steps must be {scans.steps}")
    if time_column and scans.steps > 1:
        gaps = np.diff(scans.times)
        lo, hi = float(gaps.min()), float(gaps.max())
        if not (1 - DT_TOLERANCE) * lo <= dt <= (1 + DT_TOLERANCE) * hi:
            apart = f"{lo:g} s apart" if hi - lo <= 1e-9 * hi else f"{lo:g} to {hi:g} s apart"
            raise InputError(f"{path}: [scenario] dt = {dt:g} s, but {file} gives its own scan times (column "
                             f"'{time_column}'), {apart}: the file's times are used, so dt must agree with them "
                             f"(within {DT_TOLERANCE:.0%})")
    _check_sensor_keys(path, file, spec, sensor.plugin, given, effective, reader_keys,
                       accuracy if scans.cov is not None else ())
    return data, notes


def _check_sensor_keys(path: Path, file: Path, spec, plugin: str, given: Mapping, effective: Mapping,
                       reader_keys: set, accuracy: tuple[str, ...]) -> None:
    """Refuse a ``[sensor]`` key that a run on recorded detections would not use, by the sensor's declarations
    (:attr:`workbench.params.Param.affects`): a key that only shapes simulated detections (the file replaces the
    simulation), one whose ``when`` conditions keep it out of the measurement model, and one that sets the model's
    ``R`` where the file gives each detection its own accuracy (``accuracy``: the file's columns; the filters use
    them instead of ``R``).  Keys in ``reader_keys`` are used or checked by the file's reader and pass.  Each
    error names the key, the scenario file and the recorded file."""
    from .params import format_value

    declared = {p.name: p for p in spec.declared}

    def said(params) -> str:
        return ", ".join(f"{p.name} = {format_value(given[p.name])}{' ' + p.unit_label if p.unit_label else ''}"
                         for p in params)

    chosen = [declared[key] for key in given if key in declared and key not in reader_keys]
    simulated = [p for p in chosen if p.affects == "simulation"]
    if simulated:
        them = "them" if len(simulated) > 1 else "it"
        raise InputError(f"{path}: [sensor] {said(simulated)} only shape{'' if len(simulated) > 1 else 's'} "
                         f"simulated detections (sensor {plugin!r} declares {them} simulation-only), but the "
                         f"recorded file {file} replaces the simulation: nothing would use {them}; remove {them}")
    for p in chosen:
        unmet = p.unmet(effective)
        if unmet:
            needs = ", ".join(when_text(key, want) for key, want in p.when)
            now = ", ".join(f"{key} = {format_value(effective.get(key))}" for key, _ in unmet)
            raise InputError(f"{path}: [sensor] {said([p])} enters the measurement model of sensor {plugin!r} only "
                             f"if {needs} (here {now}), else it only shapes simulated detections, which the recorded "
                             f"file {file} replaces: nothing would use it; remove it")
    noise = [p for p in chosen if p.affects == "noise"] if accuracy else []
    if noise:
        them = "them" if len(noise) > 1 else "it"
        raise InputError(f"{path}: [sensor] {said(noise)} set{'' if len(noise) > 1 else 's'} the filters' "
                         f"measurement noise R, but the recorded file {file} gives each detection its own accuracy "
                         f"(columns {', '.join(accuracy)}), which the filters use instead of R: one of the two would "
                         f"be ignored; remove {them} (or the file's accuracy columns)")


def _check_frames(path: Path, host: PluginHost, sensor: Component, clutter, removers, tracker: str,
                  det_format: str, trackers=()) -> str:
    """The frame of the scenario's detections; components of other frames are refused, naming both.  With
    installed ``trackers`` (specs), one that declares ``cartesian_2d`` needs Cartesian detections (it maps them
    through the sensor's model, as the multi-target tracker does), and any other needs the sensor's model to
    describe the detections."""
    spec = host.sensor(sensor.plugin)
    frame = FORMAT_FRAMES[det_format] if det_format else spec.detection_frame(**sensor.params)
    who = f"the recorded {det_format} file" if det_format else f"sensor {sensor.plugin!r}"
    for i, comp in enumerate(clutter):
        other = host.clutter_generator(comp.plugin).detection_frame(**comp.params)
        try:
            check_same_frame(frame, who, other, f"clutter generator {comp.plugin!r}")
        except InputError as exc:
            raise InputError(f"{path}: [clutter[{i}]] {exc}") from None
    for i, comp in enumerate(removers):
        frames = host.clutter_remover(comp.plugin).frames
        if frame and frames and frame not in frames:
            raise InputError(f"{path}: [remover[{i}]] clutter remover {comp.plugin!r} works on {', '.join(frames)} "
                             f"detections, but {who} makes {frame} detections")
    model = spec.measurement_model(**sensor.params)
    if tracker == INSTALLED_TRACKERS:
        for t in trackers:
            if "cartesian_2d" in t.capabilities and frame and frame != "cartesian-2d":
                raise InputError(f"{path}: [trackers] tracker {t.name!r} takes Cartesian (x, y) detections "
                                 f"(capability cartesian_2d), but {who} makes {frame} detections")
            if "cartesian_2d" not in t.capabilities and frame and model.frame and model.frame != frame:
                raise InputError(f"{path}: [sensor] {who} makes {frame} detections but its measurement model "
                                 f"{model.name!r} describes {model.frame} measurements, and tracker {t.name!r} reads "
                                 f"the detections through that model: choose the sensor's model of its own "
                                 f"detections")
        return frame
    if tracker == "multi-target" and frame and frame != "cartesian-2d":
        raise InputError(f"{path}: [scenario] tracker: the multi-target tracker takes Cartesian (x, y) detections, "
                         f"but {who} makes {frame} detections")
    if tracker != "multi-target" and frame and model.frame and model.frame != frame:
        raise InputError(f"{path}: [sensor] {who} makes {frame} detections but its measurement model "
                         f"{model.name!r} describes {model.frame} measurements: the filters would read one as the "
                         f"other (choose the sensor's model of its own detections, or the multi-target tracker)")
    return frame


@dataclass(frozen=True)
class ScenarioResult:
    """What ``workbench run`` wrote: the folder, each filter's time-averaged position RMSE (m) where there is a
    truth, its diagnostics, the filters that failed (name -> why) and notes."""

    out: Path
    name: str
    rmse: Mapping[str, float]
    diagnostics: Mapping[str, Mapping[str, float]]
    lines: tuple[str, ...] = ()
    failed: Mapping[str, str] = field(default_factory=dict)
    plot: Mapping[str, np.ndarray] = field(default_factory=dict)
    #: several objects per run: each tracker's (``tracker/filter``) mean GOSPA and OSPA (m) over runs and scans
    gospa: Mapping[str, float] = field(default_factory=dict)
    ospa: Mapping[str, float] = field(default_factory=dict)
    #: the Matplotlib figure saved as ``tracks.png`` (drawn through :mod:`workbench.plot`)
    figure: Any = field(default=None, compare=False, repr=False)

    def summary_text(self) -> str:
        lines = [f"scenario {self.name}: results in {self.out}"]
        for fname, value in self.rmse.items():
            lines.append(f"  {fname:12s} position RMSE (time-averaged) {value:.4g} m")
        for fname, value in self.gospa.items():
            lines.append(f"  {fname:12s} mean GOSPA {value:.4g} m, mean OSPA {self.ospa.get(fname, np.nan):.4g} m")
        lines.extend(f"  {line}" for line in self.lines)
        for fname, why in self.failed.items():
            lines.append(f"  {fname:12s} FAILED: {why}")
        return "\n".join(lines)


def _recorded(scenario: Scenario, host: PluginHost) -> Recorded:
    """The scenario's recorded file as read on load (read and checked again when the scenario was built by hand)."""
    if scenario.recorded is not None:
        return scenario.recorded
    data, _ = _read_recorded(scenario.path, scenario.detections, scenario.detections_format, scenario.dt,
                             scenario.steps, host, scenario.sensor)
    return data


def simulate(scenario: Scenario, host: PluginHost, seed: int) -> tuple[Truth | None, Scans]:
    """Truth and detections (sensor, then clutter, then removers) for all runs; recorded detections
    (no truth) when the scenario names a file."""
    if scenario.detections is not None:
        scans = _recorded(scenario, host).scans
        for comp in scenario.removers:
            scans = host.clutter_remover(comp.plugin).remove(scans, **comp.params)
        return None, scans
    if scenario.multi:
        return _simulate_multi(scenario, host, seed)
    rng = generator(seed, "scenario", scenario.name)
    moved_by = scenario.truth_motion or scenario.motion
    if scenario.legs:
        dims = moved_by.dim // 2
        one = piecewise_trajectory(scenario.initial_state[:dims], scenario.initial_state[dims:], scenario.legs,
                                   scenario.dt)
        states = np.repeat(one.states, scenario.runs, axis=0)[:, : scenario.steps]
        truth = Truth(states, one.times[: scenario.steps])
    else:
        start = scenario.initial_state + rng.standard_normal((scenario.runs, moved_by.dim)) * scenario.initial_std
        truth = sample_motion(start, moved_by, scenario.steps, rng)
    sensor = host.sensor(scenario.sensor.plugin)
    # in draw order: the sensor, then each clutter generator; merged in one pass
    scans = Scans.merge_all([sensor.simulate(truth, rng, **scenario.sensor.params)]
                            + [host.clutter_generator(c.plugin).generate(truth, rng, **c.params)
                               for c in scenario.clutter])
    for comp in scenario.removers:
        scans = host.clutter_remover(comp.plugin).remove(scans, **comp.params)
    return truth, scans


def _simulate_multi(scenario: Scenario, host: PluginHost, seed: int) -> tuple[MultiTruth, Scans]:
    """Several objects per run: the listed targets and the born objects (:func:`workbench.truth.simulate_objects`,
    draws from ``generator(seed, "scenario", name, ...)``), every object's detections
    (:func:`workbench.sensing.detect_objects`), then each clutter generator (given object 0 as its truth: they
    read its shape and times), then the removers."""
    from .sensing.objects import detect_objects

    truth = simulate_objects(scenario.targets, scenario.births, runs=scenario.runs, steps=scenario.steps,
                             motion=scenario.truth_motion or scenario.motion, seed=seed,
                             key=("scenario", scenario.name))
    rng = generator(seed, "scenario", scenario.name, "detections")
    sensor = host.sensor(scenario.sensor.plugin)
    scans = Scans.merge_all([detect_objects(sensor, truth, rng, **scenario.sensor.params)]
                            + [host.clutter_generator(c.plugin).generate(truth.as_truth(), rng, **c.params)
                               for c in scenario.clutter])
    for comp in scenario.removers:
        scans = host.clutter_remover(comp.plugin).remove(scans, **comp.params)
    return truth, scans


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


def _non_finite(est) -> str:
    """Why a filter's estimates cannot be used (NaN or inf somewhere, or a covariance that is not positive
    semi-definite, which no track file may hold), or ``""``."""
    for name in ("mean", "cov"):
        values = getattr(est, name)
        if not np.all(np.isfinite(values)):
            b, k = (int(i) for i in np.argwhere(~np.isfinite(values))[0][:2])
            return f"its {name} holds NaN or inf (run {b}, scan {k})"
    from .tracks_io import covariance_problems

    cov = np.asarray(est.cov, dtype=float)
    negative, not_psd = covariance_problems(cov.reshape((-1,) + cov.shape[-2:]))
    bad = negative | not_psd
    if bad.any():
        b, k = np.unravel_index(int(np.flatnonzero(bad)[0]), cov.shape[:-2])
        low = float(np.linalg.eigvalsh(cov[b, k])[0])
        return (f"its cov is not positive semi-definite (run {int(b)}, scan {int(k)}: smallest eigenvalue "
                f"{low:.6g})")
    return ""


def _output_name(name: str) -> bool:
    """Whether ``name`` (a bare file name) is one that ``workbench run`` writes."""
    return name in OUTPUT_NAMES or (name.startswith("tracks-") and name.endswith(".csv") and "/" not in name
                                    and "\\" not in name and name not in (".", ".."))


def _manifest_files(out: Path) -> set[str]:
    """The files an earlier ``workbench run`` recorded writing into ``out`` (only names it writes; nothing when
    there is no manifest or it cannot be read)."""
    try:
        listed = json.loads((out / MANIFEST).read_text(encoding="utf-8")).get("files", [])
    except (OSError, ValueError, AttributeError):
        return set()
    return {name for name in listed if isinstance(name, str) and _output_name(name)}


def _write_manifest(out: Path, scenario: Scenario, files) -> None:
    fd, tmp = tempfile.mkstemp(dir=out, prefix=".manifest-", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump({"written_by": "workbench run", "scenario": scenario.name, "files": sorted(files)}, fh, indent=2)
    os.replace(tmp, out / MANIFEST)


def _check_out(out: Path, planned: set[str]) -> set[str]:
    """Refuse an ``--out`` folder that holds result files this run would neither replace nor remove (files of the
    workbench's names that no earlier run's manifest lists); return the earlier run's files."""
    if not out.is_dir():
        return set()
    earlier = _manifest_files(out)
    strangers = sorted(p.name for p in out.iterdir()
                       if p.is_file() and _output_name(p.name) and p.name not in planned and p.name not in earlier)
    if strangers:
        raise InputError(f"{out}: holds {', '.join(strangers)}, which this run would not write again and no earlier "
                         f"'workbench run' recorded writing ({MANIFEST} does not list "
                         f"{'it' if len(strangers) == 1 else 'them'}): they would lie beside the new results as if "
                         f"they were part of them; move them away or choose another --out")
    return earlier


def _plot_data(scenario: Scenario, model, scans: Scans, truth: Truth | None, estimates: dict, logs: dict
               ) -> dict[str, np.ndarray]:
    """The data behind ``tracks.png`` (saved as ``tracks.npz``): run 0 in the sensor's frame converted to positions
    where the frame has them, the filters' position components (from the motion model's layout), and the RMSE or
    track counts per scan, with the axis labels and units."""
    frame = FRAMES.get(scenario.frame)
    dims = scenario.motion.position_dims
    shown = scans.valid[0]
    planar = frame is not None and frame.position is not None and dims >= 2
    data: dict[str, np.ndarray] = {"times": scans.times}
    if planar:
        pos = frame.to_position(scans.z[0][shown], model.sensor_position if model.frame == frame.name else None)
        data["detections_xy"] = pos[:, :2]
        data["left_labels"] = np.array(["x (m)", "y (m)", "run 0 in the plane"])
    else:
        label = frame.labels()[0] if frame is not None else "measurement component 0"
        k = np.nonzero(shown)[0]
        data["detections_xy"] = np.column_stack([scans.times[k], scans.z[0][shown][:, 0]])
        data["left_labels"] = np.array(["time (s)", label, "run 0: the first measured component over time"])
    if truth is not None:
        data["truth_xy"] = truth.states[0, :, :2] if planar else np.column_stack([truth.times, truth.states[0, :, 0]])
    if planar and scenario.detections is not None and scenario.detections_format == "sonar":
        from .recorded.sonar import load_sonar_recording

        own = scenario.recorded.own_ship if scenario.recorded is not None else \
            load_sonar_recording(scenario.detections, dt=scenario.dt).own_ship
        if own is not None:  # the recording's own ship: where its detections were measured from
            data["own_ship_xy"] = own.position
    for name, est in estimates.items():
        data[f"track_{name}"] = est.mean[0, :, :2] if planar else np.column_stack([scans.times, est.mean[0, :, 0]])
    for name, log in logs.items():
        from .tracking import CONFIRMED

        conf = (log.status == CONFIRMED) & (log.run == 0)
        data[f"confirmed_{name}"] = log.mean[conf, :2]
        data[f"count_{name}"] = log.confirmed_counts().mean(axis=0)
    if logs:
        data["right_labels"] = np.array(["scan", "confirmed tracks (mean over runs)", "confirmed tracks per scan"])
    elif truth is not None:
        for name, est in estimates.items():
            err = position_sq_error(truth.states, est.mean, dims)
            data[f"rmse_{name}"] = np.sqrt(err.mean(axis=0))
        data["right_labels"] = np.array(["time (s)", "position RMSE (m)", f"position RMSE over {scans.batch} runs"])
    elif estimates and all("nis" in est.records for est in estimates.values()):
        for name, est in estimates.items():
            data[f"nis_{name}"] = est.records["nis"]
        data["right_labels"] = np.array(["time (s)", f"NIS (dimensionless; {model.dim} dof)",
                                         "NIS of the updates (no truth: recorded data)"])
    else:
        data["count_detections"] = scans.valid.sum(axis=2).mean(axis=0)
        data["right_labels"] = np.array(["time (s)", "detections per scan (mean over runs)",
                                         "detections (no truth: recorded data)"])
    return data


def _draw_single(fig, data: Mapping[str, np.ndarray], scenario: Scenario, model, scans: Scans,
                 truth: Truth | None, estimates: dict, logs: dict) -> None:
    """``tracks.png`` of a single-target scenario, through :mod:`workbench.plot`: run 0's detections (positions
    where the frame gives them), the truth and each filter's estimate (or each tracker's tracks) with start
    markers, one colour and line style per filter; beside it the position RMSE per step (log axis), each
    filter's NIS with its chi-square band (recorded data), or confirmed tracks per scan (trackers)."""
    from . import plot

    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    frame = FRAMES.get(scenario.frame)
    planar = frame is not None and frame.position is not None and scenario.motion.position_dims >= 2
    dims = (0, 1) if planar else 0
    plot.detections(ax1, scans, model=model, frame=frame, component=None if planar else 0)
    if truth is not None:
        plot.truth(ax1, truth, dims=dims, motion=scenario.truth_motion or scenario.motion)
    if "own_ship_xy" in data:
        ax1.plot(data["own_ship_xy"][:, 0], data["own_ship_xy"][:, 1], "--", color="tab:green", label="own ship",
                 gid="own-ship")
    styles = plot.LINESTYLES
    for i, (name, est) in enumerate(estimates.items()):
        plot.estimate(ax1, est, dims=dims, motion=scenario.motion, times=scans.times, color=f"C{i}",
                      linestyle=styles[i % len(styles)], label=name, linewidth=_width(i))
    for i, (name, log) in enumerate(logs.items()):
        plot.tracks(ax1, log, dims=dims, motion=scenario.motion, times=scans.times, color=f"C{i}",
                    linestyle=styles[i % len(styles)], label=f"{name} confirmed", linewidth=_width(i))
    if not planar:  # the first measured component over time: its own label, not the state's
        ax1.set_ylabel(frame.labels()[0] if frame is not None else "measurement component 0")
    ax1.set_title(str(data["left_labels"][2]))
    for i, (name, log) in enumerate(logs.items()):
        plot.track_counts(ax2, log, times=scans.times, color=f"C{i}", linestyle=styles[i % len(styles)],
                          label=name)
    if not logs and truth is not None:
        for i, (name, est) in enumerate(estimates.items()):
            plot.rmse(ax2, truth, est, motion=scenario.motion, times=scans.times, color=f"C{i}",
                      linestyle=styles[i % len(styles)], label=name, linewidth=_width(i))
    elif not logs:
        for i, name in enumerate(estimates):
            if f"nis_{name}" in data:
                plot.nis(ax2, data[f"nis_{name}"], dof=model.dim, times=scans.times, color=f"C{i}", label=name)
        if "count_detections" in data:
            ax2.step(scans.times, data["count_detections"], where="mid", label="detections", gid="detections")
            ax2.set(xlabel="time (s)", ylabel=str(data["right_labels"][1]))
    ax2.set_title(str(data["right_labels"][2]))
    ax1.legend(fontsize=7)
    ax2.legend(fontsize=7)


def _draw_multi(fig, data: Mapping[str, np.ndarray], scenario: Scenario, model, scans: Scans, truth: MultiTruth,
                logs: dict, per_scan: Mapping[str, np.ndarray]) -> None:
    """``tracks.png`` of a multi-object scenario, through :mod:`workbench.plot`: run 0's clutter and target
    detections, every object's true path (start marked), each tracker's confirmed tracks, one line per track
    identity (a colour and a line style per tracker/filter); beside it GOSPA per scan, mean over runs."""
    from . import plot

    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    frame = FRAMES.get(scenario.frame)
    if frame is not None and frame.position is not None:
        plot.detections(ax1, scans, model=model, frame=frame)
    plot.truth(ax1, truth, motion=scenario.truth_motion or scenario.motion)
    styles = plot.LINESTYLES
    for i, (label, log) in enumerate(logs.items()):
        plot.tracks(ax1, log, motion=scenario.motion, color=f"C{i}", linestyle=styles[i % len(styles)],
                    label=label, linewidth=_width(i))
        plot.gospa(ax2, per_scan[label], times=scans.times, cutoff=scenario.cutoff, order=scenario.order,
                   unit=_position_unit(scenario.motion), color=f"C{i}", linestyle=styles[i % len(styles)],
                   label=label, linewidth=_width(i))
    ax1.set_title(str(data["left_labels"][2]))
    ax2.set_title(str(data["right_labels"][2]))
    ax1.legend(fontsize=7)
    if logs:
        ax2.legend(fontsize=7)


def _width(i: int) -> float:
    """The line width of the ``i``-th filter or tracker drawn on one Axes: the first widest, so that a later one
    drawn over it (dashed) leaves it visible where the two agree."""
    return max(2.4 - 0.6 * i, 0.9)


def _position_unit(motion: MotionModel) -> str | None:
    """The declared unit of the motion model's first (position) component, or ``None``."""
    units = tuple(motion.state_units)
    return units[0] if len(units) == motion.dim and motion.position_dims else None


def _recorded_line(scans: Scans, estimates: dict, logs: dict, model) -> str:
    """The console summary of a recorded-data run: scans, detections, tracks (and each filter's updates and mean
    NIS against the chi-square band of a mean of that many updates)."""
    from .plot import chi2_band

    parts = []
    for name, est in estimates.items():
        text = f"{name}: 1 track"
        if "updated" in est.records:
            updated = np.asarray(est.records["updated"], dtype=bool)[:, 1:]
            text += f", updated on {int(updated.sum())} and coasted on {int((~updated).sum())} scans"
        if "nis" in est.records:
            nis = np.asarray(est.records["nis"], dtype=float)
            nis = nis[np.isfinite(nis)]
            if nis.size:
                lo, hi = (float(v) for v in chi2_band(model.dim, nis.size))
                verdict = "inside" if lo <= nis.mean() <= hi else "OUTSIDE"
                text += (f", mean NIS {nis.mean():.3g} ({verdict} the 95 % band [{lo:.3g}, {hi:.3g}] of a mean "
                         f"of {nis.size} updates, {model.dim} dof)")
        parts.append(text)
    for name, log in logs.items():
        from .tracking import CONFIRMED

        confirmed = np.unique(log.track_id[log.status == CONFIRMED]).size
        parts.append(f"{name}: {confirmed} confirmed track{'s' * (confirmed != 1)}")
    runs = f" x {scans.batch} runs" if scans.batch != 1 else ""
    return (f"recorded data: {scans.steps} scans{runs}, {int(scans.valid.sum())} detections; tracks: "
            + ("; ".join(parts) or "none"))


def _file_label(label: str) -> str:
    """A filter label as a file-name part: ``sir(particles=2000)`` -> ``sir_particles=2000_``."""
    return "".join(c if c.isalnum() or c in "-_=." else "_" for c in label)


def run_scenario(scenario: Scenario, host: PluginHost, out: Path, seed: int | None = None) -> ScenarioResult:
    """Run every filter of the scenario on the same truth and detections; write NPZ, JSON and plots.

    Each filter runs on its own: one that raises, or returns NaN or inf, is named in the result (and in
    ``summary.json``) and the other filters' results are still written.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    from tqdm.auto import tqdm

    from .report.cache import save_arrays

    seed = scenario.seed if seed is None else seed
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder; choose another --out")
    if scenario.multi:
        return _run_multi(scenario, host, out, seed)
    planned = set(OUTPUT_NAMES) | {f"tracks-{_file_label(c.label)}.csv" for c in scenario.filters}
    earlier = _check_out(out, planned)  # before any work: a folder that would mix results is refused at once
    truth, scans = simulate(scenario, host, seed)
    sensor = host.sensor(scenario.sensor.plugin)
    model = sensor.measurement_model(**scenario.sensor.params)
    dims = scenario.motion.position_dims
    out.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"times": scans.times, "z": scans.z, "valid": scans.valid}
    if truth is not None:
        arrays["truth"] = truth.states
    rmse, diag, lines, failed = {}, {}, [], {}
    estimates, logs = {}, {}
    for comp in tqdm(scenario.filters, desc=f"scenario {scenario.name}", unit="filter", leave=False, disable=None):
        fname = comp.label
        try:
            spec = host.filter(fname)
            if scenario.tracker == "multi-target":
                from .tracking import TrackerConfig, run_tracker

                config = TrackerConfig(gate=scenario.gate) if scenario.gate else TrackerConfig()
                log = run_tracker(scans, spec, scenario.motion, model, config, seed=seed, key=("tracker", fname))
                if not np.all(np.isfinite(log.mean)):
                    raise FloatingPointError("its track estimates hold NaN or inf")
                logs[fname] = log
                arrays.update(log.to_arrays(prefix=f"{fname}_"))
                counts = log.confirmed_counts()
                lines.append(f"{fname:12s} confirmed tracks per scan (run 0): {counts[0].tolist()}")
                continue
            est = _track_single(scenario, spec, model, scans, seed)
            why = _non_finite(est)
            if why:
                raise FloatingPointError(why)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - one filter failing must not lose the others' results
            failed[fname] = f"{type(exc).__name__}: {exc}"
            continue
        estimates[fname] = est
        arrays[f"mean_{fname}"] = est.mean
        arrays[f"cov_{fname}"] = est.cov
        diag[fname] = {k: float(v) for k, v in est.diagnostics.items()}
        if truth is not None:
            err = position_sq_error(truth.states, est.mean, dims)
            arrays[f"sq_error_{fname}"] = err
            rmse[fname] = float(np.sqrt(err.mean(axis=0)).mean())
    # claim every file this run may write or remove before writing any, so an interrupted run leaves a manifest
    # that still names them all
    if scenario.detections is not None:
        lines.append(_recorded_line(scans, estimates, logs, model))
    _write_manifest(out, scenario, earlier | planned)
    save_arrays(out / "results.npz", arrays)
    from .tracks_io import write_track, write_track_log

    for fname, est in estimates.items():
        write_track(out / f"tracks-{_file_label(fname)}.csv", est, scans.times, motion=scenario.motion,
                    notes=(f"scenario {scenario.name}, filter {fname}, seed {seed}",))
    for fname, log in logs.items():
        write_track_log(out / f"tracks-{_file_label(fname)}.csv", log, scans.times, motion=scenario.motion,
                        notes=(f"scenario {scenario.name}, filter {fname}, seed {seed}",))
    (out / "summary.json").write_text(json.dumps({
        "scenario": scenario.name, "seed": seed, "runs": scans.batch, "steps": scans.steps,
        "tracker": scenario.tracker, "detections": str(scenario.detections or "simulated"), "frame": scenario.frame,
        "filters": {c.label: {"plugin": c.plugin, "params": dict(c.params)} for c in scenario.filters},
        "position_rmse": rmse, "position_rmse_unit": "m", "diagnostics": diag, "failed": failed, "notes": lines,
        "input_warnings": list(scenario.notes)}, indent=2, default=str), encoding="utf-8")
    plot = _plot_data(scenario, model, scans, truth, estimates, logs)
    save_arrays(out / "tracks.npz", plot)
    fig = Figure(figsize=(10, 4.5), layout="constrained")
    _draw_single(fig, plot, scenario, model, scans, truth, estimates, logs)
    fig.savefig(out / "tracks.png", dpi=110)
    written = set(OUTPUT_NAMES) | {f"tracks-{_file_label(f)}.csv" for f in (*estimates, *logs)}
    # an earlier run's files (and a failed filter's old track file) that this run did not write again
    for name in sorted((earlier | planned) - written):
        (out / name).unlink(missing_ok=True)
    _write_manifest(out, scenario, written)
    return ScenarioResult(out, scenario.name, rmse, diag, tuple(lines), failed, plot, figure=fig)


def _tracker_label(tracker: Component, filt: Component) -> str:
    return f"{tracker.label}/{filt.label}"


def _run_multi(scenario: Scenario, host: PluginHost, out: Path, seed: int) -> ScenarioResult:
    """Several objects per run: every tracker of ``[trackers]`` with every filter of ``[filters]`` on the same truth
    and detections, each scored by GOSPA and OSPA (``[trackers] cutoff``, ``order``) per run and scan against the
    live objects; track files with covariances (where the tracker keeps them), ``results.npz`` (the truth, its
    mask, each log, per-scan ``gospa_<label>`` and ``ospa_<label>`` arrays ``(B, T)``), ``summary.json`` and the
    plot.  A tracker that raises, or returns NaN or inf, is named in the result and the others still run."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    from .metrics.ospa import gospa, track_gospa, track_ospa
    from .report.cache import save_arrays
    from .tracking import CONFIRMED
    from .tracks_io import write_track_log

    pairs = [(t, f) for t in scenario.trackers for f in scenario.filters]
    planned = set(OUTPUT_NAMES) | {f"tracks-{_file_label(_tracker_label(t, f))}.csv" for t, f in pairs}
    earlier = _check_out(out, planned)
    truth, scans = simulate(scenario, host, seed)
    sensor = host.sensor(scenario.sensor.plugin)
    model = sensor.measurement_model(**scenario.sensor.params)
    dims = scenario.motion.position_dims
    c, p = scenario.cutoff, scenario.order
    out.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"times": scans.times, "z": scans.z, "valid": scans.valid,
                                     "origin": scans.origin, "truth": truth.states, "alive": truth.alive}
    empty = np.zeros(truth.alive.shape[:2] + (0, dims))
    no_tracks = gospa(empty, truth.states[..., :dims], c, p, y_valid=truth.alive).distance
    means_g, means_o, lines, failed, logs = {}, {}, [], {}, {}
    for tcomp, fcomp in pairs:
        label = _tracker_label(tcomp, fcomp)
        try:
            tracker = host.tracker(tcomp.plugin).configure(name=tcomp.label, **tcomp.params)
            log = tracker.run(scans, host.filter(fcomp.label), scenario.motion, model, seed=seed,
                              key=("tracker", label))
            if not np.all(np.isfinite(log.mean)) or (log.cov is not None and not np.all(np.isfinite(log.cov))):
                raise FloatingPointError("its track estimates hold NaN or inf")
            g = track_gospa(log, truth.states, c, p, truth_valid=truth.alive, dims=dims)
            o = track_ospa(log, truth.states, c, p, truth_valid=truth.alive, dims=dims)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - one tracker failing must not lose the others' results
            failed[label] = f"{type(exc).__name__}: {exc}"
            continue
        logs[label] = log
        arrays.update(log.to_arrays(prefix=f"{label}_"))
        arrays[f"gospa_{label}"] = g.distance
        arrays[f"ospa_{label}"] = o.distance
        means_g[label], means_o[label] = float(g.distance.mean()), float(o.distance.mean())
        lines.append(f"{label:12s} missed {float(g.n_missed.mean()):.3g}, false {float(g.n_false.mean()):.3g} "
                     f"objects per scan; confirmed tracks per scan (run 0): {log.confirmed_counts()[0].tolist()}")
    _write_manifest(out, scenario, earlier | planned)
    save_arrays(out / "results.npz", arrays)
    for label, log in logs.items():
        write_track_log(out / f"tracks-{_file_label(label)}.csv", log, scans.times, motion=scenario.motion,
                        notes=(f"scenario {scenario.name}, tracker/filter {label}, seed {seed}",))
    (out / "summary.json").write_text(json.dumps({
        "scenario": scenario.name, "seed": seed, "runs": scans.batch, "steps": scans.steps,
        "objects": list(truth.labels), "live_objects_per_scan_run0": truth.counts()[0].tolist(),
        "trackers": {t.label: {"plugin": t.plugin, "params": dict(t.params)} for t in scenario.trackers},
        "filters": {f.label: {"plugin": f.plugin, "params": dict(f.params)} for f in scenario.filters},
        "gospa": {"cutoff_m": c, "order": p, "alpha": 2, "mean": means_g, "no_tracks": float(no_tracks.mean()),
                  "per_scan_mean": {k: arrays[f"gospa_{k}"].mean(axis=0).tolist() for k in logs}},
        "ospa": {"cutoff_m": c, "order": p, "mean": means_o}, "failed": failed, "notes": lines,
        "frame": scenario.frame}, indent=2, default=str), encoding="utf-8")
    frame = FRAMES.get(scenario.frame)
    shown = scans.valid[0]
    plot: dict[str, np.ndarray] = {"times": scans.times}
    if frame is not None and frame.position is not None:
        plot["detections_xy"] = frame.to_position(scans.z[0][shown], model.sensor_position
                                                  if model.frame == frame.name else None)[:, :2]
    else:
        plot["detections_xy"] = np.zeros((0, 2))
    # every object of run 0, one after the other, a NaN row between them (a break in the line)
    paths = [np.vstack([truth.states[0, :, k, :2], np.full((1, 2), np.nan)]) for k in range(truth.objects)
             if truth.alive[0, :, k].any()]
    plot["truth_xy"] = np.vstack(paths) if paths else np.zeros((0, 2))
    plot["left_labels"] = np.array(["x (m)", "y (m)", "run 0: objects, detections, confirmed tracks"])
    for label, log in logs.items():
        conf = (log.status == CONFIRMED) & (log.run == 0)
        plot[f"confirmed_{label}"] = log.mean[conf, :2]
        plot[f"gospa_{label}"] = arrays[f"gospa_{label}"].mean(axis=0)
    plot["right_labels"] = np.array(["time (s)", f"GOSPA (m; c = {c:g} m, p = {p:g})",
                                     f"GOSPA per scan, mean over {scans.batch} runs"])
    save_arrays(out / "tracks.npz", plot)
    fig = Figure(figsize=(10, 4.5), layout="constrained")
    _draw_multi(fig, plot, scenario, model, scans, truth, logs, {k: arrays[f"gospa_{k}"] for k in logs})
    fig.savefig(out / "tracks.png", dpi=110)
    written = set(OUTPUT_NAMES) | {f"tracks-{_file_label(label)}.csv" for label in logs}
    for name in sorted((earlier | planned) - written):
        (out / name).unlink(missing_ok=True)
    _write_manifest(out, scenario, written)
    return ScenarioResult(out, scenario.name, {}, {}, tuple(lines), failed, plot, means_g, means_o, figure=fig)
