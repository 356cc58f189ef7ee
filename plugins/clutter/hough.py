"""Hough-transform clutter removal for active sonar (paper 001, section 3).

A target on a straight leg leaves collinear detections over consecutive pings; clutter does not.  For
every ping ``k`` the remover decides, from pings ``<= k`` only (causal) and without reading
``origin``, which detections of ping ``k`` to keep:

1. **Groups.**  ``B = pings k-W+1 .. k`` and ``A = pings k-W+1-s .. k-s`` (``W = window``,
   ``s = shift``).  The default ``s = 1`` gives the overlapping windows of the brief; ``s = W`` gives
   non-overlapping halves (the brief's ablation uses ``W = 3, s = 3``).  Group ``A`` at ping ``k`` is
   group ``B`` at ping ``k - s``, so its peaks are reused, not recomputed.
2. **Rectangular gate** (preliminary association) within a group: a detection of ping ``p`` is kept
   if some detection of another ping ``q`` of the same group with ``0 < |p - q| <= gate_gap`` lies in
   the box ``|dx|, |dy| <= v_max dt |p - q|``.
3. **Hough transform** of each gated group: every point votes once in each column ``theta_j = j dtheta``
   (``theta in [0, pi)``) at the bin ``round(rho / drho)`` of::

        rho = x cos(theta) + y sin(theta)          (eq 1; rho may be negative)

   Votes are counted per ping (``np.add.at``) and kept from ping to ping: when the gate of an earlier ping
   changes only its newly gated / ungated points vote; a cell's *support* is the number of distinct pings
   that voted for it.
4. **Peaks:** cells with support ``>= v_min`` that are maxima of ``support + votes / (max votes + 1)``
   in their 3 x 3 neighbourhood (non-maximum suppression, ties kept).  A peak of ``B`` must also hold
   a vote from ping ``k``.
5. **Similarity:** a ``B`` peak is similar to an ``A`` peak when ``|rho_a - rho_b| <= sim_rho`` and
   ``|theta_a - theta_b| <= sim_theta`` (tolerances rounded down to whole bins), comparing lines modulo
   ``(rho, theta) == (-rho, theta + pi)``: across the ``theta = 0 / pi`` seam the neighbouring column is
   the far column with ``rho`` negated (the grid is symmetric in ``rho``, so that is a flip).
6. **Inverse transform:** detection ``z`` of ping ``k`` is kept when, for some similar ``B`` line
   ``(rho_b, theta_b)``, ``|x cos theta_b + y sin theta_b - rho_b| <= eps`` and ``z`` lies within
   ``support_reach`` (default ``2 v_max dt``) of a *latest support* of that line: a gated detection of
   the most recent earlier ping of ``B`` that lies within ``eps`` of the line.  The ``eps`` tests are
   made on the ``rho`` bins (``|bin(z) - bin_b| <= floor(eps / drho)`` in the line's column).
7. **Warm-up:** pings ``k < W - 1 + s`` (group ``A`` not yet full) produce no output (``warmup="drop"``,
   the brief's choice) or pass every detection (``warmup="keep"``).

The remover only narrows ``Scans.valid`` (:meth:`workbench.types.Scans.with_valid`); it never moves a
detection (the brief's optional "replace each point by its projection on the line" is not done).

Cost per ping is ``O(n W n_theta)`` for the votes plus ``O(n_rho n_theta)`` grid filters; the inverse
step checks (detection, nearby support) pairs in rounds of nearest neighbours, so it stays bounded in
dense clutter.  Runs are processed one after another.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from workbench import hookimpl
from workbench.specs import ClutterRemoverSpec
from workbench.types import InputError, Scans

DEFAULTS = {
    "window": 5,
    "shift": 1,
    "v_max": 8.0,
    "dt": 1.0,
    "gate_gap": 2,
    "d_rho": 1.0,
    "d_theta_deg": 1.0,
    "v_min": 3,
    "sim_rho": 3.0,
    "sim_theta_deg": 3.0,
    "eps": 4.0,
    "support_reach": None,
    "support": "latest",
    "warmup": "drop",
}


@dataclass(frozen=True)
class HoughGrid:
    """The accumulator grid: ``rho`` bins ``-off .. off`` (times ``d_rho``), ``n_theta`` columns on ``[0, pi)``.

    Cell ``(i, j)`` is ``rho = (i - off) d_rho``, ``theta = j d_theta``; flat index ``i n_theta + j``.
    """

    d_rho: float
    d_theta: float
    n_theta: int
    off: int

    @property
    def n_rho(self) -> int:
        return 2 * self.off + 1

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n_rho, self.n_theta)

    @property
    def theta(self) -> np.ndarray:
        return np.arange(self.n_theta) * self.d_theta

    @property
    def rho(self) -> np.ndarray:
        return (np.arange(self.n_rho) - self.off) * self.d_rho

    def rho_index(self, points: np.ndarray) -> np.ndarray:
        """Row index of each point's vote in each column, ``(n, 2) -> (n, n_theta)`` int."""
        th = self.theta
        # rho = x cos(theta) + y sin(theta)     (eq 1)
        rho = points[:, :1] * np.cos(th)
        rho += points[:, 1:2] * np.sin(th)
        if self.d_rho != 1.0:  # x / 1.0 == x exactly
            rho /= self.d_rho
        np.rint(rho, out=rho)
        rows = rho.astype(np.int32)
        rows += self.off
        return rows


