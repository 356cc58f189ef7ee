"""The Numba version of the Hough remover's local support rule (:func:`workbench_clutter.hough._inverse` with
``support="local"``), imported only when used; its NumPy twin is the vectorised code in ``hough.py`` and both are
held to the brute-force reference of the tests.

One loop over the detections of ping ``k``.  For detection ``z``: the similar line cells within ``e`` rows of it
(``zl``, read from a bit map of the line cells, one bit per row of each column holding a line); then the earlier
pings of group B, most recent first; in each, the gated points within reach (``dx^2 + dy^2 <= reach^2``, from a
grid of square cells); for each such support ``s`` and line ``L`` of ``zl`` with ``s`` on ``L``, the triple
``(z, s, L)``.  ``first[u]`` records the rank of the first (most recent) ping at which ``(z, zl[u])`` had a local
support: a triple of an older ping is skipped (the pair was decided there).  The velocity check looks for the
support's own latest local support on ``L`` the same way.  A detection leaves the loops as soon as it is kept.
Every comparison uses the same floating-point operations as the NumPy twin, so the decisions are identical.

:func:`remove_run` is the whole remover for one run in one call (the gate, the votes, the peaks, the similar lines,
then :func:`local_keep` or the latest / any rules, and the projection), the twin of ``hough.hough_remove_run``
with this kernel: ``hough.remove`` uses it where Numba runs and a ping holds at most
``hough.RUN_KERNEL_MAX_DETECTIONS`` detections.

Module-level functions, so that Numba's on-disk cache holds across processes.
"""

import math

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def _fetch_slot(sx, sy, slot, slot2, sup_xy, cell_start, slot_ping, reach, x0, y0, h, nx, ny, pred_idx, n):
    """Append to ``pred_idx[n:]`` the gated points of slot ``slot2`` within reach of the support ``(sx, sy)`` of
    slot ``slot``; returns the new count."""
    r = reach[slot_ping[slot] - slot_ping[slot2]]
    r2 = r * r
    m = math.ceil(r / h)
    cx = math.floor((sx - x0) / h)
    cy = math.floor((sy - y0) / h)
    starts = cell_start[slot2]
    y_lo, y_hi = max(cy - m, 0), min(cy + m, ny - 1)
    for gx in range(max(cx - m, 0), min(cx + m, nx - 1) + 1):
        for s2 in range(starts[gx * ny + y_lo], starts[gx * ny + y_hi + 1]):
            ddx = sx - sup_xy[s2, 0]
            ddy = sy - sup_xy[s2, 1]
            if ddx * ddx + ddy * ddy <= r2:
                pred_idx[n] = s2
                n += 1
    return n


@numba.njit(cache=True, error_model="numpy")
def _velocity_ok(zx, zy, sx, sy, sup_xy, sup_ring, sup_idx, cell_start, slot_ping, k, slot, col, lrow, ring, e,
                 reach, x0, y0, h, nx, ny, vel_gate, sigma2, dt, require_chain, pred_idx, pred_end):
    """The velocity check of triple (z, s, line ``(lrow, col)``).  The support's predecessors are fetched slot by
    slot, the most recent first, into ``pred_idx`` (``pred_end[i]``: the end of the ``i``-th fetched slot,
    ``-1`` not yet fetched), and reused by the next triples of the same pair."""
    if vel_gate < 0.0 and not require_chain:
        return True
    p = slot_ping[slot]
    g2 = (k - p) * dt
    begin = np.int64(0)
    for i in range(slot):
        slot2 = slot - 1 - i
        if pred_end[i] < 0:
            pred_end[i] = _fetch_slot(sx, sy, slot, slot2, sup_xy, cell_start, slot_ping, reach, x0, y0, h, nx, ny,
                                      pred_idx, begin)
        found = False
        g1 = (p - slot_ping[slot2]) * dt
        for n in range(begin, pred_end[i]):
            s2 = pred_idx[n]
            if abs(ring[sup_ring[s2], sup_idx[s2], col] - lrow) > e:
                continue
            found = True
            if vel_gate < 0.0:
                return True
            # u = (z - s) / g2, u' = (s - s') / g1; var(u - u') = sigma^2 (1/g2^2 + (1/g2 + 1/g1)^2 + 1/g1^2)
            ux = (zx - sx) / g2
            uy = (zy - sy) / g2
            wx = (sx - sup_xy[s2, 0]) / g1
            wy = (sy - sup_xy[s2, 1]) / g1
            both = 1.0 / g2 + 1.0 / g1
            var = sigma2 * (1.0 / (g2 * g2) + both * both + 1.0 / (g1 * g1))
            vx = ux - wx
            vy = uy - wy
            if vx * vx + vy * vy <= vel_gate * var:
                return True
        if found:
            return False  # the latest local support's ping holds no consistent one
        begin = pred_end[i]
    return not require_chain


