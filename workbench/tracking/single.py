"""Single-target association roles for :func:`workbench.tracking.run`, batched over Monte Carlo runs.

Each role keeps the filter state of every run (the batch axis ``B``) and records, per scan, the estimate, the
prediction and what it associated.  The role decides what the filter's ``update`` sees:

- :class:`Direct`: the scan itself;
- :class:`Gated`: the detections within a radius of the predicted position (whole, or through a pseudo step);
- :class:`NearestNeighbour`: the candidate nearest to the predicted measurement (optionally gated).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..linalg import symmetrise
from ..models import MeasurementModel, MotionModel
from ..types import Gaussian, InputError, Scan
from .loop import Context, Track

__all__ = ["SingleTarget", "Direct", "Gated", "NearestNeighbour", "GATE_99", "radius_gate", "predicted_measurement",
           "nearest_candidate", "strongest_candidate", "strongest_candidate_prior"]

#: chi-square(2 dof) 0.99 quantile: the gate ``d^2 <= 9.21``.
GATE_99 = 9.21


@dataclass
class _Carry:
    ctx: Context
    state: Any
    mean: np.ndarray
    cov: np.ndarray
    predicted: np.ndarray
    records: dict
    start: float
    extra: dict = field(default_factory=dict)


class SingleTarget:
    """The common part of the single-target roles: init, predict, update with what :meth:`associate` chose,
    and the records.  A role overrides :meth:`associate` (and :meth:`begin`, :meth:`predicted_mean`,
    :meth:`record_shapes` where it needs to)."""

    def record_shapes(self, ctx: Context, n: int) -> dict[str, tuple[tuple[int, ...], Any, Any]]:
        """``name -> (trailing shape, dtype, fill)`` of the role's per-step records."""
        return {}

    def begin(self, ctx: Context, prior: Gaussian | None, first: Scan) -> tuple[Gaussian, dict]:
        """The prior to start from and the role's own carry."""
        if prior is None:
            raise InputError(f"{type(self).__name__} association needs a prior")
        return prior, {}

    def start(self, ctx: Context, prior: Gaussian | None, first: Scan) -> _Carry:
        t0 = time.perf_counter()
        prior, extra = self.begin(ctx, prior, first)
        B, T, n = ctx.batch, ctx.steps, prior.dim
        records = {name: np.full((B, T) + shape, fill, dtype=dtype)
                   for name, (shape, dtype, fill) in self.record_shapes(ctx, n).items()}
        state = ctx.filter.init(prior, ctx.rng)
        carry = _Carry(ctx, state, np.empty((B, T, n)), np.empty((B, T, n, n)), np.empty((B, T, n)), records, t0,
                       extra)
        self.started(carry, prior)
        return carry

    def started(self, carry: _Carry, prior: Gaussian) -> None:
        """Called once after ``init`` (a role that tracks its own view of the state starts it here)."""

    def predict(self, carry: _Carry, motion: MotionModel, k: int) -> _Carry:
        carry.state = carry.ctx.filter.predict(carry.state, motion, carry.ctx.rng)
        carry.extra["motion"] = motion
        return carry

    def predicted_mean(self, carry: _Carry, k: int) -> np.ndarray:
        """The predicted state mean at scan ``k`` (the filter's estimate of its predicted state)."""
        return carry.ctx.filter.estimate(carry.state).mean

    def associate(self, carry: _Carry, scan: Scan, k: int, predicted: np.ndarray
                  ) -> tuple[Scan | None, MeasurementModel]:
        """What the filter is updated with at scan ``k`` (``None``: no update) and the model it is given."""
        raise NotImplementedError

    def update(self, carry: _Carry, scan: Scan, k: int) -> _Carry:
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

    def updated(self, carry: _Carry, k: int, estimate: Gaussian) -> None:
        """Called after the update of scan ``k`` with the filter's estimate."""

    def finish(self, carry: _Carry) -> Track:
        ctx = carry.ctx
        diag = dict(ctx.filter.diagnostics(carry.state)) if ctx.filter.diagnostics is not None else {}
        return Track(ctx.filter.name, carry.mean, carry.cov, carry.predicted, diag, carry.records,
                     time.perf_counter() - carry.start)


