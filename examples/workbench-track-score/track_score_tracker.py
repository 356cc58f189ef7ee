"""``score-gnn``: a multi-target tracker with global nearest neighbour assignment and track management by
Blackman's log-likelihood-ratio track score, confirmed and deleted by Wald's sequential probability ratio test
(SPRT); an example of a third-party tracker plugin, written only against the workbench's public API
(:class:`workbench.specs.TrackerSpec`, :class:`workbench.params.Param`, :class:`workbench.tracking.TrackLog` and
a filter's ``init / predict / update / estimate / take_items / join_items``).

Install it with ``pip install -e ./examples/workbench-track-score``; the entry point ``track_score`` in the group
``workbench`` registers the tracker through the hook ``workbench_trackers``.  Then ``workbench check-plugin
score-gnn`` runs the tracker kit on it and ``workbench report --paper 001 --trackers +score-gnn`` adds it to paper
001's comparison.

The track score (Blackman and Popoli, *Design and Analysis of Modern Tracking Systems*, 1999, sec. 6.2)
---------------------------------------------------------------------------------------------------------------
Every track carries ``L = ln(P(data | true target) / P(data | false alarms))``.  With ``P_D`` the detection
probability, ``P_G`` the gate probability, ``beta_FA`` the false-alarm density and ``beta_NT`` the new-target
density (both per unit volume of the measurement space, e.g. per m^2 for Cartesian ``(x, y)``)::

    start (a detection no track takes)   L_0 = ln(P_D beta_NT / beta_FA)
    hit with innovation nu, cov. S       dL  = ln(P_D / beta_FA) - (m/2) ln(2 pi) - ln|S| / 2 - nu^T S^-1 nu / 2
                                             = ln(P_D N(nu; 0, S) / beta_FA)
    miss                                 dL  = ln(1 - P_D P_G)

Wald's SPRT with the declared probability ``alpha`` of confirming a false track and ``beta`` of deleting a true
one gives the thresholds::

    confirm when L >= T_C = ln((1 - beta) / alpha)
    delete a tentative track when L <= T_D = ln(beta / (1 - alpha))
    delete a confirmed track when L - max(L so far) <= T_D     (Blackman's score-drop deletion)

The log's ``existence`` is the track's probability of being a true target, ``P_T = 1 / (1 + exp(-L))``.

Per scan, for each run: the filter predicts every live track; each track's predicted measurement
``zhat = h(x-)`` and ``S = J P- J^T + R`` (``J`` the model's Jacobian, or ``H``) gate the detections
(``nu^T S^-1 nu <= chi2_m^-1(P_G)``); SciPy's ``linear_sum_assignment`` picks the assignment that maximises the
total score (a miss scoring ``ln(1 - P_D P_G)``); the filter updates the assigned tracks (one valid detection each,
the others marked invalid); scores, confirmation and deletion follow; every detection no track took starts a
tentative track at the detection's position (the frame's ``to_position``) with covariance ``A R A^T`` (``A = (dh/dp)
^-1``) and velocity 0 with ``velocity_sigma`` per axis.  A scan may declare its own clutter density
(``Scan.clutter_density``), which then replaces ``false_alarm_density`` for its detections.

The state is ``[x, y, vx, vy]``; detections are in the measurement model's own frame (any 2-component frame that
gives a position in the plane).  Any filter of that problem is taken: gating uses the filter's estimate (its mean
and covariance), so particle filters work too.  Random draws (a stochastic filter's) come from
``generator(seed, *key, "score-gnn", run)``, one stream per run.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from workbench import hookimpl
from workbench.frames import frame as measurement_frame
from workbench.params import Param
from workbench.rng import generator
from workbench.specs import TrackerSpec
from workbench.tracking import CONFIRMED, TENTATIVE, TrackLog
from workbench.types import Gaussian, InputError, Scan

__all__ = ["NAME", "PARAMETERS", "thresholds", "initial_score", "hit_score", "miss_score", "make_tracker",
           "run_score_gnn"]

NAME = "score-gnn"
WHO = f"tracker {NAME!r}"

PARAMETERS = (
    Param("p_detection", 0.9, "probability P_D that a target is detected at a scan", unit="dimensionless",
          above=0.0, maximum=0.999999),
    Param("false_alarm_density", 1e-4, "false-alarm density beta_FA per unit volume of the measurement space "
          "(per m^2 for Cartesian (x, y)); a scan's declared Scan.clutter_density replaces it", unit="dimensionless",
          above=0.0),
    Param("new_target_density", 1e-5, "new-target density beta_NT per unit volume of the measurement space",
          unit="dimensionless", above=0.0),
    Param("p_false_confirm", 1e-3, "SPRT alpha: probability of confirming a false track", unit="dimensionless",
          above=0.0, maximum=0.5),
    Param("p_true_delete", 1e-2, "SPRT beta: probability of deleting a true track", unit="dimensionless",
          above=0.0, maximum=0.5),
    Param("gate_probability", 0.999, "probability P_G that the gate holds the target's detection (the gate is the "
          "chi-square quantile of the measurement dimension)", unit="dimensionless", above=0.0, maximum=0.999999),
    Param("velocity_sigma", 5.0, "standard deviation of a new track's velocity per axis (velocity 0)",
          unit="speed", above=0.0),
)


# -- the score, in closed form ------------------------------------------------------------------------------------


def thresholds(p_false_confirm: float, p_true_delete: float) -> tuple[float, float]:
    """Wald's SPRT thresholds ``(T_C, T_D) = (ln((1 - beta) / alpha), ln(beta / (1 - alpha)))``."""
    a, b = p_false_confirm, p_true_delete
    return math.log((1.0 - b) / a), math.log(b / (1.0 - a))