def make_grid(d_rho: float, d_theta_deg: float, rho_max: float) -> HoughGrid:
    n_theta = 180.0 / d_theta_deg
    if not d_rho > 0 or not d_theta_deg > 0 or abs(n_theta - round(n_theta)) > 1e-9:
        raise InputError(f"hough: need d_rho > 0 and d_theta_deg > 0 dividing 180, got {d_rho}, {d_theta_deg}")
    return HoughGrid(float(d_rho), np.deg2rad(d_theta_deg), int(round(n_theta)), int(np.ceil(rho_max / d_rho)) + 2)


def neighbours(rows: np.ndarray, cols: np.ndarray, grid: HoughGrid, half_rho: int = 1,
               half_theta: int = 1) -> np.ndarray:
    """Flat indices of the cells within ``|d row| <= half_rho``, ``|d col| <= half_theta`` of each cell
    ``(rows, cols)`` (``-1`` outside the grid), across the ``theta = 0 / pi`` seam.

    Column ``-1`` is ``theta = pi - dtheta`` with ``rho`` negated: on the symmetric ``rho`` axis that is
    row ``n_rho - 1 - row`` of the last column; likewise column ``n_theta`` is column 0 flipped.
    Shapes: ``(C,) -> (C, (2 half_rho + 1) (2 half_theta + 1))``.
    """
    dr, dc = np.meshgrid(np.arange(-half_rho, half_rho + 1), np.arange(-half_theta, half_theta + 1), indexing="ij")
    r = rows[:, None] + dr.ravel()[None, :]
    c = cols[:, None] + dc.ravel()[None, :]
    wrap = (c < 0) | (c >= grid.n_theta)
    # (rho, theta) == (-rho, theta +- pi): flip the row, shift the column by n_theta
    r = np.where(wrap, grid.n_rho - 1 - r, r)
    c = np.mod(c, grid.n_theta)
    inside = (r >= 0) & (r < grid.n_rho)
    return np.where(inside, r * grid.n_theta + c, -1)


def _max_rows(values: np.ndarray, half: int) -> np.ndarray:
    """Maximum over rows ``i - half .. i + half`` of each cell (rows outside the grid ignored), ``(n_rho, J)``."""
    out = values.copy()
    for d in range(1, min(int(half), values.shape[0] - 1) + 1):
        np.maximum(out[d:], values[:-d], out=out[d:])
        np.maximum(out[:-d], values[d:], out=out[:-d])
    return out


def _max_cols_seam(values: np.ndarray, half: int) -> np.ndarray:
    """Maximum over columns ``j - half .. j + half`` across the ``theta = 0 / pi`` seam: column ``-c`` is
    column ``n_theta - c`` with ``rho`` negated (rows flipped), column ``n_theta + c`` is column ``c``
    flipped; one wrap at most (``half`` is capped at ``n_theta``).  ``(n_rho, n_theta)``."""
    n = values.shape[1]
    out = values.copy()
    flipped = values[::-1]
    for d in range(1, min(int(half), n) + 1):
        np.maximum(out[:, d:], values[:, :n - d], out=out[:, d:])  # column j - d
        np.maximum(out[:, :d], flipped[:, n - d:], out=out[:, :d])  # j - d < 0: column n + j - d flipped
        np.maximum(out[:, :n - d], values[:, d:], out=out[:, :n - d])  # column j + d
        np.maximum(out[:, n - d:], flipped[:, :d], out=out[:, n - d:])  # j + d >= n: column j + d - n flipped
    return out


