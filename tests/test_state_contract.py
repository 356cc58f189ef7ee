"""The filter-state contract (issue 25, item 5): how a tracker takes and joins the batch items of a filter's state.

A filter declares it (``FilterSpec.take`` / ``FilterSpec.join``, or ``batch_fields`` on its state's class); the
M-of-N tracker uses the declaration and never guesses the batch axis from an array's length.  The references here
are a plain hand-written slicing of each declared array, the built-in Kalman filter (which a mode-first fixture
filter of two identical modes must equal), and the length-guessing take / join the tracker used before (written out
below as ``guessing_take`` / ``guessing_join``), which breaks the CRPF at K = n live tracks.
"""

import copy
import dataclasses
from dataclasses import dataclass, replace

import numpy as np
import pytest

from workbench.kalman_core import kf_update, linear_predict
from workbench.models import constant_velocity, range_bearing
from workbench.particle_core import ParticleState
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.specs import FilterSpec, batch_size, join_batch, take_batch
from workbench.testing.trackers_check import (check_under_trackers, same_leaves, state_leaves, tracker_scene,
                                              under_trackers_applies)
from workbench.tracking import CONFIRMED, run_tracker
from workbench.types import Gaussian, InputError, Particles, Scan, Scans

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.05)


# -- the length-guessing take / join the tracker used before (the bug, kept as a reference) ---------------------


def _replaced(obj, changes):
    out = copy.copy(obj)
    for name, value in changes.items():
        object.__setattr__(out, name, value)
    return out


def guessing_take(state, index, batch):
    """The old ``take_items``: every array whose leading axis equals ``batch`` is sliced."""
    if isinstance(state, np.ndarray):
        return state[index] if state.ndim and state.shape[0] == batch else state
    if dataclasses.is_dataclass(state):
        return _replaced(state, {f.name: guessing_take(getattr(state, f.name), index, batch)
                                 for f in dataclasses.fields(state) if f.init})
    return state


def guessing_join(a, b, batch_a, batch_b):
    """The old ``join_items``: arrays whose leading axes equal the two batch sizes are concatenated."""
    if isinstance(a, np.ndarray):
        if a.ndim and a.shape[0] == batch_a and isinstance(b, np.ndarray) and b.ndim and b.shape[0] == batch_b:
            return np.concatenate([a, b], axis=0)
        return a
    if dataclasses.is_dataclass(a):
        return _replaced(a, {f.name: guessing_join(getattr(a, f.name), getattr(b, f.name), batch_a, batch_b)
                             for f in dataclasses.fields(a) if f.init})
    return a


def _guessing(spec: FilterSpec, items) -> FilterSpec:
    """``spec`` with the old length-guessing take / join (``items(state)``: the batch size the tracker knew)."""
    return replace(spec, take=lambda s, idx: guessing_take(s, idx, items(s)),
                   join=lambda states: guessing_join(states[0], states[1], items(states[0]), items(states[1])))


# -- the CRPF at K = n live tracks --------------------------------------------------------------------------------


def _four_targets(seed=3):
    """Four targets over 12 pings in Cartesian detections; D last seen at ping 5 (deleted at ping 8 after three
    misses) and A missing at ping 8, the same ping: the deletion takes 3 of 4 items while A's item is pending."""
    T = 12
    k = np.arange(float(T))[:, None]
    starts = np.array([[300.0, 200.0], [150.0, 320.0], [-250.0, 180.0], [60.0, -330.0]])
    vel = np.array([[3.0, -2.0], [-2.0, 3.0], [2.5, 2.0], [-3.0, -1.5]])
    truth = starts[None] + k[:, :, None] * vel[None]  # (T, 4, 2)
    z = truth[None] + generator(seed, "four").normal(0.0, 0.5, (1, T, 4, 2))
    valid = np.ones((1, T, 4), dtype=bool)
    valid[0, 6:, 3] = False  # D gone after ping 5
    valid[0, 8, 0] = False  # A missed at ping 8
    return Scans(np.where(valid[..., None], z, 0.0), valid, k[:, 0]), truth


def _crpf_under_mofn(spec):
    scans, truth = _four_targets()
    return run_tracker(scans, spec, MOTION, range_bearing(1.0, 0.004), seed=5), truth


