"""The JIPDA tracker (Musicki and Evans, "Joint integrated probabilistic data association: JIPDA", IEEE TAES 2004)
and plain JPDA as its fixed-existence case; registered as ``jipda`` and ``jpda`` by :mod:`.builtin`.

Every track carries a Gaussian filter state and a probability of existence ``r``.  Per scan, for the live tracks of
every run at once (one ``predict`` for all of them, one ``update`` for all gated (track, detection) pairs)::

    1. predict       x-, P- = filter.predict(...)                   r- = p_S r          (p_S = survival)
    2. gate          zhat = h(x-), S = J P- J^T + R (J = dh/dx at x-),  d2 = nu^T S^-1 nu,  nu = wrap(z - zhat);
                     (t, j) is gated when d2 <= chi2_m^-1(P_G)         g_tj = N(nu; 0, S)
    3. clutter       rho_j: the declared clutter_density, or the scan's Scan.clutter_density at the detection, or
                     estimated (clutter_estimate): "scan" (default), per run and scan, the detections not expected
                     from the live tracks over the volume of the box that bounds them,
                     max(M - P_D sum_t r_t, 1) / prod(max z - min z) (uniform clutter over the detections' extent);
                     "gate", per cluster, m_c / V_c (the nonparametric PDA: detections in the cluster over the sum
                     of its tracks' gate volumes V_t = c_m gate^(m/2) sqrt(det S_t)), which a lone detection in a
                     small gate makes large; "scan" falls back to "gate" in a run whose detections span no volume
                     (fewer than two)
    4. associate     miss weight w0_t = 1 - P_D P_G r-,  pair weight w_tj = r- P_D g_tj / rho_j;
                     marginals beta0_t, beta_tj of the joint events per cluster (workbench.tracking.jpda.marginals:
                     exact enumeration up to max_exact_tracks / max_exact_events, loopy belief propagation beyond)
    5. existence     r = beta0 (1 - P_D P_G) r- / (1 - P_D P_G r-) + sum_j beta_tj
    6. state         the moment-matched mixture of the predicted state (weight beta0 (1 - P_D P_G) r- /
                     (1 - P_D P_G r-) / r) and the filter's update with each gated detection (weight beta_tj / r):
                     the PDA update (for the Kalman filter exactly Bar-Shalom's PDAF form); the track's new filter
                     state is filter.init(that Gaussian)
    7. manage        a tentative track is confirmed when r >= confirm_existence; any track is deleted when
                     r < delete_existence
    8. initiate      one-point: every valid detection that the live tracks claim with a total probability
                     sum_t beta_tj below initiate_below (a detection outside every gate: 0) starts a tentative track
                     with existence init_existence, position the frame's position of the detection
                     (Frame.to_position) with covariance A R A^T (A = (dh/dp)^-1), velocity 0 with standard deviation
                     velocity_sigma per axis

``existence=False`` (the registered ``jpda``): plain JPDA over the confirmed tracks; every confirmed track is taken
to exist in the association and the update (r- = 1 there: ``w0 = 1 - P_D P_G``, ``w_tj = P_D g_tj / rho_j``, the
state weights are the marginals, as Stone Soup's JPDA with a PDAHypothesiser), while tentative tracks, which are
hypotheses of the initiator, take part with their existence as in JIPDA; the JIPDA existence of steps 4-5 is still
computed for every track and logged, as the track-quality score of steps 7 and 8 (confirmation, deletion, which
detections the live tracks claim).

The filter must be Gaussian (capability ``gaussian``; its state is the Gaussian it estimates) and must not draw
random numbers (``stochastic``): the mixture is a Gaussian moment match.  Detections are in the measurement model's
own frame (any frame whose position a measurement gives, for the initiation); the state is ``[x, y, vx, vy]``.  The
track log has every live track's mean, covariance and existence; ``hit`` says the track had a detection in its gate
(a new track: its own detection).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from workbench.frames import frame as _frame
from workbench.models import MeasurementModel, MotionModel
from workbench.rng import generator
from workbench.params import Param
from workbench.specs import FilterSpec, TrackerSpec
from workbench.tracking.gate import _jacobian, chi2_gate, position_covariance
from workbench.tracking.jpda import clusters, marginals
from workbench.tracking.loop import Context, run
from workbench.tracking.records import CONFIRMED, TENTATIVE, TrackLog
from workbench.types import Gaussian, InputError, Scan, Scans

__all__ = ["JIPDAConfig", "JIPDA", "run_jipda", "gate_volume", "trackers", "PARAMETERS"]


#: How the clutter density is estimated where neither the parameter nor the scans declare it.
CLUTTER_ESTIMATES = ("scan", "gate")


@dataclass(frozen=True)
class JIPDAConfig:
    """The JIPDA tracker's parameters (see the module docstring; the plugin declares them with units and ranges)."""

    p_detection: float = 0.9
    gate_probability: float = 0.99
    clutter_density: float | None = None
    clutter_estimate: str = "scan"
    survival: float = 0.98
    existence: bool = True
    init_existence: float = 0.1
    confirm_existence: float = 0.9
    delete_existence: float = 0.05
    velocity_sigma: float = 10.0
    initiate_below: float = 0.5
    max_exact_tracks: int = 8
    max_exact_events: int = 100_000
    lbp_tolerance: float = 1e-12
    lbp_iterations: int = 1000

    def __post_init__(self) -> None:
        bad = []
        if not 0.0 < self.p_detection <= 1.0:
            bad.append(f"p_detection must be in (0, 1], got {self.p_detection}")
        if not 0.0 < self.gate_probability < 1.0:
            bad.append(f"gate_probability must be in (0, 1), got {self.gate_probability}")
        if self.clutter_density is not None and not (math.isfinite(self.clutter_density) and self.clutter_density > 0):
            bad.append(f"clutter_density must be None (estimated) or a finite number > 0, got {self.clutter_density}")
        if self.clutter_estimate not in CLUTTER_ESTIMATES:
            bad.append(f"clutter_estimate must be one of {CLUTTER_ESTIMATES}, got {self.clutter_estimate!r}")
        if not 0.0 < self.survival <= 1.0:
            bad.append(f"survival must be in (0, 1], got {self.survival}")
        if not 0.0 < self.init_existence < 1.0:
            bad.append(f"init_existence must be in (0, 1), got {self.init_existence}")
        if not 0.0 <= self.delete_existence < self.confirm_existence <= 1.0:
            bad.append(f"need 0 <= delete_existence < confirm_existence <= 1, got {self.delete_existence}, "
                       f"{self.confirm_existence}")
        if not 0.0 < self.initiate_below <= 1.0:
            bad.append(f"initiate_below must be in (0, 1], got {self.initiate_below}")
        if not (math.isfinite(self.velocity_sigma) and self.velocity_sigma > 0):
            bad.append(f"velocity_sigma must be a finite number > 0, got {self.velocity_sigma}")
        if self.max_exact_tracks < 1 or self.max_exact_events < 1 or self.lbp_iterations < 1:
            bad.append(f"max_exact_tracks, max_exact_events and lbp_iterations must be >= 1, got "
                       f"{self.max_exact_tracks}, {self.max_exact_events}, {self.lbp_iterations}")
        if not self.lbp_tolerance > 0:
            bad.append(f"lbp_tolerance must be > 0, got {self.lbp_tolerance}")
        if bad:
            raise InputError("JIPDA tracker: " + "; ".join(bad))


