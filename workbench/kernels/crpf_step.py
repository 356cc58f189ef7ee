"""One fused step of the cost-reference particle filter (paper 003) for a range-bearing sensor.

For every run ``b`` (one parallel iteration each) and its ``N`` particles, with the measurement
``z_b = [r, theta]`` of a sensor at ``s`` and ``h(x) = [|p - s|, atan2(p_y - s_y, p_x - s_x)]``::

    dC(x | z)  = (dr^2 + (a dtheta)^2)^(q/2),  dtheta wrapped to (-pi, pi], a = 1 or |r| (arc-length)
    R^(i)      = lam C^(i) + dC(F x^(i) | z)                     risk, noise-free prediction
    pi^(i)    ~  (R^(i) - min_k R^(k) + delta)^-beta              selection PMF
    k_i        = systematic counts of pi with offset u0_b        (ceil(N cdf_i - u0) differences)
    x'^(j)     = F x^(parent j) + std * e^(j)                     propagation (e standard normal, given)
    C'^(j)     = lam C^(parent j) + dC(x'^(j) | z)                cost update
    pi'^(j)   ~  (C'^(j) - min C' + delta)^-beta,  mean = sum pi' x',  cov = sum pi' (x' - mean)(.)^T

Every random number is drawn by the caller in NumPy (``u0 (B,)`` uniforms in [0, 1) and ``e (B, N, n)``
standard normals), so all backends give the same particles up to float round-off.  A row whose risks
contain NaN, or are all infinite, is selected uniformly (as :func:`workbench.resampling.systematic_counts`
does); an infinite risk gets weight zero.

Backends (held to :func:`crpf_step_numpy`, which is written with the workbench's log-domain PMF,
:func:`workbench.resampling.systematic_counts` and the measurement model's ``h``):

- ``"taichi"``: one run per parallel iteration, any Taichi arch;
- ``"numba"`` (optional dependency): the same loops with ``numba.prange`` over runs, CPU only;
- ``"numpy"``: :func:`crpf_step_numpy`;
- ``"auto"``: Numba when it is installed and the arch is the CPU, else Taichi
  (:func:`workbench.kernels.tbd_weights.resolve_backend`).

Shapes: ``x (B, N, n)`` with position ``x, y`` first, ``c (B, N)``, ``F (n, n)``, ``z (B, 2)``,
``e (B, N, n)``, ``u0 (B,)``, ``std (n,)`` -> ``x' (B, N, n)``, ``C' (B, N)``, ``mean (B, n)``,
``cov (B, n, n)``.  (No ``from __future__ import annotations``: Taichi reads the annotations as objects.)
"""

import functools
import math

import numpy as np

from ..linalg import wrap_angle
from ..models import range_bearing
from ..resampling import normalise_log_weights, systematic_counts
from .runtime import ensure_taichi
from .tbd_weights import numba_available, resolve_backend

__all__ = ["crpf_step", "crpf_step_numpy", "numba_available", "resolve_backend"]

TWO_PI = 2.0 * math.pi


