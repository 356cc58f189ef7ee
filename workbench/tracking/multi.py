"""Multi-target tracking for any filter plugin: classification, two-point initiation, nearest-neighbour
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
from typing import Any, Mapping

import numpy as np

from ..linalg import wrap_angle
from ..models import MeasurementModel, MotionModel
from ..rng import generator
from ..specs import FilterSpec
from ..types import Gaussian, InputError, Scan, Scans
from .loop import Context

__all__ = [
    "TENTATIVE",
    "CONFIRMED",
    "TrackerConfig",
    "TrackTable",
    "TrackerState",
    "PingTracks",
    "TrackLog",
    "measurement_view",
    "position_covariance",
    "two_point_prior",
    "speed_course_prior",
    "detection_covariance",
    "measurement_covariance",
    "PRIORS",
    "box_pairs",
    "gate_covariance",
    "gated_pairs",
    "greedy_assign",
    "rectangular_pairs",
    "mofn_step",
    "initial_state",
    "tracker_step",
    "MofN",
    "run_tracker",
]

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
    """

    ids: np.ndarray
    status: np.ndarray
    history: np.ndarray
    misses: np.ndarray
    age: np.ndarray
    mean: np.ndarray
    state: Any = None

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

    Shapes: ``ids, status, hit (K,)``, ``mean (K, n)``.
    """

    ping: int
    ids: np.ndarray
    status: np.ndarray
    hit: np.ndarray
    mean: np.ndarray


@dataclass(frozen=True)
class TrackLog:
    """All tracks of all runs, one row per (run, ping, live track).

    Shapes
    ------
    run, ping, track_id, status, hit : (R,)
    mean : (R, n)
    """

    run: np.ndarray
    ping: np.ndarray
    track_id: np.ndarray
    status: np.ndarray
    hit: np.ndarray
    mean: np.ndarray
    runs: int
    pings: int

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """The log as named arrays (for a task result / NPZ)."""
        return {f"{prefix}run": self.run, f"{prefix}ping": self.ping, f"{prefix}track_id": self.track_id,
                f"{prefix}status": self.status, f"{prefix}hit": self.hit, f"{prefix}mean": self.mean,
                f"{prefix}shape": np.array([self.runs, self.pings])}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], prefix: str = "") -> "TrackLog":
        runs, pings = (int(v) for v in arrays[f"{prefix}shape"])
        return cls(np.asarray(arrays[f"{prefix}run"]), np.asarray(arrays[f"{prefix}ping"]),
                   np.asarray(arrays[f"{prefix}track_id"]), np.asarray(arrays[f"{prefix}status"]),
                   np.asarray(arrays[f"{prefix}hit"], dtype=bool), np.asarray(arrays[f"{prefix}mean"]), runs, pings)

    def select(self, mask: np.ndarray) -> "TrackLog":
        return TrackLog(self.run[mask], self.ping[mask], self.track_id[mask], self.status[mask], self.hit[mask],
                        self.mean[mask], self.runs, self.pings)

    def confirmed_counts(self) -> np.ndarray:
        """Number of confirmed tracks per run and ping, ``(runs, pings)``."""
        out = np.zeros((self.runs, self.pings), dtype=int)
        c = self.status == CONFIRMED
        np.add.at(out, (self.run[c], self.ping[c]), 1)
        return out


# -- pieces ---------------------------------------------------------------------------------------


def measurement_view(model: MeasurementModel, positions: np.ndarray, n: int) -> np.ndarray:
    """Cartesian detections ``(M, 2)`` in the model's measurement space, ``h([x, y, 0, ...])`` -> ``(M, m)``."""
    state = np.zeros((positions.shape[0], n))
    state[:, :2] = positions
    return np.asarray(model.h(state), dtype=float).reshape(positions.shape[0], model.dim)


def _jacobian(model: MeasurementModel, x: np.ndarray) -> np.ndarray:
    if model.jacobian is not None:
        return np.asarray(model.jacobian(x), dtype=float)
    if model.H is not None:
        return np.broadcast_to(model.H, (x.shape[0], *model.H.shape))
    raise InputError(f"the tracker gates with the Jacobian of the measurement model; {model.name!r} has none")


