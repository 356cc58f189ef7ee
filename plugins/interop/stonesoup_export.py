"""Truths, detections and tracks as Stone Soup objects, for Stone Soup's metrics, plotters and trackers.

- :func:`ground_truth_paths`: one ``GroundTruthPath`` of ``GroundTruthState`` per run of a
  :class:`~workbench.types.Truth`;
- :func:`detections`: per scan of one run, ``(time stamp, {Detection | Clutter})``, as a Stone Soup detector
  yields them; ``Clutter`` for rows whose origin is :data:`~workbench.types.CLUTTER`, ``Detection`` otherwise
  (with ``origin``, ``snr``, ``doppler`` in the metadata where known);
- :func:`track_log_tracks`: the tracks of one run of a :class:`~workbench.tracking.TrackLog`, one ``Track`` of
  ``GaussianState`` (the log's own covariance, or the one given; ``State`` where there is none) per track id,
  in the tracker's state order or in Stone Soup's (``order="stonesoup"``: ``[x, vx, y, vy]``), the layout
  written stated in each track's metadata (``state_layout``, ``state_order``);
- :func:`filter_tracks`: a single-target filter's :class:`~workbench.tracking.Track`, one ``Track`` of
  ``GaussianState`` per run.

Times: Stone Soup stamps states with ``datetime``; a workbench time ``t`` seconds becomes ``start + t`` (default
start :data:`EPOCH`), rounded to the microsecond, datetime's resolution (:func:`seconds` turns stamps back).
State and measurement values are copied exactly; angular measurement components become Stone Soup
``Bearing`` values when the measurement model is given (Stone Soup then wraps their differences).
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Sequence

import numpy as np

from workbench.models import MeasurementModel, MotionModel
from workbench.tracking import CONFIRMED, Track as WorkbenchTrack, TrackLog
from workbench.types import CLUTTER, InputError, Scans, Truth

from .stonesoup_available import AVAILABLE, EPOCH, REASON, StoneSoupMissing

__all__ = ["EPOCH", "ORDERS", "timestamps", "seconds", "ground_truth_paths", "detections", "state_order",
           "track_log_tracks", "filter_tracks"]

#: The state orders :func:`track_log_tracks` writes: ``workbench``, the tracker's own (the motion model's layout,
#: positions first: ``[x, y, vx, vy]``); ``stonesoup``, Stone Soup's, each position followed by its derivatives
#: (``[x, vx, y, vy]``, as its ``CombinedLinearGaussianTransitionModel`` of ``ConstantVelocity`` models has it).
ORDERS = ("workbench", "stonesoup")


def _require() -> None:
    if not AVAILABLE:
        raise StoneSoupMissing(REASON)  # an ImportError, and an InputError for the command line


def timestamps(times, start: datetime = EPOCH) -> list[datetime]:
    """``start + t`` for every time ``t`` (seconds), to the microsecond."""
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or not np.all(np.isfinite(times)):
        raise InputError(f"times must be a finite vector of seconds, got shape {times.shape}")
    return [start + timedelta(microseconds=round(float(t) * 1e6)) for t in times]


def seconds(stamps: Sequence[datetime], start: datetime = EPOCH) -> np.ndarray:
    """The seconds since ``start`` of Stone Soup time stamps (the inverse of :func:`timestamps`)."""
    return np.array([(s - start) / timedelta(seconds=1) for s in stamps], dtype=float)


def _column(values) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(-1, 1).copy()


def ground_truth_paths(truth: Truth, *, start: datetime = EPOCH) -> list:
    """One Stone Soup ``GroundTruthPath`` per run (``id`` ``"run <b>"``), its ``GroundTruthState`` s holding the full
    true state ``(n, 1)`` at every time."""
    _require()
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState

    stamps = timestamps(truth.times, start)
    return [GroundTruthPath([GroundTruthState(_column(truth.states[b, k]), timestamp=stamps[k])
                             for k in range(truth.steps)], id=f"run {b}") for b in range(truth.batch)]


def detections(scans: Scans, *, run: int = 0, model: MeasurementModel | None = None, ndim_state: int | None = None,
               start: datetime = EPOCH) -> list[tuple[datetime, set]]:
    """The valid detections of run ``run``, scan by scan: ``[(time stamp, {Detection | Clutter, ...}), ...]``.

    With ``model`` (and the state dimension ``ndim_state``) each detection carries it as a Stone Soup measurement
    model (:func:`workbench_interop.stonesoup_models.measurement_model`; a detection's own ``Scans.cov`` as its
    noise covariance), and angular components are ``Bearing`` values.  ``origin``, ``snr`` and ``doppler`` go into
    each detection's metadata where the scans carry them.
    """
    _require()
    from stonesoup.types.detection import Clutter, Detection

    from .stonesoup_models import measurement_model, typed_vector

    if not 0 <= run < scans.batch:
        raise InputError(f"run {run} is not in the scans' {scans.batch} runs")
    if model is not None and ndim_state is None:
        raise InputError("detections with a measurement model need the state dimension (ndim_state)")
    angular = model.angular if model is not None else (False,) * scans.z.shape[-1]
    shared = measurement_model(model, ndim_state) if model is not None else None
    out = []
    for k, stamp in enumerate(timestamps(scans.times, start)):
        found = set()
        for j in np.flatnonzero(scans.valid[run, k]):
            meta = {}
            origin = None if scans.origin is None else int(scans.origin[run, k, j])
            if origin is not None:
                meta["origin"] = origin
            for key in ("snr", "doppler"):
                values = getattr(scans, key)
                if values is not None and np.isfinite(values[run, k, j]):
                    meta[key] = float(values[run, k, j])
            mm = shared
            if model is not None and scans.cov is not None:
                mm = measurement_model(model, ndim_state, scans.cov[run, k, j])
            cls = Clutter if origin == CLUTTER else Detection
            found.add(cls(typed_vector(scans.z[run, k, j], angular), timestamp=stamp, measurement_model=mm,
                          metadata=meta))
        out.append((stamp, found))
    return out


def state_order(names: Sequence[str], order: str) -> list[int]:
    """The permutation ``perm`` that puts a state of the layout ``names`` (the motion model's ``state_names``) in
    ``order`` (:data:`ORDERS`): ``x_out = x[perm]``, ``P_out = P[perm][:, perm]``.

    ``stonesoup``: every position ``a`` whose velocity ``va`` the layout names, in the layout's order, followed by
    ``va`` (and its acceleration ``aa`` where named); any other component (a turn rate ``omega``) after them, in
    the layout's order.  ``["x", "y", "vx", "vy"]`` gives ``[0, 2, 1, 3]``."""
    if order not in ORDERS:
        raise InputError(f"order must be one of {', '.join(ORDERS)}, got {order!r}")
    names = list(names)
    if order == "workbench":
        return list(range(len(names)))
    axes = [a for a in names if f"v{a}" in names]
    if not axes:
        raise InputError(f"order='stonesoup' needs a state layout with positions and their velocities (x, ..., vx, "
                         f"...), declared by the motion model (motion=) or by names=; got {', '.join(names)}")
    perm = [names.index(f"{p}{a}") for a in axes for p in ("", "v", "a") if f"{p}{a}" in names]
    return perm + [i for i in range(len(names)) if i not in perm]


def track_log_tracks(log: TrackLog, times, *, run: int = 0, cov=None, confirmed_only: bool = True,
                     start: datetime = EPOCH, motion: MotionModel | None = None, names: Sequence[str] | None = None,
                     order: str = "workbench") -> list:
    """The tracks of run ``run`` of a tracker's log as Stone Soup ``Track`` s (``id`` ``"<run>-<track id>"``).

    Each holds a ``GaussianState`` per ping at which the track is live (confirmed, with ``confirmed_only``): the
    full state ``(n, 1)`` and its covariance, ``cov (R, n, n)`` (one per log row) where given, else the log's own
    (``TrackLog.cov``); a ``State`` where neither is there.  ``times (T,)``: each ping's time in seconds.

    The state's layout is the motion model's (``motion.state_names``) or ``names``, ``s0, s1, ...`` without
    either (:func:`workbench.tracks_io.state_layout`).  ``order`` (:data:`ORDERS`): ``workbench`` writes the
    state as the log holds it; ``stonesoup`` in Stone Soup's order, each position followed by its velocity
    (``[x, vx, y, vy]``), the covariance permuted with it (:func:`state_order`); it needs a declared layout.  Every
    track's metadata states what was written: ``state_layout`` (the component names, in the order written),
    ``state_order``, ``run`` and ``track_id``.
    """
    _require()
    from stonesoup.types.state import GaussianState, State
    from stonesoup.types.track import Track

    from workbench.tracks_io import state_layout

    n = log.mean.shape[1]
    layout, _ = state_layout(n, motion, names)
    perm = state_order(layout, order)
    stamps = timestamps(times, start)
    if len(stamps) != log.pings:
        raise InputError(f"times must have one entry per ping ({log.pings}), got {len(stamps)}")
    if cov is None:
        cov = log.cov
    if cov is not None and np.shape(cov) != (log.run.size, n, n):
        raise InputError(f"cov must have shape ({log.run.size}, n, n), one per log row, got {np.shape(cov)}")
    written = tuple(layout[i] for i in perm)
    sel = log.run == run
    if confirmed_only:
        sel &= log.status == CONFIRMED
    tracks = []
    for tid in np.unique(log.track_id[sel]):
        rows = np.flatnonzero(sel & (log.track_id == tid))
        rows = rows[np.argsort(log.ping[rows], kind="stable")]
        states = [State(_column(log.mean[r][perm]), timestamp=stamps[log.ping[r]]) if cov is None else
                  GaussianState(_column(log.mean[r][perm]), np.array(cov[r], dtype=float)[np.ix_(perm, perm)],
                                timestamp=stamps[log.ping[r]])
                  for r in rows]
        tracks.append(Track(states, id=f"{run}-{int(tid)}",
                            init_metadata={"state_layout": written, "state_order": order, "run": int(run),
                                           "track_id": int(tid)}))
    return tracks


def filter_tracks(track: WorkbenchTrack, times, *, start: datetime = EPOCH) -> list:
    """A single-target filter's output as one Stone Soup ``Track`` of ``GaussianState`` per run (``id`` ``"run
    <b>"``): the mean ``(n, 1)`` and covariance ``(n, n)`` at every step; ``times (T,)`` in seconds."""
    _require()
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track

    B, T, _ = track.mean.shape
    stamps = timestamps(times, start)
    if len(stamps) != T:
        raise InputError(f"times must have one entry per step ({T}), got {len(stamps)}")
    return [Track([GaussianState(_column(track.mean[b, k]), np.array(track.cov[b, k], dtype=float),
                                 timestamp=stamps[k]) for k in range(T)], id=f"run {b}") for b in range(B)]
