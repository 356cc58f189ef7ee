"""One fused step of the cost-reference particle filter for a range-bearing sensor.

For every run ``b`` (one parallel iteration each) and its ``N`` particles, with the measurement
``z_b = [r, theta]`` of a sensor at ``s`` and ``h(x) = [|p - s|, atan2(p_y - s_y, p_x - s_x)]``::

    dC(x | z)  = (dr^2 + (a dtheta)^2)^(q/2),  dtheta wrapped to (-pi, pi], a = 1 or |r| (arc-length)
    R^(i)      = lam C^(i) + dC(F x^(i) | z)                     risk, noise-free prediction
    pi^(i)    ~  (R^(i) - min_k R^(k) + delta)^-beta              selection PMF
    k_i        = systematic counts of pi with offset u0_b        (ceil(N cdf_i - u0) differences)
    x'^(j)     = F x^(parent j) + std * e^(j)                     propagation, e standard normal
    C'^(j)     = lam C^(parent j) + dC(x'^(j) | z)                cost update
    pi'^(j)   ~  (C'^(j) - min C' + delta)^-beta,  mean = sum pi' x',  cov = sum pi' (x' - mean)(.)^T

The randomness comes from the caller: ``u0 (B,)`` uniforms in [0, 1) and a stream ``key`` of counter-based
normals (:mod:`workbench.kernels.counter_normals`), ``e[b] = counter_normals(key, B, N n)[b]`` reshaped to
``(N, n)``; the Numba kernel computes them in place, vectorised, the other backends take them from the
NumPy twin.  So all backends give the same particles up to float round-off.  A row whose risks
contain NaN, or are all infinite, is selected uniformly (as :func:`workbench.resampling.systematic_counts`
does); an infinite risk gets weight zero.

Backends (held to :func:`crpf_step_numpy`, which is written with the workbench's log-domain PMF,
:func:`workbench.resampling.systematic_counts` and the measurement model's ``h``):

- ``"taichi"``: one run per parallel iteration, any Taichi arch;
- ``"numba"`` (the CPU default): the same loops with ``numba.prange`` over runs, CPU only;
- ``"numpy"``: :func:`crpf_step_numpy`;
- ``"auto"``: Numba when the arch is the CPU and Numba is installed, else Taichi
  (the policy of :mod:`workbench.kernels.backend`).

Shapes: ``x (B, N, n)`` with position ``x, y`` first, ``c (B, N)``, ``F (n, n)``, ``z (B, 2)``,
``key`` an unsigned 64-bit int, ``u0 (B,)``, ``std (n,)`` -> ``x' (B, N, n)``, ``C' (B, N)``, ``mean (B, n)``,
``cov (B, n, n)``.  (No ``from __future__ import annotations``: Taichi reads the annotations as objects.)
"""

import functools
import math

import numpy as np

from ..linalg import wrap_angle
from ..models import range_bearing
from ..resampling import normalise_log_weights, systematic_counts
from .counter_normals import counter_normals, counter_normals_numpy
from .runtime import ensure_taichi
from .backend import current_arch, numba_available, resolve as resolve_backend

__all__ = ["crpf_step", "crpf_step_numpy", "numba_available", "propagation_normals", "resolve_backend"]

TWO_PI = 2.0 * math.pi


