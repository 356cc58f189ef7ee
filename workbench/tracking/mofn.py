"""The M-of-N multi-target tracker for any filter plugin: classification, two-point initiation, nearest-neighbour
association, M-of-N track management; the :class:`MofN` association role of :func:`workbench.tracking.run`.

Per ping ``k``, with the live tracks as the batch axis of the filter functions (one ``predict`` and one
``update`` call per ping for all tracks)::

    1. predict every live track                         filter.predict(state, motion)
    2. gate    d2 = nu^T S^-1 nu,  nu = wrap(z - h(x-)),  S = J P- J^T + R_g   (J = model Jacobian at x-)
               a (track, detection) pair is in the gate when d2 <= gate (9.21 = chi2_2 99 %)
    3. classify: a detection inside any track's gate is an association detection; the rest are
               initiation detections
    4. associate: nearest neighbour, each detection used at most once, greedy by smallest d2
    5. update every track with its detection (none: the item comes back as predicted)
    6. manage (M-of-N, ``M = confirm_hits``, ``N = confirm_window``): the hit history holds the last N pings;
               a tentative track is confirmed at >= M hits in it; a track is deleted after ``delete_misses``
               consecutive misses, and a tentative track also when it can no longer reach M hits in its
               first N pings.  ``initiation_hits`` of the two initiation detections count as hits (0 by
               default: a track is confirmed by M hits after its initiation, so M + 2 detections in all;
               2 counts both, the looser rule under which one more hit confirms a 3-of-5 track)
    7. initiate: a tentative track from every pair (initiation detection of ping k-1, initiation
               detection of ping k) inside the rectangular gate |dx|, |dy| <= v_max dt, each detection
               in at most one pair (greedy by smallest Chebyshev distance); the prior is
               :func:`two_point_prior` (or :func:`speed_course_prior`, ``prior="speed-course"``)

Options (:class:`TrackerConfig`): ``gate_sigma`` gates with a stated position accuracy instead of the
filter's ``R``; ``detection_sigma`` gives every detection the stated covariance ``s^2 I`` in position (for
the gate, the two-point prior and, through ``Scan.cov``, the update of a filter with the
``detection_covariance`` capability); ``min_speed`` keeps slow tracks from confirmation (stationary clutter).
Scans that carry each detection's own Cartesian covariance ``C_j`` (``Scan.cov``, a recording's stated
accuracy) are used the same way, per detection: gate ``S_kj = J P- J^T + J_h C_j J_h^T``, the two-point
prior from the two detections' ``C``, and the update; ``detection_sigma`` beside them is refused.

Detections are Cartesian positions ``(x, y)``; the filter sees them through the measurement model as
``h(p)`` with ``p = [x, y, 0, ...]`` (:func:`measurement_view`).  That is exact for models whose ``h``
depends on position only (the linear position model, range-bearing); for range-bearing it is the
conversion ``(r, b) = (|p|, atan2(y, x))``.  The state layout is ``[x, y, vx, vy]``.

Every step is vectorised across the live tracks: gating (dense below ``dense_limit`` pairs, else candidate
pairs from a grid over the measurement space with each track's exact gate bounding box,
:func:`gated_pairs`), the assignment (:func:`greedy_assign`, rounds of mutually cheapest pairs), the M-of-N
state machine (:func:`mofn_step`, bit histories) and the filter states (one ``take`` and one ``join`` per
ping and run).  Where the filter draws no random numbers, the assignment is the greedy one and the scans carry no
covariances of their own (:meth:`MofN.batched`), the runs are batched too: every run's live tracks are one filter
batch (one ``predict``, ``update`` and ``init`` per ping for all runs) and gating, assignment and initiation take
all runs' pairs at once, never a pair across runs, so each run's numbers are those of :func:`tracker_step` on its
own, bit for bit.

The tracker never sees ``origin``; metrics (:mod:`workbench.metrics`) compare its log with the truth
afterwards.  Every Monte Carlo run keeps its own tracks and its own random stream (track management is per
run).  Irregular ping intervals are honoured: the initiation box and the two-point velocity use the actual
interval.

Filter states are the filter's own business; the tracker deletes tracks from them and adds new ones through
the filter-state contract the filter declares (:meth:`~workbench.specs.FilterSpec.take_items`,
:meth:`~workbench.specs.FilterSpec.join_items`: its own ``take`` / ``join``, or the ``batch_fields`` its state's
class declares).  Nothing is inferred from an array's length (a ``(4, 4)`` motion matrix is not four tracks); a
filter that declares neither is refused by name at its first track.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..models import MeasurementModel, MotionModel
from ..rng import generator
from ..specs import FilterSpec
from ..types import Gaussian, InputError, Scan, Scans
from .assign import greedy_assign
from .gate import (_whiten, detection_covariance, gate_covariance, gated_pairs, measurement_covariance,
                   measurement_view)
from .initiation import initial_state, initiate, mofn_step, new_track_prior, rectangular_pairs
from .loop import Context
from .records import CONFIRMED, TENTATIVE, PingTracks, TrackerConfig, TrackerState, TrackLog, TrackTable

__all__ = ["tracker_step", "MofN", "track_runs", "run_tracker", "Assigner"]

#: ``assign(rows, cols, d2) -> (taken rows, taken cols)``: how the gated pairs are assigned
#: (:func:`~workbench.tracking.assign.greedy_assign` for M-of-N).
Assigner = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _predict_tracks(st: TrackerState, filt: FilterSpec, motion: MotionModel, rng) -> Any:
    """The live tracks' predicted filter state (``None`` without tracks)."""
    return filt.predict(st.table.state, motion, rng) if st.table.size else None


