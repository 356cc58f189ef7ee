"""The Gaussian-mixture PHD tracker (``gm-phd``): Vo and Ma (2006), "The Gaussian mixture probability hypothesis
density filter", IEEE Trans. Signal Processing 54(11), with labelled state extraction.

The PHD (first-moment intensity) of the targets is a weighted sum of Gaussians ``v(x) = sum_j w_j N(x; m_j, P_j)``,
kept for every run of the batch at once (the components of all runs are one filter batch: one ``predict`` and one
``update`` call of the filter per scan for everything).  Per scan ``k``::

    predict   survivors  w <- P_S w,  (m, P) <- the filter's predict          (Vo & Ma eqs. 22-24)
              births     adaptive: every valid detection z of scan k-1 seeds N(B z, B R B^T + N V N)
                         (B = pinv(H), N = I - B H the unobserved directions, V = birth_velocity_std^2 I),
                         weight birth_rate / M_{k-1}, predicted with the survivors;
                         fixed: the declared GM (birth_mean, birth_std), weight birth_rate / count, at scan k
    update    missed     w (1 - P_D), (m, P) unchanged                          (eq. 26)
              detected   for every valid z and component j (of the same run) with d2 <= gate:
                         q_j(z) = N(z; h(m_j), S_j),  S_j = J_j P_j J_j^T + R   (J_j = dh/dx at m_j)
                         w_j(z) = P_D w_j q_j(z) / (kappa + P_D sum_l w_l q_l(z)),
                         (m_j(z), P_j(z)) = the filter's update of component j with z alone   (eqs. 27-30)
    prune     drop w < prune                                                (Table II)
    merge     per run, repeatedly: the heaviest remaining component and every component i with
              (m_i - m_lead)^T P_i^-1 (m_i - m_lead) <= merge become one, moment matched
              (w = sum w_i, m = sum w_i m_i / w, P = sum w_i (P_i + (m - m_i)(m - m_i)^T) / w);
              then the max_components heaviest are kept
    extract   every component with w > extract is one target estimate (mean, cov, existence = w)

``kappa`` is the clutter intensity per unit measurement volume: the declared ``clutter_density``; else the scans'
own ``Scan.clutter_density`` at each detection (both at once is refused: give one); else estimated per run and scan
as ``max(M - P_D W, 1) / V`` (``M`` valid detections, ``W`` the run's predicted PHD mass, ``V`` the volume of the
box bounding the detections, each side at least ``6 sqrt(R_ii)``).  A linear model is exact (the Kalman update); a
non-linear one is linearised at the predicted mean for ``q`` and updated by the filter's own rule (an EKF, a
UKF...).

Labels (after Panta, Clark and Vo, 2009): every component carries a label.  A birth gets a new one; predict and
update keep the parent's (the missed-detection term and every detection term of component ``j`` carry ``j``'s
label); a merged component keeps the label of its heaviest member; after the merge, where several components of a
run share a label, the heaviest keeps it and each other one gets a new label.  So at every scan labels are unique
within a run, and an extracted estimate's ``track_id`` is its component's label: a target followed by one component
keeps its identity from scan to scan.  Each extracted component is one estimate (``round(w) > 1`` copies of one
component are not duplicated, since they would share one identity).

Requirements, refused by name otherwise: a Gaussian filter (the ``gaussian`` capability) that draws no random
numbers (every run's components share its batch); a filter-state contract (``take`` / ``join`` or ``batch_fields``);
for adaptive birth, a linear measurement model (``H``); scans without per-detection covariances; finite detections.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.models import MeasurementModel, MotionModel
from workbench.params import Param
from workbench.rng import generator
from workbench.specs import FilterSpec, TrackerSpec
from workbench.tracking.gate import chi2_gate
from workbench.tracking.loop import Context
from workbench.tracking.records import CONFIRMED, TrackLog
from workbench.types import Gaussian, InputError, Scan, Scans

__all__ = ["Mixture", "GMPHD", "phd_update", "prune_merge", "relabel", "run_gmphd", "PARAMETERS", "spec"]

WHO = "gm-phd"
BIRTHS = ("adaptive", "fixed")

PARAMETERS = (
    Param("p_survival", 0.99, "probability that a target survives from one scan to the next (P_S)",
          unit="dimensionless", above=0.0, maximum=1.0),
    Param("p_detection", 0.9, "probability that a target is detected at a scan (P_D)", unit="dimensionless",
          above=0.0, maximum=0.999999),
    Param("clutter_density", None, "clutter intensity kappa per unit volume of the measurement space, in the "
          "measurement's SI units (per m^2 for Cartesian (x, y)); none: the scans' own Scan.clutter_density, else "
          "estimated per run and scan (see docs/gm-phd.md)", type="float?", unit="dimensionless", above=0.0),
    Param("birth", "adaptive", "birth model: adaptive (every detection of the previous scan seeds a component, with "
          "birth_velocity_std in the directions the measurement does not see) or fixed (the declared birth_mean, "
          "birth_std)", type="str", choices=BIRTHS),
    Param("birth_rate", 0.1, "expected number of new targets per scan: the birth components' total weight",
          unit="dimensionless", above=0.0),
    Param("birth_velocity_std", 5.0, "adaptive birth: standard deviation of the state in the directions the "
          "measurement model does not observe (the velocity of a position sensor)", unit="state", above=0.0),
    Param("birth_mean", None, "fixed birth: the component means, n numbers each (several components one after the "
          "other)", type="vector?", unit="state"),
    Param("birth_std", None, "fixed birth: the standard deviation of each state component (n numbers, the same for "
          "every birth component)", type="vector?", unit="state", above=0.0),
    Param("gate_probability", 0.9999, "a (component, detection) pair enters the update only inside the chi-square "
          "gate of this probability (none: every pair)", type="float?", unit="dimensionless", above=0.0,
          maximum=0.999999999),
    Param("prune", 1e-5, "components lighter than this are dropped (truncation threshold T)", unit="dimensionless",
          minimum=0.0, maximum=1.0),
    Param("merge", 4.0, "merging threshold U on the Mahalanobis distance squared to the heaviest component",
          unit="gate", minimum=0.0),
    Param("max_components", 100, "most components kept per run after merging (J_max)", type="int",
          unit="dimensionless", minimum=1, maximum=100000),
    Param("extract", 0.5, "a component heavier than this is a target estimate", unit="dimensionless", minimum=0.0,
          maximum=10.0),
)


@dataclass(frozen=True)
class Mixture:
    """The PHD of every run as one list of Gaussian components.

    Shapes: ``run, weight, label, hit (C,)``, ``mean (C, n)``, ``cov (C, n, n)``; ``hit``: the component's
    (heaviest member's) last update was with a detection.
    """

    run: np.ndarray
    weight: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    label: np.ndarray
    hit: np.ndarray

    @property
    def size(self) -> int:
        return int(self.weight.shape[0])

    def take(self, index) -> "Mixture":
        return Mixture(self.run[index], self.weight[index], self.mean[index], self.cov[index], self.label[index],
                       self.hit[index])

    @staticmethod
    def join(parts: list["Mixture"]) -> "Mixture":
        return Mixture(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                         ("run", "weight", "mean", "cov", "label", "hit")))

    @staticmethod
    def empty(n: int) -> "Mixture":
        return Mixture(np.zeros(0, int), np.zeros(0), np.zeros((0, n)), np.zeros((0, n, n)), np.zeros(0, int),
                       np.zeros(0, bool))


def _symmetric(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def _filter_pass(filt: FilterSpec, mix: Mixture, rng) -> Any:
    """The filter's own state for the mixture's components."""
    return filt.init(Gaussian.trusted(mix.mean, _symmetric(mix.cov)), rng)


def phd_update(mix: Mixture, state: Any, scan: Scan, model: MeasurementModel, filt: FilterSpec, rng, *,
               p_detection: float, clutter_density, gate: float | None = None) -> Mixture:
    """The GM-PHD update (Vo & Ma eqs. 26-30) of the predicted mixture ``mix`` (whose filter state is ``state``)
    with ``scan`` (``z (B, M, m)``); the components of run ``r`` see the detections of ``scan`` item ``r`` only.
    ``clutter_density``: ``kappa``, a number or one per detection ``(B, M)``.  ``gate``: the pairs with
    ``d2 > gate`` are left out (``None``: every pair)."""
    C, M = mix.size, scan.z.shape[1]
    missed = Mixture(mix.run, mix.weight * (1.0 - p_detection), mix.mean, mix.cov, mix.label,
                     np.zeros(C, bool))
    if C == 0 or M == 0:
        return missed
    eta = np.asarray(model.h(mix.mean), float)                        # (C, m)
    J = (np.broadcast_to(model.H, (C, *model.H.shape)) if model.H is not None
         else np.asarray(model.jacobian(mix.mean), float))           # (C, m, n)
    S = _symmetric(J @ mix.cov @ np.swapaxes(J, 1, 2) + model.R)      # (C, m, m)
    S_inv = np.linalg.inv(S)
    _, logdet = np.linalg.slogdet(2.0 * np.pi * S)
    z = scan.z[mix.run]                                               # (C, M, m)
    nu = model.residual(z, eta[:, None, :])
    d2 = np.einsum("cmi,cij,cmj->cm", nu, S_inv, nu)
    inside = scan.valid[mix.run] & (d2 <= gate if gate is not None else True)
    q = np.where(inside, np.exp(-0.5 * d2 - 0.5 * logdet[:, None]), 0.0)  # (C, M)
    num = p_detection * mix.weight[:, None] * q
    B = scan.z.shape[0]
    flat = (mix.run[:, None] * M + np.arange(M)[None, :]).ravel()
    denom = clutter_density + np.bincount(flat, weights=num.ravel(), minlength=B * M).reshape(B, M)
    w = num / denom[mix.run]
    jj, ii = np.nonzero(inside)
    if jj.size == 0:
        return missed
    pairs = filt.take_items(state, jj)
    one = Scan(z=scan.z[mix.run[jj], ii][:, None, :], valid=np.ones((jj.size, 1), bool), time=scan.time)
    post = filt.estimate(filt.update(pairs, one, model, rng))
    detected = Mixture(mix.run[jj], w[jj, ii], np.asarray(post.mean), np.asarray(post.cov), mix.label[jj],
                       np.ones(jj.size, bool))
    return Mixture.join([missed, detected])


def _merge_candidates(m: np.ndarray, A: np.ndarray, lam: np.ndarray, have: np.ndarray, merge: float):
    """The pairs ``(r, i, j)`` (components ``i``, ``j`` of run ``r``, both present) whose computed merging distance
    ``d2 = a_i - 2 b_ij + c_ij`` (:func:`prune_merge`) may be ``<= merge``; for every other pair it is above.

    The exact ``Q = (m_i - m_j)^T A_i (m_i - m_j)`` is at least ``lambda_min(A_i) |m_i - m_j|^2``, and the computed
    ``d2`` differs from ``Q`` by at most ``tol = 1e-13 max|A_i| (sum|m_i| + sum|m_j|)^2`` (rounding of sums of
    at most 16 products, about 25 units of round-off against the 450 allowed), so a pair with
    ``lambda_lo |m_i - m_j|^2 > merge + tol`` (``lambda_lo = lam``, the computed smallest eigenvalue, less its own
    round-off bound) is not within the threshold.  The others (pairs within a radius of ``m_i``, from one k-d tree
    of every run's means, the runs kept apart by a fifth coordinate, the radius widened by 1e-6) are returned; a
    row whose ``lambda_lo`` is not positive pairs with every component of its run."""
    from scipy.spatial import cKDTree

    R, width, n = m.shape
    big = np.abs(A).reshape(R, width, n * n).max(axis=2)
    lam = lam - 1e-12 * n * big
    l1 = np.abs(m).sum(axis=2)
    l1_max = np.where(have, l1, 0.0).max(axis=1)
    tol = 1e-13 * big * (l1 + l1_max[:, None]) ** 2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        radius = np.where(lam > 0, np.sqrt((merge + tol) / (lam * (1.0 - 1e-12))) * (1.0 + 1e-6), np.inf)
    r_of, i_of = np.nonzero(have)
    rad = radius[r_of, i_of]
    finite = np.isfinite(rad)
    out_r, out_i, out_j = [], [], []
    if finite.any():
        pts = m[r_of, i_of]
        gap = 4.0 * (float(rad[finite].max()) + float(np.abs(pts).max()) + 1.0)  # runs farther apart than any radius
        tree = cKDTree(np.concatenate([pts, (r_of * gap)[:, None]], axis=1))
        q = np.flatnonzero(finite)
        near = tree.query_ball_point(tree.data[q], rad[q])
        counts = np.fromiter(map(len, near), dtype=np.intp, count=q.size)
        a = np.repeat(q, counts)
        b = np.fromiter(itertools.chain.from_iterable(near), dtype=np.intp, count=int(counts.sum()))
        same = r_of[a] == r_of[b]
        out_r.append(r_of[a[same]])
        out_i.append(i_of[a[same]])
        out_j.append(i_of[b[same]])
    for c in np.flatnonzero(~finite):  # no usable bound: every component of its run
        r = r_of[c]
        js = np.flatnonzero(have[r])
        out_r.append(np.full(js.size, r))
        out_i.append(np.full(js.size, i_of[c]))
        out_j.append(js)
    if not out_r:
        e = np.zeros(0, dtype=np.intp)
        return e, e, e
    return np.concatenate(out_r), np.concatenate(out_i), np.concatenate(out_j)


def prune_merge(mix: Mixture, prune: float, merge: float, max_components: int) -> Mixture:
    """Vo & Ma's pruning and merging (Table II), per run, all runs at once: components lighter than ``prune`` are
    dropped; then, repeatedly, the heaviest remaining component of each run and every remaining component of that
    run within ``merge`` (``(m_i - m_lead)^T P_i^-1 (m_i - m_lead)``) become one component, moment matched, with
    the heaviest's label and hit flag; at most ``max_components`` (the heaviest) are kept per run.  The output is
    ordered by run, then by decreasing weight."""
    mix = mix.take(np.flatnonzero(mix.weight >= prune)) if prune > 0 else mix
    C = mix.size
    if C == 0:
        return mix
    mix = mix.take(np.lexsort((-mix.weight, mix.run)))  # by run, heaviest first
    runs, start, count = np.unique(mix.run, return_index=True, return_counts=True)
    R, width = runs.size, int(count.max())
    slot = np.arange(C) - np.repeat(start, count)                    # place within its run
    table = np.full((R, width), -1)                                   # component of (run, place); -1: none
    table[np.repeat(np.arange(R), count), slot] = np.arange(C)
    # absorb[r, i, j]: component i of run r is within the merging threshold of component j
    # d2(i; j) = (m_i - m_j)^T A_i (m_i - m_j) = m_i^T A_i m_i - 2 (A_i m_i)^T m_j + vec(A_i)^T vec(m_j m_j^T), as
    # batched products (the means taken relative to their run's heaviest component, against cancellation)
    P_inv = _symmetric(np.linalg.inv(mix.cov))
    n = mix.mean.shape[1]
    have = table >= 0
    ti = np.where(have, table, 0)
    m = mix.mean[ti] - mix.mean[table[:, :1]]                        # (R, width, n)
    A = P_inv[ti]                                                     # (R, width, n, n)
    Am = (A @ m[..., None])[..., 0]
    a_i = np.einsum("rin,rin->ri", Am, m)
    # d2 = a_i - 2 b_ij + c_ij is computed only for the pairs that can be within the threshold (_merge_candidates:
    # a bound that the others' computed d2 exceeds it), each by the same product as the (R, width, width) einsum
    # (the same inner loop per element, so the same bits); every other pair is not absorbed
    absorb = np.zeros((R, width, width), dtype=bool)                  # absorb[r, i, j]: i within the threshold of j
    lam = np.linalg.eigvalsh(P_inv)[:, 0][ti]                         # the smallest eigenvalue of each A_i
    r_p, i_p, j_p = _merge_candidates(m, A, lam, have, merge)
    if r_p.size:
        b_p = np.einsum("pk,pk->p", Am[r_p, i_p], m[r_p, j_p])
        c_p = np.einsum("pk,pk->p", A.reshape(R, width, n * n)[r_p, i_p],
                        (m[r_p, j_p, :, None] * m[r_p, j_p, None, :]).reshape(-1, n * n))
        d2 = a_i[r_p, i_p] - 2.0 * b_p + c_p
        absorb[r_p, i_p, j_p] = d2 <= merge
    group = np.full(C, -1)
    leaders = []
    remaining = table >= 0
    G = 0
    while remaining.any():
        live = np.flatnonzero(remaining.any(axis=1))
        lead = remaining[live].argmax(axis=1)                         # the heaviest remaining of each run
        join = remaining[live] & absorb[live, :, lead]
        join[np.arange(live.size), lead] = True
        r_i, p_i = np.nonzero(join)
        group[table[live[r_i], p_i]] = G + r_i
        leaders.append(table[live, lead])
        G += live.size
        remaining[live] &= ~join
    leaders_a = np.concatenate(leaders)
    W = np.bincount(group, weights=mix.weight, minlength=G)
    mean = np.zeros((G, mix.mean.shape[1]))
    np.add.at(mean, group, mix.weight[:, None] * mix.mean)
    mean /= W[:, None]
    d = mean[group] - mix.mean
    spread = mix.cov + d[:, :, None] * d[:, None, :]
    cov = np.zeros((G, *mix.cov.shape[1:]))
    np.add.at(cov, group, mix.weight[:, None, None] * spread)
    cov = _symmetric(cov / W[:, None, None])
    merged = Mixture(mix.run[leaders_a], W, mean, cov, mix.label[leaders_a], mix.hit[leaders_a])
    order = np.lexsort((-merged.weight, merged.run))
    merged = merged.take(order)
    rank = np.arange(G) - np.searchsorted(merged.run, merged.run)  # place within its run, heaviest first
    return merged.take(np.flatnonzero(rank < max_components))


def relabel(mix: Mixture, next_label: np.ndarray) -> tuple[Mixture, np.ndarray]:
    """Labels unique within each run: where components of a run share a label, the heaviest keeps it and each
    other one gets the run's next new label.  ``next_label (B,)`` is the next free label of each run (returned
    advanced)."""
    if mix.size == 0:
        return mix, next_label
    order = np.lexsort((-mix.weight, mix.label, mix.run))
    r, lab = mix.run[order], mix.label[order]
    dup = np.zeros(mix.size, bool)
    dup[1:] = (r[1:] == r[:-1]) & (lab[1:] == lab[:-1])
    if not dup.any():
        return mix, next_label
    label = mix.label.copy()
    nxt = next_label.copy()
    for c in order[dup]:  # few: only where one component's detection terms both survive the merge
        label[c] = nxt[mix.run[c]]
        nxt[mix.run[c]] += 1
    return Mixture(mix.run, mix.weight, mix.mean, mix.cov, label, mix.hit), nxt


@dataclass
class _Carry:
    mix: Mixture
    seeds: Mixture            # adaptive birth: the components seeded by the last scan's detections
    next_label: np.ndarray    # (B,)
    rows: list


class GMPHD:
    """The GM-PHD association role of :func:`workbench.tracking.run` (see the module docstring)."""

    def __init__(self, *, seed: int, key: tuple, p_survival: float, p_detection: float, clutter_density: float | None,
                 birth: str, birth_rate: float, birth_velocity_std: float, birth_mean, birth_std,
                 gate_probability: float | None, prune: float, merge: float, max_components: int, extract: float):
        self.seed, self.key = seed, tuple(key)
        self.p_survival, self.p_detection, self.clutter_density = p_survival, p_detection, clutter_density
        self.birth, self.birth_rate, self.birth_velocity_std = birth, birth_rate, birth_velocity_std
        self.birth_mean, self.birth_std = birth_mean, birth_std
        self.gate_probability = gate_probability
        self.prune, self.merge, self.max_components, self.extract = prune, merge, int(max_components), extract

    # -- the checks ---------------------------------------------------------------------------------------------

    def start(self, ctx: Context, prior: Gaussian | None, first: Scan) -> _Carry:
        filt, model, n = ctx.filter, ctx.model, ctx.motion.dim
        self.filt, self.model, self.n, self.B = filt, model, n, ctx.batch
        self.rng = generator(self.seed, *self.key, WHO)
        self.gate = None if self.gate_probability is None else chi2_gate(self.gate_probability, model.dim)
        if self.birth == "adaptive":
            if model.H is None:
                raise InputError(f"{WHO}: adaptive birth needs a linear measurement model (H); model "
                                 f"{model.name!r} has none: declare birth='fixed' with birth_mean and birth_std")
            H = np.asarray(model.H, float)
            if H.shape[1] != n:
                raise InputError(f"{WHO}: the measurement model's H is {H.shape} but the motion model's state has "
                                 f"{n} components")
            Bm = np.linalg.pinv(H)
            N = np.eye(n) - Bm @ H
            self.birth_map = Bm
            self.birth_cov = _symmetric(Bm @ model.R @ Bm.T + self.birth_velocity_std ** 2 * N @ N.T)
        else:
            if self.birth_mean is None or self.birth_std is None:
                raise InputError(f"{WHO}: birth='fixed' needs birth_mean (n numbers per component) and birth_std "
                                 f"(n numbers)")
            mean = np.asarray(self.birth_mean, float)
            std = np.asarray(self.birth_std, float)
            if std.size != n or mean.size % n or mean.size == 0:
                raise InputError(f"{WHO}: birth_mean must hold a multiple of n = {n} numbers and birth_std n numbers; "
                                 f"got {mean.size} and {std.size}")
            self.fixed_mean = mean.reshape(-1, n)
            self.fixed_cov = np.broadcast_to(np.diag(std ** 2), (self.fixed_mean.shape[0], n, n))
        return _Carry(Mixture.empty(n), Mixture.empty(n), np.zeros(ctx.batch, int), [])

    def _fixed_births(self, next_label: np.ndarray) -> tuple[Mixture, np.ndarray]:
        K = self.fixed_mean.shape[0]
        run = np.repeat(np.arange(self.B), K)
        label = next_label[run] + np.tile(np.arange(K), self.B)
        born = Mixture(run, np.full(run.size, self.birth_rate / K), np.tile(self.fixed_mean, (self.B, 1)),
                       np.tile(self.fixed_cov, (self.B, 1, 1)), label, np.zeros(run.size, bool))
        return born, next_label + K

    def predict(self, carry: _Carry, motion: MotionModel, k: int) -> _Carry:
        mix = carry.mix
        survivors = Mixture(mix.run, mix.weight * self.p_survival, mix.mean, mix.cov, mix.label, mix.hit)
        moving = Mixture.join([survivors, carry.seeds])
        if moving.size:
            state = self.filt.predict(_filter_pass(self.filt, moving, self.rng), motion, self.rng)
            g = self.filt.estimate(state)
            moving = Mixture(moving.run, moving.weight, np.asarray(g.mean), np.asarray(g.cov), moving.label,
                             moving.hit)
        next_label = carry.next_label
        if self.birth == "fixed":
            born, next_label = self._fixed_births(next_label)
            moving = Mixture.join([moving, born])
        return _Carry(moving, Mixture.empty(self.n), next_label, carry.rows)

    def _kappa(self, mix: Mixture, scan: Scan):
        """The clutter intensity at each detection: declared, the scans' own, or estimated (module docstring)."""
        if scan.clutter_density is not None:
            if self.clutter_density is not None:
                raise InputError(f"{WHO}: the scans declare their clutter density (Scan.clutter_density) and the "
                                 f"parameter clutter_density states another; give one of the two")
            return np.asarray(scan.clutter_density, float)
        if self.clutter_density is not None:
            return float(self.clutter_density)
        valid = scan.valid
        if valid.shape[1] == 0:
            return 1.0  # no detection to explain: no term of the update reads it
        big = np.where(valid[..., None], scan.z, np.inf)
        lo = big.min(axis=1)
        hi = np.where(valid[..., None], scan.z, -np.inf).max(axis=1)                 # (B, m)
        floor = 6.0 * np.sqrt(np.diag(self.model.R))
        side = np.maximum(np.where(valid.any(axis=1)[:, None], hi - lo, 0.0), floor)
        mass = np.bincount(mix.run, weights=mix.weight, minlength=self.B)
        count = np.maximum(valid.sum(axis=1) - self.p_detection * mass, 1.0)
        return (count / np.prod(side, axis=1))[:, None] * np.ones(valid.shape)

    def update(self, carry: _Carry, scan: Scan, k: int) -> _Carry:
        if scan.cov is not None:
            raise InputError(f"{WHO}: the scans carry each detection's own covariance (cov), which this tracker does "
                             f"not use; drop it or use a tracker that does")
        bad = scan.valid & ~np.all(np.isfinite(scan.z), axis=-1)
        if bad.any():
            r, i = (int(v) for v in np.argwhere(bad)[0])
            raise InputError(f"{WHO}: detection {i} of run {r} at scan {k} is not finite (NaN or inf)")
        if scan.z.shape[-1] != self.model.dim:
            raise InputError(f"{WHO}: the detections have {scan.z.shape[-1]} components but the measurement model "
                             f"{self.model.name!r} has {self.model.dim}")
        mix, next_label = carry.mix, carry.next_label
        if k == 0 and self.birth == "fixed":
            born, next_label = self._fixed_births(next_label)
            mix = Mixture.join([mix, born])
        state = _filter_pass(self.filt, mix, self.rng) if mix.size else None
        mix = phd_update(mix, state, scan, self.model, self.filt, self.rng, p_detection=self.p_detection,
                         clutter_density=self._kappa(mix, scan), gate=self.gate)
        mix = prune_merge(mix, self.prune, self.merge, self.max_components)
        mix, next_label = relabel(mix, next_label)
        seeds = Mixture.empty(self.n)
        if self.birth == "adaptive":
            r, i = np.nonzero(scan.valid)
            if r.size:
                counts = scan.valid.sum(axis=1)
                label = next_label[r] + (np.arange(r.size) - np.searchsorted(r, r))  # r is sorted
                seeds = Mixture(r, self.birth_rate / counts[r], scan.z[r, i] @ self.birth_map.T,
                                np.broadcast_to(self.birth_cov, (r.size, self.n, self.n)).copy(), label,
                                np.zeros(r.size, bool))
                next_label = next_label + counts
        out = np.flatnonzero(mix.weight > self.extract)
        carry.rows.append((k, mix.take(out)))
        return _Carry(mix, seeds, next_label, carry.rows)

    def finish(self, carry: _Carry) -> TrackLog:
        n = self.n
        parts = [m for _, m in carry.rows]
        pings = np.concatenate([np.full(m.size, k) for k, m in carry.rows]) if carry.rows else np.zeros(0, int)
        mix = Mixture.join(parts) if parts else Mixture.empty(n)
        order = np.lexsort((mix.label, pings, mix.run))
        return TrackLog(run=mix.run[order], ping=pings[order].astype(int), track_id=mix.label[order],
                        status=np.full(order.size, CONFIRMED), hit=mix.hit[order], mean=mix.mean[order],
                        runs=self.B, pings=len(carry.rows), cov=mix.cov[order], existence=mix.weight[order])


def run_gmphd(scans: Scans, filt: FilterSpec, motion: MotionModel, model: MeasurementModel, *, seed: int = 0,
              key: tuple = (), **params) -> TrackLog:
    """Track every run of ``scans`` (``z (B, T, M, m)`` in the measurement model's own space) with the GM-PHD
    filter; ``params`` are :data:`PARAMETERS` (their defaults where not given).  Inputs are never mutated."""
    from workbench.tracking.loop import run

    values = {p.name: p.default for p in PARAMETERS}
    unknown = sorted(set(params) - set(values))
    if unknown:
        raise InputError(f"{WHO}: unknown parameter(s) {', '.join(unknown)} (declared: {', '.join(values)})")
    values.update(params)
    if "gaussian" not in filt.capabilities:
        raise InputError(f"{WHO}: filter {filt.name!r} is not a Gaussian filter (it lacks the gaussian capability); "
                         f"the GM-PHD runs each mixture component through a Gaussian filter's predict and update")
    if "stochastic" in filt.capabilities:
        raise InputError(f"{WHO}: filter {filt.name!r} draws random numbers; the GM-PHD batches every run's "
                         f"components through one filter call and needs a deterministic Gaussian filter")
    if scans.z.shape[-1] != model.dim:
        raise InputError(f"{WHO}: the detections have {scans.z.shape[-1]} components but the measurement model "
                         f"{model.name!r} has {model.dim}")
    probe = filt.init(Gaussian.trusted(np.zeros((1, motion.dim)), np.eye(motion.dim)[None]),
                      generator(seed, *key, WHO, "probe"))
    filt.require_batch_contract(probe, WHO)
    role = GMPHD(seed=seed, key=key, **values)
    return run(filt, scans, motion, model, association=role, rng=generator(seed, *key, WHO, "run"))


def spec() -> TrackerSpec:
    return TrackerSpec("gm-phd", "Gaussian-mixture PHD (Vo & Ma 2006) with pruning, merging and labelled state "
                       "extraction", run_gmphd, params={p.name: p.default for p in PARAMETERS},
                       parameters=PARAMETERS, capabilities=frozenset({"covariance", "existence"}))
