"""Several objects per run (workbench.truth) and their detections (workbench.sensing.detect_objects), held to
closed forms (straight constant-velocity paths), binomial and Poisson bounds with fixed seeds, and the geometry of
the noise-free measurements."""

import numpy as np
import pytest

from workbench.models import constant_velocity
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.sensing import detect_objects
from workbench.truth import BirthProcess, MultiTruth, ObjectSpec, simulate_objects
from workbench.types import CLUTTER, InputError, Truth


@pytest.fixture(scope="module")
def host():
    return load_host()


def test_listed_targets_live_over_their_intervals_on_their_own_motion():
    still = constant_velocity(2, 1.0, 0.0)  # no process noise: straight lines, p_k = p_first + v (t_k - t_first)
    noisy = constant_velocity(2, 1.0, 2.0)
    targets = [ObjectSpec([0.0, 0.0, 2.0, -1.0]),
               ObjectSpec([100.0, 50.0, -1.0, 3.0], first=4, last=9, motion=noisy),
               ObjectSpec([-30.0, 10.0, 0.5, 0.5], first=7)]
    truth = simulate_objects(targets, runs=3, steps=15, motion=still, seed=5, t0=2.0)
    assert truth.states.shape == (3, 15, 3, 4)
    np.testing.assert_allclose(truth.times, 2.0 + np.arange(15))
    for k, (first, last) in enumerate([(0, 14), (4, 9), (7, 14)]):
        expect = np.zeros(15, dtype=bool)
        expect[first:last + 1] = True
        assert np.array_equal(truth.alive[:, :, k], np.broadcast_to(expect, (3, 15)))
        assert np.isnan(truth.states[:, ~expect, k]).all()
    for k, first in ((0, 0), (2, 7)):  # the default (noise-free) model: the closed form, to rounding
        x0 = targets[k].initial_state
        t = np.arange(first, 15) - first
        straight = np.column_stack([x0[0] + x0[2] * t, x0[1] + x0[3] * t])
        np.testing.assert_allclose(truth.states[:, first:, k, :2], np.broadcast_to(straight, (3,) + straight.shape),
                                   atol=1e-9)
    # target 1 moves on its own (noisy) model: its velocity changes from scan to scan
    v = truth.states[:, 4:10, 1, 2:]
    assert np.all(np.abs(np.diff(v, axis=1)) > 0)
    np.testing.assert_allclose(truth.states[:, 4, 1], np.broadcast_to(targets[1].initial_state, (3, 4)))


def test_birth_process_counts_region_velocities_and_survival():
    motion = constant_velocity(2, 1.0, 0.0)
    births = BirthProcess(rate=0.1, region=[(0.0, 100.0), (-50.0, 50.0)], velocity_std=[2.0, 3.0], max_objects=20,
                          velocity_mean=[1.0, 0.0], survival=0.9)
    runs, steps = 200, 40
    truth = simulate_objects(births=births, runs=runs, steps=steps, motion=motion, seed=3, key=("t",))
    born = truth.alive.any(axis=1)  # (B, K): slots used
    starts = np.argmax(truth.alive, axis=1)
    n_births = int(born.sum())
    mean = 0.1 * runs * (steps - 1)  # Poisson(rate) births per scan from scan 1 on
    assert abs(n_births - mean) <= 5 * np.sqrt(mean)
    assert not truth.alive[:, 0].any()
    b, k = np.nonzero(born)
    x = truth.states[b, starts[b, k], k]
    assert np.all((x[:, 0] >= 0) & (x[:, 0] <= 100) & (x[:, 1] >= -50) & (x[:, 1] <= 50))
    # velocity: N(mean, std^2) per axis -> the sample mean within 5 standard errors, the variance by chi-square
    for axis, (mu, sd) in enumerate(((1.0, 2.0), (0.0, 3.0))):
        v = x[:, 2 + axis]
        assert abs(v.mean() - mu) <= 5 * sd / np.sqrt(v.size)
        assert abs(v.var(ddof=1) / sd ** 2 - 1) <= 5 * np.sqrt(2 / (v.size - 1))
    # lifetime: geometric, P(L = l) = 0.9^(l-1) 0.1, cut at the run's end; compare the uncut ones' mean with the
    # truncated geometric's mean computed in closed form per birth scan
    life = truth.alive.sum(axis=1)[b, k]
    room = steps - starts[b, k]
    s = 0.9
    expect = np.array([sum(l * s ** (l - 1) * (1 - s) for l in range(1, r)) + r * s ** (r - 1) for r in room])
    var = np.array([sum(l * l * s ** (l - 1) * (1 - s) for l in range(1, r)) + r * r * s ** (r - 1) for r in room])
    var -= expect ** 2
    assert abs(life.sum() - expect.sum()) <= 5 * np.sqrt(var.sum())


def test_birth_process_refuses_more_births_than_max_objects_by_name():
    births = BirthProcess(rate=2.0, region=[(0.0, 1.0), (0.0, 1.0)], velocity_std=1.0, max_objects=3)
    with pytest.raises(InputError, match="max_objects = 3"):
        simulate_objects(births=births, runs=2, steps=10, motion=constant_velocity(2, 1.0, 0.1), seed=0)


