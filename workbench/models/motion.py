"""Motion models: what filters need to know about dynamics.

The motion models built here are linear-Gaussian, ``x_k = F x_{k-1} + w_k``, ``w_k ~ N(0, Q)``; ``Q_sqrt`` is an
explicit factor ``Q = Q_sqrt Q_sqrt^T`` so that square-root filters never take the Cholesky factor of a singular Q.
A subclass of :class:`MotionModel` that overrides ``f`` is a nonlinear model (``x_k = f(x_{k-1}) + w_k``): every
built-in filter either follows its ``f`` (and its ``jacobian`` where it needs one) or refuses it by name
(:func:`require_linear`, :func:`require_jacobian`), never reading ``F`` from it.

State layout convention: positions first, then velocities, e.g. ``[x, y, vx, vy]`` or ``[x, y, z, vx, vy, vz]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, ClassVar, Sequence

import numpy as np

from ..types import InputError

__all__ = [
    "MotionModel",
    "require_linear",
    "require_jacobian",
    "constant_velocity",
    "random_walk_velocity",
    "range_rate_model",
]


@dataclass(frozen=True)
class MotionModel:
    """Linear motion ``x_k = F x_{k-1} + w_k`` with ``w_k ~ N(0, Q)``.

    Shapes: ``F (n, n)``, ``Q (n, n)``, ``Q_sqrt (n, n)`` with ``Q = Q_sqrt Q_sqrt^T``.  ``state_names`` and
    ``state_units`` declare the state's layout (e.g. ``x, y, vx, vy`` in m and m/s), for track files and plots.

    Nonlinear motion ``x_k = f(x_{k-1}) + w_k``: subclass and override :meth:`f` (vectorised over any leading
    axes), and :meth:`jacobian` where filters that linearise (the EKF) should take the model.  Such a model is
    not :attr:`linear`, and no built-in filter reads its ``F`` (it still has one, its fields being this
    class's; filters that need a transition matrix refuse the model by name).  A subclass whose ``f`` is still
    ``x F^T`` (e.g. written out for speed) declares ``linear = True`` as a class attribute and keeps the exact
    linear filters and their compiled paths.
    """

    name: str
    F: np.ndarray
    Q: np.ndarray
    Q_sqrt: np.ndarray
    dt: float
    rebuild: Callable[[float], "MotionModel"] | None = field(default=None, compare=False, repr=False)
    state_names: tuple[str, ...] = ()
    state_units: tuple[str, ...] = ()

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
        """How many leading state components are a position (the layout is positions, then velocities)."""
        return self.dim // 2

    def for_interval(self, dt: float) -> "MotionModel":
        """The same model over a time step of ``dt`` seconds (itself when ``dt`` equals its own step).

        Drivers call this for every step of a scan series with irregular time stamps.  A model without a
        ``rebuild`` function (a hand-made ``F``, ``Q``) only serves its own step.
        """
        if np.isclose(dt, self.dt, rtol=1e-9, atol=1e-12):
            return self
        if not dt > 0:
            raise InputError(f"motion model {self.name!r}: time steps must increase, got a step of {dt} s")
        if self.rebuild is None:
            raise InputError(f"motion model {self.name!r} is built for steps of {self.dt} s and cannot be rebuilt "
                             f"for a step of {dt} s")
        return self.rebuild(float(dt))

    def f(self, x: np.ndarray) -> np.ndarray:
        """Noise-free propagation of states ``x (..., n)``."""
        x = np.asarray(x, dtype=float)
        # one (K, n) x (n, n) product: x @ F.T on a stack (B, S, n) makes one small product per item
        # (6x slower for the UKF's (3000, 9, 4) sigma points)
        return (x.reshape(-1, x.shape[-1]) @ self.F.T).reshape(x.shape)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """``df/dx`` at states ``x (..., n)`` -> ``(..., n, n)``: ``F`` everywhere for a linear model.

        A nonlinear subclass overrides it with its own (analytic) Jacobian; one that does not has none, and
        this raises :class:`~workbench.types.InputError` (see :attr:`has_jacobian`).
        """
        if not self.linear:
            raise InputError(f"motion model {self.name!r} ({type(self).__name__}) overrides f but gives no "
                             f"jacobian(x) method")
        x = np.asarray(x, dtype=float)
        return np.broadcast_to(self.F, x.shape + (self.F.shape[1],))


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

    Per axis ``A = [[1, T], [0, 1]]`` and ``W = sigma_a^2 [[T^4/4, T^3/2], [T^3/2, T^2]]``; the axes are
    interleaved into the layout ``[p_1..p_d, v_1..v_d]``.  ``sigma_a`` may be one value or one per
    axis (m/s^2).
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
