"""Bootstrap particle-filter pieces shared by filter plugins, batch-first and log-domain.

Plugins may not import each other, so what more than one particle filter needs lives here: the particle
state, the motion-model proposal (:func:`predict`), the Gaussian log-likelihood of a measurement for every
particle (:func:`log_likelihood`, or with a per-item covariance :func:`log_likelihood_cov`), the weighted
estimate and the counters.

State: :class:`ParticleState` with particles ``(B, N, n)`` and normalised log-weights ``(B, N)``.

Predict: ``x_i <- F x_i + Q_sqrt e_i`` (the motion model is the proposal); for a motion model that overrides ``f``
(not :attr:`~workbench.models.MotionModel.linear`) ``x_i <- f(x_i) + Q_sqrt e_i``, ``f`` called once on all
``(B N, n)`` particles (:func:`propagate_f`), the noise drawn as for a linear model (the same numbers); the compiled
backend runs the model's own compiled propagation where it declares one
(:meth:`~workbench.models.MotionModel.particle_propagator`: ``f`` and the noise in one pass, the NumPy path its
twin), and the NumPy code otherwise.
Likelihood: ``log N(z; h(x_i), R)`` up to a constant, with the residual wrapped for angular components.

Speed: the particle arrays made here are stored component-major (``(n, B, N)`` in memory, seen as
``(B, N, n)``), so that every per-component operation runs over ``B N`` contiguous numbers; the small
matrix products (``F x``, ``Q_sqrt e``, the whitening by ``chol(R)^-1``) are written out one component at a
time, skipping zero entries, instead of calling BLAS on ``(N, 4) x (4, 4)`` shapes.  Any layout of the input
particles is accepted.

Fused: :func:`predict_log_weights` is :func:`predict` and :func:`weighted_log_likelihood` in one compiled pass (a
linear model, or a nonlinear one that declares the pass,
:meth:`~workbench.models.MotionModel.fused_particle_propagator`; the planar range-bearing measurement), the two
calls' numbers bit for bit; for a linear model of the planar state it can also take the predicted state's estimate
(:func:`estimate` with the previous weights, its numbers bit for bit) in the same pass, which the time loop records
at every step.  The bootstrap filter's fused step (``FilterSpec.step``) is built on it.

Backends.  :func:`predict`, :func:`weighted_log_likelihood`, :func:`reweight` and :func:`estimate` take a
``backend`` that the kernel policy resolves (:func:`workbench.kernels.backend.resolve`): ``"numba"`` runs the
compiled twins of :mod:`workbench.kernels.particle_numba` (one pass per step where NumPy makes several, the
propagation noise drawn inside the loop from the same generator, the same numbers), ``"numpy"`` the array code
here, which is the reference the compiled code is held to.  There is no Taichi version: where the policy picks
Taichi (a GPU arch) the NumPy code runs.  The default is ``"numpy"``, so a filter that does not ask gets the
array code; the bootstrap filter asks for ``"auto"``.  With the same seed both give the same particles: the
propagation bit for bit, the weights to float round-off (a polynomial ``exp`` and ``atan2`` within an ulp or
two of the library's, sums in another order), so a resampled particle can differ only when ``N c_i - u_0`` falls
within that round-off of a whole number (about ``N 1e-16`` per particle and step).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .kernels.backend import resolve
from .linalg import safe_cholesky
from .models import MeasurementModel, MotionModel
from .types import Gaussian, InputError, Particles

__all__ = ["ParticleState", "component_major", "combine_columns", "init", "predict", "propagate_f", "noise_columns",
           "log_likelihood", "weighted_log_likelihood", "predict_log_weights", "log_likelihood_cov", "reweight",
           "reweight_estimate", "estimate", "diagnostics", "compiled", "propagation_plan"]


@dataclass(frozen=True)
class ParticleState:
    cloud: Particles
    resamples: int = 0  # total resampling events over the batch
    underflows: int = 0  # updates in which every weight of an item underflowed

    #: The batch-first fields (the counters are the whole batch's; a tracker's take and join keep the first state's).
    batch_fields = ("cloud",)


def component_major(batch: int, particles: int, dim: int) -> np.ndarray:
    """An empty ``(B, N, n)`` array stored as ``(n, B, N)``: each ``x[..., j]`` is one contiguous block."""
    return np.empty((dim, batch, particles)).transpose(1, 2, 0)


@lru_cache(maxsize=64)
def _plan(matrix_bytes: bytes, rows: int, cols: int) -> tuple:
    """Per output row of a ``(rows, cols)`` matrix: its ``(column, coefficient)`` pairs other than one, and
    the columns whose coefficient is one (zeros are skipped)."""
    matrix = np.frombuffer(matrix_bytes, dtype=float).reshape(rows, cols)
    return tuple((tuple((int(j), float(matrix[i, j])) for j in np.flatnonzero((matrix[i] != 0.0) & (matrix[i] != 1.0))),
                  tuple(int(j) for j in np.flatnonzero(matrix[i] == 1.0)))
                 for i in range(rows))


def combine_columns(out: np.ndarray, matrix: np.ndarray, *sources: np.ndarray) -> np.ndarray:
    """``out[..., i] = sum_j matrix[i, j] s[..., j]`` over the columns of ``sources`` side by side.

    The small product ``s @ matrix.T`` written out one output component at a time, skipping zero
    entries and multiplications by one (``x_0 + x_2`` is one pass); ``out`` must not share memory
    with a source.

    Shapes
    ------
    out : (..., r)
    matrix : (r, c) with ``c`` the total trailing size of ``sources``
    sources : (..., c_k) each
    """
    matrix = np.ascontiguousarray(matrix, dtype=float)
    columns = [s[..., j] for s in sources for j in range(s.shape[-1])]
    scratch = None
    for i, (scaled, unit) in enumerate(_plan(matrix.tobytes(), *matrix.shape)):
        col = out[..., i]
        unit = [columns[j] for j in unit]
        if scaled:
            np.multiply(columns[scaled[0][0]], scaled[0][1], out=col)
            for j, coef in scaled[1:]:
                if scratch is None:
                    scratch = np.empty(col.shape)
                np.multiply(columns[j], coef, out=scratch)
                col += scratch
        elif len(unit) >= 2:
            np.add(unit[0], unit[1], out=col)
            unit = unit[2:]
        elif unit:
            np.copyto(col, unit.pop())
        else:
            col[...] = 0.0
        for src in unit:
            col += src
    return out


def compiled(backend: str) -> bool:
    """Whether ``backend`` (``"auto"``, ``"numba"``, ``"numpy"``; the policy of :mod:`workbench.kernels.backend`)
    runs the compiled steps; ``"taichi"`` has none here and runs the NumPy code."""
    return resolve(backend) == "numba"


def _kernels():
    global _KERNELS
    if _KERNELS is None:
        from .kernels import particle_numba

        _KERNELS = particle_numba
    return _KERNELS


_KERNELS = None


def _rows(x: np.ndarray) -> np.ndarray:
    """Particles ``(B, N, n)`` as C-contiguous component rows ``(n, B, N)`` (no copy for a component-major array)."""
    x = np.asarray(x, dtype=float)
    rows = x.transpose(2, 0, 1) if x.ndim == 3 else np.moveaxis(x, -1, 0)
    return rows if rows.flags.c_contiguous else np.ascontiguousarray(rows)


@lru_cache(maxsize=64)
def _plan_arrays(matrix_bytes: bytes, rows: int, cols: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_plan` as flat arrays for the compiled :func:`~workbench.kernels.particle_numba.combine`: per row its
    scaled terms, then its unit ones (coefficient 1), in :func:`combine_columns`' order."""
    src, coef, ptr = [], [], [0]
    for scaled, unit in _plan(matrix_bytes, rows, cols):
        src += [j for j, _ in scaled] + list(unit)
        coef += [c for _, c in scaled] + [1.0] * len(unit)
        ptr.append(len(src))
    out = (np.array(src, dtype=np.int64), np.array(coef, dtype=float), np.array(ptr, dtype=np.int64))
    for a in out:
        a.flags.writeable = False
    return out


