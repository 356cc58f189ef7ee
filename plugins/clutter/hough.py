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
6. **Inverse transform:** detection ``z`` of ping ``k`` lies on a similar ``B`` line ``L = (rho_b, theta_b)``
   when ``|x cos theta_b + y sin theta_b - rho_b| <= eps`` (tested on the ``rho`` bins, ``|bin(z) - bin_b|
   <= floor(eps / drho)`` in the line's column); it is kept when one such line keeps it by the support rule
   (``support``):

   - ``"local"`` (default): the *latest local support* of ``z`` on ``L`` is the most recent earlier ping of
     ``B`` holding a gated detection ``s`` on ``L`` within reach of ``z``, the reach scaled by the ping gap
     ``g``: ``v_max dt max(g, 2)``.  ``z`` is kept when one such ``s`` passes the *velocity-consistency
     check*: with ``s'`` the latest local support of ``s`` on ``L`` (gap ``g1``; ``g2`` from ``s`` to ``z``)::

         u = (z - s) / (g2 dt),   u' = (s - s') / (g1 dt)
         |u - u'|^2 <= vel_gate sigma_pos^2 (1/g2^2 + (1/g2 + 1/g1)^2 + 1/g1^2) / dt^2

     (the variance of ``u - u'`` for a straight, constant-speed target with position noise ``sigma_pos``).
     Where ``s`` has no earlier local support the check passes (``require_chain=True``: fails).
     ``vel_gate=None``: no check.
   - ``"latest"`` (the previous rule): ``s`` must be of the latest earlier ping with a gated detection
     anywhere on ``L``, within ``support_reach`` (default ``2 v_max dt``) of ``z``.
   - ``"any"``: any gated detection on ``L`` within ``support_reach`` of ``z``.
7. **New measurements:** the paper's output is the clutter-removed set of ping ``k``'s detections
   (``new_measurements="detections"``: only ``Scans.valid`` narrows).  ``"projected"`` also moves each kept
   detection onto the nearest similar line within ``eps`` along its normal (``d = x cos theta + y sin theta -
   rho``, ``(x, y) <- (x, y) - d (cos theta, sin theta)``).
8. **Warm-up:** pings ``k < W - 1 + s`` (group ``A`` not yet full) produce no output (``warmup="drop"``,
   the brief's choice) or pass every detection (``warmup="keep"``).

Cost per ping is ``O(n n_theta)`` for the new votes plus a few ``O(n_rho n_theta)`` grid passes (every
one a plain slice operation; no float score grid, no 2-D ``nonzero``).  Pairs of nearby points (the gate,
and (detection, support) pairs of the inverse step) come from neighbouring square cells
(:func:`_cell_pairs`); when that would give more than ``CELL_PAIRS_PER_POINT`` candidates per point
(dense clutter) they come from k-d tree queries instead, nearest supports first, so the cost stays
bounded.  Both routes yield the same pairs, hence the same decisions (tested).  The local rule runs in a
compiled kernel (:mod:`workbench_clutter.hough_numba`) where the backend policy picks Numba (``backend="auto"``); the
vectorised NumPy code here is its twin, and both are held to the brute-force reference of the tests.  Runs are
processed one after another; where Numba runs (and a ping holds at most :data:`RUN_KERNEL_MAX_DETECTIONS`
detections) each run is one compiled call, :func:`workbench_clutter.hough_numba.remove_run` (every ping's steps
above, the same decisions), instead of this module's per-ping calls.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from workbench import hookimpl
from workbench.kernels.backend import runs_numba
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
    "support": "local",
    "support_reach": None,
    "vel_gate": 9.21,
    "sigma_pos": 2.0,
    "require_chain": False,
    "new_measurements": "detections",
    "warmup": "drop",
    "backend": "auto",
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
    return _neighbour_cells(rows, cols, grid.n_rho, grid.n_theta, half_rho, half_theta)


def _neighbour_cells(rows: np.ndarray, cols: np.ndarray, n_rho: int, n_theta: int, half_rho: int,
                     half_theta: int) -> np.ndarray:
    """:func:`neighbours` on a grid of ``n_rho x n_theta`` cells."""
    dr, dc = np.meshgrid(np.arange(-half_rho, half_rho + 1), np.arange(-half_theta, half_theta + 1), indexing="ij")
    r = rows[:, None] + dr.ravel()[None, :]
    c = cols[:, None] + dc.ravel()[None, :]
    wrap = (c < 0) | (c >= n_theta)
    # (rho, theta) == (-rho, theta +- pi): flip the row, shift the column by n_theta
    r = np.where(wrap, n_rho - 1 - r, r)
    c = np.mod(c, n_theta)
    inside = (r >= 0) & (r < n_rho)
    return np.where(inside, r * n_theta + c, -1)


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
    n_rho, n_theta = support.shape
    cand = np.flatnonzero(support >= v_min)  # the only cells that can be peaks
    if 36 * cand.size <= support.size:
        # few candidates: each compared with its 3 x 3 neighbourhood (:func:`neighbours`, the seam and the rows
        # outside the grid as the dense filter below treats them), the same decisions without a pass over
        # the grid
        nb = _neighbour_cells(*np.divmod(cand, n_theta), n_rho, n_theta, 1, 1)
        nb = np.where(nb >= 0, nb, cand[:, None])  # outside the grid: the cell itself, never above itself
        s_flat, v_flat = support.ravel(), votes.ravel()
        key = s_flat[nb].astype(np.int64) * top + v_flat[nb].astype(np.int64)
        own = s_flat[cand].astype(np.int64) * top + v_flat[cand].astype(np.int64)
        return cand[own >= key.max(axis=1)]
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
    width = (2 * int(half_rho) + 1) * (2 * int(half_theta) + 1)
    if int(half_theta) < grid.n_theta and 4 * len(flat_b) * width <= grid.n_rho * grid.n_theta:
        # few b cells: look their neighbourhoods up among the a cells (:func:`neighbours`: the same cells as
        # the dilation below, across the seam), without a pass over the grid
        rows_b, cols_b = np.divmod(np.asarray(flat_b, dtype=np.intp), grid.n_theta)
        nb = neighbours(rows_b, cols_b, grid, int(half_rho), int(half_theta))
        return (_in_sorted(nb, _sorted_unique(np.asarray(flat_a, dtype=np.intp))) & (nb >= 0)).any(axis=1)
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
    stamps: np.ndarray | None = None
    tag: int = 0
    kernel: str = "numpy"

    def rows(self, p: int) -> np.ndarray:
        """The vote rows of ping ``p`` in every column, ``(n_p, n_theta)`` (computed once while ``p`` is in
        the window)."""
        slot = p % self.ring.shape[0]
        n = len(self.pts[p])
        if self.ring_ping[slot] != p:
            if self.kernel == "numba":
                from . import hough_numba

                th = self.grid.theta
                hough_numba.rho_rows(np.ascontiguousarray(self.pts[p], dtype=float), np.cos(th), np.sin(th),
                                     float(self.grid.d_rho), int(self.grid.off), self.ring[slot, :n])
            else:
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
        if self.kernel == "numba":
            from . import hough_numba

            hough_numba.add_votes(counts, self.rows(p), np.flatnonzero(which), grid.n_theta, ufunc is np.add)
            return
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

    def stamp_buffer(self, grid: "HoughGrid") -> np.ndarray:
        """The numba kernel's per-cell stamps (kept for the whole run; see ``hough_numba.local_keep``)."""
        if self.stamps is None:
            self.stamps = np.full(grid.n_rho * grid.n_theta, -1, dtype=np.int64)
        return self.stamps

    def next_tag(self, n: int) -> int:
        """A tag base above every tag handed out before (``n`` tags are taken)."""
        tag, self.tag = self.tag, self.tag + n + 1
        return tag

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


def _gate(cache: _RunCache, group: range, v_max: float, dt: float, gap: int) -> dict:
    """The preliminary association: the points of each ping of ``group`` with a point of another ping at
    most ``gap`` pings away inside the box ``v_max dt |q - p|`` (:func:`_has_partner`)."""
    kept = {}
    for p in group:
        mask = np.zeros(len(cache.pts[p]), dtype=bool)
        for q in group:
            if q != p and abs(q - p) <= gap:
                mask |= _has_partner(cache, p, q, v_max * dt * abs(q - p))
        kept[p] = mask
    return kept


# -- step 6: the inverse transform and the support rules --------------------------------------------


@dataclass(frozen=True)
class _Lines:
    """The similar line cells of one ping, sorted by (column, row), with a count table per column.

    ``cum[j, x]``: the number of lines in column ``used[j]`` whose row is below ``x``, so the lines of that
    column in rows ``lo .. hi - 1`` are ``start[j] + cum[j, lo] .. start[j] + cum[j, hi] - 1``.
    Shapes: ``rows, cols (L,)``, ``used, start (J,)``, ``cum (J, n_rho + 1)``.
    """

    rows: np.ndarray
    cols: np.ndarray
    used: np.ndarray
    start: np.ndarray
    cum: np.ndarray

    @property
    def size(self) -> int:
        return int(self.rows.size)


def _sorted_unique(a: np.ndarray) -> np.ndarray:
    """``np.unique(a)`` by a sort (NumPy's hash-based ``unique`` is slow on large integer keys)."""
    a = np.sort(a)
    return a[np.concatenate([[True], a[1:] != a[:-1]])] if a.size else a


def _in_sorted(a: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``np.isin(a, table)`` for a sorted ``table``."""
    if table.size == 0:
        return np.zeros(a.shape, dtype=bool)
    at = np.minimum(np.searchsorted(table, a), table.size - 1)
    return table[at] == a


def _lines(flat: np.ndarray, grid: HoughGrid) -> _Lines:
    rows, cols = np.divmod(np.asarray(flat, dtype=np.intp), grid.n_theta)
    order = np.lexsort((rows, cols))
    rows, cols = rows[order], cols[order]
    used, slot = np.unique(cols, return_inverse=True)
    count = np.zeros((used.size, grid.n_rho + 1), dtype=np.int32)
    np.add.at(count, (slot, rows + 1), 1)
    return _Lines(rows, cols, used, np.searchsorted(cols, used), np.cumsum(count, axis=1, dtype=np.int32))


def _lines_near(ra: np.ndarray, rb: np.ndarray, lines: _Lines, e: int) -> tuple[np.ndarray, np.ndarray]:
    """The line cells within ``e`` rows of both points of each pair, in every column holding a line.

    ``ra, rb (P, J)``: the rows of the two points in the columns ``lines.used`` (pass ``rb = ra`` for the
    lines near one point).  Returns ``pair (Q,)``, ``line (Q,)``: every (pair, line) combination.
    """
    n_rows = lines.cum.shape[1] - 1
    lo = np.maximum(ra, rb)
    lo -= e
    np.maximum(lo, 0, out=lo)
    hi = np.minimum(ra, rb)
    hi += e + 1  # exclusive
    np.clip(hi, lo, n_rows, out=hi)
    flat = lines.cum.ravel()
    base = (np.arange(lines.used.size) * (n_rows + 1))[None, :]
    c_lo = flat[lo + base]
    n = flat[hi + base] - c_lo
    pi, jj = np.nonzero(n)
    n = n[pi, jj].astype(np.intp)
    first = lines.start[jj] + c_lo[pi, jj]
    total = int(n.sum())
    if total == 0:
        e_ = np.zeros(0, dtype=np.intp)
        return e_, e_
    pair = np.repeat(pi, n)
    line = np.repeat(first - (np.cumsum(n) - n), n) + np.arange(total)
    return pair, line


def _near_pairs(a: np.ndarray, active: np.ndarray, b: np.ndarray, r: float, process) -> None:
    """Call ``process(i, j)`` with pairs (``a[i]``, ``b[j]``), ``i`` in ``active``, ``dx^2 + dy^2 <= r^2``, until
    every active ``a`` point is settled (``process`` returns the settled mask over ``a``) or has had every
    pair.  Sparse points: all pairs at once, from neighbouring cells (:func:`_cell_pairs`).  Dense points:
    nearest first, in rounds of k-d tree queries (1, 4, 32, then all neighbours), so that points settled
    by their nearest pairs cost no more."""
    if active.size == 0 or len(b) == 0:
        return
    r2 = r * r

    def exact(i, j):
        dx, dy = a[i, 0] - b[j, 0], a[i, 1] - b[j, 1]
        close = dx * dx + dy * dy <= r2
        return i[close], j[close]

    aa = a[active]
    pairs = _cell_pairs(aa, b, r, CELL_PAIRS_PER_POINT * (len(aa) + len(b)))
    if pairs is not None:
        process(*exact(active[pairs[0]], pairs[1]))
        return
    tree = cKDTree(b, balanced_tree=False)
    bound = r * (1.0 + 1e-9)  # every exact pair is inside; the exact test decides
    todo, done = active, 0
    for k_nn in (1, 4, 32, len(b)):
        k_nn = min(k_nn, len(b))
        if todo.size == 0 or k_nn <= done:
            break
        d, idx = tree.query(a[todo], k=k_nn, distance_upper_bound=bound)
        d = d.reshape(todo.size, -1)[:, done:]
        idx = idx.reshape(todo.size, -1)[:, done:]
        found = np.isfinite(d)
        i_loc, col = np.nonzero(found)
        settled = process(*exact(todo[i_loc], idx[i_loc, col]))
        exhausted = ~found[:, -1]  # every neighbour within reach has been seen
        todo = todo[~settled[todo] & ~exhausted]
        done = k_nn


def _expand(groups: np.ndarray, n_groups: int, items_of: np.ndarray, sizes: np.ndarray, starts: np.ndarray):
    """For each entry ``g`` of ``groups``, every item ``items_of[starts[g] .. starts[g] + sizes[g] - 1]``:
    returns ``(entry, item)`` index arrays."""
    n = sizes[groups]
    total = int(n.sum())
    entry = np.repeat(np.arange(groups.size), n)
    offset = np.arange(total) - np.repeat(np.cumsum(n) - n, n)
    return entry, items_of[starts[groups[entry]] + offset]


@dataclass
class _Step6:
    """What the support rules of one ping ``k`` need (private to :func:`_inverse`)."""

    cache: "_RunCache"
    grid: HoughGrid
    k: int
    earlier: list
    kept: dict
    lines: _Lines
    e: int
    reach: dict  # gap -> reach
    vel_gate: float | None
    sigma_pos: float
    dt: float
    require_chain: bool = False

    def rows_in(self, p: int, idx: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Rows of points ``idx`` of ping ``p`` in columns ``cols`` (same shape as ``idx``)."""
        return self.cache.rows(p)[idx, cols]

    def used_rows(self, p: int, idx: np.ndarray) -> np.ndarray:
        """Rows of points ``idx`` of ping ``p`` in every column holding a line, ``(len(idx), J)``."""
        return self.cache.rows(p)[idx[:, None], self.lines.used[None, :]]

    def on_line(self, p: int, idx: np.ndarray, line: np.ndarray) -> np.ndarray:
        rows = self.rows_in(p, idx, self.lines.cols[line])
        return np.abs(rows - self.lines.rows[line]) <= self.e

    def triples(self, zi: np.ndarray, p: int, si: np.ndarray, chunk: int = 4096):
        """(pair, line) for pairs (detection ``zi`` of ping k, point ``si`` of ping ``p``): the lines within
        ``e`` rows of both."""
        out_p, out_l = [], []
        for start in range(0, zi.size, chunk):
            stop = min(start + chunk, zi.size)
            pair, line = _lines_near(self.used_rows(self.k, zi[start:stop]), self.used_rows(p, si[start:stop]),
                                     self.lines, self.e)
            out_p.append(pair + start)
            out_l.append(line)
        if not out_p:
            e_ = np.zeros(0, dtype=np.intp)
            return e_, e_
        return np.concatenate(out_p), np.concatenate(out_l)

    def velocity_ok(self, z_t: np.ndarray, p: int, s_t: np.ndarray, line_t: np.ndarray) -> np.ndarray:
        """The velocity-consistency check of triples (detection ``z_t`` of ping k, support ``s_t`` of ping
        ``p``, line ``line_t``): the step support -> detection against the step from the support's latest
        local support on the same line (the most recent earlier ping of B with a gated point on the line
        within reach of the support); where the support has none, passes (nothing to compare) or, with
        ``require_chain``, fails.  ``(Q,) -> (Q,)`` bool."""
        Q = z_t.size
        if Q == 0 or (self.vel_gate is None and not self.require_chain):
            return np.ones(Q, dtype=bool)
        L = self.lines.size
        combo_key, t_combo = np.unique(s_t * L + line_t, return_inverse=True)
        c_s, c_line = np.divmod(combo_key, L)
        C = combo_key.size
        resolved = np.zeros(C, dtype=bool)
        ok = np.zeros(Q, dtype=bool)
        pts_k, pts_p = self.cache.pts[self.k], self.cache.pts[p]
        for q in [q for q in reversed(self.earlier) if q < p]:
            open_c = np.flatnonzero(~resolved)
            pred = np.flatnonzero(self.kept[q])
            if open_c.size == 0:
                break
            if pred.size == 0:
                continue
            # the supports of the open combinations, and their pairs with the gated points of ping q
            us, us_of = np.unique(c_s[open_c], return_inverse=True)
            by_s = open_c[np.argsort(us_of, kind="stable")]
            n_of = np.bincount(us_of, minlength=us.size)
            start_of = np.cumsum(n_of) - n_of
            found = {"s": [], "j": []}

            def collect(i, j):
                found["s"].append(i)
                found["j"].append(j)
                return np.zeros(us.size, dtype=bool)

            _near_pairs(pts_p[us], np.arange(us.size), self.cache.pts[q][pred], self.reach[p - q], collect)
            if not found["s"]:
                continue
            i, j = np.concatenate(found["s"]), np.concatenate(found["j"])
            entry, combo = _expand(i, us.size, by_s, n_of, start_of)
            cand = pred[j[entry]]
            on = self.on_line(q, cand, c_line[combo])
            combo, cand = combo[on], cand[on]
            if combo.size == 0:
                continue
            resolved[combo] = True  # ping q holds their latest local support
            # every (triple, candidate) of the combinations resolved here
            order = np.argsort(combo, kind="stable")
            combo, cand = combo[order], cand[order]
            n_cand = np.bincount(combo, minlength=C)
            c_start = np.cumsum(n_cand) - n_cand
            got = np.zeros(C, dtype=bool)
            got[combo] = True
            t_here = np.flatnonzero(got[t_combo])
            t_entry, s2 = _expand(t_combo[t_here], C, cand, n_cand, c_start)
            t = t_here[t_entry]
            g2, g1 = (self.k - p) * self.dt, (p - q) * self.dt
            z_xy, s_xy, w_xy = pts_k[z_t[t]], pts_p[s_t[t]], self.cache.pts[q][s2]
            # u = (z - s) / g2, u' = (s - s') / g1;  var(u - u') = sigma^2 (1/g2^2 + (1/g2 + 1/g1)^2 + 1/g1^2)
            ux, uy = (z_xy[:, 0] - s_xy[:, 0]) / g2, (z_xy[:, 1] - s_xy[:, 1]) / g2
            wx, wy = (s_xy[:, 0] - w_xy[:, 0]) / g1, (s_xy[:, 1] - w_xy[:, 1]) / g1
            both = 1.0 / g2 + 1.0 / g1
            var = self.sigma_pos * self.sigma_pos * (1.0 / (g2 * g2) + both * both + 1.0 / (g1 * g1))
            dx, dy = ux - wx, uy - wy
            ok[t if self.vel_gate is None else t[dx * dx + dy * dy <= self.vel_gate * var]] = True
        if not self.require_chain:
            ok[~resolved[t_combo]] = True  # no earlier local support: nothing to compare
        return ok


def _inverse(cache: _RunCache, grid: HoughGrid, k: int, group_b: range, kept: dict, counts: dict,
             sim_flat: np.ndarray, eps: float, reach: dict, support: str, vel_gate: float | None,
             sigma_pos: float, dt: float, require_chain: bool = False, backend: str = "numpy") -> np.ndarray:
    """Keep mask over the valid detections of ping ``k`` (step 6).

    ``sim_flat``: the similar line cells (flat indices).  ``reach[g]``: the distance allowed between a
    detection and a support ``g`` pings older.  Triples (detection ``z``, support ``s``, line ``L``) with
    ``z`` and ``s`` within ``e`` rows of ``L`` and within reach of each other are enumerated earlier ping by
    earlier ping, the most recent first (pairs from :func:`_near_pairs`, lines from :func:`_lines_near`);
    a detection leaves the search once kept.  ``support``:

    - ``"local"``: ``(z, L)`` is decided at the first (most recent) ping holding such a triple (its latest
      local support); later pings' triples of a decided ``(z, L)`` are ignored.  Kept when one of its
      triples at that ping passes :meth:`_Step6.velocity_ok`.
    - ``"latest"``: kept when ``s`` is of the latest earlier ping with a gated point anywhere on ``L``.
    - ``"any"``: kept on any triple.
    """
    n_k = len(cache.pts[k])
    keep = np.zeros(n_k, dtype=bool)
    earlier = [p for p in group_b if p < k]
    if n_k == 0 or sim_flat.size == 0 or not earlier:
        return keep
    e = int(np.floor(eps / grid.d_rho + 1e-9))
    for p in group_b:
        cache.rows(p)  # in the ring
    if support == "local" and backend == "numba" and 2 * e + 1 < 64:
        return _local_numba(cache, grid, k, earlier, kept, sim_flat, e, reach, vel_gate, sigma_pos, dt,
                            require_chain)
    lines = _lines(sim_flat, grid)
    step = _Step6(cache, grid, k, earlier, kept, lines, e, reach, vel_gate, sigma_pos, dt, require_chain)
    # detections within e rows of some line at all
    todo = np.arange(n_k)
    near = np.zeros(n_k, dtype=bool)
    for start in range(0, n_k, 4096):
        idx = todo[start:start + 4096]
        r = step.used_rows(k, idx)
        pair, _ = _lines_near(r, r, lines, e)
        near[idx[pair]] = True
    todo = np.flatnonzero(near)
    if support == "latest":
        # the latest earlier ping of B with a gated point within e rows of each line cell, as p - k (< 0;
        # the int16 minimum where there is none)
        latest_map = np.full((grid.n_rho, lines.used.size), np.iinfo(np.int16).min, dtype=np.int16)
        for p in earlier:
            c = counts[p].reshape(grid.shape)[:, lines.used] > 0
            latest_map[c] = p - k  # negative gaps; later pings overwrite
        latest_map = _max_rows(latest_map, e)
        col_slot = np.searchsorted(lines.used, lines.cols)
        line_latest = latest_map[lines.rows, col_slot].astype(np.intp) + k
    decided = np.zeros(0, dtype=np.int64)  # "local": keys z * L + line decided at a more recent ping
    L = max(lines.size, 1)
    for p in reversed(earlier):
        if todo.size == 0:
            break
        sup = np.flatnonzero(kept[p])
        if sup.size == 0:
            continue
        seen = []

        def process(zi, si, p=p, sup=sup, seen=seen):
            pair, line = step.triples(zi, p, sup[si])
            z_t, s_t = zi[pair], sup[si[pair]]
            if support == "any":
                keep[z_t] = True
            elif support == "latest":
                keep[z_t[line_latest[line] == p]] = True
            else:
                key = z_t.astype(np.int64) * L + line
                seen.append(key)
                fresh = ~_in_sorted(key, decided)
                z_t, s_t, line = z_t[fresh], s_t[fresh], line[fresh]
                # in chunks, each detection's first triples first, so that kept detections cost no more
                order = np.argsort(z_t, kind="stable")
                z_t, s_t, line = z_t[order], s_t[order], line[order]
                first = np.searchsorted(z_t, z_t)
                rank_order = np.lexsort((z_t, np.arange(z_t.size) - first))
                z_t, s_t, line = z_t[rank_order], s_t[rank_order], line[rank_order]
                for start in range(0, z_t.size, 16384):
                    sl = slice(start, start + 16384)
                    live = ~keep[z_t[sl]]
                    if not live.any():
                        continue
                    zz, ss, ll = z_t[sl][live], s_t[sl][live], line[sl][live]
                    keep[zz[step.velocity_ok(zz, p, ss, ll)]] = True
            return keep

        _near_pairs(cache.pts[k], todo, cache.pts[p][sup], reach[k - p], process)
        if support == "local" and seen:
            decided = _sorted_unique(np.concatenate([decided] + seen))
        todo = todo[~keep[todo]]
    return keep


def _local_numba(cache: _RunCache, grid: HoughGrid, k: int, earlier: list, kept: dict, sim_flat: np.ndarray, e: int,
                 reach: dict, vel_gate, sigma_pos: float, dt: float, require_chain: bool) -> np.ndarray:
    """The ``"local"`` rule of :func:`_inverse` by :func:`workbench_clutter.hough_numba.local_keep` (same
    decisions; the arrays it needs are built here)."""
    from . import hough_numba

    n_k = len(cache.pts[k])
    rows, cols = np.divmod(np.asarray(sim_flat, dtype=np.intp), grid.n_theta)
    used = np.flatnonzero(np.bincount(cols, minlength=grid.n_theta))
    col_slot = np.full(grid.n_theta, -1, dtype=np.intp)
    col_slot[used] = np.arange(used.size)
    # one bit per row of each used column: a similar line cell there (one spare word, see hough_numba)
    bits = hough_numba.line_bits(rows.astype(np.int64), col_slot[cols].astype(np.int64), used.size,
                                 grid.n_rho // 64 + 2)
    # a grid of square cells of side h >= the smallest reach (doubled while it would hold more cells than
    # 8 per point); a point within reach r lies within ceil(r / h) cells (h carries a 2^-20 margin over the
    # reaches, all multiples of the smallest, so that the rounding of (x - x0) / h cannot add a cell)
    parts = [cache.pts[k]] + [cache.pts[p][kept[p]] for p in earlier]
    n_all = sum(len(a) for a in parts)
    lo = np.array([min(float(a[:, c].min()) for a in parts if len(a)) for c in (0, 1)])
    hi = np.array([max(float(a[:, c].max()) for a in parts if len(a)) for c in (0, 1)])
    h = min(reach.values()) * (1.0 + 2.0 ** -20)
    while (np.floor((hi[0] - lo[0]) / h) + 1) * (np.floor((hi[1] - lo[1]) / h) + 1) > 8 * n_all + 1024:
        h *= 2.0
    nx = int(np.floor((hi[0] - lo[0]) / h)) + 1
    ny = int(np.floor((hi[1] - lo[1]) / h)) + 1
    xy, ring_slot, idx, starts = [], [], [], []
    offset = 0
    for p in earlier:
        sel = np.flatnonzero(kept[p])
        pts = cache.pts[p][sel]
        cell = np.minimum(np.floor((pts - lo) / h).astype(np.int64), [nx - 1, ny - 1])
        kk = cell[:, 0] * ny + cell[:, 1]
        order = np.argsort(kk, kind="stable")
        xy.append(pts[order])
        idx.append(sel[order])
        ring_slot.append(np.full(sel.size, p % cache.ring.shape[0], dtype=np.int64))
        starts.append(offset + np.concatenate([[0], np.cumsum(np.bincount(kk, minlength=nx * ny))]))
        offset += sel.size
    reach_arr = np.zeros(max(reach) + 1)
    for g, r in reach.items():
        reach_arr[g] = r
    return hough_numba.local_keep(
        np.ascontiguousarray(cache.pts[k], dtype=float), cache.rows(k), np.arange(n_k, dtype=np.int64),
        np.concatenate(xy).reshape(-1, 2), np.concatenate(ring_slot), np.concatenate(idx).astype(np.int64),
        np.stack(starts).astype(np.int64), np.array(earlier, dtype=np.int64), k, bits, grid.n_rho,
        col_slot.astype(np.int64), cache.ring, e,
        reach_arr, float(lo[0]), float(lo[1]), float(h), nx, ny, -1.0 if vel_gate is None else float(vel_gate),
        float(sigma_pos), float(dt), bool(require_chain), cache.stamp_buffer(grid), cache.next_tag(n_k),
        hough_numba.CTZ, float(grid.d_rho), float(grid.d_theta))


def _project(cache: _RunCache, grid: HoughGrid, k: int, idx: np.ndarray, sim_flat: np.ndarray, eps: float):
    """New positions of detections ``idx`` of ping ``k``: each projected onto the nearest similar line within
    ``e`` rows (ties: lowest column, then lowest rho bin)::

        d = x cos(theta) + y sin(theta) - rho,     (x, y) <- (x - d cos(theta), y - d sin(theta))

    ``(len(idx),) -> (len(idx), 2)``.
    """
    pts = cache.pts[k][idx]
    if idx.size == 0:
        return pts.copy()
    e = int(np.floor(eps / grid.d_rho + 1e-9))
    lines = _lines(sim_flat, grid)
    rows = cache.rows(k)[idx[:, None], lines.used[None, :]]
    which, line = _lines_near(rows, rows, lines, e)
    cos, sin = np.cos(grid.theta), np.sin(grid.theta)
    c, s = cos[lines.cols[line]], sin[lines.cols[line]]
    bins = lines.rows[line] - grid.off
    x, y = pts[which, 0], pts[which, 1]
    d = x * c + y * s - bins * grid.d_rho
    best = np.lexsort((bins, lines.cols[line], np.abs(d), which))
    first = best[np.searchsorted(which[best], np.arange(idx.size))]
    out = pts.copy()
    out[:, 0] = x[first] - d[first] * c[first]
    out[:, 1] = y[first] - d[first] * s[first]
    return out


def support_reaches(window: int, v_max: float, dt: float, support: str, support_reach) -> dict:
    """The reach of every ping gap ``g = 1 .. window - 1``: ``v_max dt max(g, 2)`` (the default of the
    ``"local"`` rule: the largest travel in ``g`` pings, at least two), ``2 v_max dt`` (the default of
    ``"latest"`` and ``"any"``), or ``support_reach`` when given."""
    out = {}
    for g in range(1, window):
        if support_reach is None and support == "local":
            out[g] = v_max * dt * max(g, 2)
        elif support_reach is None:
            out[g] = 2.0 * v_max * dt
        else:
            out[g] = float(support_reach)
    return out


def hough_remove_run(z: np.ndarray, valid: np.ndarray, grid: HoughGrid, window: int = 5, shift: int = 1,
                     v_max: float = 8.0, dt: float = 1.0, gate_gap: int = 2, v_min: int = 3, sim_rho: float = 3.0,
                     sim_theta_deg: float = 3.0, eps: float = 4.0, support_reach=None, support: str = "local",
                     vel_gate: float | None = 9.21, sigma_pos: float = 2.0, require_chain: bool = False,
                     new_measurements: str = "detections", warmup: str = "drop", trace: list | None = None,
                     run: int = 0, backend: str = "numpy"):
    """The keep mask and output positions of one run: ``z (T, M, 2)``, ``valid (T, M)`` -> ``(T, M)`` bool,
    ``(T, M, 2)``."""
    T = z.shape[0]
    sr = int(np.floor(sim_rho / grid.d_rho + 1e-9))
    st = int(np.floor(np.deg2rad(sim_theta_deg) / grid.d_theta + 1e-9))
    slots = [np.flatnonzero(valid[k]) for k in range(T)]
    pts = [z[k][s] for k, s in enumerate(slots)]
    most = max([len(s) for s in slots] + [1])
    cache = _RunCache(pts=pts, grid=grid, slots=slots, count_dtype=np.min_scalar_type(most),
                      ring=np.empty((window, most, grid.n_theta), dtype=np.int32), ring_ping=[-1] * window,
                      kernel=backend)
    vote_dtype, support_dtype = np.min_scalar_type(window * most), np.min_scalar_type(window)
    out = np.zeros(valid.shape, dtype=bool)
    out_z = np.array(z, dtype=float, copy=True)
    first_output = window - 1 + shift
    reach = support_reaches(window, v_max, dt, support, support_reach)
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
            if backend == "numba":
                from . import hough_numba

                hough_numba.accumulate(n_pings, votes, counts[p])
            else:
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
        keep = _inverse(cache, grid, k, group_b, kept, counts, fb[sim], eps, reach, support, vel_gate, sigma_pos,
                        dt, require_chain, backend)
        out[k, slots[k][keep]] = True
        if new_measurements == "projected":
            idx = np.flatnonzero(keep)
            out_z[k, slots[k][idx]] = _project(cache, grid, k, idx, fb[sim], eps)
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
    return out, out_z


SUPPORTS = ("local", "latest", "any")
#: The whole-run kernel (``hough_numba.remove_run``) votes every point of the group afresh at each ping into
#: cell-indexed arrays; above this many detections in a ping of the batch the per-ping path's incremental counts and
#: grid passes are faster (10^4 detections per ping over a wide area: about 3x), so it takes those scans.  Both
#: paths decide alike; this only picks the faster.
RUN_KERNEL_MAX_DETECTIONS = 2000
BACKENDS = ("auto", "numba", "numpy")
NEW_MEASUREMENTS = ("detections", "projected")


def remove(scans: Scans, window: int = 5, shift: int = 1, v_max: float = 8.0, dt: float = 1.0, gate_gap: int = 2,
           d_rho: float = 1.0, d_theta_deg: float = 1.0, v_min: int = 3, sim_rho: float = 3.0,
           sim_theta_deg: float = 3.0, eps: float = 4.0, support_reach=None, support: str = "local",
           vel_gate: float | None = 9.21, sigma_pos: float = 2.0, require_chain: bool = False,
           new_measurements: str = "detections", warmup: str = "drop", backend: str = "auto",
           trace: list | None = None) -> Scans:
    """Hough clutter removal of every run of ``scans`` (Cartesian ``z (B, T, M, 2)``); see the module docstring.

    Returns the scans with a narrower ``valid`` mask; with ``new_measurements="projected"`` the kept
    detections are also moved onto their line (``z`` changes there, nowhere else).
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
    if support not in SUPPORTS:
        raise InputError(f"hough: support must be one of {SUPPORTS}, got {support!r}")
    if new_measurements not in NEW_MEASUREMENTS:
        raise InputError(f"hough: new_measurements must be one of {NEW_MEASUREMENTS}, got {new_measurements!r}")
    if support_reach is not None and not (isinstance(support_reach, (int, float)) and support_reach > 0):
        raise InputError(f"hough: support_reach must be None or a number > 0, got {support_reach!r}")
    if vel_gate is not None and not vel_gate > 0 or not sigma_pos > 0:
        raise InputError(f"hough: need vel_gate None or > 0 and sigma_pos > 0, got {vel_gate}, {sigma_pos}")
    if warmup not in ("drop", "keep"):
        raise InputError(f"hough: warmup must be 'drop' or 'keep', got {warmup!r}")
    if require_chain and support != "local":
        raise InputError("hough: require_chain applies to the local support rule only (support='local')")
    if backend not in BACKENDS:
        raise InputError(f"hough: backend must be one of {BACKENDS}, got {backend!r}")
    try:  # the backend policy's choice (workbench.kernels.backend), on the CPU where this code runs
        compiled = runs_numba(backend, "cpu")
    except ValueError as exc:
        raise InputError(f"hough: {exc}") from None
    kernel = "numba" if compiled and (backend == "numba" or window <= 64) else "numpy"
    if kernel == "numba" and window > 64:
        raise InputError(f"hough: the numba kernel takes window <= 64, got {window}; use backend='numpy'")
    valid = scans.valid
    # The grid only has to cover every point; its extent never changes a decision.
    extent = float(np.max(np.linalg.norm(scans.z[valid], axis=-1))) if valid.any() else 1.0
    grid = make_grid(d_rho, d_theta_deg, extent)
    keep = np.zeros(valid.shape, dtype=bool)
    new_z = np.array(scans.z, copy=True) if new_measurements == "projected" else None
    sr = int(np.floor(sim_rho / grid.d_rho + 1e-9))
    st = int(np.floor(np.deg2rad(sim_theta_deg) / grid.d_theta + 1e-9))
    e = int(np.floor(eps / grid.d_rho + 1e-9))
    most = int(valid.sum(axis=2).max()) if valid.size else 0
    if kernel == "numba" and trace is None and st < grid.n_theta and (support != "local" or 2 * e + 1 < 64) \
            and most <= RUN_KERNEL_MAX_DETECTIONS:
        # every ping of a run in one compiled call (hough_numba.remove_run: the same decisions)
        from . import hough_numba

        reach_arr = np.zeros(int(window))
        for g, r in support_reaches(int(window), v_max, dt, support, support_reach).items():
            reach_arr[g] = r
        th = grid.theta
        cos, sin = np.cos(th), np.sin(th)
        z_all = np.ascontiguousarray(scans.z, dtype=float)
        project = new_measurements == "projected"
        for b in range(scans.batch):
            keep[b], z_b = hough_numba.remove_run(
                z_all[b], np.ascontiguousarray(valid[b]), int(window), int(shift), float(v_max * dt), int(gate_gap),
                int(v_min), sr, st, e, reach_arr, SUPPORTS.index(support),
                -1.0 if vel_gate is None else float(vel_gate), float(sigma_pos), float(dt), bool(require_chain),
                warmup == "keep", project, grid.n_rho, grid.n_theta, int(grid.off), float(grid.d_rho),
                float(grid.d_theta), cos, sin, hough_numba.CTZ)
            if new_z is not None:
                new_z[b] = z_b
        out = scans.with_valid(keep)
        return dataclasses.replace(out, z=np.where(out.valid[..., None], new_z, out.z)) if project else out
    for b in range(scans.batch):
        keep[b], z_b = hough_remove_run(scans.z[b], valid[b], grid, window, shift, v_max, dt, gate_gap, v_min,
                                        sim_rho, sim_theta_deg, eps, support_reach, support, vel_gate, sigma_pos,
                                        require_chain, new_measurements, warmup, trace, b, kernel)
        if new_z is not None:
            new_z[b] = z_b
    out = scans.with_valid(keep)
    if new_z is not None:
        out = dataclasses.replace(out, z=np.where(out.valid[..., None], new_z, out.z))
    return out


PARAMETERS = (
    Param("window", 5, "pings per group W (groups A and B, shifted by s pings)", "int", unit="dimensionless", minimum=2,
          maximum=10**4),
    Param("shift", 1, "shift s between groups A and B (pings)", "int", unit="dimensionless", minimum=1, maximum=10**4),
    Param("v_max", 8.0, "largest target speed (v_max dt is the gate between pings)", unit="speed", above=0.0),
    Param("dt", 1.0, "ping period", unit="time", above=0.0),
    Param("gate_gap", 2, "a detection votes when another ping within this many pings lies within the gate", "int",
          unit="dimensionless", minimum=1, maximum=10**4),
    Param("d_rho", 1.0, "accumulator rho bin", unit="length", above=0.0),
    Param("d_theta_deg", 1.0, "accumulator theta bin, in degrees", unit="angle_deg", above=0.0, maximum=180.0),
    Param("v_min", 3, "distinct pings a line needs to be a peak", "int", unit="dimensionless", minimum=1,
          maximum=10**4),
    Param("sim_rho", 3.0, "rho tolerance of similar lines (A and B)", unit="length", minimum=0.0),
    Param("sim_theta_deg", 3.0, "theta tolerance of similar lines, in degrees", unit="angle_deg", minimum=0.0,
          maximum=180.0),
    Param("eps", 4.0, "distance from a similar line within which a detection is kept", unit="length", minimum=0.0),
    Param("support", "local", "which supports of the line keep a detection: the latest near it with a consistent "
          "velocity (local), the latest anywhere on the line (latest), or any (any)", "str", choices=SUPPORTS),
    Param("support_reach", None, "distance from a support within which a detection is kept (none: v_max dt "
          "max(gap, 2) for local, 2 v_max dt otherwise)", "float?", unit="length", above=0.0),
    Param("vel_gate", 9.21, "chi-square (2 dof) bound of the velocity-consistency check of the local rule (none: no "
          "check)", "float?", unit="gate", above=0.0),
    Param("sigma_pos", 2.0, "position accuracy of a detection per axis, for the velocity-consistency check",
          unit="length", above=0.0),
    Param("require_chain", False, "the local rule keeps a detection only when its support has an earlier local "
          "support of its own (a three-point chain) to check the velocity against", "bool"),
    Param("new_measurements", "detections", "what the tracker gets: the kept detections (the paper's extracted "
          "measurements) or their projections onto the nearest similar line", "str", choices=NEW_MEASUREMENTS),
    Param("warmup", "drop", "pings before group A is full: no output (drop) or every detection (keep)", "str",
          choices=("drop", "keep")),
    Param("backend", "auto", "the local rule's implementation: Numba where installed (auto), or the NumPy twin; the "
          "decisions are the same", "str", choices=BACKENDS),
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
