"""Track initiation and confirmation for the multi-target trackers.

- initiation: a tentative track from every pair (initiation detection of ping k-1, initiation detection of ping
  k) inside the rectangular gate ``|dx|, |dy| <= v_max dt`` (:func:`rectangular_pairs`), each detection in at most
  one pair (greedy by smallest Chebyshev distance); its prior is :func:`two_point_prior` (or
  :func:`speed_course_prior`); :func:`initiate` adds the new tracks to the live-track table through the filter's
  state contract (:meth:`~workbench.specs.FilterSpec.join_items`);
- confirmation and deletion: the M-of-N state machine :func:`mofn_step` (bit histories of hits).
"""

from __future__ import annotations

import numpy as np

from ..models import MeasurementModel, MotionModel
from ..specs import FilterSpec
from ..types import Gaussian
from .assign import greedy_assign
from .gate import box_pairs, position_covariance
from .records import CONFIRMED, TENTATIVE, TrackerConfig, TrackerState, TrackTable

__all__ = ["two_point_prior", "speed_course_prior", "new_track_prior", "rectangular_pairs", "mofn_step", "initial_state", "initiate"]


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


def new_track_prior(config, model: MeasurementModel, motion: MotionModel, p_prev: np.ndarray, p_cur: np.ndarray,
                    n: int, cov_prev: np.ndarray | None = None, cov_cur: np.ndarray | None = None) -> Gaussian:
    """The prior of the new tracks started from the position pairs ``p_prev, p_cur (K, 2)`` one step apart, by
    ``config.prior``: :func:`two_point_prior` or :func:`speed_course_prior`.  The positions' covariances are
    ``cov_prev, cov_cur (K, 2, 2)`` where given (the detections' own), else ``config.detection_sigma`` (isotropic)
    where set, else the model's (:func:`~workbench.tracking.gate.position_covariance`)."""
    if cov_cur is None:
        if config.detection_sigma is not None:
            cov_cur = np.broadcast_to(config.detection_sigma**2 * np.eye(2), (p_cur.shape[0], 2, 2))
            cov_prev = cov_cur
        else:
            cov_cur = position_covariance(model, p_cur, n)
            cov_prev = position_covariance(model, p_prev, n) if config.prior == "two-point" else None
    if config.prior == "two-point":
        return two_point_prior(p_prev, p_cur, motion.dt, cov_prev, cov_cur)
    return speed_course_prior(p_prev, p_cur, motion.dt, cov_cur, config.sigma_v, config.sigma_c)


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


def initial_state(n: int = 4) -> TrackerState:
    """No tracks, no initiation candidates."""
    e = np.zeros(0, dtype=np.int64)
    return TrackerState(TrackTable(e, e.astype(np.int8), e, e, e, np.zeros((0, n)), None, np.zeros((0, n, n))),
                        np.zeros((0, 2)))


def initiate(st: TrackerState, table: TrackTable, init_pos: np.ndarray, init_cov: np.ndarray | None,
             filt: FilterSpec, motion: MotionModel, model: MeasurementModel, config: TrackerConfig, rng,
             who: str = "M-of-N tracker") -> tuple[TrackTable, int, np.ndarray, int]:
    """Start tentative tracks from this ping's initiation detections ``init_pos (P, 2)`` (their own position
    covariances ``init_cov (P, 2, 2)`` or ``None``) and the last ping's unused ones (``st.candidates``), and add
    them after the live tracks of ``table``.

    Returns ``table, new, used, next_id``: the table with the new tracks last (in detection order), how many were
    started, which of ``init_pos`` they used ``(P,)`` and the next free identity.
    """
    n = motion.dim
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
            prior = new_track_prior(config, model, motion, p_prev, p_cur, n, cov_prev, cov_cur)
        else:
            prior = new_track_prior(config, model, motion, p_prev, p_cur, n)
        new_state = filt.init(prior, rng)
        filt.require_batch_contract(new_state, who)
        new_est = filt.estimate(new_state)
        new_mean = new_est.mean
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
                           np.concatenate([table.mean, new_mean]), joined,
                           None if table.cov is None else np.concatenate([table.cov, new_est.cov]))
    used = np.zeros(init_pos.shape[0], dtype=bool)
    used[a_c] = True
    return table, int(a_c.size), used, next_id
