"""The filter kit's check of the filter-state contract: a filter's take / join, and the filter under every built-in
tracker.

A multi-target tracker keeps one filter state per run whose batch items are the live tracks; it deletes tracks
with the filter's ``take`` and adds new ones with its ``join`` (:meth:`workbench.specs.FilterSpec.take_items`,
:meth:`~workbench.specs.FilterSpec.join_items`: the filter's own functions, or the ``batch_fields`` its state's
class declares).  A filter can pass every single-target check and still break there (an array sliced that is not
per item, a mode-first array cut along the wrong axis), so :func:`check_under_trackers` runs both:

1. the contract on a batch of ``B = n = 4`` items (the case where guessing the batch from an array's length
   slices a ``(4, 4)`` matrix): after ``init``, ``predict`` and an update that measures items 1 and 3 only,
   ``take(s, all) == s`` and ``join(take(s, a), take(s, b)) == take(s, a + b)`` exactly (every array, dtype and
   shape, every other value), the estimate of ``take(s, idx)`` is the estimate of ``s`` at ``idx``, and a taken
   and a joined state go on through ``predict`` and ``update`` (for a filter that is not stochastic, to the same
   estimate as the whole batch, item for item);
2. the M-of-N tracker (:func:`workbench.tracking.run_tracker`, default configuration) on a short scene built
   here: target A over 12 pings with a missed detection at ping 6, target B born at ping 2 (its track joins A's)
   and last seen at ping 7 (deleted three misses later).  A's track must be confirmed, held through the miss
   under one identity, and near A at the end; B's must be confirmed near B and then deleted;
3. every other built-in tracker (:func:`check_each_tracker`: ``gnn``, ``jipda``, ``jpda``, ``gm-phd``) on the same
   scene (detections in the measurement model's own frame for a tracker without the ``cartesian_2d`` capability):
   a valid track log holding A and B under one confirmed track each, or a refusal by ``InputError`` that names the
   capability the tracker refuses the filter for (``gaussian`` lacking, ``stochastic`` present, or, for a
   ``range_bearing_input`` filter, the kit's range-bearing model), which counts as a pass.

It applies to filters of the kit's 2-D constant-velocity problem (M-of-N tracks ``[x, y, vx, vy]``); detections
are seen in position (linear model) or, for a filter with ``range_bearing_input``, in range and bearing.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..models import constant_velocity, linear_measurement, range_bearing
from ..rng import generator
from ..specs import FilterSpec
from ..types import Gaussian, InputError, Scan, Scans

__all__ = ["check_under_trackers", "under_trackers_applies", "UNDER_TRACKERS_REQUIRES", "state_leaves",
           "same_leaves", "tracker_scene", "check_each_tracker", "builtin_trackers"]

UNDER_TRACKERS_REQUIRES = ("a filter of the kit's 2-D constant-velocity problem (neither position_doppler_3d nor "
                           "motion models of its own)")
#: Pings of the tracker scene; A's missed ping; B's first and last pings.
SCENE_PINGS, A_MISS, B_FIRST, B_LAST = 12, 6, 2, 7
#: How near (units) a confirmed track's position must be to its target (the scene's detection noise is 0.5 per
#: axis; the filters' stated accuracy 1 unit in position, about 1.4 across the beam in range and bearing).
NEAR = 6.0


def under_trackers_applies(spec: FilterSpec) -> bool:
    return "position_doppler_3d" not in spec.capabilities and not getattr(spec, "motion_models", ())


def _model(spec: FilterSpec):
    if "range_bearing_input" in spec.capabilities:
        return range_bearing(1.0, 0.004)
    return linear_measurement(np.eye(2, 4), np.eye(2), name="kit-position", frame="cartesian-2d", std=(1.0, 1.0))


def _motion():
    return constant_velocity(2, 1.0, 0.05)


# -- exact comparison of two states -----------------------------------------------------------------------------


def state_leaves(obj, path: str = "state", out: dict | None = None) -> dict:
    """``{path: value}`` of every leaf of a state (dataclass fields, tuple and list items, mapping values)."""
    out = {} if out is None else out
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out[f"{path}:class"] = type(obj).__name__
        for f in dataclasses.fields(obj):
            state_leaves(getattr(obj, f.name), f"{path}.{f.name}", out)
    elif isinstance(obj, (tuple, list)):
        out[f"{path}:len"] = len(obj)
        for i, v in enumerate(obj):
            state_leaves(v, f"{path}[{i}]", out)
    elif isinstance(obj, dict):
        for k in sorted(obj, key=repr):
            state_leaves(obj[k], f"{path}[{k!r}]", out)
    else:
        out[path] = obj
    return out


def _equal(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
            return False
        if a.shape != b.shape or a.dtype != b.dtype:
            return False
        nan = a.dtype.kind in "fc"
        return bool(np.array_equal(a, b, equal_nan=nan))
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return a is b


def same_leaves(a, b) -> str | None:
    """``None`` where two states are equal leaf for leaf (arrays: shape, dtype and every value, NaN equal to NaN),
    else the first difference in words."""
    la, lb = state_leaves(a), state_leaves(b)
    if la.keys() != lb.keys():
        return f"different fields: {sorted(set(la) ^ set(lb))}"
    for key in la:
        if not _equal(la[key], lb[key]):
            va, vb = la[key], lb[key]
            sa = f"{va.shape} {va.dtype}" if isinstance(va, np.ndarray) else repr(va)
            sb = f"{vb.shape} {vb.dtype}" if isinstance(vb, np.ndarray) else repr(vb)
            return f"{key} differs ({sa} against {sb})"
    return None


# -- 1. the contract ---------------------------------------------------------------------------------------------


def _contract_state(spec: FilterSpec, seed: int):
    """A state of ``B = 4`` items after init, predict and an update that measures items 1 and 3."""
    B = 4
    motion, model = _motion(), _model(spec)
    rng = generator(seed, "kit-contract")
    mean = np.array([300.0, 200.0, -3.0, 4.0]) + rng.normal(0.0, 5.0, (B, 4)) * [1, 1, 0.2, 0.2]
    prior = Gaussian(mean, np.broadcast_to(np.diag([4.0, 4.0, 1.0, 1.0]), (B, 4, 4)).copy())
    state = spec.init(prior, rng)
    state = spec.predict(state, motion, rng)
    truth = mean @ motion.F.T
    z = model.h(truth + rng.normal(0.0, 0.5, truth.shape) * [1, 1, 0, 0])
    valid = np.array([False, True, False, True])[:, None]
    state = spec.update(state, Scan(z[:, None, :], valid), model, rng)
    return state, motion, model, z, rng


def _estimate_at(spec: FilterSpec, state, B: int, n: int, what: str) -> Gaussian:
    est = spec.estimate(state)
    if est.mean.shape != (B, n) or est.cov.shape != (B, n, n):
        raise AssertionError(f"{what}: the estimate has shapes {est.mean.shape}, {est.cov.shape}; expected "
                             f"{(B, n)}, {(B, n, n)}")
    return est


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal up to the rounding of a computation repeated on a different batch (1e-12 of the values' scale)."""
    scale = max(1.0, float(np.max(np.abs(b))) if b.size else 1.0)
    return bool(np.all(np.abs(a - b) <= 1e-12 * scale))