def _check(x, c, F, z, e, u0, std):
    x = np.ascontiguousarray(x, dtype=np.float64)
    B, N, n = x.shape
    c = np.ascontiguousarray(c, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.float64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    e = np.ascontiguousarray(e, dtype=np.float64)
    u0 = np.ascontiguousarray(np.reshape(u0, (B,)), dtype=np.float64)
    std = np.ascontiguousarray(std, dtype=np.float64)
    if c.shape != (B, N) or F.shape != (n, n) or z.shape != (B, 2) or e.shape != (B, N, n) or std.shape != (n,):
        raise ValueError(f"crpf_step: inconsistent shapes x {x.shape}, c {c.shape}, F {F.shape}, z {z.shape}, "
                         f"e {e.shape}, std {std.shape}")
    if n < 2:
        raise ValueError("crpf_step: the state needs a 2-D position first (n >= 2)")
    return x, c, F, z, e, u0, std


def _cost_numpy(z, points, model, q, arc):
    """``dC(x | z)`` from the model's ``h`` and a wrapped bearing residual: ``(B, N)``."""
    hx = model.h(points)
    dr = z[:, None, 0] - hx[..., 0]
    dt = wrap_angle(z[:, None, 1] - hx[..., 1])
    if arc:
        dt = dt * np.abs(z[:, 0])[:, None]
    return (dr ** 2 + dt ** 2) ** (0.5 * q)


def _log_pmf_numpy(costs, beta, delta):
    # log pi = -beta log(C - min C + delta); rows with NaN or no finite cost are uniform
    cmin = np.min(costs, axis=1, keepdims=True)
    ok = np.isfinite(cmin)
    gap = np.where(ok, costs - np.where(ok, cmin, 0.0), 0.0)
    return -beta * np.log(gap + delta)


def crpf_step_numpy(x, c, F, z, e, u0, std, lam, beta, delta, q=2.0, arc=False, sensor=(0.0, 0.0)):
    """The NumPy twin every kernel backend is held to (same inputs and outputs as :func:`crpf_step`)."""
    x, c, F, z, e, u0, std = _check(x, c, F, z, e, u0, std)
    B, N, n = x.shape
    model = range_bearing(1.0, 1.0, sensor)
    xf = x @ F.T  # f(x) = F x
    # R = lam C + dC(F x | z)
    risk = lam * c + _cost_numpy(z, xf, model, q, arc)
    counts = systematic_counts(_log_pmf_numpy(risk, beta, delta), u0)  # (B, N)
    flat = np.repeat(np.arange(B * N), counts.ravel())
    # x' = F x_parent + std e ;  C' = lam C_parent + dC(x' | z)
    x_new = xf.reshape(B * N, n)[flat].reshape(B, N, n) + std * e
    c_new = lam * c.ravel()[flat].reshape(B, N) + _cost_numpy(z, x_new, model, q, arc)
    w = np.exp(normalise_log_weights(_log_pmf_numpy(c_new, beta, delta)))
    mean = np.einsum("bi,bij->bj", w, x_new)
    d = x_new - mean[:, None, :]
    cov = np.einsum("bi,bij,bik->bjk", w, d, d)
    return x_new, c_new, mean, 0.5 * (cov + np.swapaxes(cov, 1, 2))


def crpf_step(x, c, F, z, e, u0, std, lam, beta, delta, q=2.0, arc=False, sensor=(0.0, 0.0),
              backend="auto", arch="cpu"):
    """One CRPF step (risk, selection, propagation, cost, estimate) for every run; see the module docstring.

    Parameters
    ----------
    x, c : particles and costs before the step
    F : motion matrix; z : measured ``[range, bearing]`` per run
    e : standard normals of the propagation; u0 : systematic-resampling offsets in [0, 1)
    std : per-component propagation standard deviation
    lam, beta, delta, q : forgetting factor, PMF exponent and offset, cost exponent
    arc : arc-length cost (bearing residual times the measured range)
    sensor : sensor position ``(x, y)``
    backend, arch : ``"auto"``, ``"numba"``, ``"taichi"`` or ``"numpy"``; the Taichi arch

    Shapes
    ------
    x : (B, N, n); c : (B, N); F : (n, n); z : (B, 2); e : (B, N, n); u0 : (B,); std : (n,)
    returns : x' (B, N, n), C' (B, N), mean (B, n), cov (B, n, n)
    """
    which = resolve_backend(backend, arch)
    if which == "numpy":
        return crpf_step_numpy(x, c, F, z, e, u0, std, lam, beta, delta, q, arc, sensor)
    x, c, F, z, e, u0, std = _check(x, c, F, z, e, u0, std)
    B, N, n = x.shape
    x_new = np.empty_like(x)
    c_new = np.empty_like(c)
    mean = np.empty((B, n))
    cov = np.empty((B, n, n))
    scratch = np.empty((B, N))
    scal = np.array([lam, beta, delta, q, 1.0 if arc else 0.0, float(sensor[0]), float(sensor[1])])
    if B and N:
        if which == "numba":
            _numba_kernel()(x, c, F, z, e, u0, std, scal, x_new, c_new, mean, cov, scratch)
        else:
            ensure_taichi(arch)
            _taichi_kernel()(x, c, F, z, e, u0, std, scal, x_new, c_new, mean, cov, scratch)
    return x_new, c_new, mean, cov


# -- Numba (optional) -----------------------------------------------------------------------------


@functools.cache
def _numba_kernel():
    import numba

    @numba.njit(inline="always", fastmath=False)
    def cost(px, py, zr, zt, sx, sy, q, arc):
        dx = px - sx
        dy = py - sy
        dr = zr - math.sqrt(dx * dx + dy * dy)
        a = zt - math.atan2(dy, dx)
        # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
        dt = a - TWO_PI * math.ceil((a - math.pi) * (1.0 / TWO_PI))
        if arc:
            dt *= abs(zr)
        sq = dr * dr + dt * dt
        # dC = ||z - h(x)||^q
        return sq if q == 2.0 else sq ** (0.5 * q)

    @numba.njit(inline="always", fastmath=False)
    def pmf(vals, N, beta, delta, w):
        """w_i ~ (v_i - min v + delta)^-beta (scaled so the best is 1); returns the sum."""
        m = math.inf
        bad = False
        for i in range(N):
            v = vals[i]
            if v != v:
                bad = True
            elif v < m:
                m = v
        bad = bad or not (m < math.inf)
        total = 0.0
        for i in range(N):
            # pi ~ (C - min C + delta)^-beta = ((C - min C + delta) / delta)^-beta up to a constant
            t = (vals[i] - m + delta) / delta
            wi = 1.0 if bad else (1.0 / (t * t) if beta == 2.0 else t ** (-beta))
            w[i] = wi
            total += wi
        return total

    @numba.njit(parallel=True, fastmath=False, cache=True)
    def kernel(x, c, F, z, e, u0, std, scal, x_new, c_new, mean, cov, scratch):
        B, N, n = x.shape
        lam, beta, delta, q = scal[0], scal[1], scal[2], scal[3]
        arc = scal[4] != 0.0
        sx, sy = scal[5], scal[6]
        for b in numba.prange(B):
            zr, zt = z[b, 0], z[b, 1]
            w = scratch[b]
            # R = lam C + dC(F x | z)
            for i in range(N):
                px = 0.0
                py = 0.0
                for k in range(n):
                    px += F[0, k] * x[b, i, k]
                    py += F[1, k] * x[b, i, k]
                w[i] = lam * c[b, i] + cost(px, py, zr, zt, sx, sy, q, arc)
            total = pmf(w, N, beta, delta, w)
            # systematic selection: edge_i = clip(ceil(N cdf_i - u0), 0, N), k_i = edge_i - edge_{i-1}
            cum = 0.0
            prev = 0
            j = 0
            for i in range(N):
                cum += w[i]
                frac = 1.0 if i == N - 1 else cum / total  # the last cdf entry is exactly 1
                ie = int(min(max(math.ceil(N * frac - u0[b]), 0.0), float(N)))
                for _ in range(ie - prev):
                    # x' = F x_parent + std e ;  C' = lam C_parent + dC(x' | z)
                    for r in range(n):
                        acc = 0.0
                        for k in range(n):
                            acc += F[r, k] * x[b, i, k]
                        x_new[b, j, r] = acc + std[r] * e[b, j, r]
                    c_new[b, j] = lam * c[b, i] + cost(x_new[b, j, 0], x_new[b, j, 1], zr, zt, sx, sy, q, arc)
                    j += 1
                prev = max(prev, ie)
            # estimate: pi' ~ (C' - min C' + delta)^-beta, weighted mean and covariance
            total = pmf(c_new[b], N, beta, delta, w)
            for r in range(n):
                acc = 0.0
                for i in range(N):
                    acc += w[i] * x_new[b, i, r]
                mean[b, r] = acc / total
            for r in range(n):
                for s in range(r + 1):
                    acc = 0.0
                    for i in range(N):
                        acc += w[i] * (x_new[b, i, r] - mean[b, r]) * (x_new[b, i, s] - mean[b, s])
                    cov[b, r, s] = acc / total
                    cov[b, s, r] = acc / total

    return kernel


# -- Taichi ---------------------------------------------------------------------------------------


@functools.cache
def _taichi_kernel():
    import taichi as ti

    # Every constant goes through ti.f64(...) in Taichi scope: a bare literal would take default_fp (f32).
    @ti.func
    def cost(px, py, zr, zt, sx, sy, q, arc):
        dx = px - sx
        dy = py - sy
        dr = zr - ti.sqrt(dx * dx + dy * dy)
        a = zt - ti.atan2(dy, dx)
        # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
        dt = a - ti.f64(TWO_PI) * ti.ceil((a - ti.f64(math.pi)) * ti.f64(1.0 / TWO_PI))
        if arc:
            dt *= ti.abs(zr)
        sq = dr * dr + dt * dt
        out = sq
        if q != ti.f64(2.0):
            # dC = ||z - h(x)||^q
            out = ti.pow(sq, ti.f64(0.5) * q)
        return out

    @ti.func
    def pmf_min(vals: ti.template(), b, N):
        """(min over the row, whether the row is bad: a NaN or no finite value)."""
        m = ti.f64(math.inf)
        bad = 0
        for i in range(N):
            v = vals[b, i]
            if v != v:
                bad = 1
            elif v < m:
                m = v
        if not (m < ti.f64(math.inf)):
            bad = 1
        return m, bad

    @ti.func
    def pmf(vals: ti.template(), b, N, beta, delta, w: ti.template()):
        """Write pi_i ~ ((v_i - min v + delta) / delta)^-beta of row ``b`` into ``w[b]`` (uniform for a bad
        row); return the sum.  ``vals`` may be ``w`` itself."""
        m, bad = pmf_min(vals, b, N)
        total = ti.f64(0.0)
        for i in range(N):
            wi = ti.f64(1.0)
            if not bad:
                t = (vals[b, i] - m + delta) / delta
                wi = 1.0 / (t * t) if beta == ti.f64(2.0) else ti.pow(t, -beta)
            w[b, i] = wi
            total += wi
        return total

    @ti.kernel
    def kernel(x: ti.types.ndarray(dtype=ti.f64, ndim=3), c: ti.types.ndarray(dtype=ti.f64, ndim=2),
               F: ti.types.ndarray(dtype=ti.f64, ndim=2), z: ti.types.ndarray(dtype=ti.f64, ndim=2),
               e: ti.types.ndarray(dtype=ti.f64, ndim=3), u0: ti.types.ndarray(dtype=ti.f64, ndim=1),
               std: ti.types.ndarray(dtype=ti.f64, ndim=1), scal: ti.types.ndarray(dtype=ti.f64, ndim=1),
               x_new: ti.types.ndarray(dtype=ti.f64, ndim=3), c_new: ti.types.ndarray(dtype=ti.f64, ndim=2),
               mean: ti.types.ndarray(dtype=ti.f64, ndim=2), cov: ti.types.ndarray(dtype=ti.f64, ndim=3),
               w: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        B, N, n = x.shape[0], x.shape[1], x.shape[2]
        lam, beta, delta, q = scal[0], scal[1], scal[2], scal[3]
        arc = scal[4] != ti.f64(0.0)
        sx, sy = scal[5], scal[6]
        for b in range(B):  # the outermost loop runs in parallel: one run per iteration
            zr, zt = z[b, 0], z[b, 1]
            # R = lam C + dC(F x | z)
            for i in range(N):
                px = ti.f64(0.0)
                py = ti.f64(0.0)
                for k in range(n):
                    px += F[0, k] * x[b, i, k]
                    py += F[1, k] * x[b, i, k]
                w[b, i] = lam * c[b, i] + cost(px, py, zr, zt, sx, sy, q, arc)
            total = pmf(w, b, N, beta, delta, w)
            # systematic selection: edge_i = clip(ceil(N cdf_i - u0), 0, N), k_i = edge_i - edge_{i-1}
            cum = ti.f64(0.0)
            prev = 0
            j = 0
            for i in range(N):
                cum += w[b, i]
                frac = cum / total
                if i == N - 1:
                    frac = ti.f64(1.0)
                ie = ti.cast(ti.min(ti.max(ti.ceil(ti.cast(N, ti.f64) * frac - u0[b]), ti.f64(0.0)),
                                    ti.cast(N, ti.f64)), ti.i32)
                for _ in range(ie - prev):
                    # x' = F x_parent + std e ;  C' = lam C_parent + dC(x' | z)
                    for r in range(n):
                        acc = ti.f64(0.0)
                        for k in range(n):
                            acc += F[r, k] * x[b, i, k]
                        x_new[b, j, r] = acc + std[r] * e[b, j, r]
                    c_new[b, j] = lam * c[b, i] + cost(x_new[b, j, 0], x_new[b, j, 1], zr, zt, sx, sy, q, arc)
                    j += 1
                prev = ti.max(prev, ie)
            # estimate: pi' ~ (C' - min C' + delta)^-beta, weighted mean and covariance
            total = pmf(c_new, b, N, beta, delta, w)
            for r in range(n):
                acc = ti.f64(0.0)
                for i in range(N):
                    acc += w[b, i] * x_new[b, i, r]
                mean[b, r] = acc / total
            for r in range(n):
                for s in range(r + 1):
                    acc = ti.f64(0.0)
                    for i in range(N):
                        acc += w[b, i] * (x_new[b, i, r] - mean[b, r]) * (x_new[b, i, s] - mean[b, s])
                    cov[b, r, s] = acc / total
                    cov[b, s, r] = acc / total

    return kernel
