"""One fused step of the cost-reference particle filter for a range-bearing sensor.

For every run ``b`` (one parallel iteration each) and its ``N`` particles, with the measurement
``z_b = [r, theta]`` of a sensor at ``s``, ``h(x) = [|p - s|, atan2(p_y - s_y, p_x - s_x)]``, each particle's
propagation variance ``sigma^2`` and this step's index ``t >= 1``::

    dC(x | z)  = (dr^2 + (a dtheta)^2)^(q/2),  dtheta wrapped to (-pi, pi], a = 1 or |r| (arc-length)
    R^(i)      = lam C^(i) + dC(F x^(i) | z)                     risk, noise-free prediction
    delta_R    = delta, or delta * (mean_i R^(i) - min_k R^(k))  (relative: scale-free in the cost)
    pi^(i)    ~  (R^(i) - min_k R^(k) + delta_R)^-beta            selection PMF
    k_i        = systematic counts of pi with offset u0_b        (ceil(N cdf_i - u0) differences)
    x'^(j)     = F x^(p) + shape * sigma^(p) e^(j)               propagation, p = parent of j, e standard normal
    s'^(j)     = ((t-1)/t) sigma^2(p) + ||(x'^(j) - F x^(p)) / shape||^2 / (t n)   adaptive (running variance),
                 or sigma^2(p) (fixed variance)
    C'^(j)     = lam C^(p) + dC(x'^(j) | z)                       cost update
    pi'^(j)   ~  (C'^(j) - min C' + delta_C)^-beta,  mean = sum pi' x',  cov = sum pi' (x' - mean)(.)^T

The randomness comes from the caller: ``u0 (B,)`` uniforms in [0, 1) and a stream ``key`` of counter-based
normals (:mod:`workbench.kernels.counter_normals`: a float32 Box-Muller, its values stored as float64),
``e[b] = counter_normals(key, B, N n)[b]`` reshaped to ``(N, n)``; the Numba kernel computes them in place,
vectorised, the other backends take them from the NumPy twin (the same bits).  So all backends give the same
particles up to float round-off.  A row whose risks
contain NaN, or are all infinite, is selected uniformly (as :func:`workbench.resampling.systematic_counts`
does); an infinite risk gets weight zero.

Backends (held to :func:`crpf_step_numpy`, which is written with the workbench's log-domain PMF,
:func:`workbench.resampling.systematic_counts` and the measurement model's ``h``):

- ``"taichi"``: one run per parallel iteration, any Taichi arch;
- ``"numba"`` (the CPU default): the same loops with ``numba.prange`` over runs, CPU only;
- ``"numpy"``: :func:`crpf_step_numpy`;
- ``"auto"``: Numba when the arch is the CPU and Numba is installed, else Taichi
  (the policy of :mod:`workbench.kernels.backend`).

Shapes: ``x (B, N, n)`` with position ``x, y`` first, ``c (B, N)``, ``s2 (B, N)``, ``t (B,)`` (or a scalar),
``F (n, n)``, ``z (B, 2)``, ``key`` an unsigned 64-bit int, ``u0 (B,)``, ``shape (n,)`` -> ``x' (B, N, n)``,
``C' (B, N)``, ``s2' (B, N)``, ``mean (B, n)``, ``cov (B, n, n)``.  (No ``from __future__ import annotations``:
Taichi reads the annotations as objects.)
"""

import numpy as np

from workbench.kernels.atan_poly import atan2_poly  # the kernels' atan2's NumPy twin, exported for its tests
from workbench.kernels.backend import current_arch, numba_available, resolve as resolve_backend
from workbench.kernels.runtime import ensure_taichi

from .crpf_step_numpy import _check, crpf_step_numpy, pmf_offset, propagation_normals

__all__ = ["crpf_step", "crpf_step_numpy", "numba_available", "pmf_offset", "propagation_normals", "resolve_backend",
           "atan2_poly"]


def crpf_step(x, c, s2, t, F, z, key, u0, shape, lam, beta, delta, q=2.0, arc=False, sensor=(0.0, 0.0),
              adaptive=True, relative=True, backend="auto", arch=None):
    """One CRPF step (risk, selection, propagation, variance, cost, estimate) for every run; see the module docstring.

    Parameters
    ----------
    x, c, s2 : particles, costs and propagation variances before the step
    t : this step's index (the number of propagations including this one, >= 1 for ``adaptive``)
    F : motion matrix; z : measured ``[range, bearing]`` per run
    key : the stream of the propagation normals (:func:`propagation_normals`); u0 : systematic-resampling
        offsets in [0, 1)
    shape : per-component scale of the propagation noise (all > 0 for ``adaptive``)
    lam, beta, delta, q : forgetting factor, PMF exponent and offset, cost exponent
    arc : arc-length cost (bearing residual times the measured range)
    sensor : sensor position ``(x, y)``
    adaptive : the Table-6 running variance per particle (else each particle keeps its parent's variance)
    relative : ``delta`` is a multiple of the mean gap of the risks (costs) above their minimum
    backend, arch : ``"auto"``, ``"numba"``, ``"taichi"`` or ``"numpy"``; the arch (default: the policy's,
        :mod:`workbench.kernels.backend`)

    Shapes
    ------
    x : (B, N, n); c, s2 : (B, N); t : (B,) or scalar; F : (n, n); z : (B, 2); key : int; u0 : (B,); shape : (n,)
    returns : x' (B, N, n), C' (B, N), s2' (B, N), mean (B, n), cov (B, n, n)
    """
    which = resolve_backend(backend, arch)
    if which == "numpy":
        return crpf_step_numpy(x, c, s2, t, F, z, key, u0, shape, lam, beta, delta, q, arc, sensor, adaptive,
                               relative)
    x, c, s2, t, F, z, u0, shape = _check(x, c, s2, t, F, z, u0, shape)
    B, N, n = x.shape
    x_new = np.empty_like(x)
    c_new = np.empty_like(c)
    s2_new = np.empty_like(s2)
    mean = np.empty((B, n))
    cov = np.empty((B, n, n))
    scratch = np.empty((B, N))
    scal = np.array([lam, beta, delta, q, 1.0 if arc else 0.0, float(sensor[0]), float(sensor[1]),
                     1.0 if adaptive else 0.0, 1.0 if relative else 0.0])
    if B and N:
        if which == "numba":
            _numba_kernel()(x, c, s2, t, F, z, np.uint64(key), u0, shape, scal, x_new, c_new, s2_new, mean, cov,
                            scratch)
        else:
            ensure_taichi(current_arch() if arch is None else arch)
            e = propagation_normals(key, B, N, n)
            _taichi_kernel()(x, c, s2, t, F, z, e, u0, shape, scal, x_new, c_new, s2_new, mean, cov, scratch)
    return x_new, c_new, s2_new, mean, cov


def _numba_kernel():
    global _NUMBA_KERNEL
    if _NUMBA_KERNEL is None:  # imported (and its compiled code loaded) on first use only
        from .crpf_numba import kernel

        _NUMBA_KERNEL = kernel
    return _NUMBA_KERNEL


_NUMBA_KERNEL = None


def _taichi_kernel():
    from .crpf_taichi import _taichi_kernel as build

    return build()
