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

Cost per ping is ``O(n n_theta)`` for the new votes plus a few ``O(n_rho n_theta)`` grid passes (every
one a plain slice operation; no float score grid, no 2-D ``nonzero``).  Pairs of nearby points (the gate,
and (detection, support) pairs of the inverse step) come from neighbouring square cells
(:func:`_cell_pairs`); when that would give more than ``CELL_PAIRS_PER_POINT`` candidates per point
(dense clutter) they come from k-d tree queries instead, nearest supports first, so the cost stays
bounded.  Both routes yield the same pairs, hence the same decisions (tested).  A pair is checked in
all line columns at once with one table lookup per column (:func:`_window_tables`).  Runs are
processed one after another.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from workbench import hookimpl
from workbench.params import Param
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

    def rho_index(self, points: np.ndarray, out: np.ndarray | None = None, block: int = 512) -> np.ndarray:
        """Row index of each point's vote in each column, ``(n, 2) -> (n, n_theta)`` int32 (into ``out`` if
        given).  Computed ``block`` points at a time so that the float temporaries stay in cache; the
        arithmetic of every element is the same as in one pass."""
        th = self.theta
        cos, sin = np.cos(th), np.sin(th)
        n = points.shape[0]
        rows = np.empty((n, self.n_theta), dtype=np.int32) if out is None else out
        rho = np.empty((min(block, n), self.n_theta))
        tmp = np.empty_like(rho)
        for start in range(0, n, block):
            stop = min(start + block, n)
            r, t = rho[:stop - start], tmp[:stop - start]
            # rho = x cos(theta) + y sin(theta)     (eq 1)
            np.multiply(points[start:stop, :1], cos, out=r)
            np.multiply(points[start:stop, 1:2], sin, out=t)
            r += t
            if self.d_rho != 1.0:  # x / 1.0 == x exactly
                r /= self.d_rho
            np.rint(r, out=r)
            rows[start:stop] = r  # integral values: the cast is exact
            rows[start:stop] += self.off
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


def peak_cells(support: np.ndarray, votes: np.ndarray, v_min: int) -> np.ndarray:
    """Flat indices (ascending) of the peaks of :func:`find_peaks`."""
    if votes.size == 0:
        return np.zeros(0, dtype=np.intp)
    top = int(votes.max()) + 1
    dtype = np.min_scalar_type(int(support.max()) * top + top)
    # score = support + votes / (max votes + 1), ordered as support * (max votes + 1) + votes
    key = support.astype(dtype)
    key *= top
    key += votes.astype(dtype)
    m = _max_cols_seam(_max_rows(key, 1), 1)
    ok = key >= m
    ok &= support >= v_min
    return np.flatnonzero(ok)


def find_peaks(support: np.ndarray, votes: np.ndarray, v_min: int, grid: HoughGrid) -> tuple[np.ndarray, np.ndarray]:
    """Peaks ``(rows, cols)``: cells with ``support >= v_min`` that are maxima of
    ``score = support + votes / (max votes + 1)`` over their 3 x 3 neighbourhood (seam-aware, ties kept).

    ``support, votes (n_rho, n_theta)`` non-negative integers.  Since ``votes < max votes + 1`` the score
    orders cells exactly as the integer key ``support (max votes + 1) + votes`` (equal keys, equal
    scores), so the filter runs on that key in the smallest integer type: a 3-point maximum down ``rho``
    then a seam-aware 3-point maximum across ``theta`` (cells outside the ``rho`` range ignored).  Equal
    to comparing each cell with :func:`neighbours` (tested).
    """
    return np.divmod(peak_cells(support, votes, v_min), grid.n_theta)


def similar_cells(flat_b: np.ndarray, flat_a: np.ndarray, grid: HoughGrid, half_rho: int,
                  half_theta: int) -> np.ndarray:
    """:func:`similar_to` on flat cell indices ``(len(b),) -> (len(b),)`` bool."""
    if len(flat_a) == 0 or len(flat_b) == 0:
        return np.zeros(len(flat_b), dtype=bool)
    mark = np.zeros(grid.n_rho * grid.n_theta, dtype=bool)
    mark[flat_a] = True
    near = _max_cols_seam(_max_rows(mark.reshape(grid.shape), int(half_rho)), min(int(half_theta), grid.n_theta))
    return near.ravel()[flat_b]