def test_crpf_at_k_equals_n_runs_under_mofn():
    crpf = HOST.filter("crpf-100")
    log, truth = _crpf_under_mofn(crpf)
    assert crpf.take is None and crpf.join is None  # through the declared batch_fields of its state
    c = log.status == CONFIRMED
    alive7 = log.track_id[(log.ping == 7) & c]
    alive8 = log.track_id[log.ping == 8]
    assert alive7.size == 4 and alive8.size == 3  # four live tracks (K = n = 4), one deleted at ping 8
    last = log.ping == 11
    assert np.sum(last & c) == 3
    for j in range(3):  # A, B, C held to the end, each by one confirmed track near it
        d = np.linalg.norm(log.mean[last & c, :2] - truth[11, j], axis=1)
        assert np.sum(d < 6.0) == 1, (j, d)
    a8 = (log.ping == 8) & c
    a_id = log.track_id[a8][np.argmin(np.linalg.norm(log.mean[a8, :2] - truth[8, 0], axis=1))]
    assert not log.hit[(log.ping == 8) & (log.track_id == a_id)].any()  # A's miss, same ping as D's deletion
    assert a_id in log.track_id[last]


def test_the_length_guessing_take_broke_the_crpf_at_k_equals_n():
    """The same scene with the tracker's old take / join: the CRPF's (4, 4) motion matrix of the pending prediction
    is cut to (3, 4) at the deletion, and the next predict (A's blind move) raises."""
    broken = _guessing(HOST.filter("crpf-100"), lambda s: s.pending.shape[0])
    with pytest.raises(ValueError, match="matmul|shapes|dimension"):
        _crpf_under_mofn(broken)


def test_crpf_take_keeps_the_shared_motion_matrix_whole():
    crpf = HOST.filter("crpf-100")
    rng = generator(8, "crpf take")
    model = range_bearing(1.0, 0.004)
    mean = np.array([[300.0, 200.0, 3, -2], [150, 320, -2, 3], [-250, 180, 2.5, 2], [60, -330, -3, -1.5]])
    state = crpf.init(Gaussian(mean, np.broadcast_to(np.diag([4.0, 4, 1, 1]), (4, 4, 4)).copy()), rng)
    state = crpf.update(state, Scan(model.h(mean)[:, None], np.ones((4, 1), bool)), model, rng)
    state = crpf.predict(state, MOTION, rng)
    valid = np.array([[False], [True], [True], [False]])
    state = crpf.update(state, Scan(model.h(mean @ MOTION.F.T)[:, None], valid), model, rng)
    assert state.F.shape == (4, 4) and state.pending.tolist() == [True, False, False, True]
    part = crpf.take_items(state, np.array([0, 1, 2]))
    assert part.F is state.F and part.selections == state.selections
    for name in ("particles", "costs", "variances", "steps", "pending"):  # hand-written slicing of each array
        assert np.array_equal(getattr(part, name), getattr(state, name)[:3]), name
    assert np.array_equal(part.belief.mean, state.belief.mean[:3])
    moved = crpf.predict(part, MOTION, rng)  # item 0's blind move uses the whole F
    assert crpf.estimate(moved).mean.shape == (3, 4)


# -- every built-in: round trip of take / join -----------------------------------------------------------------


def _builtin_names():
    return sorted(n for n in HOST.filters
                  if HOST.plugin_of("workbench_filters", n).module.startswith("workbench_filters."))


@pytest.mark.parametrize("name", [n for n in _builtin_names() if "position_doppler_3d" in HOST.filter(n).capabilities
                                  or not under_trackers_applies(HOST.filter(n))])
def test_take_join_round_trip_of_filters_the_tracker_check_skips(name):
    """The kit's check_under_trackers covers the 2-D filters (plugins/filters/tests/test_kit_builtin.py); the
    others (the 3-D TBD filter) get the exact round trip here, on a predicted state of 4 items."""
    spec = HOST.filter(name)
    rng = generator(9, "round trip", name)
    n = 6
    prior = Gaussian(rng.normal(0, 100.0, (4, n)) + [30e3, 5e3, 3e3, -200, 0, 0],
                     np.broadcast_to(np.diag([200.0**2] * 3 + [10.0**2] * 3), (4, n, n)).copy())
    state = spec.predict(spec.init(prior, rng), constant_velocity(3, 1.0, 2.0), rng)
    spec.require_batch_contract(state)
    assert same_leaves(spec.take_items(state, np.arange(4)), state) is None
    joined = spec.join_items([spec.take_items(state, [3, 0]), spec.take_items(state, [2])])
    assert same_leaves(joined, spec.take_items(state, [3, 0, 2])) is None
    est, whole = spec.estimate(spec.take_items(state, [1, 3])), spec.estimate(state)
    np.testing.assert_allclose(est.mean, whole.mean[[1, 3]], rtol=1e-12)


