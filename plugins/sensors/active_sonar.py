"""Active sonar, ping by ping (paper 001): Cartesian detections of the target with detection level.

Simulation (paper 001, section 4, run directly in Cartesian coordinates)::

    detected ~ Bernoulli(pd)                         per ping, pd = 0.8
    z = [x, y] + e,   e ~ N(0, sigma_pos^2 I)        sigma_pos = 2.0
    level = level_db + u,   u ~ N(0, sigma_level^2)   20 dB, sigma_level = 0.1 dB  (stored as ``snr``)

The detections ``z`` are always Cartesian ``(x, y)``, the frame of the clutter generators, the Hough
clutter remover and the recorded-data loader.

Measurement models (``measurement_model(frame=...)``):

- ``frame="cartesian"`` (default, matches the detections): linear position model ``z = [I 0] x + v``,
  ``R = sigma_xy^2 I`` (``sigma_xy`` defaults to ``sigma_pos``, i.e. the matched ``R = 4 I``).  Its declared
  ``std = (sigma_xy, sigma_xy)`` is the sensor's stated position accuracy, which a tracker may give every
  detection as its own covariance (``TrackerConfig.detection_sigma``).
- ``frame="polar"``: :func:`workbench.models.range_bearing` with ``sigma_r`` and
  ``sigma_theta = deg2rad(sigma_b_deg)`` (the paper's 0.5 and 1 degree), sensor at ``sensor``.
  Bearing in the **mathematical** convention: ``b = atan2(y - sy, x - sx)``, counter-clockwise from
  the +x axis, so ``x = sx + r cos b``, ``y = sy + r sin b``.  This is the view the converted
  measurement filter (``cmkf-l``) needs; the multi-target tracker (:mod:`workbench.tracking.multi`) maps each
  Cartesian detection ``p`` into it as ``h(p)`` = ``(|p - s|, atan2)``, exactly as the paper computes
  ``(r, b)`` from a Cartesian detection only to build ``R``.  Paper 001 tracks with this polar model.

Shapes: truth ``(B, T, n)`` with ``x, y`` first -> scans ``z (B, T, 1, 2)``, ``valid``, ``snr``,
``origin`` ``(B, T, 1)``.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.models import MeasurementModel, linear_measurement, range_bearing
from workbench.params import Param
from workbench.specs import SensorSpec
from workbench.types import InputError, Scans, Truth

FRAMES = ("cartesian", "polar")

DEFAULTS = {
    "pd": 0.8,
    "sigma_pos": 2.0,
    "level_db": 20.0,
    "sigma_level": 0.1,
    "frame": "cartesian",
    "sigma_r": 0.5,
    "sigma_b_deg": 1.0,
    "sigma_xy": None,
    "sensor": (0.0, 0.0),
}


def _check(pd, sigma_pos, sigma_level, sigma_r, sigma_b_deg, sigma_xy, frame) -> None:
    if not 0.0 <= pd <= 1.0:
        raise InputError(f"active-sonar: pd must be in [0, 1], got {pd}")
    for key, value in (("sigma_pos", sigma_pos), ("sigma_level", sigma_level), ("sigma_r", sigma_r),
                       ("sigma_b_deg", sigma_b_deg)):
        if not value >= 0:
            raise InputError(f"active-sonar: {key} must be >= 0, got {value}")
    if sigma_xy is not None and not sigma_xy > 0:
        raise InputError(f"active-sonar: sigma_xy must be > 0, got {sigma_xy}")
    if frame not in FRAMES:
        raise InputError(f"active-sonar: frame must be one of {FRAMES}, got {frame!r}")


def measurement_model(pd: float = 0.8, sigma_pos: float = 2.0, level_db: float = 20.0, sigma_level: float = 0.1,
                      frame: str = "cartesian", sigma_r: float = 0.5, sigma_b_deg: float = 1.0,
                      sigma_xy: float | None = None, sensor=(0.0, 0.0)) -> MeasurementModel:
    """The polar (range, math bearing) or the Cartesian position model; see the module docstring."""
    _check(pd, sigma_pos, sigma_level, sigma_r, sigma_b_deg, sigma_xy, frame)
    if frame == "polar":
        return range_bearing(sigma_r, np.deg2rad(sigma_b_deg), sensor=tuple(sensor))
    s = sigma_pos if sigma_xy is None else sigma_xy
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 1] = 1.0
    return linear_measurement(H, s * s * np.eye(2), name="sonar-position", frame="cartesian-2d", std=(s, s))


def simulate(truth: Truth, rng: np.random.Generator, pd: float = 0.8, sigma_pos: float = 2.0, level_db: float = 20.0,
             sigma_level: float = 0.1, frame: str = "cartesian", sigma_r: float = 0.5, sigma_b_deg: float = 1.0,
             sigma_xy: float | None = None, sensor=(0.0, 0.0)) -> Scans:
    """Target detections of every ping (``origin`` 0); missed pings are marked invalid."""
    _check(pd, sigma_pos, sigma_level, sigma_r, sigma_b_deg, sigma_xy, frame)
    states = truth.states
    B, T = states.shape[:2]
    detected = rng.random((B, T)) < pd
    # z = [x, y] + e,  e ~ N(0, sigma_pos^2 I)
    z = states[..., :2] + sigma_pos * rng.standard_normal((B, T, 2))
    # level = level_db + u,  u ~ N(0, sigma_level^2)
    level = level_db + sigma_level * rng.standard_normal((B, T))
    return Scans(z[:, :, None, :], detected[:, :, None], truth.times, snr=level[:, :, None],
                 origin=np.zeros((B, T, 1), dtype=int))


PARAMETERS = (
    Param("pd", 0.8, "probability of detection per ping", unit="dimensionless", minimum=0.0, maximum=1.0,
          affects="simulation"),
    Param("sigma_pos", 2.0, "position noise of a detection, per axis", unit="length", minimum=0.0, affects="noise",
          when={"frame": "cartesian", "sigma_xy": None}),
    Param("level_db", 20.0, "mean detection level", unit="decibel", affects="simulation"),
    Param("sigma_level", 0.1, "level noise", unit="decibel", minimum=0.0, affects="simulation"),
    Param("frame", "cartesian", "the measurement model the filters get: Cartesian position or polar (range, "
          "bearing); the detections are Cartesian either way", "str", choices=FRAMES),
    Param("sigma_r", 0.5, "range sigma of the polar model", unit="length", minimum=0.0, affects="noise",
          when={"frame": "polar"}),
    Param("sigma_b_deg", 1.0, "bearing sigma of the polar model, in degrees", unit="angle_deg", minimum=0.0,
          maximum=360.0, affects="noise", when={"frame": "polar"}),
    Param("sigma_xy", None, "position sigma of the Cartesian model (none: sigma_pos)", "float?", unit="length",
          above=0.0, affects="noise", when={"frame": "cartesian"}),
    Param("sensor", (0.0, 0.0), "sensor position of the polar model", "vector", unit="length", length=2,
          when={"frame": "polar"}),
)

ACTIVE_SONAR = SensorSpec(
    name="active-sonar",
    summary="Active sonar pings: Cartesian target detections (pd, position and level noise); polar or Cartesian model",
    measurement_model=measurement_model,
    simulate=simulate,
    params=DEFAULTS,
    parameters=PARAMETERS,
    frame="cartesian-2d",
)


@hookimpl
def workbench_sensors():
    return [ACTIVE_SONAR]