def similar_to(rows_b, cols_b, rows_a, cols_a, grid: HoughGrid, half_rho: int, half_theta: int) -> np.ndarray:
    """Which cells ``b`` lie within ``half_rho`` rows and ``half_theta`` columns of some cell ``a``, modulo
    ``(rho, theta) == (-rho, theta + pi)``; ``(len(b),)`` bool.

    Dense: the ``a`` cells are marked on the grid, dilated by ``half_rho`` rows and (across the seam)
    ``half_theta`` columns, and read at the ``b`` cells.
    """
    flat_b = np.asarray(rows_b, dtype=np.intp) * grid.n_theta + np.asarray(cols_b, dtype=np.intp)
    flat_a = np.asarray(rows_a, dtype=np.intp) * grid.n_theta + np.asarray(cols_a, dtype=np.intp)
    return similar_cells(flat_b, flat_a, grid, half_rho, half_theta)


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


#: Neighbouring-cell candidate pairs are enumerated while there are at most this many per point (sparse
#: pings); denser pings use k-d tree queries instead.  Both give the same pairs, so the same decisions.
CELL_PAIRS_PER_POINT = 16


def _cell_pairs(a: np.ndarray, b: np.ndarray, r: float, limit: int):
    """Candidate pairs ``(i, j)`` such that every pair with ``|a_i - b_j|_inf <= r`` is among them, or
    ``None`` when there would be more than ``limit`` (or the points span too many cells).

    Points are binned into square cells of side ``h = r (1 + 2^-20)``; a pair within ``r`` lies in the
    same or neighbouring cells (the margin covers the rounding of ``(x - x0) / h`` while the span is
    below ``2^30`` cells).  Each ``a`` point looks up the three runs of three cells ``(cx + dx, cy - 1 ..
    cy + 1)`` in the sorted cell keys of ``b`` (``searchsorted``).  Pairs come out grouped by ``a`` point in
    cell order, so consecutive pairs are near each other.  Shapes: ``a (n, 2)``, ``b (m, 2)`` ->
    ``(P,), (P,)`` intp.
    """
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    if not r > 0:
        return None
    h = r * (1.0 + 2.0 ** -20)
    # per coordinate (a reduction over axis 0 of an (n, 2) array is slow)
    lo = np.array([min(a[:, c].min(), b[:, c].min()) for c in (0, 1)])
    span = (np.array([max(a[:, c].max(), b[:, c].max()) for c in (0, 1)]) - lo) / h
    if not np.all(span < 2.0 ** 30):
        return None
    # uniform points would give about 9 n m / cells candidates: do not sort what is bound to be refused
    if 9.0 * len(a) * len(b) > 4.0 * limit * (np.floor(span[0]) + 1) * (np.floor(span[1]) + 1):
        return None
    ny = int(span[1]) + 3
    ca = np.floor((a - lo) / h).astype(np.int64)
    cb = np.floor((b - lo) / h).astype(np.int64)
    ka = ca[:, 0] * ny + ca[:, 1] + 1  # + 1: the cell below, cy - 1, keeps a key >= 0 in the same x run
    kb = cb[:, 0] * ny + cb[:, 1] + 1
    b_order = np.argsort(kb, kind="stable")
    kb = kb[b_order]
    a_order = np.argsort(ka, kind="stable")
    # (3, n), each row ascending (searchsorted is fastest on sorted queries): cells (cx + dx, cy - 1)
    first = ka[a_order] + np.array([-ny - 1, -1, ny - 1])[:, None]
    start = np.searchsorted(kb, first)
    count = np.searchsorted(kb, first + 2, side="right") - start
    total = int(count.sum())
    if total > limit:
        return None
    start, count = start.T.ravel(), count.T.ravel()  # grouped by a point
    i = np.repeat(np.repeat(a_order, 3), count)
    # position of each candidate in the sorted b: its run's start plus its rank within the run
    shift = np.repeat(start - (np.cumsum(count) - count), count)
    j = b_order[shift + np.arange(total)]
    return i, j


