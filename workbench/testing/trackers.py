"""The tracker test kit: named checks that a multi-target tracker (a :class:`~workbench.specs.TrackerSpec`) tracks
a standard scene well enough, is reproducible, leaves its inputs alone, copes with empty and all-clutter scans,
refuses or skips a NaN detection by name, and writes a valid track log.

The standard scene (:func:`tracker_kit_scene`, built with :func:`workbench.truth.simulate_objects` and
:func:`workbench.sensing.detect_objects`): :data:`RUNS` runs of :data:`PINGS` scans 1 s apart in the plane,

- target A from (20, 20) m at (5, 3) m/s and target B from (20, 110) m at (5, -3) m/s: their paths cross near
  scan 15; B dies after scan :data:`B_LAST`;
- target C born at scan :data:`C_FIRST` at (150, 20) m, moving at (-3, 4) m/s;
- each object detected with probability :data:`P_D` in position with noise ``N(0, SIGMA^2 I)``;
- ``Poisson(CLUTTER_RATE)`` false detections per scan, uniform over :data:`REGION`.

Every object moves at constant velocity with a small white acceleration (``sigma_a`` = 0.05 m/s^2).  The
tracker runs with its current (configured) values on the kit's Kalman filter (linear position model ``R =
SIGMA^2 I``, the same constant-velocity model), ``[x, y, vx, vy]`` states.  GOSPA (``alpha = 2``, ``c =``
:data:`GOSPA_C` m, ``p =`` :data:`GOSPA_P`) of its confirmed tracks against the live objects, averaged over runs
and scans, must lie below :data:`GOSPA_SHARE` of the value with no track at all (every live object missed): the
bound is stated as a share of that baseline so that it reads the same for any tracker.

Each check is ``check(spec)``: it raises ``AssertionError`` naming the check and what it measured, and returns a
one-line summary when it passes.  The checks use only what a ``TrackerSpec`` declares (``run``, ``params``,
``parameters``, ``capabilities``), never its name.
"""

from __future__ import annotations

import numpy as np

from ..kalman_core import kf_update, linear_predict
from ..metrics.ospa import gospa, track_gospa
from ..models import constant_velocity, linear_measurement
from ..params import Param
from ..rng import generator
from ..sensing.objects import detect_objects
from ..specs import FilterSpec, SensorSpec, TrackerSpec
from ..tracking.records import CONFIRMED, TENTATIVE, TrackLog
from ..truth import MultiTruth, ObjectSpec, simulate_objects
from ..types import CLUTTER, InputError, Scans, Truth, _validated, check_covariance
from ._common import Check, check_parameters, fail, run_kit

__all__ = ["TRACKER_CHECKS", "tracker_checks_for", "run_tracker_checks", "tracker_kit_scene", "kit_filter",
           "check_log", "RUNS", "PINGS", "GOSPA_C", "GOSPA_P", "GOSPA_SHARE"]

#: Runs and scans of the standard scene; the scan after which B dies; the scan C is born at.
RUNS, PINGS, B_LAST, C_FIRST = 4, 30, 21, 6
#: Detection probability, position noise (m per axis), mean false detections per scan and their region (m).
P_D, SIGMA, CLUTTER_RATE = 0.95, 1.0, 5.0
REGION = ((-20.0, 200.0), (-20.0, 160.0))
#: GOSPA cut-off (m), order, and the stated bound: mean GOSPA below this share of the no-track value.
GOSPA_C, GOSPA_P, GOSPA_SHARE = 10.0, 2.0, 0.6
SEED = 7


def _predict(state, motion, rng=None):
    return linear_predict(state, motion, "kit-kf")


#: The kit's own Kalman filter (the workbench's core Kalman steps), so the kit needs no filter plugin.
KIT_KF = FilterSpec(name="kit-kf", summary="the tracker kit's Kalman filter", init=lambda prior, rng=None: prior,
                    predict=_predict, update=kf_update, estimate=lambda state: state,
                    capabilities=frozenset({"gaussian", "exact_linear", "linear_only", "detection_covariance"}))


def kit_filter() -> FilterSpec:
    return KIT_KF


def _motion():
    return constant_velocity(2, 1.0, 0.05)


def _model():
    return linear_measurement(np.eye(2, 4), SIGMA ** 2 * np.eye(2), name="kit-position", frame="cartesian-2d",
                              std=(SIGMA, SIGMA))


