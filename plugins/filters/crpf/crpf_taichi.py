"""The Taichi version of the fused CRPF step (any Taichi arch); held to :func:`.crpf_step_numpy.crpf_step_numpy`.
(No ``from __future__ import annotations``: Taichi reads the kernel annotations as objects.)"""

import functools
import math

from .crpf_step_numpy import TWO_PI

# -- the kernel ---------------------------------------------------------------------------------------


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
        """(min over the row, whether the row is bad: a NaN or no finite value, mean gap of the finite values)."""
        m = ti.f64(math.inf)
        bad = 0
        total = ti.f64(0.0)
        count = 0
        for i in range(N):
            v = vals[b, i]
            if v != v:
                bad = 1
            elif v < m:
                m = v
            if ti.abs(v) < ti.f64(math.inf):
                total += v
                count += 1
        if not (m < ti.f64(math.inf)):
            bad = 1
        gap = ti.f64(0.0)
        if count > 0:
            gap = total / ti.cast(count, ti.f64) - m
        return m, bad, gap

    @ti.func
    def pmf(vals: ti.template(), b, N, beta, delta, relative, w: ti.template()):
        """Write pi_i ~ ((v_i - min v + delta_v) / delta_v)^-beta of row ``b`` into ``w[b]`` (uniform for a bad
        row); return the sum.  ``delta_v``: ``delta``, or for ``relative`` ``delta`` times the mean gap above the
        minimum (``delta`` without a gap).  ``vals`` may be ``w`` itself."""
        m, bad, gap = pmf_min(vals, b, N)
        d = delta
        if relative and gap > ti.f64(0.0) and gap < ti.f64(math.inf):
            # delta_v = delta * (mean_i v_i - min_i v_i)
            d = delta * gap
        total = ti.f64(0.0)
        for i in range(N):
            wi = ti.f64(1.0)
            if not bad:
                t = (vals[b, i] - m + d) / d
                wi = 1.0 / (t * t) if beta == ti.f64(2.0) else ti.pow(t, -beta)
            w[b, i] = wi
            total += wi
        return total

    @ti.kernel
    def kernel(x: ti.types.ndarray(dtype=ti.f64, ndim=3), c: ti.types.ndarray(dtype=ti.f64, ndim=2),
               s2: ti.types.ndarray(dtype=ti.f64, ndim=2), t: ti.types.ndarray(dtype=ti.f64, ndim=1),
               F: ti.types.ndarray(dtype=ti.f64, ndim=2), z: ti.types.ndarray(dtype=ti.f64, ndim=2),
               e: ti.types.ndarray(dtype=ti.f64, ndim=3), u0: ti.types.ndarray(dtype=ti.f64, ndim=1),
               shape: ti.types.ndarray(dtype=ti.f64, ndim=1), scal: ti.types.ndarray(dtype=ti.f64, ndim=1),
               x_new: ti.types.ndarray(dtype=ti.f64, ndim=3), c_new: ti.types.ndarray(dtype=ti.f64, ndim=2),
               s2_new: ti.types.ndarray(dtype=ti.f64, ndim=2), mean: ti.types.ndarray(dtype=ti.f64, ndim=2),
               cov: ti.types.ndarray(dtype=ti.f64, ndim=3), w: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        B, N, n = x.shape[0], x.shape[1], x.shape[2]
        lam, beta, delta, q = scal[0], scal[1], scal[2], scal[3]
        arc = scal[4] != ti.f64(0.0)
        sx, sy = scal[5], scal[6]
        adaptive = scal[7] != ti.f64(0.0)
        relative = scal[8] != ti.f64(0.0)
        for b in range(B):  # the outermost loop runs in parallel: one run per iteration
            zr, zt = z[b, 0], z[b, 1]
            # sigma'^2 = a sigma_parent^2 + bn ||dev||^2: a = (t - 1) / t, bn = 1 / (t n); fixed: a = 1, bn = 0
            a = ti.f64(1.0)
            bn = ti.f64(0.0)
            if adaptive:
                a = (t[b] - ti.f64(1.0)) / t[b]
                bn = ti.f64(1.0) / (t[b] * ti.cast(n, ti.f64))
            # R = lam C + dC(F x | z)
            for i in range(N):
                px = ti.f64(0.0)
                py = ti.f64(0.0)
                for k in range(n):
                    px += F[0, k] * x[b, i, k]
                    py += F[1, k] * x[b, i, k]
                w[b, i] = lam * c[b, i] + cost(px, py, zr, zt, sx, sy, q, arc)
            total = pmf(w, b, N, beta, delta, relative, w)
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
                    # dev = sigma_parent e;  x' = F x_parent + shape dev;  sigma'^2 = a sigma_parent^2 + bn ||dev||^2
                    # C' = lam C_parent + dC(x' | z)
                    v = s2[b, i]
                    sd = ti.sqrt(v)
                    ss = ti.f64(0.0)
                    for r in range(n):
                        acc = ti.f64(0.0)
                        for k in range(n):
                            acc += F[r, k] * x[b, i, k]
                        d = sd * e[b, j, r]
                        ss += d * d
                        x_new[b, j, r] = acc + shape[r] * d
                    s2_new[b, j] = a * v + bn * ss
                    c_new[b, j] = lam * c[b, i] + cost(x_new[b, j, 0], x_new[b, j, 1], zr, zt, sx, sy, q, arc)
                    j += 1
                prev = ti.max(prev, ie)
            # estimate: pi' ~ (C' - min C' + delta_C)^-beta, weighted mean and covariance
            total = pmf(c_new, b, N, beta, delta, relative, w)
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
