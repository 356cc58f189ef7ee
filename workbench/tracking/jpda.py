"""Joint probabilistic data association: the marginal association probabilities of (J)IPDA / JPDA.

The problem is a bipartite graph of gated (track, detection) pairs.  Track ``t`` has a *miss weight* ``w0_t`` and
each of its gated pairs ``(t, j)`` a *pair weight* ``w_tj``; a detection that no track takes is clutter, of weight 1
(the pair weights are likelihood ratios against clutter).  A joint association event ``e`` gives each track one of
its gated detections or none, each detection to at most one track, and has the weight::

    W(e) = prod_{t missed in e} w0_t  *  prod_{(t, j) in e} w_tj

The marginals are ``beta0_t = sum_{e: t missed} W(e) / sum_e W(e)`` and ``beta_tj = sum_{e: (t, j) in e} W(e) /
sum_e W(e)``.  For JIPDA (Musicki and Evans 2004) ``w0_t = 1 - P_D P_G r_t`` and ``w_tj = r_t P_D g_tj / rho_j``
(``r_t`` the predicted existence, ``g_tj = N(nu_tj; 0, S_t)``, ``rho_j`` the clutter density at the detection);
plain JPDA is ``r_t = 1``.

:func:`marginals` splits the graph into clusters (tracks linked by shared detections, :func:`clusters`) and
computes each cluster's marginals

- in closed form for a cluster of one track (``beta_tj = w_tj / (w0_t + sum_j w_tj)``, the PDA);
- **exactly**, by enumerating every joint event (:func:`exact_marginals`), for a cluster of at most
  ``max_exact_tracks`` tracks whose event count bound ``prod_t (1 + m_t)`` (``m_t`` the track's gated
  detections) is at most ``max_exact_events``;
- otherwise by **loopy belief propagation** over the association graph (:func:`lbp_marginals`, Williams and Lau,
  "Approximate evaluation of marginal association probabilities with belief propagation", IEEE TAES 2014): the
  messages ``mu_tj = w_tj / (w0_t + sum_{j' != j} w_tj' nu_j't)`` (track to detection) and
  ``nu_jt = 1 / (1 + sum_{t' != t} mu_t'j)`` (detection to track) are iterated from ``nu = 1`` until the largest
  change is below ``tol`` (or ``iterations`` rounds; each cluster stops on its own, so its result does not depend on
  the other clusters given with it), and ``beta_tj = w_tj nu_jt / (w0_t + sum_j' w_tj' nu_j't)``.
  Each track's marginals sum to one; the method is exact on a tree (a cluster of one track, or tracks that share
  at most one detection along any cycle-free path) and approximate on loops, with errors of order 1e-3 on small
  dense clusters (``tests/test_jipda.py`` states and bounds it against enumeration).

These are the only sums the JIPDA tracker (``plugins/trackers/jipda.py``) needs; they live here, in the
tracking package, because they are plain maths on arrays that other association roles (a JPDA variant, a
track-oriented tracker, the tests' references) share with it.
"""

from __future__ import annotations

import numpy as np

from ..types import InputError

__all__ = ["clusters", "exact_marginals", "lbp_marginals", "marginals"]