def _simulate_position(truth: Truth, rng, pd: float = P_D, sigma: float = SIGMA) -> Scans:
    B, T = truth.states.shape[:2]
    detected = rng.random((B, T)) < pd
    z = truth.states[..., :2] + sigma * rng.standard_normal((B, T, 2))
    return Scans(z[:, :, None, :], detected[:, :, None], truth.times, origin=np.zeros((B, T, 1), dtype=int))


#: The kit's position sensor (detections ``N(p, SIGMA^2 I)`` with probability ``pd``).
KIT_SENSOR = SensorSpec(name="kit-position", summary="the tracker kit's position sensor",
                        measurement_model=lambda **_: _model(), simulate=_simulate_position,
                        params={"pd": P_D, "sigma": SIGMA},
                        parameters=(Param("pd", P_D, "detection probability", unit="dimensionless", minimum=0.0,
                                          maximum=1.0),
                                    Param("sigma", SIGMA, "position noise per axis", unit="length", minimum=0.0)),
                        frame="cartesian-2d")


def _clutter(runs: int, pings: int, rate: float, rng, times) -> Scans:
    counts = rng.poisson(rate, (runs, pings))
    M = int(counts.max(initial=0))
    lo = np.array([r[0] for r in REGION])
    hi = np.array([r[1] for r in REGION])
    z = lo + (hi - lo) * rng.random((runs, pings, M, 2))
    valid = np.arange(M)[None, None, :] < counts[..., None]
    return Scans(np.where(valid[..., None], z, 0.0), valid, times, origin=np.full(valid.shape, CLUTTER))


def tracker_kit_scene(seed: int = SEED, runs: int = RUNS) -> tuple[MultiTruth, Scans]:
    """The kit's scene: its truth (three objects: A, B dying after :data:`B_LAST`, C born at :data:`C_FIRST`) and
    its detections (every object's, then the clutter), origin-labelled."""
    targets = [ObjectSpec([20.0, 20.0, 5.0, 3.0], label="A"),
               ObjectSpec([20.0, 110.0, 5.0, -3.0], last=B_LAST, label="B"),
               ObjectSpec([150.0, 20.0, -3.0, 4.0], first=C_FIRST, label="C")]
    truth = simulate_objects(targets, runs=runs, steps=PINGS, motion=_motion(), seed=seed, key=("tracker-kit",))
    rng = generator(seed, "tracker-kit", "detections")
    scans = Scans.merge_all([detect_objects(KIT_SENSOR, truth, rng),
                             _clutter(runs, PINGS, CLUTTER_RATE, rng, truth.times)])
    return truth, scans


def _run(spec: TrackerSpec, scans: Scans, check: str, seed: int = SEED, key=("tracker-kit",)) -> TrackLog:
    try:
        log = spec.run(scans, KIT_KF, _motion(), _model(), seed=seed, key=key)
    except AssertionError:
        raise
    except Exception as exc:  # noqa: BLE001 - name what broke, in one line
        raise fail(check, f"run raised {type(exc).__name__}: {exc}") from None
    if not isinstance(log, TrackLog):
        raise fail(check, f"run returned {type(log).__name__}, not a TrackLog")
    return log


# -- the log -------------------------------------------------------------------------------------------------