def need_rng(rng, who: str = "this particle filter") -> None:
    """:class:`~workbench.types.InputError` when a step that draws random numbers got no generator: there is no
    hidden default stream (every draw comes from an explicit seed)."""
    if rng is None:
        raise InputError(f"{who} draws random numbers but got no generator (rng is None): pass "
                         f"rng=wb.generator(seed, key), e.g. wb.run(filt, scans, motion, model, prior=prior, "
                         f"rng=wb.generator(1, 'runs'))")


def init(prior: Gaussian, rng: np.random.Generator, particles: int) -> ParticleState:
    need_rng(rng, "particle_core.init")
    chol, _ = safe_cholesky(prior.cov)
    e = rng.standard_normal((prior.batch, particles, prior.dim))
    x = component_major(prior.batch, particles, prior.dim)
    # x_i = mean + chol e_i
    x[...] = prior.mean[:, None, :] + np.einsum("bij,bnj->bni", chol, e)
    return ParticleState(Particles.trusted(x, np.full((prior.batch, particles), -np.log(particles))))


def _propagation(motion: MotionModel) -> tuple[np.ndarray, int]:
    """``[F | G]`` for the non-zero noise columns ``G`` of ``Q_sqrt`` (read-only) and their count ``k``, computed
    once per distinct ``(F, Q_sqrt)`` (keyed by their bytes, so a model changed in place is seen)."""
    F = np.ascontiguousarray(motion.F, dtype=float)
    Q = np.ascontiguousarray(motion.Q_sqrt, dtype=float)
    return _propagation_cached(F.tobytes(), Q.tobytes(), F.shape[0], Q.shape[1])


