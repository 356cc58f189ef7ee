"""Measurement models: what filters need to know about sensors.

A sensor plugin publishes a :class:`MeasurementModel` (``h``, its Jacobian where it has one, ``R`` and which
components are angles), so filters never import sensor code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..linalg import wrap_angle
from ..types import InputError

__all__ = [
    "MeasurementModel",
    "DetectionModel",
    "linear_measurement",
    "range_bearing",
    "range_bearing_jacobian",
    "polar_to_cartesian",
    "converted_covariance",
    "quadratic_measurement",
]


@dataclass(frozen=True)
class DetectionModel:
    """How a sensor's detection quality follows the detection's own SNR (declared by the sensor).

    Filters that weight each detection by its strength (track-before-detect, PDA-style pseudo-measurements)
    read these instead of the sensor's internals.

    Attributes
    ----------
    log_pd : callable
        ``log_pd(snr_db) -> log P_D``: the log probability of detection of a target return of that SNR
        (dB), elementwise.
    position_sigma : callable
        ``position_sigma(snr_db, range_m) -> sigma (m)``: the isotropic position standard deviation of a
        detection of that SNR at that range, elementwise.
    doppler_sigma : float
        The radial-velocity standard deviation (m/s).
    pfa : float
        The false-alarm probability per cell of the detector.
    nominal_snr_db : callable or None
        ``nominal_snr_db(position) -> snr_db``: the nominal SNR (dB, no fluctuation) of the sensor's design
        target at positions ``(..., 3)`` -> ``(...)``.  ``None`` when the sensor states no design target.
    log_detection : callable or None
        ``log_detection(nominal_snr_db) -> log P_D``: the log probability that the sensor's detector reports the
        design target when its nominal SNR is ``nominal_snr_db`` (elementwise).
    log_snr_density : callable or None
        ``log_snr_density(snr_db, nominal_snr_db) -> log f``: the log density (per dB) of a target detection's
        measured SNR given its nominal SNR, conditioned on the detection (``-inf`` below the detector's
        threshold), elementwise with broadcasting.
    clutter_log_snr_density : callable or None
        ``clutter_log_snr_density(snr_db) -> log f``: the log density (per dB) of a false (clutter) detection's
        measured SNR, conditioned on the detection.  A sensor rarely knows its environment: whoever pairs the
        sensor with a clutter model may set it (``dataclasses.replace``).
    """

    log_pd: Callable[[np.ndarray], np.ndarray]
    position_sigma: Callable[[np.ndarray, np.ndarray], np.ndarray]
    doppler_sigma: float
    pfa: float
    nominal_snr_db: Callable[[np.ndarray], np.ndarray] | None = None
    log_detection: Callable[[np.ndarray], np.ndarray] | None = None
    log_snr_density: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    clutter_log_snr_density: Callable[[np.ndarray], np.ndarray] | None = None


@dataclass(frozen=True)
class MeasurementModel:
    """What a sensor publishes for filters: ``z = h(x) + v``, ``v ~ N(0, R)``.

    Attributes
    ----------
    h : callable
        ``(..., n) -> (..., m)``, vectorised over any leading axes.
    R : ndarray (m, m)
        Measurement noise covariance.
    jacobian : callable or None
        ``(B, n) -> (B, m, n)``; ``None`` for a model without one (derivative-free filters only).
    angular : tuple of bool
        Which of the ``m`` components are angles in radians; residuals and means wrap them.
    H : ndarray (m, n) or None
        Set for a linear model (``h(x) = H x``).
    frame : str
        The measurement frame of ``h(x)`` (:data:`workbench.frames.FRAMES`); ``""`` when undeclared.
    std : tuple of float or None
        The nominal standard deviation of each component, as the sensor states it (``R`` is
        ``diag(std^2)`` for an uncorrelated model); read by filters that need the stated accuracies
        themselves (the converted-measurement filter).
    sensor_position : tuple of float or None
        Where the sensor is, in the state's position coordinates.
    detection : DetectionModel or None
        How detection quality follows SNR, for sensors that report one.
    """

    name: str
    h: Callable[[np.ndarray], np.ndarray]
    R: np.ndarray
    jacobian: Callable[[np.ndarray], np.ndarray] | None = None
    angular: tuple[bool, ...] = ()
    H: np.ndarray | None = None
    frame: str = ""
    std: tuple[float, ...] | None = None
    sensor_position: tuple[float, ...] | None = None
    detection: DetectionModel | None = None

    def __post_init__(self) -> None:
        R = np.asarray(self.R, dtype=float)
        if R.ndim != 2 or R.shape[0] != R.shape[1]:
            raise InputError(f"MeasurementModel {self.name!r}: R must be square, got shape {R.shape}")
        if not np.all(np.isfinite(R)):
            raise InputError(f"MeasurementModel {self.name!r}: R holds a non-finite value")
        if not np.allclose(R, R.T) or np.any(np.linalg.eigvalsh(R) < -1e-12):
            raise InputError(f"MeasurementModel {self.name!r}: R must be symmetric positive semi-definite")
        angular = tuple(self.angular) if self.angular else (False,) * R.shape[0]
        if len(angular) != R.shape[0]:
            raise InputError(f"MeasurementModel {self.name!r}: angular has {len(angular)} entries for m={R.shape[0]}")
        if self.std is not None:
            std = tuple(float(v) for v in self.std)
            if len(std) != R.shape[0] or not all(np.isfinite(v) and v >= 0 for v in std):
                raise InputError(f"MeasurementModel {self.name!r}: std must hold {R.shape[0]} finite values >= 0, "
                                 f"got {self.std}")
            object.__setattr__(self, "std", std)
        if self.sensor_position is not None:
            object.__setattr__(self, "sensor_position", tuple(float(v) for v in self.sensor_position))
        if self.frame:
            from ..frames import frame as _frame

            declared = _frame(self.frame)
            if declared.dim != R.shape[0]:
                raise InputError(f"MeasurementModel {self.name!r}: frame {self.frame!r} has {declared.dim} "
                                 f"components, R has {R.shape[0]}")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "angular", angular)

    @property
    def stated_std(self) -> np.ndarray:
        """The stated standard deviations (``std``), or ``sqrt(diag(R))`` when none are declared."""
        return np.asarray(self.std) if self.std is not None else np.sqrt(np.diag(self.R))

    @property
    def dim(self) -> int:
        return self.R.shape[0]

    @property
    def angle_mask(self) -> np.ndarray:
        return np.asarray(self.angular, dtype=bool)

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a - b`` with angular components wrapped to (-pi, pi]."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        shape = None if a.shape == b.shape or a.size + b.size < 8192 else np.broadcast_shapes(a.shape, b.shape)
        if shape is None or shape[-1:] != (len(self.angular),):
            d = a - b
        else:
            # large and broadcast (e.g. (B, 1, m) - (B, N, m)): one component at a time, so that NumPy's
            # inner loop runs over the long axes instead of over the m components
            a, b = np.broadcast_to(a, shape), np.broadcast_to(b, shape)
            d = np.empty(shape)
            for i in range(shape[-1]):
                np.subtract(a[..., i], b[..., i], out=d[..., i])
        for i, is_angle in enumerate(self.angular):
            if is_angle:
                d[..., i] = wrap_angle(d[..., i])
        return d

    def mean(self, y: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Weighted mean of points ``y (B, S, m)`` with weights ``(S,)`` or ``(B, S)``, angle-aware.

        Angular components are averaged as ``y_0 + sum w_i wrap(y_i - y_0)`` and the result wrapped,
        so a set of bearings straddling +-pi averages correctly.  The weights must sum to one; negative
        weights (sigma points) are fine.
        """
        w = np.broadcast_to(np.asarray(weights, dtype=float), y.shape[:2])
        plain = np.einsum("bs,bsm->bm", w, y)
        if not any(self.angular):
            return plain
        ref = y[:, 0, :]
        unwrapped = ref + np.einsum("bs,bsm->bm", w, self.residual(y, ref[:, None, :]))
        return np.where(self.angle_mask, wrap_angle(unwrapped), plain)


