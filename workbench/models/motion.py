"""Motion models: what filters need to know about dynamics.

A motion model is ``x_k = f(x_{k-1}; t, dt) + w_k``, ``w_k ~ N(0, Q)``, for the step from the absolute time ``t``
to ``t + dt``; ``Q_sqrt`` is an explicit factor ``Q = Q_sqrt Q_sqrt^T`` so that square-root filters never take the
Cholesky factor of a singular Q.  The linear-Gaussian model (``f(x) = F x``) is one case of it and exposes ``F``
(:attr:`MotionModel.linear`); a subclass of :class:`MotionModel` that overrides ``f`` is a nonlinear model: every
built-in filter either follows its ``f`` (and its ``jacobian`` where it needs one) or refuses it by name
(:func:`require_linear`, :func:`require_jacobian`), never reading ``F`` from it.

The time loop binds each step's model with :meth:`MotionModel.at` (``t``: the time at the start of the step,
``dt``: its interval), so filters that call ``motion.f(x)`` and ``motion.jacobian(x)`` propagate with the absolute
time and the interval of the step they serve.

State layout convention: positions first, then velocities (then accelerations), e.g. ``[x, y, vx, vy]`` or
``[x, y, z, vx, vy, vz]``.  Built-in models: :func:`constant_velocity`, :func:`random_walk_velocity`,
:func:`range_rate_model`, :func:`constant_acceleration`, :func:`singer`, :func:`coordinated_turn` (known rate,
linear), :func:`coordinated_turn_rate` (rate in the state, nonlinear) and :func:`growth_model` (the univariate
nonstationary growth model, time-varying); ``docs/motion-models.md`` tabulates them.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Callable, ClassVar, Sequence

import numpy as np

from ..types import InputError, _replaced

__all__ = [
    "MotionModel",
    "require_linear",
    "require_jacobian",
    "constant_velocity",
    "random_walk_velocity",
    "range_rate_model",
    "ExactLinearModel",
    "constant_acceleration",
    "singer",
    "coordinated_turn",
    "CoordinatedTurnRate",
    "coordinated_turn_rate",
    "GrowthModel",
    "growth_model",
]


@dataclass(frozen=True)
class MotionModel:
    """Motion ``x_k = f(x_{k-1}; t, dt) + w_k`` with ``w_k ~ N(0, Q)``: linear (``f(x) = F x``) unless a subclass
    overrides :meth:`f`.

    Shapes: ``F (n, n)``, ``Q (n, n)``, ``Q_sqrt (n, n)`` with ``Q = Q_sqrt Q_sqrt^T``.  ``state_names`` and
    ``state_units`` declare the state's layout (e.g. ``x, y, vx, vy`` in m and m/s), for track files, plots and the
    motion-model kit.

    Time: ``dt`` is the interval of the step the model serves and ``t`` the absolute time (s) at its start.  The
    time loop (:func:`workbench.tracking.run`) and :func:`workbench.sample_motion` bind both for every step with
    :meth:`at` (``motion.at(t_{k-1}, t_k - t_{k-1})``), so a filter that calls ``motion.f(x)`` or
    ``motion.jacobian(x)`` on the model it was handed propagates with the step's absolute time and interval.
    ``f(x, t, dt)`` and ``jacobian(x, t, dt)`` take them explicitly too (``None``: the bound ``self.t`` and
    ``self.dt``); a time-varying model (:class:`GrowthModel`) reads ``t``, a time-invariant one ignores it.

    Nonlinear motion ``x_k = f(x_{k-1}) + w_k``: subclass and override :meth:`f` (vectorised over any leading
    axes ``(..., n)``), and :meth:`jacobian` where filters that linearise (the EKF) should take the model; write
    them as ``f(self, x, t=None, dt=None)`` and read ``self.t`` / ``self.dt`` where an argument is ``None``.  A
    subclass written as ``f(self, x)`` keeps working (filters call ``f`` with the state alone, on the bound
    model), as a model of its own step.  Such a model is not :attr:`linear`, and no built-in filter reads its
    ``F`` (it still has one, its fields being this class's; filters that need a transition matrix refuse the
    model by name).  A subclass whose ``f`` is still ``x F^T`` (e.g. written out for speed) declares
    ``linear = True`` as a class attribute and keeps the exact linear filters and their compiled paths.
    """

    name: str
    F: np.ndarray
    Q: np.ndarray
    Q_sqrt: np.ndarray
    dt: float
    rebuild: Callable[[float], "MotionModel"] | None = field(default=None, compare=False, repr=False)
    state_names: tuple[str, ...] = ()
    state_units: tuple[str, ...] = ()
    #: The absolute time (s) at the start of the step this model serves (bound by :meth:`at`).
    t: float = field(default=0.0, compare=False)

    #: Whether ``F`` and ``Q`` are the exact discretisation of a continuous-time model, so that
    #: ``Q(dt1 + dt2) = F(dt2) Q(dt1) F(dt2)^T + Q(dt2)`` holds (the motion-model kit checks it where ``True``);
    #: ``None``: not declared (the built-in DWNA models hold the acceleration constant over a step, so theirs
    #: does not compose), ``False``: an approximation such as an Euler step.
    exact_discretisation: ClassVar[bool | None] = None

    @property
    def dim(self) -> int:
        return self.Q.shape[0]

    @property
    def linear(self) -> bool:
        """Whether ``f(x) = x F^T``: true unless a subclass overrides :meth:`f`; a subclass that overrides it with
        the same linear map declares ``linear = True`` (a class attribute, which replaces this property)."""
        return type(self).f is MotionModel.f

    @property
    def has_jacobian(self) -> bool:
        """Whether :meth:`jacobian` is available: a linear model's (``F``), or a subclass's own."""
        return self.linear or type(self).jacobian is not MotionModel.jacobian

    @property
    def position_dims(self) -> int:
        """How many leading state components are a position: those declared in a length unit (``m``, ``km``, ...)
        where ``state_units`` is declared, else half the state (positions, then velocities)."""
        units = tuple(self.state_units)
        if len(units) == self.dim:
            from ..units import UNITS

            count = 0
            for unit in units:
                if unit not in UNITS or UNITS[unit][0] != "length":
                    break
                count += 1
            return count
        return self.dim // 2

    def for_interval(self, dt: float) -> "MotionModel":
        """The same model over a time step of ``dt`` seconds (itself when ``dt`` equals its own step).

        Drivers call this for every step of a scan series with irregular time stamps.  A model without a
        ``rebuild`` function (a hand-made ``F``, ``Q``) only serves its own step.  The result keeps the bound
        start time ``t``.
        """
        if abs(dt - self.dt) <= 1e-12 + 1e-9 * abs(self.dt):  # np.isclose's test, without its ~60 us per call
            return self
        if not dt > 0:
            raise InputError(f"motion model {self.name!r}: time steps must increase, got a step of {dt} s")
        if self.rebuild is None:
            raise InputError(f"motion model {self.name!r} is built for steps of {self.dt} s and cannot be rebuilt "
                             f"for a step of {dt} s")
        out = self.rebuild(float(dt))
        return out if out.t == self.t else _replaced(out, t=self.t)

    def at(self, t: float, dt: float | None = None) -> "MotionModel":
        """The model for the step from the absolute time ``t`` to ``t + dt`` (s): :meth:`for_interval` (``dt``;
        ``None``: this model's own step), with ``t`` bound.  Cheap when nothing changes (itself)."""
        model = self if dt is None else self.for_interval(float(dt))
        t = float(t)
        if not math.isfinite(t):
            raise InputError(f"motion model {self.name!r}: the start time of a step must be finite, got {t}")
        # dataclasses.replace(model, t=t) without re-running __init__ (13 us against a few: the loop calls it every
        # step); the class has no checks to skip, so the result is the same object
        return model if model.t == t else _replaced(model, t=t)

    def _step(self, t, dt) -> tuple[float, float]:
        """``(t, dt)`` with ``None`` replaced by the bound ``self.t`` and ``self.dt``."""
        return (self.t if t is None else float(t)), (self.dt if dt is None else float(dt))

    def _linear_at(self, dt) -> "MotionModel":
        return self if dt is None else self.for_interval(float(dt))

    def f(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        """Noise-free propagation of states ``x (..., n)`` over the step from ``t`` to ``t + dt`` (``None``: the
        bound ``self.t``, ``self.dt``); a linear model's is ``x F(dt)^T`` whatever ``t``."""
        x = np.asarray(x, dtype=float)
        F = self._linear_at(dt).F
        # one (K, n) x (n, n) product: x @ F.T on a stack (B, S, n) makes one small product per item
        # (6x slower for the UKF's (3000, 9, 4) sigma points)
        return (x.reshape(-1, x.shape[-1]) @ F.T).reshape(x.shape)

    def particle_propagator(self) -> Callable | None:
        """The compiled particle propagation this model declares for its bound step, or ``None`` (the default: a
        particle filter propagates through :meth:`f` in NumPy, or through ``F`` for a linear model).

        A model may return ``run(out, x, rng, k, src, coef, ptr)``: ``out_i = f(x_i) + G e_i`` for particles
        ``x (n, L)`` stored component-major, ``e`` drawn inside the loop from the ``numpy.random.Generator``
        ``rng`` in the order of ``rng.standard_normal((L, k))``, the noise added by the plan ``src, coef, ptr`` of
        ``[I | G]`` (``G`` the non-zero columns of ``Q_sqrt``) in the order of
        :func:`workbench.particle_core.combine_columns`.  :func:`workbench.particle_core.predict` calls it only
        where the backend policy runs Numba, and holds it to its NumPy path (the same draws, :meth:`f`, the same
        sums) as the twin."""
        return None

    def fused_particle_propagator(self, frame: str) -> Callable | None:
        """The compiled propagation of :meth:`particle_propagator` fused with the log-likelihood of a measurement
        model of ``frame``, or ``None`` (the default: the particle filter propagates, then weighs).

        The frame taken is ``"range-bearing"`` (the planar range-bearing model,
        :func:`workbench.particle_core.predict_log_weights`): the model may return
        ``run(out, x, rng, k, src, coef, ptr, present, z, sensor, linv, prev, log_w, top)``, which moves the
        particles as :meth:`particle_propagator`'s ``run`` does and, for the items with ``present (B,)``, writes
        ``log_w = prev + log N(z; h(out), R)`` (up to its constant; ``linv = chol(R)^-1``, the sensor at
        ``sensor``) and ``top = max(log_w, axis=1)``, all in one pass; the items without ``present`` get
        ``log_w = prev``.  :func:`workbench.particle_core.predict_log_weights` calls it only where the backend
        policy runs Numba, and holds it to the two calls (:func:`~workbench.particle_core.predict`, then
        :func:`~workbench.particle_core.weighted_log_likelihood`) bit for bit."""
        return None

    def jacobian(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        """``df/dx`` at states ``x (..., n)`` -> ``(..., n, n)``: ``F`` everywhere for a linear model.

        A nonlinear subclass overrides it with its own (analytic) Jacobian; one that does not has none, and
        this raises :class:`~workbench.types.InputError` (see :attr:`has_jacobian`).
        """
        if not self.linear:
            raise InputError(f"motion model {self.name!r} ({type(self).__name__}) overrides f but gives no "
                             f"jacobian(x) method")
        x = np.asarray(x, dtype=float)
        F = self._linear_at(dt).F
        return np.broadcast_to(F, x.shape + (F.shape[1],))


def model_label(motion: MotionModel) -> str:
    kind = type(motion).__name__
    return f"motion model {motion.name!r}" + (f" ({kind})" if kind != "MotionModel" else "")


def require_linear(motion: MotionModel, who: str, instead: str = "'ekf' (with the model's jacobian), 'ukf' or "
                                                                 "'sir'") -> np.ndarray:
    """The transition matrix ``F`` of a :attr:`~MotionModel.linear` model, for the filter named ``who``;
    :class:`~workbench.types.InputError` naming the filter and the model when the model overrides ``f``
    (``instead``: the filters the message suggests)."""
    if not motion.linear:
        raise InputError(f"filter {who!r} needs a linear motion model (it propagates with the transition matrix "
                         f"F), but {model_label(motion)} overrides f: use {instead}, or declare linear = True "
                         f"on the model if its f is x F^T")
    return motion.F


def require_jacobian(motion: MotionModel, who: str, instead: str = "'ukf' or 'sir'"):
    """The Jacobian ``x (..., n) -> (..., n, n)`` of ``motion`` for the filter named ``who`` (a linear model's
    is ``F``); :class:`~workbench.types.InputError` naming the filter and the model when a nonlinear model
    gives none."""
    if not motion.has_jacobian:
        raise InputError(f"filter {who!r} needs the Jacobian of {model_label(motion)}: give the model a "
                         f"jacobian(x) method, or use {instead}")
    return motion.jacobian


def _cartesian_layout(dims: int) -> dict:
    axes = ("x", "y", "z")[:dims] if dims <= 3 else tuple(f"p{i}" for i in range(dims))
    return {"state_names": axes + tuple(f"v{a}" for a in axes), "state_units": ("m",) * dims + ("m/s",) * dims}


def _dwna_axis(dt: float) -> np.ndarray:
    # Discrete white-noise acceleration, one axis: G = [T^2/2, T]^T, Q = G G^T sigma_a^2.
    return np.array([dt * dt / 2.0, dt])


def constant_velocity(dims: int, dt: float, sigma_a: float | Sequence[float]) -> MotionModel:
    """Constant velocity in ``dims`` dimensions with discrete white-noise acceleration.

    Per axis ``A = [[1, T], [0, 1]]`` and ``W = sigma_a^2 [[T^4/4, T^3/2], [T^3/2, T^2]]``; the state is
    blocked, all positions then all velocities: ``[p_1..p_d, v_1..v_d]`` (``[x, y, vx, vy]`` in 2-D; Stone
    Soup's order ``[x, vx, y, vy]`` is interleaved).  ``sigma_a`` may be one value or one per axis (m/s^2).
    """
    if dims < 1:
        raise InputError(f"constant_velocity needs dims >= 1, got {dims}")
    if dt <= 0:
        raise InputError(f"constant_velocity needs dt > 0, got {dt}")
    sig = np.broadcast_to(np.asarray(sigma_a, dtype=float), (dims,))
    if np.any(sig < 0):
        raise InputError(f"constant_velocity needs sigma_a >= 0, got {sig.tolist()}")
    n = 2 * dims
    F = np.eye(n)
    F[:dims, dims:] = dt * np.eye(dims)
    g = _dwna_axis(dt)
    G = np.zeros((n, dims))
    G[:dims] = g[0] * np.diag(sig)
    G[dims:] = g[1] * np.diag(sig)
    return MotionModel(f"cv{dims}d", F, G @ G.T, _lower_factor(G), float(dt),
                       rebuild=lambda step: constant_velocity(dims, step, sigma_a), **_cartesian_layout(dims))


def random_walk_velocity(dims: int, dt: float, sigma_a: float) -> MotionModel:
    """``r_t = r_{t-1} + T v_{t-1}``, ``v_t = v_{t-1} + a_t``, ``a_t ~ N(0, sigma_a^2 I)``.

    The position noise is exactly zero, so ``Q = blockdiag(0, sigma_a^2 I)`` is singular and
    ``Q_sqrt = blockdiag(0, sigma_a I)``.
    """
    if sigma_a < 0 or dt <= 0:
        raise InputError(f"random_walk_velocity needs dt > 0 and sigma_a >= 0, got dt={dt}, sigma_a={sigma_a}")
    n = 2 * dims
    F = np.eye(n)
    F[:dims, dims:] = dt * np.eye(dims)
    Q_sqrt = np.zeros((n, n))
    Q_sqrt[dims:, dims:] = sigma_a * np.eye(dims)
    return MotionModel(f"rwv{dims}d", F, Q_sqrt @ Q_sqrt.T, Q_sqrt, float(dt),
                       rebuild=lambda step: random_walk_velocity(dims, step, sigma_a), **_cartesian_layout(dims))


def range_rate_model(dt: float, sigma_a: float) -> MotionModel:
    """The ``[R, Rdot]`` model: constant range-rate with white-noise acceleration (e.g. a bistatic range)."""
    model = constant_velocity(1, dt, sigma_a)
    return MotionModel("range-rate", model.F, model.Q, model.Q_sqrt, model.dt,
                       rebuild=lambda step: range_rate_model(step, sigma_a), state_names=("R", "Rdot"),
                       state_units=("m", "m/s"))


def _lower_factor(g: np.ndarray) -> np.ndarray:
    """A square lower-triangular ``L`` with ``L L^T = G G^T`` (also for rank-deficient ``G``)."""
    n = g.shape[0]
    padded = np.zeros((n, max(n, g.shape[1])))
    padded[:, : g.shape[1]] = g
    r = np.linalg.qr(padded.T, mode="r")
    low = r.T[:n, :n]
    sign = np.where(np.diagonal(low) < 0, -1.0, 1.0)
    return low * sign[None, :]


# -- series for the small-argument limits -----------------------------------------------------------------------


def _exp_poly_series(terms: Sequence[tuple[Fraction, int, int]], low: int, count: int) -> np.ndarray:
    """Taylor coefficients of ``sum c u^m e^{-k u}`` (``terms`` of ``(c, m, k)``) divided by ``u^low``: the
    coefficients of ``u^0 .. u^{count-1}`` of the quotient, exactly (rational arithmetic), as floats.  The
    coefficients below ``u^low`` cancel exactly for the functions used here (checked)."""
    top = low + count
    coef = [Fraction(0)] * top
    for c, m, k in terms:
        for j in range(top - m):
            coef[m + j] += Fraction(c) * Fraction((-k) ** j, math.factorial(j))
    if any(coef[:low]):
        raise AssertionError("series: the low-order terms do not cancel")  # pragma: no cover - a coding error
    return np.array([float(v) for v in coef[low:]])


def _series(coef: np.ndarray, u: np.ndarray) -> np.ndarray:
    out = np.zeros_like(u)
    for c in coef[::-1]:
        out = out * u + c
    return out


def _blend(u: np.ndarray, small: float, series: np.ndarray, closed: Callable[[np.ndarray], np.ndarray]):
    """``series(u)`` where ``|u| < small`` (the closed form cancels there), else ``closed(u)``."""
    u = np.asarray(u, dtype=float)
    near = np.abs(u) < small
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        far = closed(np.where(near, small, u))
    return np.where(near, _series(series, u), far)


_F1 = Fraction(1)
#: Below this ``alpha T`` the Singer formulas use their (exact-coefficient) Taylor series.
_SINGER_SMALL = 1.0
_SINGER_TERMS = 32
# Singer (1970) per axis, in u = alpha T: F13 = T^2 e2(u), Q = q diag(T^{5/2}, T^{3/2}, T^{1/2}) H(u) diag(...),
# each entry of H written as a sum of c u^m e^{-k u} over 2 u^p (p = 5, 4, 3, 3, 2, 1)
_SINGER_H = {
    (0, 0): ([(_F1, 0, 0), (-_F1, 0, 2), (2 * _F1, 1, 0), (Fraction(2, 3), 3, 0), (-2 * _F1, 2, 0),
              (-4 * _F1, 1, 1)], 5),
    (0, 1): ([(_F1, 0, 2), (_F1, 0, 0), (-2 * _F1, 0, 1), (2 * _F1, 1, 1), (-2 * _F1, 1, 0), (_F1, 2, 0)], 4),
    (0, 2): ([(_F1, 0, 0), (-_F1, 0, 2), (-2 * _F1, 1, 1)], 3),
    (1, 1): ([(4 * _F1, 0, 1), (-3 * _F1, 0, 0), (-_F1, 0, 2), (2 * _F1, 1, 0)], 3),
    (1, 2): ([(_F1, 0, 2), (_F1, 0, 0), (-2 * _F1, 0, 1)], 2),
    (2, 2): ([(_F1, 0, 0), (-_F1, 0, 2)], 1),
}


@functools.cache
def _singer_series() -> tuple[np.ndarray, dict]:
    """The Taylor coefficients of Singer's ``e2(u)`` (``F13 = T^2 e2``) and of each entry of ``H(u)``: exact
    rational arithmetic, about 10 ms, so computed on the first Singer model rather than at import."""
    f13 = _exp_poly_series([(_F1, 1, 0), (-_F1, 0, 0), (_F1, 0, 1)], 2, _SINGER_TERMS)
    return f13, {ij: _exp_poly_series([(c / 2, m, k) for c, m, k in terms], p, _SINGER_TERMS)
                 for ij, (terms, p) in _SINGER_H.items()}


def _closed(terms, p):
    def value(u):
        total = np.zeros_like(u)
        for c, m, k in terms:
            total = total + float(c) * u**m * np.exp(-k * u)
        return total / (2.0 * u**p)

    return value


#: Continuous white jerk per axis (q = 1, T = 1): Q = diag(T^{5/2}, T^{3/2}, T^{1/2}) _CA_UNIT diag(...)
_CA_UNIT = np.array([[1 / 20, 1 / 8, 1 / 6], [1 / 8, 1 / 3, 1 / 2], [1 / 6, 1 / 2, 1.0]])


def _axis_sigmas(who: str, dims: int, sigma, what: str) -> np.ndarray:
    try:
        sig = np.broadcast_to(np.asarray(sigma, dtype=float), (dims,)).copy()
    except (TypeError, ValueError):
        raise InputError(f"{who} needs {what} as one value or {dims} (one per axis), got {sigma!r}") from None
    if not np.all(np.isfinite(sig)) or np.any(sig < 0):
        raise InputError(f"{who} needs finite {what} >= 0, got {sig.tolist()}")
    return sig


def _check_step(who: str, dims: int | None, dt: float) -> None:
    if dims is not None and (not isinstance(dims, (int, np.integer)) or dims < 1):
        raise InputError(f"{who} needs dims >= 1 (a whole number), got {dims!r}")
    if not (isinstance(dt, (int, float, np.floating, np.integer)) and math.isfinite(dt) and dt > 0):
        raise InputError(f"{who} needs a finite dt > 0 (s), got {dt!r}")


def _kinematic_layout(dims: int, orders: int) -> dict:
    axes = ("x", "y", "z")[:dims] if dims <= 3 else tuple(f"p{i}" for i in range(dims))
    prefixes = ("", "v", "a")[:orders]
    units = ("m", "m/s", "m/s^2")[:orders]
    return {"state_names": tuple(f"{p}{a}" for p in prefixes for a in axes),
            "state_units": tuple(u for u in units for _ in axes)}


class ExactLinearModel(MotionModel):
    """A linear model whose ``F`` and ``Q`` are the exact discretisation of a continuous-time linear SDE
    ``dx = A x dt + L dw`` (``F = e^{A dt}``, ``Q = int_0^dt e^{A s} L Qc L^T e^{A^T s} ds``), so both compose
    over intervals (``exact_discretisation = True``): :func:`constant_acceleration`, :func:`singer`."""

    exact_discretisation = True


def _third_order(name: str, dims: int, dt: float, F3: np.ndarray, Q3: np.ndarray, L3: np.ndarray,
                 sig: np.ndarray, rebuild) -> ExactLinearModel:
    """Per-axis ``F3``, unit-noise ``Q3 = L3 L3^T`` (3 x 3, orders position, velocity, acceleration) placed in the
    layout ``[p..., v..., a...]`` with the per-axis scale ``sig``."""
    eye = np.eye(dims)
    S = np.diag(sig)
    return ExactLinearModel(name, np.kron(F3, eye), np.kron(Q3, S * S), np.kron(L3, S), float(dt),
                            rebuild=rebuild, **_kinematic_layout(dims, 3))


def constant_acceleration(dims: int, dt: float, sigma_j: float | Sequence[float]) -> ExactLinearModel:
    """Constant acceleration in ``dims`` dimensions driven by continuous white-noise jerk, exactly discretised.

    State ``[p_1..p_d, v_1..v_d, a_1..a_d]`` (m, m/s, m/s^2).  Per axis, with ``T = dt`` and the jerk's spectral
    density ``q = sigma_j^2`` (``sigma_j`` in m/s^2/sqrt(s), one value or one per axis)::

        F = [[1, T, T^2/2],            Q = q [[T^5/20, T^4/8, T^3/6],
             [0, 1, T    ],                   [T^4/8,  T^3/3, T^2/2],
             [0, 0, 1    ]]                   [T^3/6,  T^2/2, T    ]]

    (Bar-Shalom, Li & Kirubarajan 2001, 6.2.3: the Wiener-process acceleration model).  ``Q`` is the exact
    integral ``int_0^T e^{A s} L L^T e^{A^T s} ds q``, so ``F`` and ``Q`` compose over intervals
    (:class:`ExactLinearModel`); ``Q_sqrt = D chol(M) D`` with ``D = diag(T^{5/2}, T^{3/2}, T^{1/2})``, accurate
    for small steps.
    """
    _check_step("constant_acceleration", dims, dt)
    sig = _axis_sigmas("constant_acceleration", dims, sigma_j, "sigma_j (m/s^2/sqrt(s))")
    T = float(dt)
    F3 = np.array([[1.0, T, T * T / 2.0], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    D = np.diag([T**2.5, T**1.5, T**0.5])
    L3 = D @ np.linalg.cholesky(_CA_UNIT)
    return _third_order(f"ca{dims}d", dims, T, F3, D @ _CA_UNIT @ D, L3, sig,
                        lambda step: constant_acceleration(dims, step, sigma_j))


def singer(dims: int, dt: float, sigma_m: float | Sequence[float], tau: float) -> ExactLinearModel:
    """The Singer (1970) manoeuvre model in ``dims`` dimensions, exactly discretised.

    State ``[p_1..p_d, v_1..v_d, a_1..a_d]`` (m, m/s, m/s^2).  Per axis the acceleration is a first-order
    Gauss-Markov process ``da/dt = -alpha a + w`` with ``alpha = 1 / tau`` (``tau``: the manoeuvre time constant,
    s) and ``w`` white with spectral density ``q = 2 alpha sigma_m^2`` (``sigma_m``: the rms manoeuvre
    acceleration, m/s^2, one value or one per axis), so that ``a`` has variance ``sigma_m^2``.  With ``T = dt``
    and ``u = alpha T``::

        F = [[1, T, (u - 1 + e^-u) / alpha^2],
             [0, 1, (1 - e^-u) / alpha      ],
             [0, 0, e^-u                    ]]

        q11 = q / (2 alpha^5) (1 - e^-2u + 2u + 2u^3/3 - 2u^2 - 4u e^-u)
        q12 = q / (2 alpha^4) (e^-2u + 1 - 2e^-u + 2u e^-u - 2u + u^2)
        q13 = q / (2 alpha^3) (1 - e^-2u - 2u e^-u)
        q22 = q / (2 alpha^3) (4e^-u - 3 - e^-2u + 2u)
        q23 = q / (2 alpha^2) (e^-2u + 1 - 2e^-u)
        q33 = q / (2 alpha) (1 - e^-2u)

    (Singer 1970, eq. 21; Bar-Shalom, Li & Kirubarajan 2001, 8.2.3).  These cancel for small ``u``: below
    ``u = 1`` each entry is evaluated from its Taylor series in ``u`` (coefficients exact), so long time constants
    and short steps are sound; ``tau = inf`` is the limit itself (``F`` of constant acceleration, ``Q = 0``, as
    ``q = 2 sigma_m^2 / tau -> 0``).  ``F`` and ``Q`` compose over intervals (:class:`ExactLinearModel`).
    """
    _check_step("singer", dims, dt)
    sig = _axis_sigmas("singer", dims, sigma_m, "sigma_m (m/s^2)")
    try:
        tau_f = float(tau)
    except (TypeError, ValueError):
        raise InputError(f"singer needs tau > 0 (s; inf for no decorrelation), got {tau!r}") from None
    if not tau_f > 0:
        raise InputError(f"singer needs tau > 0 (s; inf for no decorrelation), got {tau!r}")
    T = float(dt)
    alpha = 0.0 if math.isinf(tau_f) else 1.0 / tau_f
    u = np.array(alpha * T)
    eu = float(np.exp(-u))
    e1 = float(-np.expm1(-u) / u) if u > 0 else 1.0  # (1 - e^-u) / u
    f13_series, h_series = _singer_series()
    e2 = float(_blend(u, _SINGER_SMALL, f13_series, lambda v: (v - 1.0 + np.exp(-v)) / (v * v)))
    F3 = np.array([[1.0, T, T * T * e2], [0.0, 1.0, T * e1], [0.0, 0.0, eu]])
    H = np.zeros((3, 3))
    for (i, j), (terms, p) in _SINGER_H.items():
        H[i, j] = H[j, i] = float(_blend(u, _SINGER_SMALL, h_series[(i, j)], _closed(terms, p)))
    q_unit = 2.0 * alpha  # q = 2 alpha sigma_m^2: the per-axis sigma_m^2 enters through _third_order's scale
    D = np.diag([T**2.5, T**1.5, T**0.5])
    Q3 = q_unit * (D @ H @ D)
    L3 = np.sqrt(q_unit) * (D @ _psd_lower(H))
    return _third_order(f"singer{dims}d", dims, T, F3, Q3, L3, sig,
                        lambda step: singer(dims, step, sigma_m, tau))


def _psd_lower(M: np.ndarray) -> np.ndarray:
    """A lower-triangular factor of the symmetric positive semi-definite ``M`` (Cholesky where it succeeds)."""
    try:
        return np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh((M + M.T) / 2.0)
        return _lower_factor(V * np.sqrt(np.clip(w, 0.0, None)))


def _turn_terms(u: np.ndarray):
    """``sin u / u``, ``(1 - cos u) / u`` and their ``u``-derivatives' forms ``(u cos u - sin u) / u^2``,
    ``(u sin u - (1 - cos u)) / u^2``: closed forms, and Taylor series below ``|u| = 0.1`` (no 0/0 at u = 0)."""
    return (_blend(u, _TURN_SMALL, _SINC, lambda v: np.sin(v) / v),
            _blend(u, _TURN_SMALL, _COSC, lambda v: (1.0 - np.cos(v)) / v),
            _blend(u, _TURN_SMALL, _DSINC, lambda v: (v * np.cos(v) - np.sin(v)) / (v * v)),
            _blend(u, _TURN_SMALL, _DCOSC, lambda v: (v * np.sin(v) - (1.0 - np.cos(v))) / (v * v)))


def _trig_series(kind: str, count: int = 12) -> np.ndarray:
    """Power-series coefficients (``u^0 .. u^{2 count}``) of the four turn functions of :func:`_turn_terms`."""
    coef = [Fraction(0)] * (2 * count + 1)
    fact = math.factorial
    for k in range(count):
        sign = (-1) ** k
        if kind == "sinc":  # sin u / u = sum (-1)^k u^2k / (2k+1)!
            coef[2 * k] = Fraction(sign, fact(2 * k + 1))
        elif kind == "cosc":  # (1 - cos u) / u = sum_{k>=0} (-1)^k u^(2k+1) / (2k+2)!
            coef[2 * k + 1] = Fraction(sign, fact(2 * k + 2))
        elif kind == "dsinc":  # (u cos u - sin u) / u^2 = sum_{k>=1} (-1)^k u^(2k-1) (1/(2k)! - 1/(2k+1)!)
            if k >= 1:
                coef[2 * k - 1] = sign * (Fraction(1, fact(2 * k)) - Fraction(1, fact(2 * k + 1)))
        else:  # (u sin u - (1 - cos u)) / u^2 = sum_{k>=1} (-1)^(k+1) u^(2k-2) (1/(2k-1)! - 1/(2k)!)
            if k >= 1:
                coef[2 * k - 2] = -sign * (Fraction(1, fact(2 * k - 1)) - Fraction(1, fact(2 * k)))
    return np.array([float(v) for v in coef])


_TURN_SMALL = 0.1
_SINC, _COSC, _DSINC, _DCOSC = (_trig_series(k) for k in ("sinc", "cosc", "dsinc", "dcosc"))


def _turn_matrix(T: float, omega: float) -> np.ndarray:
    """The exact transition of ``[x, y, vx, vy]`` over ``T`` at the turn rate ``omega`` (rad/s)."""
    sa, ca, _, _ = _turn_terms(np.array(omega * T))
    a, b = T * float(sa), T * float(ca)
    c, s = math.cos(omega * T), math.sin(omega * T)
    return np.array([[1.0, 0.0, a, -b], [0.0, 1.0, b, a], [0.0, 0.0, c, -s], [0.0, 0.0, s, c]])


def _dwna_block(dims: int, dt: float, sig: np.ndarray) -> np.ndarray:
    """The DWNA ``G`` ``(2 dims, dims)`` of :func:`constant_velocity` (``Q = G G^T``)."""
    g = _dwna_axis(dt)
    G = np.zeros((2 * dims, dims))
    G[:dims] = g[0] * np.diag(sig)
    G[dims:] = g[1] * np.diag(sig)
    return G


def coordinated_turn(dt: float, omega: float, sigma_a: float | Sequence[float]) -> MotionModel:
    """Coordinated turn at a known rate ``omega`` (rad/s, positive counter-clockwise), 2-D, linear.

    State ``[x, y, vx, vy]`` (m, m/s).  With ``T = dt``, ``s = sin(omega T)``, ``c = cos(omega T)``::

        F = [[1, 0, s/omega,       -(1 - c)/omega],
             [0, 1, (1 - c)/omega,  s/omega      ],
             [0, 0, c,             -s            ],
             [0, 0, s,              c            ]]

    the exact motion along the arc (``F(T1 + T2) = F(T2) F(T1)``); ``s/omega`` and ``(1 - c)/omega`` are
    evaluated from their series near ``omega T = 0``, and ``omega = 0`` is constant velocity exactly.  ``Q`` is
    the discrete white-noise acceleration of :func:`constant_velocity` (``sigma_a`` m/s^2, one value or one per
    axis), so ``omega = 0`` gives that model bit for bit.
    """
    _check_step("coordinated_turn", None, dt)
    try:
        w = float(omega)
    except (TypeError, ValueError):
        raise InputError(f"coordinated_turn needs a finite turn rate omega (rad/s), got {omega!r}") from None
    if not math.isfinite(w):
        raise InputError(f"coordinated_turn needs a finite turn rate omega (rad/s), got {omega!r}")
    sig = _axis_sigmas("coordinated_turn", 2, sigma_a, "sigma_a (m/s^2)")
    G = _dwna_block(2, float(dt), sig)
    return MotionModel(f"ct({w:g} rad/s)", _turn_matrix(float(dt), w), G @ G.T, _lower_factor(G), float(dt),
                       rebuild=lambda step: coordinated_turn(step, omega, sigma_a), **_cartesian_layout(2))


class CoordinatedTurnRate(MotionModel):
    """Coordinated turn with the turn rate in the state ``[x, y, vx, vy, omega]`` (m, m, m/s, m/s, rad/s):
    nonlinear ``f``, analytic :meth:`jacobian`; see :func:`coordinated_turn_rate`.

    :meth:`f` and :meth:`jacobian` run the compiled loops of :mod:`workbench.kernels.motion_numba` where the
    backend policy (:func:`workbench.kernels.backend.resolve`) runs Numba, else their NumPy twins
    :meth:`f_numpy` and :meth:`jacobian_numpy` (held to each other to 1e-12 on both sides of ``omega = 0``;
    the compiled ones are several times faster on ``(3.3e4, 5)`` and ``(1e5, 5)`` states: group ``motion`` of
    ``docs/benchmarks.md``)."""

    def _states(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim == 0 or x.shape[-1] != 5:
            raise InputError(f"{model_label(self)}: states must be (..., 5), [x, y, vx, vy, omega], got shape "
                             f"{x.shape}")
        return x

    def f(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        x = self._states(x)
        kernels = _ct_rate_kernels()
        if kernels is None:
            return self.f_numpy(x, t, dt)
        flat = x.reshape(-1, 5)
        out = np.empty_like(flat, order="K")  # the input's memory order: a component-major cloud stays one
        kernels.ct_rate_f(flat, self._step(t, dt)[1], _SINC, _COSC, out)
        return out.reshape(x.shape)

    def jacobian(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        x = self._states(x)
        kernels = _ct_rate_kernels()
        if kernels is None:
            return self.jacobian_numpy(x, t, dt)
        flat = x.reshape(-1, 5)
        out = np.empty(flat.shape + (5,))
        kernels.ct_rate_jacobian(flat, self._step(t, dt)[1], _TURN_SMALL, _SINC, _COSC, _DSINC, _DCOSC, out)
        return out.reshape(x.shape + (5,))

    def particle_propagator(self) -> Callable | None:
        """The compiled propagation :func:`workbench.kernels.motion_numba.ct_rate_propagate` over the bound step
        (``f`` and the noise in one pass; see :meth:`MotionModel.particle_propagator`), or ``None`` for a subclass
        that overrides :meth:`f` (its own ``f`` is then what the particle filter follows)."""
        if type(self).f is not CoordinatedTurnRate.f:
            return None
        from ..kernels import motion_numba

        T = float(self.dt)

        def run(out, x, rng, k, src, coef, ptr):
            return motion_numba.ct_rate_propagate(out, x, rng, k, src, coef, ptr, T, _SINC, _COSC)

        return run

    def fused_particle_propagator(self, frame: str) -> Callable | None:
        """:func:`workbench.kernels.motion_numba.ct_rate_propagate_range_bearing` over the bound step for the
        planar range-bearing frame (see :meth:`MotionModel.fused_particle_propagator`), ``None`` for any other
        frame and where :meth:`particle_propagator` gives none (a subclass with its own :meth:`f`)."""
        if frame != "range-bearing" or self.particle_propagator() is None:
            return None
        from ..kernels import motion_numba

        T = float(self.dt)

        def run(out, x, rng, k, src, coef, ptr, present, z, sensor, linv, prev, log_w, top):
            return motion_numba.ct_rate_propagate_range_bearing(out, x, rng, k, src, coef, ptr, T, _SINC, _COSC,
                                                                present, z, sensor, linv, prev, log_w, top)

        return run

    def f_numpy(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        """:meth:`f` in NumPy (the twin of the compiled loop)."""
        x = self._states(x)
        T = self._step(t, dt)[1]
        px, py, vx, vy, w = (x[..., i] for i in range(5))
        sa, ca, _, _ = _turn_terms(w * T)
        a, b = T * sa, T * ca
        c, s = np.cos(w * T), np.sin(w * T)
        return np.stack([px + a * vx - b * vy, py + b * vx + a * vy, c * vx - s * vy, s * vx + c * vy, w], axis=-1)

    def jacobian_numpy(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        """:meth:`jacobian` in NumPy (the twin of the compiled loop)."""
        x = self._states(x)
        T = self._step(t, dt)[1]
        vx, vy, w = x[..., 2], x[..., 3], x[..., 4]
        sa, ca, dsa, dca = _turn_terms(w * T)
        a, b = T * sa, T * ca  # sin(wT)/w, (1 - cos(wT))/w
        da, db = T * T * dsa, T * T * dca  # their derivatives in w
        c, s = np.cos(w * T), np.sin(w * T)
        J = np.zeros(x.shape + (5,))
        J[..., 0, 0] = J[..., 1, 1] = J[..., 4, 4] = 1.0
        J[..., 0, 2], J[..., 0, 3], J[..., 0, 4] = a, -b, da * vx - db * vy
        J[..., 1, 2], J[..., 1, 3], J[..., 1, 4] = b, a, db * vx + da * vy
        J[..., 2, 2], J[..., 2, 3], J[..., 2, 4] = c, -s, -T * s * vx - T * c * vy
        J[..., 3, 2], J[..., 3, 3], J[..., 3, 4] = s, c, T * c * vx - T * s * vy
        return J


def _ct_rate_kernels():
    """The compiled loops of :class:`CoordinatedTurnRate` where the backend policy runs Numba, else ``None``."""
    from ..kernels.backend import resolve

    if resolve("auto") != "numba":
        return None
    from ..kernels import motion_numba

    return motion_numba


def coordinated_turn_rate(dt: float, sigma_a: float | Sequence[float], sigma_omega: float) -> CoordinatedTurnRate:
    """Coordinated turn with the turn rate in the state, 2-D, nonlinear (:class:`CoordinatedTurnRate`).

    State ``[x, y, vx, vy, omega]`` (m, m, m/s, m/s, rad/s).  With ``T = dt``, ``s = sin(omega T)``,
    ``c = cos(omega T)``::

        x'  = x + s/omega vx - (1 - c)/omega vy        vx' = c vx - s vy
        y'  = y + (1 - c)/omega vx + s/omega vy        vy' = s vx + c vy
        omega' = omega

    and the analytic Jacobian of that map.  ``s/omega``, ``(1 - c)/omega`` and their derivatives in ``omega``
    are evaluated from their Taylor series where ``|omega T| < 0.1``, so ``omega = 0`` is constant velocity (no
    0/0) and the Jacobian is continuous across it.  ``Q = blockdiag(Q_cv, sigma_omega^2 T)``: the discrete
    white-noise acceleration block of :func:`constant_velocity` on ``[x, y, vx, vy]`` (``sigma_a`` m/s^2, one
    value or one per axis) and a random-walk rate with spectral density ``sigma_omega^2``
    (``sigma_omega`` in rad/s/sqrt(s)).  ``F`` is the Jacobian at the zero state (constant velocity); no
    built-in filter reads it, the model not being linear.
    """
    _check_step("coordinated_turn_rate", None, dt)
    sig = _axis_sigmas("coordinated_turn_rate", 2, sigma_a, "sigma_a (m/s^2)")
    sw = _axis_sigmas("coordinated_turn_rate", 1, sigma_omega, "sigma_omega (rad/s/sqrt(s))")[0]
    T = float(dt)
    G = np.zeros((5, 3))
    G[:4, :2] = _dwna_block(2, T, sig)
    G[4, 2] = sw * math.sqrt(T)
    F = np.eye(5)
    F[0, 2] = F[1, 3] = T
    return CoordinatedTurnRate("ct-rate", F, G @ G.T, _lower_factor(G), T,
                               rebuild=lambda step: coordinated_turn_rate(step, sigma_a, sigma_omega),
                               state_names=("x", "y", "vx", "vy", "omega"),
                               state_units=("m", "m", "m/s", "m/s", "rad/s"))


class GrowthModel(MotionModel):
    """The univariate nonstationary growth model (time-varying, nonlinear); see :func:`growth_model`."""

    def f(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        t, dt = self._step(t, dt)
        k = t + dt  # the time at the end of the step
        return x / 2.0 + 25.0 * x / (1.0 + x * x) + 8.0 * np.cos(1.2 * k)

    def jacobian(self, x: np.ndarray, t: float | None = None, dt: float | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        x2 = x * x
        return (0.5 + 25.0 * (1.0 - x2) / ((1.0 + x2) ** 2))[..., None]


def growth_model(sigma_v: float = math.sqrt(10.0)) -> GrowthModel:
    """The univariate nonstationary growth model of Gordon, Salmond & Smith (1993), the standard particle-filter
    benchmark (with :func:`~workbench.models.measurement.quadratic_measurement`)::

        x_k = x_{k-1} / 2 + 25 x_{k-1} / (1 + x_{k-1}^2) + 8 cos(1.2 k) + v_k,    v_k ~ N(0, sigma_v^2)

    with ``k`` the time at the end of the step (``t + dt``, the bound start time plus the interval), ``dt = 1``:
    the model is time-varying through the time the loop binds (:meth:`MotionModel.at`), so the step from
    ``t = 0`` gives ``x_1``.  Jacobian ``1/2 + 25 (1 - x^2) / (1 + x^2)^2``.  State ``[x]``, dimensionless
    (unit ``"1"``).  A discrete-time model: it serves steps of 1 only (no ``rebuild``).  ``F`` is the Jacobian
    at ``x = 0``; no built-in filter reads it, the model not being linear.
    """
    sig = _axis_sigmas("growth_model", 1, sigma_v, "sigma_v")[0]
    return GrowthModel("growth", np.array([[25.5]]), np.array([[sig * sig]]), np.array([[sig]]), 1.0,
                       state_names=("x",), state_units=("1",))