@lru_cache(maxsize=64)
def _propagation_cached(f_bytes: bytes, q_bytes: bytes, n: int, q_cols: int) -> tuple[np.ndarray, int]:
    F = np.frombuffer(f_bytes, dtype=float).reshape(n, n)
    g = _nonzero_columns(np.frombuffer(q_bytes, dtype=float).reshape(n, q_cols))
    matrix = np.ascontiguousarray(np.hstack([F, g]), dtype=float)
    matrix.flags.writeable = False
    return matrix, g.shape[1]


def _nonzero_columns(Q: np.ndarray) -> np.ndarray:
    return Q[:, np.flatnonzero(np.any(Q != 0.0, axis=0))]


def propagation_plan(F: np.ndarray, Q_sqrt: np.ndarray) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """``(k, src, coef, ptr)``: the number ``k`` of non-zero columns ``G`` of ``Q_sqrt`` and the plan of ``[F | G]``
    that the compiled propagations take (:func:`workbench.kernels.particle_numba.combine`: per row its scaled terms,
    then its unit ones, in :func:`combine_columns`' order), for a motion matrix ``F (n, n)`` and ``Q_sqrt (n, q)``
    of a plugin's own (a mode's matrix, say).  Cached per distinct pair (by their bytes); the arrays are read-only."""
    F = np.ascontiguousarray(F, dtype=float)
    Q = np.ascontiguousarray(Q_sqrt, dtype=float)
    matrix, k = _propagation_cached(F.tobytes(), Q.tobytes(), F.shape[0], Q.shape[1])
    return (k, *_plan_arrays(matrix.tobytes(), *matrix.shape))


def noise_columns(motion: MotionModel) -> np.ndarray:
    """The non-zero columns ``G (n, k)`` of ``Q_sqrt``: the noise a particle filter draws is ``G e``, ``e`` of
    length ``k`` (no ``F`` read)."""
    return _nonzero_columns(np.asarray(motion.Q_sqrt, dtype=float))


def propagate_f(x: np.ndarray, motion: MotionModel, who: str = "this particle filter") -> np.ndarray:
    """``f(x_i)`` for particles ``x (B, N, n)``, one call of the model's ``f`` on all ``(B N, n)`` of them;
    returned component-major (:func:`component_major`).  :class:`~workbench.types.InputError` naming ``who`` and
    the model when ``f`` gives another shape."""
    B, N, n = x.shape
    moved = np.asarray(motion.f(np.asarray(x, dtype=float).reshape(B * N, n)), dtype=float)
    if moved.shape != (B * N, n):
        raise InputError(f"{who}: motion model {motion.name!r} gave f of shape {moved.shape} for particles "
                         f"{(B * N, n)}; f must keep the shape (..., n)")
    out = component_major(B, N, n)
    out[...] = moved.reshape(B, N, n)
    return out


