"""Single-target nearest-neighbour (NN) tracking on multi-candidate scans, for any filter.

Per frame ``k >= 1`` and for every Monte Carlo run at once (batch axis ``B``)::

    predict                     x-, P-       (the filter's own predict)
    predicted measurement       z^ = h(x-),  S = H P- H^T + R   (H = the model's H, or its Jacobian at x-)
    Mahalanobis distance        d2_j = (z_j - z^)^T S^-1 (z_j - z^)   for every candidate j   (B, M)
    gate (optional)             keep d2_j <= gamma  (gamma = 9.21: chi-square 2 dof, P = 0.99)
    NN choice                   j* = argmin_j d2_j;  update with z_j*;  NIS_k = d2_j*
    no candidate (in the gate)  coast: the state stays the prediction
    optional restart            after ``reinit_after`` frames without an update, restart on the
                                strongest candidate of the frame (the prior's covariance)

Frame 0 holds the prior (built from a candidate of frame 0, see :func:`strongest_candidate_prior`);
it is not updated again with that candidate.  The tracker never reads ``origin``; the association
log (:func:`association_log`) reads it afterwards, for metrics only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linalg import symmetrise
from .models import MeasurementModel, MotionModel
from .specs import FilterSpec
from .types import Gaussian, InputError, Scan, Scans

__all__ = [
    "GATE_99",
    "NNTrack",
    "AssociationLog",
    "predicted_measurement",
    "nearest_candidate",
    "strongest_candidate_prior",
    "track_nearest_neighbour",
    "association_log",
]

#: chi-square(2 dof) 0.99 quantile: the gate ``d^2 <= 9.21``.
GATE_99 = 9.21


@dataclass(frozen=True)
class NNTrack:
    """A nearest-neighbour track over a scan series, for a batch of runs.

    Shapes
    ------
    mean, predicted_mean : (B, T, n)
    cov : (B, T, n, n)
    predicted_z : (B, T, m), innovation_cov : (B, T, m, m)  (frame 0: the prior's)
    chosen : (B, T) int, the candidate row used at each frame (-1: none; frame 0: the prior's row)
    chosen_z : (B, T, m), NaN where ``chosen == -1``
    updated : (B, T) bool, an update took place (always False at frame 0)
    nis : (B, T), ``d2`` of the chosen candidate where updated, NaN elsewhere
    restarted : (B, T) bool, the track restarted on the strongest candidate (``reinit_after``)
    """

    filter: str
    gate: float | None
    mean: np.ndarray
    cov: np.ndarray
    predicted_mean: np.ndarray
    predicted_z: np.ndarray
    innovation_cov: np.ndarray
    chosen: np.ndarray
    chosen_z: np.ndarray
    updated: np.ndarray
    nis: np.ndarray
    restarted: np.ndarray

    @property
    def coasted(self) -> np.ndarray:
        """``(B, T)``: frames ``k >= 1`` with no update and no restart (no candidate, or none in the gate)."""
        out = ~self.updated & ~self.restarted
        out[:, 0] = False
        return out


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

    Shapes: ``z (B, M, m)``, ``valid (B, M)``, ``z_hat (B, m)``, ``S (B, m, m)``.
    """
    B, M = valid.shape
    if M == 0:
        return np.full(B, -1), np.full(B, np.inf)
    nu = model.residual(z, z_hat[:, None, :])  # (B, M, m)
    # d2_j = nu_j^T S^-1 nu_j = |L^-1 nu_j|^2 with S = L L^T: one factorisation per run, M right-hand sides
    white = np.linalg.solve(np.linalg.cholesky(S), np.swapaxes(nu, 1, 2))  # (B, m, M)
    d2 = np.einsum("bim,bim->bm", white, white)
    allowed = valid if gate is None else valid & (d2 <= gate)
    d2 = np.where(allowed, d2, np.inf)
    index = np.argmin(d2, axis=1)
    best = d2[np.arange(B), index]
    return np.where(np.isfinite(best), index, -1), best


def _strongest(z: np.ndarray, valid: np.ndarray, snr: np.ndarray) -> np.ndarray:
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
    index = _strongest(scan.z, scan.valid, scan.snr)
    fallback = np.broadcast_to(np.asarray(fallback_mean, dtype=float), (B, m))
    picked = scan.z[np.arange(B), np.maximum(index, 0)] if scan.z.shape[1] else fallback
    mean = np.where((index >= 0)[:, None], picked, fallback)
    cov = np.broadcast_to(np.asarray(cov0, dtype=float), (B, m, m)).copy()
    return Gaussian(mean, cov), index


def track_nearest_neighbour(spec: FilterSpec, prior: Gaussian, motion: MotionModel, model: MeasurementModel,
                            scans: Scans, rng: np.random.Generator, *, gate: float | None = None,
                            prior_index: np.ndarray | None = None, reinit_after: int | None = None) -> NNTrack:
    """Run a single-target NN tracker with filter ``spec`` over ``scans`` for all runs at once.

    Parameters
    ----------
    spec : any :class:`~workbench.specs.FilterSpec` (e.g. ``host.filter("kf")``).
    prior : the belief at frame 0, ``(B, n)``.
    gate : ``None`` (no gate: always take the nearest candidate) or a ``d2`` threshold such as
        :data:`GATE_99`; with a gate, a frame with no candidate inside it coasts on the prediction.
    prior_index : ``(B,)`` the frame-0 row the prior came from (recorded in ``chosen[:, 0]``).
    reinit_after : ``None`` (never) or a number of consecutive frames without an update after which a
        run restarts from the strongest candidate of the current frame with the prior's covariance
        (state = ``z``, as :func:`strongest_candidate_prior`; needs ``scans.snr``).  A restart calls
        ``spec.init`` on every run's current Gaussian estimate, which is exact for Kalman-type filters
        and redraws the particles of a particle filter.
    """
    if prior.batch != scans.batch:
        raise InputError(f"prior has batch {prior.batch} but the scans have batch {scans.batch}")
    if gate is not None and not gate > 0:
        raise InputError(f"gate must be None or > 0, got {gate}")
    if reinit_after is not None and (reinit_after < 1 or scans.snr is None):
        raise InputError("reinit_after must be >= 1 and needs candidate strengths (scans.snr)")
    B, T = scans.batch, scans.steps
    n, m = prior.dim, model.dim
    out = {
        "mean": np.empty((B, T, n)), "cov": np.empty((B, T, n, n)), "predicted_mean": np.empty((B, T, n)),
        "predicted_z": np.empty((B, T, m)), "innovation_cov": np.empty((B, T, m, m)),
        "chosen": np.full((B, T), -1), "chosen_z": np.full((B, T, m), np.nan),
        "updated": np.zeros((B, T), dtype=bool), "nis": np.full((B, T), np.nan),
        "restarted": np.zeros((B, T), dtype=bool),
    }
    rows = np.arange(B)
    misses = np.zeros(B, dtype=int)
    state = spec.init(prior, rng)
    for k in range(T):
        if k > 0:
            state = spec.predict(state, motion, rng)
        belief = spec.estimate(state)
        z_hat, S = predicted_measurement(belief, model)
        out["predicted_mean"][:, k] = belief.mean
        out["predicted_z"][:, k] = z_hat
        out["innovation_cov"][:, k] = S
        z_k, valid_k = scans.z[:, k], scans.valid[:, k]  # the tracker never reads scans.origin
        if k > 0:
            index, d2 = nearest_candidate(z_k, valid_k, z_hat, S, model, gate)
            found = index >= 0
            if found.any():
                z = z_k[rows, np.maximum(index, 0)]
                state = spec.update(state, Scan.single(z, found, time=float(scans.times[k])), model, rng)
                out["chosen_z"][found, k] = z[found]
            out["chosen"][:, k] = index
            out["updated"][:, k] = found
            out["nis"][:, k] = np.where(found, d2, np.nan)
            misses = np.where(found, 0, misses + 1)
            if reinit_after is not None and np.any(misses >= reinit_after):
                strongest = _strongest(z_k, valid_k, scans.snr[:, k])
                restart = (misses >= reinit_after) & (strongest >= 0)
                if restart.any():
                    est = spec.estimate(state)
                    mean = np.where(restart[:, None], z_k[rows, np.maximum(strongest, 0)], est.mean)
                    cov = np.where(restart[:, None, None], prior.cov, est.cov)
                    state = spec.init(Gaussian(mean, cov), rng)
                    out["chosen"][restart, k] = strongest[restart]
                    out["chosen_z"][restart, k] = z_k[restart, strongest[restart]]
                    out["restarted"][:, k] = restart
                    misses = np.where(restart, 0, misses)
        elif prior_index is not None:
            index = np.asarray(prior_index, dtype=int)
            out["chosen"][:, 0] = index
            if z_k.shape[1]:
                out["chosen_z"][:, 0] = np.where((index >= 0)[:, None], z_k[rows, np.maximum(index, 0)], np.nan)
        est = spec.estimate(state)
        out["mean"][:, k] = est.mean
        out["cov"][:, k] = est.cov
    return NNTrack(spec.name, gate, **out)


@dataclass(frozen=True)
class AssociationLog:
    """What the NN choices were, scored against the candidates' origin labels (metrics only).

    Shapes: every field ``(B, T)`` bool; frame 0 (the prior) is never an association.

    - ``target_present``: a valid candidate from the target exists (frames ``k >= 1``)
    - ``correct``: the chosen candidate is the target's
    - ``wrong``: a candidate was chosen and it is not the target's (clutter, or a false alarm)
    - ``coasted``: no update
    - ``jump``: the chosen candidate's range is more than ``jump_sigma`` sigma from the prediction
    """

    target_present: np.ndarray
    correct: np.ndarray
    wrong: np.ndarray
    coasted: np.ndarray
    jump: np.ndarray

    @property
    def nn_correct_rate(self) -> float:
        """Fraction of the frames with a target candidate in which NN chose it."""
        n = int(self.target_present.sum())
        return float((self.correct & self.target_present).sum() / n) if n else float("nan")

    def events(self, run: int = 0) -> list[tuple[int, str]]:
        """``(frame, kind)`` for every wrong association, jump and coast of one run, in frame order."""
        out = []
        for kind in ("wrong", "jump", "coasted"):
            out += [(int(k), kind) for k in np.flatnonzero(getattr(self, kind)[run])]
        return sorted(out)


def association_log(track: NNTrack, scans: Scans, target: int = 0, jump_sigma: float = 3.0) -> AssociationLog:
    """Score a track's NN choices against ``scans.origin`` (the truth labels, never seen by the tracker).

    A *jump* is a chosen candidate whose range (component 0) lies more than ``jump_sigma`` standard
    deviations ``sqrt(S_00)`` from the predicted range.
    """
    if scans.origin is None:
        raise InputError("association_log needs scans with origin labels")
    B, T = track.chosen.shape
    later = np.arange(T) >= 1
    from_target = scans.valid & (scans.origin == target)
    present = from_target.any(axis=2) & later
    idx = np.maximum(track.chosen, 0)
    chosen_origin = np.take_along_axis(scans.origin, idx[..., None], axis=2)[..., 0] if scans.z.shape[2] else \
        np.full((B, T), -1)
    picked = track.updated
    correct = picked & (chosen_origin == target)
    wrong = picked & (chosen_origin != target)
    sigma_r = np.sqrt(track.innovation_cov[..., 0, 0])
    jump = picked & (np.abs(np.nan_to_num(track.chosen_z[..., 0]) - track.predicted_z[..., 0]) > jump_sigma * sigma_r)
    return AssociationLog(present, correct, wrong, track.coasted & later, jump)