def check_contract(spec: FilterSpec, seed: int = 0) -> str:
    state, motion, model, z, rng = _contract_state(spec, seed)
    spec.require_batch_contract(state, "the filter kit")
    B, n = 4, 4
    full = _estimate_at(spec, state, B, n, "the state")
    whole = spec.take_items(state, np.arange(B))
    diff = same_leaves(whole, state)
    if diff:
        raise AssertionError(f"take(state, all items) is not the state: {diff}")
    a, b = np.array([3, 0]), np.array([2])
    joined = spec.join_items([spec.take_items(state, a), spec.take_items(state, b)])
    diff = same_leaves(joined, spec.take_items(state, np.concatenate([a, b])))
    if diff:
        raise AssertionError(f"join(take(s, [3, 0]), take(s, [2])) is not take(s, [3, 0, 2]): {diff}")
    idx = np.array([3, 1])
    part = spec.take_items(state, idx)
    est = _estimate_at(spec, part, 2, n, "take(s, [3, 1])")
    if not (_close(est.mean, full.mean[idx]) and _close(est.cov, full.cov[idx])):
        raise AssertionError("the estimate of take(s, [3, 1]) is not the state's estimate at items 3 and 1")
    # a taken and a joined state go on: predict, then an update that measures the first item
    stochastic = "stochastic" in spec.capabilities
    whole_next = None if stochastic else spec.predict(state, motion, rng)
    for what, sub, items in (("take(s, [3, 1])", part, idx), ("the join", joined, np.array([3, 0, 2]))):
        try:
            nxt = spec.predict(sub, motion, rng)
            _estimate_at(spec, nxt, items.size, n, f"predict of {what}")
            valid = (np.arange(items.size) == 0)[:, None]
            upd = spec.update(nxt, Scan(z[items][:, None, :], valid), model, rng)
            _estimate_at(spec, upd, items.size, n, f"update of {what}")
        except AssertionError:
            raise
        except Exception as exc:  # noqa: BLE001 - the point of the check: name what broke, in one line
            raise AssertionError(f"{what} does not go on through predict and update: "
                                 f"{type(exc).__name__}: {exc}") from None
        if whole_next is not None:
            mine, ref = spec.estimate(nxt), spec.estimate(whole_next)
            if not (_close(mine.mean, ref.mean[items]) and _close(mine.cov, ref.cov[items])):
                raise AssertionError(f"predict of {what} differs from the whole batch's prediction at its items")
    return "take all = state, join(take a, take b) = take(a + b) exactly; taken and joined states go on"


