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
ping and run).

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
from .gate import detection_covariance, gated_pairs, measurement_covariance, measurement_view
from .initiation import initial_state, initiate, mofn_step
from .loop import Context
from .records import PingTracks, TrackerConfig, TrackerState, TrackLog, TrackTable

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


@dataclass
class _MofNCarry:
    ctx: Context
    states: list  # per run: its TrackerState
    predicted: list  # per run: its live tracks' filter state predicted to the coming ping, or None
    rngs: list
    rows: dict
    motion: MotionModel


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
        return _MofNCarry(ctx, [initial_state(ctx.motion.dim) for _ in range(ctx.batch)], [None] * ctx.batch,
                          [generator(self.seed, *self.key, b) for b in range(ctx.batch)], rows, ctx.motion)

    def predict(self, carry: _MofNCarry, motion: MotionModel, k: int) -> _MofNCarry:
        carry.motion = motion
        carry.predicted = [_predict_tracks(st, carry.ctx.filter, motion, carry.rngs[b])
                           for b, st in enumerate(carry.states)]
        return carry

    def update(self, carry: _MofNCarry, scan: Scan, k: int) -> _MofNCarry:
        ctx = carry.ctx
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
