"""Track-before-detect particle weights: every particle against every gated detection, weighted by each detection's
own SNR.

For run ``b``, particle ``i`` and valid measurement ``m``::

    log w_{m,i} = c_m - a_m |p_m - p_i|^2 - beta (vr_m - vr_i)^2
    c_m  = log P_D(snr_m) - 3/2 log(2 pi sigma_p,m^2) - 1/2 log(2 pi sigma_vr^2)
    a_m  = 1 / (2 sigma_p,m^2),   beta = 1 / (2 sigma_vr^2)

and the kernels return ``log sum_m w_{m,i}`` (``-inf`` for a run with no valid measurement), computed
as a streaming max/sum over ``m`` so that memory stays ``O(B N + M)``: no ``(B, N, M)`` array is formed.

Backends (all held to :func:`workbench.kernels.reference.tbd_log_weight_sums_reference`):

- ``"taichi"``: one particle per parallel iteration, two streaming passes over ``m`` (an integer max,
  which LLVM vectorises, then the sum of exponentials); runs on any Taichi arch.
- ``"numba"`` (the CPU default): particles in tiles of :data:`TILE`, a one-pass online logsumexp
  vectorised across the particles of a tile; CPU only.
- ``"numpy"``: the chunked NumPy reference.
- ``"auto"``: Numba when the arch is the CPU and Numba is installed, else Taichi.

Both compiled kernels use the same inlined polynomial ``exp`` (:func:`poly_exp`): range reduction
``x = n ln2 + r`` with ``|r| <= ln2 / 2``, a degree-11 Taylor polynomial in Horner form (relative error
below 1e-14) and ``2^n`` built by writing ``n + 1023`` into the exponent bits.  A call to ``libm``
would stop the loop from vectorising.  Kernels take plain arrays; Taichi and Numba are imported and
started on first use only.  (No ``from __future__ import annotations`` here: Taichi reads the kernel
annotations as objects.)
"""

import numpy as np

from .backend import BACKENDS, current_arch, numba_available, resolve
from .reference import tbd_log_weight_sums_reference
from .runtime import ensure_taichi
from .tbd_weights_numpy import (EXP_COEFFS, EXP_FLOOR, INV_LN2, LN2_HI, LN2_LO, SERIAL_PAIRS, TILE,  # noqa: F401
                                pack_measurements, pack_points, poly_exp)

__all__ = [
    "BACKENDS",
    "TILE",
    "numba_available",
    "resolve_backend",
    "pack_points",
    "pack_measurements",
    "poly_exp",
    "tbd_log_weight_sums",
]


def resolve_backend(backend: str = "auto", arch: str | None = None) -> str:
    """The backend ``"auto"`` stands for (:func:`workbench.kernels.backend.resolve`)."""
    return resolve(backend, arch)


def tbd_log_weight_sums(points: np.ndarray, z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray,
                        sigma_p: np.ndarray, sigma_vr: float, backend: str = "auto", arch: str | None = None) -> np.ndarray:
    """``log sum_m w_{m,i}`` for every particle of every run (eqs 13-14), ``-inf`` where a run has no
    valid measurement.

    Parameters
    ----------
    points : particle ``[x, y, z, vr]`` (radial velocity positive when receding)
    z : measurement ``[x, y, z, vr]``, padded; ``valid`` marks the real rows
    log_pd : ``log P_D(snr_m)``; sigma_p : isotropic position sigma of each measurement (m)
    sigma_vr : radial-velocity sigma (m/s)
    backend, arch : see the module docstring

    Shapes
    ------
    points : (B, N, 4); z : (B, M, 4); valid, log_pd, sigma_p : (B, M); returns (B, N)
    """
    which = resolve_backend(backend, arch)
    if which == "numpy":
        return tbd_log_weight_sums_reference(points, z, valid, log_pd, sigma_p, sigma_vr)
    pts = pack_points(points)
    meas, counts = pack_measurements(z, valid, log_pd, sigma_p, sigma_vr)
    B, _, N = pts.shape
    out = np.zeros((B, N))
    beta = 0.5 / float(sigma_vr) ** 2
    if B and N and meas.shape[2]:
        if which == "numba":
            parallel, serial = _numba_kernel()
            (parallel if B * N * int(counts.max()) >= SERIAL_PAIRS else serial)(pts, meas, counts, beta, out)
        else:
            ensure_taichi(current_arch() if arch is None else arch)
            _taichi_kernel()(pts, meas, counts, beta, out)
    out[counts == 0] = -np.inf
    return out


def _taichi_kernel():
    from .tbd_weights_taichi import _taichi_kernel as build

    return build()


def _numba_kernel():
    from .tbd_weights_numba import parallel, serial

    return parallel, serial
