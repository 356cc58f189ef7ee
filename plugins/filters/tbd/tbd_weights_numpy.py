"""Constants and array packing shared by every backend of the track-before-detect weight kernel, the NumPy forms
of its polynomial ``exp2`` and its single-precision NumPy twin (no backend imports).  The dispatcher is
:mod:`.tbd_weights`; the reference every backend is held to is :func:`.reference.tbd_log_weight_sums_reference`.

Both precisions work in base 2: every log-weight is packed pre-multiplied by ``log2 e`` so that the kernels take
``2^x`` (no ``x / ln 2`` per pair, and the reduction ``x = n + f`` with ``f = x - round(x)`` is exact) and
return ``ln 2 (top + log2 s)``.

- ``float64``: the log-weight is expanded about a per-item origin ``o`` (the particles' mean), so that each
  pair costs five multiply-adds::

      log2 w_{m,i} = C_m + T_m . q_i + u_m v_i - A_m |q_i|^2 + K_i,   q = p - o,
      T_m = 2 a_m q_m / ln2,  u_m = 2 beta vr_m / ln2,  A_m = a_m / ln2,
      C_m = (c_m - a_m |q_m|^2 - beta vr_m^2) / ln2,   K_i = -beta vr_i^2 / ln2

  (the squares of the differences, ``|q_m - q_i|^2 = |q_m|^2 - 2 q_m . q_i + |q_i|^2``, with the large terms
  rounded once at 1e-16 relative);
- ``float32``: the differences themselves (``(x_m - x_i)^2 + ...``, centred on ``o`` as well), which keep single
  precision accurate where the expansion would cancel.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TILE", "SERIAL_PAIRS", "PRECISIONS", "LN2", "LOG2E", "EXP2_COEFFS", "EXP2_COEFFS_F32", "EXP2_FLOOR",
           "EXP2_FLOOR_F32", "EXP_FLOOR", "poly_exp2", "poly_exp", "pack_points", "pack_measurements",
           "tbd_log_weight_sums_float32"]

#: Particles per tile of the Numba kernel (its per-tile accumulators stay in L1).
TILE = 256

#: Below this many particle-measurement pairs the Numba kernel runs on one thread.
SERIAL_PAIRS = 2_000_000

#: The precisions a kernel call may ask for.
PRECISIONS = ("float64", "float32")

LN2 = math.log(2.0)
LOG2E = 1.0 / LN2
#: Taylor coefficients of ``2^f = exp(f ln 2)``, ``(ln 2)^k / k!`` for k = 11 ... 0 (Horner order): on
#: ``|f| <= 1/2`` the truncation is below 1e-14 relative.
EXP2_COEFFS = tuple(LN2**k / math.factorial(k) for k in range(11, -1, -1))
#: The same to k = 6 for single precision: truncation below 1.3e-7 relative, about one float32 ulp.
EXP2_COEFFS_F32 = tuple(LN2**k / math.factorial(k) for k in range(6, -1, -1))
#: Arguments of ``2^x`` below this are clamped (the smallest normal's exponent, per precision).
EXP2_FLOOR = -1022.0
EXP2_FLOOR_F32 = -126.0
#: The same floor in natural-log units (``exp(EXP_FLOOR)`` is the smallest value the float64 kernels produce).
EXP_FLOOR = EXP2_FLOOR * LN2


def estrin(f, coeffs):
    """``sum_k coeffs[k] f^(d - k)`` (degree ``d = len(coeffs) - 1``, highest power first) by Estrin's scheme, in
    the kernels' grouping: pairs ``(c f + c')`` from the constant term up, pairs of pairs by ``f^2``, then by ``f^4``
    (the degrees of :data:`EXP2_COEFFS` and :data:`EXP2_COEFFS_F32`, 11 and 6, written out).  About four dependent
    multiply-adds deep where Horner's rule is ``d`` deep: the kernels' loops are bound by that latency.  A few more
    multiplies (13 for 11 in degree 11, 8 for 6 in degree 6), counted in the kernels' limits."""
    f2 = f * f
    f4 = f2 * f2
    if len(coeffs) == 12:
        c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11 = coeffs
        return ((((c0 * f + c1) * f2 + (c2 * f + c3)) * f4 + ((c4 * f + c5) * f2 + (c6 * f + c7))) * f4
                + ((c8 * f + c9) * f2 + (c10 * f + c11)))
    if len(coeffs) == 7:
        s0, s1, s2, s3, s4, s5, s6 = coeffs
        return (s0 * f2 + (s1 * f + s2)) * f4 + ((s3 * f + s4) * f2 + (s5 * f + s6))
    raise ValueError(f"estrin: degree {len(coeffs) - 1} is not written out (11 and 6 are)")


