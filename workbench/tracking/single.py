"""Single-target association roles for :func:`workbench.tracking.run`, batched over Monte Carlo runs.

Each role keeps the filter state of every run (the batch axis ``B``) and records, per scan, the estimate, the
prediction and what it associated.  The role decides what the filter's ``update`` sees:

- :class:`Direct`: the scan itself;
- :class:`Gated`: the detections within a radius of the predicted position (whole, or through a pseudo step);
- :class:`NearestNeighbour`: the candidate nearest to the predicted measurement (optionally gated), or the one a
  filter that declares ``FilterSpec.gate_candidates`` chooses on its own prediction (the IMM: on its modes).

What a role keeps between calls is typed: the :class:`Carry` (the filter state, the estimates and records, the motion
model of the last predict) and, in ``Carry.role``, the role's own :class:`RoleState` (a dataclass per role with
exactly its fields: :class:`GatedState`, :class:`NearestNeighbourState`).  A role written elsewhere keeps its own
state the same way: a subclass of :class:`RoleState` (of its parent role's state, where it extends a role) returned
by :meth:`SingleTarget.begin`; nothing is kept under string keys.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..linalg import symmetrise
from ..models import MeasurementModel, MotionModel
from ..types import Gaussian, InputError, Scan, _validated
from .loop import Context, Track, default_association

__all__ = ["SingleTarget", "Carry", "RoleState", "GatedState", "NearestNeighbourState", "Direct", "Gated",
           "NearestNeighbour", "GATE_99", "radius_gate", "predicted_measurement", "nearest_candidate",
           "strongest_candidate", "strongest_candidate_prior"]

#: chi-square(2 dof) 0.99 quantile: the gate ``d^2 <= 9.21``.
GATE_99 = 9.21


@dataclass
class RoleState:
    """What a single-target role keeps between calls beyond the :class:`Carry`: nothing, for :class:`Direct`.

    A role that keeps more subclasses this dataclass with exactly its fields (shapes declared in the docstring) and
    returns one from :meth:`SingleTarget.begin`; a role extending another extends that role's state class the same
    way and names it in its ``state_class`` (the filter kit's ``_RecordPredicted`` does), so every field has one
    declared writer and type; :meth:`SingleTarget.start` refuses, by name, a ``begin`` that returns anything else."""


@dataclass
class GatedState(RoleState):
    """The :class:`Gated` role's state.

    Attributes
    ----------
    previous : (B, n) float or None
        The last estimate's mean, then (after the next predict) its prediction ``F x_{k-1|k-1}``: the gate centre
        (set from the filter's first estimate once the filter is initialised).
    masks : list of (B, M_k) bool
        The keep mask of every scan so far, each in its own row order (``finish`` packs them into ``gated``).
    """

    previous: np.ndarray | None = None
    masks: list = field(default_factory=list)


@dataclass
class NearestNeighbourState(RoleState):
    """The :class:`NearestNeighbour` role's state.

    Attributes
    ----------
    prior_cov : (B, n, n) float
        The prior's covariance: a restart's covariance.
    misses : (B,) int
        Scans in a row without an update, per run (reset by an update or a restart).
    z_hat : (B, m) float or None
        The predicted measurement of the current scan, ``h(x-)`` (``None`` before the first prediction is read).
    S : (B, m, m) float or None
        Its innovation covariance ``H P- H^T + R`` (the model's ``R``).
    scan : Scan or None
        The scan last associated (the candidates a restart picks from).
    """

    prior_cov: np.ndarray
    misses: np.ndarray
    z_hat: np.ndarray | None = None
    S: np.ndarray | None = None
    scan: Scan | None = None


@dataclass
class Carry:
    """What a single-target role carries through :func:`~workbench.tracking.run`.

    Attributes
    ----------
    ctx : Context
        The run's filter, models, shape and generator.
    state : Any
        The filter's state (its own business; read through ``ctx.filter.estimate``).
    mean, predicted : (B, T, n) float
        The estimate after each scan and the predicted mean before it.
    cov : (B, T, n, n) float
        The estimate's covariance after each scan.
    records : dict of str -> (B, T, ...) array
        The role's per-step records (:meth:`SingleTarget.record_shapes`), handed out in the :class:`Track`.
    start : float
        ``time.perf_counter()`` at the start (the track's ``seconds``).
    role : RoleState
        The role's own state (a subclass of :class:`RoleState`, from :meth:`SingleTarget.begin`).
    motion : MotionModel or None
        The motion model of the last predict (``None`` before the first).
    """

    ctx: Context
    state: Any
    mean: np.ndarray
    cov: np.ndarray
    predicted: np.ndarray
    records: dict
    start: float
    role: RoleState
    motion: MotionModel | None = None


class SingleTarget:
    """The common part of the single-target roles: init, predict, update with what :meth:`associate` chose,
    and the records.  A role overrides :meth:`associate` (and :meth:`begin`, :meth:`predicted_mean`,
    :meth:`record_shapes` where it needs to).  Its own state between calls is the :class:`RoleState` that
    :meth:`begin` returns, kept in ``carry.role``."""

    #: The class of this role's :class:`RoleState` (what :meth:`begin` must return, or a subclass of it).
    state_class: type[RoleState] = RoleState
    #: Declared for :func:`~workbench.tracking.loop.run`: the filter's batch is the runs' (one item per run), so the
    #: loop may record each update's innovations (``run(..., innovations=True)``).
    single_target = True

    def record_shapes(self, ctx: Context, n: int) -> dict[str, tuple[tuple[int, ...], Any, Any]]:
        """``name -> (trailing shape, dtype, fill)`` of the role's per-step records."""
        return {}

    def begin(self, ctx: Context, prior: Gaussian | None, first: Scan) -> tuple[Gaussian, RoleState]:
        """The prior to start from and the role's own state (an instance of :attr:`state_class`)."""
        if prior is None:
            raise InputError(f"{type(self).__name__} association needs a prior")
        return prior, RoleState()

    def start(self, ctx: Context, prior: Gaussian | None, first: Scan) -> Carry:
        t0 = time.perf_counter()
        prior, role = self.begin(ctx, prior, first)
        if not isinstance(role, self.state_class):
            raise InputError(f"association {type(self).__name__}: begin() must return its state as a "
                             f"{self.state_class.__name__} (a RoleState dataclass), got {type(role).__name__}")
        B, T, n = ctx.batch, ctx.steps, prior.dim
        records = {name: np.full((B, T) + shape, fill, dtype=dtype)
                   for name, (shape, dtype, fill) in self.record_shapes(ctx, n).items()}
        state = ctx.filter.init(prior, ctx.rng)
        carry = Carry(ctx, state, np.empty((B, T, n)), np.empty((B, T, n, n)), np.empty((B, T, n)), records, t0,
                      role)
        self.started(carry, prior)
        return carry

    def started(self, carry: Carry, prior: Gaussian) -> None:
        """Called once after ``init`` (a role that tracks its own view of the state starts it here)."""

    def predict(self, carry: Carry, motion: MotionModel, k: int) -> Carry:
        carry.state = carry.ctx.filter.predict(carry.state, motion, carry.ctx.rng)
        carry.motion = motion
        return carry

    def predicted_mean(self, carry: Carry, k: int) -> np.ndarray:
        """The predicted state mean at scan ``k`` (the filter's estimate of its predicted state)."""
        return carry.ctx.filter.estimate(carry.state).mean

    def associate(self, carry: Carry, scan: Scan, k: int, predicted: np.ndarray
                  ) -> tuple[Scan | None, MeasurementModel]:
        """What the filter is updated with at scan ``k`` (``None``: no update) and the model it is given."""
        raise NotImplementedError

    def update(self, carry: Carry, scan: Scan, k: int) -> Carry:
        ctx = carry.ctx
        predicted = self.predicted_mean(carry, k)
        carry.predicted[:, k] = predicted
        step, model = self.associate(carry, scan, k, predicted)
        if step is not None:
            carry.state = ctx.filter.update(carry.state, step, model, ctx.rng)
        est = ctx.filter.estimate(carry.state)
        carry.mean[:, k] = est.mean
        carry.cov[:, k] = est.cov
        self.updated(carry, k, est)
        return carry

    def updated(self, carry: Carry, k: int, estimate: Gaussian) -> None:
        """Called after the update of scan ``k`` with the filter's estimate."""

    def finish(self, carry: Carry) -> Track:
        ctx = carry.ctx
        diag = dict(ctx.filter.diagnostics(carry.state)) if ctx.filter.diagnostics is not None else {}
        return Track(ctx.filter.name, carry.mean, carry.cov, carry.predicted, diag, carry.records,
                     time.perf_counter() - carry.start)


class Direct(SingleTarget):
    """Update with each scan as it is: at most one valid row per item, or any number for a filter with the
    ``multi_measurement`` capability (its own association).  No records."""

    def associate(self, carry, scan, k, predicted):
        return scan, carry.ctx.model

    def step(self, carry: Carry, motion: MotionModel, scan: Scan, k: int) -> Carry:
        """:meth:`predict` then :meth:`update` through one call of the filter's fused ``FilterSpec.step`` (the time
        loop's choice where the filter gives one): the scan does not depend on the prediction, so the filter may
        predict, update and estimate in one go; the records are the two calls'.  A subclass that overrides how the
        prediction is read, the scan chosen or a step recorded gets the two calls."""
        ctx = carry.ctx
        plain = all(getattr(type(self), name) is getattr(Direct, name)
                    for name in ("predict", "predicted_mean", "associate", "update"))
        if ctx.filter.step is None or not plain:
            return self.update(self.predict(carry, motion, k), scan, k)
        carry.state, est, predicted = ctx.filter.step(carry.state, motion, scan, ctx.model, ctx.rng, predicted=True)
        carry.motion = motion
        carry.predicted[:, k] = predicted.mean
        carry.mean[:, k] = est.mean
        carry.cov[:, k] = est.cov
        self.updated(carry, k, est)
        return carry


# -- gating by distance ---------------------------------------------------------------------------------


def radius_gate(scan: Scan, centre: np.ndarray, radius: float, dims: int | None = None) -> tuple[Scan, np.ndarray]:
    """The detections within ``radius`` of ``centre`` in the first ``dims`` measurement components (a position).

    The kept rows are moved to the front and the scan narrowed to the largest kept count, so later steps loop
    over few rows.  Returns the gated scan and the keep mask in the original row order.

    Shapes
    ------
    scan.z : (B, M, m); centre : (B, dims); returns (Scan (B, M', m), keep (B, M)), M' <= M
    """
    centre = np.asarray(centre, dtype=float)
    dims = centre.shape[-1] if dims is None else dims
    if centre.shape != (scan.batch, dims):
        raise InputError(f"gate centre must have shape {(scan.batch, dims)}, got {centre.shape}")
    if not radius > 0:
        raise InputError(f"gate radius must be > 0, got {radius}")
    if dims > scan.z.shape[-1]:
        raise InputError(f"gate dims {dims} exceeds the scan's {scan.z.shape[-1]} measurement components")
    if 0 < dims < 8:
        # the squared distance as np.sum((z - c) ** 2, axis=-1) adds a short axis (in index order), one component
        # at a time: the same numbers without the slow reduction over a length-3 axis
        d2 = scan.z[..., 0] - centre[:, 0, None]
        d2 *= d2
        for k in range(1, dims):
            dk = scan.z[..., k] - centre[:, k, None]
            dk *= dk
            d2 += dk
    else:
        d2 = np.sum((scan.z[..., :dims] - centre[:, None, :]) ** 2, axis=-1)
    keep = scan.valid & (d2 <= radius * radius)
    width = int(keep.sum(axis=1).max()) if keep.size else 0
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    rows = np.arange(scan.batch)[:, None]
    pick = lambda a: None if a is None else a[rows, order]  # noqa: E731  (rows moved, every trailing axis kept)
    # the rows of a checked scan, so the Scan's checks are not run again; its normalisation is: padding rows
    # zeroed (z), identity covariances
    valid = keep[rows, order]
    z = scan.z[rows, order]
    if np.any(~valid & np.any(z != 0.0, axis=-1)):
        z = np.where(valid[..., None], z, 0.0)
    cov = pick(scan.cov)
    if cov is not None:
        cov = np.where(valid[..., None, None], cov, np.broadcast_to(np.eye(z.shape[-1]), cov.shape))
    gated = _validated(Scan, z=z, valid=valid, snr=pick(scan.snr), doppler=pick(scan.doppler),
                       origin=pick(scan.origin), time=float(scan.time), cov=cov,
                       clutter_density=pick(scan.clutter_density))
    return gated, keep


#: :func:`~workbench.tracking.loop.run`'s default association (the loop imports no role).
default_association(Direct)


class Gated(SingleTarget):
    """Gate by a radius around the predicted position; update with the whole gated scan (a filter with the
    ``multi_measurement`` capability) or with ``pseudo(gated, predicted_mean, rng)`` (any other filter).

    Per scan: predict (from scan 1 on); the predicted position is ``F x_{k-1|k-1}``, the motion model's
    prediction of the last estimate (for a particle cloud the expectation of its predicted mean), so the
    estimate is taken once per scan; for a motion model that overrides ``f`` (not linear) it is the filter's own
    estimate of its predicted state, never ``F x``; gate; update.  ``pseudo`` returns the pseudo-measurement as a
    :class:`~workbench.types.Scan` (with its own ``cov`` and ``clutter_density`` where it has them), or
    ``(Scan, MeasurementModel)`` when the model changes per scan.

    Records: ``gated_count (B, T)`` int; ``gated (B, T, M)`` bool, the keep mask of every scan in its own row
    order (metrics read the detections' origin through it; the filter never does).
    """

    def __init__(self, radius: float, pseudo: Callable[..., Any] | None = None, dims: int = 3):
        if not radius > 0:
            raise InputError(f"gate radius must be > 0, got {radius}")
        self.radius, self.pseudo, self.dims = float(radius), pseudo, int(dims)
        self._width = 0

    state_class = GatedState

    def begin(self, ctx, prior, first):
        multi = "multi_measurement" in ctx.filter.capabilities
        if not multi and self.pseudo is None:
            raise InputError(f"filter {ctx.filter.name!r} takes one measurement per scan: the gated association "
                             "needs a pseudo-measurement step for it")
        prior, _ = super().begin(ctx, prior, first)
        return prior, GatedState()

    def record_shapes(self, ctx, n):
        return {"gated_count": ((), int, 0)}

    def started(self, carry, prior):
        carry.role.previous = carry.ctx.filter.estimate(carry.state).mean

    def predicted_mean(self, carry, k):
        role: GatedState = carry.role
        if k > 0:
            motion = carry.motion
            if not motion.linear:
                # a nonlinear model: the filter's own prediction (its F is not the model's transition)
                return super().predicted_mean(carry, k)
            # p_{k|k-1} = F x_{k-1|k-1}
            role.previous = role.previous @ motion.F.T
        return role.previous

    def associate(self, carry, scan, k, predicted):
        gated, keep = radius_gate(scan, predicted[:, : self.dims], self.radius, self.dims)
        carry.records["gated_count"][:, k] = gated.counts
        carry.role.masks.append(keep)
        if "multi_measurement" in carry.ctx.filter.capabilities:
            return gated, carry.ctx.model
        step = self.pseudo(gated, predicted, carry.ctx.rng)
        if isinstance(step, tuple):  # (pseudo-measurement, its per-scan model)
            return step
        return step, carry.ctx.model

    def updated(self, carry, k, estimate):
        carry.role.previous = estimate.mean

    def finish(self, carry):
        track = super().finish(carry)
        masks = carry.role.masks
        width = max((m.shape[1] for m in masks), default=0)
        gated = np.zeros((carry.ctx.batch, len(masks), width), dtype=bool)
        for k, m in enumerate(masks):
            gated[:, k, : m.shape[1]] = m
        return Track(track.filter, track.mean, track.cov, track.predicted_mean, track.diagnostics,
                     {**track.records, "gated": gated}, track.seconds)


# -- nearest neighbour ----------------------------------------------------------------------------------


def predicted_measurement(belief: Gaussian, model: MeasurementModel) -> tuple[np.ndarray, np.ndarray]:
    """``z^ = h(x-)`` and ``S = H P- H^T + R`` for a predicted belief.

    Shapes: ``belief.mean (B, n)`` -> ``z^ (B, m)``, ``S (B, m, m)``.
    """
    if model.H is not None:
        H = np.broadcast_to(model.H, (belief.batch, *model.H.shape))
    elif model.jacobian is not None:
        H = model.jacobian(belief.mean)
    else:
        raise InputError(f"nearest-neighbour association needs H or a Jacobian of {model.name!r}")
    # S = H P- H^T + R
    S = symmetrise(H @ belief.cov @ np.swapaxes(H, -1, -2) + model.R)
    return model.h(belief.mean), S


def nearest_candidate(z: np.ndarray, valid: np.ndarray, z_hat: np.ndarray, S: np.ndarray,
                      model: MeasurementModel, gate: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Index of the candidate nearest (Mahalanobis) to the predicted measurement, per run.

    Returns ``index (B,)`` (-1 where no valid candidate, or none with ``d2 <= gate``) and
    ``d2 (B,)`` of the chosen one (inf where none).

    Shapes: ``z (B, M, m)``, ``valid (B, M)``, ``z_hat (B, m)``, ``S (B, m, m)`` (one innovation covariance per run)
    or ``(B, M, m, m)`` (one per candidate, where each candidate has its own measurement covariance).
    """
    B, M = valid.shape
    if M == 0:
        return np.full(B, -1), np.full(B, np.inf)
    nu = model.residual(z, z_hat[:, None, :])  # (B, M, m)
    if S.ndim == 4:
        # d2_j = |L_j^-1 nu_j|^2 with S_j = L_j L_j^T, one factorisation per candidate
        safe = np.where(valid[..., None, None], S, np.eye(S.shape[-1]))
        white = np.linalg.solve(np.linalg.cholesky(safe), nu[..., None])[..., 0]
        d2 = np.einsum("bmi,bmi->bm", white, white)
    else:
        # d2_j = nu_j^T S^-1 nu_j = |L^-1 nu_j|^2 with S = L L^T: one factorisation per run, M right-hand sides
        white = np.linalg.solve(np.linalg.cholesky(S), np.swapaxes(nu, 1, 2))  # (B, m, M)
        d2 = np.einsum("bim,bim->bm", white, white)
    allowed = valid if gate is None else valid & (d2 <= gate)
    d2 = np.where(allowed, d2, np.inf)
    index = np.argmin(d2, axis=1)
    best = d2[np.arange(B), index]
    return np.where(np.isfinite(best), index, -1), best


def _checked_choice(index: Any, scan: Scan, filter_name: str) -> np.ndarray:
    """The candidate rows a filter's ``gate_candidates`` returned, refused by name unless ``(B,)`` integers, each
    ``-1`` or a valid row of ``scan``."""
    B, M = scan.valid.shape
    index = np.asarray(index)
    where = f"filter {filter_name!r}: gate_candidates"
    if index.shape != (B,) or not np.issubdtype(index.dtype, np.integer):
        raise InputError(f"{where} must return one integer row per run, shape {(B,)}, got {index.dtype} "
                         f"{index.shape}")
    if np.any((index < -1) | (index >= M)):
        bad = sorted(set(index[(index < -1) | (index >= M)].tolist()))
        raise InputError(f"{where} returned rows outside -1 .. {M - 1}: {bad}")
    chosen = index >= 0
    if chosen.any() and not np.all(scan.valid[np.arange(B)[chosen], index[chosen]]):
        raise InputError(f"{where} chose an invalid (empty) row of the scan")
    return index


def strongest_candidate(z: np.ndarray, valid: np.ndarray, snr: np.ndarray) -> np.ndarray:
    """Row of the strongest valid candidate per run, ``(B,)`` (-1 where none)."""
    if z.shape[1] == 0:
        return np.full(z.shape[0], -1)
    # a valid candidate without a strength (NaN) still beats an empty slot
    strength = np.where(valid, np.nan_to_num(snr, nan=-np.finfo(float).max), -np.inf)
    return np.where(valid.any(axis=1), np.argmax(strength, axis=1), -1)


def strongest_candidate_prior(scan: Scan, cov0, fallback_mean) -> tuple[Gaussian, np.ndarray]:
    """Prior from each run's strongest valid candidate (``scan.snr``) of one frame, state = ``z``.

    The state must be the measured quantities themselves (``H = I``, e.g. ``[R, Rdot]``).  A run whose
    frame holds no valid candidate starts at ``fallback_mean`` with the same ``cov0``.

    Returns the prior ``(B, n)``, ``(B, n, n)`` and the chosen row index ``(B,)`` (-1 for the fallback).
    """
    if scan.snr is None:
        raise InputError("strongest_candidate_prior needs candidate strengths (scan.snr)")
    B, _, m = scan.z.shape
    index = strongest_candidate(scan.z, scan.valid, scan.snr)
    fallback = np.broadcast_to(np.asarray(fallback_mean, dtype=float), (B, m))
    picked = scan.z[np.arange(B), np.maximum(index, 0)] if scan.z.shape[1] else fallback
    mean = np.where((index >= 0)[:, None], picked, fallback)
    cov = np.broadcast_to(np.asarray(cov0, dtype=float), (B, m, m)).copy()
    return Gaussian(mean, cov), index


class NearestNeighbour(SingleTarget):
    """Single-target nearest-neighbour association on multi-candidate scans, for any filter.

    Per frame ``k >= 1`` and for every run at once::

        predicted measurement       z^ = h(x-),  S = H P- H^T + R   (H = the model's H, or its Jacobian at x-)
        Mahalanobis distance        d2_j = (z_j - z^)^T S^-1 (z_j - z^)   for every candidate j   (B, M)
        gate (optional)             keep d2_j <= gate  (GATE_99 = 9.21: chi-square 2 dof, P = 0.99)
        NN choice                   j* = argmin_j d2_j;  update with z_j*;  NIS_k = d2_j*
        no candidate (in the gate)  coast: the state stays the prediction
        optional restart            after ``reinit_after`` frames without an update, restart on the
                                    strongest candidate of the frame (the prior's covariance)

    Frame 0 holds the prior; it is not updated again.  ``prior_index (B,)`` names the frame-0 row the prior came
    from (recorded in ``chosen[:, 0]``).  A restart calls ``filter.init`` on every run's current estimate, exact
    for Kalman-type filters and a redraw for a particle filter.

    Where the scan carries each candidate's own covariance (``Scan.cov``), the distance of candidate ``j`` uses
    ``S_j = H P- H^T + R_j`` and the filter is updated with the chosen candidate's ``R_j``.

    **The filter's own choice**: where the filter declares ``FilterSpec.gate_candidates`` (the IMM does: it gates on
    its modes' own predictions, docs/imm.md "Gating on the modes"), the gate and the choice are the filter's,
    ``j* = gate_candidates(state, scan, model, gate)`` on its predicted state (``gate`` as given here, ``None``: no
    gate); everything else (coasting, restarts, the records) is as above, and ``nis`` is the chosen candidate's
    distance under the moment-matched ``S`` of the records.  ``filter_candidates=False`` ignores the declaration and
    gates every filter on its moment-matched prediction ``N(x-, P-)`` (for an IMM: its combined mixture).

    Records: ``predicted_z (B, T, m)``, ``innovation_cov (B, T, m, m)`` (with the model's ``R``; the chosen
    candidate's own where it has one), ``chosen (B, T)`` (-1: none), ``chosen_z (B, T, m)`` (NaN where none),
    ``updated (B, T)``, ``nis (B, T)`` (NaN where not updated), ``restarted (B, T)``.  State between calls:
    :class:`NearestNeighbourState`.
    """

    state_class = NearestNeighbourState

    def __init__(self, gate: float | None = None, prior_index: np.ndarray | None = None,
                 reinit_after: int | None = None, filter_candidates: bool = True):
        if gate is not None and not gate > 0:
            raise InputError(f"gate must be None or > 0, got {gate}")
        if reinit_after is not None and reinit_after < 1:
            raise InputError("reinit_after must be >= 1")
        if not isinstance(filter_candidates, bool):
            raise InputError(f"filter_candidates must be True or False, got {filter_candidates!r}")
        self.gate, self.prior_index, self.reinit_after = gate, prior_index, reinit_after
        self.filter_candidates = filter_candidates

    def begin(self, ctx, prior, first):
        if prior is None:
            raise InputError("nearest-neighbour association needs a prior (strongest_candidate_prior builds one "
                             "from the first scan)")
        hook = ctx.filter.gate_candidates
        if hook is not None and not callable(hook):
            raise InputError(f"filter {ctx.filter.name!r}: FilterSpec.gate_candidates must be a function "
                             f"gate_candidates(state, scan, model, gate) -> index (B,) or None, got "
                             f"{type(hook).__name__}")
        return prior, NearestNeighbourState(prior.cov, np.zeros(ctx.batch, dtype=int))

    def candidate_choice(self, ctx: Context) -> Callable[..., Any] | None:
        """The function that chooses each run's candidate on the filter's own prediction,
        ``choice(state, scan, model, gate) -> index (B,)``, or ``None`` for the nearest under the moment-matched
        prediction: the filter's ``gate_candidates`` where it declares one and ``filter_candidates`` is on."""
        return ctx.filter.gate_candidates if self.filter_candidates else None

    def record_shapes(self, ctx, n):
        m = ctx.model.dim
        return {"predicted_z": ((m,), float, np.nan), "innovation_cov": ((m, m), float, np.nan),
                "chosen": ((), int, -1), "chosen_z": ((m,), float, np.nan), "updated": ((), bool, False),
                "nis": ((), float, np.nan), "restarted": ((), bool, False)}

    def predicted_mean(self, carry, k):
        belief = carry.ctx.filter.estimate(carry.state)
        z_hat, S = predicted_measurement(belief, carry.ctx.model)
        carry.records["predicted_z"][:, k] = z_hat
        carry.records["innovation_cov"][:, k] = S
        carry.role.z_hat, carry.role.S = z_hat, S
        return belief.mean

    def associate(self, carry, scan, k, predicted):
        rec, ctx = carry.records, carry.ctx
        rows = np.arange(ctx.batch)
        z_k, valid_k = scan.z, scan.valid
        if k == 0:
            if self.prior_index is not None:
                index = np.asarray(self.prior_index, dtype=int)
                rec["chosen"][:, 0] = index
                if z_k.shape[1]:
                    rec["chosen_z"][:, 0] = np.where((index >= 0)[:, None], z_k[rows, np.maximum(index, 0)], np.nan)
            return None, ctx.model
        role: NearestNeighbourState = carry.role
        S = role.S
        if scan.cov is not None:  # each candidate's own R: S_j = H P- H^T + R_j
            S = (S - ctx.model.R)[:, None] + scan.cov
        choice = self.candidate_choice(ctx)
        if choice is None:
            index, d2 = nearest_candidate(z_k, valid_k, role.z_hat, S, ctx.model, self.gate)
        else:
            index = _checked_choice(choice(carry.state, scan, ctx.model, self.gate), scan, ctx.filter.name)
        found = index >= 0
        step = None
        if found.any():
            pick = np.maximum(index, 0)
            z = z_k[rows, pick]
            S_chosen = S[rows, pick] if scan.cov is not None else S
            if choice is not None:
                # NIS as the nearest neighbour records it: the chosen candidate's distance under the moment-matched S
                nu = ctx.model.residual(z, role.z_hat)
                safe = np.where(found[:, None, None], S_chosen, np.eye(S_chosen.shape[-1]))
                d2 = np.einsum("bi,bi->b", nu, np.linalg.solve(safe, nu[..., None])[..., 0])
            cov = None if scan.cov is None else np.where(found[:, None, None], scan.cov[rows, pick],
                                                         np.eye(z.shape[-1]))
            density = None if scan.clutter_density is None else scan.clutter_density[rows, pick]
            step = Scan.single(z, found, time=scan.time, cov=cov, clutter_density=density)
            rec["chosen_z"][found, k] = z[found]
            if scan.cov is not None:
                rec["innovation_cov"][found, k] = S_chosen[found]
        rec["chosen"][:, k] = index
        rec["updated"][:, k] = found
        if found.any() or choice is None:
            rec["nis"][:, k] = np.where(found, d2, np.nan)
        role.misses = np.where(found, 0, role.misses + 1)
        role.scan = scan
        return step, ctx.model

    def updated(self, carry, k, estimate):
        if k == 0 or self.reinit_after is None:
            return
        role: NearestNeighbourState = carry.role
        misses = role.misses
        if not np.any(misses >= self.reinit_after):
            return
        scan, ctx, rec = role.scan, carry.ctx, carry.records
        if scan.snr is None:
            raise InputError("restarting on the strongest candidate needs candidate strengths (scan.snr)")
        if scan.z.shape[-1] != estimate.dim:
            raise InputError(f"restarting on the strongest candidate takes the candidate as the state, so the state "
                             f"({estimate.dim} components) must be the measured quantities ({scan.z.shape[-1]}); "
                             f"use reinit_after=None with this model")
        z_k = scan.z
        rows = np.arange(ctx.batch)
        strongest = strongest_candidate(z_k, scan.valid, scan.snr)
        restart = (misses >= self.reinit_after) & (strongest >= 0)
        if not restart.any():
            return
        mean = np.where(restart[:, None], z_k[rows, np.maximum(strongest, 0)], estimate.mean)
        cov = np.where(restart[:, None, None], role.prior_cov, estimate.cov)
        carry.state = ctx.filter.init(Gaussian(mean, cov), ctx.rng)
        rec["chosen"][restart, k] = strongest[restart]
        rec["chosen_z"][restart, k] = z_k[restart, strongest[restart]]
        rec["restarted"][:, k] = restart
        role.misses = np.where(restart, 0, misses)
        est = ctx.filter.estimate(carry.state)
        carry.mean[:, k] = est.mean
        carry.cov[:, k] = est.cov

    def finish(self, carry):
        track = super().finish(carry)
        return Track(track.filter, track.mean, track.cov, track.predicted_mean, track.diagnostics,
                     {**track.records, "gate": np.array(np.nan if self.gate is None else self.gate)}, track.seconds)