def linear_measurement(H, R, name: str = "linear", frame: str = "", std=None) -> MeasurementModel:
    """``z = H x + v``; ``frame`` and ``std`` as :class:`MeasurementModel` declares them."""
    H = np.asarray(H, dtype=float)
    return MeasurementModel(
        name=name,
        h=lambda x: x @ H.T,
        R=np.asarray(R, dtype=float),
        jacobian=lambda x: np.broadcast_to(H, (x.shape[0], *H.shape)),
        H=H,
        frame=frame,
        std=std,
    )


def range_bearing_jacobian(x: np.ndarray, sensor=(0.0, 0.0)) -> np.ndarray:
    """Jacobian of ``[sqrt(dx^2 + dy^2), atan2(dy, dx)]`` for states ``(B, n)`` with ``x, y`` first.

    ``H = [[dx/r, dy/r, 0...], [-dy/r^2, dx/r^2, 0...]]``.  One float64 state (a single track's EKF update) is
    worked out in Python floats: the same IEEE operations in the same order as the array code (subtract, multiply,
    add, max, correctly rounded sqrt, divide), so the same numbers, at a fifth of the time of eight array calls.
    """
    if x.ndim == 2 and x.shape[0] == 1 and x.shape[1] >= 2 and x.dtype == np.float64:
        px, py = x[0, :2].tolist()
        dx = px - float(sensor[0])
        dy = py - float(sensor[1])
        r2 = max(dx * dx + dy * dy, 1e-300)  # NaN stays NaN, as with np.maximum
        r = math.sqrt(r2)
        n = x.shape[1]
        jac = np.zeros((1, 2, n))
        flat = jac.reshape(-1)  # a view of the new array
        flat[0], flat[1], flat[n], flat[n + 1] = dx / r, dy / r, -dy / r2, dx / r2
        return jac
    dx = x[:, 0] - sensor[0]
    dy = x[:, 1] - sensor[1]
    r2 = np.maximum(dx * dx + dy * dy, 1e-300)
    r = np.sqrt(r2)
    jac = np.zeros((x.shape[0], 2, x.shape[1]))
    jac[:, 0, 0] = dx / r
    jac[:, 0, 1] = dy / r
    jac[:, 1, 0] = -dy / r2
    jac[:, 1, 1] = dx / r2
    return jac


