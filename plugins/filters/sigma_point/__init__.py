"""Sigma-point Kalman filters: UKF, CDKF and their square-root forms SR-UKF, SR-CDKF (van der Merwe 2004).

All four are batch-first (``mean (B, n)``; covariance or lower Cholesky factor ``(B, n, n)``) and use the
additive-noise forms.  With ``L = n`` and ``X = [x, x + c sqrt(P), x - c sqrt(P)]`` (``2L + 1`` points;
``sqrt(P)`` the lower Cholesky factor, its columns added and subtracted):

UKF (spread ``c = gamma = sqrt(L + lam)``, ``lam = alpha^2 (L + kappa) - L``)::

    Wm0 = lam / (L + lam)   Wc0 = Wm0 + 1 - alpha^2 + beta   Wm_i = Wc_i = 1 / (2 (L + lam))
    x- = sum Wm f(X)        P- = sum Wc (f(X) - x-)(.)^T + Q
    redraw X from (x-, P-); Y = h(X); y^ = sum Wm Y (angle-aware)
    Pyy = sum Wc (Y - y^)(.)^T + R     Pxy = sum Wc (X - x-)(Y - y^)^T
    K = Pxy Pyy^-1          x = x- + K wrap(z - y^)      P = P- - K Pyy K^T

CDKF (spread ``c = h``)::

    Wm0 = (h^2 - L) / h^2   Wm_i = 1 / (2 h^2)   Wc1 = 1 / (4 h^2)   Wc2 = (h^2 - 1) / (4 h^4)
    P- = sum_i Wc1 (X*_i - X*_{L+i})(.)^T + Wc2 (X*_i + X*_{L+i} - 2 X*_0)(.)^T + Q
    Pyy likewise with Y, plus R;  Pxy = sqrt(Wc1) sqrt(P-) [Y_{1:L} - Y_{L+1:2L}]^T

Square-root forms carry ``S`` (``P = S S^T``): QR (:func:`workbench.linalg.tria`) of the weighted
deviations and ``sqrt(Q)`` / ``sqrt(R)``, a rank-1 :func:`~workbench.linalg.cholupdate` with the
centre point (SR-UKF, sign of ``Wc0``), ``K`` by two triangular solves, and
``S = cholupdate(S-, K S_y, -1)`` over the columns of ``K S_y``.  They never form and refactor a full
covariance.  A downdate that would lose positive definiteness falls back (inside ``cholupdate``) to a
jittered refactorisation; every such item is counted in the state and reported by ``diagnostics``.
The SR-CDKF also offers the downdate-free form ``S = tria([S- - K A, K B, K sqrt(R)])``.

Angles: bearing residuals use :meth:`MeasurementModel.residual` (wrapped to (-pi, pi]) and sigma-point
means of bearings use :meth:`MeasurementModel.mean`; every deviation ``Y_i - y^`` or ``Y_i - Y_j`` is
a wrapped residual.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache, partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, require_finite, single_measurement
from workbench.kalman_core import cached_angle_mask
from workbench.kernels.backend import BackendRecord, runs_numba
from workbench.linalg import cholupdate, safe_cholesky, symmetrise, tria
from workbench.models import MeasurementModel, MotionModel
from workbench.params import Param, declared_factory
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Scan


# -- weights and sigma points -----------------------------------------------------------------------


@dataclass(frozen=True)
class SigmaWeights:
    """Weights of a ``2n + 1`` point set.

    ``kind`` is ``"unscented"`` or ``"central"``; ``spread`` is ``gamma`` or ``h``; ``mean (2n+1,)``;
    ``cov (2n+1,)`` (unscented only); ``c1``, ``c2`` the CDKF's ``Wc1``, ``Wc2``.
    """

    kind: str
    spread: float
    mean: np.ndarray
    cov: np.ndarray | None = None
    c1: float = 0.0
    c2: float = 0.0


def unscented_weights(n: int, alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0) -> SigmaWeights:
    """UKF weights for state dimension ``n`` (van der Merwe's scaled unscented transform)."""
    # lam = alpha^2 (L + kappa) - L
    lam = alpha * alpha * (n + kappa) - n
    if n + lam <= 0:
        raise InputError(f"ukf: alpha^2 (L + kappa) must be > 0, got alpha={alpha}, kappa={kappa}, L={n}")
    wm = np.full(2 * n + 1, 1.0 / (2.0 * (n + lam)))  # Wm_i = 1 / (2 (L + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)  # Wm0 = lam / (L + lam)
    wc[0] = wm[0] + 1.0 - alpha * alpha + beta  # Wc0 = Wm0 + 1 - alpha^2 + beta
    return SigmaWeights("unscented", float(np.sqrt(n + lam)), wm, wc)  # gamma = sqrt(L + lam)


def central_difference_weights(n: int, h: float = np.sqrt(3.0)) -> SigmaWeights:
    """CDKF weights for state dimension ``n`` and step ``h >= 1``."""
    if h < 1.0:
        raise InputError(f"cdkf: the step h must be >= 1, got {h}")
    h2 = h * h
    wm = np.full(2 * n + 1, 1.0 / (2.0 * h2))  # Wm_i = 1 / (2 h^2)
    wm[0] = (h2 - n) / h2  # Wm0 = (h^2 - L) / h^2
    # Wc1 = 1 / (4 h^2), Wc2 = (h^2 - 1) / (4 h^4)
    return SigmaWeights("central", float(h), wm, None, 1.0 / (4.0 * h2), (h2 - 1.0) / (4.0 * h2 * h2))


def sigma_points(mean: np.ndarray, chol: np.ndarray, spread: float) -> np.ndarray:
    """``[x, x + c S_j, x - c S_j]`` for the columns ``S_j`` of the lower factor; ``(B, 2n + 1, n)``.

    Shapes: ``mean (B, n)``, ``chol (B, n, n)``.
    """
    B, n = mean.shape
    cols = spread * np.swapaxes(chol, 1, 2)  # row j = c * column j of S
    centre = mean[:, None, :]
    out = np.empty((B, 2 * n + 1, n))
    out[:, 0] = mean
    np.add(centre, cols, out=out[:, 1:n + 1])
    np.subtract(centre, cols, out=out[:, n + 1:])
    return out


def _weighted_outer(a: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum_s w_s a_s b_s^T`` for ``a (B, S, p)``, ``w (S,)``, ``b (B, S, q)`` -> ``(B, p, q)``."""
    return np.swapaxes(a * w[None, :, None], 1, 2) @ b


def _central_diffs(points: np.ndarray, n: int, residual=None) -> tuple[np.ndarray, np.ndarray]:
    """``A = P_{1:L} - P_{L+1:2L}`` and ``D = P_{1:L} + P_{L+1:2L} - 2 P_0``, each ``(B, L, m)``.

    With ``residual`` (the measurement model's), differences of angles are wrapped.
    """
    plus, minus, centre = points[:, 1:n + 1], points[:, n + 1:], points[:, :1]
    if residual is None:
        return plus - minus, plus + minus - 2.0 * centre
    return residual(plus, minus), residual(plus, centre) + residual(minus, centre)


def _lower_sqrt(R: np.ndarray) -> np.ndarray:
    """A lower factor of the (PSD) measurement noise covariance (computed once per distinct ``R``; read-only)."""
    R = np.ascontiguousarray(R, dtype=float)
    return _lower_sqrt_cached(R.tobytes(), R.shape[0])


@lru_cache(maxsize=64)
def _lower_sqrt_cached(r_bytes: bytes, m: int) -> np.ndarray:
    chol, _ = safe_cholesky(np.frombuffer(r_bytes, dtype=float).reshape(m, m)[None], jitter=1e-15)
    out = np.ascontiguousarray(chol[0])
    out.flags.writeable = False
    return out


def _solve_lower(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Forward substitution ``L X = B`` for lower-triangular ``L (B, m, m)`` and ``b (B, m, k)``."""
    m = L.shape[-1]
    x = np.empty(np.broadcast_shapes(L.shape[:-1], b.shape[:-2] + (m,)) + (b.shape[-1],))
    for i in range(m):
        acc = b[:, i] - np.sum(L[:, i, :i, None] * x[:, :i], axis=1) if i else b[:, i]
        x[:, i] = acc / L[:, i, i, None]
    return x


def _solve_upper(U: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Back substitution ``U X = B`` for upper-triangular ``U (B, m, m)`` and ``b (B, m, k)``."""
    m = U.shape[-1]
    x = np.empty(np.broadcast_shapes(U.shape[:-1], b.shape[:-2] + (m,)) + (b.shape[-1],))
    for i in range(m - 1, -1, -1):
        acc = b[:, i] - np.sum(U[:, i, i + 1:, None] * x[:, i + 1:], axis=1) if i < m - 1 else b[:, i]
        x[:, i] = acc / U[:, i, i, None]
    return x


# -- full-covariance filters (UKF, CDKF) ------------------------------------------------------------


@dataclass(frozen=True)
class SigmaPointState:
    """Mean ``(B, n)``, covariance ``(B, n, n)`` and the number of items whose Cholesky factorisation
    needed jitter (summed over the batch and the run)."""

    mean: np.ndarray
    cov: np.ndarray
    jitters: int = 0

    #: The batch-first fields (the jitter count is the batch's).
    batch_fields = ("mean", "cov")


def _full_state(mean: np.ndarray, cov: np.ndarray, jitters: int) -> SigmaPointState:
    """``SigmaPointState(mean, cov, jitters)`` without the frozen dataclass's ``__init__`` (which sets each field
    through ``object.__setattr__``, a third of the time): the compiled paths build one per step."""
    out = object.__new__(SigmaPointState)
    out.__dict__.update(mean=mean, cov=cov, jitters=jitters)
    return out


def _init_full(prior: Gaussian, rng=None) -> SigmaPointState:
    return SigmaPointState(prior.mean, prior.cov)


def _cholesky(P: np.ndarray) -> tuple[np.ndarray, int]:
    """Lower factor of symmetric ``P (B, n, n)``: one batched call, and :func:`safe_cholesky` (which
    adds and counts jitter) only when some item is not numerically positive definite."""
    try:
        return np.linalg.cholesky(P), 0
    except np.linalg.LinAlgError:
        return safe_cholesky(P)


def _gain(Pxy: np.ndarray, chol_yy: np.ndarray) -> np.ndarray:
    """``K = Pxy Pyy^-1`` with ``Pyy = L L^T``: solve ``L M = Pxy^T``, then ``L^T K^T = M``."""
    return np.swapaxes(_solve_upper(np.swapaxes(chol_yy, 1, 2), _solve_lower(chol_yy, np.swapaxes(Pxy, 1, 2))), 1, 2)


_RECORD = BackendRecord()  # which code the last full-covariance predict / update of this thread ran


def last_backend() -> str | None:
    """Which code computed this thread's last sigma-point predict or update: ``"numba"`` (the compiled UKF loops of
    :mod:`workbench_filters.sigma_point.sigma_numba`, or its square-root loops for the SR-UKF and SR-CDKF) or
    ``"numpy"`` (the NumPy code below: the backend policy did not pick Numba, e.g. ``WORKBENCH_BACKEND=numpy``, no
    Numba or a GPU arch; the full-covariance CDKF; a covariance the compiled Cholesky declines; a square-root update
    or downdate that would fail, which the NumPy code falls back from and counts; a motion model that is not
    linear in the square-root predict; the SR-CDKF's downdate-free form); ``None`` before the first call.  For tests, which must know
    which path ran."""
    return _RECORD.last()


def backend_counts() -> dict:
    """Calls per backend (``{"numba": k, "numpy": m}``) of this thread so far, for the same functions as
    :func:`last_backend`."""
    return _RECORD.counts()


_LOOPS: list = []


def _compiled(weights: SigmaWeights):
    """The Numba loops of the UKF (:mod:`workbench_filters.sigma_point.sigma_numba`) where the backend policy picks Numba
    (:func:`workbench.kernels.backend.runs_numba`) and the weights are unscented, else ``None``."""
    if weights.kind != "unscented" or not runs_numba():
        return None
    if not _LOOPS:  # imported once: an import statement per call costs a tenth of a one-track step's Python
        from . import sigma_numba

        _LOOPS.append(sigma_numba)
    return _LOOPS[0]


def _compiled_points(fast, x: np.ndarray, P: np.ndarray, spread: float) -> np.ndarray | None:
    """The sigma points ``X`` from the compiled loops ``fast``, or ``None`` (no compiled loops, or some ``P`` not
    positive definite)."""
    if fast is None:
        return None
    B, n = x.shape
    X = np.empty((B, 2 * n + 1, n))
    return X if fast.chol_sigma(x, P, float(spread), X, np.empty((B, n, n))) else None


def _predict_full(state: SigmaPointState, motion: MotionModel, rng=None, *, weights: SigmaWeights) -> SigmaPointState:
    x, P = state.mean, state.cov
    n = x.shape[1]
    central = _compiled_any() if weights.kind == "central" and motion.linear else None
    if central is not None:  # the CDKF: points, f = X F^T and the central differences' moments in one call
        mean, cov = np.empty(x.shape), np.empty(P.shape)
        if central.central_linear_predict(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(P, dtype=float),
                                          np.ascontiguousarray(motion.F, dtype=float), float(weights.spread),
                                          weights.mean, float(weights.c1), float(weights.c2),
                                          np.ascontiguousarray(motion.Q, dtype=float), mean, cov):
            _RECORD.note("numba")
            return _full_state(mean, cov, state.jitters)
    fast = _compiled(weights)
    if fast is not None and motion.linear:  # f(X) = X F^T, declared: points, f and moments in one compiled call
        mean, cov = np.empty(x.shape), np.empty(P.shape)
        if fast.linear_predict(x, P, np.ascontiguousarray(motion.F, dtype=float), float(weights.spread), weights.mean,
                               weights.cov, np.ascontiguousarray(motion.Q, dtype=float), mean, cov):
            _RECORD.note("numba")
            return _full_state(mean, cov, state.jitters)
        fast = None  # some P not positive definite: the NumPy code below adds and counts jitter
    X = _compiled_points(fast, x, P, weights.spread)
    if X is not None:  # the same formulas as below, item by item (tests/test_sigma_numba.py)
        Xf = np.ascontiguousarray(motion.f(X))
        mean, cov = np.empty(x.shape), np.empty(P.shape)
        fast.predicted_moments(Xf, weights.mean, weights.cov, np.asarray(motion.Q, dtype=float), mean, cov)
        _RECORD.note("numba")
        return _full_state(mean, cov, state.jitters)
    _RECORD.note("numpy")
    S, jit = _cholesky(P)
    Xf = motion.f(sigma_points(x, S, weights.spread))  # X* = f(X)
    mean = weights.mean @ Xf  # x- = sum Wm X*
    if weights.kind == "unscented":
        d = Xf - mean[:, None, :]
        cov = _weighted_outer(d, weights.cov, d)  # P- = sum Wc (X* - x-)(.)^T
    else:
        a, b = _central_diffs(Xf, n)
        # P- = sum_i Wc1 (X*_i - X*_{L+i})(.)^T + Wc2 (X*_i + X*_{L+i} - 2 X*_0)(.)^T
        cov = weights.c1 * (np.swapaxes(a, 1, 2) @ a) + weights.c2 * (np.swapaxes(b, 1, 2) @ b)
    return SigmaPointState(mean, symmetrise(cov + motion.Q), state.jitters + jit)


def _update_full(state: SigmaPointState, scan: Scan, model: MeasurementModel, rng=None, *,
                 weights: SigmaWeights, who: str) -> SigmaPointState:
    z, present = single_measurement(scan, who)
    if not (present[0] if present.shape[0] == 1 else present.any()):  # any(), a tenth of the time at B = 1
        return state
    x, P = state.mean, state.cov
    B, n = x.shape
    central = _compiled_any() if weights.kind == "central" else None
    X = _compiled_points(central, x, P, weights.spread)
    if X is not None:  # the CDKF's update item by item, the same formulas as below
        Y = np.ascontiguousarray(model.h(X), dtype=float)
        m = z.shape[1]
        angular = cached_angle_mask(model)
        if Y.shape == (B, 2 * n + 1, m) and model.R.shape == (m, m) and angular.shape == (m,):
            mean, cov = np.empty(x.shape), np.empty(P.shape)
            if central.central_update(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(P, dtype=float), Y, float(weights.spread),
                                      weights.mean, float(weights.c1), float(weights.c2), angular,
                                      np.ascontiguousarray(model.R, dtype=float), np.ascontiguousarray(z, dtype=float),
                                      np.ascontiguousarray(present, dtype=bool), mean, cov):
                _RECORD.note("numba")
                return _full_state(mean, cov, state.jitters)
    fast = _compiled(weights)
    X = _compiled_points(fast, x, P, weights.spread)
    if X is not None:  # the same formulas as below, item by item (tests/test_sigma_numba.py)
        Y = np.ascontiguousarray(model.h(X), dtype=float)
        m = z.shape[1]
        angular = cached_angle_mask(model)
        if Y.shape == (B, 2 * n + 1, m) and model.R.shape == (m, m) and angular.shape == (m,):  # the loop's indices
            mean, cov = np.empty(x.shape), np.empty(P.shape)
            # declined (False) for a Pyy that is not positive definite or a present z that is not finite
            if fast.unscented_update(x, P, X, Y, weights.mean, weights.cov, angular, model.R,
                                     np.ascontiguousarray(z, dtype=float), present, mean, cov):
                _RECORD.note("numba")
                return _full_state(mean, cov, state.jitters)
    require_finite(z, present, who)
    _RECORD.note("numpy")
    S, jit = _cholesky(P)
    X = sigma_points(x, S, weights.spread)  # redraw from (x-, P-)
    Y = model.h(X)
    y_hat = model.mean(Y, weights.mean)  # y^ = sum Wm Y, angle-aware
    if weights.kind == "unscented":
        dy = model.residual(Y, y_hat[:, None, :])
        # [Pxy; Pyy] = sum Wc [X - x-; Y - y^] (Y - y^)^T in one product (R is added to Pyy below)
        both = _weighted_outer(np.concatenate([X - x[:, None, :], dy], axis=2), weights.cov, dy)
        Pxy, Pyy = both[:, :n], both[:, n:]
    else:
        a, b = _central_diffs(Y, n, model.residual)
        Pyy = weights.c1 * (np.swapaxes(a, 1, 2) @ a) + weights.c2 * (np.swapaxes(b, 1, 2) @ b)
        Pxy = np.sqrt(weights.c1) * (S @ a)  # Pxy = sqrt(Wc1) sqrt(P-) [Y_{1:L} - Y_{L+1:2L}]^T
    Pyy = symmetrise(Pyy + model.R)
    Lyy, jit_y = _cholesky(Pyy)
    K = _gain(Pxy, Lyy)  # K = Pxy Pyy^-1
    nu = model.residual(z, y_hat)  # wrap(z - y^)
    mean = x + (K @ nu[:, :, None])[:, :, 0]
    KLyy = K @ Lyy
    cov = symmetrise(P - KLyy @ np.swapaxes(KLyy, 1, 2))  # P = P- - K Pyy K^T
    if not present.all():
        mean, cov = keep_where(present, mean, x), keep_where(present, cov, P)
    return SigmaPointState(mean, cov, state.jitters + jit + jit_y)


def _estimate_full(state: SigmaPointState) -> Gaussian:
    return Gaussian.trusted(state.mean, state.cov)


def _diagnostics_full(state: SigmaPointState) -> dict:
    return {"cholesky_jitter": state.jitters}


# -- square-root filters (SR-UKF, SR-CDKF) ----------------------------------------------------------


@dataclass(frozen=True)
class SquareRootState:
    """Mean ``(B, n)``, lower Cholesky factor ``(B, n, n)`` with ``P = S S^T``, and the number of
    rank-1 downdates that fell back to a refactorisation (summed over the batch and the run)."""

    mean: np.ndarray
    chol: np.ndarray
    fallbacks: int = 0

    #: The batch-first fields (the fallback count is the batch's).
    batch_fields = ("mean", "chol")


def _init_sqrt(prior: Gaussian, rng=None) -> SquareRootState:
    chol, _ = safe_cholesky(prior.cov)  # S0 = chol(P0), once
    return SquareRootState(prior.mean, chol)


def _compiled_any():
    """The module of the Numba loops (:mod:`workbench_filters.sigma_point.sigma_numba`) where the backend policy picks
    Numba, whatever the weights (the CDKF's loops and the square-root forms' use it), else ``None``."""
    if not runs_numba():
        return None
    if not _LOOPS:
        from . import sigma_numba

        _LOOPS.append(sigma_numba)
    return _LOOPS[0]


def _weights_args(weights: SigmaWeights) -> tuple:
    """``(wm, wc, central, c1, c2)`` of the compiled square-root loops (``wc`` unused by the central form)."""
    central = weights.kind == "central"
    return (weights.mean, weights.mean if weights.cov is None else weights.cov, central, float(weights.c1),
            float(weights.c2))


def _predict_sqrt(state: SquareRootState, motion: MotionModel, rng=None, *, weights: SigmaWeights) -> SquareRootState:
    x, S = state.mean, state.chol
    B, n = x.shape
    fast = _compiled_any() if motion.linear else None
    if fast is not None:  # f(X) = X F^T, declared: points, f, QR and the centre's update in one compiled call
        mean, S_new = np.empty(x.shape), np.empty(S.shape)
        if fast.sqrt_linear_predict(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(S, dtype=float),
                                    np.ascontiguousarray(motion.F, dtype=float), float(weights.spread),
                                    *_weights_args(weights), np.ascontiguousarray(motion.Q_sqrt, dtype=float), mean,
                                    S_new):
            _RECORD.note("numba")
            return SquareRootState(mean, S_new, state.fallbacks)
        # an update would lose positive definiteness: the NumPy code below falls back and counts it
    _RECORD.note("numpy")
    Xf = motion.f(sigma_points(x, S, weights.spread))  # X* = f(X)
    mean = weights.mean @ Xf  # x- = sum Wm X*
    q_sqrt = np.broadcast_to(motion.Q_sqrt, (B, n, n))
    failed = 0
    if weights.kind == "unscented":
        d = Xf - mean[:, None, :]
        w1 = np.sqrt(weights.cov[1])
        # S- = qr([sqrt(W1) (X*_{1:2L} - x-), sqrt(Q)]); S- = cholupdate(S-, X*_0 - x-, Wc0)
        S_new = tria(np.concatenate([w1 * np.swapaxes(d[:, 1:], 1, 2), q_sqrt], axis=2))
        if weights.cov[0] != 0.0:
            S_new, bad = cholupdate(S_new, d[:, 0], weights.cov[0])
            failed = int(bad.sum())
    else:
        a, b = _central_diffs(Xf, n)
        # S- = qr([sqrt(Wc1) (X*_{1:L} - X*_{L+1:2L}), sqrt(Wc2) (X*_{1:L} + X*_{L+1:2L} - 2 X*_0), sqrt(Q)])
        S_new = tria(np.concatenate([np.sqrt(weights.c1) * np.swapaxes(a, 1, 2),
                                     np.sqrt(weights.c2) * np.swapaxes(b, 1, 2), q_sqrt], axis=2))
    return SquareRootState(mean, S_new, state.fallbacks + failed)


def _update_sqrt(state: SquareRootState, scan: Scan, model: MeasurementModel, rng=None, *,
                 weights: SigmaWeights, who: str, downdate: str) -> SquareRootState:
    z, present = single_measurement(scan, who)
    if not present.any():
        return state
    require_finite(z, present, who)
    x, S = state.mean, state.chol
    B, n = x.shape
    m = model.dim
    X = sigma_points(x, S, weights.spread)  # redraw from (x-, S-)
    Y = model.h(X)
    fast = _compiled_any() if weights.kind == "unscented" or downdate == "cholupdate" else None
    if fast is not None:
        Y = np.ascontiguousarray(Y, dtype=float)
        angular = cached_angle_mask(model)
        r_sqrt = _lower_sqrt(model.R)
        if Y.shape == (B, 2 * n + 1, m) and r_sqrt.shape[0] == m and angular.shape == (m,):  # the loop's indices
            mean, S_new = np.empty(x.shape), np.empty(S.shape)
            # declined (False) for a present z that is not finite or an update or downdate that would fail
            if fast.sqrt_update(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(S, dtype=float), X, Y,
                                *_weights_args(weights), angular, r_sqrt, np.ascontiguousarray(z, dtype=float),
                                np.ascontiguousarray(present, dtype=bool), mean, S_new):
                _RECORD.note("numba")
                return SquareRootState(mean, S_new, state.fallbacks)
    _RECORD.note("numpy")
    y_hat = model.mean(Y, weights.mean)  # y^ = sum Wm Y, angle-aware
    r_sqrt = np.broadcast_to(_lower_sqrt(model.R), (B, m, m))
    failed = np.zeros(B, dtype=bool)
    if weights.kind == "unscented":
        dy = model.residual(Y, y_hat[:, None, :])
        w1 = np.sqrt(weights.cov[1])
        # S_y = qr([sqrt(W1) (Y_{1:2L} - y^), sqrt(R)]); S_y = cholupdate(S_y, Y_0 - y^, Wc0)
        Sy = tria(np.concatenate([w1 * np.swapaxes(dy[:, 1:], 1, 2), r_sqrt], axis=2))
        if weights.cov[0] != 0.0:
            Sy, bad = cholupdate(Sy, dy[:, 0], weights.cov[0])
            failed |= bad
        Pxy = _weighted_outer(X - x[:, None, :], weights.cov, dy)  # Pxy = sum Wc (X - x-)(Y - y^)^T
    else:
        a, b = _central_diffs(Y, n, model.residual)
        a = np.sqrt(weights.c1) * a  # A = sqrt(Wc1) (Y_{1:L} - Y_{L+1:2L}), rows = points
        b = np.sqrt(weights.c2) * b  # B = sqrt(Wc2) (Y_{1:L} + Y_{L+1:2L} - 2 Y_0)
        Sy = tria(np.concatenate([np.swapaxes(a, 1, 2), np.swapaxes(b, 1, 2), r_sqrt], axis=2))
        Pxy = S @ a  # Pxy = S- A^T
    K = _gain(Pxy, Sy)  # K = (Pxy / S_y^T) / S_y: two triangular solves
    nu = model.residual(z, y_hat)  # wrap(z - y^)
    mean = x + (K @ nu[:, :, None])[:, :, 0]
    if weights.kind == "central" and downdate == "qr":
        # S = qr([S- - K A, K B, K sqrt(R)]): algebraically P- - K Pyy K^T, no downdate
        S_new = tria(np.concatenate([S - K @ np.swapaxes(a, 1, 2), K @ np.swapaxes(b, 1, 2), K @ r_sqrt], axis=2))
    else:
        U = K @ Sy  # S = cholupdate(S-, K S_y, -1), one column at a time
        S_new = S
        for j in range(m):
            S_new, bad = cholupdate(S_new, U[:, :, j], -1.0)
            failed |= bad
    failed &= present
    if not present.all():
        mean, S_new = keep_where(present, mean, x), keep_where(present, S_new, S)
    return SquareRootState(mean, S_new, state.fallbacks + int(failed.sum()))


def _estimate_sqrt(state: SquareRootState) -> Gaussian:
    return Gaussian.trusted(state.mean, state.chol @ np.swapaxes(state.chol, 1, 2))


def _diagnostics_sqrt(state: SquareRootState) -> dict:
    return {"downdate_fallbacks": state.fallbacks}


# -- factories --------------------------------------------------------------------------------------


UKF_PARAMETERS = (
    Param("alpha", 1.0, "spread of the sigma points", unit="dimensionless", above=0.0, maximum=10.0),
    Param("beta", 2.0, "prior-knowledge weight on the centre point (2 for a Gaussian)", unit="dimensionless",
          minimum=0.0, maximum=100.0),
    Param("kappa", 0.0, "secondary scaling of the spread (>= 0 keeps the predicted covariance semi-definite, "
          "Julier and Uhlmann 1997)", unit="dimensionless", minimum=0.0, maximum=1e3),
    Param("square_root", False, "propagate a Cholesky factor (QR + cholupdate) instead of the covariance", "bool"),
)
CDKF_PARAMETERS = (
    Param("h", float(np.sqrt(3.0)), "central-difference step (sqrt(3) is optimal for a Gaussian prior)",
          unit="dimensionless", minimum=1.0, maximum=100.0),
    Param("square_root", False, "propagate a Cholesky factor instead of the covariance", "bool"),
    Param("downdate", "cholupdate", "square-root update: the paper's rank-1 downdates or a downdate-free QR", "str",
          choices=("cholupdate", "qr")),
)


def _spec(name, summary, weights_for, square_root, params, who, downdate="cholupdate", parameters=(),
          build=None) -> FilterSpec:
    """Build a FilterSpec whose weights are made (and cached) for the state dimension met at run time."""
    cache: dict[int, SigmaWeights] = {}

    def weights_of(n: int) -> SigmaWeights:
        if n not in cache:
            cache[n] = weights_for(n)
        return cache[n]

    if square_root:
        def predict(state, motion, rng=None):
            return _predict_sqrt(state, motion, rng, weights=weights_of(state.mean.shape[1]))

        def update(state, scan, model, rng=None):
            return _update_sqrt(state, scan, model, rng, weights=weights_of(state.mean.shape[1]), who=who,
                                downdate=downdate)

        init, estimate, diagnostics = _init_sqrt, _estimate_sqrt, _diagnostics_sqrt
    else:
        def predict(state, motion, rng=None):
            return _predict_full(state, motion, rng, weights=weights_of(state.mean.shape[1]))

        def update(state, scan, model, rng=None):
            return _update_full(state, scan, model, rng, weights=weights_of(state.mean.shape[1]), who=who)

        init, estimate, diagnostics = _init_full, _estimate_full, _diagnostics_full
    return FilterSpec(name=name, summary=summary, init=init, predict=predict, update=update, estimate=estimate,
                      capabilities=frozenset({"gaussian", "exact_linear"}), params=params, diagnostics=diagnostics,
                      parameters=parameters, build=build)


@declared_factory(UKF_PARAMETERS, "ukf")
def make_ukf(values: dict, *, name: str | None = None) -> FilterSpec:
    """An unscented Kalman filter (or SR-UKF); defaults alpha=1, beta=2, kappa=0 keep every weight >= 0 for L=4.

    Takes the declared :data:`UKF_PARAMETERS` (positionally in their order, or by keyword) and ``name``; its
    signature, checks and ``params`` all come from that declaration."""
    alpha, beta, kappa, square_root = (values[k] for k in ("alpha", "beta", "kappa", "square_root"))
    unscented_weights(4, alpha, beta, kappa)  # validate early
    label = "sr-ukf" if square_root else "ukf"
    return _spec(name or label,
                 f"{'Square-root ' if square_root else ''}unscented Kalman filter (alpha={alpha}, beta={beta}, "
                 f"kappa={kappa}){', QR + cholupdate' if square_root else ''}",
                 partial(unscented_weights, alpha=alpha, beta=beta, kappa=kappa), square_root, dict(values), label,
                 parameters=UKF_PARAMETERS, build=make_ukf)


@declared_factory(CDKF_PARAMETERS, "cdkf")
def make_cdkf(values: dict, *, name: str | None = None) -> FilterSpec:
    """A central difference Kalman filter (or SR-CDKF) with step ``h`` (default sqrt(3)).

    ``downdate`` (SR-CDKF): ``"cholupdate"`` (the paper's rank-1 downdates) or ``"qr"`` (the
    downdate-free ``qr([S- - K A, K B, K sqrt(R)])``).  Takes the declared :data:`CDKF_PARAMETERS` (positionally
    in their order, or by keyword) and ``name``; its signature, checks and ``params`` come from that declaration.
    """
    h, square_root, downdate = (values[k] for k in ("h", "square_root", "downdate"))
    central_difference_weights(4, h)  # validate early
    label = "sr-cdkf" if square_root else "cdkf"
    return _spec(name or label,
                 f"{'Square-root ' if square_root else ''}central difference Kalman filter (h={h:.4g})"
                 f"{', QR + ' + downdate if square_root else ''}",
                 partial(central_difference_weights, h=h), square_root, dict(values), label, downdate,
                 parameters=CDKF_PARAMETERS, build=make_cdkf)


@hookimpl
def workbench_filters():
    return [make_ukf(), make_cdkf(), make_ukf(square_root=True), make_cdkf(square_root=True)]
