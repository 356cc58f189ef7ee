"""Track-before-detect particle weights: every particle against every gated detection, weighted by each detection's
own SNR.

For run ``b``, particle ``i`` and valid measurement ``m``::

    log w_{m,i} = c_m - a_m |p_m - p_i|^2 - beta (vr_m - vr_i)^2
    c_m  = log P_D(snr_m) - 3/2 log(2 pi sigma_p,m^2) - 1/2 log(2 pi sigma_vr^2)
    a_m  = 1 / (2 sigma_p,m^2),   beta = 1 / (2 sigma_vr^2)

and the kernels return ``log sum_m w_{m,i}`` (``-inf`` for a run with no valid measurement), computed
as a streaming max/sum over ``m`` so that memory stays ``O(B N + M)``: no ``(B, N, M)`` array is formed.

Backends (all held to :func:`workbench_filters.tbd.reference.tbd_log_weight_sums_reference`):

- ``"taichi"``: one particle per parallel iteration, two streaming passes over ``m`` (an integer max,
  which LLVM vectorises, then the sum of exponentials); runs on any Taichi arch.
- ``"numba"`` (the CPU default): particles in tiles of :data:`TILE`, a one-pass online logsumexp
  vectorised across the particles of a tile; CPU only.
- ``"numpy"``: the chunked NumPy reference (``float32``: :func:`.tbd_weights_numpy.tbd_log_weight_sums_float32`,
  the single-precision arithmetic in NumPy).
- ``"auto"``: Numba when the arch is the CPU and Numba is installed, else Taichi.

Precision (``precision=``): ``"float64"`` (the default) or ``"float32"``, on every backend.  The arithmetic is
in base 2 (log-weights pre-multiplied by ``log2 e``, then ``2^x``) with a polynomial ``2^x`` inlined in the
loop (a ``libm`` call would stop the loop from vectorising): degree 11 in float64 (relative error below
1e-14), degree 6 in float32 (about one float32 ulp).  In float64 each pair costs five multiply-adds for its
log-weight (the squared distance expanded about the particles' mean, :mod:`.tbd_weights_numpy`); in float32
the differences are formed directly, which keeps single precision accurate.  Float32 runs twice as many
numbers per vector instruction and a shorter polynomial; its log-sums carry float32 round-off (about
``1e-6`` relative, growing with the number of measurements summed), which moves normalised particle weights
by far less than :data:`FLOAT32_WEIGHT_RTOL` (tested on realistic scenes); the returned array is float64 either
way.

Kernels take plain arrays; Taichi and Numba are imported and started on first use only.  (No ``from __future__
import annotations`` here: Taichi reads the kernel annotations as objects.)
"""

import numpy as np

from workbench.kernels.backend import BACKENDS, current_arch, numba_available, resolve, runs_numba, threaded
from workbench.kernels.runtime import ensure_taichi

from .reference import tbd_log_weight_sums_reference
from .tbd_weights_numpy import (EXP_FLOOR, LOG2E, PRECISIONS, SERIAL_PAIRS, TILE, _origin,  # noqa: F401
                                pack_measurements, pack_points, poly_exp, poly_exp2, tbd_log_weight_sums_float32)

__all__ = [
    "BACKENDS",
    "PRECISIONS",
    "TILE",
    "FLOAT32_WEIGHT_RTOL",
    "numba_available",
    "resolve_backend",
    "pack_points",
    "pack_measurements",
    "poly_exp",
    "poly_exp2",
    "tbd_log_weight_sums",
]

#: The stated tolerance of the float32 variant: on every particle whose normalised weight is at least 1e-12 of the
#: largest, ``|w32 - w64| <= FLOAT32_WEIGHT_RTOL * w64`` after normalisation over the particles of a run.  Measured
#: on realistic track-before-detect scenes (tests/test_kernels.py): about 5e-6, every backend.  The error grows with the size
#: of the log-weights that dominate a particle's sum (float32 keeps about 7 digits of ``c_m - a_m d^2 - ...``), so a
#: particle whose best detection lies thousands of sigmas away has a log-sum, not a weight, of float32 accuracy.
FLOAT32_WEIGHT_RTOL = 1e-4


def resolve_backend(backend: str = "auto", arch: str | None = None) -> str:
    """The backend ``"auto"`` stands for (:func:`workbench.kernels.backend.resolve`)."""
    return resolve(backend, arch)


