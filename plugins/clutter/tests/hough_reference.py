"""A brute-force reference of the Hough clutter remover (paper 001, section 3), written to be read, not run fast.

Plain loops over pings, points and accumulator cells, with dicts for the accumulator, straight from the
algorithm's statement (``plugins/clutter/hough.py`` module docstring and ``docs/paper001.md``).  It shares no
code with the remover: the only common arithmetic is the one every implementation of eq 1 must do, the vote
row ``round((x cos theta_j + y sin theta_j) / d_rho)`` with ``theta_j = j d_theta`` (computed here with the same
IEEE operations, so that exact ties agree), and the distance tests ``dx^2 + dy^2 <= reach^2``.

Accumulator cells are keyed ``(b, j)`` with ``b`` the rho bin (``rho = b d_rho``, negative allowed) and ``j``
the theta column; the line ``(rho, theta)`` equals ``(-rho, theta + pi)``, so across the ``theta = 0 / pi``
seam the neighbour of ``(b, 0)`` at column ``-1`` is ``(-b, n_theta - 1)``.
"""

from __future__ import annotations

import math

import numpy as np


def _bins(point, cos_t, sin_t, d_rho):
    """The rho bin of ``point`` in every column: ``rint((x cos theta + y sin theta) / d_rho)``."""
    x, y = float(point[0]), float(point[1])
    rho = x * cos_t + y * sin_t  # eq 1
    return [int(v) for v in np.rint(rho / d_rho)]


def _neighbour_cells(b, j, n_theta):
    """The 8 neighbours of cell ``(b, j)``, across the seam with the rho bin negated."""
    out = []
    for db in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if db == 0 and dj == 0:
                continue
            bb, jj = b + db, j + dj
            if jj < 0:
                bb, jj = -bb, jj + n_theta
            elif jj >= n_theta:
                bb, jj = -bb, jj - n_theta
            out.append((bb, jj))
    return out


def _similar(cell_b, cell_a, half_rho, half_theta, n_theta):
    """Is line ``b`` within ``half_rho`` bins and ``half_theta`` columns of line ``a``, modulo the seam?"""
    (bb, jb), (ba, ja) = cell_b, cell_a
    for d in range(-min(half_theta, n_theta), min(half_theta, n_theta) + 1):
        j = jb + d
        if 0 <= j < n_theta:
            if j == ja and abs(bb - ba) <= half_rho:
                return True
        else:  # across the seam: column j -+ n_theta with the rho bin negated
            if j % n_theta == ja and abs(bb + ba) <= half_rho:
                return True
    return False