class Direct(SingleTarget):
    """Update with each scan as it is: at most one valid row per item, or any number for a filter with the
    ``multi_measurement`` capability (its own association).  No records."""

    def associate(self, carry, scan, k, predicted):
        return scan, carry.ctx.model

    def step(self, carry: _Carry, motion: MotionModel, scan: Scan, k: int) -> _Carry:
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
        carry.extra["motion"] = motion
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
    d2 = np.sum((scan.z[..., :dims] - centre[:, None, :]) ** 2, axis=-1)
    keep = scan.valid & (d2 <= radius * radius)
    width = int(keep.sum(axis=1).max()) if keep.size else 0
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    pick = lambda a: None if a is None else np.take_along_axis(a, order, axis=1)  # noqa: E731
    cov = None if scan.cov is None else np.take_along_axis(scan.cov, order[..., None, None], axis=1)
    gated = Scan(np.take_along_axis(scan.z, order[..., None], axis=1), np.take_along_axis(keep, order, axis=1),
                 pick(scan.snr), pick(scan.doppler), pick(scan.origin), time=scan.time, cov=cov,
                 clutter_density=pick(scan.clutter_density))
    return gated, keep


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

    def begin(self, ctx, prior, first):
        multi = "multi_measurement" in ctx.filter.capabilities
        if not multi and self.pseudo is None:
            raise InputError(f"filter {ctx.filter.name!r} takes one measurement per scan: the gated association "
                             "needs a pseudo-measurement step for it")
        return super().begin(ctx, prior, first)

    def record_shapes(self, ctx, n):
        return {"gated_count": ((), int, 0)}

    def started(self, carry, prior):
        carry.extra["previous"] = carry.ctx.filter.estimate(carry.state).mean
        carry.extra["masks"] = []

    def predicted_mean(self, carry, k):
        if k > 0:
            motion = carry.extra["motion"]
            if not motion.linear:
                # a nonlinear model: the filter's own prediction (its F is not the model's transition)
                return super().predicted_mean(carry, k)
            # p_{k|k-1} = F x_{k-1|k-1}
            carry.extra["previous"] = carry.extra["previous"] @ motion.F.T
        return carry.extra["previous"]

    def associate(self, carry, scan, k, predicted):
        gated, keep = radius_gate(scan, predicted[:, : self.dims], self.radius, self.dims)
        carry.records["gated_count"][:, k] = gated.counts
        carry.extra["masks"].append(keep)
        if "multi_measurement" in carry.ctx.filter.capabilities:
            return gated, carry.ctx.model
        step = self.pseudo(gated, predicted, carry.ctx.rng)
        if isinstance(step, tuple):  # (pseudo-measurement, its per-scan model)
            return step
        return step, carry.ctx.model

    def updated(self, carry, k, estimate):
        carry.extra["previous"] = estimate.mean

    def finish(self, carry):
        track = super().finish(carry)
        masks = carry.extra["masks"]
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

    Records: ``predicted_z (B, T, m)``, ``innovation_cov (B, T, m, m)`` (with the model's ``R``; the chosen
    candidate's own where it has one), ``chosen (B, T)`` (-1: none), ``chosen_z (B, T, m)`` (NaN where none),
    ``updated (B, T)``, ``nis (B, T)`` (NaN where not updated), ``restarted (B, T)``.
    """

    def __init__(self, gate: float | None = None, prior_index: np.ndarray | None = None,
                 reinit_after: int | None = None):
        if gate is not None and not gate > 0:
            raise InputError(f"gate must be None or > 0, got {gate}")
        if reinit_after is not None and reinit_after < 1:
            raise InputError("reinit_after must be >= 1")
        self.gate, self.prior_index, self.reinit_after = gate, prior_index, reinit_after

    def begin(self, ctx, prior, first):
        if prior is None:
            raise InputError("nearest-neighbour association needs a prior (strongest_candidate_prior builds one "
                             "from the first scan)")
        return prior, {"prior_cov": prior.cov, "misses": np.zeros(ctx.batch, dtype=int)}

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
        carry.extra["z_hat"], carry.extra["S"] = z_hat, S
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
        S = carry.extra["S"]
        if scan.cov is not None:  # each candidate's own R: S_j = H P- H^T + R_j
            S = (S - ctx.model.R)[:, None] + scan.cov
        index, d2 = nearest_candidate(z_k, valid_k, carry.extra["z_hat"], S, ctx.model, self.gate)
        found = index >= 0
        step = None
        if found.any():
            pick = np.maximum(index, 0)
            z = z_k[rows, pick]
            cov = None if scan.cov is None else np.where(found[:, None, None], scan.cov[rows, pick],
                                                         np.eye(z.shape[-1]))
            density = None if scan.clutter_density is None else scan.clutter_density[rows, pick]
            step = Scan.single(z, found, time=scan.time, cov=cov, clutter_density=density)
            rec["chosen_z"][found, k] = z[found]
            if scan.cov is not None:
                rec["innovation_cov"][found, k] = S[rows, pick][found]
        rec["chosen"][:, k] = index
        rec["updated"][:, k] = found
        rec["nis"][:, k] = np.where(found, d2, np.nan)
        carry.extra["misses"] = np.where(found, 0, carry.extra["misses"] + 1)
        carry.extra["scan"] = scan
        return step, ctx.model

    def updated(self, carry, k, estimate):
        if k == 0 or self.reinit_after is None:
            return
        misses = carry.extra["misses"]
        if not np.any(misses >= self.reinit_after):
            return
        scan, ctx, rec = carry.extra["scan"], carry.ctx, carry.records
        if scan.snr is None:
            raise InputError("restarting on the strongest candidate needs candidate strengths (scan.snr)")
        z_k = scan.z
        rows = np.arange(ctx.batch)
        strongest = strongest_candidate(z_k, scan.valid, scan.snr)
        restart = (misses >= self.reinit_after) & (strongest >= 0)
        if not restart.any():
            return
        mean = np.where(restart[:, None], z_k[rows, np.maximum(strongest, 0)], estimate.mean)
        cov = np.where(restart[:, None, None], carry.extra["prior_cov"], estimate.cov)
        carry.state = ctx.filter.init(Gaussian(mean, cov), ctx.rng)
        rec["chosen"][restart, k] = strongest[restart]
        rec["chosen_z"][restart, k] = z_k[restart, strongest[restart]]
        rec["restarted"][:, k] = restart
        carry.extra["misses"] = np.where(restart, 0, misses)
        est = ctx.filter.estimate(carry.state)
        carry.mean[:, k] = est.mean
        carry.cov[:, k] = est.cov

    def finish(self, carry):
        track = super().finish(carry)
        return Track(track.filter, track.mean, track.cov, track.predicted_mean, track.diagnostics,
                     {**track.records, "gate": np.array(np.nan if self.gate is None else self.gate)}, track.seconds)
