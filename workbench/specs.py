"""The records a plugin returns from its hooks: one frozen dataclass per kind of component.

A plugin module implements one or more hooks of :mod:`workbench.hookspecs`; each hook returns a list
of these specs.  The host validates them at start-up (type, unique names) and hands them to the
report recipes, the CLI and the test kit.  See ``docs/writing-a-plugin.md``.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

from .criteria import Criterion
from .params import Param, check_values, format_value, infer_params
from .types import InputError, _replaced

if TYPE_CHECKING:  # pragma: no cover - typing only
    from matplotlib.figure import Figure

    from .models import MeasurementModel, MotionModel
    from .types import Gaussian, Scans

__all__ = [
    "CAPABILITIES",
    "FilterSpec",
    "SensorSpec",
    "MotionModelSpec",
    "TrackerSpec",
    "ClutterGeneratorSpec",
    "ClutterRemoverSpec",
    "RecipeSpec",
    "RecipeOptions",
    "Task",
    "TaskContext",
    "FigureSpec",
    "TableSpec",
    "Table",
    "Criterion",
    "BenchmarkSpec",
    "Param",
    "configured_name",
    "take_batch",
    "join_batch",
]

#: Capabilities a filter may declare; the test kit picks its checks from these (never from names).
CAPABILITIES = {
    "gaussian": "the state is a Gaussian whose covariance the filter itself maintains (NEES is meaningful)",
    "exact_linear": "on a linear-Gaussian model the filter equals the closed-form Kalman filter",
    "stochastic": "the filter draws random numbers (particle filters); checked for same-seed reproducibility",
    "multi_measurement": "update accepts several measurements per scan; otherwise at most one valid row",
    "needs_jacobian": "the filter needs MeasurementModel.jacobian",
    "linear_only": "the filter needs a linear measurement model (MeasurementModel.H)",
    "position_doppler_3d": "the filter takes 3-D position + radial-velocity detections [x, y, z, vr] with SNR "
                           "(a 6-D constant-velocity state), as a track-before-detect radar filter does",
    "range_bearing_input": "the filter takes range-bearing measurements only (e.g. a converted-measurement KF)",
    "detection_covariance": "update uses each detection's own covariance (Scan.cov) where the scan carries one",
    "clutter_density": "update accounts for clutter with the scan's declared clutter density (Scan.clutter_density)",
    "ignores_noise_statistics": "the filter never reads Q or R (e.g. a cost-reference particle filter), so handing it "
                                "other noise statistics changes nothing",
    "manoeuvre_modes": "the filter carries a manoeuvre mode of its own (a jump-Markov or NIS-switched model), so a "
                       "recipe hands it the quiet motion model instead of one with the manoeuvres' noise moment-matched "
                       "in",
    "innovations": "update(state, scan, model, rng, innovations=True) returns (state, Innovations): the innovation, "
                   "its covariance, NIS and log-likelihood per item (workbench.kalman_core.Innovations)",
}


def configured_name(base: str, changed: Mapping[str, Any]) -> str:
    """The label of a configured component: ``sir(particles=2000)``; ``base`` when nothing changed."""
    if not changed:
        return base
    return f"{base}(" + ", ".join(f"{k}={format_value(v)}" for k, v in changed.items()) + ")"


class BoundFunction:
    """A component's function with the component's current ``params`` as the values of every parameter the caller
    does not pass: ``spec.simulate(truth, rng)`` simulates with the spec's configured values, and
    ``spec.simulate(truth, rng, sigma_r=2.0)`` with 2.0 for ``sigma_r`` and the spec's values for the rest.

    A sensor, clutter generator or remover spec wraps its functions in this when it is made (so
    :meth:`SensorSpec.configure` and ``dataclasses.replace(spec, params=...)`` bind the new values); the plugin's
    own function is :attr:`raw`, and the wrapper reports its name, module and docstring
    (:func:`functools.update_wrapper`), so report fingerprints and listings see the plugin's function.  Two bound
    functions are equal when their raw functions are, bound to equal values.
    """

    def __init__(self, raw: Callable[..., Any], params: Mapping[str, Any] | None):
        functools.update_wrapper(self, raw)
        self.raw = raw
        self.params = params if isinstance(params, Mapping) else {}
        try:
            signature = inspect.signature(raw)
        except (TypeError, ValueError):  # no signature to read (a builtin): every value goes by keyword
            self._positional: tuple[str, ...] = ()
        else:
            self._positional = tuple(n for n, q in signature.parameters.items()
                                     if q.kind in (q.POSITIONAL_ONLY, q.POSITIONAL_OR_KEYWORD))
            # help() and inspect.signature show the values it is bound to as the defaults
            try:
                self.__signature__ = signature.replace(parameters=[
                    q.replace(default=self.params[n]) if n in self.params and q.kind not in (q.VAR_POSITIONAL,
                                                                                             q.VAR_KEYWORD) else q
                    for n, q in signature.parameters.items()])
            except ValueError:  # a bound value before a parameter without default: show the plugin's own
                pass

    def __call__(self, *args, **kwargs):
        # the caller's positional arguments fill the first parameters; the spec's values fill every parameter
        # neither they nor the caller's keywords give
        taken = self._positional[:len(args)]
        values = {k: v for k, v in self.params.items() if k not in kwargs and k not in taken}
        return self.raw(*args, **values, **kwargs)

    def __eq__(self, other) -> bool:
        if not isinstance(other, BoundFunction):
            return NotImplemented
        return self.raw == other.raw and _same_values(self.params, other.params)

    def __hash__(self) -> int:
        try:
            return hash(self.raw)
        except TypeError:  # an unhashable callable object
            return id(self.raw)

    def __repr__(self) -> str:
        return f"<{getattr(self.raw, '__qualname__', self.raw)!s} bound to {dict(self.params)!r}>"

    def __reduce__(self):
        return BoundFunction, (self.raw, self.params)


def _same_values(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    if a is b:
        return True
    try:
        return bool(dict(a) == dict(b))
    except (TypeError, ValueError):  # values that do not compare to one bool (arrays)
        return dict(a).keys() == dict(b).keys() and all(
            np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a)


class _Configurable:
    """What every component spec shares: declared parameters, their current values, one checked way in."""

    #: The names of the spec's functions that take the parameters as keywords (``**params``); each is bound to
    #: ``params`` when the spec is made (:class:`BoundFunction`).
    _BOUND: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in self._BOUND:
            fn = getattr(self, name)
            if isinstance(fn, BoundFunction):  # a replace() or configure(): bind the plugin's own function again
                fn = fn.raw
            if callable(fn):  # anything else is left for the host's load check to name
                object.__setattr__(self, name, BoundFunction(fn, self.params))

    @property
    def declared(self) -> tuple[Param, ...]:
        """The declared parameters (inferred from ``params`` for a plugin that declares none)."""
        return tuple(self.parameters) if self.parameters else infer_params(self.params)

    def check(self, **values) -> dict[str, Any]:
        """``values`` checked against the declarations and converted to SI (:func:`workbench.params.check_values`)."""
        return check_values(self.declared, values, f"{self.kind} {self.name!r}")

    def changed(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """The entries of ``values`` that differ from the current ``params``."""
        return {k: v for k, v in values.items() if k not in self.params or self.params[k] != v}


# -- the filter-state contract: how a state's batch items are taken and joined ------------------------------


def _declared_fields(state: Any) -> tuple[str, ...] | None:
    """The batch-first fields the state's class declares (its ``batch_fields`` class attribute), or ``None``."""
    declared = getattr(type(state), "batch_fields", None)
    if declared is None:
        return None
    cls = type(state).__name__
    if not dataclasses.is_dataclass(state) or isinstance(state, type):
        raise InputError(f"state class {cls} declares batch_fields but is not a dataclass")
    if isinstance(declared, str) or not all(isinstance(n, str) for n in declared):
        raise InputError(f"state class {cls}: batch_fields must be a tuple of field names, got {declared!r}")
    unknown = sorted(set(declared) - {f.name for f in dataclasses.fields(state)})
    if unknown:
        raise InputError(f"state class {cls} declares batch_fields {unknown} that are not among its fields")
    return tuple(declared)