def clusters(n_tracks: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """The cluster label ``(n_tracks,)`` of every track: tracks linked (directly or through other tracks) by a
    shared detection have the same label; labels are ``0 .. C-1`` in order of each cluster's first track."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows, cols = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp)
    if n_tracks == 0:
        return np.zeros(0, dtype=np.intp)
    if rows.size == 0:
        return np.arange(n_tracks, dtype=np.intp)
    n_det = int(cols.max()) + 1
    # the bipartite graph: tracks 0..K-1, detections K..K+D-1
    graph = coo_matrix((np.ones(rows.size), (rows, n_tracks + cols)), shape=(n_tracks + n_det,) * 2)
    _, label = connected_components(graph, directed=False)
    label = label[:n_tracks]
    _, first, inverse = np.unique(label, return_index=True, return_inverse=True)
    rank = np.empty(first.size, dtype=np.intp)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size)
    return rank[inverse]


def _check(miss: np.ndarray, rows: np.ndarray, cols: np.ndarray, w: np.ndarray, n_tracks: int) -> None:
    if not (miss.shape == (n_tracks,) and rows.shape == cols.shape == w.shape and rows.ndim == 1):
        raise InputError(f"association weights: need miss ({n_tracks},) and rows, cols, w of one length; got "
                         f"{miss.shape}, {rows.shape}, {cols.shape}, {w.shape}")
    if not (np.all(np.isfinite(miss)) and np.all(miss >= 0) and np.all(np.isfinite(w)) and np.all(w >= 0)):
        raise InputError("association weights must be finite and >= 0")
    if rows.size and (np.any(rows < 0) or np.any(rows >= n_tracks) or np.any(cols < 0)):
        raise InputError(f"association weights: track labels must be in 0..{n_tracks - 1} and detection labels >= 0")
    if rows.size and np.unique(rows.astype(np.int64) * (int(cols.max()) + 1) + cols).size != rows.size:
        raise InputError("association weights: a (track, detection) pair is given twice")


def exact_marginals(miss: np.ndarray, rows: np.ndarray, cols: np.ndarray, w: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The exact marginals of one cluster by enumeration of every joint event (see the module docstring).

    ``miss (K,)``: the tracks' miss weights; ``rows, cols, w (P,)``: the gated pairs (track ``0..K-1``, any detection
    labels) and their weights.  Returns ``beta0 (K,)`` and ``beta (P,)``.
    """
    miss = np.asarray(miss, dtype=float)
    rows, cols, w = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp), np.asarray(w, dtype=float)
    _check(miss, rows, cols, w, miss.shape[0])
    return _enumerate(miss, rows, cols, w)


