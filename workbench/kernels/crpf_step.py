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
- ``"numba"`` (the CPU default): the same loops with ``numba.prange`` over runs, CPU only;
- ``"numpy"``: :func:`crpf_step_numpy`;
- ``"auto"``: Numba when the arch is the CPU and Numba is installed, else Taichi
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


@functools.cache
def _numba_kernel():
    import numba

    p0, p1, p2, p3, p4 = ATAN_P
    q0, q1, q2, q3, q4 = ATAN_Q
    tan_pi_8, pi, two_pi = TAN_PI_8, math.pi, TWO_PI
    # error_model="numpy": a float division by zero gives inf instead of raising, so the loops below
    # carry no exception branch and LLVM can vectorise them; no fastmath (the NaN checks must hold).
    jit = functools.partial(numba.njit, error_model="numpy")

    @jit(inline="always")
    def atan2(y, x):  # atan2_poly, select by select
        ax = abs(x)
        ay = abs(y)
        swap = ay > ax
        mx = ay if swap else ax
        mn = ax if swap else ay
        a = mn / (mx if mx > 0.0 else 1.0)
        big = a > tan_pi_8
        t = (a - 1.0 if big else a) / (a + 1.0 if big else 1.0)
        z = t * t
        r = t + t * z * ((((p0 * z + p1) * z + p2) * z + p3) * z + p4) / (((((z + q0) * z + q1) * z + q2) * z + q3)
                                                                            * z + q4)
        r = r + (0.25 * pi if big else 0.0)
        r = 0.5 * pi - r if swap else r
        r = pi - r if math.copysign(1.0, x) < 0.0 else r  # the sign bit: atan2(+-0, -0) = +-pi
        return math.copysign(r, y)

    @jit(inline="always")
    def cost(px, py, zr, zt, sx, sy, q, arc):
        dx = px - sx
        dy = py - sy
        dr = zr - math.sqrt(dx * dx + dy * dy)
        a = zt - atan2(dy, dx)
        # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
        dt = a - two_pi * math.ceil((a - pi) * (1.0 / two_pi))
        dt = dt * abs(zr) if arc else dt
        return dr * dr + dt * dt

    @jit(inline="always")
    def costs_into(out, base, px, py, zr, zt, sx, sy, q, arc):
        """out_i = base_i + dC(p_i | z) over contiguous rows: one vectorisable loop (q = 2), then the power."""
        N = out.shape[0]
        for i in range(N):
            out[i] = cost(px[i], py[i], zr, zt, sx, sy, q, arc)
        if q != 2.0:
            # dC = ||z - h(x)||^q
            for i in range(N):
                out[i] = out[i] ** (0.5 * q)
        for i in range(N):
            out[i] += base[i]

    @jit(inline="always")
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
        if bad:
            for i in range(N):
                w[i] = 1.0
            return float(N)
        # pi ~ (C - min C + delta)^-beta = ((C - min C + delta) / delta)^-beta up to a constant
        inv = 1.0 / delta
        if beta == 2.0:
            for i in range(N):
                t = (vals[i] - m + delta) * inv
                w[i] = 1.0 / (t * t)
        else:
            for i in range(N):
                w[i] = ((vals[i] - m + delta) * inv) ** (-beta)
        total = 0.0
        for i in range(N):
            total += w[i]
        return total

    @jit(inline="always")
    def select(w, total, u0, parent, edges):
        """Systematic selection without a data-dependent branch: with ``e_i = clip(ceil(N cdf_i - u0), 0, N)``
        (non-decreasing, ``e_{N-1} = N``), particle ``i`` fills the slots ``[e_{i-1}, e_i)``, so the parent
        of slot ``j`` is ``#{i : e_i <= j}``: a histogram of the edges and its running sum."""
        N = w.shape[0]
        for j in range(N + 1):
            edges[j] = 0
        cum = 0.0
        for i in range(N):
            cum += w[i]
            frac = 1.0 if i == N - 1 else cum / total  # the last cdf entry is exactly 1
            edges[int(min(max(math.ceil(N * frac - u0), 0.0), float(N)))] += 1
        run = 0
        for j in range(N):
            run += edges[j]
            parent[j] = run

    @jit
    def one_run(xb, cb, F, zr, zt, eb, u0, std, scal, xn, cn, mean, cov, w):
        """The step of one run.  (Compiled as a function of its own: written inline in the prange body,
        its loops vectorised less and the kernel was 1.5x slower.)  The state of every paper is 4-D
        ``[x, y, vx, vy]``; that case has its loops over components written out (2x faster)."""
        N, n = xb.shape
        lam, beta, delta, q = scal[0], scal[1], scal[2], scal[3]
        arc = scal[4] != 0.0
        sx, sy = scal[5], scal[6]
        px = np.empty(N)
        py = np.empty(N)
        base = np.empty(N)
        parent = np.empty(N, dtype=np.int64)
        edges = np.empty(N + 1, dtype=np.int64)
        # R = lam C + dC(F x | z): the noise-free positions gathered first, so the cost loop vectorises
        for i in range(N):
            ax = 0.0
            ay = 0.0
            for k in range(n):
                ax += F[0, k] * xb[i, k]
                ay += F[1, k] * xb[i, k]
            px[i] = ax
            py[i] = ay
            base[i] = lam * cb[i]
        costs_into(w, base, px, py, zr, zt, sx, sy, q, arc)
        total = pmf(w, N, beta, delta, w)
        select(w, total, u0, parent, edges)
        # x' = F x_parent + std e ;  C' = lam C_parent + dC(x' | z)
        if n == 4:
            f00, f01, f02, f03 = F[0, 0], F[0, 1], F[0, 2], F[0, 3]
            f10, f11, f12, f13 = F[1, 0], F[1, 1], F[1, 2], F[1, 3]
            f20, f21, f22, f23 = F[2, 0], F[2, 1], F[2, 2], F[2, 3]
            f30, f31, f32, f33 = F[3, 0], F[3, 1], F[3, 2], F[3, 3]
            s0, s1, s2, s3 = std[0], std[1], std[2], std[3]
            for j in range(N):
                i = parent[j]
                x0, x1, x2, x3 = xb[i, 0], xb[i, 1], xb[i, 2], xb[i, 3]
                y0 = f00 * x0 + f01 * x1 + f02 * x2 + f03 * x3 + s0 * eb[j, 0]
                y1 = f10 * x0 + f11 * x1 + f12 * x2 + f13 * x3 + s1 * eb[j, 1]
                xn[j, 0] = y0
                xn[j, 1] = y1
                xn[j, 2] = f20 * x0 + f21 * x1 + f22 * x2 + f23 * x3 + s2 * eb[j, 2]
                xn[j, 3] = f30 * x0 + f31 * x1 + f32 * x2 + f33 * x3 + s3 * eb[j, 3]
                px[j] = y0
                py[j] = y1
                base[j] = lam * cb[i]
        else:
            for j in range(N):
                i = parent[j]
                for r in range(n):
                    acc = 0.0
                    for k in range(n):
                        acc += F[r, k] * xb[i, k]
                    xn[j, r] = acc + std[r] * eb[j, r]
                px[j] = xn[j, 0]
                py[j] = xn[j, 1]
                base[j] = lam * cb[i]
        costs_into(cn, base, px, py, zr, zt, sx, sy, q, arc)
        # estimate: pi' ~ (C' - min C' + delta)^-beta, weighted mean and covariance
        total = pmf(cn, N, beta, delta, w)
        if n == 4:
            m0 = m1 = m2 = m3 = 0.0
            for i in range(N):
                wi = w[i]
                m0 += wi * xn[i, 0]
                m1 += wi * xn[i, 1]
                m2 += wi * xn[i, 2]
                m3 += wi * xn[i, 3]
            m0 /= total
            m1 /= total
            m2 /= total
            m3 /= total
            s00 = s10 = s11 = s20 = s21 = s22 = s30 = s31 = s32 = s33 = 0.0
            for i in range(N):
                wi = w[i]
                d0 = xn[i, 0] - m0
                d1 = xn[i, 1] - m1
                d2 = xn[i, 2] - m2
                d3 = xn[i, 3] - m3
                s00 += wi * d0 * d0
                s10 += wi * d1 * d0
                s11 += wi * d1 * d1
                s20 += wi * d2 * d0
                s21 += wi * d2 * d1
                s22 += wi * d2 * d2
                s30 += wi * d3 * d0
                s31 += wi * d3 * d1
                s32 += wi * d3 * d2
                s33 += wi * d3 * d3
            mean[0], mean[1], mean[2], mean[3] = m0, m1, m2, m3
            sums = (s00, s10, s11, s20, s21, s22, s30, s31, s32, s33)
            k = 0
            for r in range(4):
                for t in range(r + 1):
                    cov[r, t] = sums[k] / total
                    cov[t, r] = sums[k] / total
                    k += 1
            return
        m = np.zeros(n)
        for i in range(N):  # every component's sum in one pass: independent chains
            for r in range(n):
                m[r] += w[i] * xn[i, r]
        for r in range(n):
            m[r] /= total
            mean[r] = m[r]
        s = np.zeros((n, n))
        d = np.empty(n)
        for i in range(N):
            for r in range(n):
                d[r] = xn[i, r] - m[r]
            for r in range(n):
                for t in range(r + 1):
                    s[r, t] += w[i] * d[r] * d[t]
        for r in range(n):
            for t in range(r + 1):
                cov[r, t] = s[r, t] / total
                cov[t, r] = s[r, t] / total

    @jit(parallel=True, cache=True)
    def kernel(x, c, F, z, e, u0, std, scal, x_new, c_new, mean, cov, scratch):
        for b in numba.prange(x.shape[0]):
            one_run(x[b], c[b], F, z[b, 0], z[b, 1], e[b], u0[b], std, scal, x_new[b], c_new[b], mean[b], cov[b],
                    scratch[b])

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