def _require_declared(state: Any) -> tuple[str, ...]:
    names = _declared_fields(state)
    if names is None:
        raise InputError(f"state class {type(state).__name__} declares no batch_fields (the names of its batch-first "
                         f"fields), so its batch items cannot be taken or joined")
    return names


def _leading(state: Any, out: dict, where: str) -> dict:
    """``{field path: leading length}`` of every declared batch-first array of ``state`` (nested states walked)."""
    for name in _require_declared(state):
        value, path = getattr(state, name), f"{where}.{name}"
        if value is None:
            continue
        if isinstance(value, np.ndarray):
            if value.ndim == 0:
                raise InputError(f"{path} is declared batch-first but is a 0-d array")
            out[path] = value.shape[0]
        elif _declared_fields(value) is not None:
            _leading(value, out, path)
        else:
            raise InputError(f"{path} is declared batch-first but holds a {type(value).__name__}, neither an array "
                             f"nor a state that declares batch_fields")
    return out


def batch_size(state: Any) -> int:
    """The batch size of a state whose class declares ``batch_fields``: the common leading length of its declared
    arrays (refused by name where they differ, or where it declares none that holds an array)."""
    sizes = _leading(state, {}, type(state).__name__)
    if not sizes:
        raise InputError(f"state class {type(state).__name__}: no declared batch field holds an array")
    if len(set(sizes.values())) > 1:
        raise InputError(f"state class {type(state).__name__}: the declared batch-first fields have different leading "
                         f"lengths ({', '.join(f'{k}: {v}' for k, v in sizes.items())})")
    return next(iter(sizes.values()))