def predict(state: ParticleState, motion: MotionModel, rng: np.random.Generator,
            backend: str = "numpy") -> ParticleState:
    """``x_i <- F x_i + Q_sqrt e_i`` with ``e = rng.standard_normal((B, N, k))`` for the ``k`` non-zero columns of
    ``Q_sqrt``; ``backend`` as in the module docstring (the same particles either way).  A model that overrides
    ``f``: ``x_i <- f(x_i) + Q_sqrt e_i``, the same draws: in NumPy (:func:`propagate_f`, then
    :func:`combine_columns` of ``[I | G]``), or, where the backend runs Numba and the model declares a compiled
    propagation (:meth:`~workbench.models.MotionModel.particle_propagator`, e.g. the coordinated turn with the rate
    in the state), by that loop in one pass, which is held to the NumPy path as its twin."""
    need_rng(rng, "particle_core.predict")
    x = state.cloud.particles
    B, N, n = x.shape
    if not motion.linear:
        g = noise_columns(motion)
        run = motion.particle_propagator() if compiled(backend) else None
        if run is not None and (g.shape[1] == 0 or type(rng) is np.random.Generator):
            # the model's declared compiled propagation: f and the noise in one pass, the same draws and sums
            matrix = np.ascontiguousarray(np.hstack([np.eye(n), g]), dtype=float)
            out = np.empty((n, B, N))
            run(out.reshape(n, B * N), _rows(x).reshape(n, B * N), rng, g.shape[1],
                *_plan_arrays(matrix.tobytes(), *matrix.shape))
            return ParticleState(Particles.trusted(out.transpose(1, 2, 0), state.cloud.log_weights), state.resamples,
                                 state.underflows)
        sources = [propagate_f(x, motion, "particle_core.predict")]
        if g.shape[1]:
            sources.append(rng.standard_normal((B, N, g.shape[1])))
        # x_i <- f(x_i) + Q_sqrt e_i: [I | G] applied to [f(x_i), e_i]
        moved = combine_columns(component_major(B, N, n), np.hstack([np.eye(n), g]), *sources)
        return ParticleState(Particles.trusted(moved, state.cloud.log_weights), state.resamples, state.underflows)
    matrix, k = _propagation(motion)
    if compiled(backend):
        out = np.empty((n, B, N))
        plan = _plan_arrays(matrix.tobytes(), *matrix.shape)
        rows = _rows(x).reshape(n, B * N)
        if k == 0 or type(rng) is np.random.Generator:
            # e drawn inside the loop: the numbers of rng.standard_normal((B, N, k)), in that order
            _kernels().propagate(out.reshape(n, B * N), rows, rng, k, *plan)
        else:  # a generator Numba cannot type: NumPy draws, compiled product
            e = np.ascontiguousarray(rng.standard_normal((B, N, k))).reshape(B * N, k)
            _kernels().combine(out.reshape(n, B * N), rows, e, *plan)
        moved = out.transpose(1, 2, 0)
    else:
        # x_i <- F x_i + Q_sqrt e_i, drawing e only for the non-zero columns of Q_sqrt
        sources = [x]
        if k:
            sources.append(rng.standard_normal((B, N, k)))
        moved = combine_columns(component_major(B, N, n), matrix, *sources)
    return ParticleState(Particles.trusted(moved, state.cloud.log_weights), state.resamples, state.underflows)


_SCRATCH = threading.local()


def _scratch(name: str, size: int, dtype=float) -> np.ndarray:
    """A work array of ``size`` entries that this thread reuses from call to call (its contents are garbage):
    the compiled steps' temporaries, whose fresh allocation at every step costs page faults once they pass
    the allocator's thresholds (at ``N = 10^5`` about a fifth of the step).  Never returned to the caller."""
    pool = _SCRATCH.__dict__
    buf = pool.get(name)
    if buf is None or buf.size < size or buf.dtype != dtype:
        buf = pool[name] = np.empty(size, dtype=dtype)
    return buf[:size]