def _check_filter(filt: FilterSpec, config: TrackerConfig, own_cov: bool = False) -> None:
    if config.detection_sigma is not None and "detection_covariance" not in filt.capabilities:
        raise InputError(f"tracker: detection_sigma hands each detection's covariance to the filter, which filter "
                         f"{filt.name!r} would ignore (it lacks the detection_covariance capability)")
    if own_cov and config.detection_sigma is not None:
        raise InputError("tracker: the detections carry their own covariances (Scan.cov) and detection_sigma states "
                         "another; give one of the two")
    if own_cov and "detection_covariance" not in filt.capabilities:
        raise InputError(f"tracker: the detections carry their own covariances (Scan.cov), which filter "
                         f"{filt.name!r} would ignore (it lacks the detection_covariance capability)")



def tracker_step(st: TrackerState, positions: np.ndarray, filt: FilterSpec, motion: MotionModel,
                 model: MeasurementModel, config: TrackerConfig, rng: np.random.Generator,
                 predicted: Any = None, position_cov: np.ndarray | None = None, assign: Assigner = greedy_assign,
                 who: str = "M-of-N tracker") -> tuple[TrackerState, PingTracks]:
    """Process one ping's Cartesian detections ``positions (M, 2)``; see the module docstring.

    ``predicted`` is the live tracks' filter state already predicted to this ping (by :func:`_predict_tracks`);
    ``None`` predicts here.  ``position_cov (M, 2, 2)``: each detection's own Cartesian position covariance
    ``C_j`` (a recording's stated accuracy); it takes the place of ``detection_sigma`` everywhere: the gate
    (``S_kj = J P- J^T + J_h C_j J_h^T``, unless ``gate_sigma``), the update (``Scan.cov``) and the two-point
    prior.  ``assign`` assigns the gated pairs (greedy nearest neighbour by default; the GNN tracker passes its
    global assignment); ``who`` names the tracker in refusals.
    """
    positions = np.asarray(positions, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(positions)):
        raise InputError(f"tracker: ping {st.ping + 1} holds a non-finite detection position")
    n = motion.dim
    if n != 4:
        raise InputError(f"tracker: the state must be [x, y, vx, vy] (n = 4), got a motion model with n = {n}")
    _check_filter(filt, config, own_cov=position_cov is not None)
    k = st.ping + 1
    table = st.table
    K, M = table.size, positions.shape[0]
    zm = measurement_view(model, positions, n) if M else np.zeros((0, model.dim))
    det_cov = None
    if position_cov is not None:
        position_cov = np.asarray(position_cov, dtype=float).reshape(M, 2, 2)
        if not np.all(np.isfinite(position_cov)):
            raise InputError(f"tracker: ping {k} holds a non-finite detection covariance")
        det_cov = measurement_covariance(model, positions, n, position_cov) if M else np.zeros((0, 2, 2))
    near = np.zeros(M, dtype=bool)
    if K:
        state = predicted if predicted is not None else filt.predict(table.state, motion, rng)
        pred = filt.estimate(state)
        rows, cols, d2 = gated_pairs(pred, positions, zm, model, config, det_cov)
        near[cols] = True
        a_rows, a_cols = assign(rows, cols, d2)
        hit = np.zeros(K, dtype=bool)
        hit[a_rows] = True
        z = np.zeros((K, 1, model.dim))
        z[a_rows, 0] = zm[a_cols]
        cov = None
        if config.detection_sigma is not None or det_cov is not None:  # each detection's own covariance
            cov = np.broadcast_to(np.eye(model.dim), (K, 1, model.dim, model.dim)).copy()
            cov[a_rows, 0] = (det_cov[a_cols] if det_cov is not None
                              else detection_covariance(model, positions[a_cols], n, config.detection_sigma))
        state = filt.update(state, Scan(z, hit[:, None], cov=cov), model, rng)
        est = filt.estimate(state)
        mean = est.mean
        slow = None if config.min_speed is None else np.hypot(mean[:, 2], mean[:, 3]) < config.min_speed
        history, misses, age, status, delete = mofn_step(table.history, table.misses, table.age, table.status, hit,
                                                         config, slow)
        keep = np.flatnonzero(~delete)
        table = TrackTable(table.ids[keep], status[keep], history[keep], misses[keep], age[keep], mean[keep],
                           filt.take_items(state, keep) if keep.size else None,
                           None if table.cov is None else np.asarray(est.cov)[keep])
        hits_out = hit[keep]
    else:
        hits_out = np.zeros(0, dtype=bool)
    # initiation from the unclaimed detections of this ping and the last
    init_pos = positions[~near]
    init_cov = None if position_cov is None else position_cov[~near]
    table, new, used, next_id = initiate(st, table, init_pos, init_cov, filt, motion, model, config, rng, who)
    if new:
        hits_out = np.concatenate([hits_out, np.ones(new, dtype=bool)])
    out = PingTracks(k, table.ids.copy(), table.status.copy(), hits_out, table.mean.copy(),
                     None if table.cov is None else table.cov.copy())
    return TrackerState(table, init_pos[~used], next_id, k,
                        None if init_cov is None else init_cov[~used]), out