def take_batch(state: Any, index) -> Any:
    """The batch items ``index`` (a 1-D integer array, in that order) of a state whose class declares
    ``batch_fields``: each declared field is indexed along its leading axis (a nested state that declares its own
    fields is walked, ``None`` stays ``None``); every other field (counters, settings shared by the batch) is kept."""
    index = np.asarray(index)
    if index.ndim != 1 or not (index.size == 0 or np.issubdtype(index.dtype, np.integer)):
        raise InputError(f"take_batch: index must be a 1-D integer array, got shape {index.shape} "
                         f"and dtype {index.dtype}")
    size = batch_size(state)
    if index.size and (index.min() < -size or index.max() >= size):
        raise InputError(f"take_batch: index out of range for a batch of {size} items")
    return _take(state, index)


def _take(state: Any, index: np.ndarray) -> Any:
    changes = {}
    for name in _require_declared(state):
        value = getattr(state, name)
        changes[name] = None if value is None else value[index] if isinstance(value, np.ndarray) else _take(value,
                                                                                                             index)
    return _replaced(state, **changes)  # sub-batches of arrays the state already validated


def join_batch(states: Sequence[Any]) -> Any:
    """The states' batch items one after the other (states of one class that declares ``batch_fields``): each
    declared field concatenated along its leading axis (nested states walked; a field ``None`` in every state stays
    ``None``); every other field is the first state's."""
    states = list(states)
    if not states:
        raise InputError("join_batch: no states to join")
    kinds = sorted({type(s).__name__ for s in states})
    if len(kinds) > 1:
        raise InputError(f"join_batch: the states are of different classes ({', '.join(kinds)}); a filter whose "
                         f"states change class declares its own FilterSpec.join")
    for s in states:
        batch_size(s)  # declared, consistent
    return _join(states)


def _join(states: list) -> Any:
    first = states[0]
    changes = {}
    for name in _require_declared(first):
        values = [getattr(s, name) for s in states]
        nones = sum(v is None for v in values)
        if nones == len(values):
            changes[name] = None
        elif nones:
            raise InputError(f"join_batch: {type(first).__name__}.{name} is None in some states and not in others; "
                             f"a filter whose fields may be missing declares its own FilterSpec.join")
        elif len({type(v) for v in values}) > 1:
            raise InputError(f"join_batch: {type(first).__name__}.{name} holds values of different types "
                             f"({', '.join(sorted({type(v).__name__ for v in values}))}) in the states")
        elif isinstance(values[0], np.ndarray):
            changes[name] = np.concatenate(values, axis=0)
        else:
            changes[name] = _join(values)
    return _replaced(first, **changes)  # joins of arrays the states already validated