@dataclass
class _RunCache:
    """Per-run memo of what earlier pings already computed (mutable, private to one ``remove`` call).

    ``counts[p] = (mask, flat counts)``: ping ``p``'s votes from its gated points ``mask``, kept up to date
    when the gate of ``p`` changes (add the newly gated points' votes, drop the ungated ones') instead of
    re-voting the whole ping.  The vote rows of the last ``window`` pings live in one ring buffer
    ``ring (window, most, n_theta)``, ping ``p`` at ``p % window``.
    """

    pts: list
    grid: HoughGrid
    slots: list
    count_dtype: np.dtype
    ring: np.ndarray
    ring_ping: list
    trees: dict = field(default_factory=dict)
    partner: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    peaks: dict = field(default_factory=dict)
    scratch: np.ndarray | None = None

    def rows(self, p: int) -> np.ndarray:
        """The vote rows of ping ``p`` in every column, ``(n_p, n_theta)`` (computed once while ``p`` is in
        the window)."""
        slot = p % self.ring.shape[0]
        n = len(self.pts[p])
        if self.ring_ping[slot] != p:
            self.grid.rho_index(self.pts[p], out=self.ring[slot, :n])
            self.ring_ping[slot] = p
        return self.ring[slot, :n]

    def tree(self, p: int) -> cKDTree:
        if p not in self.trees:
            self.trees[p] = cKDTree(self.pts[p], balanced_tree=False)
        return self.trees[p]

    def _add_votes(self, counts: np.ndarray, p: int, which: np.ndarray, ufunc) -> None:
        """``counts[cell] (+/-)= 1`` for every vote of the points ``which`` of ping ``p`` (unbuffered)."""
        grid = self.grid
        flat = self.rows(p)[which]
        flat *= grid.n_theta
        flat += np.arange(grid.n_theta, dtype=flat.dtype)
        ufunc.at(counts, flat.ravel(), counts.dtype.type(1))

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

    def buffer(self, shape: tuple, dtype) -> np.ndarray:
        """A scratch array of ``shape`` (reused from ping to ping; contents undefined)."""
        size = int(np.prod(shape))
        if self.scratch is None or self.scratch.size < size or self.scratch.dtype != dtype:
            self.scratch = np.empty(size, dtype=dtype)
        return self.scratch[:size].reshape(shape)


def _has_partner(cache: _RunCache, p: int, q: int, box: float) -> np.ndarray:
    """Points of ping ``p`` with a point of ping ``q`` in the box ``|dx|, |dy| <= box`` (symmetric: the
    answer for ``(q, p)`` is stored at the same time)."""
    key = (p, q)
    if key not in cache.partner:
        a, b = cache.pts[p], cache.pts[q]
        in_a, in_b = np.zeros(len(a), dtype=bool), np.zeros(len(b), dtype=bool)
        pairs = _cell_pairs(a, b, box, CELL_PAIRS_PER_POINT * (len(a) + len(b)))
        if pairs is not None:
            i, j = pairs
            # |dx|, |dy| <= box: the Chebyshev distance that the k-d tree query below compares
            ok = np.abs(a[i, 0] - b[j, 0]) <= box
            ok &= np.abs(a[i, 1] - b[j, 1]) <= box
            in_a[i[ok]] = True
            in_b[j[ok]] = True
        else:  # dense pings: nearest neighbour in the max norm, both ways
            bound = np.nextafter(box, np.inf)
            in_a = np.isfinite(cache.tree(q).query(a, k=1, p=np.inf, distance_upper_bound=bound)[0])
            in_b = np.isfinite(cache.tree(p).query(b, k=1, p=np.inf, distance_upper_bound=bound)[0])
        cache.partner[key], cache.partner[(q, p)] = in_a, in_b
    return cache.partner[key]