def position_covariance(model: MeasurementModel, positions: np.ndarray, n: int) -> np.ndarray:
    """Covariance of the Cartesian position a detection implies, ``A R A^T`` with ``A = (dh/dp)^-1``.

    For the linear position model this is ``R``; for range-bearing it is the linearised conversion
    covariance of the converted-measurement filter (``R11, R22, R12``).  ``(M, 2) -> (M, 2, 2)``.
    """
    if model.dim != 2:
        raise InputError(f"the tracker needs a 2-component position-like measurement model, got m={model.dim}")
    state = np.zeros((positions.shape[0], n))
    state[:, :2] = positions
    jp = _jacobian(model, state)[:, :, :2]  # dh/dp, (M, 2, 2)
    # A = (dh/dp)^-1;  A R A^T = solve(J, solve(J, R)^T)^T
    x = np.linalg.solve(jp, np.broadcast_to(model.R, jp.shape))
    out = np.linalg.solve(jp, np.swapaxes(x, -1, -2))
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def two_point_prior(p_prev: np.ndarray, p_cur: np.ndarray, dt: float, cov_prev: np.ndarray,
                    cov_cur: np.ndarray) -> Gaussian:
    """The standard two-point initialisation from detections of consecutive pings.

    ``x0 = [p_cur, v0]``, ``v0 = (p_cur - p_prev) / dt``, with the covariance of exactly that difference
    (``R0, R1``: the two detections' position covariances)::

        P0 = [[R1,       R1 / dt          ],
              [R1 / dt,  (R0 + R1) / dt^2 ]]

    Shapes: ``p_prev, p_cur (K, 2)``, ``cov_prev, cov_cur (K, 2, 2)`` -> Gaussian ``(K, 4)``.
    """
    vel = (p_cur - p_prev) / dt
    cov = np.empty((p_cur.shape[0], 4, 4))
    cov[:, :2, :2] = cov_cur
    cov[:, :2, 2:] = cov_cur / dt  # cov(p_cur, v0) = R1 / dt
    cov[:, 2:, :2] = cov_cur / dt
    cov[:, 2:, 2:] = (cov_prev + cov_cur) / (dt * dt)  # cov(v0) = (R0 + R1) / dt^2
    return Gaussian(np.concatenate([p_cur, vel], axis=1), 0.5 * (cov + np.swapaxes(cov, -1, -2)))


def speed_course_prior(p_prev: np.ndarray, p_cur: np.ndarray, dt: float, pos_cov: np.ndarray, sigma_v: float,
                       sigma_c: float) -> Gaussian:
    """Two-point initialisation with a speed-course velocity covariance (``prior="speed-course"``).

    ``x0 = [p_cur, (p_cur - p_prev) / dt]`` and, with speed ``v`` and course ``c`` of that velocity
    (``vx = v cos c``, ``vy = v sin c``)::

        P0 = blockdiag(R_c(p_cur), J diag(sigma_v^2, sigma_c^2) J^T),   J = [[cos c, -v sin c], [sin c, v cos c]]

    Shapes: ``p_prev, p_cur (K, 2)``, ``pos_cov (K, 2, 2)`` -> Gaussian ``(K, 4)``.
    """
    vel = (p_cur - p_prev) / dt
    v = np.hypot(vel[:, 0], vel[:, 1])
    c = np.arctan2(vel[:, 1], vel[:, 0])
    J = np.empty((p_cur.shape[0], 2, 2))
    J[:, 0, 0], J[:, 0, 1] = np.cos(c), -v * np.sin(c)
    J[:, 1, 0], J[:, 1, 1] = np.sin(c), v * np.cos(c)
    # P_v = J diag(sigma_v^2, sigma_c^2) J^T
    pv = J @ np.diag([sigma_v**2, sigma_c**2]) @ np.swapaxes(J, -1, -2)
    cov = np.zeros((p_cur.shape[0], 4, 4))
    cov[:, :2, :2] = pos_cov
    cov[:, 2:, 2:] = 0.5 * (pv + np.swapaxes(pv, -1, -2))
    return Gaussian(np.concatenate([p_cur, vel], axis=1), cov)


def detection_covariance(model: MeasurementModel, positions: np.ndarray, n: int, sigma: float) -> np.ndarray:
    """Each detection's covariance in the model's measurement space when its position accuracy is ``sigma`` per
    axis: ``J_h(p) (sigma^2 I) J_h(p)^T``, ``J_h = dh/dp`` at the detection.  ``(M, 2) -> (M, m, m)``."""
    return measurement_covariance(model, positions, n, np.broadcast_to(sigma * sigma * np.eye(2),
                                                                       (positions.shape[0], 2, 2)))