#: From this many particles (all runs together) the compiled packing runs threaded.
SERIAL_PACK = 1 << 16


def _pack_points(points: np.ndarray, sigma_vr: float, precision: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pack_points` for the compiled kernels: compiled where the policy runs Numba on the host CPU (the same
    rows and origin bit for bit, :mod:`.tbd_weights_numba`'s ``mean_position``, ``pack64`` and ``pack32``; NumPy's
    passes over strided views cost as much as the float64 kernel itself on a GPU at 10^6 particles), else the NumPy
    function.  The origin is summed compiled for C-ordered particles only, the layout whose order of summation
    NumPy's mean follows particle by particle; another layout gets NumPy's own mean (it may sum pairwise there)."""
    points = np.asarray(points, dtype=np.float64)
    B, N = points.shape[0], points.shape[1]
    if N == 0 or not runs_numba("auto", "cpu"):  # the packing runs on the host, whatever arch the kernel runs on
        return pack_points(points, sigma_vr, precision)
    from . import tbd_weights_numba as nb

    if points.flags.c_contiguous:
        origin = np.empty((B, 3))
        nb.mean_position_compiled(points, origin)
    else:
        origin = _origin(points)
    big = threaded(B * N, SERIAL_PACK)
    if precision == "float32":
        out = np.empty((B, 4, N), dtype=np.float32)
        (nb.pack32_parallel if big else nb.pack32_serial)(points, out, origin)
    else:
        out = np.empty((B, 6, N))
        beta = 0.5 / float(sigma_vr) ** 2
        (nb.pack64_parallel if big else nb.pack64_serial)(points, -beta * LOG2E, out, origin)
    return out, origin


def tbd_log_weight_sums(points: np.ndarray, z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray,
                        sigma_p: np.ndarray, sigma_vr: float, backend: str = "auto", arch: str | None = None,
                        precision: str = "float64") -> np.ndarray:
    """``log sum_m w_{m,i}`` for every particle of every run (eqs 13-14), ``-inf`` where a run has no
    valid measurement.

    Parameters
    ----------
    points : particle ``[x, y, z, vr]`` (radial velocity positive when receding)
    z : measurement ``[x, y, z, vr]``, padded; ``valid`` marks the real rows
    log_pd : ``log P_D(snr_m)``; sigma_p : isotropic position sigma of each measurement (m)
    sigma_vr : radial-velocity sigma (m/s)
    backend, arch : see the module docstring
    precision : ``"float64"`` or ``"float32"`` arithmetic (see the module docstring); the result is float64

    Shapes
    ------
    points : (B, N, 4); z : (B, M, 4); valid, log_pd, sigma_p : (B, M); returns (B, N)
    """
    if precision not in PRECISIONS:
        raise ValueError(f"unknown kernel precision {precision!r}; expected one of {', '.join(PRECISIONS)}")
    which = resolve_backend(backend, arch)
    if which == "numpy":
        if precision == "float32":
            return tbd_log_weight_sums_float32(points, z, valid, log_pd, sigma_p, sigma_vr)
        return tbd_log_weight_sums_reference(points, z, valid, log_pd, sigma_p, sigma_vr)
    single = precision == "float32"
    pts, origin = _pack_points(points, sigma_vr, precision)
    meas, counts = pack_measurements(z, valid, log_pd, sigma_p, sigma_vr, precision, origin)
    B, _, N = pts.shape
    out = np.zeros((B, N))
    # beta / ln 2 for the float32 kernels (the float64 packing carries it)
    beta2 = 0.5 / float(sigma_vr) ** 2 * LOG2E
    if B and N and meas.shape[2]:
        if which == "numba":
            from . import tbd_weights_numba as nb

            big = threaded(B * N * int(counts.max()), SERIAL_PAIRS)  # threaded and serial: the same numbers
            if single:
                (nb.parallel32 if big else nb.serial32)(pts, meas, counts, np.float32(beta2), nb.COEFFS_F32, out)
            else:
                (nb.parallel if big else nb.serial)(pts, meas, counts, nb.COEFFS, out)
        else:
            ensure_taichi(current_arch() if arch is None else arch)
            from .tbd_weights_taichi import _taichi_kernel

            _taichi_kernel(precision)(pts, meas, counts, beta2, out)
    out[counts == 0] = -np.inf
    return out
