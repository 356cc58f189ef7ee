"""The NumPy twin of the fused CRPF step and the constants its compiled versions share (no backend imports).

See :mod:`.crpf_step` for the step's formulas; every backend is held to :func:`crpf_step_numpy`.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.kernels.counter_normals import counter_normals, counter_normals_numpy
from workbench.linalg import wrap_angle
from workbench.models import range_bearing
from workbench.resampling import normalise_log_weights, systematic_counts

__all__ = ["crpf_step_numpy", "propagation_normals", "pmf_offset", "TWO_PI"]

TWO_PI = 2.0 * math.pi


def _spread(a, shape: tuple) -> np.ndarray:
    """``a`` broadcast to ``shape`` (itself where it has that shape already: a one-track step calls this twice)."""
    a = np.asarray(a)
    return a if a.shape == shape else np.broadcast_to(a, shape)


def _check(x, c, s2, t, F, z, u0, shape):
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.ndim != 3:
        raise ValueError(f"crpf_step: particles must be (B, N, n), got shape {x.shape}")
    B, N, n = x.shape
    c = np.ascontiguousarray(c, dtype=np.float64)
    s2 = np.ascontiguousarray(_spread(s2, (B, N)), dtype=np.float64)
    t = np.ascontiguousarray(_spread(t, (B,)), dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.float64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    u0 = np.ascontiguousarray(np.reshape(u0, (B,)), dtype=np.float64)
    shape = np.ascontiguousarray(shape, dtype=np.float64)
    if c.shape != (B, N) or F.shape != (n, n) or z.shape != (B, 2) or shape.shape != (n,):
        raise ValueError(f"crpf_step: inconsistent shapes x {x.shape}, c {c.shape}, F {F.shape}, z {z.shape}, "
                         f"shape {shape.shape}")
    if n < 2:
        raise ValueError("crpf_step: the state needs a 2-D position first (n >= 2)")
    return x, c, s2, t, F, z, u0, shape


def propagation_normals(key: int, B: int, N: int, n: int, twin: bool = False, backend: str = "auto") -> np.ndarray:
    """The standard normals ``e (B, N, n)`` of the propagation for stream ``key`` (``twin``: computed by
    the pure NumPy :func:`~workbench.kernels.counter_normals.counter_normals_numpy`; else by
    :func:`~workbench.kernels.counter_normals.counter_normals` for ``backend``, the policy's choice; the same
    numbers)."""
    if twin:
        return counter_normals_numpy(key, B, N * n).reshape(B, N, n)
    return counter_normals(key, B, N * n, backend).reshape(B, N, n)


def pmf_offset(values: np.ndarray, delta: float, relative: bool) -> np.ndarray:
    """The offset ``delta_b`` of the PMF ``(v - min v + delta_b)^-beta`` for each row of ``values (B, N)``: ``(B, 1)``.

    Absolute: ``delta``.  Relative: ``delta`` times the mean gap of the row's finite values above their minimum,
    ``delta_b = delta * (mean_i v_i - min_i v_i)``, so the PMF does not change when every cost is scaled; a row
    without spread (or without a finite value) takes ``delta`` itself (its finite values are then equally
    likely whatever the offset).
    """
    values = np.asarray(values, dtype=float)
    B = values.shape[0]
    if not relative:
        return np.full((B, 1), float(delta))
    finite = np.isfinite(values)
    count = finite.sum(axis=1)
    vmin = np.min(np.where(finite, values, np.inf), axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        # delta_b = delta * (mean_i v_i - min_i v_i) over the finite v_i
        gap = np.sum(np.where(finite, values, 0.0), axis=1) / np.maximum(count, 1) - vmin
    ok = (count > 0) & np.isfinite(gap) & (gap > 0.0)
    return np.where(ok, delta * np.where(ok, gap, 1.0), delta)[:, None]


def _cost_numpy(z, points, model, q, arc):
    """``dC(x | z)`` from the model's ``h`` and a wrapped bearing residual: ``(B, N)``."""
    hx = model.h(points)
    dr = z[:, None, 0] - hx[..., 0]
    dt = wrap_angle(z[:, None, 1] - hx[..., 1])
    if arc:
        dt = dt * np.abs(z[:, 0])[:, None]
    return (dr ** 2 + dt ** 2) ** (0.5 * q)


def _log_pmf_numpy(costs, beta, delta, relative):
    # log pi = -beta log(C - min C + delta_b); rows with NaN or no finite cost are uniform
    cmin = np.min(costs, axis=1, keepdims=True)
    ok = np.isfinite(cmin)
    gap = np.where(ok, costs - np.where(ok, cmin, 0.0), 0.0)
    return -beta * np.log(gap + pmf_offset(costs, delta, relative))


def crpf_step_numpy(x, c, s2, t, F, z, key, u0, shape, lam, beta, delta, q=2.0, arc=False, sensor=(0.0, 0.0),
                    adaptive=True, relative=True):
    """The NumPy twin every kernel backend is held to (same inputs and outputs as :func:`crpf_step`)."""
    x, c, s2, t, F, z, u0, shape = _check(x, c, s2, t, F, z, u0, shape)
    B, N, n = x.shape
    e = propagation_normals(key, B, N, n, twin=True)
    model = range_bearing(1.0, 1.0, sensor)
    xf = x @ F.T  # f(x) = F x
    # R = lam C + dC(F x | z)
    risk = lam * c + _cost_numpy(z, xf, model, q, arc)
    counts = systematic_counts(_log_pmf_numpy(risk, beta, delta, relative), u0)  # (B, N)
    flat = np.repeat(np.arange(B * N), counts.ravel())
    parent_xf = xf.reshape(B * N, n)[flat].reshape(B, N, n)
    parent_s2 = s2.ravel()[flat].reshape(B, N)
    # x' ~ N(F x_parent, sigma_parent^2 diag(shape^2)):  x' = F x_parent + shape sigma_parent e
    x_new = parent_xf + shape * np.sqrt(parent_s2)[..., None] * e
    if adaptive:
        # sigma'^2 = ((t - 1) / t) sigma_parent^2 + ||(x' - F x_parent) / shape||^2 / (t dim)
        dev = (x_new - parent_xf) / shape
        s2_new = ((t - 1.0) / t)[:, None] * parent_s2 + np.sum(dev * dev, axis=-1) / (t[:, None] * n)
    else:
        s2_new = parent_s2
    # C' = lam C_parent + dC(x' | z)
    c_new = lam * c.ravel()[flat].reshape(B, N) + _cost_numpy(z, x_new, model, q, arc)
    w = np.exp(normalise_log_weights(_log_pmf_numpy(c_new, beta, delta, relative)))
    mean = np.einsum("bi,bij->bj", w, x_new)
    d = x_new - mean[:, None, :]
    cov = np.einsum("bi,bij,bik->bjk", w, d, d)
    return x_new, c_new, s2_new, mean, 0.5 * (cov + np.swapaxes(cov, 1, 2))