def find_peaks(support: np.ndarray, votes: np.ndarray, v_min: int, grid: HoughGrid) -> tuple[np.ndarray, np.ndarray]:
    """Peaks ``(rows, cols)``: cells with ``support >= v_min`` that are maxima of
    ``score = support + votes / (max votes + 1)`` over their 3 x 3 neighbourhood (seam-aware, ties kept).

    ``support, votes (n_rho, n_theta)`` non-negative integers.  Since ``votes < max votes + 1`` the score
    orders cells exactly as the integer key ``support (max votes + 1) + votes`` (equal keys, equal
    scores), so the filter runs on that key in the smallest integer type: a 3-point maximum down ``rho``
    then a seam-aware 3-point maximum across ``theta`` (cells outside the ``rho`` range ignored).  Equal
    to comparing each cell with :func:`neighbours` (tested).
    """
    if votes.size == 0:
        return np.nonzero(np.zeros(grid.shape, dtype=bool))
    top = int(votes.max()) + 1
    dtype = np.min_scalar_type(int(support.max()) * top + top)
    # score = support + votes / (max votes + 1), ordered as support * (max votes + 1) + votes
    key = support.astype(dtype)
    key *= top
    key += votes.astype(dtype)
    m = _max_cols_seam(_max_rows(key, 1), 1)
    return np.nonzero((support >= v_min) & (key >= m))


def similar_to(rows_b, cols_b, rows_a, cols_a, grid: HoughGrid, half_rho: int, half_theta: int) -> np.ndarray:
    """Which cells ``b`` lie within ``half_rho`` rows and ``half_theta`` columns of some cell ``a``, modulo
    ``(rho, theta) == (-rho, theta + pi)``; ``(len(b),)`` bool.

    Dense: the ``a`` cells are marked on the grid, dilated by ``half_rho`` rows and (across the seam)
    ``half_theta`` columns, and read at the ``b`` cells.
    """
    out = np.zeros(len(rows_b), dtype=bool)
    if len(rows_a) == 0 or len(rows_b) == 0:
        return out
    mark = np.zeros(grid.shape, dtype=bool)
    mark[rows_a, cols_a] = True
    near = _max_cols_seam(_max_rows(mark, int(half_rho)), min(int(half_theta), grid.n_theta))
    return near[rows_b, cols_b]


def lines_similar(rho_a, theta_a, rho_b, theta_b, tol_rho: float, tol_theta: float) -> np.ndarray:
    """Pairwise similarity of lines ``a`` and ``b`` modulo ``(rho, theta) == (-rho, theta + pi)``.

    ``theta`` in ``[0, pi)``; returns ``(len(a), len(b))`` bool.  (The remover uses the equivalent
    cell test :func:`similar_to`; this is the closed form in ``(rho, theta)``, for tests and small sets.)
    """
    ra, ta = np.asarray(rho_a, float)[:, None], np.asarray(theta_a, float)[:, None]
    rb, tb = np.asarray(rho_b, float)[None, :], np.asarray(theta_b, float)[None, :]
    dt = ta - tb
    direct = (np.abs(ra - rb) <= tol_rho) & (np.abs(dt) <= tol_theta)
    # across the seam: (rho_b, theta_b) == (-rho_b, theta_b +- pi)
    flipped = (np.abs(ra + rb) <= tol_rho) & (np.abs(np.abs(dt) - np.pi) <= tol_theta)
    return direct | flipped


