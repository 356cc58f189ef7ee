"""The multi-target trackers' configuration and records: :class:`TrackerConfig`, the live-track table a tracker
carries from ping to ping (:class:`TrackTable`, :class:`TrackerState`), one ping's output (:class:`PingTracks`) and
the log of a whole batch of runs (:class:`TrackLog`: identities, states and, where the tracker keeps them,
covariances).  The track statuses are :data:`TENTATIVE` and :data:`CONFIRMED`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..types import InputError

__all__ = ["TENTATIVE", "CONFIRMED", "PRIORS", "TrackerConfig", "TrackTable", "TrackerState", "PingTracks", "TrackLog"]

TENTATIVE = 0
CONFIRMED = 1


PRIORS = ("two-point", "speed-course")


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker parameters (defaults: an active-sonar tracker of ~2 units position accuracy).

    gate : Mahalanobis gate on ``d2`` (9.21: chi-square 2 dof, 99 %).
    v_max : initiation box half-width per ping, ``|dx|, |dy| <= v_max dt`` (units per ping).
    confirm_hits, confirm_window : M-of-N confirmation, M of the last N pings (3 of 5).
    delete_misses : consecutive misses that delete a track (3).
    initiation_hits : how many of the two initiation detections count as hits of the M-of-N window: 0
        (default; confirmation needs M hits after initiation) up to 2 (both count).
    prior : ``"two-point"`` (default, :func:`two_point_prior`: position and velocity covariance from the two
        detections' covariances, with the cross terms) or ``"speed-course"`` (:func:`speed_course_prior` with
        ``sigma_v``, ``sigma_c``).
    sigma_v, sigma_c : speed (units/ping) and course (rad) standard deviations of the speed-course prior.
    dense_limit : above this many (track, detection) pairs, candidate pairs come from a spatial grid first.
    gate_sigma : ``None`` (default): gate with the filter's ``R``.  A number ``s``: gate with the position
        accuracy ``s`` instead, ``R_g = J_p (s^2 I) J_p^T`` (``J_p = dh/dp`` at the prediction), i.e.
        ``S_g = J P- J^T + R_g``; the filter's own update still uses its ``R``.
    detection_sigma : ``None`` (default) or the stated position accuracy ``s`` of every detection: its
        covariance is ``s^2 I`` in position, ``J_h(p) s^2 I J_h(p)^T`` in the measurement space.  Used for
        the gate (as ``gate_sigma``), for the two-point prior and for the update (handed to the filter as
        ``Scan.cov``; the filter needs the ``detection_covariance`` capability).
    min_speed : ``None`` (default) or a speed (units per ping): a track whose estimated speed is below it is
        not confirmed, and a confirmed one is deleted (a stationary-clutter test).
    """

    gate: float = 9.21
    v_max: float = 8.0
    confirm_hits: int = 3
    confirm_window: int = 5
    delete_misses: int = 3
    initiation_hits: int = 0
    prior: str = "two-point"
    sigma_v: float = 1.0
    sigma_c: float = 1.0
    dense_limit: int = 250_000
    gate_sigma: float | None = None
    detection_sigma: float | None = None
    min_speed: float | None = None

    def __post_init__(self) -> None:
        if self.gate_sigma is not None and not self.gate_sigma > 0:
            raise InputError(f"TrackerConfig: gate_sigma must be None or > 0, got {self.gate_sigma}")
        if self.detection_sigma is not None and not self.detection_sigma > 0:
            raise InputError(f"TrackerConfig: detection_sigma must be None or > 0, got {self.detection_sigma}")
        if self.min_speed is not None and not self.min_speed >= 0:
            raise InputError(f"TrackerConfig: min_speed must be None or >= 0, got {self.min_speed}")
        if not (self.gate > 0 and self.v_max > 0 and self.sigma_v >= 0 and self.sigma_c >= 0):
            raise InputError(f"TrackerConfig: need gate, v_max > 0 and sigma_v, sigma_c >= 0; got {self}")
        if not (1 <= self.confirm_hits <= self.confirm_window <= 30 and self.delete_misses >= 1):
            raise InputError(f"TrackerConfig: need 1 <= confirm_hits <= confirm_window <= 30 and delete_misses >= 1; "
                             f"got {self.confirm_hits}, {self.confirm_window}, {self.delete_misses}")
        if not 0 <= self.initiation_hits <= 2:
            raise InputError(f"TrackerConfig: initiation_hits must be 0, 1 or 2, got {self.initiation_hits}")
        if self.prior not in PRIORS:
            raise InputError(f"TrackerConfig: prior must be one of {PRIORS}, got {self.prior!r}")