def gate_volume(S: np.ndarray, gate: float) -> np.ndarray:
    """The volume of the gates ``nu^T S^-1 nu <= gate``: ``c_m gate^(m/2) sqrt(det S)``, ``c_m = pi^(m/2) /
    Gamma(m/2 + 1)`` (``pi`` for ``m = 2``).  ``S (K, m, m) -> (K,)``."""
    m = S.shape[-1]
    c = math.pi ** (m / 2) / math.gamma(m / 2 + 1)
    return c * gate ** (m / 2) * np.sqrt(np.linalg.det(S))


@dataclass
class _Carry:
    ctx: Context
    state: object = None  # the filter state of every live track of every run (None without tracks)
    run: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    r: np.ndarray = field(default_factory=lambda: np.zeros(0))
    next_id: np.ndarray | None = None
    rows: dict = field(default_factory=dict)
    motion: MotionModel | None = None
    rng: np.random.Generator | None = None  # handed to the filter, which does not draw


class JIPDA:
    """The JIPDA association role of :func:`workbench.tracking.run` (see the module docstring): the live tracks of
    every run are one batch of the filter."""

    def __init__(self, config: JIPDAConfig = JIPDAConfig(), seed: int = 0, key: tuple = ()):
        self.config, self.seed, self.key = config, seed, tuple(key)
        self.who = "JIPDA tracker" if config.existence else "JPDA tracker"

    # -- the loop's four calls ---------------------------------------------------------------------------------

    def start(self, ctx: Context, prior, first: Scan) -> _Carry:
        filt, model, motion = ctx.filter, ctx.model, ctx.motion
        if "gaussian" not in filt.capabilities or "stochastic" in filt.capabilities:
            raise InputError(f"{self.who}: filter {filt.name!r} is not a deterministic Gaussian filter (it needs the "
                             f"'gaussian' capability and no 'stochastic' one): the tracker moment-matches each "
                             f"track's Gaussian mixture")
        if motion.dim != 4:
            raise InputError(f"{self.who}: the state must be [x, y, vx, vy] (n = 4), got a motion model with "
                             f"n = {motion.dim}")
        if first.z.shape[-1] != model.dim:
            raise InputError(f"{self.who}: the detections have {first.z.shape[-1]} components but measurement model "
                             f"{model.name!r} has {model.dim}")
        if not model.frame:
            raise InputError(f"{self.who}: measurement model {model.name!r} declares no frame; one-point initiation "
                             f"needs the frame's position of a detection")
        fr = _frame(model.frame)
        if fr.position is None or fr.space != 2 or model.dim != 2:
            raise InputError(f"{self.who}: one-point initiation needs a 2-component frame whose measurement gives a "
                             f"position in the plane; {model.frame!r} does not")
        _jacobian(model, np.zeros((1, 4)))  # refuses a model without a Jacobian by name
        carry = _Carry(ctx, next_id=np.zeros(ctx.batch, dtype=np.int64), motion=motion,
                       rng=generator(self.seed, *self.key, "jipda"))
        carry.rows = {k: [] for k in ("run", "ping", "track_id", "status", "hit", "mean", "cov", "existence")}
        return carry

    def predict(self, carry: _Carry, motion: MotionModel, k: int) -> _Carry:
        carry.motion = motion
        if carry.state is not None:
            carry.state = carry.ctx.filter.predict(carry.state, motion, carry.rng)
            carry.r = self.config.survival * carry.r
        return carry

    def update(self, carry: _Carry, scan: Scan, k: int) -> _Carry:
        cfg, ctx = self.config, carry.ctx
        filt, model = ctx.filter, ctx.model
        z, valid = np.asarray(scan.z, dtype=float), np.asarray(scan.valid, dtype=bool)
        B, M, m = z.shape
        if not np.all(np.isfinite(z[valid])):
            b, j = np.argwhere(valid & ~np.all(np.isfinite(z), axis=-1))[0]
            raise InputError(f"{self.who}: scan {k} of run {b} holds a non-finite detection (row {j})")
        if scan.cov is not None:
            raise InputError(f"{self.who}: the scans carry each detection's own covariance (Scan.cov), which this "
                             f"tracker does not use; give the measurement model's R instead")
        declared = None
        if scan.clutter_density is not None:
            if cfg.clutter_density is not None:
                raise InputError(f"{self.who}: the scans declare their clutter density (Scan.clutter_density) and "
                                 f"the parameter clutter_density states another; give one of the two")
            declared = np.asarray(scan.clutter_density, dtype=float)
            if not np.all(np.isfinite(declared[valid]) & (declared[valid] > 0)):
                raise InputError(f"{self.who}: scan {k} declares a clutter density that is not a finite number > 0")
        gate = chi2_gate(cfg.gate_probability, m)
        pdpg = cfg.p_detection * cfg.gate_probability
        K = carry.ids.shape[0]
        claimed = np.zeros((B, M))  # sum_t beta_tj: the probability that a live track made detection j
        hit = np.zeros(K, dtype=bool)
        if K:
            pred = filt.estimate(carry.state)
            x0, P0 = np.asarray(pred.mean), np.asarray(pred.cov)
            J = _jacobian(model, x0)
            S = J @ P0 @ np.swapaxes(J, -1, -2) + model.R  # S = J P- J^T + R
            S = 0.5 * (S + np.swapaxes(S, -1, -2))
            zhat = np.asarray(model.h(x0), dtype=float).reshape(K, m)
            nu = model.residual(z[carry.run], zhat[:, None, :])  # (K, M, m)
            chol = np.linalg.cholesky(S)
            w_ = np.linalg.solve(chol[:, None], nu[..., None])[..., 0] if m != 2 else _whiten2(chol, nu)
            d2 = np.einsum("kmi,kmi->km", w_, w_)
            inside = (d2 <= gate) & valid[carry.run]
            rows, cols = np.nonzero(inside)
            d2p = d2[rows, cols]
            logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
            g = np.exp(-0.5 * d2p - 0.5 * (m * math.log(2.0 * math.pi) + logdet[rows]))  # N(nu; 0, S)
            det_id = carry.run[rows] * M + cols  # a detection's label over every run
            hit[rows] = True
            # clutter density at each pair
            if cfg.clutter_density is not None:
                rho = np.full(rows.size, float(cfg.clutter_density))
            elif declared is not None:
                rho = declared[carry.run[rows], cols]
            else:
                rho = np.full(rows.size, np.nan)
                if cfg.clutter_estimate == "scan":
                    rho = _scan_density(z, valid, cfg.p_detection * np.bincount(carry.run, weights=carry.r,
                                                                                minlength=B))[carry.run[rows]]
                if np.isnan(rho).any():  # "gate", and "scan" where a run's detections span no volume
                    label = clusters(K, rows, det_id)
                    volume = np.bincount(label, weights=gate_volume(S, gate) * hit)
                    first = np.unique(det_id, return_index=True)[1]
                    count = np.bincount(label[rows[first]], minlength=volume.size)  # distinct detections per cluster
                    rho = np.where(np.isnan(rho), (count / np.maximum(volume, 1e-300))[label[rows]], rho)
            r_pred = carry.r
            limits = dict(max_exact_tracks=cfg.max_exact_tracks, max_exact_events=cfg.max_exact_events,
                          tol=cfg.lbp_tolerance, iterations=cfg.lbp_iterations)
            # JIPDA: miss 1 - P_D P_G r-, pair r- P_D g / rho
            beta0, beta, _ = marginals(1.0 - pdpg * r_pred, rows, det_id, r_pred[rows] * cfg.p_detection * g / rho,
                                       **limits)
            np.add.at(claimed, (carry.run[rows], cols), beta)
            undetected = beta0 * (1.0 - pdpg) * r_pred / (1.0 - pdpg * r_pred)
            r_post = undetected + np.bincount(rows, weights=beta, minlength=K)
            if cfg.existence:
                c0, c = undetected / r_post, beta / r_post[rows]
            else:  # JPDA: every confirmed track exists (r- = 1) in the association and the update
                r_w = np.where(carry.status == CONFIRMED, 1.0, r_pred)
                b0w, bw, _ = marginals(1.0 - pdpg * r_w, rows, det_id, r_w[rows] * cfg.p_detection * g / rho, **limits)
                und_w = b0w * (1.0 - pdpg) * r_w / (1.0 - pdpg * r_w)
                r_w_post = und_w + np.bincount(rows, weights=bw, minlength=K)
                c0, c = und_w / r_w_post, bw / r_w_post[rows]
            # the moment-matched mixture of the prediction and the filter's update with each gated detection
            mean = c0[:, None] * x0
            if rows.size:
                upd = filt.update(filt.take_items(carry.state, rows),
                                  Scan(z[carry.run[rows], cols][:, None, :], np.ones((rows.size, 1), dtype=bool)),
                                  model, carry.rng)
                ue = filt.estimate(upd)
                xj, Pj = np.asarray(ue.mean), np.asarray(ue.cov)
                np.add.at(mean, rows, c[:, None] * xj)
            d0 = x0 - mean
            cov = c0[:, None, None] * (P0 + d0[:, :, None] * d0[:, None, :])
            if rows.size:
                dj = xj - mean[rows]
                np.add.at(cov, rows, c[:, None, None] * (Pj + dj[:, :, None] * dj[:, None, :]))
            cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
            # a mixture of the filter's own covariances with non-negative weights, plus spreads: PSD by algebra
            state = filt.init(Gaussian.trusted(mean, cov), carry.rng)
            status = np.where((carry.status == TENTATIVE) & (r_post >= cfg.confirm_existence), CONFIRMED,
                              carry.status).astype(np.int8)
            keep = np.flatnonzero(r_post >= cfg.delete_existence)
            carry.state = filt.take_items(state, keep) if keep.size else None
            carry.run, carry.ids, carry.status, carry.r = carry.run[keep], carry.ids[keep], status[keep], r_post[keep]
            hit = hit[keep]
            mean_out, cov_out = mean[keep], cov[keep]
        else:
            mean_out, cov_out = np.zeros((0, 4)), np.zeros((0, 4, 4))
        # one-point initiation from every valid detection the live tracks do not claim
        nb, nj = np.nonzero(valid & (claimed < cfg.initiate_below))
        if nb.size:
            fr = _frame(model.frame)
            p = fr.to_position(z[nb, nj], model.sensor_position)
            Pp = position_covariance(model, p, 4)
            x = np.concatenate([p, np.zeros_like(p)], axis=1)
            P = np.zeros((nb.size, 4, 4))
            P[:, :2, :2] = Pp
            P[:, 2, 2] = P[:, 3, 3] = cfg.velocity_sigma**2
            new_state = filt.init(Gaussian(x, P), carry.rng)
            filt.require_batch_contract(new_state, self.who)
            ne = filt.estimate(new_state)
            # identities in detection order within each run
            counts = np.bincount(nb, minlength=B)
            offset = np.arange(nb.size) - np.repeat(np.cumsum(counts) - counts, counts)
            new_ids = carry.next_id[nb] + offset
            carry.next_id = carry.next_id + counts
            status0 = CONFIRMED if cfg.init_existence >= cfg.confirm_existence else TENTATIVE
            carry.state = new_state if carry.state is None else filt.join_items([carry.state, new_state])
            carry.run = np.concatenate([carry.run, nb.astype(np.int64)])
            carry.ids = np.concatenate([carry.ids, new_ids.astype(np.int64)])
            carry.status = np.concatenate([carry.status, np.full(nb.size, status0, dtype=np.int8)])
            carry.r = np.concatenate([carry.r, np.full(nb.size, cfg.init_existence)])
            hit = np.concatenate([hit, np.ones(nb.size, dtype=bool)])
            mean_out = np.concatenate([mean_out, np.asarray(ne.mean)])
            cov_out = np.concatenate([cov_out, np.asarray(ne.cov)])
        n_live = carry.ids.shape[0]
        rows_out = carry.rows
        rows_out["run"].append(carry.run.copy())
        rows_out["ping"].append(np.full(n_live, k, dtype=np.int64))
        rows_out["track_id"].append(carry.ids.copy())
        rows_out["status"].append(carry.status.copy())
        rows_out["hit"].append(hit)
        rows_out["mean"].append(mean_out)
        rows_out["cov"].append(cov_out)
        rows_out["existence"].append(carry.r.copy())
        return carry

    def finish(self, carry: _Carry) -> TrackLog:
        cat = {key: (np.concatenate(v) if v else np.zeros(0)) for key, v in carry.rows.items()
               if key not in ("mean", "cov")}
        order = np.lexsort((cat["ping"], cat["run"]))  # stable: within a (run, ping) the tracks keep their order
        mean = np.concatenate(carry.rows["mean"]).reshape(-1, 4)[order] if carry.rows["mean"] else np.zeros((0, 4))
        cov = (np.concatenate(carry.rows["cov"]).reshape(-1, 4, 4)[order] if carry.rows["cov"]
               else np.zeros((0, 4, 4)))
        return TrackLog(cat["run"][order].astype(np.int64), cat["ping"][order].astype(np.int64),
                        cat["track_id"][order].astype(np.int64), cat["status"][order].astype(np.int8),
                        cat["hit"][order].astype(bool), mean, carry.ctx.batch, carry.ctx.steps, cov,
                        cat["existence"][order].astype(float))


