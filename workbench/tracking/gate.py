"""Gating for the multi-target trackers: which (track, detection) pairs are close enough to be associated.

A pair is in the gate when its squared Mahalanobis distance ``d2 = nu^T S^-1 nu`` (``nu = wrap(z - h(x-))``,
``S = J P- J^T + R_g``, ``J`` the model's Jacobian at the prediction) is at most the gate; :func:`chi2_gate` gives
the gate of a stated gate probability.  :func:`gated_pairs` computes every pair densely below
``TrackerConfig.dense_limit`` pairs and from a spatial grid over the measurement space above it (the same pairs
and values).  Detections are Cartesian positions seen through the measurement model (:func:`measurement_view`);
:func:`position_covariance`, :func:`detection_covariance` and :func:`measurement_covariance` carry covariances
between the two spaces.
"""

from __future__ import annotations

import numpy as np

from ..linalg import wrap_angle
from ..models import MeasurementModel
from ..types import Gaussian, InputError
from .records import TrackerConfig

__all__ = ["chi2_gate", "measurement_view", "position_covariance", "detection_covariance", "measurement_covariance",
           "box_pairs", "gate_covariance", "gated_pairs"]


def chi2_gate(probability: float, dim: int) -> float:
    """The gate ``d2 <= g`` that holds a correct detection with ``probability``: the chi-square quantile of ``dim``
    degrees of freedom (``chi2_gate(0.99, 2) = 9.2103...``)."""
    from scipy.stats import chi2

    if not 0.0 < probability < 1.0:
        raise InputError(f"gate probability must be in (0, 1), got {probability}")
    if dim < 1:
        raise InputError(f"gate: the measurement dimension must be >= 1, got {dim}")
    return float(chi2.ppf(probability, dim))


def measurement_view(model: MeasurementModel, positions: np.ndarray, n: int) -> np.ndarray:
    """Cartesian detections ``(M, 2)`` in the model's measurement space, ``h([x, y, 0, ...])`` -> ``(M, m)``."""
    state = np.zeros((positions.shape[0], n))
    state[:, :2] = positions
    return np.asarray(model.h(state), dtype=float).reshape(positions.shape[0], model.dim)


def _jacobian(model: MeasurementModel, x: np.ndarray) -> np.ndarray:
    if model.jacobian is not None:
        return np.asarray(model.jacobian(x), dtype=float)
    if model.H is not None:
        return np.broadcast_to(model.H, (x.shape[0], *model.H.shape))
    raise InputError(f"the tracker gates with the Jacobian of the measurement model; {model.name!r} has none")


def position_covariance(model: MeasurementModel, positions: np.ndarray, n: int) -> np.ndarray:
    """Covariance of the Cartesian position a detection implies, ``A R A^T`` with ``A = (dh/dp)^-1``.

    For the linear position model this is ``R``; for range-bearing it is the linearised conversion
    covariance of the converted-measurement filter (``R11, R22, R12``).  ``(M, 2) -> (M, 2, 2)``.
    """
    if model.dim != 2:
        raise InputError(f"the tracker needs a 2-component position-like measurement model, got m={model.dim}")
    state = np.zeros((positions.shape[0], n))
    state[:, :2] = positions
    jp = _jacobian(model, state)[:, :, :2]  # dh/dp, (M, 2, 2)
    # A = (dh/dp)^-1;  A R A^T = solve(J, solve(J, R)^T)^T
    x = np.linalg.solve(jp, np.broadcast_to(model.R, jp.shape))
    out = np.linalg.solve(jp, np.swapaxes(x, -1, -2))
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def detection_covariance(model: MeasurementModel, positions: np.ndarray, n: int, sigma: float) -> np.ndarray:
    """Each detection's covariance in the model's measurement space when its position accuracy is ``sigma`` per
    axis: ``J_h(p) (sigma^2 I) J_h(p)^T``, ``J_h = dh/dp`` at the detection.  ``(M, 2) -> (M, m, m)``."""
    return measurement_covariance(model, positions, n, np.broadcast_to(sigma * sigma * np.eye(2),
                                                                       (positions.shape[0], 2, 2)))


