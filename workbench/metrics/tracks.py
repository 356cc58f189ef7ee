"""Multi-target track metrics from a :class:`~workbench.tracking.TrackLog` and the truth.

Track-truth association: a confirmed track is **true** when its position estimate lies within ``radius`` of
the truth (e.g. 3 sigma of the position accuracy) for at least ``min_fraction`` (80 %) of its confirmed life
(the pings at which it is confirmed); every other confirmed track is **false**.

Per run ``b`` and ping ``k``:

- ``confirmed[b, k]``: confirmed tracks; ``false[b, k]``: confirmed tracks that are not true.
- ``held[b, k]``: some true track is confirmed at ``k``; ``sq_error[b, k]``: squared position error of
  the true confirmed track nearest the truth (NaN where not held).

False-track removal rate, for counts before and after clutter removal::

    r_k = 1 - F_after(k) / F_before(k)        over the pings with F_before(k) > 0

averaged per run (:func:`removal_rate`), then mean +- std over Monte Carlo runs (:func:`mean_std`).
The total-count variant uses the confirmed counts instead of the false counts.

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
    "removal_rate",
    "removal_rate_per_ping",
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


def _rates(before: np.ndarray, after: np.ndarray, pings) -> np.ndarray:
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    if before.shape != after.shape:
        raise InputError(f"removal rate: before {before.shape} and after {after.shape} must match")
    use = before > 0
    if pings is not None:
        use &= np.asarray(pings, dtype=bool)[None, :]
    # r_k = 1 - F_after(k) / F_before(k)  where F_before(k) > 0
    return np.where(use, 1.0 - after / np.where(use, before, 1.0), np.nan)


def removal_rate(before: np.ndarray, after: np.ndarray, pings=None) -> np.ndarray:
    """Per-run mean of ``r_k`` over the pings with ``before > 0`` (and in ``pings (T,)`` if given).

    ``before, after (B, T)`` -> ``(B,)``; NaN for a run without such a ping.
    """
    r = _rates(before, after, pings)
    n = np.sum(np.isfinite(r), axis=1)
    return np.where(n > 0, np.nansum(r, axis=1) / np.maximum(n, 1), np.nan)


def removal_rate_per_ping(before: np.ndarray, after: np.ndarray, pings=None) -> np.ndarray:
    """Mean over runs of ``r_k`` at each ping (runs with ``before > 0`` there), ``(T,)``; NaN if none."""
    r = _rates(before, after, pings)
    n = np.sum(np.isfinite(r), axis=0)
    return np.where(n > 0, np.nansum(r, axis=0) / np.maximum(n, 1), np.nan)


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