#: ``ctz(w) = CTZ[((w & -w) * DE_BRUIJN) >> 58]`` (count of trailing zeros of a nonzero 64-bit word)
DE_BRUIJN = np.uint64(0x03F79D71B4CB0A89)
CTZ = np.zeros(64, dtype=np.int64)
for _i in range(64):
    CTZ[((1 << _i) * 0x03F79D71B4CB0A89 % (1 << 64)) >> 58] = _i


@numba.njit(cache=True, error_model="numpy")
def local_keep(z_xy, z_rows, todo, sup_xy, sup_ring, sup_idx, cell_start, slot_ping, k, bits, n_rho, col_slot, ring,
               e, reach, x0, y0, h, nx, ny, vel_gate, sigma_pos, dt, require_chain, stamp, tag0, ctz, d_rho, d_theta):
    """Keep mask ``(n_k,)`` of the local support rule.

    ``z_xy (n_k, 2)``, ``z_rows (n_k, n_theta)``: ping k's detections and their vote rows; ``todo``: those to
    decide.  ``sup_*`` ``(N,)``: the gated points of the earlier pings of B, slot by slot (ping ``slot_ping[i]``,
    ascending), each slot sorted by its cell ``cx ny + cy`` of the grid ``x0, y0, h`` (``nx x ny`` cells):
    ``cell_start[i, c] .. cell_start[i, c + 1]`` are slot ``i``'s points in cell ``c``, so a run of cells
    ``(cx, cy0 .. cy1)`` is one index range.  ``sup_ring, sup_idx`` locate a point's rows in ``ring``.  ``bits (J, words)`` uint64:
    bit ``r`` of row ``j`` is set where the column ``c`` with ``col_slot[c] = j`` holds a similar line cell at
    row ``r`` (``col_slot[c] = -1``: no line in column ``c``; one spare zero word at the end of each row;
    ``2 e + 1 < 64``).  A pair at distance ``d`` shares a line only in columns with ``|d cos(theta - phi)| <=
    (2 e + 1) d_rho`` (its rows differ by at most ``2 e`` there), so only those (with a margin) are visited.  ``reach (W,)`` by ping gap; ``vel_gate < 0``: no
    velocity check.  ``stamp (n_rho n_theta,)`` int64, kept across calls: ``(tag0 + z) * 64 + rank`` marks the
    most recent ping (rank 0 = ping k - 1) at which line ``(row, column)`` had a local support of ``z``;
    ``tag0`` must exceed every tag of earlier calls by ``n_k``.
    """
    n_k = z_xy.shape[0]
    n_theta = z_rows.shape[1]
    keep = np.empty(n_k, dtype=np.bool_)
    for i in range(n_k):
        keep[i] = False
    S = cell_start.shape[0]
    sigma2 = sigma_pos * sigma_pos
    zero = np.uint64(0)
    one = np.uint64(1)
    pred_idx = np.empty(sup_xy.shape[0], dtype=np.int64)
    pred_end = np.empty(S, dtype=np.int64)
    span = (2 * e + 2) * d_rho  # |d cos(theta - phi)| bound with a margin for the rounding of rows
    for t in range(todo.shape[0]):
        zi = todo[t]
        tag = (tag0 + zi) * 64
        zrow = z_rows[zi]
        zx, zy = z_xy[zi, 0], z_xy[zi, 1]
        cx = math.floor((zx - x0) / h)
        cy = math.floor((zy - y0) / h)
        done = False
        for rank in range(S):
            slot = S - 1 - rank
            p = slot_ping[slot]
            r = reach[k - p]
            r2 = r * r
            m = math.ceil(r / h)
            starts = cell_start[slot]
            y_lo, y_hi = max(cy - m, 0), min(cy + m, ny - 1)
            for gx in range(max(cx - m, 0), min(cx + m, nx - 1) + 1):
                for si in range(starts[gx * ny + y_lo], starts[gx * ny + y_hi + 1]):
                    sx, sy = sup_xy[si, 0], sup_xy[si, 1]
                    ddx = zx - sx
                    ddy = zy - sy
                    d2 = ddx * ddx + ddy * ddy
                    if d2 > r2:
                        continue
                    # the columns where the two can share a line: theta within half of phi + pi / 2 (mod pi)
                    if d2 <= span * span:
                        c_first, c_count = 0, n_theta
                    else:
                        half = np.arcsin(span / np.sqrt(d2))
                        centre = np.arctan2(ddy, ddx) + 0.5 * np.pi
                        c_first = math.floor((centre - half) / d_theta) - 1
                        c_count = min(math.ceil(2.0 * half / d_theta) + 3, n_theta)
                    srow = ring[sup_ring[si], sup_idx[si]]
                    for i in range(S):
                        pred_end[i] = -1
                    for cc in range(c_count):
                        c = (c_first + cc) % n_theta
                        j = col_slot[c]
                        if j < 0:
                            continue
                        rz = np.int64(zrow[c])
                        rs = np.int64(srow[c])
                        lo_r = max(max(rz, rs) - e, 0)
                        hi_r = min(min(rz, rs) + e, n_rho - 1)
                        if hi_r < lo_r:
                            continue
                        # the bits of rows lo_r .. hi_r (fewer than 64) of the column's bit row, lowest row first;
                        # branch-free: the two words that can hold them are always read (one spare word per row)
                        wi = lo_r >> 6
                        sh = np.uint64(lo_r & 63)
                        word = (bits[j, wi] >> sh) | ((bits[j, wi + 1] << (np.uint64(63) - sh)) << one)
                        word &= (one << np.uint64(hi_r - lo_r + 1)) - one
                        while word != zero:
                            low = word & (~word + one)
                            word ^= low
                            rr = lo_r + ctz[(low * DE_BRUIJN) >> np.uint64(58)]
                            cell = rr * n_theta + c
                            st = stamp[cell]
                            if st // 64 == tag // 64:
                                if st - tag < rank:
                                    continue  # (z, L) was decided at a more recent ping
                            else:
                                stamp[cell] = tag + rank
                            if _velocity_ok(zx, zy, sx, sy, sup_xy, sup_ring, sup_idx, cell_start, slot_ping, k,
                                            slot, c, rr, ring, e, reach, x0, y0, h, nx, ny, vel_gate, sigma2, dt,
                                            require_chain, pred_idx, pred_end):
                                keep[zi] = True
                                done = True
                                break
                        if done:
                            break
                    if done:
                        break
                if done:
                    break
            if done:
                break
    return keep