def _scan_density(z: np.ndarray, valid: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """Per run ``(B,)``: ``max(M_b - expected_b, 1) / prod(max z - min z)`` over the run's valid detections ``z (B, M,
    m)`` (an extent of zero on an axis counts as 1e-9 of the largest one); NaN where the box has no volume (fewer than
    two detections, or all at one point)."""
    big = np.where(valid[..., None], z, -np.inf).max(axis=1)
    small = np.where(valid[..., None], z, np.inf).min(axis=1)
    n = valid.sum(axis=1)
    extent = np.where(n[:, None] > 1, big - small, 0.0)
    extent = np.maximum(extent, 1e-9 * extent.max(axis=1, keepdims=True))
    volume = np.prod(extent, axis=1)
    out = np.full(valid.shape[0], np.nan)
    np.divide(np.maximum(n - expected, 1.0), volume, out=out, where=volume > 0)
    return out


def _whiten2(chol: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """``L^-1 nu`` for ``chol (K, 2, 2)`` lower triangular and ``nu (K, M, 2)``: forward substitution."""
    w1 = nu[..., 0] / chol[:, None, 0, 0]
    w2 = (nu[..., 1] - chol[:, None, 1, 0] * w1) / chol[:, None, 1, 1]
    return np.stack([w1, w2], axis=-1)


def run_jipda(scans: Scans, filt: FilterSpec, motion: MotionModel, model: MeasurementModel,
              config: JIPDAConfig = JIPDAConfig(), seed: int = 0, key: tuple = ()) -> TrackLog:
    """Track every run of ``scans`` (``z (B, T, M, m)`` in the model's frame; ``origin`` never read) with
    :class:`JIPDA` through :func:`workbench.tracking.run`; returns the :class:`TrackLog` with covariances and
    existence probabilities."""
    if scans.z.shape[-1] != model.dim:
        raise InputError(f"JIPDA tracker: the detections have {scans.z.shape[-1]} components but measurement model "
                         f"{model.name!r} has {model.dim}")
    return run(filt, scans, motion, model, association=JIPDA(config, seed, key),
               rng=generator(seed, *key, "run"))


# -- the plugin's specs ------------------------------------------------------------------------------------------

_D = JIPDAConfig()

#: The declared parameters of ``jipda`` (``jpda``: the same less ``existence``, which it holds at False).
PARAMETERS = (
    Param("p_detection", _D.p_detection, "P_D: probability that a target is detected at a scan", unit="dimensionless",
          above=0.0, maximum=1.0),
    Param("gate_probability", _D.gate_probability, "P_G: probability that the gate holds a detected target's "
          "detection; the gate is the chi-square quantile of the measurement dimension", unit="dimensionless",
          above=0.0, maximum=0.999999),
    Param("clutter_density", _D.clutter_density, "clutter density per unit measurement volume, in the frame's SI "
          "units (per m^2 in cartesian-2d, per m rad in range-bearing); none: the scans' declared "
          "Scan.clutter_density, else estimated per cluster as detections over gate volume", type="float?",
          unit="dimensionless", above=0.0),
    Param("clutter_estimate", _D.clutter_estimate, "where no density is declared: 'scan' (the detections not expected "
          "from tracks over the box that bounds them, per run and scan) or 'gate' (detections over gate volume per "
          "cluster, the nonparametric PDA)", type="str", choices=CLUTTER_ESTIMATES),
    Param("survival", _D.survival, "p_S: probability that a track's target survives from one scan to the next",
          unit="dimensionless", above=0.0, maximum=1.0),
    Param("init_existence", _D.init_existence, "existence probability of a track started from one detection",
          unit="dimensionless", above=0.0, maximum=0.999999),
    Param("confirm_existence", _D.confirm_existence, "a tentative track is confirmed at this existence probability",
          unit="dimensionless", above=0.0, maximum=1.0),
    Param("delete_existence", _D.delete_existence, "a track is deleted below this existence probability",
          unit="dimensionless", minimum=0.0, maximum=0.999999),
    Param("velocity_sigma", _D.velocity_sigma, "one-point initiation: standard deviation of each velocity "
          "component of a new track (mean 0)", unit="speed", above=0.0),
    Param("initiate_below", _D.initiate_below, "a detection starts a tentative track when the live tracks claim it "
          "with a total association probability below this (outside every gate: 0)", unit="dimensionless",
          above=0.0, maximum=1.0),
    Param("max_exact_tracks", _D.max_exact_tracks, "clusters of at most this many tracks get exact marginals by "
          "enumeration; larger ones loopy belief propagation", type="int", unit="dimensionless", minimum=1,
          maximum=64),
    Param("max_exact_events", _D.max_exact_events, "nor more joint events than this (the bound prod(1 + gated "
          "detections) over the cluster's tracks)", type="int", unit="dimensionless", minimum=1, maximum=10_000_000),
    Param("lbp_tolerance", _D.lbp_tolerance, "belief propagation stops when no message changes by more than this",
          unit="dimensionless", above=0.0, maximum=1.0),
    Param("lbp_iterations", _D.lbp_iterations, "belief propagation stops after this many rounds", type="int",
          unit="dimensionless", minimum=1, maximum=1_000_000),
)
_EXISTENCE = Param("existence", True, "track existence (JIPDA); false: plain JPDA, every confirmed track taken to "
                   "exist in the association and the update, the JIPDA existence a track-quality score for "
                   "confirmation, deletion and initiation only", type="bool")

CAPABILITIES = frozenset({"covariance", "existence"})


def _jipda(scans, filt, motion, model, *, seed=0, key=(), **params):
    return run_jipda(scans, filt, motion, model, JIPDAConfig(**params), seed=seed, key=key)


def _jpda(scans, filt, motion, model, *, seed=0, key=(), **params):
    return run_jipda(scans, filt, motion, model, JIPDAConfig(existence=False, **params), seed=seed, key=key)


def trackers() -> list[TrackerSpec]:
    """The specs of ``jipda`` and ``jpda`` (listed by :func:`workbench_trackers.builtin.trackers`)."""
    both = (("jipda", "JIPDA (Musicki-Evans): JPDA with track existence, exact per cluster, loopy BP beyond; "
             "one-point initiation, confirmation and deletion by existence", _jipda, (*PARAMETERS, _EXISTENCE)),
            ("jpda", "JPDA: the JIPDA with every confirmed track taken to exist (existence=False)", _jpda,
             PARAMETERS))
    return [TrackerSpec(name, summary, fn, params={p.name: p.default for p in params}, parameters=tuple(params),
                        capabilities=CAPABILITIES) for name, summary, fn, params in both]