def _inverse_cholesky(R: np.ndarray) -> np.ndarray:
    """``L^-1`` for ``R = L L^T`` (``m x m``, computed once per distinct ``R``)."""
    R = np.ascontiguousarray(R, dtype=float)
    return _inverse_cholesky_cached(R.tobytes(), R.shape[0])


@lru_cache(maxsize=64)
def _inverse_cholesky_cached(r_bytes: bytes, m: int) -> np.ndarray:
    out = np.linalg.inv(np.linalg.cholesky(np.frombuffer(r_bytes, dtype=float).reshape(m, m)))
    out.flags.writeable = False
    return out


def log_likelihood(z: np.ndarray, x: np.ndarray, model: MeasurementModel) -> np.ndarray:
    """``log N(z_b; h(x_bi), R)`` up to a constant, for ``z (B, m)`` and particles ``x (B, N, n)`` -> ``(B, N)``."""
    nu = model.residual(z[:, None, :], model.h(x))
    B, N, m = nu.shape
    # white = L^-1 nu with R = L L^T
    white = combine_columns(np.empty((m, B, N)).transpose(1, 2, 0), _inverse_cholesky(model.R), nu)
    # -1/2 nu^T R^-1 nu = -1/2 |white|^2
    np.square(white, out=white)
    out = white[..., 0].copy() if m == 1 else np.add(white[..., 0], white[..., 1])
    for j in range(2, m):
        out += white[..., j]
    out *= -0.5
    return out


def _plane_range_bearing(model: MeasurementModel, dim: int = 4) -> np.ndarray | None:
    """The sensor position ``(2,)`` when ``model`` declares the planar range-bearing frame (``h(x) = [|p - s|,
    atan2(p_y - s_y, p_x - s_x)]`` for ``p = x[:2]``, the bearing angular) and its ``h`` agrees with that on a
    set of probe points, else ``None``: the compiled likelihood is chosen by what the model declares, and the
    probe keeps a model that declares the frame but computes something else on the general path.  ``dim``: the
    state dimension the probe points have."""
    if model.frame != "range-bearing" or model.sensor_position is None or len(model.sensor_position) != 2 \
            or tuple(model.angular) != (False, True):
        return None
    key = (id(model), int(dim))
    hit = _PROBED.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
    sensor = np.array(model.sensor_position, dtype=float)
    d = _PROBE_OFFSETS
    if dim < 2:
        return None
    probe = np.zeros((1, d.shape[0], int(dim)))
    probe[0, :, :2] = sensor + d
    try:
        got = np.asarray(model.h(probe), dtype=float)
        expect = np.stack([np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2), np.arctan2(d[:, 1], d[:, 0])], axis=-1)[None]
        ok = got.shape == expect.shape and bool(np.allclose(got, expect, rtol=1e-12, atol=1e-12))
    except Exception:  # noqa: BLE001 - a model that cannot take the probe takes the general path
        ok = False
    result = sensor if ok else None
    if len(_PROBED) > 256:
        _PROBED.clear()
    _PROBED[key] = (model, result)
    return result


#: Probe offsets from the sensor (every quadrant, the axes, near and far) for :func:`_plane_range_bearing`.
_PROBE_OFFSETS = np.array([[3.0, 4.0], [-120.0, 35.0], [-7.5, -2e4], [5e3, -0.25], [0.0, 9.0], [-1.0, 0.0],
                           [2e5, 1e5], [1e-3, -1e-3]])
_PROBED: dict = {}