def range_bearing(sigma_r: float, sigma_theta: float, sensor=(0.0, 0.0)) -> MeasurementModel:
    """Range and bearing (math convention, from the x-axis) of a 2-D position from ``sensor``.

    ``h(x) = [sqrt(dx^2 + dy^2), atan2(dy, dx)]``, ``R = diag(sigma_r^2, sigma_theta^2)``; the bearing is
    angular.
    """
    if sigma_r < 0 or sigma_theta < 0:
        raise InputError(f"range_bearing needs non-negative noise, got sigma_r={sigma_r}, sigma_theta={sigma_theta}")
    sx, sy = float(sensor[0]), float(sensor[1])

    def h(x: np.ndarray) -> np.ndarray:
        if x.ndim == 2 and x.shape[0] == 1 and x.shape[1] >= 2 and x.dtype == np.float64:
            # one track: Python floats for the range (the same IEEE operations as the array code), NumPy's own
            # arctan2 for the bearing (the loop a length-1 array gets), the same numbers at half the time
            px, py = x[0, :2].tolist()
            dx, dy = px - sx, py - sy
            out = np.empty((1, 2))
            flat = out.reshape(-1)
            flat[0], flat[1] = math.sqrt(dx * dx + dy * dy), np.arctan2(dy, dx)
            return out
        dx = x[..., 0] - sx
        dy = x[..., 1] - sy
        # sqrt(dx^2 + dy^2) rather than np.hypot: no overflow at tracking ranges, and it is the hot path
        # of every particle filter on this model; written into one array rather than np.stack (a third of the
        # call at one track, the same numbers)
        out = np.empty(dx.shape + (2,), dtype=dx.dtype)
        out[..., 0] = np.sqrt(dx * dx + dy * dy)
        out[..., 1] = np.arctan2(dy, dx)
        return out

    return MeasurementModel(
        name="range-bearing",
        h=h,
        R=np.diag([sigma_r**2, sigma_theta**2]),
        jacobian=lambda x: range_bearing_jacobian(x, (sx, sy)),
        angular=(False, True),
        frame="range-bearing",
        std=(float(sigma_r), float(sigma_theta)),
        sensor_position=(sx, sy),
    )