@numba.njit(cache=True, error_model="numpy")
def add_votes(counts, rows, which, n_theta, add):
    """``counts[rows[i, j] n_theta + j] (+/-)= 1`` for every point ``i`` of ``which`` and column ``j`` (the twin
    of ``np.add.at`` / ``np.subtract.at`` in ``hough._RunCache._add_votes``)."""
    for t in range(which.shape[0]):
        i = which[t]
        for j in range(n_theta):
            cell = np.int64(rows[i, j]) * n_theta + j
            if add:
                counts[cell] += 1
            else:
                counts[cell] -= 1


@numba.njit(cache=True, error_model="numpy")
def accumulate(n_pings, votes, counts):
    """``n_pings += counts > 0``, ``votes += counts`` in one pass (flat arrays; branch-free, so that the loop
    vectorises: adding 0 where a cell has no vote changes nothing)."""
    for c in range(counts.shape[0]):
        v = counts[c]
        n_pings[c] += v > 0
        votes[c] += v


@numba.njit(cache=True, error_model="numpy")
def line_bits(rows, col_slot_of_line, n_used, n_words):
    """The bit map of the similar line cells: bit ``rows[L]`` of row ``col_slot_of_line[L]`` set, ``(n_used,
    n_words)`` uint64."""
    bits = np.empty((n_used, n_words), dtype=np.uint64)
    zero = np.uint64(0)
    one = np.uint64(1)
    for j in range(n_used):
        for w in range(n_words):
            bits[j, w] = zero
    for L in range(rows.shape[0]):
        r = rows[L]
        bits[col_slot_of_line[L], r >> 6] |= one << np.uint64(r & 63)
    return bits


@numba.njit(cache=True, error_model="numpy")
def rho_rows(points, cos, sin, d_rho, off, out):
    """The vote row of each point in each column: ``rint((x cos theta_j + y sin theta_j) / d_rho) + off`` into
    ``out (n, n_theta)`` int32 (the twin of ``HoughGrid.rho_index``: the same operations in the same order)."""
    n_theta = cos.shape[0]
    scale = d_rho != 1.0
    for i in range(points.shape[0]):
        x = points[i, 0]
        y = points[i, 1]
        for j in range(n_theta):
            a = x * cos[j]
            b = y * sin[j]
            r = a + b  # rho = x cos(theta) + y sin(theta)   (eq 1)
            if scale:
                r = r / d_rho
            out[i, j] = np.int32(np.rint(r)) + off
    return out