def weighted_log_likelihood(z: np.ndarray, x: np.ndarray, model: MeasurementModel, log_weights: np.ndarray,
                            backend: str = "numpy") -> np.ndarray:
    """``log w_bi + log N(z_b; h(x_bi), R)`` (up to the likelihood's constant): :func:`log_likelihood` plus the
    previous log-weights.  ``backend`` as in the module docstring; the compiled path fuses the planar
    range-bearing model (declared by its ``frame``) into one pass, and runs any other model's ``h`` in NumPy.

    Shapes: ``z (B, m)``, ``x (B, N, n)``, ``log_weights (B, N)`` -> ``(B, N)``.
    """
    sensor = _plane_range_bearing(model, x.shape[-1]) if compiled(backend) else None
    if sensor is None:
        out = log_likelihood(z, x, model)
        out += log_weights
        return out
    rows = _rows(x)
    out = np.empty(np.shape(log_weights))
    _kernels().range_bearing_log_weights(rows[0], rows[1], np.ascontiguousarray(z, dtype=float), sensor,
                                         _inverse_cholesky(model.R), np.ascontiguousarray(log_weights, dtype=float),
                                         out)
    return out


def predict_log_weights(state: ParticleState, motion: MotionModel, rng: np.random.Generator, z: np.ndarray,
                        present: np.ndarray, model: MeasurementModel, backend: str = "numpy",
                        scratch: bool = False, predicted_estimate: bool = False) -> tuple | None:
    """:func:`predict` and :func:`weighted_log_likelihood` in one compiled pass, or ``None`` where that pass does not
    apply (then call the two): it needs the compiled backend, a :attr:`~workbench.models.MotionModel.linear` motion
    model or one that declares the fused pass for the frame
    (:meth:`~workbench.models.MotionModel.fused_particle_propagator`, e.g. the coordinated turn with the rate in the
    state), the planar range-bearing measurement model (declared by its frame, as :func:`weighted_log_likelihood`
    requires) and a ``numpy.random.Generator`` (or no noise).  The same draws, particles and log-weights as the two
    calls bit for bit (:func:`~workbench.kernels.particle_numba.propagate_range_bearing` for a linear model,
    :func:`~workbench.kernels.motion_numba.ct_rate_propagate_range_bearing` for the turn).

    Returns the moved particles ``(B, N, n)`` (component-major; ``scratch``: in this thread's work array, valid
    until the next call, for a caller that resamples them into a new array at once), the log-weights ``(B, N)``
    (:func:`weighted_log_likelihood`'s for the items with ``present``, the previous ones for the others) and their
    rows' max ``(B,)`` (``np.max(log_w, axis=1)`` where ``present``, ``-inf`` elsewhere).  ``predicted_estimate``:
    a fourth element, :func:`estimate` of the moved particles with the previous weights (the predicted state's
    estimate, a :class:`~workbench.types.Gaussian`) where the pass takes it (a linear model and the planar state:
    its sums taken in the same pass, :func:`estimate`'s numbers bit for bit), else ``None`` (call :func:`estimate`).

    Shapes: ``z (B, 2)``, ``present (B,)``.
    """
    x = state.cloud.particles
    B, N, n = x.shape
    if not compiled(backend):
        return None
    sensor = _plane_range_bearing(model, n)
    if sensor is None:
        return None
    if motion.linear:
        matrix, k = _propagation(motion)
        run = _kernels().propagate_range_bearing
    else:
        # the model's declared compiled pass (MotionModel.fused_particle_propagator), else the two calls
        run = motion.fused_particle_propagator("range-bearing")
        if run is None:
            return None
        g = noise_columns(motion)
        matrix, k = np.ascontiguousarray(np.hstack([np.eye(n), g]), dtype=float), g.shape[1]
    if k and type(rng) is not np.random.Generator:
        return None
    out = (_scratch("predicted", n * B * N) if scratch else np.empty(n * B * N)).reshape(n, B, N)
    log_w = np.empty((B, N))
    top = np.full(B, -np.inf)
    args = (out.reshape(n, B * N), _rows(x).reshape(n, B * N), rng, k, *_plan_arrays(matrix.tobytes(), *matrix.shape),
            np.ascontiguousarray(present, dtype=bool), np.ascontiguousarray(z, dtype=float), sensor,
            _inverse_cholesky(model.R), np.ascontiguousarray(state.cloud.log_weights, dtype=float), log_w, top)
    if not predicted_estimate:
        run(*args)
        return out.transpose(1, 2, 0), log_w, top
    before = None
    if motion.linear and n == 4 and N > 0:
        # the predicted state's estimate, its sums taken in the same pass (estimate's numbers bit for bit)
        mean, cov = np.empty((B, 4)), np.empty((B, 4, 4))
        run(*args, mean, cov)
        before = Gaussian.trusted(mean, cov)
    else:
        run(*args)
    return out.transpose(1, 2, 0), log_w, top, before


