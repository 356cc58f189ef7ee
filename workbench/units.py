"""Quantities in scenario files: a bare number in the documented SI unit, or a string such as
``"10 deg"``, ``"0.5 s"``, ``"2.5 km"``, ``"15 m/s"``.  Values are converted to SI (angles to radians).

Every key that takes a number declares its *dimension* (:data:`DIMENSIONS`): ``"length"``, ``"angle"``,
``"angular_rate"``, ``"gate"`` (a Mahalanobis gate, held as the chi-square value d^2), ``"dimensionless"`` (a ratio,
a probability, a count), ... A string's unit must belong to that dimension: ``"3 km"`` for a turn rate or a gate is
refused with a message naming the key, the unit given and the units allowed.  A key with no declared dimension
(``None``) takes bare numbers only.  Each dimension also has a physical limit (:data:`LIMITS`) on the magnitude of a
value, so an extreme finite number (``1e200``, whose square overflows) is refused where it comes in.
"""

from __future__ import annotations

import math
import re

from .types import InputError

__all__ = ["UNITS", "DIMENSIONS", "LIMITS", "GENERIC_LIMIT", "SI_LABELS", "parse_quantity", "units_of"]

#: unit -> (dimension, factor to SI): the units of the SI dimensions, each unit in one dimension
UNITS: dict[str, tuple[str, float]] = {
    "m": ("length", 1.0), "km": ("length", 1e3), "nmi": ("length", 1852.0), "yd": ("length", 0.9144),
    "s": ("time", 1.0), "ms": ("time", 1e-3), "min": ("time", 60.0),
    "rad": ("angle", 1.0), "mrad": ("angle", 1e-3), "deg": ("angle", math.pi / 180.0),
    "m/s": ("speed", 1.0), "km/h": ("speed", 1.0 / 3.6), "kn": ("speed", 1852.0 / 3600.0),
    "m/s^2": ("acceleration", 1.0), "m/s2": ("acceleration", 1.0), "g": ("acceleration", 9.80665),
    "Hz": ("frequency", 1.0), "kHz": ("frequency", 1e3), "MHz": ("frequency", 1e6), "GHz": ("frequency", 1e9),
    "dB": ("decibel", 1.0), "dBsm": ("decibel", 1.0), "dBi": ("decibel", 1.0),
    "W": ("power", 1.0), "kW": ("power", 1e3), "MW": ("power", 1e6),
    "rad/s": ("angular_rate", 1.0), "mrad/s": ("angular_rate", 1e-3), "deg/s": ("angular_rate", math.pi / 180.0),
    "m^2": ("area", 1.0), "m2": ("area", 1.0), "km^2": ("area", 1e6), "km2": ("area", 1e6),
    "/m^3": ("inverse_volume", 1.0), "1/m^3": ("inverse_volume", 1.0), "/km^3": ("inverse_volume", 1e-9),
    "chi2": ("gate", 1.0),
}

#: dimension -> {unit: factor to the value's unit}.  Besides the SI dimensions of :data:`UNITS`:
#: ``"angle_deg"``, an angle held in degrees (``"0.01 rad"`` -> 0.573); ``"gate"``, a Mahalanobis gate held as the
#: chi-square value d^2, written bare, as ``"9.21 chi2"`` or in standard deviations (``"3 sigma"`` -> 9);
#: ``"state"``, a number in the SI units of the filter's state components (a spread, a variance): bare numbers only;
#: ``"dimensionless"``, a pure number (a ratio, a probability, a count, a factor): bare numbers only.
DIMENSIONS: dict[str, dict[str, float]] = {}
for _unit, (_dim, _factor) in UNITS.items():
    DIMENSIONS.setdefault(_dim, {})[_unit] = _factor
DIMENSIONS["angle_deg"] = {"deg": 1.0, "rad": 180.0 / math.pi, "mrad": 0.18 / math.pi}
DIMENSIONS["gate"]["sigma"] = math.nan  # not a factor: d^2 = s^2 (see parse_quantity)
DIMENSIONS["state"] = {}  # in the SI units of the filter's state components (mixed: m, m/s...): bare numbers
DIMENSIONS["dimensionless"] = {}
#: White-noise amplitudes of continuous-time motion models (the square root of a spectral density): a jerk's in
#: m/s^2/sqrt(s) (constant acceleration), a turn rate's in rad/s/sqrt(s) (the random-walk rate of a coordinated
#: turn): bare numbers in those units.
DIMENSIONS["jerk_noise"] = {}
DIMENSIONS["angular_rate_noise"] = {}

#: The SI unit a dimension's values are held in, for messages and listings.
SI_LABELS: dict[str, str] = {
    "length": "m", "angle": "rad", "time": "s", "speed": "m/s", "acceleration": "m/s^2", "frequency": "Hz",
    "decibel": "dB", "power": "W", "angular_rate": "rad/s", "area": "m^2", "inverse_volume": "1/m^3",
    "angle_deg": "deg", "gate": "chi2", "state": "", "dimensionless": "",
    "jerk_noise": "m/s^2/sqrt(s)", "angular_rate_noise": "rad/s/sqrt(s)",
}