def check_log(log: TrackLog, runs: int, pings: int, n: int, capabilities=frozenset(), who: str = "the log"
              ) -> list[str]:
    """What is wrong with a track log for ``runs`` x ``pings`` scans and ``n``-component states: the problems in
    words (empty when it is valid)."""
    out = []
    if (log.runs, log.pings) != (runs, pings):
        out.append(f"{who} says {log.runs} runs x {log.pings} pings for scans of {runs} x {pings}")
    R = np.shape(log.run)[0] if np.ndim(log.run) == 1 else -1
    for name in ("run", "ping", "track_id", "status", "hit"):
        if np.shape(getattr(log, name)) != (R,):
            out.append(f"{who}: {name} has shape {np.shape(getattr(log, name))}, expected ({R},)")
    if np.shape(log.mean) != (R, n):
        out.append(f"{who}: mean has shape {np.shape(log.mean)}, expected ({R}, {n})")
    if out:
        return out
    if R and (log.run.min() < 0 or log.run.max() >= runs):
        out.append(f"{who}: run indices outside [0, {runs})")
    if R and (log.ping.min() < 0 or log.ping.max() >= pings):
        out.append(f"{who}: ping indices outside [0, {pings})")
    cell = np.stack([log.run, log.ping, log.track_id], axis=1) if R else np.zeros((0, 3))
    if R and np.unique(cell, axis=0).shape[0] != R:
        out.append(f"{who}: a track identity appears twice in one (run, ping)")
    bad_status = ~np.isin(log.status, [TENTATIVE, CONFIRMED])
    if bad_status.any():
        out.append(f"{who}: statuses {sorted(set(np.asarray(log.status)[bad_status].tolist()))} are neither "
                   f"TENTATIVE ({TENTATIVE}) nor CONFIRMED ({CONFIRMED})")
    if not np.all(np.isfinite(log.mean)):
        out.append(f"{who}: mean holds NaN or inf")
    if "covariance" in capabilities and log.cov is None:
        out.append(f"{who}: no covariances, but the tracker declares the 'covariance' capability")
    if log.cov is not None:
        if np.shape(log.cov) != (R, n, n):
            out.append(f"{who}: cov has shape {np.shape(log.cov)}, expected ({R}, {n}, {n})")
        elif not np.all(np.isfinite(log.cov)):
            out.append(f"{who}: cov holds NaN or inf")
        else:
            try:
                check_covariance(f"{who}: cov", np.asarray(log.cov, dtype=float))
            except InputError as exc:
                out.append(str(exc))
    if "existence" in capabilities and log.existence is None:
        out.append(f"{who}: no existence probabilities, but the tracker declares the 'existence' capability")
    if log.existence is not None:
        # TrackLog.existence: an existence probability (JIPDA) or a Gaussian component's weight (PHD, which may
        # exceed 1): finite and >= 0 either way
        e = np.asarray(log.existence, dtype=float)
        if e.shape != (R,):
            out.append(f"{who}: existence has shape {e.shape}, expected ({R},)")
        elif not np.all(np.isfinite(e) & (e >= 0)):
            out.append(f"{who}: existence holds a negative, NaN or inf value")
    return out


def _require_valid(check: str, log: TrackLog, scans: Scans, spec: TrackerSpec, what: str) -> None:
    problems = check_log(log, scans.batch, scans.steps, 4, spec.capabilities, f"the log {what}")
    if problems:
        raise fail(check, "; ".join(problems))


#: How near two runs' numbers must be where only rounding may differ (a run tracked alone against the same run
#: in a batch: batched linear algebra may round differently), relative to the field's largest value.
ROUNDING = 1e-9


def _same_logs(a: TrackLog, b: TrackLog, rounding: float = 0.0) -> str | None:
    """The first field in which two logs differ (``None``: none); ``rounding > 0`` lets the float fields (``mean``,
    ``cov``, ``existence``) differ by that share of their largest value, the rest must be equal."""
    for name in ("run", "ping", "track_id", "status", "hit", "mean", "cov", "existence"):
        x, y = getattr(a, name), getattr(b, name)
        if x is None and y is None:
            continue
        if x is None or y is None or np.shape(x) != np.shape(y):
            return name
        if rounding and name in ("mean", "cov", "existence"):
            x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
            scale = max(1.0, float(np.max(np.abs(x), initial=0.0)))
            if not np.all(np.abs(x - y) <= rounding * scale):
                return name
        elif not np.array_equal(x, y, equal_nan=True):
            return name
    if (a.runs, a.pings) != (b.runs, b.pings):
        return "runs, pings"
    return None


# -- the checks ----------------------------------------------------------------------------------------------


def _no_track_gospa(truth: MultiTruth) -> float:
    """Mean GOSPA with no track at all: every live object missed, ``sqrt(n_live c^p / 2)`` per scan."""
    empty = np.zeros(truth.alive.shape[:2] + (0, 2))
    return float(gospa(empty, truth.states[..., :2], GOSPA_C, GOSPA_P, y_valid=truth.alive).distance.mean())


def check_gospa(spec: TrackerSpec) -> str:
    """Mean GOSPA (c = GOSPA_C, p = GOSPA_P) of the confirmed tracks on the standard scene below GOSPA_SHARE of
    the no-track value."""
    name = "check_gospa"
    truth, scans = tracker_kit_scene()
    log = _run(spec, scans, name)
    _require_valid(name, log, scans, spec, "of the standard scene")
    g = track_gospa(log, truth.states, GOSPA_C, GOSPA_P, truth_valid=truth.alive)
    mean, baseline = float(g.distance.mean()), _no_track_gospa(truth)
    bound = GOSPA_SHARE * baseline
    if not mean < bound:
        raise fail(name, f"mean GOSPA (c = {GOSPA_C:g} m, p = {GOSPA_P:g}) over {RUNS} runs x {PINGS} scans is "
                         f"{mean:.3g} m, not below {GOSPA_SHARE:g} x the no-track value {baseline:.3g} m = "
                         f"{bound:.3g} m (missed {float(g.n_missed.mean()):.2f}, false "
                         f"{float(g.n_false.mean()):.2f} per scan)")
    return (f"mean GOSPA {mean:.3g} m < {bound:.3g} m ({GOSPA_SHARE:g} x no-track {baseline:.3g} m); missed "
            f"{float(g.n_missed.mean()):.2f}, false {float(g.n_false.mean()):.2f} per scan")