def _gate(cache: _RunCache, group: range, v_max: float, dt: float, gap: int, has_partner=None) -> dict:
    """The preliminary association: the points of each ping of ``group`` with a point of another ping at
    most ``gap`` pings away inside the box ``v_max dt |q - p|`` (``has_partner`` defaults to
    :func:`_has_partner`; the tests pass their k-d tree reference)."""
    has_partner = _has_partner if has_partner is None else has_partner
    kept = {}
    for p in group:
        mask = np.zeros(len(cache.pts[p]), dtype=bool)
        for q in group:
            if q != p and abs(q - p) <= gap:
                mask |= has_partner(cache, p, q, v_max * dt * abs(q - p))
        kept[p] = mask
    return kept


def _window_tables(bits: np.ndarray, e: int, out: np.ndarray) -> np.ndarray:
    """OR of the line bits over every row window a pair can ask about.

    ``bits (W, J, H)`` (rows padded with ``e`` empty rows at each end) -> ``out (W, J, 2 e + 2, H)``:
    level ``a`` holds the OR of rows ``r .. r + 2 e - a`` (window length ``2 e + 1 - a``; rows past the
    end empty), level ``2 e + 1`` is empty.  A pair whose rows differ by ``a = |r_z - r_s|`` asks for the
    rows ``max(r_z, r_s) - e .. min(r_z, r_s) + e``: level ``min(a, 2 e + 1)`` at padded row
    ``max(r_z, r_s)``.  Rows are the last axis so that nearby pairs read nearby bytes.
    """
    H = bits.shape[-1]
    out[:, :, 2 * e] = bits
    out[:, :, 2 * e + 1] = 0
    for length in range(2, 2 * e + 2):
        a = 2 * e + 1 - length
        np.copyto(out[:, :, a], out[:, :, a + 1])
        np.bitwise_or(out[:, :, a, :H - length + 1], bits[:, :, length - 1:], out=out[:, :, a, :H - length + 1])
    return out


def _supported_numpy(zi, si, rows_k, ring, sup_ring, sup_index, sup_word, sup_bit, cols, table, e,
                     chunk: int = 1024) -> np.ndarray:
    """Pairs (detection ``zi``, support ``si``) with a line cell of the support's bit within ``e`` rows of
    both in some column: ``table[word, j, min(|r_z - r_s|, 2 e + 1), max(r_z, r_s)] & bit``, ``chunk``
    pairs at a time over all line columns.  ``(P,) -> (P,)`` bool."""
    ok = np.zeros(zi.size, dtype=bool)
    n_words, J, levels, H = table.shape
    idx_type = np.int32 if table[0].size < 2 ** 31 else np.int64
    col_base = np.arange(J, dtype=idx_type) * (levels * H)
    every_col = J == rows_k.shape[1]
    for w in range(n_words):
        flat = table[w].ravel()
        sel = np.arange(zi.size) if n_words == 1 else np.flatnonzero(sup_word[si] == w)
        for start in range(0, sel.size, chunk):
            at = sel[start:start + chunk]
            z, s = zi[at], si[at]
            rz = rows_k[z]
            rs = ring[sup_ring[s], sup_index[s]]
            if not every_col:
                rz, rs = rz[:, cols], rs[:, cols]
            a = rz - rs
            np.abs(a, out=a)
            np.minimum(a, 2 * e + 1, out=a)
            a = a.astype(idx_type, copy=False)
            # flat index (column, level, padded row): the rows max - e .. min + e
            a *= H
            a += np.maximum(rz, rs)
            a += col_base
            got = np.take(flat, a)
            got &= sup_bit[s][:, None]
            ok[at] = got.any(axis=1)
    return ok


