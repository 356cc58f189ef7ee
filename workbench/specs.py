"""The records a plugin returns from its hooks: one frozen dataclass per kind of component.

A plugin module implements one or more hooks of :mod:`workbench.hookspecs`; each hook returns a list
of these specs.  The host validates them at start-up (type, unique names) and hands them to the
report recipes, the CLI and the test kit.  See ``docs/writing-a-plugin.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

from .criteria import Criterion

if TYPE_CHECKING:  # pragma: no cover - typing only
    from matplotlib.figure import Figure

    from .models import MeasurementModel, MotionModel
    from .types import Gaussian, Scan, Scans, Truth

__all__ = [
    "CAPABILITIES",
    "FilterSpec",
    "SensorSpec",
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
}


@dataclass(frozen=True)
class FilterSpec:
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
    capabilities : frozenset of str
        Keys of :data:`CAPABILITIES`.
    params : mapping
        The parameter values the functions were built with (shown in reports, part of cache keys).
    diagnostics : callable or None
        ``diagnostics(state) -> dict[str, float]``: counters a filter must not hide (Cholesky
        downdate fallbacks, jitter events, resampling counts).
    expected_failures : mapping
        Test-kit check name -> reason, for checks this filter is known and documented to fail.
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


@dataclass(frozen=True)
class SensorSpec:
    """A sensor: turns truth into detections and publishes its measurement model.

    Attributes
    ----------
    measurement_model : callable
        ``measurement_model(**params) -> MeasurementModel``.
    simulate : callable
        ``simulate(truth: Truth, rng, **params) -> Scans``: target detections only (clutter comes
        from clutter generators), ``origin`` set to the truth object's index.
    params : mapping
        Default parameter values, each overridable from a scenario file.
    """

    name: str
    summary: str
    measurement_model: Callable[..., "MeasurementModel"]
    simulate: Callable[..., "Scans"]
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ClutterGeneratorSpec:
    """Clutter detections: ``generate(truth: Truth, rng, **params) -> Scans`` with ``origin = CLUTTER``.

    The returned scans have the same ``times`` and measurement dimension as the sensor's, so the host
    joins them with :meth:`workbench.types.Scans.merge`.
    """

    name: str
    summary: str
    generate: Callable[..., "Scans"]
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ClutterRemoverSpec:
    """Clutter removal: ``remove(scans: Scans, **params) -> Scans`` with a narrower ``valid`` mask.

    A remover must be causal (the decision for scan ``k`` uses scans ``<= k`` only) and must not read
    ``scans.origin``.
    """

    name: str
    summary: str
    remove: Callable[..., "Scans"]
    params: Mapping[str, Any] = field(default_factory=dict)


# -- report recipes ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RecipeOptions:
    """What the user asked for: ``size`` is ``"quick"`` or ``"full"``; ``sizes`` the recipe's values for it."""

    size: str
    values: Mapping[str, Any]
    seed: int
    filters: tuple[str, ...]
    arch: str = "cpu"


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
    """

    key: str
    params: Mapping[str, Any]
    run: Callable[[TaskContext], Mapping[str, np.ndarray]]


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
    tasks : callable
        ``tasks(options: RecipeOptions) -> list[Task]``.
    figures, tables : tuples of specs
    criteria : callable or None
        ``criteria(results) -> list[Criterion]``: the brief's 'reproduced if' checks.
    published : mapping
        The paper's published numbers or claims this recipe compares against (shown in the report).
    notes : str
        Choices the recipe made where the paper is silent (shown in the report).
    """

    paper: str
    title: str
    sizes: Mapping[str, Mapping[str, Any]]
    tasks: Callable[[RecipeOptions], Sequence[Task]]
    figures: tuple[FigureSpec, ...] = ()
    tables: tuple[TableSpec, ...] = ()
    criteria: Callable[[Results], Sequence[Criterion]] | None = None
    default_filters: tuple[str, ...] = ()
    published: Mapping[str, Any] = field(default_factory=dict)
    notes: str = ""
