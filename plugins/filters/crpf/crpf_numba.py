"""The Numba backend of :func:`workbench_filters.crpf.crpf_step.crpf_step` (imported only when it is used).

The functions live at module level, not in a factory, so that Numba's on-disk cache finds them again
in a new process (a closure's cache key includes its cells, which differ from process to process, and
every process compiled the kernel anew: 7-12 s).  See :mod:`workbench_filters.crpf.crpf_step` for the step.

Where a step's time goes (B = 250 runs of N = 500 particles, n = 4, one thread of a 2-core AMD EPYC Zen 1, AVX2 on
128-bit units; ns per particle-step): the four propagation normals 14 (3.6 each,
:mod:`workbench.kernels.counter_normals_numba`: one hash word per pair in a scalar loop, then the vectorised
float32 Box-Muller; 28, 7.0 each, with the float64 generator before it, measured beside it: the step
80.4-80.7 ns then, 66.1-67.1 now, best of 30-40 interleaved calls, four runs).  The rest, measured from variants
cut short after each phase when the step took 95 ns on this machine: the two costs 12 each (two thirds of it
the select-only atan2), the propagation's gather from the parents 9, the selection 5, the first pass (``F x``,
``sigma``, ``lam C``) 4, the two PMFs with their sums 3-4 each, the weighted mean and covariance 10; about 800 ns
per run besides (calls, views, loop set-up), 8 ns per particle-step at N = 100.

The 4-D state and any other state size are separate compilations (:func:`one_run4` in :func:`kernel_serial4` and
:func:`kernel_parallel4`, :func:`one_run` in :func:`kernel_serial` and :func:`kernel_parallel`); :func:`kernel`
picks them by ``x.shape[2]``, so a process compiles (or loads from the cache) only the one it calls, with the same
numbers bit for bit as the single kernel that held both paths behind a runtime ``if n == 4`` (checked for n = 2,
3, 4, 6 on both threadings).  First call of the one-thread kernel in a fresh Numba cache, CPU seconds after
Numba's own start-up (0.9 s), same machine: the single kernel with the float64 normals 9.1, with the float32
ones 7.9; the 4-D kernel alone 6.7 (the general one 4.1 more where it is called too).
"""

import functools
import math

import numba
import numpy as np

from workbench.kernels.backend import threaded
from workbench.kernels.counter_normals_numba import row_normals
from workbench.kernels.particle_numba import atan2  # the select-only polynomial atan2 both kernels use
from workbench.kernels.vector_width import wide_vectors

from .crpf_step_numpy import TWO_PI

pi, two_pi = math.pi, TWO_PI
# error_model="numpy": a float division by zero gives inf instead of raising, so the loops below
# carry no exception branch and LLVM can vectorise them; no fastmath (the NaN checks must hold).
jit = functools.partial(numba.njit, error_model="numpy")


@jit(inline="always")
def cost(px, py, zr, zt, sx, sy, arc):
    """(dr^2 + (a dtheta)^2) for one point, dtheta wrapped; a = |z_r| for the arc-length cost, else 1."""
    dx = px - sx
    dy = py - sy
    dr = zr - math.sqrt(dx * dx + dy * dy)
    a = zt - atan2(dy, dx)
    # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
    dt = a - two_pi * math.ceil((a - pi) * (1.0 / two_pi))
    dt = dt * abs(zr) if arc else dt
    return dr * dr + dt * dt


@jit
def costs_into(out, base, px, py, zr, zt, sx, sy, q, arc):
    """out_i = base_i + dC(p_i | z) over contiguous rows: one vectorisable loop (q = 2), then the power.  (A
    function of its own, called twice, not inlined into ``one_run`` by Numba: the same speed, and 1.5 s less to
    compile than two inlined copies.)"""
    wide_vectors()
    N = out.shape[0]
    for i in range(N):
        out[i] = cost(px[i], py[i], zr, zt, sx, sy, arc)
    if q != 2.0:
        # dC = ||z - h(x)||^q
        for i in range(N):
            out[i] = out[i] ** (0.5 * q)
    for i in range(N):
        out[i] += base[i]