def poly_exp2(x: np.ndarray, precision: str = "float64") -> np.ndarray:
    """The kernels' ``2^x`` for ``x <= 0`` in NumPy (same steps), for tests and documentation.

    ``x = n + f`` with ``n`` the whole number nearest ``x`` (for ``x <= 0``: ``x - 1/2`` truncated toward zero, one
    conversion instruction in the kernels; halves round down), ``|f| <= 1/2``; ``2^f`` by the polynomial, ``2^n`` by
    writing the biased exponent into the bits of the result; the polynomial by Estrin's scheme (:func:`estrin`).
    Shapes: any -> same.
    """
    if precision == "float32":
        dt, itype, coeffs, floor, bias, shift = np.float32, np.int32, EXP2_COEFFS_F32, EXP2_FLOOR_F32, 127, 23
    else:
        dt, itype, coeffs, floor, bias, shift = np.float64, np.int64, EXP2_COEFFS, EXP2_FLOOR, 1023, 52
    x = np.maximum(np.asarray(x, dtype=dt), dt(floor))
    n = np.trunc(x - dt(0.5)).astype(itype)
    f = x - n.astype(dt)
    p = estrin(f, [dt(c) for c in coeffs])
    # 2^n: the biased exponent n + bias in the exponent bits of an IEEE float
    return p * ((n + bias) << shift).view(dt)


def poly_exp(x: np.ndarray) -> np.ndarray:
    """``exp(x) = 2^(x log2 e)`` by :func:`poly_exp2` (float64), for ``x <= 0``.  Shapes: any -> same."""
    return poly_exp2(np.asarray(x, dtype=float) * LOG2E)


def _origin(points: np.ndarray) -> np.ndarray:
    """The per-item origin of the packed coordinates: the mean particle position ``(B, 3)``."""
    return points[:, :, :3].mean(axis=1) if points.shape[1] else np.zeros((points.shape[0], 3))


