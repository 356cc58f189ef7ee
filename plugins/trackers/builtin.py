"""The built-in multi-target trackers, registered as a plugin through the entry point ``trackers`` (group
``workbench``), exactly as a third-party plugin registers its own.

- ``mofn``: the M-of-N tracker (:func:`workbench.tracking.run_tracker`): gating, greedy nearest neighbour,
  two-point initiation, M-of-N confirmation and deletion;
- ``gnn``: the same with global nearest neighbour assignment (:func:`workbench.tracking.run_gnn`: SciPy's
  ``linear_sum_assignment`` on the squared Mahalanobis distances, a miss costing the gate) and the gate from a
  declared gate probability.

Both take Cartesian ``(x, y)`` detections and a ``[x, y, vx, vy]`` state, and log each track's covariance.  Their
parameters are :class:`workbench.tracking.TrackerConfig`'s, declared once here with units and ranges; the defaults
are its defaults (so ``mofn`` with its defaults is ``run_tracker`` with ``TrackerConfig()``).
"""

from __future__ import annotations

import math

from workbench import hookimpl
from workbench.params import Param
from workbench.specs import TrackerSpec
from workbench.tracking.gnn import run_gnn
from workbench.tracking.mofn import run_tracker
from workbench.tracking.records import PRIORS, TrackerConfig

from . import gmphd, jipda

_DEFAULT = TrackerConfig()

#: The parameters both trackers share (TrackerConfig's fields, less the gate).
_SHARED = (
    Param("v_max", _DEFAULT.v_max, "initiation box half-width per unit time: |dx|, |dy| <= v_max dt between the two "
          "initiation detections", unit="speed", above=0.0),
    Param("confirm_hits", _DEFAULT.confirm_hits, "M of M-of-N: hits in the window that confirm a tentative track",
          type="int", unit="dimensionless", minimum=1, maximum=30),
    Param("confirm_window", _DEFAULT.confirm_window, "N of M-of-N: the window of pings the hits are counted in",
          type="int", unit="dimensionless", minimum=1, maximum=30),
    Param("delete_misses", _DEFAULT.delete_misses, "consecutive misses that delete a track", type="int",
          unit="dimensionless", minimum=1),
    Param("initiation_hits", _DEFAULT.initiation_hits, "how many of the two initiation detections count as hits "
          "of the M-of-N window", type="int", unit="dimensionless", minimum=0, maximum=2),
    Param("prior", _DEFAULT.prior, "the new track's prior: two-point (the two detections' covariances) or "
          "speed-course", type="str", choices=PRIORS),
    Param("sigma_v", _DEFAULT.sigma_v, "speed standard deviation of the speed-course prior", unit="speed",
          minimum=0.0),
    Param("sigma_c", _DEFAULT.sigma_c, "course standard deviation of the speed-course prior", unit="angle",
          minimum=0.0, maximum=2 * math.pi),
    Param("dense_limit", _DEFAULT.dense_limit, "above this many (track, detection) pairs, candidate pairs come from "
          "a spatial grid first (the same pairs)", type="int", unit="dimensionless", minimum=1),
    Param("gate_sigma", _DEFAULT.gate_sigma, "gate with this position accuracy instead of the filter's R (none: "
          "the filter's R)", type="float?", unit="length", above=0.0),
    Param("detection_sigma", _DEFAULT.detection_sigma, "every detection's stated position accuracy, for the gate, "
          "the prior and the update (none: the filter's R)", type="float?", unit="length", above=0.0),
    Param("min_speed", _DEFAULT.min_speed, "tracks slower than this are not confirmed, and confirmed ones are "
          "deleted (none: no test)", type="float?", unit="speed", minimum=0.0),
)

_GATE = Param("gate", _DEFAULT.gate, "Mahalanobis gate on d2 (9.21: chi-square, 2 dof, 99 %)", unit="gate",
              above=0.0)
_GATE_PROBABILITY = Param("gate_probability", 0.99, "probability that the gate holds a correct detection: the gate "
                          "is the chi-square quantile of the measurement dimension, and a track left without a "
                          "detection costs the gate", unit="dimensionless", above=0.0, maximum=0.999999)

CAPABILITIES = frozenset({"cartesian_2d", "covariance"})


def _mofn(scans, filt, motion, model, *, seed=0, key=(), **params):
    return run_tracker(scans, filt, motion, model, TrackerConfig(**params), seed=seed, key=key, keep_cov=True)


def _gnn(scans, filt, motion, model, *, seed=0, key=(), gate_probability=0.99, **params):
    return run_gnn(scans, filt, motion, model, TrackerConfig(**params), seed=seed, key=key,
                   gate_probability=gate_probability, keep_cov=True)


def _spec(name, summary, run, parameters) -> TrackerSpec:
    return TrackerSpec(name, summary, run, params={p.name: p.default for p in parameters},
                       parameters=tuple(parameters), capabilities=CAPABILITIES)


def trackers() -> list[TrackerSpec]:
    """The built-in trackers' specs."""
    return [
        _spec("mofn", "M-of-N: gating, greedy nearest neighbour, two-point initiation, M-of-N confirmation",
              _mofn, (_GATE, *_SHARED)),
        _spec("gnn", "global nearest neighbour (least-cost assignment) with M-of-N initiation and confirmation",
              _gnn, (_GATE_PROBABILITY, *_SHARED)),
        gmphd.spec(),
        *jipda.trackers(),
    ]


@hookimpl
def workbench_trackers():
    return trackers()
