"""Bistatic geometry of a passive radar: excess path, its rate, and the Doppler <-> range-rate map.

One sign convention is used everywhere in the workbench (truth, signal model, candidate lists, filter):

    f_D = -(1/lambda) dR/dt,    i.e.    Rdot = -lambda f_D

so a *positive* Doppler shift means an *approaching* target whose bistatic range is *decreasing*.
The bistatic range is the excess path ``|p - Tx| + |p - Rx| - |Tx - Rx|`` (zero on the baseline); the
baseline is always subtracted, in truth, in the cross-ambiguity delay axis and in the tracker.

All functions broadcast over leading axes: positions ``(..., d)`` with ``d`` = 2 or 3.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "SPEED_OF_LIGHT",
    "wavelength",
    "bistatic_range",
    "bistatic_range_rate",
    "range_and_rate",
    "doppler_to_range_rate",
    "range_rate_to_doppler",
    "monostatic_velocity",
]

#: Speed of light in vacuum (m/s).
SPEED_OF_LIGHT = 299_792_458.0


def wavelength(frequency_hz: float) -> float:
    """Carrier wavelength ``lambda = c / f`` (m); 701 MHz gives 0.42766 m."""
    return SPEED_OF_LIGHT / float(frequency_hz)


def _norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", a, a))


def bistatic_range(p, tx, rx) -> np.ndarray:
    """Bistatic range (excess path length) of points ``p``.

    ``R = |p - Tx| + |p - Rx| - |Tx - Rx|``.

    Shapes
    ------
    p : (..., d)
    tx, rx : (d,) or broadcastable to ``p``
    returns : (...)
    """
    p = np.asarray(p, dtype=float)
    tx = np.asarray(tx, dtype=float)
    rx = np.asarray(rx, dtype=float)
    # R = |p - Tx| + |p - Rx| - |Tx - Rx|
    return _norm(p - tx) + _norm(p - rx) - _norm(tx - rx)


def bistatic_range_rate(p, v, tx, rx) -> np.ndarray:
    """Rate of change of the bistatic range of a point at ``p`` moving with velocity ``v``.

    ``Rdot = v . (u_T + u_R)`` with the unit vectors ``u_T = (p - Tx)/|p - Tx|`` and
    ``u_R = (p - Rx)/|p - Rx|`` (stationary transmitter and receiver).

    Shapes
    ------
    p, v : (..., d)
    tx, rx : (d,) or broadcastable
    returns : (...)
    """
    p = np.asarray(p, dtype=float)
    v = np.asarray(v, dtype=float)
    d_t = p - np.asarray(tx, dtype=float)
    d_r = p - np.asarray(rx, dtype=float)
    # u_T + u_R
    u_sum = d_t / _norm(d_t)[..., None] + d_r / _norm(d_r)[..., None]
    # Rdot = v . (u_T + u_R)
    return np.einsum("...i,...i->...", v, u_sum)


def range_and_rate(states, tx, rx) -> np.ndarray:
    """``[R, Rdot]`` of states ``[p, v]`` (positions first, then velocities, ``d`` of each).

    Shapes: ``states (..., 2d)`` with ``d`` = 2 or 3 (``tx``, ``rx`` are cut to ``d`` components)
    -> ``(..., 2)``.
    """
    states = np.asarray(states, dtype=float)
    d = states.shape[-1] // 2
    tx = np.asarray(tx, dtype=float)[:d]
    rx = np.asarray(rx, dtype=float)[:d]
    p, v = states[..., :d], states[..., d:2 * d]
    return np.stack([bistatic_range(p, tx, rx), bistatic_range_rate(p, v, tx, rx)], axis=-1)


def doppler_to_range_rate(f_d, wavelength_m: float) -> np.ndarray:
    """Bistatic range-rate (m/s) from Doppler (Hz): ``Rdot = -lambda f_D`` (positive Doppler = approaching)."""
    # Rdot = -lambda f_D
    return -float(wavelength_m) * np.asarray(f_d, dtype=float)


def range_rate_to_doppler(range_rate, wavelength_m: float) -> np.ndarray:
    """Doppler (Hz) from bistatic range-rate (m/s): ``f_D = -Rdot / lambda``."""
    # f_D = -(1/lambda) dR/dt
    return -np.asarray(range_rate, dtype=float) / float(wavelength_m)


def monostatic_velocity(f_d, wavelength_m: float) -> np.ndarray:
    """The *mismatched* reading of a bistatic Doppler as a monostatic radial velocity (m/s).

    ``v = -lambda f_D / 2``: the monostatic two-way formula ``|v| = lambda |f_D| / 2`` with the
    workbench's sign (positive = receding), so that the only difference from
    :func:`doppler_to_range_rate` is the physical one, the factor 1/2 (for ablations that
    read a bistatic Doppler as a monostatic one).
    """
    # v = lambda f_D / 2 in magnitude; sign as Rdot
    return -0.5 * float(wavelength_m) * np.asarray(f_d, dtype=float)