def pack_points(points: np.ndarray, sigma_vr: float = 1.0, precision: str = "float64",
                origin: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Particles as contiguous structure-of-arrays rows, centred on ``origin`` (default: their mean position).

    float64: rows ``[q_x, q_y, q_z, vr, |q|^2, K]`` with ``K = -beta vr^2 / ln 2``; float32: ``[q_x, q_y, q_z, vr]``.

    Shapes: ``points (B, N, 4)`` -> ``(B, 6, N)`` float64 or ``(B, 4, N)`` float32, and the origin ``(B, 3)``.
    """
    points = np.asarray(points, dtype=np.float64)
    origin = _origin(points) if origin is None else np.asarray(origin, dtype=np.float64)
    q = np.swapaxes(points, 1, 2)  # (B, 4, N) view
    if precision == "float32":
        out = np.empty((points.shape[0], 4, points.shape[1]), dtype=np.float32)
        np.subtract(q[:, :3], origin[:, :, None], out=out[:, :3], casting="same_kind")
        out[:, 3] = q[:, 3]
        return out, origin
    beta = 0.5 / float(sigma_vr) ** 2
    out = np.empty((points.shape[0], 6, points.shape[1]))
    np.subtract(q[:, :3], origin[:, :, None], out=out[:, :3])
    out[:, 3] = q[:, 3]
    out[:, 4] = np.sum(out[:, :3] ** 2, axis=1)
    # K_i = -beta vr_i^2 / ln 2
    out[:, 5] = (-beta * LOG2E) * q[:, 3] ** 2
    return out, origin


def pack_measurements(z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray, sigma_p: np.ndarray, sigma_vr: float,
                      precision: str = "float64", origin: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Valid measurements moved to the front, as packed rows, plus their counts.

    ``c_m = log P_D - 3/2 log(2 pi sigma_p^2) - 1/2 log(2 pi sigma_vr^2)`` and ``a_m = 1 / (2 sigma_p^2)``, then
    with ``q_m = p_m - origin`` (default origin: zero):

    - float64: rows ``[T_x, T_y, T_z, u, -A, C]`` (see the module docstring);
    - float32: rows ``[q_x, q_y, q_z, vr, c_m / ln 2, a_m / ln 2]``.

    Shapes
    ------
    z : (B, M, 4); valid, log_pd, sigma_p : (B, M); origin : (B, 3)
    returns : ``meas (B, 6, M')`` with ``M' = max count`` and ``counts (B,)`` int32
    """
    valid = np.asarray(valid, dtype=bool)
    B, M = valid.shape
    counts = valid.sum(axis=1).astype(np.int32)
    width = int(counts.max()) if B and M else 0
    live = np.arange(width) < counts[:, None]  # (B, M'): the packed rows that hold a measurement
    if np.array_equal(valid[:, :width], live):
        # the valid rows are in front already (a gated scan): the packing is the first M' rows, no gather
        take = lambda a: np.asarray(a, dtype=np.float64)[:, :width]  # noqa: E731
        zz = np.asarray(z, dtype=np.float64)[:, :width]
    else:
        order = np.argsort(~valid, axis=1, kind="stable")[:, :width]  # valid rows first, in their order
        take = lambda a: np.take_along_axis(np.asarray(a, dtype=np.float64), order, axis=1)  # noqa: E731
        zz = np.take_along_axis(np.asarray(z, dtype=np.float64), order[..., None], axis=1)
    origin = np.zeros((B, 3)) if origin is None else np.asarray(origin, dtype=np.float64)
    q = np.swapaxes(zz[..., :3] - origin[:, None, :], 1, 2)  # (B, 3, M')
    vr = zz[..., 3]
    var_p = take(sigma_p) ** 2
    # c_m = log P_D - 3/2 log(2 pi sigma_p^2) - 1/2 log(2 pi sigma_vr^2);  a_m = 1 / (2 sigma_p^2)
    c = take(log_pd) - 1.5 * np.log(2.0 * np.pi * var_p) - 0.5 * np.log(2.0 * np.pi * sigma_vr**2)
    a = 0.5 / var_p
    beta = 0.5 / float(sigma_vr) ** 2
    meas = np.empty((B, 6, width))
    if precision == "float32":
        meas[:, :3] = q
        meas[:, 3] = vr
        meas[:, 4] = c * LOG2E
        meas[:, 5] = a * LOG2E
    else:
        # T = 2 a q / ln2, u = 2 beta vr / ln2, -A = -a / ln2, C = (c - a |q|^2 - beta vr^2) / ln2
        meas[:, :3] = (2.0 * LOG2E) * a[:, None, :] * q
        meas[:, 3] = (2.0 * beta * LOG2E) * vr
        meas[:, 4] = -LOG2E * a
        meas[:, 5] = LOG2E * (c - a * np.sum(q**2, axis=1) - beta * vr**2)
    meas = np.where(live[:, None, :], meas, 0.0)  # padding: harmless finite values, never read
    dt = np.float32 if precision == "float32" else np.float64
    return np.ascontiguousarray(meas, dtype=dt), counts


def tbd_log_weight_sums_float32(points: np.ndarray, z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray,
                                sigma_p: np.ndarray, sigma_vr: float, chunk: int = 2048) -> np.ndarray:
    """The single-precision NumPy twin: the float32 kernels' arithmetic (centred differences, base 2, a max shift)
    in float32 NumPy, chunked over particles; returned as float64 (values of float32 accuracy).

    Shapes: as :func:`.reference.tbd_log_weight_sums_reference`: ``points (B, N, 4)`` ... -> ``(B, N)``.
    """
    points = np.asarray(points, dtype=np.float64)
    pts, origin = pack_points(points, sigma_vr, "float32")
    meas, counts = pack_measurements(z, valid, log_pd, sigma_p, sigma_vr, "float32", origin)
    beta2 = np.float32(0.5 / float(sigma_vr) ** 2 * LOG2E)
    B, _, N = pts.shape
    out = np.full((B, N), -np.inf)
    for b in range(B):
        k = int(counts[b])
        if k == 0:
            continue
        mx, my, mz, mv, mc, ma = (meas[b, r, :k][None, :] for r in range(6))
        for lo in range(0, N, chunk):
            px, py, pz, pv = (pts[b, r, lo:lo + chunk][:, None] for r in range(4))
            # log2 w = c/ln2 - (a/ln2) |q_m - q_i|^2 - (beta/ln2) (vr_m - vr_i)^2
            lw = mc - ma * ((mx - px) ** 2 + (my - py) ** 2 + (mz - pz) ** 2) - beta2 * (mv - pv) ** 2
            top = lw.max(axis=1, keepdims=True)
            s = poly_exp2(lw - top, "float32").sum(axis=1, dtype=np.float32)
            out[b, lo:lo + chunk] = LN2 * (top[:, 0].astype(np.float64) + np.log2(s).astype(np.float64))
    return out