def test_same_seed_same_objects_and_targets_keep_their_streams():
    motion = constant_velocity(2, 1.0, 0.5)
    a = [ObjectSpec([0.0, 0.0, 1.0, 1.0])]
    one = simulate_objects(a, runs=2, steps=8, motion=motion, seed=9)
    two = simulate_objects(a + [ObjectSpec([5.0, 5.0, 0.0, 0.0])], runs=2, steps=8, motion=motion, seed=9)
    again = simulate_objects(a, runs=2, steps=8, motion=motion, seed=9)
    assert np.array_equal(one.states, again.states)
    assert np.array_equal(one.states[:, :, 0], two.states[:, :, 0])  # adding a target does not move the first
    twins = simulate_objects(a + a, runs=2, steps=8, motion=motion, seed=9)  # same start, own streams: apart
    assert np.all(twins.states[:, 1:, 0] != twins.states[:, 1:, 1])
    other = simulate_objects(a, runs=2, steps=8, motion=motion, seed=10)
    assert not np.array_equal(one.states, other.states)


def test_multi_truth_refuses_a_second_life_and_a_nan_live_state():
    states = np.zeros((1, 4, 1, 4))
    with pytest.raises(InputError, match="born more than once"):
        MultiTruth(states, np.array([True, False, True, True])[None, :, None], np.arange(4.0))
    states[0, 1, 0, 2] = np.nan
    with pytest.raises(InputError, match="NaN or inf for a live object"):
        MultiTruth(states, np.ones((1, 4, 1), bool), np.arange(4.0))


def _scene(runs=60, steps=40):
    motion = constant_velocity(2, 1.0, 0.02)
    targets = [ObjectSpec([0.0, 0.0, 1.0, 0.0], p_d=0.3), ObjectSpec([0.0, 300.0, 1.0, 0.0], p_d=0.6, first=5,
                                                                      last=30),
               ObjectSpec([300.0, 0.0, 0.0, 1.0], first=12)]
    return simulate_objects(targets, runs=runs, steps=steps, motion=motion, seed=21)


def test_detections_follow_each_objects_p_d_and_name_the_nearest_object(host):
    truth = _scene()
    sonar = host.sensor("active-sonar").configure(pd=0.9, sigma_pos=1.0)
    scans = detect_objects(sonar, truth, generator(21, "detect"))
    assert scans.z.shape[:2] == truth.alive.shape[:2]
    origin = scans.origin
    # births and deaths: no detection of an object where it is not alive
    for k in range(truth.objects):
        det = (scans.valid & (origin == k)).any(axis=2)
        assert not (det & ~truth.alive[:, :, k]).any()
    # every detection's origin is the live object whose noise-free position (the sensor's h) is nearest
    b, t, m = np.nonzero(scans.valid)
    pos = truth.states[b, t, :, :2]  # (D, K, 2), NaN where not alive
    d = np.linalg.norm(scans.z[b, t, m][:, None, :] - pos, axis=-1)
    d = np.where(truth.alive[b, t], d, np.inf)
    assert np.array_equal(np.argmin(d, axis=1), origin[b, t, m])
    for k, p in enumerate((0.3, 0.6, 0.9)):  # the object's own p_d, else the sensor's
        live = int(truth.alive[:, :, k].sum())
        count = int((scans.valid & (origin == k)).sum())
        assert abs(count - live * p) <= 5 * np.sqrt(live * p * (1 - p)), (k, count, live * p)


def test_clutter_keeps_its_label_after_merging(host):
    truth = _scene(runs=4, steps=32)
    sonar = host.sensor("active-sonar")
    clutter = host.clutter_generator("uniform-clutter")
    rng = generator(1, "c")
    from workbench.types import Scans

    scans = Scans.merge_all([detect_objects(sonar, truth, rng), clutter.generate(truth.as_truth(), rng, rate=5.0)])
    m_obj = detect_objects(sonar, truth, generator(1, "c")).z.shape[2]
    assert np.all(scans.origin[..., m_obj:][scans.valid[..., m_obj:]] == CLUTTER)
    assert set(np.unique(scans.origin[..., :m_obj][scans.valid[..., :m_obj]])) <= {0, 1, 2}


def test_an_objects_own_p_d_is_refused_by_name_for_a_sensor_without_pd(host):
    motion = constant_velocity(2, 1.0, 0.0)
    truth = simulate_objects([ObjectSpec([100.0, 100.0, 1.0, 0.0], p_d=0.5)], runs=1, steps=3, motion=motion, seed=0)
    with pytest.raises(InputError, match="range-bearing.*'pd'"):
        detect_objects(host.sensor("range-bearing"), truth, generator(0))
    single = Truth(np.zeros((1, 3, 4)), np.arange(3.0))
    with pytest.raises(InputError, match="MultiTruth"):
        detect_objects(host.sensor("range-bearing"), single, generator(0))
    # a single truth as one always-alive object: every detection labelled 0
    scans = detect_objects(host.sensor("range-bearing"), MultiTruth.from_truth(
        Truth(np.tile([100.0, 0.0, 1.0, 0.0], (2, 3, 1)), np.arange(3.0))), generator(0))
    assert np.all(scans.origin[scans.valid] == 0)


def test_no_object_alive_gives_empty_scans_of_the_sensors_dimension(host):
    births = BirthProcess(rate=0.0, region=[(0.0, 1.0), (0.0, 1.0)], velocity_std=1.0, max_objects=2)
    truth = simulate_objects(births=births, runs=2, steps=5, motion=constant_velocity(2, 1.0, 0.1), seed=0)
    assert not truth.alive.any()
    scans = detect_objects(host.sensor("range-bearing"), truth, generator(0))
    assert scans.z.shape[:2] == (2, 5) and scans.z.shape[3] == 2 and not scans.valid.any()