def test_every_builtin_filter_declares_the_contract_and_the_kit_runs_it_under_the_tracker():
    from workbench.testing import checks_for

    names = _builtin_names()
    assert len(names) >= 12
    for name in names:
        spec = HOST.filter(name)
        ran = "check_under_trackers" in {c.name for c in checks_for(spec)}
        assert ran == ("position_doppler_3d" not in spec.capabilities), name


def test_sir_jm_join_mixes_mode_and_plain_particle_states_exactly():
    spec = HOST.filter("sir-jm")
    rng = generator(10, "sir-jm join")
    prior = Gaussian(rng.normal(0, 10.0, (3, 4)), np.broadcast_to(np.eye(4), (3, 4, 4)).copy())
    fresh = spec.init(prior, rng)  # a ParticleState: every particle quiet
    moved = spec.predict(spec.init(prior, rng), MOTION, rng)  # a ModeState
    assert type(fresh) is ParticleState and moved.mode is not None
    joined = spec.join_items([moved, fresh])
    # the plain reference: modes of the moved items, then zeros (quiet) for the fresh ones
    assert np.array_equal(joined.mode, np.concatenate([moved.mode, np.zeros(fresh.cloud.log_weights.shape)]))
    assert np.array_equal(joined.cloud.particles, np.concatenate([moved.cloud.particles, fresh.cloud.particles]))
    with pytest.raises(InputError, match="different classes"):
        join_batch([moved, fresh])  # without the filter's own join: refused by name, not guessed


# -- a mode-first filter, declared; and one that declares nothing -----------------------------------------------


@dataclass(frozen=True)
class ModeFirstState:
    """Per mode ``j``: ``means[j] (B, n)``, ``covs[j] (B, n, n)``, i.e. arrays ``(r, B, ...)``, mode first."""

    means: np.ndarray
    covs: np.ndarray


R_MODES = 2


def _mf_init(prior, rng=None):
    return ModeFirstState(np.stack([prior.mean] * R_MODES), np.stack([prior.cov] * R_MODES))


def _mf_predict(state, motion, rng=None):
    out = [linear_predict(Gaussian.trusted(m, c), motion, "mode-first") for m, c in zip(state.means, state.covs)]
    return ModeFirstState(np.stack([g.mean for g in out]), np.stack([g.cov for g in out]))


def _mf_update(state, scan, model, rng=None):
    out = [kf_update(Gaussian.trusted(m, c), scan, model) for m, c in zip(state.means, state.covs)]
    return ModeFirstState(np.stack([g.mean for g in out]), np.stack([g.cov for g in out]))


def _mf_estimate(state):
    """The mixture's moments with equal mode probabilities."""
    w = 1.0 / R_MODES
    mean = sum(w * m for m in state.means)
    cov = sum(w * (c + (m - mean)[..., :, None] * (m - mean)[..., None, :]) for m, c in zip(state.means, state.covs))
    return Gaussian.trusted(mean, cov)


def _mf_take(state, index):
    return ModeFirstState(state.means[:, index], state.covs[:, index])


def _mf_join(states):
    return ModeFirstState(np.concatenate([s.means for s in states], axis=1),
                          np.concatenate([s.covs for s in states], axis=1))


MODE_FIRST = FilterSpec("mode-first", "two identical Kalman modes stored mode first", _mf_init, _mf_predict,
                        _mf_update, _mf_estimate, frozenset({"gaussian", "linear_only"}), take=_mf_take,
                        join=_mf_join)
BARE = replace(MODE_FIRST, name="mode-first-bare", take=None, join=None)