@jit(inline="always")
def pmf(vals, N, beta, delta, relative, w):
    """w_i ~ (v_i - min v + delta_v)^-beta (scaled so the best is 1); ``delta_v = delta``, or for ``relative``
    ``delta`` times the mean gap of the finite values above their minimum (``delta`` where there is no gap): the
    twin's :func:`~workbench_filters.crpf.crpf_step_numpy.pmf_offset`.  Rows with a NaN or no finite value get
    ``w = 1``.  (The sum is the caller's: :func:`running_sum` or :func:`total_of`.)"""
    m = math.inf
    bad = False
    total = 0.0
    count = 0
    for i in range(N):
        v = vals[i]
        if v != v:
            bad = True
        elif v < m:
            m = v
        if abs(v) < math.inf:
            total += v
            count += 1
    bad = bad or not (m < math.inf)
    if bad:
        for i in range(N):
            w[i] = 1.0
        return
    if relative:
        # delta_v = delta * (mean_i v_i - min_i v_i)
        gap = total / count - m
        if gap > 0.0 and gap < math.inf:
            delta = delta * gap
    # pi ~ (C - min C + delta)^-beta = ((C - min C + delta) / delta)^-beta up to a constant
    inv = 1.0 / delta
    if beta == 2.0:
        for i in range(N):
            t = (vals[i] - m + delta) * inv
            w[i] = 1.0 / (t * t)
    else:
        for i in range(N):
            w[i] = ((vals[i] - m + delta) * inv) ** (-beta)


@jit(inline="always")
def running_sum(w, cum):
    """``cum_i = w_0 + ... + w_i`` in order (the one serial chain the selection needs); returns the total."""
    total = 0.0
    for i in range(w.shape[0]):
        total += w[i]
        cum[i] = total
    return total


@jit(inline="always")
def total_of(w):
    total = 0.0
    for i in range(w.shape[0]):
        total += w[i]
    return total


@jit(inline="always")
def select(cum, total, u0, parent, edges, ef):
    """Systematic selection without a data-dependent branch: with ``e_i = clip(ceil(N cdf_i - u0), 0, N)``
    (non-decreasing, ``e_{N-1} = N``), particle ``i`` fills the slots ``[e_{i-1}, e_i)``, so the parent
    of slot ``j`` is ``#{i : e_i <= j}``: a histogram of the edges and its running sum.  ``cdf_i = cum_i / total``
    (``cum`` from :func:`running_sum`), the last one exactly 1; the edges are computed in one vectorisable loop
    (``ef``, as floats), then scattered."""
    N = cum.shape[0]
    fN = float(N)
    for i in range(N - 1):
        ef[i] = min(max(math.ceil(N * (cum[i] / total) - u0), 0.0), fN)
    ef[N - 1] = min(max(math.ceil(N * 1.0 - u0), 0.0), fN)
    for j in range(N + 1):
        edges[j] = 0
    for i in range(N):
        edges[int(ef[i])] += 1
    run = 0
    for j in range(N):
        run += edges[j]
        parent[j] = run


@jit(inline="always")
def run_scalars(scal, t, n):
    """The step's scalars from ``scal`` (see :func:`workbench_filters.crpf.crpf_step.crpf_step`) and ``t``."""
    lam, beta, delta, q = scal[0], scal[1], scal[2], scal[3]
    arc = scal[4] != 0.0
    sx, sy = scal[5], scal[6]
    adaptive = scal[7] != 0.0
    relative = scal[8] != 0.0
    # sigma'^2 = a sigma_parent^2 + ||dev||^2 b  with a = (t - 1) / t, b = 1 / (t n); fixed: a = 1, b = 0
    a = (t - 1.0) / t if adaptive else 1.0
    bn = 1.0 / (t * n) if adaptive else 0.0
    return lam, beta, delta, q, arc, sx, sy, relative, a, bn