# -- the whole run in one call (the remover's default path: the detections themselves as the output) -------------
#
# Compile time matters here as much as run time (every worker of ``workbench report`` compiles these from an empty
# cache): the run's data are flat arrays with offsets (no lists of arrays), every loop is written out (no np.sort,
# np.argsort, np.searchsorted, np.flatnonzero, np.full, np.arange, array min / max or slice assignment, each of
# which instantiates a sizeable library routine), and every integer handed to another kernel is int64 from its
# first assignment (a literal ``0`` would type the call once as ``Literal[int]`` and compile the callee twice).


@numba.njit(cache=True, error_model="numpy")
def _argsort_x(xy, lo, hi, order):
    """``order[lo:hi]``: the rows ``lo .. hi - 1`` of ``xy`` by ascending x (a heap sort; the order among equal x
    is unspecified, which no caller depends on)."""
    n = hi - lo
    for i in range(n):
        order[lo + i] = lo + i
    i = n // 2
    end = n
    while True:
        if i > 0:  # building the heap
            i -= 1
            top = order[lo + i]
        else:  # moving the largest to the end
            end -= 1
            if end <= 0:
                return
            top = order[lo + end]
            order[lo + end] = order[lo]
        key = xy[top, 0]
        parent = i
        child = 2 * i + 1
        while child < end:
            if child + 1 < end and xy[order[lo + child + 1], 0] > xy[order[lo + child], 0]:
                child += 1
            if xy[order[lo + child], 0] > key:
                order[lo + parent] = order[lo + child]
                parent = child
                child = 2 * parent + 1
            else:
                break
        order[lo + parent] = top


@numba.njit(cache=True, error_model="numpy")
def _has_partner(pts, a0, a1, bx, border, b0, b1, box, out):
    """``out[i - a0] |= some row of pts in b0 .. b1 - 1 lies in the box |dx|, |dy| <= box around pts[i]`` for
    ``i`` in ``a0 .. a1 - 1`` (the exact test of ``hough._has_partner``), by a sweep over those rows by ascending x
    (``bx[b0:b1]``, rows ``border[b0:b1]``; the sorted window only narrows the candidates, a margin keeps every
    pair the exact test accepts)."""
    if a1 == a0 or b1 == b0:
        return
    for i in range(a0, a1):
        if out[i - a0]:
            continue
        ax, ay = pts[i, 0], pts[i, 1]
        margin = 1e-9 * (abs(ax) + box) + 1e-300
        v = ax - box - margin
        lo, hi = b0, b1  # the first j with bx[j] >= v
        while lo < hi:
            mid = (lo + hi) >> 1
            if bx[mid] < v:
                lo = mid + 1
            else:
                hi = mid
        j = lo
        while j < b1 and bx[j] <= ax + box + margin:
            jj = border[j]
            if abs(ax - pts[jj, 0]) <= box and abs(ay - pts[jj, 1]) <= box:
                out[i - a0] = True
                break
            j += 1


@numba.njit(cache=True, error_model="numpy")
def _neighbour(row, col, dr, dc, n_rho, n_theta):
    """The flat cell ``(row + dr, col + dc)`` across the ``theta = 0 / pi`` seam (``-1`` outside the grid); the
    twin of ``hough._neighbour_cells``."""
    r = row + dr
    c = col + dc
    if c < 0 or c >= n_theta:
        r = n_rho - 1 - r
        c = c % n_theta
    if r < 0 or r >= n_rho:
        return -1
    return r * n_theta + c