def _check(x, c, F, z, u0, std):
    x = np.ascontiguousarray(x, dtype=np.float64)
    B, N, n = x.shape
    c = np.ascontiguousarray(c, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.float64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    u0 = np.ascontiguousarray(np.reshape(u0, (B,)), dtype=np.float64)
    std = np.ascontiguousarray(std, dtype=np.float64)
    if c.shape != (B, N) or F.shape != (n, n) or z.shape != (B, 2) or std.shape != (n,):
        raise ValueError(f"crpf_step: inconsistent shapes x {x.shape}, c {c.shape}, F {F.shape}, z {z.shape}, "
                         f"std {std.shape}")
    if n < 2:
        raise ValueError("crpf_step: the state needs a 2-D position first (n >= 2)")
    return x, c, F, z, u0, std


def propagation_normals(key: int, B: int, N: int, n: int, twin: bool = False) -> np.ndarray:
    """The standard normals ``e (B, N, n)`` of the propagation for stream ``key`` (``twin``: computed by
    the pure NumPy :func:`~workbench.kernels.counter_normals.counter_normals_numpy`; the same numbers)."""
    return (counter_normals_numpy if twin else counter_normals)(key, B, N * n).reshape(B, N, n)


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


def crpf_step_numpy(x, c, F, z, key, u0, std, lam, beta, delta, q=2.0, arc=False, sensor=(0.0, 0.0)):
    """The NumPy twin every kernel backend is held to (same inputs and outputs as :func:`crpf_step`)."""
    x, c, F, z, u0, std = _check(x, c, F, z, u0, std)
    B, N, n = x.shape
    e = propagation_normals(key, B, N, n, twin=True)
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


def crpf_step(x, c, F, z, key, u0, std, lam, beta, delta, q=2.0, arc=False, sensor=(0.0, 0.0),
              backend="auto", arch=None):
    """One CRPF step (risk, selection, propagation, cost, estimate) for every run; see the module docstring.

    Parameters
    ----------
    x, c : particles and costs before the step
    F : motion matrix; z : measured ``[range, bearing]`` per run
    key : the stream of the propagation normals (:func:`propagation_normals`); u0 : systematic-resampling
        offsets in [0, 1)
    std : per-component propagation standard deviation
    lam, beta, delta, q : forgetting factor, PMF exponent and offset, cost exponent
    arc : arc-length cost (bearing residual times the measured range)
    sensor : sensor position ``(x, y)``
    backend, arch : ``"auto"``, ``"numba"``, ``"taichi"`` or ``"numpy"``; the arch (default: the policy's,
        :mod:`workbench.kernels.backend`)

    Shapes
    ------
    x : (B, N, n); c : (B, N); F : (n, n); z : (B, 2); key : int; u0 : (B,); std : (n,)
    returns : x' (B, N, n), C' (B, N), mean (B, n), cov (B, n, n)
    """
    which = resolve_backend(backend, arch)
    if which == "numpy":
        return crpf_step_numpy(x, c, F, z, key, u0, std, lam, beta, delta, q, arc, sensor)
    x, c, F, z, u0, std = _check(x, c, F, z, u0, std)
    B, N, n = x.shape
    x_new = np.empty_like(x)
    c_new = np.empty_like(c)
    mean = np.empty((B, n))
    cov = np.empty((B, n, n))
    scratch = np.empty((B, N))
    scal = np.array([lam, beta, delta, q, 1.0 if arc else 0.0, float(sensor[0]), float(sensor[1])])
    if B and N:
        if which == "numba":
            _numba_kernel()(x, c, F, z, np.uint64(key), u0, std, scal, x_new, c_new, mean, cov, scratch)
        else:
            ensure_taichi(current_arch() if arch is None else arch)
            e = propagation_normals(key, B, N, n)
            _taichi_kernel()(x, c, F, z, e, u0, std, scal, x_new, c_new, mean, cov, scratch)
    return x_new, c_new, mean, cov


# -- Numba (the CPU default) ---------------------------------------------------------------------

#: Cephes' rational approximation of atan on |t| <= 0.66: atan(t) = t + t z P(z) / Q(z), z = t^2
#: (Q monic); about 1 ulp in float64.
ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
          -1.228866684490136173410e2, -6.485021904942025371773e1)
ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
          4.853903996359136964868e2, 1.945506571482613964425e2)
TAN_PI_8 = 0.41421356237309504880


def atan2_poly(y, x):
    """``atan2(y, x)`` by range reduction and :data:`ATAN_P` / :data:`ATAN_Q`, written with selects only.

    The NumPy twin of the Numba kernel's ``atan2`` (a library ``atan2`` call per particle does not
    vectorise; this does).  Reduction: ``a = min(|x|, |y|) / max(|x|, |y|)`` in [0, 1]; above
    tan(pi/8), ``t = (a - 1) / (a + 1)`` and ``atan a = pi/4 + atan t``, so ``|t| <= tan(pi/8)``; then
    the octant (``pi/2 - .``), the half plane (``pi - .``) and the sign of ``y``, signed zeros as the library's atan2.
    """
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    ax, ay = np.abs(x), np.abs(y)
    swap = ay > ax
    mx = np.where(swap, ay, ax)
    mn = np.where(swap, ax, ay)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = mn / np.where(mx > 0.0, mx, 1.0)
        big = a > TAN_PI_8
        t = np.where(big, a - 1.0, a) / np.where(big, a + 1.0, 1.0)
    z = t * t
    p0, p1, p2, p3, p4 = ATAN_P
    q0, q1, q2, q3, q4 = ATAN_Q
    r = t + t * z * ((((p0 * z + p1) * z + p2) * z + p3) * z + p4) / (((((z + q0) * z + q1) * z + q2) * z + q3) * z + q4)
    r = r + np.where(big, 0.25 * math.pi, 0.0)
    r = np.where(swap, 0.5 * math.pi - r, r)
    r = np.where(np.signbit(x), math.pi - r, r)  # signbit: atan2(+-0, -0) = +-pi, as the library's
    return np.copysign(r, y)


def _numba_kernel():
    from .crpf_numba import kernel

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