@dataclass(frozen=True)
class FilterSpec(_Configurable):
    """A recursive Bayesian filter, batch-first and functional.

    The four functions never mutate their inputs; each returns a new state.  The state's type is the
    filter's own business (a :class:`~workbench.types.Gaussian`, a square-root factor, particles and
    costs...); the host only ever reads it through ``estimate``.

    Attributes
    ----------
    name : str
        Unique among all installed filters, e.g. ``"ukf"``.  Used by ``--filters`` and in reports.
    summary : str
        One line for ``workbench plugins`` and report legends.
    init : callable
        ``init(prior: Gaussian, rng: np.random.Generator) -> state``.  ``prior`` has shapes
        ``mean (B, n)``, ``cov (B, n, n)``.
    predict : callable
        ``predict(state, motion: MotionModel, rng) -> state``, one step of ``motion.dt``.
    update : callable
        ``update(state, scan: Scan, model: MeasurementModel, rng) -> state``.  ``scan.z`` is
        ``(B, M, m)`` with ``scan.valid (B, M)``; a batch item with no valid row must come back
        unchanged (update equals predict).  Filters without the ``multi_measurement`` capability may
        reject a scan with more than one valid row per item (:func:`workbench.filtering.single_measurement`).
    estimate : callable
        ``estimate(state) -> Gaussian``: the point estimate and its covariance, ``(B, n)``, ``(B, n, n)``.
    step : callable or None
        Optional: ``step(state, motion, scan, model, rng, predicted=False) -> (state, estimate, predicted)``,
        ``predict``, ``update`` and ``estimate`` in one call (a filter that can fuse them, e.g. in one pass over its
        particles); ``predicted`` is ``estimate`` of the predicted state where ``predicted=True`` asks for it, else
        ``None``.  It must give the three calls' numbers bit for bit (the same draws from ``rng`` in the same
        order): the filter kit holds it to them.  The time loop uses it where it is given (with the
        :class:`~workbench.tracking.single.Direct` association, which updates with the scan whatever the
        prediction).  A spec derived with another ``predict``, ``update`` or ``estimate``
        (``dataclasses.replace``) must give its own ``step`` or ``step=None``.
    gate_candidates : callable or None
        Optional association hook: ``gate_candidates(state, scan, model, gate) -> index (B,)``, the row of ``scan``
        (``z (B, M, m)``, ``valid (B, M)``) each batch item is to be updated with, chosen on the filter's own
        predicted state ``state`` (-1 where no valid row lies inside the gate; ``gate`` a chi-square value on the
        squared Mahalanobis distance, or ``None``: no gate).  The single-target
        :class:`~workbench.tracking.NearestNeighbour` uses it where given (unless asked for
        ``filter_candidates=False``), instead of the nearest candidate under the moment-matched ``N(x-, P-)`` of
        ``estimate``: a filter whose prediction is not one Gaussian (the IMM: a mixture of its modes) gates on
        its own.  The result is checked (shape, integer, valid rows) and refused by name.  ``None`` (the default):
        the moment-matched gate.
    capabilities : frozenset of str
        Keys of :data:`CAPABILITIES`.
    params : mapping
        The parameter values the functions were built with (shown in reports, part of cache keys).
    parameters : tuple of :class:`~workbench.params.Param`
        The declared parameters (name, type, default, unit, range, doc): what :meth:`configure` accepts.
    build : callable or None
        ``build(**params) -> FilterSpec``: the factory that makes this filter from parameter values; needed by
        :meth:`configure`.
    diagnostics : callable or None
        ``diagnostics(state) -> dict[str, float]``: counters a filter must not hide (Cholesky
        downdate fallbacks, jitter events, resampling counts).
    expected_failures : mapping
        Test-kit check name -> reason, for checks this filter is known and documented to fail.
    motion_models : tuple of str
        The registered motion models (:class:`MotionModelSpec` names, e.g. ``("ct-rate",)``) this filter is built
        for.  The filter test kit draws its truths, prior and motion model from the first one (through the plugin
        host) instead of its 4-D constant-velocity reference problem; a name no plugin registers makes the
        filter's plugin broken at load.  Empty (the default): the filter serves the kit's 4-D constant velocity.
    take : callable or None
        ``take(state, index) -> state``: the batch items ``index`` (a 1-D integer array, in that order) of a state.
    join : callable or None
        ``join(states) -> state``: the states' batch items one after the other.  ``take`` and ``join`` are the
        filter-state contract through which a multi-target tracker keeps a filter state per set of live tracks
        (it deletes tracks with ``take`` and adds new ones with ``join``).  Give both, or neither: then the state's
        class declares its batch-first fields, ``batch_fields: ClassVar[tuple[str, ...]]`` on a dataclass (as
        :class:`~workbench.types.Gaussian` does), and :func:`take_batch` / :func:`join_batch` index and concatenate
        exactly those fields along their leading axis (nested states that declare their own are walked; every other
        field, a counter or a matrix the batch shares, is kept).  Nothing is inferred from an array's length: a
        filter whose state declares nothing and that gives no ``take`` / ``join`` is refused by name by the
        trackers (:meth:`require_batch_contract`).
    """

    name: str
    summary: str
    init: Callable[..., Any]
    predict: Callable[..., Any]
    update: Callable[..., Any]
    estimate: Callable[[Any], "Gaussian"]
    capabilities: frozenset = frozenset()
    params: Mapping[str, Any] = field(default_factory=dict)
    diagnostics: Callable[[Any], Mapping[str, float]] | None = None
    expected_failures: Mapping[str, str] = field(default_factory=dict)
    parameters: tuple[Param, ...] = ()
    build: Callable[..., "FilterSpec"] | None = None
    motion_models: tuple[str, ...] = ()
    take: Callable[[Any, np.ndarray], Any] | None = None
    join: Callable[[Sequence[Any]], Any] | None = None
    step: Callable[..., Any] | None = None
    gate_candidates: Callable[..., Any] | None = None

    kind = "filter"

    def require_batch_contract(self, state: Any, who: str = "tracker") -> None:
        """Refuse, in one line naming this filter, a state whose batch items cannot be taken and joined: neither
        ``take`` and ``join`` given nor ``batch_fields`` declared by the state's class (or only one of the two
        functions given, or a declaration that does not hold)."""
        if (self.take is None) != (self.join is None):
            given, missing = ("take", "join") if self.join is None else ("join", "take")
            raise InputError(f"{who}: filter {self.name!r} gives FilterSpec.{given} without FilterSpec.{missing}; "
                             f"give both, or neither and declare batch_fields on its state class")
        if self.take is not None:
            return
        if _declared_fields(state) is None:
            raise InputError(f"{who}: filter {self.name!r} does not declare how its state's batch items are taken and "
                             f"joined: its state class {type(state).__name__} declares no batch_fields and the filter "
                             f"gives no FilterSpec.take / FilterSpec.join; declare one of the two")
        try:
            batch_size(state)
        except InputError as exc:
            raise InputError(f"{who}: filter {self.name!r}: {exc}") from None

    def take_items(self, state: Any, index) -> Any:
        """The batch items ``index`` of ``state``: the declared ``take``, else :func:`take_batch` (whose refusal
        names this filter)."""
        if self.take is not None:
            return self.take(state, np.asarray(index))
        try:
            return take_batch(state, index)
        except InputError as exc:
            raise InputError(f"filter {self.name!r}: {exc}") from None

    def join_items(self, states: Sequence[Any]) -> Any:
        """The states' batch items one after the other: the declared ``join``, else :func:`join_batch` (whose
        refusal names this filter)."""
        if self.join is not None:
            return self.join(list(states))
        try:
            return join_batch(states)
        except InputError as exc:
            raise InputError(f"filter {self.name!r}: {exc}") from None

    def configure(self, name: str | None = None, **values) -> "FilterSpec":
        """This filter with some parameters set: ``spec.configure(particles=2000)``.

        The values are checked against :attr:`parameters` (type, unit, range) and the filter is rebuilt by
        :attr:`build` from its current ``params`` updated with them.  The result is named
        ``base(key=value, ...)`` for the values that changed, unless ``name`` is given.  Without values (and
        without ``name``) the spec itself is returned.
        """
        if not values and name is None:
            return self
        checked = self.check(**values)
        changed = self.changed(checked)
        if not changed and name is None:
            return self
        if self.build is None:
            raise InputError(f"filter {self.name!r} declares no build function, so it cannot be configured")
        built = self.build(**{**self.params, **checked})
        return replace(built, name=name or configured_name(self.name, changed))