def log_likelihood_cov(z: np.ndarray, x: np.ndarray, model: MeasurementModel, R: np.ndarray) -> np.ndarray:
    """``log N(z_b; h(x_bi), R_b)`` for a per-item covariance ``R (B, m, m)``, including the normalising
    ``-(m log 2 pi + log |R_b|) / 2``; ``z (B, m)``, ``x (B, N, n)`` -> ``(B, N)``."""
    nu = model.residual(z[:, None, :], model.h(x))
    L = np.linalg.cholesky(R)
    # white = L_b^-1 nu (one triangular solve per item for all its particles)
    white = np.linalg.solve(L, np.swapaxes(nu, 1, 2))
    m = nu.shape[-1]
    log_det = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)
    return -0.5 * np.einsum("bmn,bmn->bn", white, white) - 0.5 * (m * np.log(2.0 * np.pi) + log_det)[:, None]


def reweight(particles: np.ndarray, log_w: np.ndarray, previous: np.ndarray, present: np.ndarray, threshold: float,
             rng: np.random.Generator, backend: str = "numpy", top: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Normalise, and resample where the effective sample size is low: the end of a bootstrap update.

    Items with ``present``: ``log_w`` normalised (an item whose every weight underflowed, or that holds a NaN or
    ``+inf``, keeps ``previous`` and is counted as ``dead``); items without: ``previous``.  Then the items with
    ``present`` and ``N_eff < threshold N`` (every such item when ``threshold > 1``) are resampled
    systematically (:func:`workbench.resampling.resample_where`: one offset ``u_0 ~ U[0, 1)`` per resampled item,
    drawn as ``rng.random((R, 1))``) and get weights ``1/N``.  ``backend`` as in the module docstring.  ``top``:
    ``np.max(log_w, axis=1)`` where the caller has it (:func:`predict_log_weights`), the rows of items without
    ``present`` ignored.

    Shapes: ``particles (B, N, n)``; ``log_w, previous (B, N)``; ``present (B,)`` ->
    ``particles (B, N, n)`` (component-major), ``log_w (B, N)``, ``resampled (B,)``, ``dead (B,)``.
    """
    from .resampling import effective_sample_size, normalise_log_weights, resample_where

    need_rng(rng, "particle_core.reweight")
    B, N = np.shape(log_w)
    # contiguous: a strided mask (a column of a scan's batch) would compile the kernels a second time
    present = np.ascontiguousarray(present, dtype=bool)
    if top is None:
        top = np.max(log_w, axis=1)
    if not compiled(backend):
        # every weight of an item underflowed (or a NaN/inf crept in): its max is not finite
        dead = present & ~np.isfinite(top)
        log_w = normalise_log_weights(log_w, fallback=previous)
        if not present.all():
            log_w = np.where(present[:, None], log_w, previous)
        # N_eff <= N, so a threshold above one resamples every item with a measurement
        resample = present if threshold > 1.0 else present & (effective_sample_size(log_w) < threshold * N)
        x, log_w = resample_where(resample, particles, log_w, rng)
        return x, log_w, resample, dead
    k = _kernels()
    previous = np.ascontiguousarray(previous, dtype=float)
    if threshold > 1.0:
        # every present item is resampled, so its normalised weights are never kept: the CDF comes from
        # exp(log_w - max) directly (the twin's exp(normalised - max) up to round-off), a dead item's from its
        # previous weights, as the twin's fallback gives
        resample = present
        dead = present & ~np.isfinite(top)
        weights = log_w
        if dead.any():
            weights = np.where(dead[:, None], previous, log_w)
            top = np.max(weights, axis=1)
        # the weights after resampling, 1/N, written once here
        out = np.where(present[:, None], -np.log(N), previous) if not present.all() else np.full((B, N), -np.log(N))
    else:
        out = np.empty((B, N))
        dead = np.empty(B, dtype=bool)
        k.normalise(log_w, top, present, previous, out, dead)
        weights, top = out, np.max(out, axis=1)
        ess = k.effective_sample_size(out, top, np.empty(B))
        resample = present & (ess < threshold * N)
    if not resample.any():
        return particles, out, resample, dead
    rows = np.flatnonzero(resample)
    u0 = rng.random((rows.size, 1))
    src = _rows(particles)
    n = src.shape[0]
    moved = np.empty((n, B, N))
    k.systematic_gather(np.ascontiguousarray(weights, dtype=float), top, rows, u0[:, 0], src, moved,
                        _scratch("cdf", N), _scratch("parent", N + 1, np.int64))
    if threshold <= 1.0:
        out[rows] = -np.log(N)
    return moved.transpose(1, 2, 0), out, resample, dead


def reweight_estimate(particles: np.ndarray, log_w: np.ndarray, previous: np.ndarray, present: np.ndarray,
                      threshold: float, rng: np.random.Generator, backend: str = "numpy",
                      top: np.ndarray | None = None):
    """:func:`reweight` and :func:`estimate` of its result in one pass over the resampled particles, or ``None`` where
    that pass does not apply (then call the two): it needs the compiled backend, resampling at every update
    (``threshold > 1``), a measurement for every item and the planar state (``n = 4``).  The gather sums each tile
    of particles it has written while the tile is in L1
    (:func:`~workbench.kernels.particle_numba.systematic_gather_moments`), the tiles and sums of
    :func:`~workbench.kernels.particle_numba.moments`, so the numbers are the two calls' bit for bit: the same draw
    of the offsets, particles, weights, counters and estimate.

    Returns ``(particles, log_w, resampled, dead, estimate)`` (:func:`reweight`'s, then a
    :class:`~workbench.types.Gaussian`).  Shapes as :func:`reweight`'s.
    """
    B, N = np.shape(log_w)
    present = np.asarray(present, dtype=bool)
    if not compiled(backend) or not threshold > 1.0 or not present.all() or np.shape(particles)[-1] != 4 or N == 0:
        return None
    need_rng(rng, "particle_core.reweight_estimate")
    previous = np.ascontiguousarray(previous, dtype=float)
    if top is None:
        top = np.max(log_w, axis=1)
    # as reweight: an item whose every weight underflowed (or holds a NaN/inf) is resampled from its previous weights
    dead = ~np.isfinite(top)
    weights = log_w
    if dead.any():
        weights = np.where(dead[:, None], previous, log_w)
        top = np.max(weights, axis=1)
    u0 = rng.random((B, 1))
    src = _rows(particles)
    moved = np.empty((4, B, N))
    mean = np.empty((B, 4))
    cov = np.empty((B, 4, 4))
    lw_equal = -np.log(N)
    _kernels().systematic_gather_moments(np.ascontiguousarray(weights, dtype=float), np.ascontiguousarray(top), u0[:, 0],
                                         src, moved, _scratch("cdf", N), _scratch("parent", N + 1, np.int64),
                                         lw_equal, mean, cov)
    return (moved.transpose(1, 2, 0), np.full((B, N), lw_equal), present, dead, Gaussian.trusted(mean, cov))


def estimate(state: ParticleState, backend: str = "numpy") -> Gaussian:
    """Weighted mean and covariance of each item's particles (``Particles.to_gaussian``); ``backend`` as in the
    module docstring."""
    if not compiled(backend):
        return state.cloud.to_gaussian()
    x = _rows(state.cloud.particles)
    n, B, N = x.shape
    mean = np.empty((B, n))
    cov = np.empty((B, n, n))
    _kernels().moments(x, np.ascontiguousarray(state.cloud.log_weights, dtype=float), mean, cov, _scratch("w", N))
    return Gaussian.trusted(mean, cov)


def diagnostics(state: ParticleState) -> dict:
    return {"resamples": state.resamples, "weight_underflows": state.underflows}


