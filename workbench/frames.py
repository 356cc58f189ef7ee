"""Measurement frames: what the components of a detection are, in which units, and where they put a target.

Every sensor and clutter generator declares the frame of the detections it makes, and every measurement
model the frame of ``h(x)``.  A scenario that merges detections of different frames, or hands a filter
detections in a frame its measurement model does not produce, is refused with a message naming both.

A frame also knows how to turn a measurement into a Cartesian position (for plots and for trackers that
initiate tracks from positions): :meth:`Frame.to_position`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .types import InputError

__all__ = ["Frame", "FRAMES", "frame", "check_same_frame"]


@dataclass(frozen=True)
class Frame:
    """One measurement frame.

    Attributes
    ----------
    name : str
    components : tuple of str
        The component names, in order.
    units : tuple of str
        The SI unit of each component.
    angular : tuple of bool
        Which components are angles in radians (residuals wrap them).
    doc : str
    position : callable or None
        ``position(z (..., m), sensor (d,)) -> (..., d)``: the Cartesian position a measurement implies, or
        ``None`` when a measurement alone does not give one (e.g. a bistatic range and its rate).
    """

    name: str
    components: tuple[str, ...]
    units: tuple[str, ...]
    angular: tuple[bool, ...]
    doc: str
    position: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None

    @property
    def dim(self) -> int:
        return len(self.components)

    def labels(self) -> tuple[str, ...]:
        """Axis labels such as ``"range (m)"``, ``"bearing (rad)"``."""
        return tuple(f"{c} ({u})" for c, u in zip(self.components, self.units))

    def to_position(self, z: np.ndarray, sensor=None) -> np.ndarray:
        """The Cartesian position of measurements ``z (..., m)`` seen from ``sensor`` (default: the origin)."""
        if self.position is None:
            raise InputError(f"a {self.name} measurement does not give a Cartesian position")
        z = np.asarray(z, dtype=float)
        d = 3 if self.name.startswith("cartesian-3d") or self.name == "position-doppler-3d" else 2
        s = np.zeros(d) if sensor is None else np.asarray(sensor, dtype=float)
        return self.position(z, s)


def _identity(d: int):
    return lambda z, s: z[..., :d]


def _polar(z: np.ndarray, s: np.ndarray) -> np.ndarray:
    # (r, b) -> (sx + r cos b, sy + r sin b), bearing counter-clockwise from +x
    return np.stack([s[0] + z[..., 0] * np.cos(z[..., 1]), s[1] + z[..., 0] * np.sin(z[..., 1])], axis=-1)


#: The frames the built-in components use; a plugin may use any of these names.
FRAMES: dict[str, Frame] = {f.name: f for f in (
    Frame("cartesian-2d", ("x", "y"), ("m", "m"), (False, False), "Cartesian position in the plane", _identity(2)),
    Frame("cartesian-3d", ("x", "y", "z"), ("m", "m", "m"), (False,) * 3, "Cartesian position in space",
          _identity(3)),
    Frame("range-bearing", ("range", "bearing"), ("m", "rad"), (False, True),
          "range and bearing from the sensor, bearing counter-clockwise from +x (math convention)", _polar),
    Frame("position-doppler-3d", ("x", "y", "z", "radial velocity"), ("m", "m", "m", "m/s"), (False,) * 4,
          "Cartesian position and radial velocity (positive receding) of a monostatic radar", _identity(3)),
    Frame("bistatic-range-rate", ("bistatic range", "bistatic range rate"), ("m", "m/s"), (False, False),
          "bistatic range (transmitter-target-receiver minus baseline) and its rate"),
    Frame("range-rate", ("range", "range rate"), ("m", "m/s"), (False, False),
          "a range and its rate, as a [R, Rdot] state is measured"),
)}


def frame(name: str) -> Frame:
    """The frame called ``name``; :class:`InputError` naming the known ones otherwise."""
    if name not in FRAMES:
        raise InputError(f"unknown measurement frame {name!r} (frames: {', '.join(FRAMES)})")
    return FRAMES[name]


def check_same_frame(a: str, who_a: str, b: str, who_b: str) -> None:
    """Refuse to combine detections of two different declared frames (an undeclared frame, ``""``, passes)."""
    if a and b and a != b:
        raise InputError(f"{who_a} makes {a} detections but {who_b} makes {b} detections; they cannot be combined "
                         f"(convert one, or choose components of the same frame)")