def test_a_mode_first_filter_declared_properly_equals_the_kalman_filter_under_mofn():
    """Two identical modes: the mixture is the Kalman filter, so the tracks must be the KF's, ping by ping; at two
    live tracks (r = K = 2) the length-guessing take would have cut the mode axis."""
    scans, _, _ = tracker_scene(seed=4, runs=2)
    model = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=1.0)
    mine = run_tracker(scans, MODE_FIRST, MOTION, model, seed=6)
    ref = run_tracker(scans, HOST.filter("kf"), MOTION, model, seed=6)
    for key, value in ref.to_arrays().items():
        np.testing.assert_allclose(mine.to_arrays()[key], value, rtol=1e-12, atol=1e-9, err_msg=key)
    assert np.any(np.diff(np.bincount(mine.ping[mine.run == 0])) < 0)  # a deletion
    broken = _guessing(MODE_FIRST, lambda s: s.means.shape[1])
    with pytest.raises((ValueError, IndexError)):
        run_tracker(scans, broken, MOTION, model, seed=6)


def test_the_kit_check_passes_the_declared_mode_first_filter_and_fails_guessing():
    assert "take all" in check_under_trackers(MODE_FIRST)
    with pytest.raises(AssertionError, match="'mode-first-bare'.*batch_fields"):
        check_under_trackers(BARE)
    with pytest.raises(AssertionError):
        check_under_trackers(_guessing(HOST.filter("crpf-100"), lambda s: s.pending.shape[0]))


def test_a_filter_declaring_nothing_is_refused_by_name():
    scans, _, _ = tracker_scene(seed=4)
    model = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=1.0)
    with pytest.raises(InputError, match=r"M-of-N tracker: filter 'mode-first-bare' does not declare .*batch_fields"):
        run_tracker(scans, BARE, MOTION, model)
    half = replace(MODE_FIRST, name="half", join=None)
    with pytest.raises(InputError, match="filter 'half' gives FilterSpec.take without FilterSpec.join"):
        run_tracker(scans, half, MOTION, model)


# -- take_batch / join_batch themselves ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Tree:
    cloud: Particles
    flags: np.ndarray
    shared: np.ndarray
    note: str = "kept"
    extra: np.ndarray | None = None

    batch_fields = ("cloud", "flags", "extra")


def _tree(B, seed):
    rng = generator(seed, "tree")
    return Tree(Particles(rng.normal(size=(B, 5, 4)), np.full((B, 5), -np.log(5))), rng.random(B) < 0.5,
                np.arange(16.0).reshape(4, 4))


def test_take_and_join_follow_the_declaration_only():
    a, b = _tree(4, 1), _tree(2, 2)  # 4 items and a (4, 4) shared matrix: only the declaration tells them apart
    assert batch_size(a) == 4 and batch_size(b) == 2
    t = take_batch(a, np.array([3, 1]))
    assert np.array_equal(t.cloud.particles, a.cloud.particles[[3, 1]]) and np.array_equal(t.flags, a.flags[[3, 1]])
    assert t.shared is a.shared and t.note == "kept" and t.extra is None
    j = join_batch([a, b])
    assert np.array_equal(j.cloud.log_weights, np.concatenate([a.cloud.log_weights, b.cloud.log_weights]))
    assert np.array_equal(j.flags, np.concatenate([a.flags, b.flags])) and j.shared is a.shared
    assert same_leaves(take_batch(j, np.arange(6)), j) is None
    assert same_leaves(join_batch([take_batch(j, [5, 0]), take_batch(j, [2])]), take_batch(j, [5, 0, 2])) is None
    assert "state.cloud.particles" in state_leaves(j)


def test_take_and_join_refuse_what_does_not_hold_by_name():
    a = _tree(4, 1)
    with pytest.raises(InputError, match="different leading lengths"):
        batch_size(replace(a, flags=np.zeros(3, bool)))
    with pytest.raises(InputError, match="None in some states"):
        join_batch([a, replace(a, extra=np.zeros(4))])
    with pytest.raises(InputError, match="1-D integer"):
        take_batch(a, np.array([0.5]))
    with pytest.raises(InputError, match="out of range"):
        take_batch(a, np.array([4]))

    @dataclass(frozen=True)
    class Typo:
        mean: np.ndarray
        batch_fields = ("means",)

    with pytest.raises(InputError, match=r"Typo declares batch_fields \['means'\]"):
        take_batch(Typo(np.zeros((2, 4))), [0])

    @dataclass(frozen=True)
    class Plain:
        mean: np.ndarray

    with pytest.raises(InputError, match="Plain declares no batch_fields"):
        take_batch(Plain(np.zeros((2, 4))), [0])