@dataclass(frozen=True)
class SensorSpec(_Configurable):
    """A sensor: turns truth into detections and publishes its measurement model.

    Attributes
    ----------
    measurement_model : callable
        ``measurement_model(**params) -> MeasurementModel``.
    simulate : callable
        ``simulate(truth: Truth, rng, **params) -> Scans``: target detections only (clutter comes
        from clutter generators), ``origin`` set to the truth object's index.
    params : mapping
        The current parameter values (the defaults, unless configured), each overridable from a scenario
        file.
    parameters : tuple of :class:`~workbench.params.Param`
        The declared parameters.
    frame : str or callable
        The measurement frame of the detections it simulates (a name of :data:`workbench.frames.FRAMES`), or
        ``frame(params) -> str`` when a parameter chooses it.
    truth_to_state : callable or None
        ``truth_to_state(states (..., n), **params) -> (..., n')``: the state the measurement model's ``h`` takes,
        for a sensor whose model describes a quantity derived from the truth (a bistatic range and its rate);
        ``None``: ``h`` takes the truth state itself.  The sensor kit centres the detections on
        ``h(truth_to_state(truth))``.
    noise_cov : callable or None
        ``noise_cov(truth: Truth, scans: Scans, **params) -> (B, T, M, m, m)`` (or anything that broadcasts to it):
        the covariance of the simulated noise of each target detection, for a sensor whose simulation noise is
        not its model's ``R`` (accuracy that follows each detection's SNR, or a filters' ``R`` tuned apart from
        the simulation); ``None``: the simulation noise is ``R``.  The sensor kit's chi-square test uses it.

    The plugin passes its own functions; the spec binds each of them to ``params`` (:class:`BoundFunction`), so
    ``spec.measurement_model()`` and ``spec.simulate(truth, rng)`` use the spec's current (configured) values
    for every parameter the caller does not pass, and keywords the caller passes win.
    """

    name: str
    summary: str
    measurement_model: Callable[..., "MeasurementModel"]
    simulate: Callable[..., "Scans"]
    params: Mapping[str, Any] = field(default_factory=dict)
    parameters: tuple[Param, ...] = ()
    frame: str | Callable[[Mapping[str, Any]], str] = ""
    truth_to_state: Callable[..., np.ndarray] | None = None
    noise_cov: Callable[..., np.ndarray] | None = None

    kind = "sensor"
    _BOUND = ("measurement_model", "simulate", "truth_to_state", "noise_cov")

    def configure(self, **values) -> "SensorSpec":
        """This sensor with some parameter values set (checked, converted to SI)."""
        return replace(self, params={**self.params, **self.check(**values)}) if values else self

    def detection_frame(self, **values) -> str:
        """The frame of the detections this sensor simulates with ``values`` (its ``params`` otherwise)."""
        return _frame_of(self.frame, {**self.params, **values})


@dataclass(frozen=True)
class ClutterGeneratorSpec(_Configurable):
    """Clutter detections: ``generate(truth: Truth, rng, **params) -> Scans`` with ``origin = CLUTTER``.

    The returned scans have the same ``times`` and measurement dimension as the sensor's, so the host
    joins them with :meth:`workbench.types.Scans.merge`.  ``frame`` names the measurement frame of the
    points it makes (or is ``frame(params) -> str``); the clutter's declared mean count per scan and its
    region and amplitude law, where it has them, are what the clutter test kit checks.

    ``expected_count(truth, **params) -> (B, T)``, ``region(truth, **params) -> (low, high)`` (each ``(B, T, m)``,
    ``(T, m)`` or ``(m,)``: inclusive bounds of every component) and ``amplitude_cdf(snr_db, **params) ->
    P(Scans.snr <= snr_db)`` are optional declarations for the clutter kit (:mod:`workbench.testing.clutter`).

    Each of these functions is bound to ``params`` (:class:`BoundFunction`): called without a parameter, it uses
    the spec's current (configured) value; a keyword the caller passes wins.
    """

    name: str
    summary: str
    generate: Callable[..., "Scans"]
    params: Mapping[str, Any] = field(default_factory=dict)
    parameters: tuple[Param, ...] = ()
    frame: str | Callable[[Mapping[str, Any]], str] = ""
    expected_count: Callable[..., np.ndarray] | None = None
    region: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None
    amplitude_cdf: Callable[..., np.ndarray] | None = None

    kind = "clutter generator"
    _BOUND = ("generate", "expected_count", "region", "amplitude_cdf")

    def configure(self, **values) -> "ClutterGeneratorSpec":
        """This clutter model with some parameter values set (checked, converted to SI)."""
        return replace(self, params={**self.params, **self.check(**values)}) if values else self

    def detection_frame(self, **values) -> str:
        """The frame of the clutter points made with ``values`` (its ``params`` otherwise)."""
        return _frame_of(self.frame, {**self.params, **values})


