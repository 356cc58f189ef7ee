"""Tracking: the one time loop (:func:`run`) and its association roles.

- :func:`run` drives any filter over a scan series with an association role (:mod:`.loop`);
- single target, batched over runs: :class:`Direct`, :class:`Gated`, :class:`NearestNeighbour` (:mod:`.single`);
- multi-target: :class:`MofN` and :class:`GNN` with :class:`TrackerConfig`, which log a :class:`TrackLog`; split by
  role into :mod:`.records`, :mod:`.gate`, :mod:`.assign`, :mod:`.initiation`, :mod:`.mofn` and :mod:`.gnn`
  (:mod:`.multi` imports them all).  As plugins, trackers are :class:`~workbench.specs.TrackerSpec` records
  (hook ``workbench_trackers``; the built-in ``mofn`` and ``gnn`` live in ``plugins/trackers``).

``docs/architecture.md`` describes the loop once for every driver.
"""

from .loop import Association, Context, Track, run
from .gnn import GNN, run_gnn
from .multi import CONFIRMED, TENTATIVE, MofN, TrackerConfig, TrackLog, run_tracker
from .single import (GATE_99, Direct, Gated, NearestNeighbour, SingleTarget, nearest_candidate, predicted_measurement,
                     radius_gate, strongest_candidate, strongest_candidate_prior)

__all__ = ["run", "Association", "Context", "Track", "Direct", "Gated", "NearestNeighbour", "SingleTarget", "MofN",
           "GNN", "run_gnn", "TrackerConfig", "TrackLog", "run_tracker", "CONFIRMED", "TENTATIVE", "GATE_99", "radius_gate",
           "predicted_measurement", "nearest_candidate", "strongest_candidate", "strongest_candidate_prior"]