@numba.njit(cache=True, error_model="numpy")
def _local_inputs(pts, a0, a1, g_xy, g_sel, g_start, S, g0, reach, W):
    """The support arrays ``hough._local_numba`` builds for :func:`local_keep` (the same grid, order and slots):
    ping k's points are rows ``a0 .. a1 - 1`` of ``pts``; the gated points of the earlier ping ``g0 + s`` of the
    group (``s < S``) are rows ``g_start[s] .. g_start[s + 1] - 1`` of ``g_xy`` (``g_sel``: their index in the
    ping)."""
    n_all = a1 - a0
    for s in range(S):
        n_all += g_start[s + 1] - g_start[s]
    lo0, lo1 = pts[a0, 0], pts[a0, 1]
    hi0, hi1 = lo0, lo1
    for i in range(a0 + 1, a1):
        lo0, lo1 = min(lo0, pts[i, 0]), min(lo1, pts[i, 1])
        hi0, hi1 = max(hi0, pts[i, 0]), max(hi1, pts[i, 1])
    for t in range(g_start[0], g_start[S]):
        lo0, lo1 = min(lo0, g_xy[t, 0]), min(lo1, g_xy[t, 1])
        hi0, hi1 = max(hi0, g_xy[t, 0]), max(hi1, g_xy[t, 1])
    rmin = np.inf
    for gap in range(1, reach.shape[0]):
        rmin = min(rmin, reach[gap])
    h = rmin * (1.0 + 2.0 ** -20)
    while (np.floor((hi0 - lo0) / h) + 1) * (np.floor((hi1 - lo1) / h) + 1) > 8 * n_all + 1024:
        h *= 2.0
    nx = math.floor((hi0 - lo0) / h) + 1
    ny = math.floor((hi1 - lo1) / h) + 1
    N = n_all - (a1 - a0)
    n_c = nx * ny
    sup_xy = np.empty((N, 2))
    sup_ring = np.empty(N, dtype=np.int64)
    sup_idx = np.empty(N, dtype=np.int64)
    starts = np.empty((S, n_c + 1), dtype=np.int64)
    kk = np.empty(N, dtype=np.int64)
    count = np.empty(n_c, dtype=np.int64)
    offset = 0
    for s in range(S):
        b0 = g_start[s]
        n = g_start[s + 1] - b0
        for c in range(n_c):
            count[c] = 0
        for i in range(n):
            cx = min(math.floor((g_xy[b0 + i, 0] - lo0) / h), nx - 1)
            cy = min(math.floor((g_xy[b0 + i, 1] - lo1) / h), ny - 1)
            kk[i] = cx * ny + cy
            count[kk[i]] += 1
        starts[s, 0] = offset
        for c in range(n_c):
            starts[s, c + 1] = starts[s, c] + count[c]
            count[c] = starts[s, c]  # now the next free row of cell c
        for i in range(n):  # a counting sort by cell: the order of a stable argsort
            d = count[kk[i]]
            count[kk[i]] = d + 1
            sup_xy[d, 0] = g_xy[b0 + i, 0]
            sup_xy[d, 1] = g_xy[b0 + i, 1]
            sup_idx[d] = g_sel[b0 + i]
            sup_ring[d] = (g0 + s) % W
        offset += n
    return sup_xy, sup_ring, sup_idx, starts, lo0, lo1, h, nx, ny


@numba.njit(cache=True, error_model="numpy")
def _rule_keep(pts, a0, rows_k, k, g_xy, g_sel, g_start, earlier, reach, ring, W, line_r, line_c, line_latest, e,
               any_rule):
    """The ``"latest"`` (``any_rule`` False) and ``"any"`` rules of ``hough._inverse``: detection ``z`` of ping k
    (row ``a0 + z`` of ``pts``; ``rows_k``: its vote rows) is kept when a gated point ``s`` of an earlier ping
    ``p`` of B within ``reach[k - p]`` (``dx^2 + dy^2 <= r^2``) and ``z`` both lie within ``e`` rows of a similar
    line cell ``L`` and (``"latest"``) ``p`` is the latest earlier ping of B with a gated point within ``e`` rows
    of ``L`` (``line_latest[L]``).  The gated points of ``earlier[s]`` are rows ``g_start[s] .. g_start[s + 1] - 1``
    of ``g_xy``."""
    n_k = rows_k.shape[0]
    keep = np.empty(n_k, dtype=np.bool_)
    for zi in range(n_k):
        keep[zi] = False
    S = earlier.shape[0]
    for zi in range(n_k):
        zx, zy = pts[a0 + zi, 0], pts[a0 + zi, 1]
        for rank in range(S):
            s = S - 1 - rank
            p = earlier[s]
            r = reach[k - p]
            r2 = r * r
            for t in range(g_start[s], g_start[s + 1]):
                ddx = zx - g_xy[t, 0]
                ddy = zy - g_xy[t, 1]
                if ddx * ddx + ddy * ddy > r2:
                    continue
                srow = ring[p % W, g_sel[t]]
                for L in range(line_r.shape[0]):
                    c = line_c[L]
                    lr = line_r[L]
                    if abs(np.int64(rows_k[zi, c]) - lr) <= e and abs(np.int64(srow[c]) - lr) <= e:
                        if any_rule or line_latest[L] == p:
                            keep[zi] = True
                            break
                if keep[zi]:
                    break
            if keep[zi]:
                break
    return keep


