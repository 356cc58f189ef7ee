"""Assignment for the multi-target trackers: which gated (track, detection) pair updates which track.

Both take the gated pairs as ``rows`` (tracks), ``cols`` (detections) and their costs (the squared Mahalanobis
distance ``d2``) and return the taken pairs, each track and each detection in at most one:

- :func:`greedy_assign`: nearest neighbour, the globally cheapest remaining pair first (the M-of-N tracker);
- :func:`gnn_assign`: global nearest neighbour, the one-to-one assignment of least total cost, a track left
  without a detection costing ``miss_cost`` (SciPy's ``linear_sum_assignment`` on each cluster of tracks that
  share detections).
"""

from __future__ import annotations

import numpy as np

from ..types import InputError

__all__ = ["greedy_assign", "gnn_assign", "assignment_cost"]


def greedy_assign(rows: np.ndarray, cols: np.ndarray, cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Greedy one-to-one assignment by smallest cost (ties broken by row, then column).

    Equivalent to repeatedly taking the globally cheapest remaining pair in the order (cost, row, column);
    computed in rounds in which every pair that is the first of both its row and its column in that order is
    taken at once.  A round costs ``O(pairs left)`` and sorts nothing: the cheapest cost of every row and
    column comes from ``np.minimum.at``, and among a row's (column's) pairs of equal cheapest cost the smallest
    column (row) is found the same way.  Returns the taken ``rows, cols``.
    """
    rows, cols, cost = np.asarray(rows), np.asarray(cols), np.asarray(cost, dtype=float)
    if rows.size == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e
    rows, cols = rows.astype(np.intp), cols.astype(np.intp)
    n_r, n_c = int(rows.max()) + 1, int(cols.max()) + 1
    taken_r, taken_c = np.zeros(n_r, dtype=bool), np.zeros(n_c, dtype=bool)
    best_r, best_c = np.empty(n_r), np.empty(n_c)
    first_r, first_c = np.empty(n_r, dtype=np.intp), np.empty(n_c, dtype=np.intp)
    live = np.arange(rows.size)
    out_r, out_c = [], []
    while live.size:
        r, c, x = rows[live], cols[live], cost[live]
        best_r.fill(np.inf)
        best_c.fill(np.inf)
        np.minimum.at(best_r, r, x)  # the cheapest remaining cost of each row and column
        np.minimum.at(best_c, c, x)
        at_r, at_c = x == best_r[r], x == best_c[c]
        # ties: the smallest column among a row's cheapest pairs, the smallest row among a column's
        first_r.fill(n_c)
        first_c.fill(n_r)
        np.minimum.at(first_r, r[at_r], c[at_r])
        np.minimum.at(first_c, c[at_c], r[at_c])
        mutual = at_r & at_c & (c == first_r[r]) & (r == first_c[c])
        tr, tc = r[mutual], c[mutual]
        out_r.append(tr)
        out_c.append(tc)
        taken_r[tr] = True
        taken_c[tc] = True
        live = live[~(taken_r[r] | taken_c[c])]
    return np.concatenate(out_r), np.concatenate(out_c)



def _clusters(r: np.ndarray, c: np.ndarray, n_r: int, n_c: int) -> np.ndarray:
    """The connected component of every pair in the bipartite graph of tracks ``r`` and detections ``c``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(r.size, dtype=np.int8), (r, n_r + c)), shape=(n_r + n_c, n_r + n_c))
    _, labels = connected_components(graph, directed=False)
    return labels[r]


def gnn_assign(rows: np.ndarray, cols: np.ndarray, cost: np.ndarray, miss_cost: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Global nearest neighbour: the one-to-one assignment of least total cost.

    Minimises ``sum(cost of the taken pairs) + miss_cost * (tracks of `rows` left without a detection)`` over
    every assignment that uses only the given pairs (a pair not given is outside the gate and cannot be taken),
    each track and each detection at most once.  Solved exactly by :func:`scipy.optimize.linear_sum_assignment`
    on every cluster of tracks linked through shared detections, the cost matrix of a cluster of ``k`` tracks and
    ``d`` detections being ``k x (d + k)``: the pair costs (``inf`` outside the gate) and one private
    "no detection" column per track at ``miss_cost``.  A cluster with one track or one detection takes its
    cheapest pair when that costs less than ``miss_cost`` (the same optimum, without the solver).  Returns the taken ``rows, cols`` (ordered by row).
    """
    from scipy.optimize import linear_sum_assignment

    rows, cols, cost = np.asarray(rows), np.asarray(cols), np.asarray(cost, dtype=float)
    e = np.zeros(0, dtype=np.intp)
    if rows.size == 0:
        return e, e
    if not np.isfinite(miss_cost) or not np.all(np.isfinite(cost)):
        raise InputError("gnn_assign: the pair costs and miss_cost must be finite")
    rows, cols = rows.astype(np.intp), cols.astype(np.intp)
    ur, r = np.unique(rows, return_inverse=True)
    uc, c = np.unique(cols, return_inverse=True)
    label = _clusters(r, c, ur.size, uc.size)
    n_l = int(label.max()) + 1
    # a cluster with one track or one detection: its cheapest pair, when cheaper than a miss (ties: the first pair
    # in the given order); every other cluster: linear_sum_assignment
    tracks = np.bincount(label[np.unique(r, return_index=True)[1]], minlength=n_l)
    dets = np.bincount(np.unique(np.stack([label, c]), axis=1)[0], minlength=n_l)
    simple = (tracks == 1) | (dets == 1)
    best = np.full(n_l, np.inf)
    np.minimum.at(best, label, cost)
    first = np.full(n_l, rows.size)
    at = np.flatnonzero(simple[label] & (cost == best[label]))
    np.minimum.at(first, label[at], at)
    pick = first[simple & (best < miss_cost)]
    out_r, out_c = [r[pick]], [c[pick]]
    hard = np.flatnonzero(~simple[label])
    order = hard[np.argsort(label[hard], kind="stable")]
    bounds = np.flatnonzero(np.diff(label[order])) + 1
    for group in np.split(order, bounds) if order.size else ():
        gr, ri = np.unique(r[group], return_inverse=True)
        gc, ci = np.unique(c[group], return_inverse=True)
        k, d = gr.size, gc.size
        matrix = np.full((k, d + k), np.inf)
        matrix[ri, ci] = cost[group]
        matrix[np.arange(k), d + np.arange(k)] = miss_cost  # each track's own "no detection"
        a_r, a_c = linear_sum_assignment(matrix)
        taken = a_c < d
        out_r.append(gr[a_r[taken]])
        out_c.append(gc[a_c[taken]])
    tr, tc = np.concatenate(out_r), np.concatenate(out_c)
    keep = np.argsort(tr, kind="stable")
    return ur[tr[keep]], uc[tc[keep]]


def assignment_cost(rows: np.ndarray, cols: np.ndarray, cost: np.ndarray, taken_rows: np.ndarray,
                    taken_cols: np.ndarray, miss_cost: float) -> float:
    """The total cost of an assignment as :func:`gnn_assign` counts it: the costs of the taken pairs plus
    ``miss_cost`` for every track of ``rows`` without one.  Each taken pair must be one of the given pairs."""
    table = {(int(a), int(b)): float(x) for a, b, x in zip(rows, cols, cost)}
    total = sum(table[(int(a), int(b))] for a, b in zip(taken_rows, taken_cols))
    return total + miss_cost * (np.unique(rows).size - np.unique(taken_rows).size)