def check_same_seed(spec: TrackerSpec) -> str:
    """The same scans and seed give the same log, field for field; each run's tracks do not depend on the other
    runs (a run tracked alone gives its rows of the whole batch's log: identities, statuses and hits equal, numbers
    to :data:`ROUNDING`)."""
    name = "check_same_seed"
    _, scans = tracker_kit_scene()
    first, second = _run(spec, scans, name), _run(spec, scans, name)
    diff = _same_logs(first, second)
    if diff:
        raise fail(name, f"two runs with the same scans and seed differ in the log's {diff}")
    alone = _run(spec, scans.take(np.array([1])), name)
    rows = first.select(first.run == 1)
    rows = TrackLog(rows.run - 1, rows.ping, rows.track_id, rows.status, rows.hit, rows.mean, 1, rows.pings,
                    rows.cov, rows.existence)
    diff = _same_logs(alone, rows, ROUNDING)
    if diff:
        raise fail(name, f"run 1 tracked alone differs from its rows of the whole batch's log in {diff} (beyond "
                         f"{ROUNDING:g} of its scale): a run's tracks depend on the other runs (one random stream "
                         f"per run)")
    return (f"same seed, same log ({first.run.size} rows); run 1 alone gives its rows of the batch (to "
            f"{ROUNDING:g})")


def _snapshot(scans: Scans) -> dict:
    return {k: None if getattr(scans, k) is None else np.array(getattr(scans, k), copy=True)
            for k in ("z", "valid", "times", "snr", "doppler", "origin", "cov", "clutter_density")}


def check_inputs_unchanged(spec: TrackerSpec) -> str:
    """The scans (every field), the motion model's and measurement model's matrices and the spec's values are the
    same after a run."""
    name = "check_inputs_unchanged"
    _, scans = tracker_kit_scene()
    motion, model = _motion(), _model()
    before = _snapshot(scans)
    mats = {k: np.array(getattr(motion, k), copy=True) for k in ("F", "Q")}
    mats.update({f"model.{k}": np.array(getattr(model, k), copy=True) for k in ("H", "R")})
    params = dict(spec.params)
    try:
        spec.run(scans, KIT_KF, motion, model, seed=SEED, key=("tracker-kit",))
    except Exception as exc:  # noqa: BLE001
        raise fail(name, f"run raised {type(exc).__name__}: {exc}") from None
    changed = [k for k, v in before.items()
               if not (v is None and getattr(scans, k) is None)
               and (v is None or getattr(scans, k) is None or not np.array_equal(v, getattr(scans, k), equal_nan=True))]
    changed += [k for k, v in mats.items()
                if not np.array_equal(v, getattr(model if k.startswith("model.") else motion, k.split(".")[-1]))]
    if dict(spec.params) != params:
        changed.append("the spec's params")
    if changed:
        raise fail(name, f"the run changed its inputs: {', '.join(changed)}")
    return "scans, motion and measurement models and params unchanged"


def check_empty_scans(spec: TrackerSpec) -> str:
    """Scans with no detection at all (M = 0), and scans whose rows are all padding: a valid log without a
    confirmed track."""
    name = "check_empty_scans"
    times = np.arange(float(PINGS))
    for what, scans in (("of scans with M = 0", Scans(np.zeros((2, PINGS, 0, 2)), np.zeros((2, PINGS, 0), bool),
                                                     times)),
                        ("of scans of padding only", Scans(np.zeros((2, PINGS, 3, 2)),
                                                           np.zeros((2, PINGS, 3), bool), times))):
        log = _run(spec, scans, name)
        _require_valid(name, log, scans, spec, what)
        if np.any(log.status == CONFIRMED):
            raise fail(name, f"the log {what} holds {int(np.sum(log.status == CONFIRMED))} confirmed track rows")
    return "no detections (M = 0, and padding only): valid logs without tracks"


