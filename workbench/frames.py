"""Measurement frames: what the components of a detection are, in which units, and where they put a target.

Every sensor and clutter generator declares the frame of the detections it makes, and every measurement
model the frame of ``h(x)``.  A scenario that merges detections of different frames, or hands a filter
detections in a frame its measurement model does not produce, is refused with a message naming both.

A frame also knows how to turn a measurement into a Cartesian position (for plots and for trackers that
initiate tracks from positions): :meth:`Frame.to_position`.

The built-in frames (:data:`BUILTIN_FRAMES`) are always known.  Plugins add frames through the
``workbench_frames`` hook (:mod:`workbench.hookspecs`); the plugin host registers them when it loads
(:func:`register_frame`), so :func:`frame` and :data:`FRAMES` know them from then on, in this process, with
or without a host at hand.  A plugin frame never redefines a built-in one, and two plugins never define one name
differently: the second is refused (its plugin is reported broken).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Callable, Iterator, Mapping

import numpy as np

from .types import InputError

__all__ = ["Frame", "FRAMES", "BUILTIN_FRAMES", "frame", "check_same_frame", "register_frame",
           "registration_problem", "frame_problems"]


def frame_problems(f: "Frame") -> list[str]:
    """What is wrong with a frame's declaration (empty when nothing is)."""
    out = []
    name = f.name
    if not isinstance(name, str) or not name or name != name.strip() or any(c in name for c in "/\\\0(),"):
        out.append(f"the name must be a non-empty string without slashes, parentheses, commas or surrounding "
                   f"spaces, got {name!r}")
    parts = {"components": f.components, "units": f.units, "angular": f.angular}
    bad = [k for k, v in parts.items() if not isinstance(v, tuple)]
    if bad:
        out.append(f"{', '.join(bad)} must be tuples, got " + ", ".join(f"{k}={parts[k]!r}" for k in bad))
        return out
    m = len(f.components)
    if m == 0:
        out.append("it has no components")
    if not all(isinstance(c, str) and c.strip() for c in f.components) or len(set(f.components)) != m:
        out.append(f"components must be distinct non-empty names, got {f.components!r}")
    if len(f.units) != m or len(f.angular) != m:
        out.append(f"components, units and angular must have one entry each per component ({m} components "
                   f"{f.components!r}), got {len(f.units)} units and {len(f.angular)} angular flags")
    else:
        if not all(isinstance(u, str) and u.strip() for u in f.units):
            out.append(f"units must be non-empty strings (SI: 'm', 'm/s', 'rad'), got {f.units!r}")
        if not all(isinstance(a, bool) for a in f.angular):
            out.append(f"angular must hold booleans, got {f.angular!r}")
        else:
            wrong = [c for c, u, a in zip(f.components, f.units, f.angular) if a and u != "rad"]
            if wrong:
                out.append(f"the angular components {wrong} must be in 'rad' (residuals wrap them to (-pi, pi])")
    if isinstance(f.space, bool) or not isinstance(f.space, int) or not 1 <= f.space <= 3:
        out.append(f"space (the number of Cartesian position axes of what it measures: 1, 2 or 3) must be 1, 2 or "
                   f"3, got {f.space!r}")
    if f.position is not None and not callable(f.position):
        out.append(f"position must be a function position(z, sensor) or None, got {type(f.position).__name__}")
    if not isinstance(f.doc, str):
        out.append(f"doc must be a string, got {type(f.doc).__name__}")
    return out


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
        Which components are angles in radians (residuals wrap them to (-pi, pi]).
    doc : str
    space : int
        The number of Cartesian position axes of the space the measured object moves in (2: the plane, 3: space,
        1: a line); the length of the positions :meth:`to_position` gives and of the position part of the test
        kits' truths (``[p, v]``, ``2 space`` components).
    position : callable or None
        ``position(z (..., m), sensor (space,)) -> (..., space)``: the Cartesian position a measurement implies,
        or ``None`` when a measurement alone does not give one (e.g. a bearing, a bistatic range and its rate).

    A frame that contradicts itself (lengths that disagree, an angular component not in radians, ``space`` not 1
    to 3) is refused when it is made, with an :class:`~workbench.types.InputError` naming the frame.
    """

    name: str
    components: tuple[str, ...]
    units: tuple[str, ...]
    angular: tuple[bool, ...]
    doc: str
    space: int
    position: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        problems = frame_problems(self)
        if problems:
            raise InputError(f"measurement frame {self.name!r}: " + "; ".join(problems))

    @property
    def dim(self) -> int:
        return len(self.components)

    @property
    def summary(self) -> str:
        """One line: the doc and the components with their units."""
        return f"{self.doc} [{', '.join(self.labels())}]"

    def labels(self) -> tuple[str, ...]:
        """Axis labels such as ``"range (m)"``, ``"bearing (rad)"``."""
        return tuple(f"{c} ({u})" for c, u in zip(self.components, self.units))

    def to_position(self, z: np.ndarray, sensor=None) -> np.ndarray:
        """The Cartesian position of measurements ``z (..., m)`` seen from ``sensor`` (default: the origin)."""
        if self.position is None:
            raise InputError(f"a {self.name} measurement does not give a Cartesian position")
        z = np.asarray(z, dtype=float)
        s = np.zeros(self.space) if sensor is None else np.asarray(sensor, dtype=float)
        return self.position(z, s)


def _identity(d: int):
    return lambda z, s: z[..., :d]


def _polar(z: np.ndarray, s: np.ndarray) -> np.ndarray:
    # (r, b) -> (sx + r cos b, sy + r sin b), bearing counter-clockwise from +x
    return np.stack([s[0] + z[..., 0] * np.cos(z[..., 1]), s[1] + z[..., 0] * np.sin(z[..., 1])], axis=-1)


#: The built-in frames: always known, with or without a plugin host; no plugin may redefine one.
BUILTIN_FRAMES: Mapping[str, Frame] = MappingProxyType({f.name: f for f in (
    Frame("cartesian-2d", ("x", "y"), ("m", "m"), (False, False), "Cartesian position in the plane", 2,
          _identity(2)),
    Frame("cartesian-3d", ("x", "y", "z"), ("m", "m", "m"), (False,) * 3, "Cartesian position in space", 3,
          _identity(3)),
    Frame("range-bearing", ("range", "bearing"), ("m", "rad"), (False, True),
          "range and bearing from the sensor, bearing counter-clockwise from +x (math convention)", 2, _polar),
    Frame("bearing", ("bearing",), ("rad",), (True,),
          "bearing from the sensor in the plane, counter-clockwise from +x (math convention); no range, so no "
          "position", 2),
    Frame("position-doppler-3d", ("x", "y", "z", "radial velocity"), ("m", "m", "m", "m/s"), (False,) * 4,
          "Cartesian position and radial velocity (positive receding) of a monostatic radar", 3, _identity(3)),
    Frame("bistatic-range-rate", ("bistatic range", "bistatic range rate"), ("m", "m/s"), (False, False),
          "bistatic range (transmitter-target-receiver minus baseline) and its rate", 3),
    Frame("range-rate", ("range", "range rate"), ("m", "m/s"), (False, False),
          "a range and its rate, as a [R, Rdot] state is measured", 1),
)})

#: name -> (frame, who registered it): the frames plugins added (see :func:`register_frame`).
_PLUGIN_FRAMES: dict[str, tuple[Frame, str]] = {}


class _Frames(Mapping):
    """Every known frame, by name: the built-ins, then those the loaded plugins added (a live, read-only view)."""

    def __getitem__(self, name: str) -> Frame:
        if name in BUILTIN_FRAMES:
            return BUILTIN_FRAMES[name]
        return _PLUGIN_FRAMES[name][0]

    def __contains__(self, name) -> bool:
        return name in BUILTIN_FRAMES or name in _PLUGIN_FRAMES

    def __iter__(self) -> Iterator[str]:
        yield from BUILTIN_FRAMES
        yield from (n for n in list(_PLUGIN_FRAMES) if n not in BUILTIN_FRAMES)

    def __len__(self) -> int:
        return len(BUILTIN_FRAMES) + len(_PLUGIN_FRAMES)

    def __repr__(self) -> str:
        return f"FRAMES({', '.join(self)})"


#: Every known frame by name: :data:`BUILTIN_FRAMES` and the frames of the plugins loaded in this process.
FRAMES: Mapping[str, Frame] = _Frames()


def _same_definition(a: Frame, b: Frame) -> bool:
    try:
        return a == b
    except Exception:  # noqa: BLE001 - a position function whose == misbehaves: not provably the same
        return False


def registration_problem(f: Frame, who: str) -> str:
    """Why frame ``f``, provided by ``who`` (a plugin, as the host names it), cannot be registered, or ``""``.

    A built-in name is refused; so is a name another plugin registered in this process with another definition.
    ``who`` registering its own frame again (a second host loading the same plugin) is fine."""
    if not isinstance(f, Frame):
        return f"expected a workbench.frames.Frame, got {type(f).__name__}"
    if f.name in BUILTIN_FRAMES:
        return (f"frame {f.name!r} is a built-in frame and cannot be redefined (built-in frames: "
                f"{', '.join(BUILTIN_FRAMES)}); give the plugin's frame its own name")
    held = _PLUGIN_FRAMES.get(f.name)
    if held is not None and held[1] != who and not _same_definition(held[0], f):
        return (f"frame {f.name!r} is already defined differently by {held[1]} in this process; frames are never "
                f"shadowed: rename one")
    return ""


def register_frame(f: Frame, who: str) -> None:
    """Make frame ``f`` (provided by ``who``) known to :func:`frame` and :data:`FRAMES` in this process.

    The plugin host calls this for the frames of the plugins it loads; :class:`InputError` where
    :func:`registration_problem` finds a problem."""
    problem = registration_problem(f, who)
    if problem:
        raise InputError(f"{who}: {problem}")
    _PLUGIN_FRAMES[f.name] = (f, who)


def frame(name: str) -> Frame:
    """The frame called ``name`` (built in, or added by a loaded plugin); :class:`InputError` naming the known
    ones otherwise."""
    if name in FRAMES:
        return FRAMES[name]
    hint = ("" if _PLUGIN_FRAMES else "; a frame a plugin provides is known once the plugin host has loaded "
            "(workbench.plugins.load_host())")
    raise InputError(f"unknown measurement frame {name!r} (frames: {', '.join(FRAMES)}){hint}")


def check_same_frame(a: str, who_a: str, b: str, who_b: str) -> None:
    """Refuse to combine detections of two different declared frames (an undeclared frame, ``""``, passes)."""
    if a and b and a != b:
        raise InputError(f"{who_a} makes {a} detections but {who_b} makes {b} detections; they cannot be combined "
                         f"(convert one, or choose components of the same frame)")