def measurement_covariance(model: MeasurementModel, positions: np.ndarray, n: int, pos_cov: np.ndarray) -> np.ndarray:
    """Each detection's covariance in the model's measurement space from its own Cartesian position covariance
    ``C_j``: ``J_h(p_j) C_j J_h(p_j)^T``, ``J_h = dh/dp`` at the detection.  ``(M, 2), (M, 2, 2) -> (M, m, m)``."""
    state = np.zeros((positions.shape[0], n))
    state[:, :2] = positions
    jp = _jacobian(model, state)[:, :, :2]
    out = jp @ pos_cov @ np.swapaxes(jp, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _whiten(chol: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """``L^-1 nu`` for lower-triangular ``chol (..., m, m)`` and ``nu (..., m)`` (broadcasting).

    Forward substitution written out for ``m = 2`` (the tracker's case: no LAPACK call per pair), a
    batched solve otherwise.
    """
    if nu.shape[-1] != 2:
        return np.linalg.solve(chol, nu[..., None])[..., 0]
    w1 = nu[..., 0] / chol[..., 0, 0]
    w2 = (nu[..., 1] - chol[..., 1, 0] * w1) / chol[..., 1, 1]
    return np.stack([w1, w2], axis=-1)


def _grid_query(lo: np.ndarray, hi: np.ndarray, b: np.ndarray, cell) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs ``(i, j)``: every point ``b_j`` inside box ``i`` (``lo_i <= b_j <= hi_i`` on both axes) is
    among them, by spatial grid hashing.

    ``b`` is binned into cells of side ``cell`` (one value or one per axis); each box visits the cells it
    overlaps, and the points of those cells are found with ``searchsorted`` on the sorted cell keys.  Fully
    vectorised, no ``(Na, Nb)`` matrix and no Python loop over points.  Shapes: ``lo, hi (Na, 2)``, ``b (Nb, 2)``
    -> ``i, j (P,)`` grouped by ``i``.
    """
    e = np.zeros(0, dtype=np.intp)
    if lo.shape[0] == 0 or b.shape[0] == 0:
        return e, e
    cell = np.broadcast_to(np.asarray(cell, dtype=float), (2,))
    b_lo = b.min(axis=0)
    extent = b.max(axis=0) - b_lo
    cell = np.maximum(np.maximum(cell, extent / 4096.0), 1e-12)
    nb = np.floor((b - b_lo) / cell).astype(np.int64)
    nx, ny = int(nb[:, 0].max()) + 1, int(nb[:, 1].max()) + 1
    keys = nb[:, 0] * ny + nb[:, 1]
    order = np.argsort(keys, kind="stable")
    skeys = keys[order]
    c0 = np.maximum(np.floor((lo - b_lo) / cell).astype(np.int64), 0)
    c1 = np.minimum(np.floor((hi - b_lo) / cell).astype(np.int64), [nx - 1, ny - 1])
    ncx, ncy = np.maximum(c1[:, 0] - c0[:, 0] + 1, 0), np.maximum(c1[:, 1] - c0[:, 1] + 1, 0)
    # one run of consecutive keys per visited x column: cells (cx, c0y .. c1y)
    rep = np.repeat(np.arange(lo.shape[0]), ncx)
    cx = c0[rep, 0] + (np.arange(rep.size) - np.repeat(np.cumsum(ncx) - ncx, ncx))
    first = np.searchsorted(skeys, cx * ny + c0[rep, 1], side="left")
    count = np.searchsorted(skeys, cx * ny + c0[rep, 1] + ncy[rep] - 1, side="right") - first
    n = int(count.sum())
    if n == 0:
        return e, e
    i = np.repeat(rep, count)
    j = order[np.repeat(first - (np.cumsum(count) - count), count) + np.arange(n)]
    return i, j


def box_pairs(a: np.ndarray, b: np.ndarray, half, cell: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All pairs ``(i, j)`` with ``|a_i - b_j| <= half_i`` on both axes, by spatial grid hashing
    (:func:`_grid_query`; default cell: half the median box width).

    Shapes: ``a (Na, 2)``, ``b (Nb, 2)``, ``half`` scalar, ``(Na,)`` or ``(Na, 2)`` -> ``i, j (P,)``, sorted
    by ``i``.
    """
    a = np.asarray(a, dtype=float).reshape(-1, 2)
    b = np.asarray(b, dtype=float).reshape(-1, 2)
    e = np.zeros(0, dtype=np.intp)
    if a.shape[0] == 0 or b.shape[0] == 0:
        return e, e
    half = np.asarray(half, dtype=float)
    half = np.broadcast_to(half[..., None] if half.ndim == 1 else half, a.shape)
    if cell is None:
        cell = float(np.median(half))
    # the grid query with boxes widened by a relative 1e-9 (the exact test below decides)
    pad = 1e-9 * (np.abs(a) + half) + 1e-300
    i, j = _grid_query(a - half - pad, a + half + pad, b, max(float(cell), 1e-9))  # grouped by i, ascending
    inside = (np.abs(a[i, 0] - b[j, 0]) <= half[i, 0]) & (np.abs(a[i, 1] - b[j, 1]) <= half[i, 1])
    return i[inside], j[inside]


def gate_covariance(est: Gaussian, model: MeasurementModel, config: TrackerConfig,
                    per_detection: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Gate innovation covariance ``S = J P- J^T + R_g`` and the Jacobian ``J`` at the prediction.

    ``R_g = R`` (the filter's), or ``J_p (s^2 I) J_p^T`` with ``J_p = dh/dp`` and ``s = config.gate_sigma``
    (else ``config.detection_sigma``) when one is set.  ``per_detection`` (and no ``gate_sigma``): ``R_g = 0``,
    each detection's own covariance is added per pair by :func:`gated_pairs`.  Shapes: ``(K, m, m)``,
    ``(K, m, n)``.
    """
    J = _jacobian(model, est.mean)
    sigma = config.gate_sigma if config.gate_sigma is not None else config.detection_sigma
    if per_detection and config.gate_sigma is None:
        R = 0.0
    elif sigma is None:
        R = model.R
    else:
        jp = J[:, :, :2]
        R = sigma**2 * (jp @ np.swapaxes(jp, -1, -2))  # R_g = J_p (s^2 I) J_p^T
    S = J @ est.cov @ np.swapaxes(J, -1, -2) + R  # S = J P- J^T + R_g
    return 0.5 * (S + np.swapaxes(S, -1, -2)), J


def _measurement_boxes(zhat: np.ndarray, half: np.ndarray, angular: np.ndarray):
    """The query boxes of gates centred at ``zhat (K, 2)`` with half-widths ``half (K, 2)`` in the measurement
    space, angular components wrapped to (-pi, pi]: a box crossing the seam gets a second, shifted copy.
    Returns ``track (Q,)``, ``lo, hi (Q, 2)``."""
    lo, hi = zhat - half, zhat + half
    track = np.arange(zhat.shape[0])
    extra_t, extra_lo, extra_hi = [], [], []
    for axis in np.flatnonzero(angular):
        whole = half[:, axis] >= np.pi
        lo[whole, axis], hi[whole, axis] = -np.pi - 1.0, np.pi + 1.0
        for shift, over in ((2.0 * np.pi, lo[:, axis] < -np.pi), (-2.0 * np.pi, hi[:, axis] > np.pi)):
            over &= ~whole
            if over.any():
                l2, h2 = lo[over].copy(), hi[over].copy()
                l2[:, axis] += shift
                h2[:, axis] += shift
                extra_t.append(track[over])
                extra_lo.append(l2)
                extra_hi.append(h2)
    if extra_t:
        track = np.concatenate([track] + extra_t)
        lo = np.concatenate([lo] + extra_lo)
        hi = np.concatenate([hi] + extra_hi)
    return track, lo, hi


def gated_pairs(est: Gaussian, positions: np.ndarray, zm: np.ndarray, model: MeasurementModel,
                config: TrackerConfig, det_cov: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(track, detection, d2)`` for every pair inside the gate; see the module docstring.

    ``est`` are the predictions ``(K, n)``, ``positions (M, 2)`` the Cartesian detections and ``zm (M, m)`` the
    same in the model's measurement space.  ``det_cov (M, m, m)``: each detection's own covariance in the
    measurement space; unless ``config.gate_sigma`` is set, pair ``(k, j)`` is gated with
    ``S_kj = J_k P_k J_k^T + det_cov_j``.  At most ``dense_limit`` pairs: every pair's ``d2``.  Above: a
    pair's residual satisfies ``|nu_i| <= sqrt(gate S_ii)`` on each axis inside the gate ellipse, so the
    candidates are the detections inside that box around ``h(x-)`` in the measurement space (angular
    components wrapped; :func:`_grid_query`; with ``det_cov``, ``S_ii`` bounded by the largest detection's),
    and ``d2`` is computed for them only: the same pairs and values as the dense computation.
    """
    K, M = est.batch, zm.shape[0]
    if K == 0 or M == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e, np.zeros(0)
    zhat = model.h(est.mean)
    pair_cov = det_cov is not None and config.gate_sigma is None
    S, J = gate_covariance(est, model, config, per_detection=pair_cov)
    if K * M <= config.dense_limit:
        nu = model.residual(zm[None, :, :], zhat[:, None, :])  # (K, M, m)
        if pair_cov:
            Skj = S[:, None] + det_cov[None]  # S_kj = J P- J^T + R_j
            chol = np.linalg.cholesky(0.5 * (Skj + np.swapaxes(Skj, -1, -2)))
            w = _whiten(chol, nu)
        else:
            w = _whiten(np.linalg.cholesky(S)[:, None], nu)  # L^-1 nu
        d2 = np.einsum("kmi,kmi->km", w, w)
        rows, cols = np.nonzero(d2 <= config.gate)
        return rows, cols, d2[rows, cols]
    if model.dim != 2:
        raise InputError(f"the tracker needs a 2-component measurement model, got m={model.dim}")
    # |nu_i| <= sqrt(gate S_ii) inside the gate; widened by a relative 1e-9 (the d2 test decides)
    diag = np.diagonal(S, axis1=1, axis2=2)
    if pair_cov:
        diag = diag + np.max(np.diagonal(det_cov, axis1=1, axis2=2), axis=0)
    half = np.sqrt(config.gate * np.maximum(diag, 0.0)) * (1.0 + 1e-9) + 1e-12
    track, lo, hi = _measurement_boxes(zhat.astype(float), half, model.angle_mask)
    cell = 0.25 * np.median(2.0 * half, axis=0)
    rows, cols = _grid_query(lo, hi, np.asarray(zm, dtype=float), cell)
    if rows.size == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e, np.zeros(0)
    rows = track[rows]
    # nu = wrap(z - h(x-));  w = L^-1 nu (forward substitution, as _whiten), d2 = |w|^2; the per-track and
    # per-detection factors are gathered from contiguous copies
    z0, z1 = np.ascontiguousarray(zm[:, 0]), np.ascontiguousarray(zm[:, 1])
    h0, h1 = np.ascontiguousarray(zhat[:, 0]), np.ascontiguousarray(zhat[:, 1])
    nu0 = z0[cols] - h0[rows]
    nu1 = z1[cols] - h1[rows]
    if model.angle_mask[0]:
        nu0 = wrap_angle(nu0)
    if model.angle_mask[1]:
        nu1 = wrap_angle(nu1)
    if pair_cov:
        # the 2x2 Cholesky factor of S_kj = S_k + R_j per pair: l00 = sqrt(s00), l10 = s10 / l00,
        # l11 = sqrt(s11 - l10^2)
        s00 = S[rows, 0, 0] + det_cov[cols, 0, 0]
        s10 = 0.5 * (S[rows, 1, 0] + S[rows, 0, 1] + det_cov[cols, 1, 0] + det_cov[cols, 0, 1])
        s11 = S[rows, 1, 1] + det_cov[cols, 1, 1]
        l00 = np.sqrt(s00)
        l10 = s10 / l00
        l11 = np.sqrt(s11 - l10 * l10)
        w1 = nu0 / l00
        w2 = (nu1 - l10 * w1) / l11
    else:
        chol = np.linalg.cholesky(S)
        l00, l10, l11 = (np.ascontiguousarray(chol[:, i, j]) for i, j in ((0, 0), (1, 0), (1, 1)))
        w1 = nu0 / l00[rows]
        w2 = (nu1 - l10[rows] * w1) / l11[rows]
    d2 = w1 * w1 + w2 * w2
    inside = d2 <= config.gate
    return rows[inside], cols[inside], d2[inside]


