"""Batched linear-algebra helpers: every function works on stacks ``(B, n, n)``.

NumPy's ``np.linalg`` broadcasts over leading axes, so none of these loops over the batch in Python
(except :func:`cholupdate`, which loops over the ``n`` columns of the factor, never over ``B``).
"""

from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi

__all__ = [
    "wrap_angle",
    "symmetrise",
    "psd_solve",
    "safe_cholesky",
    "joseph_update",
    "cholupdate",
    "tria",
    "mahalanobis_sq",
]


def wrap_angle(angle):
    """Wrap angles to the interval (-pi, pi]."""
    a = np.asarray(angle, dtype=float)
    # a - 2 pi ceil((a - pi) / 2 pi) lies in (-pi, pi]: one pass cheaper than np.mod + a fix-up.
    return a - TWO_PI * np.ceil((a - np.pi) * (1.0 / TWO_PI))


def symmetrise(a: np.ndarray) -> np.ndarray:
    """``(A + A^T) / 2`` over the last two axes."""
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def psd_solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``A X = B`` for symmetric positive definite ``A (..., n, n)`` via Cholesky.

    ``B`` is ``(..., n, k)``.  Falls back to a general solve only for the items whose Cholesky
    factorisation fails, so an ill-conditioned item does not stop the batch.
    """
    try:
        chol = np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        return np.linalg.solve(a, b)
    y = np.linalg.solve(chol, b)  # forward substitution (general solve keeps it batched)
    return np.linalg.solve(np.swapaxes(chol, -1, -2), y)


def safe_cholesky(a: np.ndarray, jitter: float = 1e-9) -> tuple[np.ndarray, int]:
    """Lower Cholesky factor of a batch of (nearly) PSD matrices.

    Items that are not numerically positive definite get ``jitter * scale * I`` added, repeatedly
    growing by 10x. Returns the factor and the number of items that needed jitter, so callers can
    count and report the event rather than hide it.
    """
    a = symmetrise(np.asarray(a, dtype=float))
    try:
        return np.linalg.cholesky(a), 0
    except np.linalg.LinAlgError:
        pass
    out = np.empty_like(a)
    n = a.shape[-1]
    flat = a.reshape(-1, n, n)
    out_flat = out.reshape(-1, n, n)
    fixed = 0
    scale = np.maximum(np.abs(np.diagonal(flat, axis1=1, axis2=2)).max(axis=1), 1.0)
    for i in range(flat.shape[0]):  # only the rare failing items reach this loop
        try:
            out_flat[i] = np.linalg.cholesky(flat[i])
            continue
        except np.linalg.LinAlgError:
            fixed += 1
        eps = jitter * scale[i]
        while True:
            try:
                out_flat[i] = np.linalg.cholesky(flat[i] + eps * np.eye(n))
                break
            except np.linalg.LinAlgError:
                eps *= 10.0
    return out, fixed


def joseph_update(p_prior: np.ndarray, gain: np.ndarray, h: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Joseph-form covariance update ``(I - K H) P (I - K H)^T + K R K^T``.

    Algebraically equal to ``(I - K H) P`` for the optimal gain, but stays symmetric positive
    definite under round-off.

    Shapes: ``p_prior (B, n, n)``, ``gain (B, n, m)``, ``h (B, m, n)`` or ``(m, n)``, ``r (B, m, m)`` or
    ``(m, m)``.
    """
    n = p_prior.shape[-1]
    i_kh = np.eye(n) - gain @ h
    return symmetrise(i_kh @ p_prior @ np.swapaxes(i_kh, -1, -2) + gain @ r @ np.swapaxes(gain, -1, -2))


def tria(a: np.ndarray) -> np.ndarray:
    """Lower-triangular square root of ``A A^T`` for ``A (B, n, k)``, by QR of ``A^T``.

    The diagonal is made non-negative so the result is the Cholesky factor of ``A A^T``.
    """
    r = np.linalg.qr(np.swapaxes(a, -1, -2), mode="r")
    s = np.swapaxes(r, -1, -2)[..., : a.shape[-2], : a.shape[-2]]
    sign = np.sign(np.diagonal(s, axis1=-2, axis2=-1))
    sign = np.where(sign == 0, 1.0, sign)
    return s * sign[..., None, :]


def cholupdate(s: np.ndarray, u: np.ndarray, sign: float | np.ndarray = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Rank-1 update (``sign > 0``) or downdate (``sign < 0``) of a lower Cholesky factor.

    Returns ``S'`` with ``S' S'^T = S S^T + sign * u u^T``, computed by the standard O(n^2) sweep over
    the columns, vectorised over the batch.  ``sign`` may be a scalar or ``(B,)``; its magnitude
    scales ``u`` by ``sqrt(|sign|)``.

    Where a downdate would make the factor indefinite, that item falls back to a Cholesky
    factorisation of ``S S^T - u u^T`` (with jitter).  The second return value is a ``(B,)`` bool
    mask of the items that took the fallback, so that callers count and report them.

    Shapes: ``s (B, n, n)``, ``u (B, n)``.
    """
    s = np.array(s, dtype=float, copy=True)
    u = np.asarray(u, dtype=float)
    sign = np.broadcast_to(np.asarray(sign, dtype=float), (s.shape[0],))
    x = u * np.sqrt(np.abs(sign))[:, None]
    sgn = np.where(sign < 0, -1.0, 1.0)
    s_orig = s.copy()
    failed = np.zeros(s.shape[0], dtype=bool)
    n = s.shape[-1]
    for k in range(n):
        skk = s[:, k, k]
        r2 = skk * skk + sgn * x[:, k] * x[:, k]
        bad = r2 <= 0.0
        failed |= bad
        r = np.sqrt(np.where(bad, 1.0, r2))
        skk_safe = np.where(skk == 0.0, 1.0, skk)
        c = r / skk_safe
        sn = x[:, k] / skk_safe
        s[:, k, k] = r
        if k + 1 < n:
            col = (s[:, k + 1:, k] + sgn[:, None] * sn[:, None] * x[:, k + 1:]) / c[:, None]
            x[:, k + 1:] = c[:, None] * x[:, k + 1:] - sn[:, None] * col
            s[:, k + 1:, k] = col
    if failed.any():
        s0 = s_orig[failed]
        xf = u[failed] * np.sqrt(np.abs(sign[failed]))[:, None]
        target = s0 @ np.swapaxes(s0, -1, -2) + sgn[failed, None, None] * np.einsum("bi,bj->bij", xf, xf)
        s[failed], _ = safe_cholesky(target, jitter=1e-12)
    return s, failed


def mahalanobis_sq(residual: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``r^T C^{-1} r`` for ``residual (..., m)`` and ``cov (..., m, m)``."""
    sol = psd_solve(cov, residual[..., None])[..., 0]
    return np.einsum("...i,...i->...", residual, sol)