def _same_run_pairs(run_a: np.ndarray, run_b: np.ndarray, B: int, limit: int):
    """The pairs ``(i, j)`` of items of the same run, ``run_a[i] == run_b[j]`` (both sorted by run), in blocks of
    whole runs of at most about ``max(limit, 2^20)`` pairs each; a run with more than ``limit`` pairs of its own
    comes alone, flagged (``big``), for the caller's spatial-grid path.  Yields ``i, j, big``."""
    na, nb = np.bincount(run_a, minlength=B), np.bincount(run_b, minlength=B)
    start_a, start_b = np.cumsum(na) - na, np.cumsum(nb) - nb
    size = na * nb
    block = max(int(limit), 1 << 20)
    lo = 0
    while lo < B:
        if size[lo] > limit:
            yield (np.arange(start_a[lo], start_a[lo] + na[lo]), np.arange(start_b[lo], start_b[lo] + nb[lo]),
                   True)
            lo += 1
            continue
        hi, total = lo, 0
        while hi < B and size[hi] <= limit and total + size[hi] <= block:
            total += size[hi]
            hi += 1
        hi = max(hi, lo + 1)
        a = np.arange(start_a[lo], start_a[hi - 1] + na[hi - 1])
        per = nb[run_a[a]]
        i = np.repeat(a, per)
        j = np.repeat(start_b[run_a[a]] - (np.cumsum(per) - per), per) + np.arange(i.size)
        yield i, j, False
        lo = hi


