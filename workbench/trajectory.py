"""Truth trajectories: piecewise manoeuvre legs, and random paths drawn from a motion model."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .models import MotionModel
from .types import InputError, Truth, check_size

__all__ = ["Leg", "piecewise_trajectory", "sample_motion"]

_KINDS = ("straight", "turn", "climb")


@dataclass(frozen=True)
class Leg:
    """One manoeuvre leg.

    kind : ``"straight"`` (constant velocity), ``"turn"`` (coordinated turn of the horizontal velocity at
    ``turn_rate`` rad/s, positive = counter-clockwise, speed kept) or ``"climb"`` (vertical speed set to
    ``climb_rate`` m/s for the leg, then back to level flight unless the next leg is a climb too).
    duration : seconds.
    """

    kind: str
    duration: float
    turn_rate: float = 0.0
    climb_rate: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise InputError(f"leg kind must be one of {_KINDS}, got {self.kind!r}")
        if not self.duration > 0:
            raise InputError(f"leg duration must be > 0 s, got {self.duration}")


def piecewise_trajectory(position: Sequence[float], velocity: Sequence[float], legs: Sequence[Leg],
                         dt: float) -> Truth:
    """A deterministic trajectory of piecewise legs, sampled every ``dt``; a batch of one.

    The state is ``[p, v]`` in 2-D or 3-D; the first sample is the start state.  Turns rotate
    ``(vx, vy)`` exactly (closed-form integration of the coordinated turn within each step).
    """
    p = np.asarray(position, dtype=float).copy()
    v = np.asarray(velocity, dtype=float).copy()
    if p.shape != v.shape or p.shape[0] not in (2, 3):
        raise InputError(f"position and velocity must both be 2-D or 3-D, got {p.shape} and {v.shape}")
    if dt <= 0:
        raise InputError(f"dt must be > 0, got {dt}")
    states = [np.concatenate([p, v])]
    for leg in legs:
        steps = int(round(leg.duration / dt))
        for _ in range(steps):
            if leg.kind == "turn" and leg.turn_rate != 0.0:
                w = leg.turn_rate
                s, c = np.sin(w * dt), np.cos(w * dt)
                vx, vy = v[0], v[1]
                p[0] += (s * vx - (1 - c) * vy) / w
                p[1] += ((1 - c) * vx + s * vy) / w
                v[0], v[1] = c * vx - s * vy, s * vx + c * vy
                if p.shape[0] == 3:
                    p[2] += v[2] * dt
            else:
                if leg.kind == "climb" and p.shape[0] == 3:
                    v[2] = leg.climb_rate
                p = p + v * dt
            states.append(np.concatenate([p, v]))
        if leg.kind == "climb" and p.shape[0] == 3:
            v[2] = 0.0
    states = np.asarray(states)[None]
    return Truth(states, dt * np.arange(states.shape[1]))


def sample_motion(x0: np.ndarray, motion: MotionModel, steps: int, rng: np.random.Generator, *,
                  t0: float = 0.0) -> Truth:
    """Random paths ``x_k = f(x_{k-1}; t_{k-1}, dt) + Q_sqrt e_k`` from start states ``x0 (B, n)`` at time ``t0``;
    ``steps`` samples each, at ``t_k = t0 + k dt`` (``dt``: the model's step).

    ``f(x) = F x`` for a linear model; the model's own ``f`` where a subclass overrides it, called on the model
    bound to each step (``motion.at(t_{k-1}, dt)``), so a time-varying model (e.g. the growth model) is sampled
    at the right time.
    """
    x0 = np.atleast_2d(np.asarray(x0, dtype=float))
    B, n = x0.shape
    if n != motion.dim:
        raise InputError(f"start states have dimension {n} but the motion model has {motion.dim}")
    try:
        t0 = float(t0)
    except (TypeError, ValueError):
        raise InputError(f"sample_motion: t0 must be a time in seconds, got {t0!r}") from None
    if not np.isfinite(t0):
        raise InputError(f"sample_motion: t0 must be finite, got {t0}")
    steps = check_size("sample_motion: steps", steps, 2 * 8.0 * B * n)
    noise = rng.standard_normal((B, steps - 1, n)) @ motion.Q_sqrt.T
    states = np.empty((B, steps, n))
    states[:, 0] = x0
    times = t0 + motion.dt * np.arange(steps)
    for k in range(1, steps):
        if motion.linear:
            moved = states[:, k - 1] @ motion.F.T
        else:
            moved = motion.at(float(times[k - 1])).f(states[:, k - 1])
        states[:, k] = moved + noise[:, k - 1]
    return Truth(states, times)