@jit(inline="always")
def scratch_rows(sc, ic, N):
    """The per-particle rows both step kernels keep in their scratch ``sc`` (floats) and ``ic`` (ints): positions
    ``px``, ``py``; ``base`` (lam C_i, then lam C_parent(j)); ``lamc``; ``sd`` (sigma_i); ``cum`` (the PMF's running
    sum, then the selection edges); ``parent``; ``edges``.  (``F x`` follows them in ``sc`` from row 6 on.)"""
    return (sc[0:N], sc[N:2 * N], sc[2 * N:3 * N], sc[3 * N:4 * N], sc[4 * N:5 * N], sc[5 * N:6 * N], ic[0:N],
            ic[N:2 * N + 1])


@jit(inline="always")
def risk_and_select(w, lamc, px, py, zr, zt, sx, sy, q, arc, beta, delta, relative, cum, u0, parent, edges):
    """R = lam C + dC(F x | z) (positions ``px``, ``py`` of ``F x``), its PMF into ``w`` and the parents."""
    costs_into(w, lamc, px, py, zr, zt, sx, sy, q, arc)
    pmf(w, w.shape[0], beta, delta, relative, w)
    total = running_sum(w, cum)
    select(cum, total, u0, parent, edges, cum)


@jit
def one_run4(xb, cb, s2b, t, F, zr, zt, eb, u0, shape, scal, xn, cn, s2n, mean, cov, w, sc, ic):
    """The step of one run of the common 4-D state ``[x, y, vx, vy]``, its loops over components written out
    (2x faster than :func:`one_run`), with its propagation normals ``eb`` (``e[j, r] = eb[4 j + r]``) and scratch
    ``sc`` (``10 N`` floats) and ``ic`` (``2 N + 1`` ints).  (Compiled as a function of its own: written inline in
    the prange body, its loops vectorised less and the kernel was 1.5x slower.)

    Every per-particle quantity the propagation gathers from its parent (``F x``, ``sigma``, ``lam C``) is
    computed once per particle, in the vectorisable first pass, so the gathering loop only adds the noise."""
    wide_vectors()  # the cost, PMF and moment loops: the CPU's full vector width
    N = xb.shape[0]
    lam, beta, delta, q, arc, sx, sy, relative, a, bn = run_scalars(scal, t, 4)
    px, py, base, lamc, sd, cum, parent, edges = scratch_rows(sc, ic, N)
    fx = sc[6 * N:10 * N].reshape((N, 4))  # F x_i
    # R = lam C + dC(F x | z): the noise-free positions gathered first, so the cost loop vectorises
    f00, f01, f02, f03 = F[0, 0], F[0, 1], F[0, 2], F[0, 3]
    f10, f11, f12, f13 = F[1, 0], F[1, 1], F[1, 2], F[1, 3]
    f20, f21, f22, f23 = F[2, 0], F[2, 1], F[2, 2], F[2, 3]
    f30, f31, f32, f33 = F[3, 0], F[3, 1], F[3, 2], F[3, 3]
    for i in range(N):
        x0, x1, x2, x3 = xb[i, 0], xb[i, 1], xb[i, 2], xb[i, 3]
        y0 = f00 * x0 + f01 * x1 + f02 * x2 + f03 * x3
        y1 = f10 * x0 + f11 * x1 + f12 * x2 + f13 * x3
        fx[i, 0] = y0
        fx[i, 1] = y1
        fx[i, 2] = f20 * x0 + f21 * x1 + f22 * x2 + f23 * x3
        fx[i, 3] = f30 * x0 + f31 * x1 + f32 * x2 + f33 * x3
        # the risk's position is the sum started from 0.0 (0.0 + s is s, but -0.0 becomes +0.0)
        px[i] = y0 + 0.0
        py[i] = y1 + 0.0
        lamc[i] = lam * cb[i]
        sd[i] = math.sqrt(s2b[i])
    risk_and_select(w, lamc, px, py, zr, zt, sx, sy, q, arc, beta, delta, relative, cum, u0, parent, edges)
    # dev = sigma_parent e;  x' = F x_parent + shape dev;  sigma'^2 = a sigma_parent^2 + b ||dev||^2;
    # C' = lam C_parent + dC(x' | z)
    g0, g1, g2, g3 = shape[0], shape[1], shape[2], shape[3]
    for j in range(N):
        i = parent[j]
        s = sd[i]
        d0 = s * eb[4 * j]
        d1 = s * eb[4 * j + 1]
        d2 = s * eb[4 * j + 2]
        d3 = s * eb[4 * j + 3]
        y0 = fx[i, 0] + g0 * d0
        y1 = fx[i, 1] + g1 * d1
        xn[j, 0] = y0
        xn[j, 1] = y1
        xn[j, 2] = fx[i, 2] + g2 * d2
        xn[j, 3] = fx[i, 3] + g3 * d3
        s2n[j] = a * s2b[i] + bn * (d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3)
        px[j] = y0
        py[j] = y1
        base[j] = lamc[i]
    costs_into(cn, base, px, py, zr, zt, sx, sy, q, arc)
    # estimate: pi' ~ (C' - min C' + delta_C)^-beta, weighted mean and covariance
    pmf(cn, N, beta, delta, relative, w)
    m0 = m1 = m2 = m3 = 0.0
    total = 0.0  # the weights' sum, in order, beside the four weighted sums (independent chains)
    for i in range(N):
        wi = w[i]
        total += wi
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