def reference_remove_run(z, valid, *, window=5, shift=1, v_max=8.0, dt=1.0, gate_gap=2, d_rho=1.0, d_theta_deg=1.0,
                         v_min=3, sim_rho=3.0, sim_theta_deg=3.0, eps=4.0, support="local", support_reach=None,
                         vel_gate=9.21, sigma_pos=2.0, require_chain=False, new_measurements="detections",
                         warmup="drop"):
    """Keep mask ``(T, M)`` and output positions ``(T, M, 2)`` of one run, ``z (T, M, 2)``, ``valid (T, M)``."""
    T, M = valid.shape
    n_theta = int(round(180.0 / d_theta_deg))
    d_theta = np.deg2rad(d_theta_deg)
    theta = np.arange(n_theta) * d_theta
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    e = int(math.floor(eps / d_rho + 1e-9))
    sr = int(math.floor(sim_rho / d_rho + 1e-9))
    st = int(math.floor(np.deg2rad(sim_theta_deg) / d_theta + 1e-9))
    points = {k: [m for m in range(M) if valid[k, m]] for k in range(T)}
    bins = {(k, m): _bins(z[k, m], cos_t, sin_t, d_rho) for k in range(T) for m in points[k]}
    keep = np.zeros((T, M), dtype=bool)
    out_z = np.array(z, dtype=float, copy=True)

    def reach(gap):
        if support_reach is None:
            return v_max * dt * max(gap, 2) if support == "local" else 2.0 * v_max * dt
        if support_reach == "gap":
            return v_max * dt * max(gap, 2)
        return float(support_reach)

    def close(a, b, r):
        dx, dy = z[a[0], a[1], 0] - z[b[0], b[1], 0], z[a[0], a[1], 1] - z[b[0], b[1], 1]
        return dx * dx + dy * dy <= r * r

    def gated(group):
        """Step 3, the rectangular gate: the points of the group with a partner in another ping."""
        out = set()
        for p in group:
            for m in points[p]:
                for q in group:
                    if q == p or abs(q - p) > gate_gap:
                        continue
                    box = v_max * dt * abs(q - p)
                    if any(abs(z[p, m, 0] - z[q, n, 0]) <= box and abs(z[p, m, 1] - z[q, n, 1]) <= box
                           for n in points[q]):
                        out.add((p, m))
                        break
        return out

    def peaks(group, kept_points, need_ping=None):
        """Steps 4: the accumulator of the gated group and its peaks (support >= v_min, 3 x 3 maxima of
        (support, votes) in lexicographic order, ties kept); with ``need_ping``, only peaks voted by it."""
        votes, pings = {}, {}
        for (p, m) in kept_points:
            for j in range(n_theta):
                cell = (bins[(p, m)][j], j)
                votes[cell] = votes.get(cell, 0) + 1
                pings.setdefault(cell, set()).add(p)
        found = []
        for cell, voters in pings.items():
            if len(voters) < v_min:
                continue
            score = (len(voters), votes[cell])
            if all(score >= (len(pings.get(nb, ())), votes.get(nb, 0)) for nb in _neighbour_cells(*cell, n_theta)):
                if need_ping is None or need_ping in voters:
                    found.append(cell)
        return found

    def on_line(point, line):
        b, j = line
        return abs(bins[point][j] - b) <= e

    def velocity_ok(zp, sp, line, sup):
        """Step 6, the velocity-consistency check of the (support -> detection) step against the step from the
        support's own latest local support on the line."""
        k, p = zp[0], sp[0]
        before = [q for (q, n) in sup if q < p and on_line((q, n), line) and close(sp, (q, n), reach(p - q))]
        if not before:
            return not require_chain
        if vel_gate is None:
            return True
        latest = max(before)
        g2, g1 = (k - p) * dt, (p - latest) * dt
        # var(u - u') per axis = sigma^2 (1/g2^2 + (1/g2 + 1/g1)^2 + 1/g1^2)
        both = 1.0 / g2 + 1.0 / g1
        var = sigma_pos * sigma_pos * (1.0 / (g2 * g2) + both * both + 1.0 / (g1 * g1))
        for (q, n) in sup:
            if q != latest or not on_line((q, n), line) or not close(sp, (q, n), reach(p - q)):
                continue
            ux = (z[zp[0], zp[1], 0] - z[sp[0], sp[1], 0]) / g2
            uy = (z[zp[0], zp[1], 1] - z[sp[0], sp[1], 1]) / g2
            wx = (z[sp[0], sp[1], 0] - z[q, n, 0]) / g1
            wy = (z[sp[0], sp[1], 1] - z[q, n, 1]) / g1
            if (ux - wx) * (ux - wx) + (uy - wy) * (uy - wy) <= vel_gate * var:
                return True
        return False

    def supported(zp, line, sup):
        """Step 6, the support rule: does ``line`` keep detection ``zp``?"""
        k = zp[0]
        if support == "any":
            return any(on_line(s, line) and close(zp, s, reach(k - s[0])) for s in sup)
        if support == "latest":  # the most recent earlier ping with a gated point anywhere on the line
            on = [s for s in sup if on_line(s, line)]
            if not on:
                return False
            latest = max(p for p, _ in on)
            return any(p == latest and close(zp, (p, n), reach(k - p)) for p, n in on)
        # "local": the most recent earlier ping with a gated point on the line within reach of the detection
        local = [s for s in sup if on_line(s, line) and close(zp, s, reach(k - s[0]))]
        if not local:
            return False
        latest = max(p for p, _ in local)
        return any(s[0] == latest and velocity_ok(zp, s, line, sup) for s in local)

    first_output = window - 1 + shift
    for k in range(T):
        if k < first_output:
            if warmup == "keep":
                keep[k] = valid[k]
            continue
        group_b = range(k - window + 1, k + 1)
        group_a = range(k - shift - window + 1, k - shift + 1)
        kept_b, kept_a = gated(group_b), gated(group_a)
        lines_b, lines_a = peaks(group_b, kept_b, need_ping=k), peaks(group_a, kept_a)
        similar = [lb for lb in lines_b if any(_similar(lb, la, sr, st, n_theta) for la in lines_a)]
        sup = [s for s in kept_b if s[0] < k]
        for m in points[k]:
            zp = (k, m)
            lines = [line for line in similar if on_line(zp, line)]
            if not any(supported(zp, line, sup) for line in lines):
                continue
            keep[k, m] = True
            if new_measurements == "projected":
                # onto the nearest similar line within eps (ties: lowest column, then lowest rho bin)
                x, y = z[k, m]
                best = min(lines, key=lambda ln: (abs(x * cos_t[ln[1]] + y * sin_t[ln[1]] - ln[0] * d_rho), ln[1], ln[0]))
                b, j = best
                c, s = cos_t[j], sin_t[j]
                dist = x * c + y * s - b * d_rho
                out_z[k, m] = (x - dist * c, y - dist * s)
    return keep, out_z