def polar_to_cartesian(z: np.ndarray, sensor=(0.0, 0.0)) -> np.ndarray:
    """``(r, b) -> (sx + r cos b, sy + r sin b)`` for ``z (..., 2)``; math bearing convention."""
    z = np.asarray(z, dtype=float)
    r, b = z[..., 0], z[..., 1]
    return np.stack([sensor[0] + r * np.cos(b), sensor[1] + r * np.sin(b)], axis=-1)


def converted_covariance(r: np.ndarray, b: np.ndarray, sigma_r: float, sigma_b: float) -> np.ndarray:
    """Linearised covariance of the converted measurement, ``(...,) -> (..., 2, 2)``.

    ``sigma_b`` in radians; ``b`` in the math convention (from the +x axis).
    """
    r = np.asarray(r, dtype=float)
    c, s = np.cos(b), np.sin(b)
    sr2 = sigma_r * sigma_r
    rb2 = r * r * sigma_b * sigma_b
    out = np.empty(r.shape + (2, 2))
    out[..., 0, 0] = sr2 * c * c + rb2 * s * s  # R11 = sr^2 cos^2 b + r^2 sb^2 sin^2 b
    out[..., 1, 1] = sr2 * s * s + rb2 * c * c  # R22 = sr^2 sin^2 b + r^2 sb^2 cos^2 b
    out[..., 0, 1] = out[..., 1, 0] = (sr2 - rb2) * s * c  # R12 = (sr^2 - r^2 sb^2) sin b cos b
    return out


def quadratic_measurement(scale: float = 1.0 / 20.0, sigma: float = 1.0) -> MeasurementModel:
    """``z = scale x^2 + w``, ``w ~ N(0, sigma^2)``, of a univariate state ``[x]``: the measurement of the growth
    model benchmark of Gordon, Salmond & Smith (1993) (``scale = 1/20``, ``sigma = 1``; see
    :func:`workbench.models.motion.growth_model`).  Jacobian ``2 scale x``; the frame is undeclared (``""``).
    The sign of ``x`` is not observed, so the posterior is bimodal: a benchmark for particle filters."""
    try:
        a, sd = float(scale), float(sigma)
    except (TypeError, ValueError):
        raise InputError(f"quadratic_measurement needs numbers, got scale={scale!r}, sigma={sigma!r}") from None
    if not (np.isfinite(a) and a != 0.0):
        raise InputError(f"quadratic_measurement needs a finite, non-zero scale, got {scale!r}")
    if not (np.isfinite(sd) and sd >= 0.0):
        raise InputError(f"quadratic_measurement needs a finite sigma >= 0, got {sigma!r}")

    def h(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return a * x * x

    def jacobian(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return (2.0 * a * x)[..., None, :]

    return MeasurementModel(name="quadratic", h=h, R=np.array([[sd * sd]]), jacobian=jacobian, std=(sd,))
