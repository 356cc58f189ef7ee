"""Hook specifications: the one place that says what a workbench plugin can provide.

A plugin is a module named by an entry point in the group ``workbench``::

    [project.entry-points.workbench]
    alpha_beta = "my_package.alpha_beta"

The module implements any of the hooks below with the :data:`workbench.hookimpl` marker.  Each hook
takes no arguments and returns a list of specs (:mod:`workbench.specs`).  Built-in plugins register
exactly the same way.  The host calls every hook once at start-up; a plugin that raises, returns the
wrong type or reuses a name is reported as broken by ``workbench plugins`` and the rest keep working.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:  # pragma: no cover - typing only
    from .specs import (BenchmarkSpec, ClutterGeneratorSpec, ClutterRemoverSpec, FilterSpec, MotionModelSpec, RecipeSpec,
                        SensorSpec)
    from .specs import TrackerSpec
    from .frames import Frame

PROJECT = "workbench"
ENTRY_POINT_GROUP = "workbench"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


# -- components ---------------------------------------------------------------------------------------


@hookspec
def workbench_filters() -> list["FilterSpec"]:
    """Return the filters/trackers this plugin provides.

    Each :class:`~workbench.specs.FilterSpec` bundles ``init``, ``predict``, ``update`` and ``estimate``
    functions that work on a batch (leading axis ``B``) and never mutate their inputs, plus the
    capabilities the test kit uses to choose its checks.  Names must be unique across plugins.
    """


@hookspec
def workbench_sensors() -> list["SensorSpec"]:
    """Return the sensor models this plugin provides.

    A :class:`~workbench.specs.SensorSpec` simulates target detections from a truth trajectory and
    publishes the :class:`~workbench.models.MeasurementModel` (``h``, Jacobian, ``R``, angular
    components) that filters use.
    """


@hookspec
def workbench_motion_models() -> list["MotionModelSpec"]:
    """Return the motion models this plugin provides.

    Each :class:`~workbench.specs.MotionModelSpec` builds a :class:`~workbench.models.MotionModel` for a time step
    from its declared parameters (``build(dt, **params)``).  Scenario files and references name a model with its
    parameters (``"ct-rate(sigma_omega=0.01)"``); filters declare the models they serve
    (:attr:`~workbench.specs.FilterSpec.motion_models`).  Names must be unique across plugins.
    """


@hookspec
def workbench_frames() -> list["Frame"]:
    """Return the measurement frames this plugin adds (:class:`~workbench.frames.Frame`: components, SI units,
    which are angles, ``space``, and ``position(z, sensor)`` where a measurement gives a position).

    The built-in frames (:data:`workbench.frames.BUILTIN_FRAMES`) are always known; the host registers a plugin's
    frames when it loads, and from then on :func:`workbench.frames.frame` finds them by name, so the plugin's
    sensors, clutter generators and measurement models may declare them.  A frame that redefines a built-in one or
    another plugin's (a name already taken) makes its plugin broken.
    """


@hookspec
def workbench_trackers() -> list["TrackerSpec"]:
    """Return the multi-target trackers this plugin provides.

    A :class:`~workbench.specs.TrackerSpec` declares its parameters and capabilities and a ``run(scans, filt,
    motion, model, *, seed, key=(), **params)`` that tracks a batch of runs with any installed filter doing the
    per-track maths and returns a :class:`~workbench.tracking.TrackLog` (identities, states, covariances where
    kept).  References name a tracker with its parameters (``"gnn(gate_probability=0.95)"``,
    :meth:`~workbench.plugins.PluginHost.tracker`).  Names must be unique across plugins.
    """


@hookspec
def workbench_clutter_generators() -> list["ClutterGeneratorSpec"]:
    """Return the clutter generators this plugin provides (detections labelled as clutter)."""


@hookspec
def workbench_clutter_removers() -> list["ClutterRemoverSpec"]:
    """Return the clutter removers this plugin provides (each narrows the ``valid`` mask of a scan
    series, causally, without reading the origin labels)."""


# -- reports ------------------------------------------------------------------------------------------


@hookspec
def workbench_report_recipes() -> list["RecipeSpec"]:
    """Return report recipes: one per paper, each declaring its tasks, figures, tables, quick and
    full sizes, the published values it compares against and its 'reproduced if' criteria."""


@hookspec
def workbench_benchmarks() -> list["BenchmarkSpec"]:
    """Return benchmark groups for ``workbench bench``: each a :class:`~workbench.specs.BenchmarkSpec` whose
    ``run(quick)`` returns its figures (targets as ``target_*``, whether they were met as ``met_*``).  Group
    names must be unique across plugins."""
