"""Multi-target tracking, one import for all of it (the modules are split by role):

- :mod:`.records`: :class:`TrackerConfig`, the live-track table and :class:`TrackLog`;
- :mod:`.gate`: gating (:func:`gated_pairs`, :func:`chi2_gate`) and the covariances between the Cartesian
  detections and the measurement space;
- :mod:`.assign`: assignment, greedy nearest neighbour (:func:`greedy_assign`) and global nearest neighbour
  (:func:`gnn_assign`);
- :mod:`.initiation`: two-point initiation (:func:`initiate`) and the M-of-N confirmation and deletion machine
  (:func:`mofn_step`);
- :mod:`.mofn`: the M-of-N tracker (:class:`MofN`, :func:`run_tracker`); :mod:`.gnn`: the GNN tracker
  (:class:`GNN`, :func:`run_gnn`).

Every name this module held before the split is importable from it still.
"""

from __future__ import annotations

from .assign import assignment_cost, gnn_assign, greedy_assign
from .gate import (box_pairs, chi2_gate, detection_covariance, gate_covariance, gated_pairs, measurement_covariance,
                   measurement_view, position_covariance)
from .gnn import GNN, run_gnn
from .initiation import (initial_state, initiate, mofn_step, rectangular_pairs, speed_course_prior,
                         two_point_prior)
from .mofn import MofN, run_tracker, track_runs, tracker_step
from .records import CONFIRMED, PRIORS, TENTATIVE, PingTracks, TrackerConfig, TrackerState, TrackLog, TrackTable

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
    "chi2_gate",
    "gnn_assign",
    "assignment_cost",
    "initiate",
    "track_runs",
    "GNN",
    "run_gnn",
]