def check_all_clutter(spec: TrackerSpec) -> str:
    """Scans of clutter only (the scene's clutter, no object): a valid log; the false confirmed tracks are counted
    in the summary."""
    name = "check_all_clutter"
    rng = generator(SEED, "tracker-kit", "all-clutter")
    scans = _clutter(RUNS, PINGS, CLUTTER_RATE, rng, np.arange(float(PINGS)))
    log = _run(spec, scans, name)
    _require_valid(name, log, scans, spec, "of all-clutter scans")
    false = float(log.confirmed_counts().mean())
    return f"all-clutter scans ({CLUTTER_RATE:g} per scan): valid log, {false:.2f} confirmed false tracks per scan"


_NAN_WORDS = ("nan", "non-finite", "not finite", "finite")


def check_nan_detection(spec: TrackerSpec) -> str:
    """A valid detection holding NaN (smuggled past the ``Scans`` check, as a reader that builds records without
    it could) is refused with an ``InputError`` that says so, or skipped: the log is then the log of the same scans
    with that row marked invalid."""
    name = "check_nan_detection"
    _, scans = tracker_kit_scene()
    b, k = 0, PINGS // 2
    j = int(np.argmax(scans.valid[b, k]))
    z = scans.z.copy()
    z[b, k, j, 0] = np.nan
    bad = _validated(Scans, **{**vars(scans), "z": z})
    try:
        log = spec.run(bad, KIT_KF, _motion(), _model(), seed=SEED, key=("tracker-kit",))
    except InputError as exc:
        if not any(w in str(exc).lower() for w in _NAN_WORDS):
            raise fail(name, f"the NaN detection was refused, but the message does not say it is NaN or "
                             f"non-finite: {exc}") from None
        return f"refused by name: {str(exc)[:120]}"
    except Exception as exc:  # noqa: BLE001
        raise fail(name, f"a NaN detection raised {type(exc).__name__} ({exc}), not an InputError naming it") \
            from None
    valid = scans.valid.copy()
    valid[b, k, j] = False
    ref = _run(spec, Scans(scans.z, valid, scans.times), name)
    diff = _same_logs(log, ref)
    if diff:
        raise fail(name, f"a NaN detection was neither refused (InputError) nor skipped: the log differs from the "
                         f"log with that row invalid in {diff}")
    return "skipped: the log equals the log with the NaN row marked invalid"


def check_log_valid(spec: TrackerSpec) -> str:
    """The standard scene's log: shapes, runs and pings in range, one row per (run, ping, identity), statuses
    TENTATIVE or CONFIRMED, finite means, covariances symmetric PSD where kept (and kept where declared),
    existence finite and >= 0 where kept (and kept where declared); round trip through ``to_arrays``."""
    name = "check_log_valid"
    _, scans = tracker_kit_scene()
    log = _run(spec, scans, name)
    _require_valid(name, log, scans, spec, "of the standard scene")
    again = TrackLog.from_arrays(log.to_arrays())
    diff = _same_logs(log, again)
    if diff:
        raise fail(name, f"the log does not survive to_arrays / from_arrays: {diff} differs")
    kept = ", ".join(w for w, v in (("cov", log.cov), ("existence", log.existence)) if v is not None) or "none"
    return f"{log.run.size} rows valid; kept: {kept}"


def _check_parameters(spec: TrackerSpec) -> str:
    return check_parameters(spec, "check_parameters")


def _always(spec) -> bool:
    return True


TRACKER_CHECKS = (
    Check("check_parameters", "declared parameters: defaults valid, NaN, wrong units and undeclared keys refused",
          _always, _check_parameters),
    Check("check_gospa", "mean GOSPA on the standard scene below the stated bound", _always, check_gospa),
    Check("check_same_seed", "same seed, same tracks; runs independent", _always, check_same_seed),
    Check("check_inputs_unchanged", "inputs never mutated", _always, check_inputs_unchanged),
    Check("check_empty_scans", "empty scans handled", _always, check_empty_scans),
    Check("check_all_clutter", "all-clutter scans handled", _always, check_all_clutter),
    Check("check_nan_detection", "a NaN detection refused by name or skipped", _always, check_nan_detection),
    Check("check_log_valid", "a valid track log", _always, check_log_valid),
)


def tracker_checks_for(spec: TrackerSpec) -> list[Check]:
    return [c for c in TRACKER_CHECKS if c.applies(spec)]


def run_tracker_checks(spec: TrackerSpec):
    """Every check of the tracker kit on ``spec`` without pytest (:func:`workbench.testing.run_checks`)."""
    if not isinstance(spec, TrackerSpec):
        raise TypeError(f"the tracker kit checks a TrackerSpec, got {type(spec).__name__}")
    return run_kit(spec, TRACKER_CHECKS)