def measurement_covariance(model: MeasurementModel, positions: np.ndarray, n: int, pos_cov: np.ndarray) -> np.ndarray:
    """Each detection's covariance in the model's measurement space from its own Cartesian position covariance
    ``C_j``: ``J_h(p_j) C_j J_h(p_j)^T``, ``J_h = dh/dp`` at the detection.  ``(M, 2), (M, 2, 2) -> (M, m, m)``."""
    state = np.zeros((positions.shape[0], n))
    state[:, :2] = positions
    jp = _jacobian(model, state)[:, :, :2]
    out = jp @ pos_cov @ np.swapaxes(jp, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _whiten(chol: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """``L^-1 nu`` for lower-triangular ``chol (..., m, m)`` and ``nu (..., m)`` (broadcasting).

    Forward substitution written out for ``m = 2`` (the tracker's case: no LAPACK call per pair), a
    batched solve otherwise.
    """
    if nu.shape[-1] != 2:
        return np.linalg.solve(chol, nu[..., None])[..., 0]
    w1 = nu[..., 0] / chol[..., 0, 0]
    w2 = (nu[..., 1] - chol[..., 1, 0] * w1) / chol[..., 1, 1]
    return np.stack([w1, w2], axis=-1)


def _grid_query(lo: np.ndarray, hi: np.ndarray, b: np.ndarray, cell) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs ``(i, j)``: every point ``b_j`` inside box ``i`` (``lo_i <= b_j <= hi_i`` on both axes) is
    among them, by spatial grid hashing.

    ``b`` is binned into cells of side ``cell`` (one value or one per axis); each box visits the cells it
    overlaps, and the points of those cells are found with ``searchsorted`` on the sorted cell keys.  Fully
    vectorised, no ``(Na, Nb)`` matrix and no Python loop over points.  Shapes: ``lo, hi (Na, 2)``, ``b (Nb, 2)``
    -> ``i, j (P,)`` grouped by ``i``.
    """
    e = np.zeros(0, dtype=np.intp)
    if lo.shape[0] == 0 or b.shape[0] == 0:
        return e, e
    cell = np.broadcast_to(np.asarray(cell, dtype=float), (2,))
    b_lo = b.min(axis=0)
    extent = b.max(axis=0) - b_lo
    cell = np.maximum(np.maximum(cell, extent / 4096.0), 1e-12)
    nb = np.floor((b - b_lo) / cell).astype(np.int64)
    nx, ny = int(nb[:, 0].max()) + 1, int(nb[:, 1].max()) + 1
    keys = nb[:, 0] * ny + nb[:, 1]
    order = np.argsort(keys, kind="stable")
    skeys = keys[order]
    c0 = np.maximum(np.floor((lo - b_lo) / cell).astype(np.int64), 0)
    c1 = np.minimum(np.floor((hi - b_lo) / cell).astype(np.int64), [nx - 1, ny - 1])
    ncx, ncy = np.maximum(c1[:, 0] - c0[:, 0] + 1, 0), np.maximum(c1[:, 1] - c0[:, 1] + 1, 0)
    # one run of consecutive keys per visited x column: cells (cx, c0y .. c1y)
    rep = np.repeat(np.arange(lo.shape[0]), ncx)
    cx = c0[rep, 0] + (np.arange(rep.size) - np.repeat(np.cumsum(ncx) - ncx, ncx))
    first = np.searchsorted(skeys, cx * ny + c0[rep, 1], side="left")
    count = np.searchsorted(skeys, cx * ny + c0[rep, 1] + ncy[rep] - 1, side="right") - first
    n = int(count.sum())
    if n == 0:
        return e, e
    i = np.repeat(rep, count)
    j = order[np.repeat(first - (np.cumsum(count) - count), count) + np.arange(n)]
    return i, j


def box_pairs(a: np.ndarray, b: np.ndarray, half, cell: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All pairs ``(i, j)`` with ``|a_i - b_j| <= half_i`` on both axes, by spatial grid hashing
    (:func:`_grid_query`; default cell: half the median box width).

    Shapes: ``a (Na, 2)``, ``b (Nb, 2)``, ``half`` scalar, ``(Na,)`` or ``(Na, 2)`` -> ``i, j (P,)``, sorted
    by ``i``.
    """
    a = np.asarray(a, dtype=float).reshape(-1, 2)
    b = np.asarray(b, dtype=float).reshape(-1, 2)
    e = np.zeros(0, dtype=np.intp)
    if a.shape[0] == 0 or b.shape[0] == 0:
        return e, e
    half = np.asarray(half, dtype=float)
    half = np.broadcast_to(half[..., None] if half.ndim == 1 else half, a.shape)
    if cell is None:
        cell = float(np.median(half))
    # the grid query with boxes widened by a relative 1e-9 (the exact test below decides)
    pad = 1e-9 * (np.abs(a) + half) + 1e-300
    i, j = _grid_query(a - half - pad, a + half + pad, b, max(float(cell), 1e-9))  # grouped by i, ascending
    inside = (np.abs(a[i, 0] - b[j, 0]) <= half[i, 0]) & (np.abs(a[i, 1] - b[j, 1]) <= half[i, 1])
    return i[inside], j[inside]


def gate_covariance(est: Gaussian, model: MeasurementModel, config: TrackerConfig,
                    per_detection: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Gate innovation covariance ``S = J P- J^T + R_g`` and the Jacobian ``J`` at the prediction.

    ``R_g = R`` (the filter's), or ``J_p (s^2 I) J_p^T`` with ``J_p = dh/dp`` and ``s = config.gate_sigma``
    (else ``config.detection_sigma``) when one is set.  ``per_detection`` (and no ``gate_sigma``): ``R_g = 0``,
    each detection's own covariance is added per pair by :func:`gated_pairs`.  Shapes: ``(K, m, m)``,
    ``(K, m, n)``.
    """
    J = _jacobian(model, est.mean)
    sigma = config.gate_sigma if config.gate_sigma is not None else config.detection_sigma
    if per_detection and config.gate_sigma is None:
        R = 0.0
    elif sigma is None:
        R = model.R
    else:
        jp = J[:, :, :2]
        R = sigma**2 * (jp @ np.swapaxes(jp, -1, -2))  # R_g = J_p (s^2 I) J_p^T
    S = J @ est.cov @ np.swapaxes(J, -1, -2) + R  # S = J P- J^T + R_g
    return 0.5 * (S + np.swapaxes(S, -1, -2)), J


def _measurement_boxes(zhat: np.ndarray, half: np.ndarray, angular: np.ndarray):
    """The query boxes of gates centred at ``zhat (K, 2)`` with half-widths ``half (K, 2)`` in the measurement
    space, angular components wrapped to (-pi, pi]: a box crossing the seam gets a second, shifted copy.
    Returns ``track (Q,)``, ``lo, hi (Q, 2)``."""
    lo, hi = zhat - half, zhat + half
    track = np.arange(zhat.shape[0])
    extra_t, extra_lo, extra_hi = [], [], []
    for axis in np.flatnonzero(angular):
        whole = half[:, axis] >= np.pi
        lo[whole, axis], hi[whole, axis] = -np.pi - 1.0, np.pi + 1.0
        for shift, over in ((2.0 * np.pi, lo[:, axis] < -np.pi), (-2.0 * np.pi, hi[:, axis] > np.pi)):
            over &= ~whole
            if over.any():
                l2, h2 = lo[over].copy(), hi[over].copy()
                l2[:, axis] += shift
                h2[:, axis] += shift
                extra_t.append(track[over])
                extra_lo.append(l2)
                extra_hi.append(h2)
    if extra_t:
        track = np.concatenate([track] + extra_t)
        lo = np.concatenate([lo] + extra_lo)
        hi = np.concatenate([hi] + extra_hi)
    return track, lo, hi


def gated_pairs(est: Gaussian, positions: np.ndarray, zm: np.ndarray, model: MeasurementModel,
                config: TrackerConfig, det_cov: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(track, detection, d2)`` for every pair inside the gate; see the module docstring.

    ``est`` are the predictions ``(K, n)``, ``positions (M, 2)`` the Cartesian detections and ``zm (M, m)`` the
    same in the model's measurement space.  ``det_cov (M, m, m)``: each detection's own covariance in the
    measurement space; unless ``config.gate_sigma`` is set, pair ``(k, j)`` is gated with
    ``S_kj = J_k P_k J_k^T + det_cov_j``.  At most ``dense_limit`` pairs: every pair's ``d2``.  Above: a
    pair's residual satisfies ``|nu_i| <= sqrt(gate S_ii)`` on each axis inside the gate ellipse, so the
    candidates are the detections inside that box around ``h(x-)`` in the measurement space (angular
    components wrapped; :func:`_grid_query`; with ``det_cov``, ``S_ii`` bounded by the largest detection's),
    and ``d2`` is computed for them only: the same pairs and values as the dense computation.
    """
    K, M = est.batch, zm.shape[0]
    if K == 0 or M == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e, np.zeros(0)
    zhat = model.h(est.mean)
    pair_cov = det_cov is not None and config.gate_sigma is None
    S, J = gate_covariance(est, model, config, per_detection=pair_cov)
    if K * M <= config.dense_limit:
        nu = model.residual(zm[None, :, :], zhat[:, None, :])  # (K, M, m)
        if pair_cov:
            Skj = S[:, None] + det_cov[None]  # S_kj = J P- J^T + R_j
            chol = np.linalg.cholesky(0.5 * (Skj + np.swapaxes(Skj, -1, -2)))
            w = _whiten(chol, nu)
        else:
            w = _whiten(np.linalg.cholesky(S)[:, None], nu)  # L^-1 nu
        d2 = np.einsum("kmi,kmi->km", w, w)
        rows, cols = np.nonzero(d2 <= config.gate)
        return rows, cols, d2[rows, cols]
    if model.dim != 2:
        raise InputError(f"the tracker needs a 2-component measurement model, got m={model.dim}")
    # |nu_i| <= sqrt(gate S_ii) inside the gate; widened by a relative 1e-9 (the d2 test decides)
    diag = np.diagonal(S, axis1=1, axis2=2)
    if pair_cov:
        diag = diag + np.max(np.diagonal(det_cov, axis1=1, axis2=2), axis=0)
    half = np.sqrt(config.gate * np.maximum(diag, 0.0)) * (1.0 + 1e-9) + 1e-12
    track, lo, hi = _measurement_boxes(zhat.astype(float), half, model.angle_mask)
    cell = 0.25 * np.median(2.0 * half, axis=0)
    rows, cols = _grid_query(lo, hi, np.asarray(zm, dtype=float), cell)
    if rows.size == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e, np.zeros(0)
    rows = track[rows]
    # nu = wrap(z - h(x-));  w = L^-1 nu (forward substitution, as _whiten), d2 = |w|^2; the per-track and
    # per-detection factors are gathered from contiguous copies
    z0, z1 = np.ascontiguousarray(zm[:, 0]), np.ascontiguousarray(zm[:, 1])
    h0, h1 = np.ascontiguousarray(zhat[:, 0]), np.ascontiguousarray(zhat[:, 1])
    nu0 = z0[cols] - h0[rows]
    nu1 = z1[cols] - h1[rows]
    if model.angle_mask[0]:
        nu0 = wrap_angle(nu0)
    if model.angle_mask[1]:
        nu1 = wrap_angle(nu1)
    if pair_cov:
        # the 2x2 Cholesky factor of S_kj = S_k + R_j per pair: l00 = sqrt(s00), l10 = s10 / l00,
        # l11 = sqrt(s11 - l10^2)
        s00 = S[rows, 0, 0] + det_cov[cols, 0, 0]
        s10 = 0.5 * (S[rows, 1, 0] + S[rows, 0, 1] + det_cov[cols, 1, 0] + det_cov[cols, 0, 1])
        s11 = S[rows, 1, 1] + det_cov[cols, 1, 1]
        l00 = np.sqrt(s00)
        l10 = s10 / l00
        l11 = np.sqrt(s11 - l10 * l10)
        w1 = nu0 / l00
        w2 = (nu1 - l10 * w1) / l11
    else:
        chol = np.linalg.cholesky(S)
        l00, l10, l11 = (np.ascontiguousarray(chol[:, i, j]) for i, j in ((0, 0), (1, 0), (1, 1)))
        w1 = nu0 / l00[rows]
        w2 = (nu1 - l10[rows] * w1) / l11[rows]
    d2 = w1 * w1 + w2 * w2
    inside = d2 <= config.gate
    return rows[inside], cols[inside], d2[inside]


def greedy_assign(rows: np.ndarray, cols: np.ndarray, cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Greedy one-to-one assignment by smallest cost (ties broken by row, then column).

    Equivalent to repeatedly taking the globally cheapest remaining pair in the order (cost, row, column);
    computed in rounds in which every pair that is the first of both its row and its column in that order is
    taken at once.  A round costs ``O(pairs left)`` and sorts nothing: the cheapest cost of every row and
    column comes from ``np.minimum.at``, and among a row's (column's) pairs of equal cheapest cost the smallest
    column (row) is found the same way.  Returns the taken ``rows, cols``.
    """
    rows, cols, cost = np.asarray(rows), np.asarray(cols), np.asarray(cost, dtype=float)
    if rows.size == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e
    rows, cols = rows.astype(np.intp), cols.astype(np.intp)
    n_r, n_c = int(rows.max()) + 1, int(cols.max()) + 1
    taken_r, taken_c = np.zeros(n_r, dtype=bool), np.zeros(n_c, dtype=bool)
    best_r, best_c = np.empty(n_r), np.empty(n_c)
    first_r, first_c = np.empty(n_r, dtype=np.intp), np.empty(n_c, dtype=np.intp)
    live = np.arange(rows.size)
    out_r, out_c = [], []
    while live.size:
        r, c, x = rows[live], cols[live], cost[live]
        best_r.fill(np.inf)
        best_c.fill(np.inf)
        np.minimum.at(best_r, r, x)  # the cheapest remaining cost of each row and column
        np.minimum.at(best_c, c, x)
        at_r, at_c = x == best_r[r], x == best_c[c]
        # ties: the smallest column among a row's cheapest pairs, the smallest row among a column's
        first_r.fill(n_c)
        first_c.fill(n_r)
        np.minimum.at(first_r, r[at_r], c[at_r])
        np.minimum.at(first_c, c[at_c], r[at_c])
        mutual = at_r & at_c & (c == first_r[r]) & (r == first_c[c])
        tr, tc = r[mutual], c[mutual]
        out_r.append(tr)
        out_c.append(tc)
        taken_r[tr] = True
        taken_c[tc] = True
        live = live[~(taken_r[r] | taken_c[c])]
    return np.concatenate(out_r), np.concatenate(out_c)


def rectangular_pairs(a: np.ndarray, b: np.ndarray, box: float, dense_limit: int = 250_000):
    """Pairs ``(i, j)`` with ``|a_i - b_j|_inf <= box`` and their Chebyshev distances (dense below
    ``dense_limit`` pairs, else the spatial grid of :func:`box_pairs`)."""
    if a.shape[0] == 0 or b.shape[0] == 0:
        e = np.zeros(0, dtype=np.intp)
        return e, e, np.zeros(0)
    if a.shape[0] * b.shape[0] <= dense_limit:
        d = np.max(np.abs(a[:, None, :] - b[None, :, :]), axis=-1)
        i, j = np.nonzero(d <= box)
        return i, j, d[i, j]
    i, j = box_pairs(a, b, box, cell=max(0.5 * box, 1e-9))
    return i, j, np.maximum(np.abs(a[i, 0] - b[j, 0]), np.abs(a[i, 1] - b[j, 1]))


_POPCOUNT = np.array([bin(v).count("1") for v in range(1 << 12)], dtype=np.int64)


def _popcount(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.int64)
    out = np.zeros_like(x)
    while np.any(x):
        out += _POPCOUNT[x & 0xFFF]
        x = x >> 12
    return out


def mofn_step(history: np.ndarray, misses: np.ndarray, age: np.ndarray, status: np.ndarray, hit: np.ndarray,
              config: TrackerConfig, slow: np.ndarray | None = None):
    """Advance the M-of-N state machine of every track by one ping.

    Returns ``history, misses, age, status, delete`` (each ``(K,)``)::

        history <- (history << 1 | hit) mod 2^N       hits = popcount(history)
        confirm   tentative with hits >= M (and not slow)
        delete    misses >= delete_misses, or tentative with age >= N (never confirmed in its first N
                  pings) or hits + (N - age) < M (can no longer be), or confirmed and slow

    ``age`` counts the pings since initiation plus ``initiation_hits`` (the initiation detections that count);
    ``slow (K,)``: tracks below ``min_speed`` (``None``: none).
    """
    N, M = config.confirm_window, config.confirm_hits
    hit = np.asarray(hit, dtype=bool)
    history = ((np.asarray(history, dtype=np.int64) << 1) | hit) & ((1 << N) - 1)
    age = np.asarray(age) + 1
    misses = np.where(hit, 0, np.asarray(misses) + 1)
    hits = _popcount(history)
    was_confirmed = status == CONFIRMED
    can = (hits >= M) if slow is None else (hits >= M) & ~slow
    status = np.where((status == TENTATIVE) & can, CONFIRMED, status).astype(np.int8)
    tentative = status == TENTATIVE
    delete = (misses >= config.delete_misses) | (tentative & ((age >= N) | (hits + (N - age) < M)))
    if slow is not None:
        delete |= was_confirmed & slow
    return history, misses, age, status, delete


# -- the tracker ----------------------------------------------------------------------------------


def initial_state(n: int = 4) -> TrackerState:
    """No tracks, no initiation candidates."""
    e = np.zeros(0, dtype=np.int64)
    return TrackerState(TrackTable(e, e.astype(np.int8), e, e, e, np.zeros((0, n))), np.zeros((0, 2)))


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
                 predicted: Any = None, position_cov: np.ndarray | None = None) -> tuple[TrackerState, PingTracks]:
    """Process one ping's Cartesian detections ``positions (M, 2)``; see the module docstring.

    ``predicted`` is the live tracks' filter state already predicted to this ping (by :func:`_predict_tracks`);
    ``None`` predicts here.  ``position_cov (M, 2, 2)``: each detection's own Cartesian position covariance
    ``C_j`` (a recording's stated accuracy); it takes the place of ``detection_sigma`` everywhere: the gate
    (``S_kj = J P- J^T + J_h C_j J_h^T``, unless ``gate_sigma``), the update (``Scan.cov``) and the two-point
    prior.
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
        a_rows, a_cols = greedy_assign(rows, cols, d2)
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
        mean = filt.estimate(state).mean
        slow = None if config.min_speed is None else np.hypot(mean[:, 2], mean[:, 3]) < config.min_speed
        history, misses, age, status, delete = mofn_step(table.history, table.misses, table.age, table.status, hit,
                                                         config, slow)
        keep = np.flatnonzero(~delete)
        table = TrackTable(table.ids[keep], status[keep], history[keep], misses[keep], age[keep], mean[keep],
                           filt.take_items(state, keep) if keep.size else None)
        hits_out = hit[keep]
    else:
        hits_out = np.zeros(0, dtype=bool)
    # initiation from the unclaimed detections of this ping and the last
    init_pos = positions[~near]
    init_cov = None if position_cov is None else position_cov[~near]
    pi, ci, dist = rectangular_pairs(st.candidates, init_pos, config.v_max * motion.dt, config.dense_limit)
    a_p, a_c = greedy_assign(pi, ci, dist)
    next_id = st.next_id
    if a_c.size:
        order = np.argsort(a_c)  # new tracks in detection order
        a_p, a_c = a_p[order], a_c[order]
        p_prev, p_cur = st.candidates[a_p], init_pos[a_c]
        if init_cov is not None:
            cov_cur = init_cov[a_c]
            cov_prev = (st.candidate_cov[a_p] if st.candidate_cov is not None
                        else position_covariance(model, p_prev, n))
        elif config.detection_sigma is not None:
            cov_cur = np.broadcast_to(config.detection_sigma**2 * np.eye(2), (a_c.size, 2, 2))
            cov_prev = cov_cur
        else:
            cov_cur = position_covariance(model, p_cur, n)
            cov_prev = position_covariance(model, p_prev, n) if config.prior == "two-point" else None
        if config.prior == "two-point":
            prior = two_point_prior(p_prev, p_cur, motion.dt, cov_prev, cov_cur)
        else:
            prior = speed_course_prior(p_prev, p_cur, motion.dt, cov_cur, config.sigma_v, config.sigma_c)
        new_state = filt.init(prior, rng)
        filt.require_batch_contract(new_state, "M-of-N tracker")
        new_mean = filt.estimate(new_state).mean
        Kn = a_c.size
        ids = np.arange(next_id, next_id + Kn, dtype=np.int64)
        next_id += Kn
        h0 = config.initiation_hits
        status0 = CONFIRMED if h0 >= config.confirm_hits else TENTATIVE
        if status0 == CONFIRMED and config.min_speed is not None:
            status0 = np.where(np.hypot(new_mean[:, 2], new_mean[:, 3]) < config.min_speed, TENTATIVE, CONFIRMED)
        joined = new_state if table.size == 0 else filt.join_items([table.state, new_state])
        table = TrackTable(np.concatenate([table.ids, ids]),
                           np.concatenate([table.status, np.broadcast_to(status0, (Kn,)).astype(np.int8)]),
                           np.concatenate([table.history, np.full(Kn, (1 << h0) - 1, dtype=np.int64)]),
                           np.concatenate([table.misses, np.zeros(Kn, dtype=np.int64)]),
                           np.concatenate([table.age, np.full(Kn, h0, dtype=np.int64)]),
                           np.concatenate([table.mean, new_mean]), joined)
        hits_out = np.concatenate([hits_out, np.ones(Kn, dtype=bool)])
    used = np.zeros(init_pos.shape[0], dtype=bool)
    used[a_c] = True
    out = PingTracks(k, table.ids.copy(), table.status.copy(), hits_out, table.mean.copy())
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
    (:func:`measurement_view`).  :meth:`finish` returns a :class:`TrackLog` (rows ordered by run, then ping).
    """

    def __init__(self, config: TrackerConfig = TrackerConfig(), seed: int = 0, key: tuple = ()):
        self.config, self.seed, self.key = config, seed, tuple(key)

    def start(self, ctx: Context, prior: Gaussian | None, first: Scan) -> _MofNCarry:
        if first.z.shape[-1] != 2:
            raise InputError(f"tracker: detections must be Cartesian (x, y), got dimension {first.z.shape[-1]}")
        _check_filter(ctx.filter, self.config, own_cov=first.cov is not None)
        rows: dict[str, list] = {"run": [], "ping": [], "track_id": [], "status": [], "hit": [], "mean": []}
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
                                   position_cov=None if scan.cov is None else scan.cov[b][scan.valid[b]])
            carry.states[b], carry.predicted[b] = st, None
            K = out.ids.shape[0]
            carry.rows["run"].append(np.full(K, b))
            carry.rows["ping"].append(np.full(K, k))
            carry.rows["track_id"].append(out.ids)
            carry.rows["status"].append(out.status)
            carry.rows["hit"].append(out.hit)
            carry.rows["mean"].append(out.mean)
        return carry

    def finish(self, carry: _MofNCarry) -> TrackLog:
        n = carry.motion.dim
        cat = {key: (np.concatenate(v) if v else np.zeros(0)) for key, v in carry.rows.items() if key != "mean"}
        order = np.lexsort((cat["ping"], cat["run"]))  # stable: within a (run, ping) the tracks keep their order
        cat = {key: v[order] for key, v in cat.items()}
        mean = np.concatenate(carry.rows["mean"]).reshape(-1, n)[order] if carry.rows["mean"] else np.zeros((0, n))
        return TrackLog(cat["run"].astype(np.int64), cat["ping"].astype(np.int64), cat["track_id"].astype(np.int64),
                        cat["status"].astype(np.int8), cat["hit"].astype(bool), mean, carry.ctx.batch, carry.ctx.steps)


def run_tracker(scans: Scans, filt: FilterSpec, motion: MotionModel, model: MeasurementModel,
                config: TrackerConfig = TrackerConfig(), seed: int = 0, key: tuple = ()) -> TrackLog:
    """Track every run of ``scans`` (Cartesian detections, ``z (B, T, M, 2)``) with :class:`MofN` through
    :func:`workbench.tracking.run`; one generator per run, ``generator(seed, *key, run)``.  ``origin`` is never
    read."""
    from .loop import run

    if scans.z.shape[-1] != 2:
        raise InputError(f"tracker: detections must be Cartesian (x, y), got dimension {scans.z.shape[-1]}")
    # MofN draws from its own per-run streams; the run's generator is declared (the loop refuses a stochastic filter
    # without one) and never drawn from
    return run(filt, scans, motion, model, association=MofN(config, seed, key), rng=generator(seed, *key, "run"))