#: The largest magnitude a value of each dimension may have (in its SI unit): generous physical bounds (beyond the
#: Moon's distance, the speed of light, optical frequencies, +-300 dB...) that keep a value's square and its
#: products with the other quantities of a filter finite.
LIMITS: dict[str, float] = {
    "length": 1e9, "angle": 1e4, "time": 1e9, "speed": 3e8, "acceleration": 1e7, "frequency": 1e15,
    "decibel": 300.0, "power": 1e12, "angular_rate": 1e4, "area": 1e18, "inverse_volume": 1e12,
    "angle_deg": 1e6, "gate": 1e12, "state": 1e12, "dimensionless": 1e15,
    "jerk_noise": 1e7, "angular_rate_noise": 1e4,
}
#: The limit of a number whose key declares no dimension.
GENERIC_LIMIT = 1e15

_PATTERN = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z/^0-9]+)?\s*$")


def units_of(dimension: str | None) -> tuple[str, ...]:
    """The units a value of ``dimension`` may be written in (none for ``None`` and ``"dimensionless"``)."""
    return tuple(DIMENSIONS.get(dimension or "", {}))


def parse_quantity(value, dimension: str | None, where: str) -> float:
    """Convert ``value`` to a float in SI units (see :data:`DIMENSIONS` for the units a dimension allows).

    ``dimension`` (e.g. ``"angle"``) is what the key expects; ``None`` (no declared dimension) and
    ``"dimensionless"`` take bare numbers only.  ``where`` names the file and key for error messages.  A value
    beyond the dimension's :data:`LIMITS` is refused.
    """
    if dimension is not None and dimension not in DIMENSIONS:
        raise ValueError(f"unknown dimension {dimension!r} (known: {', '.join(DIMENSIONS)})")
    if isinstance(value, bool):
        raise InputError(f"{where}: expected a number{_hint(dimension)}, got {value!r}")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {value!r}")
        return _limited(float(value), value, dimension, where)
    if not isinstance(value, str):
        raise InputError(f"{where}: expected a number{_hint(dimension)}, got {type(value).__name__} {value!r}")
    match = _PATTERN.match(value)
    if not match:
        raise InputError(f"{where}: cannot read {value!r} as a quantity; write e.g. '10 deg' or a bare number")
    number, unit = float(match.group(1)), match.group(2)
    if not math.isfinite(number):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    if unit is None:
        return _limited(number, value, dimension, where)
    allowed = DIMENSIONS.get(dimension or "", {})
    if unit not in allowed:
        given = UNITS[unit][0] if unit in UNITS else ("gate in standard deviations" if unit == "sigma" else None)
        if dimension is None or not allowed:
            what = {"dimensionless": "a pure number",
                    "state": "a bare number in the SI units of the state's components",
                    "jerk_noise": "a bare number in m/s^2/sqrt(s)",
                    "angular_rate_noise": "a bare number in rad/s/sqrt(s)"}.get(
                dimension or "", "a bare number (no unit is declared for it)")
            raise InputError(f"{where}: {value!r} carries the unit {unit!r}, but this key takes {what}")
        if given is None:
            raise InputError(f"{where}: unknown unit {unit!r} in {value!r}{_hint(dimension)}")
        raise InputError(f"{where}: {value!r} is {_a(_name(given))}, but this key expects {_a(_name(dimension))}"
                         f"{_hint(dimension)}")
    if dimension == "gate" and unit == "sigma":
        if number < 0:
            raise InputError(f"{where}: a gate in standard deviations must be >= 0, got {value!r}")
        return _limited(number * number, value, dimension, where)
    return _limited(number * allowed[unit], value, dimension, where)


def _limited(number: float, value, dimension: str | None, where: str) -> float:
    limit = LIMITS.get(dimension or "", GENERIC_LIMIT)
    if not abs(number) <= limit:
        si = SI_LABELS.get(dimension or "", "")
        kind = _a(_name(dimension)) if dimension else "a number"
        raise InputError(f"{where}: {value!r} is beyond the physical range of {kind} (|value| <= {limit:g}"
                         f"{' ' + si if si else ''})")
    return number


def _a(noun: str) -> str:
    return f"{'an' if noun[:1] in 'aeiou' else 'a'} {noun}"


def _name(dimension: str | None) -> str:
    return {"angular_rate": "angular rate", "inverse_volume": "density per volume",
            "angle_deg": "angle (in degrees)", "gate": "gate (chi-square value d^2, or in sigma)",
            "state": "number in the state's units", "dimensionless": "pure number"}.get(dimension or "",
                                                                                       dimension or "number")


def _hint(dimension: str | None) -> str:
    units = units_of(dimension)
    if not units:
        return ""
    return f" (units: {', '.join(units)})"