@jit
def one_run(xb, cb, s2b, t, F, zr, zt, eb, u0, shape, scal, xn, cn, s2n, mean, cov, w, sc, ic):
    """The step of one run of any state size ``n`` (:func:`one_run4` is the 4-D one), with its propagation
    normals ``eb`` (``e[j, r] = eb[j n + r]``) and scratch ``sc`` (``(n + 6) N`` floats) and ``ic`` (``2 N + 1``
    ints)."""
    wide_vectors()  # the cost and PMF loops: the CPU's full vector width
    N, n = xb.shape
    lam, beta, delta, q, arc, sx, sy, relative, a, bn = run_scalars(scal, t, n)
    px, py, base, lamc, sd, cum, parent, edges = scratch_rows(sc, ic, N)
    fx = sc[6 * N:(6 + n) * N].reshape((N, n))  # F x_i
    # R = lam C + dC(F x | z): the noise-free positions gathered first, so the cost loop vectorises
    for i in range(N):
        for r in range(n):
            acc = 0.0
            for k in range(n):
                acc += F[r, k] * xb[i, k]
            fx[i, r] = acc
        px[i] = fx[i, 0]
        py[i] = fx[i, 1]
        lamc[i] = lam * cb[i]
        sd[i] = math.sqrt(s2b[i])
    risk_and_select(w, lamc, px, py, zr, zt, sx, sy, q, arc, beta, delta, relative, cum, u0, parent, edges)
    # dev = sigma_parent e;  x' = F x_parent + shape dev;  sigma'^2 = a sigma_parent^2 + b ||dev||^2;
    # C' = lam C_parent + dC(x' | z)
    for j in range(N):
        i = parent[j]
        s = sd[i]
        ss = 0.0
        for r in range(n):
            d = s * eb[j * n + r]
            ss += d * d
            xn[j, r] = fx[i, r] + shape[r] * d
        s2n[j] = a * s2b[i] + bn * ss
        px[j] = xn[j, 0]
        py[j] = xn[j, 1]
        base[j] = lamc[i]
    costs_into(cn, base, px, py, zr, zt, sx, sy, q, arc)
    # estimate: pi' ~ (C' - min C' + delta_C)^-beta, weighted mean and covariance
    pmf(cn, N, beta, delta, relative, w)
    total = total_of(w)
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


# The kernels, one per state size path (4-D or any n) and per threading, each compiled (and cached) only when
# first called: :func:`kernel` picks one by ``x.shape[2]``.  (One ``one_run`` holding both paths behind a runtime
# ``if n == 4`` compiled both whenever the kernel compiled.)  The propagation normals are drawn in the loop over
# runs, not in ``one_run``: there LLVM kept their loop's constants in registers it then spilled (13 instead of
# 9 ns a normal with the float64 generator, one AVX2 core).  Each kernel's body is marked ``wide_vectors()``: LLVM
# inlines ``row_normals`` into it, and the vectorisation of the inlined Box-Muller loop then follows the kernel's own
# function attributes; unmarked, the loop stayed scalar on an AVX-512 Zen 4 (about 8 ns a normal in the kernel, where
# the vectorised loop alone takes 1.5) and the 4-D serial step took 55 instead of 31 ns a particle-step (B = 250,
# N = 500, one thread), the same bits.

