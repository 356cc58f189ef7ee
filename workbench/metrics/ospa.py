"""OSPA and GOSPA: distances between a set of estimated positions and a set of true positions.

Both compare two finite sets ``X = {x_1..x_m}`` (estimates) and ``Y = {y_1..y_n}`` (truths) of any sizes,
including empty ones, with a cut-off ``c > 0`` and an order ``1 <= p < inf``.  With the cut-off distance
``d_c(x, y) = min(|x - y|, c)`` (Euclidean) and, for ``m <= n``, ``pi`` ranging over the injections of
``{1..m}`` into ``{1..n}`` (swap the roles for ``m > n``):

OSPA (Schuhmacher, Vo and Vo, IEEE Trans. Signal Processing 56(8), 2008)::

    d_OSPA(X, Y)^p = (1 / n) (min_pi sum_i d_c(x_i, y_pi(i))^p + c^p (n - m))        (0 when m = n = 0)
                   = e_loc^p + e_card^p
    e_loc^p  = (1 / n) min_pi sum_i d_c(x_i, y_pi(i))^p                              (localisation)
    e_card^p = (1 / n) c^p (n - m)                                                     (cardinality)

GOSPA with alpha = 2 (Rahmathullah, Garcia-Fernandez and Svensson, FUSION 2017)::

    d_GOSPA(X, Y)^p = min_pi sum_i d_c(x_i, y_pi(i))^p + (c^p / 2) (n - m)
                    = localisation + missed + false
    localisation = sum of |x - y|^p over the assigned pairs with |x - y| < c
    missed       = (c^p / 2) * (truths in no such pair)
    false        = (c^p / 2) * (estimates in no such pair)

(an assigned pair at ``d >= c`` costs ``c^p``, exactly one missed truth plus one false estimate, so it is counted
as both).  GOSPA with ``alpha = 2`` is not normalised by the set size, so it grows with the number of targets and
penalises a missed target and a false track by ``c^p / 2`` each; OSPA is a mean per point of the larger set.

Both minimisations are the same linear assignment of the cost ``d_c^p``, solved by
:func:`scipy.optimize.linear_sum_assignment`.  The functions are batch-first: the sets of every (run, time) item
are padded to a common size with a validity mask (as :class:`~workbench.types.Scans` pads detections), the
distances and all items with at most one point on either side are computed for the whole batch at once, and the
assignment is solved item by item only where both sets hold two or more points (SciPy has no batched solver).

:func:`track_ospa` and :func:`track_gospa` score a :class:`~workbench.tracking.TrackLog` (its confirmed tracks per
run and ping, positions = the first two state components) against the true positions.  Stone Soup's
``GOSPAMetric`` (switching penalty 0) and ``OSPAMetric`` compute the same quantities; the tests compare the two.
Stone Soup's ``OSPAMetric`` solves its assignment on ``d_c`` rather than ``d_c^p``, which for ``p > 1`` can miss
the minimum; here the cost is always ``d_c^p``, as the definition says.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracking.multi import CONFIRMED, TrackLog
from ..types import InputError, Truth, real_scalar

__all__ = ["OSPA", "GOSPA", "ospa", "gospa", "track_positions", "truth_positions", "track_ospa", "track_gospa"]


@dataclass(frozen=True)
class OSPA:
    """OSPA distances and their decomposition, one value per item of the batch.

    ``distance ** p == localisation ** p + cardinality ** p``.

    Shapes
    ------
    distance, localisation, cardinality : (...) (the batch shape of the sets compared)
    """

    distance: np.ndarray
    localisation: np.ndarray
    cardinality: np.ndarray
    c: float
    p: float


@dataclass(frozen=True)
class GOSPA:
    """GOSPA (``alpha = 2``) distances and their decomposition, one value per item of the batch.

    ``distance ** p == localisation + missed + false``: the three terms are in units of distance to the power
    ``p`` (as Stone Soup's ``GOSPAMetric`` reports them); ``missed == c ** p / 2 * n_missed`` and
    ``false == c ** p / 2 * n_false``.

    Shapes
    ------
    distance, localisation, missed, false : (...) float
    assigned, n_missed, n_false : (...) int (pairs closer than ``c``; truths and estimates in no such pair)
    """

    distance: np.ndarray
    localisation: np.ndarray
    missed: np.ndarray
    false: np.ndarray
    assigned: np.ndarray
    n_missed: np.ndarray
    n_false: np.ndarray
    c: float
    p: float


#: ``c^p`` (and the sums of up to 1e8 such terms) must stay inside the float range: ``|p log10 c| <= POWER_DECADES``.
POWER_DECADES = 290.0


def _check_order(c: float, p: float) -> tuple[float, float]:
    c, p = real_scalar("the cut-off c", c), real_scalar("the order p", p)
    if not (np.isfinite(c) and c > 0):
        raise InputError(f"the cut-off c must be a finite number > 0, got {c}")
    if not (np.isfinite(p) and p >= 1):
        raise InputError(f"the order p must be a finite number >= 1, got {p}")
    decades = p * abs(np.log10(c))
    if decades > POWER_DECADES:
        largest = POWER_DECADES / abs(np.log10(c))
        raise InputError(f"the order p = {p:g} with the cut-off c = {c:g} puts c^p = 10^{p * np.log10(c):.0f} "
                         f"outside the float range (|p log10 c| <= {POWER_DECADES:g}): use p <= {largest:.4g}, or "
                         f"state the positions in units that make c nearer 1")
    return c, p


def _sets(name: str, points, valid) -> tuple[np.ndarray, np.ndarray]:
    points = np.asarray(points, dtype=float)
    if points.ndim < 2:
        raise InputError(f"{name} must have shape (..., count, dims), got {points.shape}")
    if valid is None:
        valid = np.ones(points.shape[:-1], dtype=bool)
    valid = np.asarray(valid, dtype=bool)
    if valid.shape != points.shape[:-1]:
        raise InputError(f"{name}: the mask must have shape {points.shape[:-1]}, got {valid.shape}")
    if not np.all(np.isfinite(points[valid])):
        raise InputError(f"{name} holds a non-finite position in a valid entry")
    return points, valid


def _assignment(x, y, x_valid, y_valid, c: float, p: float):
    """The optimal assignment of the cost ``min(|x - y|, c)^p`` for every item.

    Returns ``cost`` (the minimal sum over the assigned pairs), ``real`` (pairs closer than ``c``), ``loc`` (the
    sum of ``|x - y|^p`` over those), ``m`` and ``n`` (the set sizes), each of the batch shape.
    """
    x, x_valid = _sets("the estimated positions", x, x_valid)
    y, y_valid = _sets("the true positions", y, y_valid)
    if x.shape[-1] != y.shape[-1]:
        raise InputError(f"estimated positions have {x.shape[-1]} components but true positions {y.shape[-1]}")
    try:
        batch = np.broadcast_shapes(x.shape[:-2], y.shape[:-2])
    except ValueError:
        raise InputError(f"the batch shapes of the estimates {x.shape[:-2]} and the truths {y.shape[:-2]} do not "
                         f"match") from None
    M, N, d = x.shape[-2], y.shape[-2], x.shape[-1]
    L = int(np.prod(batch, dtype=np.int64))
    x = np.broadcast_to(x, batch + (M, d)).reshape(L, M, d)
    y = np.broadcast_to(y, batch + (N, d)).reshape(L, N, d)
    xv = np.broadcast_to(x_valid, batch + (M,)).reshape(L, M)
    yv = np.broadcast_to(y_valid, batch + (N,)).reshape(L, N)
    m, n = xv.sum(axis=1), yv.sum(axis=1)
    cost, loc = np.zeros(L), np.zeros(L)
    real = np.zeros(L, dtype=np.int64)
    if M and N and L:
        # D_ij = |x_i - y_j|, cut off at c:  C_ij = min(D_ij, c)^p
        dist = np.sqrt(np.sum((x[:, :, None, :] - y[:, None, :, :]) ** 2, axis=-1))
        pair = xv[:, :, None] & yv[:, None, :]
        close = pair & (dist < c)
        dist_p = np.where(close, dist, 0.0) ** p
        lost = close & (dist > 0) & (dist_p == 0)  # |x - y|^p underflowed: the localisation would read as 0
        if np.any(lost):
            d_min = float(dist[lost].min())
            raise InputError(f"the order p = {p:g} underflows |x - y|^p to 0 for a distance of {d_min:.3g} (cut-off "
                             f"c = {c:g}); use a smaller p, or state the positions in other units")
        C = np.where(close, dist_p, c ** p)
        # one point on either side: the optimal injection takes the cheapest valid pair
        one = np.minimum(m, n) == 1
        if np.any(one):
            flat = np.where(pair[one], C[one], np.inf).reshape(int(one.sum()), -1)
            best = np.argmin(flat, axis=1)
            rows = np.arange(best.size)
            cost[one] = flat[rows, best]
            hit = close[one].reshape(best.size, -1)[rows, best]
            real[one] = hit
            loc[one] = np.where(hit, dist_p[one].reshape(best.size, -1)[rows, best], 0.0)
        for i in np.flatnonzero(np.minimum(m, n) >= 2):  # no batched assignment solver: one item at a time
            r_idx, c_idx = np.flatnonzero(xv[i]), np.flatnonzero(yv[i])
            sub = C[i][np.ix_(r_idx, c_idx)]
            rows, cols = _linear_sum_assignment()(sub)
            cost[i] = sub[rows, cols].sum()
            hit = close[i][r_idx[rows], c_idx[cols]]
            real[i] = int(hit.sum())
            loc[i] = dist_p[i][r_idx[rows], c_idx[cols]][hit].sum()
    shape = lambda a: a.reshape(batch)  # noqa: E731
    return shape(cost), shape(real), shape(loc), shape(m), shape(n)


def ospa(x, y, c: float, p: float = 1.0, *, x_valid=None, y_valid=None) -> OSPA:
    """The OSPA distance of order ``p`` with cut-off ``c`` between estimated and true position sets.

    Parameters
    ----------
    x : array (..., M, d)
        Estimated positions, padded to ``M`` per item (``x_valid`` marks the real ones; all by default).
    y : array (..., N, d)
        True positions, padded to ``N`` per item (``y_valid``).
    c : float
        The cut-off distance, > 0 (a missing or extra point costs ``c``).
    p : float
        The order, ``1 <= p < inf``.
    x_valid, y_valid : bool arrays (..., M), (..., N), optional

    Returns
    -------
    OSPA
        ``distance``, ``localisation``, ``cardinality`` of the batch shape (the broadcast of the leading axes of
        ``x`` and ``y``); 0 where both sets are empty.
    """
    c, p = _check_order(c, p)
    cost, _, _, m, n = _assignment(x, y, x_valid, y_valid, c, p)
    big = np.maximum(m, n)
    scale = np.where(big > 0, 1.0 / np.maximum(big, 1), 0.0)
    # e_loc^p = (1/n) min sum d_c^p;  e_card^p = (1/n) c^p |n - m|;  d^p = e_loc^p + e_card^p
    loc_p = scale * cost
    card_p = scale * c ** p * np.abs(n - m)
    return OSPA(np.asarray((loc_p + card_p) ** (1.0 / p)), np.asarray(loc_p ** (1.0 / p)),
                np.asarray(card_p ** (1.0 / p)), c, p)


def gospa(x, y, c: float, p: float = 1.0, *, x_valid=None, y_valid=None) -> GOSPA:
    """The GOSPA distance (``alpha = 2``) of order ``p`` with cut-off ``c`` and its decomposition.

    Parameters
    ----------
    x : array (..., M, d)
        Estimated positions (``x_valid`` marks the real ones; all by default).
    y : array (..., N, d)
        True positions (``y_valid``).
    c : float
        The cut-off distance, > 0: a missed target or a false estimate costs ``c^p / 2``.
    p : float
        The order, ``1 <= p < inf``.
    x_valid, y_valid : bool arrays (..., M), (..., N), optional

    Returns
    -------
    GOSPA
        Every field of the batch shape; ``distance ** p == localisation + missed + false``.
    """
    c, p = _check_order(c, p)
    _, real, loc, m, n = _assignment(x, y, x_valid, y_valid, c, p)
    half = c ** p / 2.0
    n_missed, n_false = n - real, m - real
    # d^p = sum over real pairs |x - y|^p + c^p/2 (missed + false)
    missed, false = half * n_missed, half * n_false
    return GOSPA(np.asarray((loc + missed + false) ** (1.0 / p)), np.asarray(loc), np.asarray(missed),
                 np.asarray(false), np.asarray(real), np.asarray(n_missed), np.asarray(n_false), c, p)


# -- a tracker's log against the truth -----------------------------------------------------------------


def track_positions(log: TrackLog, confirmed_only: bool = True, dims: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The tracks of a :class:`~workbench.tracking.TrackLog` as padded position sets per run and ping.

    Returns ``positions (B, T, K, dims)`` (the first ``dims`` state components) and ``valid (B, T, K)``, ``K``
    being the largest number of (confirmed, with ``confirmed_only``) tracks at any (run, ping).
    """
    rows = log.select(log.status == CONFIRMED) if confirmed_only else log
    if rows.mean.ndim != 2 or rows.mean.shape[1] < dims:
        raise InputError(f"the track log's states have {rows.mean.shape[-1]} components; need {dims} positions")
    B, T = log.runs, log.pings
    cell = rows.run.astype(np.int64) * T + rows.ping.astype(np.int64)
    order = np.argsort(cell, kind="stable")
    cell = cell[order]
    counts = np.bincount(cell, minlength=B * T)
    K = int(counts.max(initial=0))
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(cell.size) - start[cell]  # the row's place among its (run, ping)'s tracks
    positions = np.zeros((B * T, K, dims))
    valid = np.zeros((B * T, K), dtype=bool)
    positions[cell, slot] = rows.mean[order, :dims]
    valid[cell, slot] = True
    return positions.reshape(B, T, K, dims), valid.reshape(B, T, K)


def truth_positions(truth, runs: int, pings: int, valid=None, dims: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """True positions as padded sets per run and ping.

    ``truth`` is a :class:`~workbench.types.Truth` or an array: ``(B, T, n)`` for one target per run (its first
    ``dims`` components are the position) or ``(B, T, N, n)`` for ``N`` targets, with ``valid (B, T, N)`` saying
    which exist at each ping.  Returns ``positions (B, T, N, dims)`` and ``valid (B, T, N)``.
    """
    states = truth.states if isinstance(truth, Truth) else np.asarray(truth, dtype=float)
    if states.ndim == 3:
        states = states[:, :, None, :]
    if states.ndim != 4 or states.shape[:2] != (runs, pings) or states.shape[3] < dims:
        raise InputError(f"true positions must have shape ({runs}, {pings}, >= {dims}) or ({runs}, {pings}, N, "
                         f">= {dims}), got {np.shape(truth.states if isinstance(truth, Truth) else truth)}")
    if valid is None:
        valid = np.ones(states.shape[:3], dtype=bool)
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim == 2:
        valid = valid[:, :, None]
    if valid.shape != states.shape[:3]:
        raise InputError(f"the truth mask must have shape {states.shape[:3]}, got {valid.shape}")
    return states[..., :dims], valid


def track_ospa(log: TrackLog, truth, c: float, p: float = 1.0, *, truth_valid=None, confirmed_only: bool = True,
               dims: int = 2) -> OSPA:
    """OSPA between a tracker's (confirmed) tracks and the truth at every run and ping, each field ``(B, T)``.

    ``truth`` as :func:`truth_positions` takes it; positions are the first ``dims`` (2) state components.
    """
    x, xv = track_positions(log, confirmed_only, dims)
    y, yv = truth_positions(truth, log.runs, log.pings, truth_valid, dims)
    return ospa(x, y, c, p, x_valid=xv, y_valid=yv)


def track_gospa(log: TrackLog, truth, c: float, p: float = 1.0, *, truth_valid=None, confirmed_only: bool = True,
                dims: int = 2) -> GOSPA:
    """GOSPA (``alpha = 2``) between a tracker's (confirmed) tracks and the truth at every run and ping, each field
    ``(B, T)``; see :func:`track_ospa`."""
    x, xv = track_positions(log, confirmed_only, dims)
    y, yv = truth_positions(truth, log.runs, log.pings, truth_valid, dims)
    return gospa(x, y, c, p, x_valid=xv, y_valid=yv)


def _linear_sum_assignment():
    """SciPy's ``linear_sum_assignment``, imported on first use (``scipy.optimize`` takes a second to import)."""
    from scipy.optimize import linear_sum_assignment

    return linear_sum_assignment