@dataclass(frozen=True)
class ClutterRemoverSpec(_Configurable):
    """Clutter removal: ``remove(scans: Scans, **params) -> Scans`` with a narrower ``valid`` mask.

    A remover must be causal (the decision for scan ``k`` uses scans ``<= k`` only) and must not read
    ``scans.origin``.  It may also replace the detections it keeps (e.g. project them onto a line it found), when
    a declared parameter asks for it; it never adds rows.  ``frames`` lists the measurement frames it works in
    (empty: any).  ``remove`` is bound to ``params`` (:class:`BoundFunction`): ``spec.remove(scans)`` uses the
    spec's current (configured) values.
    """

    name: str
    summary: str
    remove: Callable[..., "Scans"]
    params: Mapping[str, Any] = field(default_factory=dict)
    parameters: tuple[Param, ...] = ()
    frames: tuple[str, ...] = ()

    kind = "clutter remover"
    _BOUND = ("remove",)

    def configure(self, **values) -> "ClutterRemoverSpec":
        """This remover with some parameter values set (checked, converted to SI)."""
        return replace(self, params={**self.params, **self.check(**values)}) if values else self


@dataclass(frozen=True)
class MotionModelSpec(_Configurable):
    """A motion model a plugin registers (hook ``workbench_motion_models``): how to build a
    :class:`~workbench.models.MotionModel` for a time step from declared parameters.

    Attributes
    ----------
    name : str
        Unique among the installed motion models, e.g. ``"ct-rate"``; scenario files and references name it,
        with parameters: ``"ct-rate(sigma_omega=0.01)"``.
    summary : str
        One line for ``workbench plugins``.
    build : callable
        ``build(dt, **params) -> MotionModel``: the model over steps of ``dt`` seconds.  Bound to ``params``
        (:class:`BoundFunction`): ``spec.build(1.0)`` builds with the spec's current (configured) values.
    params, parameters
        The current values and the declared parameters (each with its unit dimension and range: ``sigma_a`` an
        acceleration, ``omega`` an angular rate, ``tau`` a time).
    dims : int or None
        How many position axes the state has (its first ``dims`` components are the position, in metres); ``None``
        where the state holds no position.
    example_state, example_std : tuple of float
        A typical start state of the model and the standard deviation of each component around it (SI units of the
        state): the filter kit draws the truths of a filter that serves this model from ``N(example_state,
        diag(example_std^2))``.  Empty: no kit truths can be drawn from this model.
    """

    name: str
    summary: str
    build: Callable[..., "MotionModel"]
    params: Mapping[str, Any] = field(default_factory=dict)
    parameters: tuple[Param, ...] = ()
    dims: int | None = None
    example_state: tuple[float, ...] = ()
    example_std: tuple[float, ...] = ()

    kind = "motion model"
    _BOUND = ("build",)

    def configure(self, **values) -> "MotionModelSpec":
        """This motion model with some parameter values set (checked, converted to SI)."""
        return replace(self, params={**self.params, **self.check(**values)}) if values else self

    def model(self, dt: float = 1.0, **values) -> "MotionModel":
        """The :class:`~workbench.models.MotionModel` over steps of ``dt`` seconds, with the spec's values and
        ``values`` (checked against the declarations, converted to SI; an unknown name is refused by name)."""
        from .models import MotionModel
        from .units import parse_quantity

        step = parse_quantity(dt, "time", f"motion model {self.name!r}: dt")
        if not step > 0:
            raise InputError(f"motion model {self.name!r}: dt must be > 0 s, got {step:g}")
        built = self.build(step, **self.check(**values))
        if not isinstance(built, MotionModel):
            raise InputError(f"motion model {self.name!r}: its build function returned a {type(built).__name__}, "
                             f"not a MotionModel")
        return built


