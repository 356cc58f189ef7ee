"""The one time loop of the workbench: every driver is this loop with a pluggable association step.

::

    carry = association.start(context, prior)
    for k, scan in enumerate(scans):                  # the filter never sees scan.origin
        if k > 0 (or predict_first):
            motion_k = motion.at(t_{k-1}, t_k - t_{k-1})   # the step's start time and interval bound
            carry = association.predict(carry, motion_k, k)  # (predict_first: t_0 - dt, dt before scan 0)
        carry = association.update(carry, scan, k)
    return association.finish(carry)

(from scan 1 on, ``association.step(carry, motion_k, scan, k)`` in place of the two calls where the filter gives a
fused ``FilterSpec.step`` and the role takes it: the same numbers bit for bit, the filter kit checks)

An *association* decides what the filter is updated with at each scan, and records what it decided:

- :class:`~workbench.tracking.single.Direct`: the scan as it is (at most one valid row per item, or any number for a
  filter with the ``multi_measurement`` capability);
- :class:`~workbench.tracking.single.Gated`: the detections inside a radius around the predicted position, handed
  whole to a multi-measurement filter or through a pseudo-measurement step to any other;
- :class:`~workbench.tracking.single.NearestNeighbour`: the candidate nearest (Mahalanobis) to the predicted
  measurement, optionally gated, with coasting and restarts;
- :class:`~workbench.tracking.multi.MofN`: multi-target tracking (gating, greedy nearest neighbour, two-point
  initiation, M-of-N confirmation and deletion), the live tracks of a run being the filter's batch.

The single-target roles return a :class:`Track` (the estimates over time and the association's records); the
multi-target role returns a :class:`~workbench.tracking.multi.TrackLog`.  A filter state is the filter's own
business; the loop only ever calls the filter's four functions through the association.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol

import numpy as np

from ..models import MeasurementModel, MotionModel
from ..specs import FilterSpec
from ..types import Gaussian, InputError, Scan, Scans

__all__ = ["Context", "Association", "Track", "run", "default_association"]

#: The association :func:`run` uses where the caller names none, as a factory: registered by the module that defines
#: it (:mod:`.single` registers :class:`~workbench.tracking.single.Direct` when it is imported, and the package
#: imports it), so that the loop imports no role.
_DEFAULT_ASSOCIATION: list[Callable[[], Any]] = []


def default_association(factory: Callable[[], Any]) -> Callable[[], Any]:
    """Register ``factory`` (called with no arguments, it returns an association) as :func:`run`'s default
    association, replacing any earlier one; returns ``factory``."""
    if not callable(factory):
        raise InputError(f"a default association is registered as a factory (a class or callable), got {factory!r}")
    _DEFAULT_ASSOCIATION[:] = [factory]
    return factory


@dataclass(frozen=True)
class Context:
    """What an association works with: the filter, the measurement model, the motion model (of the nominal step),
    the scan series' shape and times, and the random generator of the run (``None`` for a role that keys its own
    per-run streams)."""

    filter: FilterSpec
    model: MeasurementModel
    motion: MotionModel
    batch: int
    steps: int
    times: np.ndarray
    rng: np.random.Generator | None


class Association(Protocol):
    """An association role for :func:`run` (see the module docstring)."""

    def start(self, ctx: Context, prior: Gaussian | None, first: Scan) -> Any: ...

    def predict(self, carry: Any, motion: MotionModel, k: int) -> Any: ...

    def update(self, carry: Any, scan: Scan, k: int) -> Any: ...

    def finish(self, carry: Any) -> Any: ...

    # Optional: ``step(carry, motion, scan, k) -> carry``, predict and update at scan ``k`` through the filter's
    # fused ``FilterSpec.step``, the same records as ``predict`` then ``update``; :func:`run` calls it from scan 1 on
    # where the filter gives a step and the role has this method (:class:`~workbench.tracking.single.Direct`).
    # Optional: ``single_target = True``, declaring that the filter's batch is the runs' (one item per run), which
    # ``run(..., innovations=True)`` needs (:class:`~workbench.tracking.single.SingleTarget` declares it).


@dataclass(frozen=True)
class Track:
    """A single-target filter's output over a scan series, for a batch of runs.

    Shapes
    ------
    mean, predicted_mean : (B, T, n)
    cov : (B, T, n, n)
    records : the association's per-step records, each ``(B, T, ...)`` (see each role)

    ``seconds`` is the wall time of the loop; ``diagnostics`` the filter's counters after the last scan.
    ``innovations``: with ``run(..., innovations=True)``, a :class:`~workbench.kalman_core.Innovations` whose
    fields are ``(B, T, ...)`` (``y (B, T, m)``, ``S (B, T, m, m)``, ``nis``, ``log_likelihood`` and ``present``
    ``(B, T)``; NaN where an item had no update at a scan); ``None`` otherwise.
    """

    filter: str
    mean: np.ndarray
    cov: np.ndarray
    predicted_mean: np.ndarray
    diagnostics: Mapping[str, float]
    records: Mapping[str, np.ndarray] = field(default_factory=dict)
    seconds: float = 0.0
    innovations: Any = None


def run(filt: FilterSpec, scans: Scans, motion: MotionModel, model: MeasurementModel, *,
        association: Association | None = None, prior: Gaussian | None = None,
        rng: np.random.Generator | None = None, predict_first: bool = False,
        progress: Callable[[float], None] | None = None, innovations: bool = False):
    """Drive ``filt`` over ``scans`` with ``association`` (default :class:`~workbench.tracking.single.Direct`).

    Parameters
    ----------
    filt : FilterSpec
        The filter (any :class:`~workbench.specs.FilterSpec`).
    scans : Scans
        The detections, ``z (B, T, M, m)``; their ``origin`` labels are stripped before any step sees them.
    motion : MotionModel
        The motion model; each predict gets ``motion.at(t_{k-1}, t_k - t_{k-1})`` (rebuilt where the interval
        differs from its own ``dt``, the step's absolute start time bound, so a time-varying model sees it;
        with ``predict_first``, the step before the first scan is ``motion.at(t_0 - dt, dt)``).
    model : MeasurementModel
        The measurement model the filter is given.
    association : Association or None
        The role that chooses what the filter is updated with (see the module docstring).
    prior : Gaussian or None
        The belief at the first scan, ``(B, n)`` (a role may build its own, e.g. from the first scan).
    rng : numpy.random.Generator or None
        The generator of the run's random draws (filters that draw, pseudo steps).
    predict_first : bool
        Predict before the first update too (as FilterPy and Stone Soup do, when the prior is the belief one step
        before the first scan); by default the first scan updates the prior directly.
    progress : callable or None
        Called with the finished fraction after each scan.
    innovations : bool
        Record each update's innovation, its covariance, NIS and log-likelihood into the returned
        :class:`Track`'s ``innovations`` (``(B, T, ...)``); the filter must declare the ``innovations`` capability
        and the association be a single-target one.
    """
    if association is None:
        if not _DEFAULT_ASSOCIATION:
            raise InputError("run: no association given and none registered as the default (import "
                             "workbench.tracking, whose single-target roles register Direct)")
        association = _DEFAULT_ASSOCIATION[0]()
    if prior is not None and prior.batch != scans.batch:
        raise InputError(f"prior has batch {prior.batch} but the scans have batch {scans.batch}")
    if scans.cov is not None and "detection_covariance" not in filt.capabilities:
        raise InputError(f"the scans carry each detection's own covariance (cov), which filter {filt.name!r} would "
                         f"ignore (it lacks the detection_covariance capability)")
    from ..params import check_footprint

    check_footprint(filt.declared, filt.params, scans.batch, motion.dim, f"filter {filt.name!r}")
    if rng is None and "stochastic" in filt.capabilities:
        raise InputError(f"filter {filt.name!r} draws random numbers but no generator was given (rng is None): pass "
                         f"rng=wb.generator(seed, key), e.g. wb.run(filt, scans, motion, model, prior=prior, "
                         f"rng=wb.generator(1, 'runs'))")
    T = scans.steps
    recorder = None
    if innovations:
        filt, recorder = _recording(filt, association, scans.batch, T, model.dim)
    ctx = Context(filt, model, motion, scans.batch, T, scans.times, rng)
    carry = association.start(ctx, prior, scans.scan(0).for_filter() if T else Scan.empty(scans.batch,
                                                                                           scans.z.shape[-1]))
    times = np.asarray(scans.times, dtype=float)
    # a filter's fused predict + update + estimate (FilterSpec.step), where the role takes it (Association.step)
    fused = getattr(association, "step", None) if filt.step is not None and recorder is None else None
    for k in range(T):
        scan = scans.scan(k).for_filter()
        if k > 0 and fused is not None:
            carry = fused(carry, motion.at(float(times[k - 1]), float(times[k] - times[k - 1])), scan, k)
            if progress is not None:
                progress((k + 1) / T)
            continue
        if k > 0:
            # the step from t_{k-1} to t_k: its absolute start time and interval bound into the model
            carry = association.predict(carry, motion.at(float(times[k - 1]), float(times[k] - times[k - 1])), k)
        elif predict_first:
            # the prior is the belief one nominal step before the first scan
            carry = association.predict(carry, motion.at(float(times[0]) - motion.dt, motion.dt), k)
        if recorder is not None:
            recorder["k"] = k
        carry = association.update(carry, scan, k)
        if progress is not None:
            progress((k + 1) / T)
    result = association.finish(carry)
    if recorder is not None:
        import dataclasses

        result = dataclasses.replace(result, innovations=recorder["record"])
    return result


def _recording(filt: FilterSpec, association: Any, batch: int, steps: int, m: int):
    """``filt`` with an update that asks for the innovations and writes them at the loop's scan ``k``, and the
    recorder (``{"k": scan, "record": Innovations (B, T, ...)}``); refused by name where the filter does not declare
    ``innovations`` or the association is not a single-target role (its batch is not the runs')."""
    import dataclasses

    from ..kalman_core import Innovations

    if "innovations" not in filt.capabilities:
        raise InputError(f"filter {filt.name!r} does not record innovations (it lacks the innovations capability; "
                         f"the Kalman family and the IMM have it)")
    if getattr(association, "single_target", False) is not True:
        raise InputError(f"innovations=True needs a single-target association (Direct, Gated, NearestNeighbour), "
                         f"not {type(association).__name__}")
    record = Innovations(np.full((batch, steps, m), np.nan), np.full((batch, steps, m, m), np.nan),
                         np.full((batch, steps), np.nan), np.full((batch, steps), np.nan),
                         np.zeros((batch, steps), dtype=bool))
    recorder: dict = {"k": 0, "record": record}
    update = filt.update

    def recording_update(state, scan, model, rng=None):
        state, got = update(state, scan, model, rng, innovations=True)
        if got.y.shape != (batch, m):
            raise InputError(f"filter {filt.name!r} gave innovations of shape {got.y.shape} at scan "
                             f"{recorder['k']}; the run records {(batch, m)} (the measurement model's dimension)")
        k = recorder["k"]
        for name in ("y", "S", "nis", "log_likelihood", "present"):
            getattr(record, name)[:, k] = getattr(got, name)
        return state

    return dataclasses.replace(filt, update=recording_update, step=None), recorder

