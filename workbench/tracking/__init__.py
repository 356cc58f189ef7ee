"""Tracking: the one time loop (:func:`run`) and its association roles.

- :func:`run` drives any filter over a scan series with an association role (:mod:`.loop`);
- single target, batched over runs: :class:`Direct`, :class:`Gated`, :class:`NearestNeighbour` (:mod:`.single`);
- multi-target: :class:`MofN` with :class:`TrackerConfig` (:mod:`.multi`), which logs a :class:`TrackLog`.

``docs/architecture.md`` describes the loop once for every driver.
"""

from .loop import Association, Context, Track, run
from .multi import CONFIRMED, TENTATIVE, MofN, TrackerConfig, TrackLog, run_tracker
from .single import (GATE_99, Direct, Gated, NearestNeighbour, SingleTarget, nearest_candidate, predicted_measurement,
                     radius_gate, strongest_candidate, strongest_candidate_prior)

__all__ = ["run", "Association", "Context", "Track", "Direct", "Gated", "NearestNeighbour", "SingleTarget", "MofN",
           "TrackerConfig", "TrackLog", "run_tracker", "CONFIRMED", "TENTATIVE", "GATE_99", "radius_gate",
           "predicted_measurement", "nearest_candidate", "strongest_candidate", "strongest_candidate_prior"]
