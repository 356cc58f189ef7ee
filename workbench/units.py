"""Quantities in scenario files: a bare number in the documented SI unit, or a string such as
``"10 deg"``, ``"0.5 s"``, ``"2.5 km"``, ``"15 m/s"``.  Values are converted to SI (angles to radians)."""

from __future__ import annotations

import math
import re

from .types import InputError

__all__ = ["UNITS", "parse_quantity"]

#: unit -> (dimension, factor to SI)
UNITS: dict[str, tuple[str, float]] = {
    "m": ("length", 1.0), "km": ("length", 1e3), "nmi": ("length", 1852.0), "yd": ("length", 0.9144),
    "s": ("time", 1.0), "ms": ("time", 1e-3), "min": ("time", 60.0),
    "rad": ("angle", 1.0), "mrad": ("angle", 1e-3), "deg": ("angle", math.pi / 180.0),
    "m/s": ("speed", 1.0), "km/h": ("speed", 1.0 / 3.6), "kn": ("speed", 1852.0 / 3600.0),
    "m/s^2": ("acceleration", 1.0), "m/s2": ("acceleration", 1.0), "g": ("acceleration", 9.80665),
    "Hz": ("frequency", 1.0), "kHz": ("frequency", 1e3), "MHz": ("frequency", 1e6), "GHz": ("frequency", 1e9),
    "dB": ("decibel", 1.0), "dBsm": ("decibel", 1.0), "dBi": ("decibel", 1.0),
    "W": ("power", 1.0), "kW": ("power", 1e3), "MW": ("power", 1e6),
}

_PATTERN = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z/^0-9]+)?\s*$")


def parse_quantity(value, dimension: str | None, where: str) -> float:
    """Convert ``value`` to a float in SI units.

    ``dimension`` (e.g. ``"angle"``) is what the key expects; ``None`` accepts any unit.  ``where``
    names the file and key for error messages.
    """
    if isinstance(value, bool):
        raise InputError(f"{where}: expected a number{_hint(dimension)}, got {value!r}")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if not isinstance(value, str):
        raise InputError(f"{where}: expected a number{_hint(dimension)}, got {type(value).__name__} {value!r}")
    match = _PATTERN.match(value)
    if not match:
        raise InputError(f"{where}: cannot read {value!r} as a quantity; write e.g. '10 deg' or a bare number")
    number, unit = float(match.group(1)), match.group(2)
    if unit is None:
        return number
    if unit not in UNITS:
        raise InputError(f"{where}: unknown unit {unit!r} in {value!r}{_hint(dimension)}")
    dim, factor = UNITS[unit]
    if dimension is not None and dim != dimension:
        raise InputError(f"{where}: {value!r} is a {dim}, but this key expects a {dimension}{_hint(dimension)}")
    return number * factor


def _hint(dimension: str | None) -> str:
    if dimension is None:
        return ""
    units = [u for u, (d, _) in UNITS.items() if d == dimension]
    return f" (units: {', '.join(units)})"
