"""Uniform clutter: a Poisson number of false detections per scan, uniform over a declared region of a declared frame.

Per scan and run::

    N ~ Poisson(rate)
    z_i ~ Uniform(region), each component independently:  U(low_c, high_c)
    A ~ Rayleigh with E[A^2] = 10^(mean_snr_db / 10)  ->  level = 10 log10(A^2) dB   (stored as ``snr``)

The region is declared per component of the frame, each bound with its unit:

- ``frame = "cartesian-2d"``: ``x`` and ``y``, each ``(low, high)`` in metres;
- ``frame = "range-bearing"``: ``range`` ``(low, high)`` in metres and ``bearing`` ``(low, high)`` in radians
  (inside ``[-pi, pi]``; ``"75 deg"`` is read as an angle), counter-clockwise from +x as the frame says.

Uniform in the frame's own components (in range and bearing, not in area), so the clutter density per unit
measurement volume is the constant ``rate / volume`` (``volume`` the product of the region's sides): every point
carries it as ``Scans.clutter_density``, for filters that weigh clutter by it.  The level is stored, not
thresholded.  Each point is labelled ``CLUTTER``.

Shapes: ``z (B, T, M, 2)``, ``valid``, ``snr``, ``origin``, ``clutter_density`` ``(B, T, M)`` with ``M`` the largest
count over the batch (padding rows invalid).  The draws, in order: the counts ``(B, T)``, the components ``(B, T, M,
2)`` (uniform in ``[0, 1)``, scaled), the levels ``(B, T, M)``.
"""

from __future__ import annotations

import math

import numpy as np

from workbench import hookimpl
from workbench.params import Param, defaults
from workbench.specs import ClutterGeneratorSpec
from workbench.types import CLUTTER, InputError, Scans, Truth

NAME = "uniform-clutter"
#: The frames this generator makes points in, and the parameter that bounds each of their components.
FRAME_COMPONENTS = {"cartesian-2d": ("x", "y"), "range-bearing": ("range", "bearing")}

PARAMETERS = (
    Param("rate", 10.0, "mean number of false detections per scan (Poisson)", unit="dimensionless", minimum=0.0,
          maximum=1e6),
    Param("frame", "cartesian-2d", "measurement frame of the points; the region's components are that frame's", "str",
          choices=tuple(FRAME_COMPONENTS)),
    Param("x", (0.0, 1000.0), "x bounds of the region (low, high)", "vector", unit="length", length=2,
          when={"frame": "cartesian-2d"}),
    Param("y", (0.0, 1000.0), "y bounds of the region (low, high)", "vector", unit="length", length=2,
          when={"frame": "cartesian-2d"}),
    Param("range", (0.0, 5000.0), "range bounds of the region (low, high)", "vector", unit="length", length=2,
          minimum=0.0, when={"frame": "range-bearing"}),
    Param("bearing", (-math.pi, math.pi), "bearing bounds of the region (low, high), inside [-pi, pi], "
          "counter-clockwise from +x", "vector", unit="angle", length=2, minimum=-math.pi, maximum=math.pi,
          when={"frame": "range-bearing"}),
    Param("mean_snr_db", 10.0, "mean clutter level (Rayleigh amplitude)", unit="decibel"),
)
PARAMS = defaults(PARAMETERS)


def _values(params) -> dict:
    unknown = set(params) - set(PARAMS)
    if unknown:
        raise InputError(f"{NAME}: unknown parameter(s) {sorted(unknown)}; known: {sorted(PARAMS)}")
    return {**PARAMS, **params}


def bounds(**params) -> tuple[np.ndarray, np.ndarray]:
    """The region's inclusive bounds ``(low (2,), high (2,))`` in the frame's components; :class:`InputError`
    naming the parameter where a bound pair is not ``low < high``, or the frame is not one this generator makes."""
    p = _values(params)
    frame = p["frame"]
    if frame not in FRAME_COMPONENTS:
        raise InputError(f"{NAME}: frame must be one of {', '.join(FRAME_COMPONENTS)}, got {frame!r}")
    low, high = [], []
    for key in FRAME_COMPONENTS[frame]:
        pair = tuple(float(v) for v in p[key])
        if len(pair) != 2 or not all(math.isfinite(v) for v in pair) or not pair[0] < pair[1]:
            raise InputError(f"{NAME}: {key} must be (low, high) with low < high, got {p[key]!r}")
        if key == "bearing" and not (-math.pi <= pair[0] and pair[1] <= math.pi):
            raise InputError(f"{NAME}: bearing bounds must lie inside [-pi, pi] (a sector across +-pi is not "
                             f"supported), got {pair}")
        if key == "range" and pair[0] < 0:
            raise InputError(f"{NAME}: range bounds must be >= 0, got {pair}")
        low.append(pair[0])
        high.append(pair[1])
    return np.array(low), np.array(high)


def density(**params) -> float:
    """The clutter density per unit measurement volume: ``rate / prod(high - low)``."""
    p = _values(params)
    low, high = bounds(**p)
    return float(p["rate"] / np.prod(high - low))


def generate(truth: Truth, rng: np.random.Generator, **params) -> Scans:
    """Clutter detections for every run and scan of ``truth`` (its states are not read: the clutter does not
    depend on the target)."""
    p = _values(params)
    low, high = bounds(**p)
    if not 0.0 <= p["rate"] <= 1e6:
        raise InputError(f"{NAME}: rate must be in [0, 1e6], got {p['rate']}")
    B, T = truth.batch, truth.steps
    counts = rng.poisson(p["rate"], size=(B, T))
    M = int(counts.max()) if counts.size else 0
    z = low + (high - low) * rng.random((B, T, M, 2))
    valid = np.arange(M) < counts[..., None]
    power = rng.exponential(10.0 ** (p["mean_snr_db"] / 10.0), size=(B, T, M))
    level = 10.0 * np.log10(np.maximum(power, 1e-300))
    return Scans(z, valid, truth.times, snr=level, origin=np.full(valid.shape, CLUTTER),
                 clutter_density=np.full(valid.shape, density(**p)))


def expected_count(truth: Truth, **params) -> np.ndarray:
    """The declared mean count per scan, ``(B, T)``: ``rate``."""
    p = _values(params)
    return np.full((truth.batch, truth.steps), float(p["rate"]))


def region(truth: Truth, **params) -> tuple[np.ndarray, np.ndarray]:
    """The declared region, ``(2,)`` twice: the bounds of each of the frame's components."""
    return bounds(**_values(params))


def amplitude_cdf(level_db, **params) -> np.ndarray:
    """``P(level <= s)`` of Rayleigh amplitudes: ``1 - exp(-10^(s/10) / 10^(mean/10))``."""
    p = _values(params)
    power = 10.0 ** (np.asarray(level_db, dtype=float) / 10.0)
    return 1.0 - np.exp(-power / 10.0 ** (p["mean_snr_db"] / 10.0))


def _frame(params) -> str:
    return params.get("frame", PARAMS["frame"])


UNIFORM_CLUTTER = ClutterGeneratorSpec(
    name=NAME,
    summary="Poisson(rate) false detections per scan, uniform over a declared region of a declared frame "
            "(cartesian-2d: x, y; range-bearing: range, bearing); Rayleigh levels",
    generate=generate,
    params=PARAMS,
    parameters=PARAMETERS,
    frame=_frame,
    expected_count=expected_count,
    region=region,
    amplitude_cdf=amplitude_cdf,
)


@hookimpl
def workbench_clutter_generators():
    return [UNIFORM_CLUTTER]