def _gated_pairs_runs(est: Gaussian, track_run: np.ndarray, positions: np.ndarray, det_run: np.ndarray,
                      zm: np.ndarray, model: MeasurementModel, config: TrackerConfig, B: int):
    """:func:`gated_pairs` of every run at once, tracks and detections grouped by run (``track_run``,
    ``det_run``), pairs only within a run: the same pairs and ``d2`` as one call per run (the dense formula for a
    run of at most ``dense_limit`` pairs, :func:`gated_pairs` itself for a larger one).  Indices are global."""
    K, M = est.batch, zm.shape[0]
    e = np.zeros(0, dtype=np.intp)
    if K == 0 or M == 0:
        return e, e, np.zeros(0)
    zhat = model.h(est.mean)
    S, _ = gate_covariance(est, model, config)
    chol = np.linalg.cholesky(S)
    out_r, out_c, out_d = [], [], []
    for i, j, big in _same_run_pairs(track_run, det_run, B, config.dense_limit):
        if i.size == 0 or j.size == 0:
            continue
        if big:  # one run of many pairs: the spatial grid of gated_pairs
            r, c, d2 = gated_pairs(Gaussian.trusted(est.mean[i], est.cov[i]), positions[j], zm[j], model, config)
            out_r.append(i[r])
            out_c.append(j[c])
            out_d.append(d2)
            continue
        # the dense computation of gated_pairs, pair by pair: nu = wrap(z - h(x-)), w = L^-1 nu, d2 = |w|^2
        nu = model.residual(zm[j], zhat[i])
        w = _whiten(chol[i], nu)
        d2 = np.einsum("pi,pi->p", w, w)
        inside = d2 <= config.gate
        out_r.append(i[inside])
        out_c.append(j[inside])
        out_d.append(d2[inside])
    if not out_r:
        return e, e, np.zeros(0)
    return np.concatenate(out_r), np.concatenate(out_c), np.concatenate(out_d)


def _rectangular_pairs_runs(a: np.ndarray, run_a: np.ndarray, b: np.ndarray, run_b: np.ndarray, box: float,
                            dense_limit: int, B: int):
    """:func:`rectangular_pairs` of every run at once (``a``, ``b`` grouped by run), pairs only within a run:
    the same pairs and Chebyshev distances; indices are global."""
    e = np.zeros(0, dtype=np.intp)
    out_i, out_j, out_d = [], [], []
    for i, j, big in _same_run_pairs(run_a, run_b, B, dense_limit):
        if i.size == 0 or j.size == 0:
            continue
        if big:
            ii, jj, d = rectangular_pairs(a[i], b[j], box, dense_limit)
            out_i.append(i[ii])
            out_j.append(j[jj])
            out_d.append(d)
            continue
        d = np.max(np.abs(a[i] - b[j]), axis=-1)
        inside = d <= box
        out_i.append(i[inside])
        out_j.append(j[inside])
        out_d.append(d[inside])
    if not out_i:
        return e, e, np.zeros(0)
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_d)


@dataclass
class _Runs:
    """Every run's live tracks in one table (the filter's batch), grouped by run, each run's tracks in the order
    :func:`tracker_step` keeps them; and every run's initiation candidates, grouped by run likewise."""

    run: np.ndarray  # (K,) each track's run
    table: TrackTable
    candidates: np.ndarray  # (P, 2)
    candidate_run: np.ndarray  # (P,)
    next_id: np.ndarray  # (B,) each run's next free identity
    predicted: Any = None  # the live tracks' filter state predicted to the coming ping, or None


@dataclass
class _MofNCarry:
    ctx: Context
    states: list  # per run: its TrackerState (the per-run path)
    predicted: list  # per run: its live tracks' filter state predicted to the coming ping, or None
    rngs: list
    rows: dict
    motion: MotionModel
    runs: _Runs | None = None  # every run at once (the batched path, see MofN.batched)


