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

Module-level functions, so that Numba's on-disk cache holds across processes.
"""

import numba
import numpy as np


@numba.njit(cache=True)
def _fetch_slot(sx, sy, slot, slot2, sup_xy, cell_start, slot_ping, reach, x0, y0, h, nx, ny, pred_idx, n):
    """Append to ``pred_idx[n:]`` the gated points of slot ``slot2`` within reach of the support ``(sx, sy)`` of
    slot ``slot``; returns the new count."""
    r = reach[slot_ping[slot] - slot_ping[slot2]]
    r2 = r * r
    m = np.int64(np.ceil(r / h))
    cx = np.int64(np.floor((sx - x0) / h))
    cy = np.int64(np.floor((sy - y0) / h))
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


@numba.njit(cache=True)
def _velocity_ok(zx, zy, sx, sy, sup_xy, sup_ring, sup_idx, cell_start, slot_ping, k, slot, col, lrow, ring, e,
                 reach, x0, y0, h, nx, ny, vel_gate, sigma2, dt, require_chain, pred_idx, pred_end):
    """The velocity check of triple (z, s, line ``(lrow, col)``).  The support's predecessors are fetched slot by
    slot, the most recent first, into ``pred_idx`` (``pred_end[i]``: the end of the ``i``-th fetched slot,
    ``-1`` not yet fetched), and reused by the next triples of the same pair."""
    if vel_gate < 0.0 and not require_chain:
        return True
    p = slot_ping[slot]
    g2 = (k - p) * dt
    begin = 0
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


@numba.njit(cache=True, inline="always")
def _window_bits(bj, lo_r, hi_r):
    """The bits of rows ``lo_r .. hi_r`` (fewer than 64 of them) of one column's bit row, lowest row first.

    Branch-free: the two words that can hold them are always read (the bit rows carry one spare word)."""
    i = lo_r >> 6
    s = np.uint64(lo_r & 63)
    word = (bj[i] >> s) | ((bj[i + 1] << (np.uint64(63) - s)) << np.uint64(1))
    return word & ((np.uint64(1) << np.uint64(hi_r - lo_r + 1)) - np.uint64(1))


#: ``ctz(w) = CTZ[((w & -w) * DE_BRUIJN) >> 58]`` (count of trailing zeros of a nonzero 64-bit word)
DE_BRUIJN = np.uint64(0x03F79D71B4CB0A89)
CTZ = np.zeros(64, dtype=np.int64)
for _i in range(64):
    CTZ[((1 << _i) * 0x03F79D71B4CB0A89 % (1 << 64)) >> 58] = _i


@numba.njit(cache=True)
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
    keep = np.zeros(n_k, dtype=np.bool_)
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
        cx = np.int64(np.floor((zx - x0) / h))
        cy = np.int64(np.floor((zy - y0) / h))
        done = False
        for rank in range(S):
            slot = S - 1 - rank
            p = slot_ping[slot]
            r = reach[k - p]
            r2 = r * r
            m = np.int64(np.ceil(r / h))
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
                        c_first = np.int64(np.floor((centre - half) / d_theta)) - 1
                        c_count = min(np.int64(np.ceil(2.0 * half / d_theta)) + 3, n_theta)
                    srow = ring[sup_ring[si], sup_idx[si]]
                    pred_end[:] = -1
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
                        word = _window_bits(bits[j], lo_r, hi_r)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
def accumulate(n_pings, votes, counts):
    """``n_pings += counts > 0``, ``votes += counts`` in one pass (flat arrays; branch-free, so that the loop
    vectorises: adding 0 where a cell has no vote changes nothing)."""
    for c in range(counts.shape[0]):
        v = counts[c]
        n_pings[c] += v > 0
        votes[c] += v


@numba.njit(cache=True)
def line_bits(rows, col_slot_of_line, n_used, n_words):
    """The bit map of the similar line cells: bit ``rows[L]`` of row ``col_slot_of_line[L]`` set, ``(n_used,
    n_words)`` uint64."""
    bits = np.zeros((n_used, n_words), dtype=np.uint64)
    one = np.uint64(1)
    for L in range(rows.shape[0]):
        r = rows[L]
        bits[col_slot_of_line[L], r >> 6] |= one << np.uint64(r & 63)
    return bits


@numba.njit(cache=True)
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