@jit(parallel=True, cache=True)
def kernel_parallel4(x, c, s2, t, F, z, key, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch):
    B, N, n = x.shape
    for b in numba.prange(B):
        wide_vectors()  # the normals' vectorised loop, inlined here (see the note above the kernels)
        eb = np.empty(N * 4)
        row_normals(key, b, eb, np.empty(N * 2 + 1, dtype=np.uint64))  # run b's propagation normals
        one_run4(x[b], c[b], s2[b], t[b], F, z[b, 0], z[b, 1], eb, u0[b], shape, scal, x_new[b], c_new[b],
                 s2_new[b], mean[b], cov[b], scratch[b], np.empty(10 * N), np.empty(2 * N + 1, dtype=np.int64))


@jit(cache=True)
def kernel_serial4(x, c, s2, t, F, z, key, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch):
    B, N, n = x.shape
    wide_vectors()  # the normals' vectorised loop, inlined here (see the note above the kernels)
    eb = np.empty(N * 4)
    words = np.empty(N * 2 + 1, dtype=np.uint64)  # the normals' hash words, one per pair
    sc = np.empty(10 * N)
    ic = np.empty(2 * N + 1, dtype=np.int64)
    for b in range(B):
        row_normals(key, b, eb, words)
        one_run4(x[b], c[b], s2[b], t[b], F, z[b, 0], z[b, 1], eb, u0[b], shape, scal, x_new[b], c_new[b],
                 s2_new[b], mean[b], cov[b], scratch[b], sc, ic)


@jit(parallel=True, cache=True)
def kernel_parallel(x, c, s2, t, F, z, key, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch):
    B, N, n = x.shape
    for b in numba.prange(B):
        wide_vectors()  # the normals' vectorised loop, inlined here (see the note above the kernels)
        eb = np.empty(N * n)
        row_normals(key, b, eb, np.empty(N * n // 2 + 1, dtype=np.uint64))  # run b's propagation normals
        one_run(x[b], c[b], s2[b], t[b], F, z[b, 0], z[b, 1], eb, u0[b], shape, scal, x_new[b], c_new[b],
                s2_new[b], mean[b], cov[b], scratch[b], np.empty((n + 6) * N), np.empty(2 * N + 1, dtype=np.int64))


@jit(cache=True)
def kernel_serial(x, c, s2, t, F, z, key, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch):
    B, N, n = x.shape
    wide_vectors()  # the normals' vectorised loop, inlined here (see the note above the kernels)
    eb = np.empty(N * n)
    words = np.empty(N * n // 2 + 1, dtype=np.uint64)  # the normals' hash words, one per pair
    sc = np.empty((n + 6) * N)
    ic = np.empty(2 * N + 1, dtype=np.int64)
    for b in range(B):
        row_normals(key, b, eb, words)
        one_run(x[b], c[b], s2[b], t[b], F, z[b, 0], z[b, 1], eb, u0[b], shape, scal, x_new[b], c_new[b],
                s2_new[b], mean[b], cov[b], scratch[b], sc, ic)


#: Below this many runs the step runs on one thread: waking the thread pool costs more than the work (and on a
#: busy machine a parallel region waits for a descheduled thread: 15 ms a step instead of 0.6 ms for B = 1).
PARALLEL_FROM = 16


def kernel(x, c, s2, t, F, z, key, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch):
    """The step of every run: the 4-D kernels for ``x.shape[2] == 4``, else the general ones; a thread per run from
    :data:`PARALLEL_FROM` runs on where Numba has more than one thread
    (:func:`workbench.kernels.backend.threaded`), else one thread: the same numbers either way."""
    four = x.shape[2] == 4
    if threaded(x.shape[0], PARALLEL_FROM):
        run = kernel_parallel4 if four else kernel_parallel
    else:
        run = kernel_serial4 if four else kernel_serial
    run(x, c, s2, t, F, z, key, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch)
