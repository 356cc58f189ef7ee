"""Multi-target track metrics from a :class:`~workbench.tracking.TrackLog` and the truth.

Track-truth association: a confirmed track is **true** when its position estimate lies within ``radius`` of
the truth (e.g. 3 sigma of the position accuracy) for at least ``min_fraction`` (80 %) of its confirmed life
(the pings at which it is confirmed); every other confirmed track is **false**.

Per run ``b`` and ping ``k``:

- ``confirmed[b, k]``: confirmed tracks; ``false[b, k]``: confirmed tracks that are not true.
- ``held[b, k]``: some true track is confirmed at ``k``; ``sq_error[b, k]``: squared position error of
  the true confirmed track nearest the truth (NaN where not held).

False-track removal rate, for counts before and after clutter removal, as a **ratio of sums** over the runs
``b`` and the judged pings ``k``::

    rate = 1 - sum_{b,k} F_after(b, k) / sum_{b,k} F_before(b, k)
         = sum_{b,k} (F_before - F_after) / sum_{b,k} F_before

(:func:`removal_rate_pooled`; NaN when no false track is counted before removal).  Every false track counts:
one left after removal on a ping that had none before lowers the rate.  Its interval is a bootstrap over
runs, never pings: :func:`false_track_sums` gives each run's two sums, a paired sample whose resamples keep
a run's before and after together, and :func:`removal_ratio` is the statistic on it.
:func:`removal_rate_pooled_per_ping` is the same ratio at each ping, summed over the runs.  The total-count
variant uses the confirmed counts instead of the false counts.

(An earlier estimator averaged ``r_k = 1 - F_after(k) / F_before(k)`` per run over the pings with
``F_before(k) > 0`` only: it dropped every false track left after removal on a ping without one before, and
weighted a ping with one false track as much as a ping with ten.  It is gone.)

Continuity: the fraction of pings, from the first held ping to the last ping of the run, at which the
target is held (0 for a run in which it never is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracking.multi import CONFIRMED, TrackLog
from ..types import InputError

__all__ = [
    "TrackCounts",
    "track_truth_match",
    "track_counts",
    "false_track_sums",
    "removal_ratio",
    "removal_rate_pooled",
    "removal_rate_pooled_per_ping",
    "continuity",
    "pooled_rmse",
    "mean_std",
]


@dataclass(frozen=True)
class TrackCounts:
    """Per-run, per-ping track counts against the truth.

    Shapes: ``confirmed, false, held, sq_error`` all ``(B, T)``.
    """

    confirmed: np.ndarray
    false: np.ndarray
    held: np.ndarray
    sq_error: np.ndarray

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        return {f"{prefix}confirmed": self.confirmed, f"{prefix}false": self.false, f"{prefix}held": self.held,
                f"{prefix}sq_error": self.sq_error}

    @classmethod
    def from_arrays(cls, arrays, prefix: str = "") -> "TrackCounts":
        return cls(np.asarray(arrays[f"{prefix}confirmed"]), np.asarray(arrays[f"{prefix}false"]),
                   np.asarray(arrays[f"{prefix}held"], dtype=bool), np.asarray(arrays[f"{prefix}sq_error"]))


def _truth_at(log: TrackLog, truth_pos: np.ndarray) -> np.ndarray:
    truth_pos = np.asarray(truth_pos, dtype=float)
    if truth_pos.shape[:2] != (log.runs, log.pings) or truth_pos.shape[2] < 2:
        raise InputError(f"truth positions must have shape ({log.runs}, {log.pings}, 2), got {truth_pos.shape}")
    return truth_pos[log.run, log.ping, :2]


def track_truth_match(log: TrackLog, truth_pos: np.ndarray, radius: float = 6.0, min_fraction: float = 0.8):
    """Classify every track that was ever confirmed.

    Returns ``run (U,)``, ``track_id (U,)``, ``fraction (U,)`` (share of its confirmed life within
    ``radius`` of the truth) and ``is_true (U,)`` (``fraction >= min_fraction``).
    """
    conf = log.status == CONFIRMED
    d = np.linalg.norm(log.mean[conf, :2] - _truth_at(log.select(conf), truth_pos), axis=1)
    key = log.run[conf] * (int(log.track_id.max(initial=0)) + 1) + log.track_id[conf]
    uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
    life = np.bincount(inv, minlength=uniq.size)
    near = np.bincount(inv, weights=(d <= radius).astype(float), minlength=uniq.size)
    frac = near / np.maximum(life, 1)
    runs, ids = log.run[conf][first], log.track_id[conf][first]
    return runs, ids, frac, frac >= min_fraction


def track_counts(log: TrackLog, truth_pos: np.ndarray, radius: float = 6.0, min_fraction: float = 0.8) -> TrackCounts:
    """Confirmed, false and held counts per run and ping; see the module docstring.

    ``truth_pos (B, T, 2)``: the target's true position at every ping.
    """
    B, T = log.runs, log.pings
    conf = log.status == CONFIRMED
    clog = log.select(conf)
    runs, ids, _, is_true = track_truth_match(log, truth_pos, radius, min_fraction)
    width = int(log.track_id.max(initial=0)) + 1
    true_keys = np.sort(runs[is_true] * width + ids[is_true])
    row_true = np.isin(clog.run * width + clog.track_id, true_keys)
    confirmed = np.zeros((B, T), dtype=int)
    np.add.at(confirmed, (clog.run, clog.ping), 1)
    false = np.zeros((B, T), dtype=int)
    np.add.at(false, (clog.run[~row_true], clog.ping[~row_true]), 1)
    best = np.full((B, T), np.inf)
    d2 = np.sum((clog.mean[:, :2] - _truth_at(clog, truth_pos)) ** 2, axis=1)
    np.minimum.at(best, (clog.run[row_true], clog.ping[row_true]), d2[row_true])
    held = np.isfinite(best)
    return TrackCounts(confirmed, false, held, np.where(held, best, np.nan))


def _pair(before: np.ndarray, after: np.ndarray, pings) -> tuple[np.ndarray, np.ndarray]:
    """``before, after`` as float ``(B, T)`` arrays with the pings outside ``pings (T,)`` set to 0."""
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    if before.shape != after.shape or before.ndim != 2:
        raise InputError(f"removal rate: before {before.shape} and after {after.shape} must be the same (runs, pings)")
    if pings is not None:
        use = np.asarray(pings, dtype=bool)
        if use.shape != (before.shape[1],):
            raise InputError(f"removal rate: pings must be a mask of {before.shape[1]} pings, got shape {use.shape}")
        before, after = before * use, after * use
    return before, after


def false_track_sums(before: np.ndarray, after: np.ndarray, pings=None) -> tuple[np.ndarray, np.ndarray]:
    """Per run, the counts before and after removal summed over the pings in ``pings (T,)`` (all if None).

    ``before, after (B, T)`` -> ``(sum_before (B,), sum_after (B,))``: the paired per-run sample of
    :func:`removal_ratio` (resample runs, keep each run's two sums together).
    """
    before, after = _pair(before, after, pings)
    return before.sum(axis=1), after.sum(axis=1)


def removal_ratio(sum_before: np.ndarray, sum_after: np.ndarray) -> float:
    """``1 - sum(sum_after) / sum(sum_before)`` over the runs given; NaN when ``sum(sum_before) == 0``."""
    den = float(np.sum(sum_before))
    return 1.0 - float(np.sum(sum_after)) / den if den > 0 else float("nan")


def removal_rate_pooled(before: np.ndarray, after: np.ndarray, pings=None) -> float:
    """The removal rate as a ratio of sums over all runs and the pings in ``pings`` (see the module text)."""
    return removal_ratio(*false_track_sums(before, after, pings))


def removal_rate_pooled_per_ping(before: np.ndarray, after: np.ndarray, pings=None) -> np.ndarray:
    """At each ping, ``1 - sum_b F_after(b, k) / sum_b F_before(b, k)`` over the runs, ``(T,)``; NaN where no run
    has a count before removal there (or the ping is outside ``pings``)."""
    before, after = _pair(before, after, pings)
    den = before.sum(axis=0)
    return np.where(den > 0, 1.0 - after.sum(axis=0) / np.where(den > 0, den, 1.0), np.nan)


def continuity(held: np.ndarray) -> np.ndarray:
    """Per run, the share of pings from the first held ping on at which the target is held, ``(B,)``."""
    held = np.asarray(held, dtype=bool)
    T = held.shape[1]
    any_ = held.any(axis=1)
    first = np.argmax(held, axis=1)
    span = T - first
    after = np.arange(T)[None, :] >= first[:, None]
    frac = np.sum(held & after, axis=1) / np.maximum(span, 1)
    return np.where(any_, frac, 0.0)


def pooled_rmse(sq_error: np.ndarray) -> float:
    """``sqrt`` of the mean of all finite squared errors (NaN if there are none)."""
    sq = np.asarray(sq_error, dtype=float)
    finite = np.isfinite(sq)
    return float(np.sqrt(sq[finite].mean())) if finite.any() else float("nan")


def mean_std(values: np.ndarray) -> tuple[float, float, int]:
    """Mean, standard deviation (ddof = 1 when possible) and count of the finite values."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan"), 0
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else 0.0, int(v.size)