@dataclass(frozen=True)
class TrackerSpec(_Configurable):
    """A multi-target tracker a plugin registers (hook ``workbench_trackers``): it runs any installed filter for the
    per-track maths over a batch of runs and logs every track with its identity.

    Attributes
    ----------
    name : str
        Unique among the installed trackers, e.g. ``"gnn"``; references name it with parameters:
        ``"gnn(gate_probability=0.95)"`` (:meth:`~workbench.plugins.PluginHost.tracker`).
    summary : str
        One line for ``workbench plugins``.
    run : callable
        ``run(scans, filt, motion, model, *, seed, key=(), **params) -> TrackLog``: track every run of ``scans``
        (``z (B, T, M, m)``, never reading ``origin``) with the filter ``filt`` (a
        :class:`FilterSpec`), the :class:`~workbench.models.MotionModel` and the
        :class:`~workbench.models.MeasurementModel`; every random draw from ``generator(seed, *key, ...)``, one
        stream per run so that a run's tracks do not depend on the others.  Returns a
        :class:`~workbench.tracking.TrackLog` (run, ping, identity, status, hit and state of every live track, and
        their covariances where the tracker has the ``covariance`` capability).  Inputs are never mutated.  Bound
        to ``params`` (:class:`BoundFunction`): ``spec.run(scans, filt, motion, model, seed=1)`` runs with the
        spec's current (configured) values.
    params, parameters
        The current values and the declared parameters (each with its unit dimension and range).
    capabilities : frozenset of str
        Keys of :attr:`CAPABILITIES`.
    """

    name: str
    summary: str
    run: Callable[..., Any]
    params: Mapping[str, Any] = field(default_factory=dict)
    parameters: tuple[Param, ...] = ()
    capabilities: frozenset = frozenset()

    kind = "tracker"
    _BOUND = ("run",)

    #: Capabilities a tracker may declare.
    CAPABILITIES = {  # not a field: no annotation
        "cartesian_2d": "detections are Cartesian (x, y) positions, seen by the filter through its measurement "
                        "model, and the state is [x, y, vx, vy]",
        "covariance": "the track log carries every track's covariance (TrackLog.cov)",
        "existence": "the track log carries every track's existence probability",
    }

    def configure(self, name: str | None = None, **values) -> "TrackerSpec":
        """This tracker with some parameter values set (checked against :attr:`parameters`, converted to SI), named
        ``base(key=value, ...)`` for the values that changed unless ``name`` is given."""
        if not values and name is None:
            return self
        checked = self.check(**values)
        changed = self.changed(checked)
        return replace(self, params={**self.params, **checked}, name=name or configured_name(self.name, changed))


def _frame_of(frame, params: Mapping[str, Any]) -> str:
    return frame(params) if callable(frame) else frame


@dataclass(frozen=True)
class BenchmarkSpec:
    """A benchmark group for ``workbench bench``.

    ``run(quick: bool) -> dict`` returns flat figures (numbers or short strings); it runs in a fresh process
    of its own (the host finds it again there by ``group``), so its peak memory is its own.

    A target ``X`` is declared by three figures: ``target_X`` (the goal as text, e.g. ``"<= 2"``), ``measured_X``
    (the measured number) and ``met_X`` (a bool), with an optional ``note_X`` (how it was measured, or why it is
    missed); ``workbench bench`` prints one line per target and never says "met" in quick mode.  ``curves`` (a list
    of series) feeds ``workbench bench --plot`` (:mod:`workbench.bench.plots`).
    """

    group: str
    summary: str
    run: Callable[[bool], Mapping[str, Any]]


# -- report recipes ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RecipeOptions:
    """What the user asked for: ``size`` is ``"quick"`` or ``"full"``; ``sizes`` the recipe's values for it."""

    size: str
    values: Mapping[str, Any]
    seed: int
    filters: tuple[str, ...]
    arch: str = "cpu"
    #: the multi-target trackers to compare (tracker references, ``"gm-phd(prune=1e-5)"``): the recipe's
    #: ``default_trackers`` with ``--trackers`` applied; empty for a recipe that compares none
    trackers: tuple[str, ...] = ()


@dataclass(frozen=True)
class TaskContext:
    """Handed to a task's ``run``: its parameters, a seed and the plugin host to find components."""

    params: Mapping[str, Any]
    seed: int
    host: Any
    progress: Callable[[float], None] = lambda fraction: None
    arch: str = "cpu"