# -- 2. under the M-of-N tracker ---------------------------------------------------------------------------------


def tracker_scene(seed: int = 0, runs: int = 1) -> tuple[Scans, np.ndarray, np.ndarray]:
    """The check's scene: Cartesian detections of targets A and B (``Scans`` with ``z (runs, 12, 2, 2)``), A's and
    B's true positions ``(12, 2)`` each.  A's detection is missing at ping :data:`A_MISS`; B's exist from
    :data:`B_FIRST` to :data:`B_LAST`."""
    k = np.arange(float(SCENE_PINGS))[:, None]
    a = np.array([300.0, 200.0]) + k * [3.0, -2.0]
    b = np.array([150.0, 320.0]) + k * [-2.0, 3.0]
    rng = generator(seed, "kit-tracker-scene")
    z = np.stack([a, b], axis=1)[None] + rng.normal(0.0, 0.5, (runs, SCENE_PINGS, 2, 2))
    valid = np.ones((runs, SCENE_PINGS, 2), dtype=bool)
    valid[:, A_MISS, 0] = False
    valid[:, :B_FIRST, 1] = False
    valid[:, B_LAST + 1:, 1] = False
    z = np.where(valid[..., None], z, 0.0)
    return Scans(z, valid, k[:, 0]), a, b


def check_mofn(spec: FilterSpec, seed: int = 0) -> str:
    from ..tracking import CONFIRMED, run_tracker

    scans, a, b = tracker_scene(seed)
    log = run_tracker(scans, spec, _motion(), _model(spec), seed=seed, key=("kit-trackers",))
    last = SCENE_PINGS - 1

    def confirmed_near(ping, target):
        rows = (log.ping == ping) & (log.status == CONFIRMED)
        d = np.linalg.norm(log.mean[rows, :2] - target[ping], axis=1)
        return log.track_id[rows][d <= NEAR], (float(d.min()) if d.size else np.inf)

    a_ids = [confirmed_near(p, a)[0] for p in (A_MISS - 1, A_MISS, last)]
    if not all(ids.size == 1 for ids in a_ids) or len({int(ids[0]) for ids in a_ids}) != 1:
        raise AssertionError(f"target A is not held by one confirmed track within {NEAR} units through its missed "
                             f"detection at ping {A_MISS} to ping {last} (tracks near A at pings {A_MISS - 1}, "
                             f"{A_MISS}, {last}: {[ids.tolist() for ids in a_ids]}; nearest confirmed at the end "
                             f"{confirmed_near(last, a)[1]:.3g} units away)")
    a_id = int(a_ids[0][0])
    miss = (log.ping == A_MISS) & (log.track_id == a_id)
    if log.hit[miss].any():
        raise AssertionError(f"the track of target A reports a hit at ping {A_MISS}, where A has no detection")
    b_ids, dist = confirmed_near(B_LAST, b)
    if b_ids.size != 1:
        raise AssertionError(f"target B is not held by one confirmed track within {NEAR} units at ping {B_LAST} "
                             f"(nearest confirmed {dist:.3g} units away)")
    alive = np.unique(log.track_id[log.ping == last])
    if int(b_ids[0]) in alive.tolist():
        raise AssertionError(f"the track of target B (last detected at ping {B_LAST}) is still alive at ping {last}")
    extra = np.setdiff1d(log.track_id[(log.ping == last) & (log.status == CONFIRMED)], [a_id])
    if extra.size:
        raise AssertionError(f"confirmed tracks other than A's at ping {last}: {extra.tolist()}")
    return (f"M-of-N: A held through its miss ({confirmed_near(last, a)[1]:.2f} units off at the end), B's track "
            f"joined, confirmed ({dist:.2f} units off) and deleted")


# -- 3. under every built-in tracker ----------------------------------------------------------------------------

#: Pings at which every tracker that takes the filter must hold each target: A before its miss and at B's last
#: detection, B at its last detection (after B's track joined A's, before B's deletion).
HELD_PINGS = {"A": (A_MISS - 1, B_LAST), "B": (B_LAST,)}

#: The filter capabilities a tracker may refuse a filter for, each with whether the filter must have it (True:
#: ``stochastic``, a filter that draws random numbers where the tracker moment-matches or batches a mixture) or lack
#: it (False: ``gaussian``).
_REFUSAL_WORDS = {"gaussian": False, "stochastic": True}


