"""workbench: simulate, compare and accelerate target-tracking algorithms in clutter and at low SNR.

The public API (stable names; everything else is reached through its module):

- records: :class:`Gaussian`, :class:`Particles`, :class:`Scan`, :class:`Scans`, :class:`Truth`, :data:`CLUTTER`,
  :class:`InputError`
- models: :class:`MotionModel`, :class:`MeasurementModel`, :func:`constant_velocity`,
  :func:`random_walk_velocity`, :func:`range_rate_model`, :func:`constant_acceleration`, :func:`singer`,
  :func:`coordinated_turn`, :func:`coordinated_turn_rate`, :func:`growth_model`, :func:`linear_measurement`,
  :func:`range_bearing`, :func:`quadratic_measurement` (``docs/motion-models.md``)
- simulation: :func:`sample_motion`, :func:`piecewise_trajectory`, :class:`Leg`, :func:`generator` (keyed random
  streams)
- components: :func:`load_host` (the installed filters, sensors, clutter models, papers), :class:`FilterSpec`,
  :class:`SensorSpec`, :class:`Param`, :data:`hookimpl` (for plugin authors)
- tracking: :func:`run` (the time loop), :func:`run_filter`, the association roles :class:`Direct`,
  :class:`Gated`, :class:`NearestNeighbour`, :class:`MofN` with :class:`TrackerConfig`, and their outputs
  :class:`Track`, :class:`TrackLog`
- metrics: :func:`position_sq_error`, :func:`rmse`, :func:`nees`
- figures: the ``workbench.plot`` module (``wb.plot.truth``, ``wb.plot.tracks``, ...; Matplotlib is imported
  on its first use)

See ``docs/quickstart.md``.
"""

from importlib.metadata import PackageNotFoundError, version

from . import plot
from .filtering import run_filter
from .hookspecs import hookimpl
from .metrics import nees, position_sq_error, rmse
from .models import (MeasurementModel, MotionModel, constant_acceleration, constant_velocity, coordinated_turn,
                     coordinated_turn_rate, growth_model, linear_measurement, quadratic_measurement,
                     random_walk_velocity, range_bearing, range_rate_model, singer)
from .params import Param
from .plugins import load_host
from .rng import generator
from .specs import FilterSpec, SensorSpec
from .tracking import Direct, Gated, MofN, NearestNeighbour, Track, TrackerConfig, TrackLog, run
from .trajectory import Leg, piecewise_trajectory, sample_motion
from .types import CLUTTER, Gaussian, InputError, Particles, Scan, Scans, Truth

try:
    __version__ = version("workbench")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0+unknown"

__all__ = [
    "__version__",
    # records
    "Gaussian", "Particles", "Scan", "Scans", "Truth", "CLUTTER", "InputError",
    # models
    "MotionModel", "MeasurementModel", "constant_velocity", "random_walk_velocity", "range_rate_model",
    "constant_acceleration", "singer", "coordinated_turn", "coordinated_turn_rate", "growth_model",
    "linear_measurement", "range_bearing", "quadratic_measurement",
    # simulation
    "sample_motion", "piecewise_trajectory", "Leg", "generator",
    # components
    "load_host", "FilterSpec", "SensorSpec", "Param", "hookimpl",
    # tracking
    "run", "run_filter", "Direct", "Gated", "NearestNeighbour", "MofN", "TrackerConfig", "Track", "TrackLog",
    # metrics
    "position_sq_error", "rmse", "nees",
    # figures
    "plot",
]