def _inverse(cache: _RunCache, grid: HoughGrid, k: int, group_b: range, kept: dict, counts: dict,
             sim_rows: np.ndarray, sim_cols: np.ndarray, eps: float, reach: np.ndarray, support: str) -> np.ndarray:
    """Keep mask over the valid detections of ping ``k`` (step 6).

    ``sim_rows, sim_cols``: the similar line cells.  ``reach (len(earlier pings),)``: the distance allowed
    to a support of each earlier ping of B.  Only the columns holding a similar line are looked at.

    Each line cell gets one bit: the slot (earlier ping of B, oldest first) of its latest support
    (``support="latest"``), or bit 0 for every line (``"any"``).  A pair (detection ``z``, support ``s``)
    is supported when some column holds a line cell with ``s``'s bit within ``e`` rows of both: an OR
    over the rows ``max(r_z, r_s) - e .. min(r_z, r_s) + e``, one lookup in :func:`_window_tables`.
    Pairs within reach come from neighbouring cells (:func:`_cell_pairs`), or in dense pings from rounds
    of k-d tree nearest neighbours (a detection settled in one round skips the rest).
    """
    n_k = len(cache.pts[k])
    keep = np.zeros(n_k, dtype=bool)
    earlier = [p for p in group_b if p < k]
    if n_k == 0 or sim_rows.size == 0 or not earlier:
        return keep
    e = int(np.floor(eps / grid.d_rho + 1e-9))
    used = np.zeros(grid.n_theta, dtype=bool)
    used[sim_cols] = True
    cols = np.flatnonzero(used)
    col_of = (np.cumsum(used) - 1)[sim_cols]
    J = cols.size
    every_col = J == grid.n_theta

    n_slots = len(earlier)
    if support == "latest":
        # latest earlier ping of B with a gated point within e rows of each line cell: the largest
        # slot + 1 voted in the cell, dilated over e rows (0: none)
        latest = np.zeros((grid.n_rho, J), dtype=np.min_scalar_type(n_slots))
        for slot, p in enumerate(earlier):
            c = counts[p].reshape(grid.shape)
            voted = (c if every_col else c[:, cols]) > 0
            voted = voted.astype(latest.dtype, copy=False) if latest.dtype != np.uint8 else voted.view(np.uint8)
            voted *= latest.dtype.type(slot + 1)
            np.maximum(latest, voted, out=latest)
        latest = _max_rows(latest, e)
        cell_slot = latest.ravel()[sim_rows * J + col_of].astype(np.intp) - 1
        has = cell_slot >= 0
        cell_rows, cell_cols, cell_slot = sim_rows[has], col_of[has], cell_slot[has]
    else:  # "any": every earlier support of the line counts; one bit serves all slots
        cell_rows, cell_cols, cell_slot = sim_rows, col_of, np.zeros(sim_rows.size, dtype=np.intp)
    sup_pts = [cache.pts[p][kept[p]] for p in earlier]
    sup_xy = np.concatenate(sup_pts, axis=0)
    if cell_rows.size == 0 or sup_xy.shape[0] == 0:
        return keep
    n_words = int(cell_slot.max()) // 8 + 1
    H = grid.n_rho + 2 * e  # e empty rows above and below: windows never leave the array
    bits = np.zeros((n_words, J, H), dtype=np.uint8)
    bits[cell_slot // 8, cell_cols, cell_rows + e] = (1 << (cell_slot % 8)).astype(np.uint8)
    table = _window_tables(bits, e, cache.buffer((n_words, J, 2 * e + 2, H), np.uint8))

    sup_slot = np.concatenate([np.full(len(sp), i, dtype=np.intp) for i, sp in enumerate(sup_pts)])
    sup_index = np.concatenate([np.flatnonzero(kept[p]) for p in earlier])
    sup_ring = np.array([p % cache.ring.shape[0] for p in earlier], dtype=np.intp)[sup_slot]
    for p in earlier:
        cache.rows(p)  # in the ring
    rows_k = cache.rows(k)
    sup_reach = reach[sup_slot]
    sup_bitslot = sup_slot if support == "latest" else np.zeros_like(sup_slot)
    sup_word = sup_bitslot // 8
    sup_bit = (1 << (sup_bitslot % 8)).astype(np.uint8)

    def supported(zi: np.ndarray, si: np.ndarray) -> np.ndarray:
        return _supported_numpy(zi, si, rows_k, cache.ring, sup_ring, sup_index, sup_word, sup_bit, cols, table, e)

    z_xy = cache.pts[k]
    S = sup_xy.shape[0]
    pairs = _cell_pairs(z_xy, sup_xy, float(reach.max()), CELL_PAIRS_PER_POINT * (n_k + S))
    if pairs is not None:
        zi, si = pairs
        dx, dy = z_xy[zi, 0] - sup_xy[si, 0], z_xy[zi, 1] - sup_xy[si, 1]
        # Euclidean distance, computed as the k-d tree computes it
        close = np.sqrt(dx * dx + dy * dy) <= sup_reach[si]
        zi, si = zi[close], si[close]
        keep[zi[supported(zi, si)]] = True
        return keep

    tree = cKDTree(sup_xy, balanced_tree=False)
    todo = np.arange(n_k)
    done_k = 0
    for k_nn in (1, 4, 32, S):  # rounds of nearest supports; most detections settle in the first
        k_nn = min(k_nn, S)
        if todo.size == 0 or k_nn <= done_k:
            break
        d, idx = tree.query(z_xy[todo], k=k_nn, distance_upper_bound=np.nextafter(reach.max(), np.inf))
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
    cache = _RunCache(pts=pts, grid=grid, slots=slots, count_dtype=np.min_scalar_type(most),
                      ring=np.empty((window, most, grid.n_theta), dtype=np.int32), ring_ping=[-1] * window)
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
        cache.peaks[k] = peak_cells(n_pings, votes, v_min)
        for old in [q for q in cache.peaks if q < k - shift]:
            del cache.peaks[old]
        if k < first_output:
            continue
        fa, fb = cache.peaks[k - shift], cache.peaks[k]
        fb = fb[counts[k][fb] > 0]  # a B peak needs a vote from ping k
        sim = similar_cells(fb, fa, grid, sr, st)
        rb, cb = np.divmod(fb[sim], grid.n_theta)
        keep = _inverse(cache, grid, k, group_b, kept, counts, rb, cb, eps, reach, support)
        out[k, slots[k][keep]] = True
        # memo entries later pings can no longer use
        for p in [p for p in cache.trees if p < k - window]:
            del cache.trees[p]
        for p in [p for p in cache.counts if p <= k - window]:
            del cache.counts[p]
        cache.partner = {key: v for key, v in cache.partner.items() if min(key) > k - window}
        if trace is not None:
            rho, theta = grid.rho, grid.theta
            ra, ca = np.divmod(fa, grid.n_theta)
            rb, cb = np.divmod(fb, grid.n_theta)
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


PARAMETERS = (
    Param("window", 5, "pings per group W (groups A and B, shifted by s pings)", "int", minimum=2),
    Param("shift", 1, "shift s between groups A and B (pings)", "int", minimum=1),
    Param("v_max", 8.0, "largest target speed (units per ping period): the gate between pings", above=0.0),
    Param("dt", 1.0, "ping period", unit="time", above=0.0),
    Param("gate_gap", 2, "a detection votes when another ping within this many pings lies within the gate", "int",
          minimum=1),
    Param("d_rho", 1.0, "accumulator rho bin", above=0.0),
    Param("d_theta_deg", 1.0, "accumulator theta bin, in degrees", above=0.0),
    Param("v_min", 3, "distinct pings a line needs to be a peak", "int", minimum=1),
    Param("sim_rho", 3.0, "rho tolerance of similar lines (A and B)", minimum=0.0),
    Param("sim_theta_deg", 3.0, "theta tolerance of similar lines, in degrees", minimum=0.0),
    Param("eps", 4.0, "distance from a similar line within which a detection is kept", minimum=0.0),
    Param("support_reach", None, "distance from the line's latest support within which a detection is kept "
          "(none: 2 v_max dt)", "float?", above=0.0),
    Param("support", "latest", "which detections of the line support a kept detection", "str",
          choices=("latest", "any")),
    Param("warmup", "drop", "pings before group A is full: no output (drop) or every detection (keep)", "str",
          choices=("drop", "keep")),
)

HOUGH = ClutterRemoverSpec(
    name="hough",
    summary="Hough-transform clutter removal over accumulated pings (two groups, similarity, inverse HT)",
    remove=remove,
    params=DEFAULTS,
    parameters=PARAMETERS,
    frames=("cartesian-2d",),
)


@hookimpl
def workbench_clutter_removers():
    return [HOUGH]