@dataclass
class _RunCache:
    """Per-run memo of what earlier pings already computed (mutable, private to one ``remove`` call).

    ``counts[p] = (mask, flat counts)``: ping ``p``'s votes from its gated points ``mask``, kept up to date
    when the gate of ``p`` changes (add the newly gated points' votes, drop the ungated ones') instead of
    re-voting the whole ping.
    """

    pts: list
    grid: HoughGrid
    slots: list
    count_dtype: np.dtype
    row_cache: dict = field(default_factory=dict)
    trees: dict = field(default_factory=dict)
    partner: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    peaks: dict = field(default_factory=dict)

    def rows(self, p: int) -> np.ndarray:
        """The vote rows of ping ``p`` in every column, ``(n_p, n_theta)`` (computed once)."""
        if p not in self.row_cache:
            self.row_cache[p] = self.grid.rho_index(self.pts[p])
        return self.row_cache[p]

    def tree(self, p: int) -> cKDTree:
        if p not in self.trees:
            self.trees[p] = cKDTree(self.pts[p])
        return self.trees[p]

    def _add_votes(self, counts: np.ndarray, p: int, which: np.ndarray, ufunc) -> None:
        """``counts[cell] (+/-)= 1`` for every vote of the points ``which`` of ping ``p`` (unbuffered)."""
        grid = self.grid
        flat = (self.rows(p)[which] * grid.n_theta + np.arange(grid.n_theta)).ravel()
        ufunc.at(counts, flat, np.ones(flat.size, dtype=counts.dtype))

    def counts_of(self, p: int, mask: np.ndarray) -> np.ndarray:
        """Votes of the points ``mask`` of ping ``p`` per cell, flat ``(n_rho n_theta,)``."""
        entry = self.counts.get(p)
        if entry is None:
            counts = np.zeros(self.grid.n_rho * self.grid.n_theta, dtype=self.count_dtype)
            self._add_votes(counts, p, mask, np.add)
        else:
            old, counts = entry
            added, dropped = mask & ~old, old & ~mask
            if added.any():
                self._add_votes(counts, p, added, np.add)
            if dropped.any():  # never below zero: these votes were added before
                self._add_votes(counts, p, dropped, np.subtract)
        self.counts[p] = (mask.copy(), counts)
        return counts


def _has_partner(cache: _RunCache, p: int, q: int, box: float) -> np.ndarray:
    """Points of ping ``p`` with a point of ping ``q`` in the box ``|dx|, |dy| <= box``."""
    key = (p, q)
    if key not in cache.partner:
        if len(cache.pts[p]) == 0 or len(cache.pts[q]) == 0:
            cache.partner[key] = np.zeros(len(cache.pts[p]), dtype=bool)
        else:
            bound = np.nextafter(box, np.inf)
            d, _ = cache.tree(q).query(cache.pts[p], k=1, p=np.inf, distance_upper_bound=bound)
            cache.partner[key] = np.isfinite(d)
    return cache.partner[key]


def _gate(cache: _RunCache, group: range, v_max: float, dt: float, gap: int) -> dict:
    kept = {}
    for p in group:
        mask = np.zeros(len(cache.pts[p]), dtype=bool)
        for q in group:
            if q != p and abs(q - p) <= gap:
                mask |= _has_partner(cache, p, q, v_max * dt * abs(q - p))
        kept[p] = mask
    return kept


def _range_tables(bits: np.ndarray, longest: int) -> np.ndarray:
    """Sparse table of ``bits (n_rho, J)`` along ``rho``: level ``t`` holds the OR of rows ``r .. r + 2^t - 1``
    (rows past the grid ignored); levels ``0 .. floor(log2 longest)``, ``-> (levels, n_rho, J)``.  The OR
    over rows ``lo .. hi`` (``hi - lo + 1 <= longest``) is ``level[t][lo] | level[t][hi - 2^t + 1]`` with
    ``t = floor(log2(hi - lo + 1))``."""
    levels = [bits]
    step = 1
    while 2 * step <= longest:
        prev = levels[-1]
        nxt = prev.copy()
        np.bitwise_or(nxt[:-step], prev[step:], out=nxt[:-step])
        levels.append(nxt)
        step *= 2
    return np.stack(levels)