def _enumerate(miss: np.ndarray, rows: np.ndarray, cols: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`exact_marginals` without the checks: a depth-first walk over the tracks, each taking its miss or one of
    its detections that no earlier track of the event took (a bit mask); at every complete event its weight (the
    product of its choices' weights) is added to the total and to the marginal of each of its choices.  Plain Python
    on Python floats: a cluster has few events, and a NumPy call per step would cost more than the step."""
    K, P = miss.shape[0], rows.shape[0]
    _, local = np.unique(cols, return_inverse=True)
    options: list[list[tuple[int, int, float]]] = [[] for _ in range(K)]
    for p, (t, d, x) in enumerate(zip(rows.tolist(), local.tolist(), w.tolist())):
        options[t].append((p, 1 << d, x))
    miss_l = miss.tolist()
    b0, b = [0.0] * K, [0.0] * P
    choice = [-1] * K
    total = 0.0

    def walk(t: int, used: int, weight: float) -> None:
        nonlocal total
        if t == K:
            total += weight
            for i, c in enumerate(choice):
                if c < 0:
                    b0[i] += weight
                else:
                    b[c] += weight
            return
        choice[t] = -1
        walk(t + 1, used, weight * miss_l[t])
        for p, bit, x in options[t]:
            if not used & bit:
                choice[t] = p
                walk(t + 1, used | bit, weight * x)
        choice[t] = -1

    walk(0, 0, 1.0)
    if not total > 0:
        raise InputError("association weights: every joint event has weight 0 (a track with miss weight 0 and no "
                         "detection it can take)")
    return np.array(b0) / total, np.array(b, dtype=float).reshape(P) / total


def lbp_marginals(miss: np.ndarray, rows: np.ndarray, cols: np.ndarray, w: np.ndarray, tol: float = 1e-12,
                  iterations: int = 1000) -> tuple[np.ndarray, np.ndarray, int]:
    """Loopy belief propagation over the association graph (Williams and Lau 2014; see the module docstring),
    vectorised over every pair of every cluster given.  Returns ``beta0 (K,)``, ``beta (P,)`` and the number of
    rounds run."""
    miss = np.asarray(miss, dtype=float)
    rows, cols, w = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp), np.asarray(w, dtype=float)
    K = miss.shape[0]
    _check(miss, rows, cols, w, K)
    if rows.size == 0:
        return np.ones(K), np.zeros(0), 0
    _, local = np.unique(cols, return_inverse=True)
    D = int(local.max()) + 1
    group = clusters(K, rows, local)[rows]  # each pair's cluster: a cluster stops when its own messages have converged
    live = np.ones(int(group.max()) + 1, dtype=bool)
    nu = np.ones(rows.size)
    rounds = 0
    for rounds in range(1, iterations + 1):
        wnu = w * nu
        denom = miss + np.bincount(rows, weights=wnu, minlength=K)  # w0_t + sum_j w_tj nu_jt
        mu = w / np.maximum(denom[rows] - wnu, 1e-300)  # leave out the pair's own term
        col_sum = np.bincount(local, weights=mu, minlength=D)
        new = 1.0 / (1.0 + col_sum[local] - mu)
        change = np.zeros(live.size)
        np.maximum.at(change, group, np.abs(new - nu))
        nu = np.where(live[group], new, nu)
        live &= change >= tol
        if not live.any():
            break
    wnu = w * nu
    denom = miss + np.bincount(rows, weights=wnu, minlength=K)
    return miss / denom, wnu / denom[rows], rounds


def marginals(miss: np.ndarray, rows: np.ndarray, cols: np.ndarray, w: np.ndarray, *, max_exact_tracks: int = 8,
              max_exact_events: int = 100_000, tol: float = 1e-12, iterations: int = 1000
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every track's marginals: closed form for clusters of one track, exact enumeration for clusters within
    ``max_exact_tracks`` tracks and ``max_exact_events`` events (the bound ``prod_t (1 + m_t)``), loopy belief
    propagation for the rest (see the module docstring).  Returns ``beta0 (K,)``, ``beta (P,)`` and ``exact (K,)``
    (``False`` for the tracks whose marginals came from belief propagation)."""
    miss = np.asarray(miss, dtype=float)
    rows, cols, w = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp), np.asarray(w, dtype=float)
    K = miss.shape[0]
    _check(miss, rows, cols, w, K)
    beta0, beta = np.ones(K), np.zeros(rows.size)
    exact = np.ones(K, dtype=bool)
    if rows.size == 0:
        return beta0, beta, exact
    label = clusters(K, rows, cols)
    size = np.bincount(label)
    single = size[label[rows]] == 1
    # one track: the PDA's closed form, all such tracks at once
    denom = miss + np.bincount(rows[single], weights=w[single], minlength=K)
    lone = size[label] == 1
    beta0[lone] = miss[lone] / denom[lone]
    beta[single] = w[single] / denom[rows[single]]
    shared = np.flatnonzero(size > 1)
    if shared.size == 0:
        return beta0, beta, exact
    m_t = np.bincount(rows, minlength=K)
    pair_order = np.argsort(label[rows], kind="stable")
    pair_start = np.searchsorted(label[rows][pair_order], np.arange(size.size + 1))
    track_order = np.argsort(label, kind="stable")  # each cluster's tracks, ascending
    track_start = np.searchsorted(label[track_order], np.arange(size.size + 1))
    loopy = []
    for c in shared:
        tracks = track_order[track_start[c]:track_start[c + 1]]
        pairs = pair_order[pair_start[c]:pair_start[c + 1]]
        events = float(np.prod(1.0 + m_t[tracks]))
        if tracks.size <= max_exact_tracks and events <= max_exact_events:
            local_rows = np.searchsorted(tracks, rows[pairs])
            b0, b = _enumerate(miss[tracks], local_rows, cols[pairs], w[pairs])
            beta0[tracks], beta[pairs] = b0, b
        else:
            loopy.append((tracks, pairs))
    if loopy:
        tracks = np.concatenate([t for t, _ in loopy])
        pairs = np.concatenate([p for _, p in loopy])
        local_rows = np.searchsorted(np.sort(tracks), rows[pairs])
        order = np.sort(tracks)
        b0, b, _ = lbp_marginals(miss[order], local_rows, cols[pairs], w[pairs], tol, iterations)
        beta0[order], beta[pairs] = b0, b
        exact[order] = False
    return beta0, beta, exact