def builtin_trackers() -> dict:
    """The built-in trackers (distribution ``workbench``), by name: ``mofn``, ``gnn``, ``jipda``, ``jpda``,
    ``gm-phd``.  An installed third-party tracker is left out (the filter kit must not depend on what else is
    installed; a tracker has its own kit, :func:`workbench.testing.run_tracker_checks`)."""
    from ..plugins import BUILTIN_DISTRIBUTION, load_host

    host = load_host()
    return {name: spec for name, spec in host.trackers.items()
            if host.plugin_of("workbench_trackers", name).distribution == BUILTIN_DISTRIBUTION}


def _scene_for(tracker, model, scans: Scans) -> Scans:
    """The scene's detections as the tracker declares it takes them: Cartesian ``(x, y)`` for a tracker with the
    ``cartesian_2d`` capability, else in the measurement model's own frame (``h`` of the detection's position)."""
    if "cartesian_2d" in tracker.capabilities or model.frame == "cartesian-2d":
        return scans
    x = np.zeros(scans.z.shape[:-1] + (4,))
    x[..., :2] = scans.z
    z = model.h(x.reshape(-1, 4)).reshape(scans.z.shape[:-1] + (model.dim,))
    return Scans(np.where(scans.valid[..., None], z, 0.0), scans.valid, scans.times)


def _refusal_names_capability(spec: FilterSpec, message: str) -> str | None:
    """The capability a refusal names that the filter lacks, or has and the tracker cannot take (``None``: the
    refusal names no such capability).  The measurement model the kit builds for a ``range_bearing_input`` filter
    (no ``H``) counts as that capability where the refusal names the model."""
    low = message.lower()
    for word, has in _REFUSAL_WORDS.items():
        if word in low and (word in spec.capabilities) == has:
            return word
    if "range_bearing_input" in spec.capabilities and repr(_model(spec).name) in message:
        return "range_bearing_input"
    return None


def check_each_tracker(spec: FilterSpec, seed: int = 0) -> str:
    """The filter under every built-in tracker but M-of-N (which :func:`check_mofn` holds to more) on the scene of
    :func:`tracker_scene`: a valid track log (:func:`workbench.testing.trackers.check_log`) in which each of A and B
    is held by exactly one confirmed track within :data:`NEAR` at its pings of :data:`HELD_PINGS`; or a refusal by
    ``InputError`` that names the filter's capability it refuses for."""
    from ..tracking import CONFIRMED
    from .trackers import check_log

    base, a, b = tracker_scene(seed)
    motion, model = _motion(), _model(spec)
    ran, refused = [], []
    for name, tracker in sorted(builtin_trackers().items()):
        if name == "mofn":
            continue
        scans = _scene_for(tracker, model, base)
        try:
            log = tracker.run(scans, spec, motion, model, seed=seed, key=("kit-trackers", name))
        except InputError as exc:
            word = _refusal_names_capability(spec, str(exc))
            if word is None:
                raise AssertionError(f"tracker {name!r} refused filter {spec.name!r} without naming a capability "
                                     f"the filter lacks (or has and the tracker cannot take): {exc}") from None
            refused.append(f"{name} ({word})")
            continue
        except Exception as exc:  # noqa: BLE001 - the point of the check: name what broke, in one line
            raise AssertionError(f"tracker {name!r} broke on filter {spec.name!r}: {type(exc).__name__}: {exc}") \
                from None
        problems = check_log(log, 1, SCENE_PINGS, 4, tracker.capabilities, f"the log of tracker {name!r}")
        if problems:
            raise AssertionError("; ".join(problems))
        for label, target in (("A", a), ("B", b)):
            for ping in HELD_PINGS[label]:
                rows = (log.ping == ping) & (log.status == CONFIRMED)
                d = np.linalg.norm(log.mean[rows, :2] - target[ping], axis=1)
                if int(np.sum(d <= NEAR)) != 1:
                    raise AssertionError(f"under tracker {name!r}, target {label} is not held by exactly one "
                                         f"confirmed track within {NEAR} units at ping {ping} ({int(np.sum(d <= NEAR))}"
                                         f" such tracks; nearest {float(d.min()) if d.size else np.inf:.3g} units)")
        ran.append(name)
    return (f"under {', '.join(ran) or 'no other tracker'}: A held at pings {HELD_PINGS['A']}, B at {HELD_PINGS['B']}"
            + (f"; refused by name: {', '.join(refused)}" if refused else ""))


def check_under_trackers(spec: FilterSpec) -> str:
    """The filter-state contract: take / join exact on a batch of 4 (= n) items, the filter under the M-of-N
    tracker through a join, a missed detection and a deletion, and under every other built-in tracker (GNN, JIPDA,
    JPDA, GM-PHD) holding both targets, or refused by name for a capability."""
    try:
        first = check_contract(spec)
        second = check_mofn(spec)
    except InputError as exc:
        raise AssertionError(str(exc)) from None
    third = check_each_tracker(spec)
    return f"{first}; {second}; {third}"