def _inverse(cache: _RunCache, grid: HoughGrid, k: int, group_b: range, kept: dict, counts: dict,
             sim_rows: np.ndarray, sim_cols: np.ndarray, eps: float, reach: np.ndarray, support: str) -> np.ndarray:
    """Keep mask over the valid detections of ping ``k`` (step 6).

    ``sim_rows, sim_cols``: the similar line cells.  ``reach (len(earlier pings),)``: the distance allowed
    to a support of each earlier ping of B.  Only the columns holding a similar line are looked at.

    Each line cell gets one bit: the slot (earlier ping of B, oldest first) of its latest support
    (``support="latest"``), or bit 0 for every line (``"any"``).  A pair (detection ``z``, support ``s``)
    is supported when some column holds a line cell with ``s``'s bit within ``e`` rows of both: an OR
    over the rows ``max(r_z, r_s) - e .. min(r_z, r_s) + e``, read from a sparse table (two lookups).
    """
    n_k = len(cache.pts[k])
    keep = np.zeros(n_k, dtype=bool)
    earlier = [p for p in group_b if p < k]
    if n_k == 0 or sim_rows.size == 0 or not earlier:
        return keep
    e = int(np.floor(eps / grid.d_rho + 1e-9))
    cols, col_of = np.unique(sim_cols, return_inverse=True)
    J = cols.size
    every_col = J == grid.n_theta

    def in_cols(a: np.ndarray) -> np.ndarray:
        return a if every_col else a[:, cols]

    n_slots = len(earlier)
    if support == "latest":
        # latest earlier ping of B with a gated point within e rows of each line cell
        latest = np.full((grid.n_rho, J), -1, dtype=np.min_scalar_type(-n_slots))
        for slot, p in enumerate(earlier):
            np.copyto(latest, slot, where=in_cols(counts[p].reshape(grid.shape)) > 0)
        latest = _max_rows(latest, e)
        cell_slot = latest[sim_rows, col_of].astype(np.intp)
        has = cell_slot >= 0
        cell_rows, cell_cols, cell_slot = sim_rows[has], col_of[has], cell_slot[has]
    else:  # "any": every earlier support of the line counts; one bit serves all slots
        cell_rows, cell_cols, cell_slot = sim_rows, col_of, np.zeros(sim_rows.size, dtype=np.intp)
    if cell_rows.size == 0:
        return keep
    n_words = int(cell_slot.max()) // 8 + 1
    bits = np.zeros((n_words, grid.n_rho, J), dtype=np.uint8)
    bits[cell_slot // 8, cell_rows, cell_cols] = (1 << (cell_slot % 8)).astype(np.uint8)
    # candidates: detections of ping k within e rows of some line cell at all
    near_line = _max_rows(bits.any(axis=0), e)
    rz_all = in_cols(cache.rows(k))
    cand = np.flatnonzero(near_line[rz_all, np.arange(J)].any(axis=1))
    sup_pts = [cache.pts[p][kept[p]] for p in earlier]
    sup_xy = np.concatenate(sup_pts, axis=0)
    if cand.size == 0 or sup_xy.shape[0] == 0:
        return keep
    tables = [_range_tables(bits[w], 2 * e + 1) for w in range(n_words)]
    sup_ping = np.concatenate([np.full(len(sp), i, dtype=np.intp) for i, sp in enumerate(sup_pts)])
    sup_index = np.concatenate([np.flatnonzero(kept[p]) for p in earlier])
    sup_reach = reach[sup_ping]
    sup_bit = sup_ping if support == "latest" else np.zeros_like(sup_ping)

    longest = 2 * e + 1
    log2 = np.zeros(longest + 1, dtype=np.intp)
    log2[1:] = np.floor(np.log2(np.arange(1, longest + 1)))
    table_flat = [t.ravel() for t in tables]

    def supported(zi: np.ndarray, si: np.ndarray, chunk: int = 30) -> np.ndarray:
        """Pairs (detection ``zi``, support ``si``) with a line cell of the support's bit near both, a few
        columns at a time (a pair settled by one column skips the rest)."""
        ok = np.zeros(zi.size, dtype=bool)
        todo = np.arange(zi.size)
        for start in range(0, J, chunk):
            if todo.size == 0:
                break
            c = np.arange(start, min(start + chunk, J))
            s = si[todo]
            rs = np.empty((todo.size, c.size), dtype=np.int32)
            for slot, p in enumerate(earlier):
                m = sup_ping[s] == slot
                if m.any():
                    rs[m] = cache.rows(p)[sup_index[s[m]][:, None], cols[c]]
            rz = rz_all[zi[todo][:, None], c]
            # rows max(rz, rs) - e .. min(rz, rs) + e (inside the grid) are not empty
            i_pair, i_col = np.nonzero(np.abs(rz - rs) <= 2 * e)
            rz, rs = rz[i_pair, i_col], rs[i_pair, i_col]
            lo = np.maximum(np.maximum(rz, rs) - e, 0)
            hi = np.minimum(np.minimum(rz, rs) + e, grid.n_rho - 1)
            t = log2[hi - lo + 1]
            bit = sup_bit[s[i_pair]]
            col = c[i_col]
            hit = np.zeros(todo.size, dtype=bool)
            for w in range(n_words):
                sel = slice(None) if n_words == 1 else bit // 8 == w
                at = (t[sel] * grid.n_rho + lo[sel]) * J + col[sel]
                to = (t[sel] * grid.n_rho + hi[sel] - (1 << t[sel]) + 1) * J + col[sel]
                # OR of the line bits over rows lo .. hi: two overlapping power-of-two windows
                got = (table_flat[w][at] | table_flat[w][to]) & (1 << (bit[sel] % 8)).astype(np.uint8)
                hit[i_pair[sel][got > 0]] = True
            ok[todo[hit]] = True
            todo = todo[~hit]
        return ok

    tree = cKDTree(sup_xy)
    todo = cand
    done_k = 0
    S = sup_xy.shape[0]
    for k_nn in (1, 4, 32, S):  # rounds of nearest supports; most detections settle in the first
        k_nn = min(k_nn, S)
        if todo.size == 0 or k_nn <= done_k:
            break
        d, idx = tree.query(cache.pts[k][todo], k=k_nn, distance_upper_bound=np.nextafter(reach.max(), np.inf))
        d = d.reshape(todo.size, -1)[:, done_k:]
        idx = idx.reshape(todo.size, -1)[:, done_k:]
        found = np.isfinite(d)
        i_loc, col = np.nonzero(found)
        s_idx = idx[i_loc, col]
        close = d[i_loc, col] <= sup_reach[s_idx]
        i_loc, s_idx = i_loc[close], s_idx[close]
        hit = np.zeros(todo.size, dtype=bool)
        ok = supported(todo[i_loc], s_idx)
        hit[i_loc[ok]] = True
        keep[todo[hit]] = True
        # a detection whose every support within reach has been checked is finished
        exhausted = ~found[:, -1]
        todo = todo[~hit & ~exhausted]
        done_k = k_nn
    return keep


def hough_remove_run(z: np.ndarray, valid: np.ndarray, grid: HoughGrid, window: int = 5, shift: int = 1,
                     v_max: float = 8.0, dt: float = 1.0, gate_gap: int = 2, v_min: int = 3, sim_rho: float = 3.0,
                     sim_theta_deg: float = 3.0, eps: float = 4.0, support_reach=None,
                     support: str = "latest", warmup: str = "drop", trace: list | None = None,
                     run: int = 0) -> np.ndarray:
    """The keep mask of one run, ``z (T, M, 2)``, ``valid (T, M)`` -> ``(T, M)`` bool."""
    if support not in ("latest", "any"):
        raise InputError(f"hough: support must be 'latest' or 'any', got {support!r}")
    T = z.shape[0]
    sr = int(np.floor(sim_rho / grid.d_rho + 1e-9))
    st = int(np.floor(np.deg2rad(sim_theta_deg) / grid.d_theta + 1e-9))
    slots = [np.flatnonzero(valid[k]) for k in range(T)]
    pts = [z[k][s] for k, s in enumerate(slots)]
    most = max([len(s) for s in slots] + [1])
    cache = _RunCache(pts=pts, grid=grid, slots=slots, count_dtype=np.min_scalar_type(most))
    vote_dtype, support_dtype = np.min_scalar_type(window * most), np.min_scalar_type(window)
    out = np.zeros(valid.shape, dtype=bool)
    first_output = window - 1 + shift
    gaps = np.arange(window - 1, 0, -1)  # k - p for the earlier pings of B, oldest first
    if support_reach is None:  # two pings at the largest speed
        reach = np.full(gaps.shape, 2.0 * v_max * dt)
    elif support_reach == "gap":  # the largest travel since that ping, at least two pings
        reach = v_max * dt * np.maximum(gaps, 2).astype(float)
    else:
        reach = np.full(gaps.shape, float(support_reach))
    for k in range(T):
        if k < first_output and warmup == "keep":
            out[k] = valid[k]
        if k < window - 1:
            continue
        group_b = range(k - window + 1, k + 1)
        kept = _gate(cache, group_b, v_max, dt, gate_gap)
        counts = {p: cache.counts_of(p, kept[p]) for p in group_b}
        n_pings = np.zeros(grid.n_rho * grid.n_theta, dtype=support_dtype)
        votes = np.zeros(grid.n_rho * grid.n_theta, dtype=vote_dtype)
        for p in group_b:
            n_pings += counts[p] > 0
            votes += counts[p]
        n_pings, votes = n_pings.reshape(grid.shape), votes.reshape(grid.shape)
        cache.peaks[k] = find_peaks(n_pings, votes, v_min, grid)
        for old in [q for q in cache.peaks if q < k - shift]:
            del cache.peaks[old]
        if k < first_output:
            continue
        ra, ca = cache.peaks[k - shift]
        rb, cb = cache.peaks[k]
        now = counts[k].reshape(grid.shape)[rb, cb] > 0  # a B peak needs a vote from ping k
        rb, cb = rb[now], cb[now]
        sim = similar_to(rb, cb, ra, ca, grid, sr, st)
        keep = _inverse(cache, grid, k, group_b, kept, counts, rb[sim], cb[sim], eps, reach, support)
        out[k, slots[k][keep]] = True
        # memo entries later pings can no longer use
        for p in [p for p in cache.trees if p < k - window]:
            del cache.trees[p]
        for p in [p for p in cache.row_cache if p <= k - window]:
            del cache.row_cache[p]
        for p in [p for p in cache.counts if p <= k - window]:
            del cache.counts[p]
        cache.partner = {key: v for key, v in cache.partner.items() if min(key) > k - window}
        if trace is not None:
            rho, theta = grid.rho, grid.theta
            trace.append({
                "run": np.array(run), "ping": np.array(k), "rho": rho, "theta": theta,
                "support_b": n_pings.astype(np.int8),
                "peaks_a": np.stack([rho[ra], theta[ca]], axis=1), "peaks_b": np.stack([rho[rb], theta[cb]], axis=1),
                "similar": np.stack([rho[rb[sim]], theta[cb[sim]]], axis=1),
                "kept": slots[k][keep],
            })
    return out


def remove(scans: Scans, window: int = 5, shift: int = 1, v_max: float = 8.0, dt: float = 1.0, gate_gap: int = 2,
           d_rho: float = 1.0, d_theta_deg: float = 1.0, v_min: int = 3, sim_rho: float = 3.0,
           sim_theta_deg: float = 3.0, eps: float = 4.0, support_reach=None, support: str = "latest",
           warmup: str = "drop", trace: list | None = None) -> Scans:
    """Hough clutter removal of every run of ``scans`` (Cartesian ``z (B, T, M, 2)``); see the module docstring.

    ``trace``: pass a list to receive one dict per output ping (accumulator support of group B, peaks of
    A and B, the similar lines, the kept detections) for figures and debugging.
    """
    if scans.z.shape[-1] != 2:
        raise InputError(f"hough: needs Cartesian (x, y) detections, got measurement dimension {scans.z.shape[-1]}")
    if int(window) != window or window < 2 or int(shift) != shift or shift < 1 or int(gate_gap) != gate_gap \
            or gate_gap < 1 or int(v_min) != v_min or v_min < 1 or v_min > window:
        raise InputError(f"hough: need integers window >= 2, shift >= 1, gate_gap >= 1, 1 <= v_min <= window; got "
                         f"window={window}, shift={shift}, gate_gap={gate_gap}, v_min={v_min}")
    if not (v_max > 0 and dt > 0 and eps >= 0 and sim_rho >= 0 and sim_theta_deg >= 0):
        raise InputError(f"hough: need v_max, dt > 0 and eps, sim_rho, sim_theta_deg >= 0; got {v_max}, {dt}, {eps}, "
                         f"{sim_rho}, {sim_theta_deg}")
    if warmup not in ("drop", "keep"):
        raise InputError(f"hough: warmup must be 'drop' or 'keep', got {warmup!r}")
    valid = scans.valid
    # The grid only has to cover every point; its extent never changes a decision.
    extent = float(np.max(np.linalg.norm(scans.z[valid], axis=-1))) if valid.any() else 1.0
    grid = make_grid(d_rho, d_theta_deg, extent)
    keep = np.zeros(valid.shape, dtype=bool)
    for b in range(scans.batch):
        keep[b] = hough_remove_run(scans.z[b], valid[b], grid, window, shift, v_max, dt, gate_gap, v_min, sim_rho,
                                   sim_theta_deg, eps, support_reach, support, warmup, trace, b)
    return scans.with_valid(keep)


HOUGH = ClutterRemoverSpec(
    name="hough",
    summary="Hough-transform clutter removal over accumulated pings (two groups, similarity, inverse HT)",
    remove=remove,
    params=DEFAULTS,
)


@hookimpl
def workbench_clutter_removers():
    return [HOUGH]