@dataclass(frozen=True)
class TrackTable:
    """The live tracks after a ping.

    Shapes
    ------
    ids, status, history, misses, age : (K,)   (``history``: bit 0 = hit at the latest ping)
    mean : (K, n), the filter's estimate
    state : the filter's state for a batch of K (None when K = 0)
    cov : (K, n, n), the filter's covariance of ``mean`` (None where the tracker does not keep it)
    """

    ids: np.ndarray
    status: np.ndarray
    history: np.ndarray
    misses: np.ndarray
    age: np.ndarray
    mean: np.ndarray
    state: Any = None
    cov: np.ndarray | None = None

    @property
    def size(self) -> int:
        return int(self.ids.shape[0])


@dataclass(frozen=True)
class TrackerState:
    """Everything the tracker carries from one ping to the next (for one run)."""

    table: TrackTable
    candidates: np.ndarray  # (P, 2) initiation detections of the last ping not used by a new track
    next_id: int = 0
    ping: int = -1
    candidate_cov: np.ndarray | None = None  # (P, 2, 2) their own position covariances, where the scans carry them


@dataclass(frozen=True)
class PingTracks:
    """The tracker's output for one ping: every live track after management.

    Shapes: ``ids, status, hit (K,)``, ``mean (K, n)``, ``cov (K, n, n)`` (None where not kept).
    """

    ping: int
    ids: np.ndarray
    status: np.ndarray
    hit: np.ndarray
    mean: np.ndarray
    cov: np.ndarray | None = None


@dataclass(frozen=True)
class TrackLog:
    """All tracks of all runs, one row per (run, ping, live track).

    Shapes
    ------
    run, ping, track_id, status, hit : (R,)
    mean : (R, n)
    cov : (R, n, n), the covariance of each ``mean``; ``None`` where the tracker does not keep covariances
    existence : (R,), each track's probability of existence (JIPDA) or its Gaussian component's weight (PHD);
        ``None`` where the tracker has no such number
    """

    run: np.ndarray
    ping: np.ndarray
    track_id: np.ndarray
    status: np.ndarray
    hit: np.ndarray
    mean: np.ndarray
    runs: int
    pings: int
    cov: np.ndarray | None = None
    existence: np.ndarray | None = None

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """The log as named arrays (for a task result / NPZ); ``cov`` only where the log keeps it."""
        out = {f"{prefix}run": self.run, f"{prefix}ping": self.ping, f"{prefix}track_id": self.track_id,
               f"{prefix}status": self.status, f"{prefix}hit": self.hit, f"{prefix}mean": self.mean,
               f"{prefix}shape": np.array([self.runs, self.pings])}
        if self.cov is not None:
            out[f"{prefix}cov"] = self.cov
        if self.existence is not None:
            out[f"{prefix}existence"] = self.existence
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], prefix: str = "") -> "TrackLog":
        runs, pings = (int(v) for v in arrays[f"{prefix}shape"])
        return cls(np.asarray(arrays[f"{prefix}run"]), np.asarray(arrays[f"{prefix}ping"]),
                   np.asarray(arrays[f"{prefix}track_id"]), np.asarray(arrays[f"{prefix}status"]),
                   np.asarray(arrays[f"{prefix}hit"], dtype=bool), np.asarray(arrays[f"{prefix}mean"]), runs, pings,
                   np.asarray(arrays[f"{prefix}cov"]) if f"{prefix}cov" in arrays else None,
                   np.asarray(arrays[f"{prefix}existence"], dtype=float) if f"{prefix}existence" in arrays else None)

    def select(self, mask: np.ndarray) -> "TrackLog":
        return TrackLog(self.run[mask], self.ping[mask], self.track_id[mask], self.status[mask], self.hit[mask],
                        self.mean[mask], self.runs, self.pings, None if self.cov is None else self.cov[mask],
                        None if self.existence is None else self.existence[mask])

    def confirmed_counts(self) -> np.ndarray:
        """Number of confirmed tracks per run and ping, ``(runs, pings)``."""
        out = np.zeros((self.runs, self.pings), dtype=int)
        c = self.status == CONFIRMED
        np.add.at(out, (self.run[c], self.ping[c]), 1)
        return out