class MofN:
    """The multi-target role of :func:`workbench.tracking.run`: every run's live tracks are the filter's batch.

    Per run ``b`` the random stream is ``generator(seed, *key, b)``, so a run's tracks do not depend on the other
    runs.  Detections must be Cartesian ``(x, y)``; the filter sees them through its model
    (:func:`measurement_view`).  :meth:`finish` returns a :class:`TrackLog` (rows ordered by run, then ping), with
    each track's covariance when ``keep_cov``.
    """

    #: names the tracker in refusals
    who = "M-of-N tracker"

    def __init__(self, config: TrackerConfig = TrackerConfig(), seed: int = 0, key: tuple = (),
                 keep_cov: bool = False):
        self.config, self.seed, self.key, self.keep_cov = config, seed, tuple(key), bool(keep_cov)

    def assign(self, rows: np.ndarray, cols: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The assignment of the gated pairs: greedy nearest neighbour (:func:`greedy_assign`)."""
        return greedy_assign(rows, cols, d2)

    def start(self, ctx: Context, prior: Gaussian | None, first: Scan) -> _MofNCarry:
        if first.z.shape[-1] != 2:
            raise InputError(f"tracker: detections must be Cartesian (x, y), got dimension {first.z.shape[-1]}")
        _check_filter(ctx.filter, self.config, own_cov=first.cov is not None)
        rows: dict[str, list] = {"run": [], "ping": [], "track_id": [], "status": [], "hit": [], "mean": [],
                                 "cov": []}
        carry = _MofNCarry(ctx, [initial_state(ctx.motion.dim) for _ in range(ctx.batch)], [None] * ctx.batch,
                           [generator(self.seed, *self.key, b) for b in range(ctx.batch)], rows, ctx.motion)
        if self.batched(ctx.filter, first):
            empty = initial_state(ctx.motion.dim)
            carry.runs = _Runs(np.zeros(0, dtype=np.int64), empty.table, empty.candidates,
                               np.zeros(0, dtype=np.int64), np.zeros(ctx.batch, dtype=np.int64))
        return carry

    def batched(self, filt: FilterSpec, first: Scan) -> bool:
        """Whether every run's tracks go through the filter as one batch (one predict, update and init call per
        ping for all runs, gating and assignment of all runs at once, pairs never across runs): for a filter that
        draws no random numbers (a stochastic one draws from each run's own stream, so its runs stay apart), the
        greedy assignment (a subclass's own ``assign`` keeps the per-run path) and scans without their own
        covariances.  The numbers are those of the per-run path, bit for bit (``tests/test_mofn_batched.py``).
        A subclass with its own ``assign`` takes it only where its class declares ``assign_runs_apart = True``
        (its assignment of several runs' pairs at once is each run's own: the GNN's, solved per cluster)."""
        own = getattr(type(self).assign, "__func__", type(self).assign) is not MofN.assign
        return ("stochastic" not in filt.capabilities and first.cov is None
                and (not own or type(self).__dict__.get("assign_runs_apart", False) is True))

    def predict(self, carry: _MofNCarry, motion: MotionModel, k: int) -> _MofNCarry:
        carry.motion = motion
        if carry.runs is not None:
            table = carry.runs.table
            carry.runs.predicted = (carry.ctx.filter.predict(table.state, motion, carry.ctx.rng) if table.size
                                    else None)
            return carry
        carry.predicted = [_predict_tracks(st, carry.ctx.filter, motion, carry.rngs[b])
                           for b, st in enumerate(carry.states)]
        return carry

    def _update_runs(self, carry: _MofNCarry, scan: Scan, k: int) -> _MofNCarry:
        """One ping of every run at once (see :meth:`batched`): :func:`tracker_step` with the live tracks of all
        runs as one batch, gating, assignment and initiation pairs within each run only."""
        ctx, R, config = carry.ctx, carry.runs, self.config
        filt, model, motion, B = ctx.filter, ctx.model, carry.motion, ctx.batch
        det_run = np.nonzero(scan.valid)[0]  # run-major: each run's detections in their order
        positions = np.asarray(scan.z[scan.valid], dtype=float).reshape(-1, 2)
        if not np.all(np.isfinite(positions)):
            raise InputError(f"tracker: ping {k} holds a non-finite detection position")
        n = motion.dim
        if n != 4:
            raise InputError(f"tracker: the state must be [x, y, vx, vy] (n = 4), got a motion model with n = {n}")
        _check_filter(filt, config)
        table, run = R.table, R.run
        K, M = table.size, positions.shape[0]
        zm = measurement_view(model, positions, n) if M else np.zeros((0, model.dim))
        near = np.zeros(M, dtype=bool)
        if K:
            state = R.predicted if R.predicted is not None else filt.predict(table.state, motion, ctx.rng)
            pred = filt.estimate(state)
            rows, cols, d2 = _gated_pairs_runs(pred, run, positions, det_run, zm, model, config, B)
            near[cols] = True
            a_rows, a_cols = self.assign(rows, cols, d2)  # runs never share a pair: each run's own assignment
            hit = np.zeros(K, dtype=bool)
            hit[a_rows] = True
            z = np.zeros((K, 1, model.dim))
            z[a_rows, 0] = zm[a_cols]
            cov = None
            if config.detection_sigma is not None:
                cov = np.broadcast_to(np.eye(model.dim), (K, 1, model.dim, model.dim)).copy()
                cov[a_rows, 0] = detection_covariance(model, positions[a_cols], n, config.detection_sigma)
            state = filt.update(state, Scan(z, hit[:, None], cov=cov), model, ctx.rng)
            est = filt.estimate(state)
            mean = est.mean
            slow = None if config.min_speed is None else np.hypot(mean[:, 2], mean[:, 3]) < config.min_speed
            history, misses, age, status, delete = mofn_step(table.history, table.misses, table.age, table.status,
                                                             hit, config, slow)
            keep = np.flatnonzero(~delete)
            run = run[keep]
            table = TrackTable(table.ids[keep], status[keep], history[keep], misses[keep], age[keep], mean[keep],
                               filt.take_items(state, keep) if keep.size else None, np.asarray(est.cov)[keep])
            hits_out = hit[keep]
        else:
            hits_out = np.zeros(0, dtype=bool)
        # initiation from the unclaimed detections of this ping and the last, pairs within each run
        init_pos, init_run = positions[~near], det_run[~near]
        pi, ci, dist = _rectangular_pairs_runs(R.candidates, R.candidate_run, init_pos, init_run,
                                               config.v_max * motion.dt, config.dense_limit, B)
        a_p, a_c = greedy_assign(pi, ci, dist)
        next_id = R.next_id.copy()
        if a_c.size:
            order = np.argsort(a_c)  # new tracks in detection order (runs in order)
            a_p, a_c = a_p[order], a_c[order]
            prior = new_track_prior(config, model, motion, R.candidates[a_p], init_pos[a_c], n)
            new_state = filt.init(prior, ctx.rng)
            filt.require_batch_contract(new_state, self.who)
            new_est = filt.estimate(new_state)
            new_mean = new_est.mean
            Kn = a_c.size
            new_run = init_run[a_c]
            per_run = np.bincount(new_run, minlength=B)
            first = np.cumsum(per_run) - per_run
            ids = next_id[new_run] + (np.arange(Kn) - first[new_run])  # each run's own identities, in order
            next_id += per_run
            h0 = config.initiation_hits
            status0 = CONFIRMED if h0 >= config.confirm_hits else TENTATIVE
            if status0 == CONFIRMED and config.min_speed is not None:
                status0 = np.where(np.hypot(new_mean[:, 2], new_mean[:, 3]) < config.min_speed, TENTATIVE,
                                   CONFIRMED)
            # each run's kept tracks, then its new ones
            joined = new_state if table.size == 0 else filt.join_items([table.state, new_state])
            all_run = np.concatenate([run, new_run])
            perm = np.argsort(all_run, kind="stable")
            in_order = bool(np.all(perm == np.arange(perm.size)))
            pick = (lambda a: a) if in_order else (lambda a: a[perm])
            table = TrackTable(pick(np.concatenate([table.ids, ids])),
                               pick(np.concatenate([table.status, np.broadcast_to(status0, (Kn,)).astype(np.int8)])),
                               pick(np.concatenate([table.history, np.full(Kn, (1 << h0) - 1, dtype=np.int64)])),
                               pick(np.concatenate([table.misses, np.zeros(Kn, dtype=np.int64)])),
                               pick(np.concatenate([table.age, np.full(Kn, h0, dtype=np.int64)])),
                               pick(np.concatenate([table.mean, new_mean])),
                               joined if in_order else filt.take_items(joined, perm),
                               pick(np.concatenate([table.cov, new_est.cov])))
            hits_out = pick(np.concatenate([hits_out, np.ones(Kn, dtype=bool)]))
            run = all_run[perm]
        used = np.zeros(init_pos.shape[0], dtype=bool)
        used[a_c] = True
        carry.runs = _Runs(run, table, init_pos[~used], init_run[~used], next_id)
        rows = carry.rows
        rows["run"].append(run)
        rows["ping"].append(np.full(table.size, k))
        rows["track_id"].append(table.ids.copy())
        rows["status"].append(table.status.copy())
        rows["hit"].append(hits_out)
        rows["mean"].append(table.mean.copy())
        if self.keep_cov:
            rows["cov"].append(table.cov.copy())
        return carry

    def update(self, carry: _MofNCarry, scan: Scan, k: int) -> _MofNCarry:
        ctx = carry.ctx
        if carry.runs is not None:
            if scan.cov is not None:
                raise InputError("tracker: a scan carries its own covariances (Scan.cov) but the first did not")
            return self._update_runs(carry, scan, k)
        for b in range(ctx.batch):
            st, out = tracker_step(carry.states[b], scan.z[b][scan.valid[b]], ctx.filter, carry.motion, ctx.model,
                                   self.config, carry.rngs[b], predicted=carry.predicted[b],
                                   position_cov=None if scan.cov is None else scan.cov[b][scan.valid[b]],
                                   assign=self.assign, who=self.who)
            carry.states[b], carry.predicted[b] = st, None
            K = out.ids.shape[0]
            carry.rows["run"].append(np.full(K, b))
            carry.rows["ping"].append(np.full(K, k))
            carry.rows["track_id"].append(out.ids)
            carry.rows["status"].append(out.status)
            carry.rows["hit"].append(out.hit)
            carry.rows["mean"].append(out.mean)
            if self.keep_cov:
                carry.rows["cov"].append(out.cov)
        return carry

    def finish(self, carry: _MofNCarry) -> TrackLog:
        n = carry.motion.dim
        cat = {key: (np.concatenate(v) if v else np.zeros(0)) for key, v in carry.rows.items()
               if key not in ("mean", "cov")}
        order = np.lexsort((cat["ping"], cat["run"]))  # stable: within a (run, ping) the tracks keep their order
        cat = {key: v[order] for key, v in cat.items()}
        mean = np.concatenate(carry.rows["mean"]).reshape(-1, n)[order] if carry.rows["mean"] else np.zeros((0, n))
        cov = None
        if self.keep_cov:
            cov = (np.concatenate(carry.rows["cov"]).reshape(-1, n, n)[order] if carry.rows["cov"]
                   else np.zeros((0, n, n)))
        return TrackLog(cat["run"].astype(np.int64), cat["ping"].astype(np.int64), cat["track_id"].astype(np.int64),
                        cat["status"].astype(np.int8), cat["hit"].astype(bool), mean, carry.ctx.batch, carry.ctx.steps,
                        cov)


def track_runs(role: MofN, scans: Scans, filt: FilterSpec, motion: MotionModel, model: MeasurementModel
               ) -> TrackLog:
    """Track every run of ``scans`` (Cartesian detections, ``z (B, T, M, 2)``) with the multi-target ``role``
    through :func:`workbench.tracking.run`.  ``origin`` is never read."""
    from .loop import run

    if scans.z.shape[-1] != 2:
        raise InputError(f"tracker: detections must be Cartesian (x, y), got dimension {scans.z.shape[-1]}")
    # the role draws from its own per-run streams; the run's generator is declared (the loop refuses a stochastic
    # filter without one) and never drawn from
    return run(filt, scans, motion, model, association=role, rng=generator(role.seed, *role.key, "run"))


def run_tracker(scans: Scans, filt: FilterSpec, motion: MotionModel, model: MeasurementModel,
                config: TrackerConfig = TrackerConfig(), seed: int = 0, key: tuple = (),
                keep_cov: bool = False) -> TrackLog:
    """Track every run of ``scans`` (Cartesian detections, ``z (B, T, M, 2)``) with :class:`MofN` through
    :func:`workbench.tracking.run`; one generator per run, ``generator(seed, *key, run)``.  ``origin`` is never
    read.  ``keep_cov``: the log carries each track's covariance."""
    return track_runs(MofN(config, seed, key, keep_cov), scans, filt, motion, model)