def initial_score(p_detection: float, new_target_density: float, false_alarm_density) -> np.ndarray:
    """``L_0 = ln(P_D beta_NT / beta_FA)`` of a track started on a detection."""
    return np.log(p_detection * new_target_density / np.asarray(false_alarm_density, dtype=float))


def hit_score(nu: np.ndarray, S: np.ndarray, p_detection: float, false_alarm_density) -> np.ndarray:
    """``ln(P_D N(nu; 0, S) / beta_FA)`` for innovations ``nu (..., m)`` with covariances ``S (..., m, m)``."""
    nu, S = np.asarray(nu, dtype=float), np.asarray(S, dtype=float)
    m = nu.shape[-1]
    d2 = np.einsum("...i,...i->...", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    logdet = np.linalg.slogdet(S)[1]
    return (math.log(p_detection) - np.log(np.asarray(false_alarm_density, dtype=float)) - 0.5 * m * math.log(2 * math.pi)
            - 0.5 * logdet - 0.5 * d2)


def miss_score(p_detection: float, gate_probability: float) -> float:
    """``ln(1 - P_D P_G)``."""
    return math.log1p(-p_detection * gate_probability)


# -- the tracker ----------------------------------------------------------------------------------------------------


def _jacobian(model, x: np.ndarray) -> np.ndarray:
    if model.jacobian is not None:
        return np.asarray(model.jacobian(x), dtype=float)
    if model.H is not None:
        return np.broadcast_to(np.asarray(model.H, dtype=float), (x.shape[0], *np.shape(model.H)))
    raise InputError(f"{WHO}: measurement model {model.name!r} has neither a Jacobian nor H; the gate needs one")


def _check_inputs(scans, filt, motion, model):
    z, valid = np.asarray(scans.z), np.asarray(scans.valid, dtype=bool)
    if motion.dim != 4:
        raise InputError(f"{WHO}: the state must be [x, y, vx, vy] (n = 4); motion model has n = {motion.dim}")
    if z.shape[-1] != model.dim:
        raise InputError(f"{WHO}: the detections have {z.shape[-1]} components but measurement model "
                         f"{model.name!r} has {model.dim}")
    if not model.frame:
        raise InputError(f"{WHO}: measurement model {model.name!r} declares no frame; starting a track needs the "
                         f"frame's position of a detection")
    fr = measurement_frame(model.frame)
    if fr.position is None or fr.space != 2 or model.dim != 2:
        raise InputError(f"{WHO}: starting a track needs a 2-component frame that gives a position in the plane; "
                         f"{model.frame!r} does not")
    if scans.cov is not None:
        raise InputError(f"{WHO}: the scans carry each detection's own covariance (Scans.cov), which this tracker "
                         f"does not use; give the measurement model's R instead")
    bad = valid & ~np.all(np.isfinite(z), axis=-1)
    if bad.any():
        b, k, j = (int(v) for v in np.argwhere(bad)[0])
        raise InputError(f"{WHO}: detection {j} of run {b} at scan {k} is not finite (NaN or inf)")
    if scans.clutter_density is not None:
        dens = np.asarray(scans.clutter_density, dtype=float)
        if not np.all(np.isfinite(dens[valid]) & (dens[valid] > 0)):
            raise InputError(f"{WHO}: the scans declare a clutter density (Scans.clutter_density) that is not a "
                             f"finite number > 0 at every valid detection")
    return fr


def run_score_gnn(scans, filt, motion, model, *, seed=0, key=(), p_detection=0.9, false_alarm_density=1e-4,
                  new_target_density=1e-5, p_false_confirm=1e-3, p_true_delete=1e-2, gate_probability=0.999,
                  velocity_sigma=5.0) -> TrackLog:
    """Track every run of ``scans`` (``z (B, T, M, 2)``); see the module's docstring for the maths."""
    fr = _check_inputs(scans, filt, motion, model)
    z_all, valid_all = np.asarray(scans.z, dtype=float), np.asarray(scans.valid, dtype=bool)
    dens_all = None if scans.clutter_density is None else np.asarray(scans.clutter_density, dtype=float)
    B, T = valid_all.shape[:2]
    m, R = model.dim, np.asarray(model.R, dtype=float)
    t_confirm, t_delete = thresholds(p_false_confirm, p_true_delete)
    gate = float(chi2.ppf(gate_probability, m))
    miss = miss_score(p_detection, gate_probability)
    rows = {k: [] for k in ("run", "ping", "track_id", "status", "hit", "mean", "cov", "existence")}
    for b in range(B):
        rng = generator(seed, *key, NAME, b)
        state, next_id = None, 0
        ids = np.zeros(0, dtype=np.int64)
        status = np.zeros(0, dtype=np.int8)
        score = np.zeros(0)
        best = np.zeros(0)
        for k in range(T):
            sel = valid_all[b, k]
            zk = z_all[b, k][sel]
            dens = (np.full(zk.shape[0], float(false_alarm_density)) if dens_all is None else dens_all[b, k][sel])
            M, K = zk.shape[0], ids.shape[0]
            taken = np.zeros(M, dtype=bool)
            hit = np.zeros(K, dtype=bool)
            if K:
                state = filt.predict(state, motion, rng)
                est = filt.estimate(state)
                gain = np.zeros(K)
                if M:
                    x, P = np.asarray(est.mean), np.asarray(est.cov)
                    J = _jacobian(model, x)
                    S = J @ P @ np.swapaxes(J, -1, -2) + R
                    S = 0.5 * (S + np.swapaxes(S, -1, -2))
                    nu = model.residual(zk[None, :, :], np.asarray(model.h(x))[:, None, :])  # (K, M, m)
                    Sk = np.broadcast_to(S[:, None], (K, M, m, m))
                    d2 = np.einsum("kji,kji->kj", nu, np.linalg.solve(Sk, nu[..., None])[..., 0])
                    pair = hit_score(nu, Sk, p_detection, dens[None, :])
                    big = 1e12
                    cost = np.full((K, M + K), big)
                    cost[:, :M] = np.where(d2 <= gate, -pair, big)
                    cost[np.arange(K), M + np.arange(K)] = -miss
                    r, c = linear_sum_assignment(cost)
                    use = (c < M) & (cost[r, c] < big)
                    r, c = r[use], c[use]
                    hit[r] = True
                    taken[c] = True
                    gain[r] = pair[r, c]
                    zs = np.zeros((K, 1, m))
                    zs[r, 0] = zk[c]
                    state = filt.update(state, Scan(zs, hit[:, None]), model, rng)
                score = score + np.where(hit, gain, miss)
                best = np.maximum(best, score)
                status = np.where(score >= t_confirm, CONFIRMED, status).astype(np.int8)
                drop = np.where(status == CONFIRMED, score - best <= t_delete, score <= t_delete)
                keep = np.flatnonzero(~drop)
                state = filt.take_items(state, keep) if keep.size else None
                ids, status, score, best, hit = ids[keep], status[keep], score[keep], best[keep], hit[keep]
            new = np.flatnonzero(~taken)
            if new.size:
                p = fr.to_position(zk[new], model.sensor_position)
                x0 = np.concatenate([p, np.zeros_like(p)], axis=1)
                Jp = _jacobian(model, x0)[:, :, :2]
                A = np.linalg.inv(Jp)
                P0 = np.zeros((new.size, 4, 4))
                P0[:, :2, :2] = A @ R @ np.swapaxes(A, -1, -2)
                P0[:, 2, 2] = P0[:, 3, 3] = velocity_sigma ** 2
                born = filt.init(Gaussian(x0, P0), rng)
                state = born if state is None else filt.join_items([state, born])
                s0 = initial_score(p_detection, new_target_density, dens[new])
                ids = np.concatenate([ids, next_id + np.arange(new.size)])
                next_id += new.size
                status = np.concatenate([status, np.where(s0 >= t_confirm, CONFIRMED, TENTATIVE).astype(np.int8)])
                score, best = np.concatenate([score, s0]), np.concatenate([best, s0])
                hit = np.concatenate([hit, np.ones(new.size, dtype=bool)])
            K = ids.shape[0]
            if K:
                est = filt.estimate(state)
                rows["mean"].append(np.asarray(est.mean, dtype=float).copy())
                rows["cov"].append(np.asarray(est.cov, dtype=float).copy())
                rows["run"].append(np.full(K, b, dtype=np.int64))
                rows["ping"].append(np.full(K, k, dtype=np.int64))
                rows["track_id"].append(ids.copy())
                rows["status"].append(status.copy())
                rows["hit"].append(hit.copy())
                rows["existence"].append(1.0 / (1.0 + np.exp(-score)))
    if not rows["run"]:
        return TrackLog(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64),
                        np.zeros(0, dtype=np.int8), np.zeros(0, dtype=bool), np.zeros((0, 4)), B, T,
                        np.zeros((0, 4, 4)), np.zeros(0))
    cat = {key: np.concatenate(v) for key, v in rows.items()}
    return TrackLog(cat["run"], cat["ping"], cat["track_id"], cat["status"], cat["hit"], cat["mean"], B, T,
                    cat["cov"], cat["existence"])


def make_tracker() -> TrackerSpec:
    return TrackerSpec(NAME, "GNN with Blackman's track score, confirmed and deleted by Wald's SPRT (example plugin)",
                       run_score_gnn, params={p.name: p.default for p in PARAMETERS}, parameters=PARAMETERS,
                       capabilities=frozenset({"covariance", "existence"}))


@hookimpl
def workbench_trackers():
    return [make_tracker()]
