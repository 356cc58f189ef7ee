"""Paper 000's scenario: the path, the sensor and clutter models it is seen through, and what the filters are told.

- :func:`scenario_truth`: the approach, descent, 90 deg turn and exit of Fig. 2;
- :func:`sensor_for`, :func:`clutter_for`: the ``lband-radar`` sensor (with the reference RCS of the run, the
  brief's -20 dBsm or a sensitivity value) and the ``radar-clutter`` model, configured through their declared
  parameters;
- :func:`simulate_scans`: target detections merged with clutter, every detection carrying the clutter intensity
  the clutter model declares (``Scans.clutter_density``, per unit ``(x, y, z, vr)`` volume);
- :func:`tracking_model`: the sensor's measurement model with the clutter model's SNR law attached to its
  detection model (``DetectionModel.clutter_log_snr_density``), which is what a filter weighing a detection's
  strength needs.

Every random draw comes from ``workbench.rng.generator(seed, "paper000", "scans", threshold)``: the reference RCS
is not part of the key, so the runs of the RCS sensitivity see the same noise, fluctuation and clutter draws and
differ only in the target's strength (common random numbers).
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from workbench.models import MeasurementModel
from workbench.rng import generator
from workbench.sensing.radar import exponential_power_log_density
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import Scans, Truth

__all__ = ["SENSOR", "CLUTTER_MODEL", "DT", "START_POSITION", "START_VELOCITY", "LEGS", "PHASES", "PRIMARY_RCS",
           "SENSITIVITY_RCS", "scenario_truth", "sensor_for", "clutter_for", "clutter_intensity", "simulate_scans",
           "tracking_model"]

SENSOR, CLUTTER_MODEL = "lband-radar", "radar-clutter"
DT = 1.0  # s [U]
START_POSITION = (56e3, 2e3, 3e3)  # m [U]
START_VELOCITY = (-200.0, 0.0, 0.0)  # m/s [U]
#: approach (front aspect), descent (top), 90 deg turn at 9 deg/s (side), exit along +y (side) [U]
LEGS = (Leg("straight", 100.0), Leg("climb", 60.0, climb_rate=-40.0),
        Leg("turn", 10.0, turn_rate=-np.deg2rad(9.0)), Leg("straight", 129.0))
PHASES = (("front", 0, 100), ("top", 101, 160), ("side", 161, 299))
#: the reference (front-aspect) RCS: the brief's value [U] and the sensitivity values of the full report (dBsm)
PRIMARY_RCS = -20.0
SENSITIVITY_RCS = (-18.5, -17.0)


def scenario_truth(runs: int = 1) -> Truth:
    """The paper's path (Fig. 2) for ``runs`` identical runs: states ``(runs, 300, 6)``."""
    one = piecewise_trajectory(START_POSITION, START_VELOCITY, LEGS, DT)
    return Truth(np.repeat(one.states, runs, axis=0), one.times)


def sensor_for(host, rcs_dbsm: float = PRIMARY_RCS, threshold_db: float | None = 5.0):
    """The ``lband-radar`` sensor with reference RCS ``rcs_dbsm`` and detection threshold ``threshold_db``."""
    return host.sensor(SENSOR).configure(rcs_ref_dbsm=float(rcs_dbsm), threshold_db=threshold_db)


def clutter_for(host, threshold_db: float | None):
    """The ``radar-clutter`` model cut at ``threshold_db``."""
    return host.clutter_generator(CLUTTER_MODEL).configure(threshold_db=threshold_db)


def clutter_intensity(clutter, truth: Truth) -> np.ndarray:
    """The clutter model's intensity per unit ``(x, y, z, vr)`` volume, from its declared mean count and region:
    ``lambda = expected_count / |region|``, ``(B, T)`` (m^-3 (m/s)^-1)."""
    count = clutter.expected_count(truth, **clutter.params)
    low, high = clutter.region(truth, **clutter.params)
    volume = np.prod(np.maximum(high - low, 0.0), axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(volume > 0, count / volume, 0.0)


def simulate_scans(host, truth: Truth, seed: int, threshold_db: float | None, rcs_dbsm: float = PRIMARY_RCS,
                   stream: str = "") -> Scans:
    """Target detections (``lband-radar``) merged with clutter (``radar-clutter``) at ``threshold_db``.

    With ``threshold_db`` None the target keeps every return and the clutter goes down to the lowest paper
    threshold (3 dB); every detection's SNR is in ``Scans.snr``, so higher thresholds can be cut afterwards.  With a
    threshold, every detection carries the clutter model's intensity (``clutter_density``).  Same seed and
    threshold, same draws (common random numbers for every filter and every reference RCS); another ``stream`` (e.g.
    ``"replicate"``) draws independent runs.
    """
    key = ("scans", -1 if threshold_db is None else float(threshold_db)) + ((stream,) if stream else ())
    rng = generator(seed, "paper000", *key)
    sensor = sensor_for(host, rcs_dbsm, threshold_db)
    target = sensor.simulate(truth, rng, **sensor.params)
    clutter = clutter_for(host, 3.0 if threshold_db is None else threshold_db)
    points = clutter.generate(truth, rng, **clutter.params)
    if threshold_db is None:
        return target.merge(points)
    # the clutter intensity at the target's detection too (the clutter model's points carry their own)
    density = clutter_intensity(clutter, truth)[..., None]
    return replace(target, clutter_density=np.broadcast_to(density, target.valid.shape)).merge(points)


def tracking_model(host, rcs_dbsm: float = PRIMARY_RCS, threshold_db: float = 5.0) -> MeasurementModel:
    """The measurement model the filters are given: the sensor's, with the clutter model's SNR law (exponential
    power above the threshold, :func:`workbench.sensing.radar.exponential_power_log_density` at the clutter model's
    declared mean power) attached to the declared detection model."""
    sensor = sensor_for(host, rcs_dbsm, threshold_db)
    model = sensor.measurement_model(**sensor.params)
    clutter = clutter_for(host, threshold_db)
    law = partial(exponential_power_log_density, mean_power=float(clutter.params["mean_power"]),
                  threshold_db=threshold_db)
    return replace(model, detection=replace(model.detection, clutter_log_snr_density=law))