@numba.njit(cache=True, error_model="numpy")
def remove_run(z, valid, window, shift, box1, gate_gap, v_min, sr, st, e, reach, rule, vel_gate, sigma_pos, dt,
               require_chain, warmup_keep, project, n_rho, n_theta, off, d_rho, d_theta, cos, sin, ctz):
    """The keep mask ``(T, M)`` and the output positions ``(T, M, 2)`` of one run, every ping in one call: the twin of
    ``hough.hough_remove_run`` with the Numba kernel (the same steps in the same order, on the same rows and grids;
    every decision an integer or the same floating-point comparison, so the masks are identical).  ``project``:
    ``new_measurements="projected"`` (each kept detection moved onto its nearest similar line, as
    ``hough._project``); else the positions are ``z``.

    ``box1 = v_max dt`` (the gate between pings ``q`` and ``p`` is ``box1 |q - p|``); ``sr, st, e``: the similarity
    and line tolerances in bins; ``reach (window,)`` by ping gap; ``rule``: 0 local, 1 latest, 2 any;
    ``vel_gate < 0``: no velocity check.
    """
    T, M = valid.shape
    W = window
    keep_out = np.empty((T, M), dtype=np.bool_)
    for k in range(T):
        for i in range(M):
            keep_out[k, i] = False
    z_out = z.copy()
    first_output = W - 1 + shift
    # the valid detections of each ping, flat: ping p's are rows ps[p] .. ps[p + 1] - 1 of pts (slot: their index
    # in the ping), and the same rows by ascending x (xorder, xs: the gate's sweep)
    ps = np.empty(T + 1, dtype=np.int64)
    n = np.int64(0)
    for k in range(T):
        ps[k] = n
        for i in range(M):
            if valid[k, i]:
                n += 1
    ps[T] = n
    pts = np.empty((n, 2))
    slot = np.empty(n, dtype=np.int64)
    most = np.int64(1)
    n = 0
    for k in range(T):
        for i in range(M):
            if valid[k, i]:
                pts[n, 0] = z[k, i, 0]
                pts[n, 1] = z[k, i, 1]
                slot[n] = i
                n += 1
        most = max(most, ps[k + 1] - ps[k])
    xorder = np.empty(n, dtype=np.int64)
    xs = np.empty(n)
    for k in range(T):
        _argsort_x(pts, ps[k], ps[k + 1], xorder)
    for t in range(n):
        xs[t] = pts[xorder[t], 0]
    ring = np.empty((W, most, n_theta), dtype=np.int32)
    ring_t = np.empty((W, n_theta, most), dtype=np.int32)  # the same rows column by column, for the votes
    ring_ping = np.empty(W, dtype=np.int64)
    for i in range(W):
        ring_ping[i] = -1
    n_cells = n_rho * n_theta
    # the accumulator column by column (cell (row, col) at col n_rho + row: a column's votes stay in cache); the
    # peaks and lines handed on are flat row n_theta + col as everywhere else
    votes = np.empty(n_cells, dtype=np.int32)      # (a cell's votes and pings are reset at its first vote of
    n_pings = np.empty(n_cells, dtype=np.int32)    # each group, when ``last`` says it is fresh)
    last = np.empty(n_cells, dtype=np.int32)    # the last (iteration, ping) stamp that voted in a cell
    mark = np.empty(n_cells, dtype=np.int32)    # group A's peaks of the current ping
    stamp = np.empty(n_cells, dtype=np.int64)   # local_keep's stamps, kept for the whole run
    for c in range(n_cells):
        last[c] = -1
        mark[c] = -1
        stamp[c] = -1
    n_max = min(W * most * n_theta, n_cells)
    touched = np.empty(n_max, dtype=np.int64)  # each cell once per group
    # the gated points of the current group, flat: the group's ping g0 + gi has rows g_start[gi] .. g_start[gi + 1]
    # - 1 of g_xy (g_sel: their index in the ping)
    g_xy = np.empty((W * most, 2))
    g_sel = np.empty(W * most, dtype=np.int64)
    g_start = np.empty(W + 1, dtype=np.int64)
    gate = np.empty(most, dtype=np.bool_)
    # the peaks of every ping, flat: ping p's are pk_buf[pk_start[p] .. pk_start[p + 1] - 1] (grown by doubling)
    pk_buf = np.empty(max(n_max, 64), dtype=np.int64)
    pk_start = np.empty(T + 1, dtype=np.int64)
    pk_start[0] = 0
    sim = np.empty(n_max, dtype=np.int64)
    line_r = np.empty(n_max, dtype=np.int64)
    line_c = np.empty(n_max, dtype=np.int64)
    line_latest = np.empty(n_max, dtype=np.int64)
    slot_of_line = np.empty(n_max, dtype=np.int64)
    col_slot = np.empty(n_theta, dtype=np.int64)
    earlier = np.empty(W - 1, dtype=np.int64)
    todo = np.empty(most, dtype=np.int64)
    for i in range(most):
        todo[i] = i
    tag = np.int64(0)
    for k in range(T):
        pk_start[k + 1] = pk_start[k]
        if k < first_output and warmup_keep:
            for i in range(M):
                keep_out[k, i] = valid[k, i]
        if k < W - 1:
            continue
        g0 = k - W + 1
        for p in range(g0, k + 1):  # the vote rows of the group's pings, in the ring
            rs = p % W
            if ring_ping[rs] != p:
                n_p = ps[p + 1] - ps[p]
                rho_rows(pts[ps[p]:ps[p + 1]], cos, sin, d_rho, off, ring[rs, :n_p])
                for i in range(n_p):
                    for j in range(n_theta):
                        ring_t[rs, j, i] = ring[rs, i, j]
                ring_ping[rs] = p
        # step 2: the rectangular gate within the group
        n_g = 0
        for gi in range(W):
            p = g0 + gi
            a0, a1 = ps[p], ps[p + 1]
            for i in range(a1 - a0):
                gate[i] = False
            for q in range(g0, k + 1):
                if q != p and abs(q - p) <= gate_gap:
                    _has_partner(pts, a0, a1, xs, xorder, ps[q], ps[q + 1], box1 * abs(q - p), gate)
            g_start[gi] = n_g
            for i in range(a1 - a0):
                if gate[i]:
                    g_xy[n_g, 0] = pts[a0 + i, 0]
                    g_xy[n_g, 1] = pts[a0 + i, 1]
                    g_sel[n_g] = i
                    n_g += 1
        g_start[W] = n_g
        # steps 3-4: votes, distinct pings per cell, and the peaks (3 x 3 maxima of support * top + votes)
        n_touched = 0
        fresh = k * W
        for j in range(n_theta):
            base = j * n_rho
            for gi in range(W):
                label = k * W + gi
                rows_j = ring_t[(g0 + gi) % W, j]
                for t in range(g_start[gi], g_start[gi + 1]):
                    cell = base + np.int64(rows_j[g_sel[t]])
                    if last[cell] < fresh:  # first vote of this ping's group: a fresh cell
                        votes[cell] = 0
                        n_pings[cell] = 0
                        touched[n_touched] = cell
                        n_touched += 1
                    votes[cell] += 1
                    if last[cell] != label:
                        last[cell] = label
                        n_pings[cell] += 1
        top = np.int64(1)
        for t in range(n_touched):
            top = max(top, np.int64(votes[touched[t]]) + 1)
        pk0 = pk_start[k]
        if pk0 + n_touched > pk_buf.shape[0]:
            grown = np.empty(max(2 * pk_buf.shape[0], pk0 + n_touched), dtype=np.int64)
            for t in range(pk0):
                grown[t] = pk_buf[t]
            pk_buf = grown
        n_cand = 0
        for t in range(n_touched):
            cell = touched[t]
            if n_pings[cell] < v_min:
                continue
            own = np.int64(n_pings[cell]) * top + votes[cell]
            row, col = cell % n_rho, cell // n_rho
            ok = True
            inner = 0 < row < n_rho - 1 and 0 < col < n_theta - 1
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if inner:  # no seam and no edge: the neighbour's offset in the column-by-column layout
                        nb = cell + dc * n_rho + dr
                    else:
                        nb = _neighbour(row, col, dr, dc, n_rho, n_theta)
                        if nb < 0:
                            continue  # outside the grid
                        nb = (nb % n_theta) * n_rho + nb // n_theta
                    if last[nb] < fresh:
                        continue  # no vote (key 0)
                    if np.int64(n_pings[nb]) * top + votes[nb] > own:
                        ok = False
            if ok:
                # in the order found (column by column), not sorted: every use below is independent of the
                # order (marks, bits, any-of tests, and the projection's tie rule on (|d|, column, row))
                pk_buf[pk0 + n_cand] = row * n_theta + col
                n_cand += 1
        pk_start[k + 1] = pk0 + n_cand
        if k < first_output:
            continue
        # step 5: B peaks with a vote from ping k, similar to an A peak
        for t in range(pk_start[k - shift], pk_start[k - shift + 1]):
            a = pk_buf[t]
            mark[(a % n_theta) * n_rho + a // n_theta] = k
        k_label = k * W + W - 1
        n_sim = 0
        for t in range(pk0, pk0 + n_cand):
            cell = pk_buf[t]
            row, col = cell // n_theta, cell % n_theta
            if last[col * n_rho + row] != k_label:
                continue  # no vote from ping k
            found = False
            for dr in range(-sr, sr + 1):
                for dc in range(-st, st + 1):
                    nb = _neighbour(row, col, dr, dc, n_rho, n_theta)
                    if nb >= 0 and mark[(nb % n_theta) * n_rho + nb // n_theta] == k:
                        found = True
                        break
                if found:
                    break
            if found:
                sim[n_sim] = cell
                n_sim += 1
        # step 6: the inverse transform and the support rule
        a0, a1 = ps[k], ps[k + 1]
        n_k = a1 - a0
        if n_k == 0 or n_sim == 0:
            continue
        for s in range(W - 1):
            earlier[s] = g0 + s
        for L in range(n_sim):
            line_r[L] = sim[L] // n_theta
            line_c[L] = sim[L] % n_theta
        lr = line_r[:n_sim]
        lc = line_c[:n_sim]
        if rule == 0:
            for c in range(n_theta):
                col_slot[c] = -1
            n_used = np.int64(0)
            for c in range(n_theta):  # the columns holding a line, ascending
                for L in range(n_sim):
                    if line_c[L] == c:
                        col_slot[c] = n_used
                        n_used += 1
                        break
            for L in range(n_sim):
                slot_of_line[L] = col_slot[line_c[L]]
            bits = line_bits(lr, slot_of_line[:n_sim], n_used, n_rho // 64 + 2)
            sup_xy, sup_ring, sup_idx, starts, x0, y0, h, nx, ny = _local_inputs(pts, a0, a1, g_xy, g_sel, g_start,
                                                                                 W - 1, g0, reach, W)
            tag0 = tag
            tag = tag + n_k + 1
            keep = local_keep(pts[a0:a1], ring[k % W, :n_k], todo[:n_k], sup_xy, sup_ring, sup_idx, starts,
                              earlier, k, bits, n_rho, col_slot, ring, e, reach, x0, y0, h, nx, ny, vel_gate,
                              sigma_pos, dt, require_chain, stamp, tag0, ctz, d_rho, d_theta)
        else:
            for L in range(n_sim):
                line_latest[L] = -(2 ** 40)
                for s in range(W - 1):
                    rows = ring[earlier[s] % W]
                    for t in range(g_start[s], g_start[s + 1]):
                        if abs(np.int64(rows[g_sel[t], line_c[L]]) - line_r[L]) <= e:
                            line_latest[L] = earlier[s]
                            break
            keep = _rule_keep(pts, a0, ring[k % W, :n_k], k, g_xy, g_sel, g_start, earlier, reach, ring, W, lr, lc,
                              line_latest[:n_sim], e, rule == 2)
        for i in range(n_k):
            if keep[i]:
                keep_out[k, slot[a0 + i]] = True
        if project:
            _project_kept(pts[a0:a1], ring[k % W], keep, slot[a0:a1], lr, lc, e, off, d_rho, cos, sin, z_out[k])
    return keep_out, z_out


@numba.njit(cache=True, error_model="numpy")
def _project_kept(pts_k, rows_k, keep, slots_k, line_r, line_c, e, off, d_rho, cos, sin, out):
    """``hough._project``: each kept detection of ping k onto the nearest similar line within ``e`` rows (ties: the
    lowest column, then the lowest rho bin), ``d = x cos + y sin - rho``, ``(x, y) - d (cos, sin)`` into ``out``."""
    for i in range(pts_k.shape[0]):
        if not keep[i]:
            continue
        x, y = pts_k[i, 0], pts_k[i, 1]
        best = -1
        best_d, best_abs = 0.0, np.inf
        for L in range(line_r.shape[0]):
            c = line_c[L]
            if abs(np.int64(rows_k[i, c]) - line_r[L]) > e:
                continue
            bins = line_r[L] - off
            d = x * cos[c] + y * sin[c] - bins * d_rho
            a = abs(d)
            if best < 0 or a < best_abs or (a == best_abs and (c < line_c[best] or (c == line_c[best]
                                                                                      and line_r[L] < line_r[best]))):
                best, best_d, best_abs = L, d, a
        c = line_c[best]
        out[slots_k[i], 0] = x - best_d * cos[c]
        out[slots_k[i], 1] = y - best_d * sin[c]