@dataclass(frozen=True)
class Task:
    """One cacheable unit of a recipe's computation.

    ``run(ctx) -> dict[str, np.ndarray]`` returns the raw numbers; the report stores them (NPZ) under a
    key made of the recipe, ``key``, ``params``, the seed and the code version, so a re-run reuses
    finished tasks and a changed parameter recomputes only the tasks whose ``params`` changed.
    ``params`` must be JSON-serialisable.

    ``runs``: the number of runs (Monte Carlo repetitions) the task computes, where it has such a count; the
    report's time table shows it beside the task's seconds (None: not declared, shown as "-").
    ``seeded``: False for a task whose result does not depend on the report's seed (a tuning task that draws from
    its own fixed tuning seed): the confirmation seed reuses its result on the reported seed instead of running it
    again.  Declared by the recipe, never guessed; a task that reads ``ctx.seed`` must leave it True.
    ``sensitivity``: True for a task computed only at a non-primary grid value of a declared unknown (it feeds a
    criterion's ``across``, never its verdict at the primary values).  The confirmation seed judges the primary
    values only, so it does not run such a task again: the re-judged criteria read the reported seed's result, and
    only their discarded ``across`` depends on it.  Declared by the recipe (its tests check that the primary
    verdicts read no such task).
    ``timed``: True for a task whose results include wall-clock times (a timing comparison).  Workers that run
    tasks side by side take it apart from the other tasks of its batch: on the confirmation seed once the report's
    own process has drawn the figures and tables (a third process on the cores, whose load a timing taken then
    would read), or after every other task where the executor cannot hold it back; on the reported seed before
    them (the report's process only waits there, and a timed task at the start leaves no worker idle at the
    batch's end).  Declared by the recipe.
    """

    key: str
    params: Mapping[str, Any]
    run: Callable[[TaskContext], Mapping[str, np.ndarray]]
    runs: int | None = None
    seeded: bool = True
    sensitivity: bool = False
    timed: bool = False

    def __post_init__(self) -> None:
        if self.runs is not None and (isinstance(self.runs, bool) or not isinstance(self.runs, (int, np.integer))
                                      or self.runs < 1):
            raise InputError(f"task {self.key!r}: runs is a whole number >= 1 or None, got {self.runs!r}")
        if not isinstance(self.seeded, bool):
            raise InputError(f"task {self.key!r}: seeded is True or False, got {self.seeded!r}")
        if not isinstance(self.sensitivity, bool):
            raise InputError(f"task {self.key!r}: sensitivity is True or False, got {self.sensitivity!r}")
        if not isinstance(self.timed, bool):
            raise InputError(f"task {self.key!r}: timed is True or False, got {self.timed!r}")


#: Results of a recipe's tasks: task key -> that task's arrays.
Results = Mapping[str, Mapping[str, np.ndarray]]


@dataclass(frozen=True)
class FigureSpec:
    """A figure: ``data(results) -> dict[str, ndarray]`` is the data behind it (saved as NPZ, tested),
    ``draw(data, fig)`` draws it onto a fresh matplotlib figure."""

    id: str
    caption: str
    data: Callable[[Results], Mapping[str, np.ndarray]]
    draw: Callable[[Mapping[str, np.ndarray], "Figure"], None]
    size: tuple[float, float] = (6.4, 4.8)


@dataclass(frozen=True)
class Table:
    columns: tuple[str, ...]
    rows: tuple[tuple[Any, ...], ...]


@dataclass(frozen=True)
class TableSpec:
    """A table: ``make(results) -> Table``; published values sit in their own columns beside ours."""

    id: str
    caption: str
    make: Callable[[Results], Table]


@dataclass(frozen=True)
class RecipeSpec:
    """How to regenerate one paper's figures and tables.

    Attributes
    ----------
    paper : str
        ``"000"`` ... ``"003"`` (or a plugin's own id).
    sizes : mapping
        ``{"quick": {...}, "full": {...}}``: the values (runs, steps, particle counts...) of each size.
    default_filters : tuple of str
        The filters compared by default; ``--filters`` adds to or replaces them.
    default_trackers : tuple of str
        The multi-target trackers compared by default (e.g. ``("mofn",)``), for a recipe whose tasks run the
        trackers of :attr:`RecipeOptions.trackers`; ``--trackers`` adds to or replaces them.  Empty (the default):
        the recipe compares no installed trackers, and ``--trackers`` naming it is refused.
    tasks : callable
        ``tasks(options: RecipeOptions) -> list[Task]``.
    figures, tables : tuples of specs
    criteria : callable or None
        ``criteria(results) -> list[Criterion]``: the paper's 'reproduced if' checks.
    published : mapping
        The paper's published numbers or claims this recipe compares against (shown in the report).
    notes : str
        Choices the recipe made where the paper is silent (shown in the report).
    unknowns : tuple of workbench.criteria.DeclaredUnknown
        The values the paper withholds that the recipe had to choose (name, unit, primary value, grid, why); its
        criteria that hinge on one carry their verdicts across the grid (``Criterion.across``).
    """

    paper: str
    title: str
    sizes: Mapping[str, Mapping[str, Any]]
    tasks: Callable[[RecipeOptions], Sequence[Task]]
    figures: tuple[FigureSpec, ...] = ()
    tables: tuple[TableSpec, ...] = ()
    criteria: Callable[[Results], Sequence[Criterion]] | None = None
    default_filters: tuple[str, ...] = ()
    default_trackers: tuple[str, ...] = ()
    published: Mapping[str, Any] = field(default_factory=dict)
    notes: str = ""
    unknowns: tuple[Any, ...] = ()

    def __post_init__(self) -> None:
        # a figure and a table (or two of either) with one id would write the same files of the report
        seen: dict[str, str] = {}
        for kind, specs in (("figure", self.figures), ("table", self.tables)):
            for spec in specs:
                if spec.id in seen:
                    raise ValueError(f"recipe {self.paper}: the {kind} id {spec.id!r} is already a {seen[spec.id]} "
                                     f"id; ids name the report's files and must be unique")
                seen[spec.id] = kind
