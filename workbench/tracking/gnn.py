"""The global-nearest-neighbour (GNN) multi-target tracker.

The M-of-N tracker (:mod:`.mofn`) with one part changed: at every ping the gated (track, detection) pairs are
assigned by :func:`~workbench.tracking.assign.gnn_assign`, the one-to-one assignment of least total squared
Mahalanobis distance in which a track left without a detection costs the gate itself, instead of greedily pair by
pair.  The gate comes from a declared gate probability ``P_G`` (``d2 <= chi2_m^-1(P_G)``, ``m`` the measurement
dimension, :func:`~workbench.tracking.gate.chi2_gate`).  Gating, two-point initiation, M-of-N confirmation and
deletion are the M-of-N tracker's own.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..models import MeasurementModel, MotionModel
from ..specs import FilterSpec
from ..types import Scans
from .assign import gnn_assign
from .gate import chi2_gate
from .mofn import MofN, track_runs
from .records import TrackerConfig, TrackLog

__all__ = ["GNN", "run_gnn"]


class GNN(MofN):
    """The GNN association role of :func:`workbench.tracking.run`: :class:`~workbench.tracking.mofn.MofN` with the
    global assignment.  ``config.gate`` is the gate and the cost of leaving a track without a detection
    (:func:`run_gnn` sets it from a gate probability)."""

    who = "GNN tracker"
    #: :func:`gnn_assign` solves each cluster of tracks linked through shared detections alone, and pairs of two
    #: runs share neither, so one call on every run's pairs is each run's own assignment: the batched path of
    #: :meth:`MofN.batched` (one filter batch per ping for all runs), bit for bit the per-run path
    assign_runs_apart = True

    def assign(self, rows: np.ndarray, cols: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The least-cost one-to-one assignment of the gated pairs (:func:`gnn_assign`, a miss costing the gate)."""
        return gnn_assign(rows, cols, d2, self.config.gate)


def run_gnn(scans: Scans, filt: FilterSpec, motion: MotionModel, model: MeasurementModel,
            config: TrackerConfig = TrackerConfig(), seed: int = 0, key: tuple = (),
            gate_probability: float | None = 0.99, keep_cov: bool = False) -> TrackLog:
    """Track every run of ``scans`` with :class:`GNN`; one generator per run, ``generator(seed, *key, run)``.

    ``gate_probability``: the gate is ``chi2_gate(gate_probability, model.dim)`` (replacing ``config.gate``);
    ``None`` keeps ``config.gate``.  ``keep_cov``: the log carries each track's covariance.
    """
    if gate_probability is not None:
        config = dataclasses.replace(config, gate=chi2_gate(gate_probability, model.dim))
    return track_runs(GNN(config, seed, key, keep_cov), scans, filt, motion, model)
