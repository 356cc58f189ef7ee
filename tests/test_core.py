"""Records, linear algebra, models and random streams against independent references."""

import numpy as np
import pytest

from workbench.linalg import cholupdate, joseph_update, psd_solve, safe_cholesky, tria, wrap_angle
from workbench.models import (constant_velocity, random_walk_velocity, range_bearing, range_bearing_jacobian,
                              range_rate_model)
from workbench.rng import chunk_bounds, generator
from workbench.trajectory import Leg, piecewise_trajectory, sample_motion
from workbench.types import CLUTTER, Gaussian, InputError, Scan, Scans


# -- records ------------------------------------------------------------------------------------------

def test_gaussian_rejects_bad_shapes_and_nan():
    with pytest.raises(InputError, match="cov must have shape"):
        Gaussian(np.zeros((2, 3)), np.zeros((2, 2, 2)))
    with pytest.raises(InputError, match="non-finite value.*index \\(1, 0\\)"):
        Gaussian(np.array([[0.0, 0], [np.nan, 0]]), np.tile(np.eye(2), (2, 1, 1)))


def test_scan_masks_padding_and_rejects_nan_in_valid_rows():
    z = np.array([[[1.0, 2.0], [np.nan, np.nan]]])
    scan = Scan(z, np.array([[True, False]]))  # NaN padding is fine when masked
    assert np.array_equal(scan.z[0, 1], [0.0, 0.0]) and scan.counts.tolist() == [1]
    with pytest.raises(InputError, match="NaN or inf in a valid measurement at index \\(0, 1\\)"):
        Scan(z, np.array([[True, True]]))
    with pytest.raises(InputError, match="valid must have shape"):
        Scan(z, np.array([[True, True, True]]))


def test_scans_merge_slice_and_strip_origin():
    t = np.arange(3.0)
    a = Scans(np.ones((2, 3, 1, 2)), np.ones((2, 3, 1), bool), t, origin=np.zeros((2, 3, 1), int))
    b = Scans(np.zeros((2, 3, 4, 2)), np.ones((2, 3, 4), bool), t)
    both = a.merge(b)
    assert both.z.shape == (2, 3, 5, 2) and np.all(both.origin[..., 1:] == CLUTTER)
    scan = both.scan(2)
    assert scan.time == 2.0 and scan.counts.tolist() == [5, 5] and scan.for_filter().origin is None
    narrowed = both.with_valid(np.zeros((2, 3, 5), bool))
    assert not narrowed.valid.any()
    with pytest.raises(InputError, match="mask of shape"):
        both.with_valid(np.zeros((2, 3), bool))


def test_merge_all_equals_pairwise_concatenation_and_releases_its_inputs():
    import gc
    import weakref

    rng = np.random.default_rng(4)
    t = np.arange(4.0)
    parts = []
    for m, snr in ((1, True), (3, False), (2, True)):
        valid = rng.random((2, 4, m)) < 0.7
        parts.append(Scans(rng.normal(size=(2, 4, m, 2)), valid, t,
                           snr=rng.normal(size=(2, 4, m)) if snr else None, origin=np.zeros((2, 4, m), int)))
    ref = parts[0].merge(parts[1]).merge(parts[2])
    # by hand: every field concatenated along M, snr NaN where a part had none, padding zeroed
    z = np.concatenate([np.where(p.valid[..., None], p.z, 0.0) for p in parts], axis=2)
    snr = np.concatenate([p.snr if p.snr is not None else np.full(p.valid.shape, np.nan) for p in parts], axis=2)
    assert np.array_equal(ref.z, z) and np.array_equal(ref.snr, snr, equal_nan=True) and ref.doppler is None
    watch = [weakref.ref(p.z) for p in parts]
    lst = list(parts)
    del parts
    got = Scans.merge_all(lst)
    assert lst == []  # emptied: the caller's list no longer holds the inputs
    for name in ("z", "valid", "snr", "origin"):
        assert np.array_equal(getattr(got, name), getattr(ref, name), equal_nan=True), name
    del ref
    gc.collect()
    assert all(w() is None for w in watch)  # the inputs were released
    with pytest.raises(InputError, match="empty"):
        Scans.merge_all([])
    with pytest.raises(InputError, match="time stamps"):
        Scans.merge_all([got, Scans(got.z, got.valid, got.times + 1.0)])


def test_scans_do_not_copy_clean_padding_but_zero_dirty_padding():
    z = np.ones((1, 2, 2, 2))
    valid = np.array([[[True, False], [True, True]]])
    dirty = Scans(z, valid, np.arange(2.0))
    assert np.array_equal(dirty.z[0, 0, 1], [0.0, 0.0]) and np.array_equal(z[0, 0, 1], [1.0, 1.0])  # caller's kept
    z[0, 0, 1] = 0.0
    clean = Scans(z, valid, np.arange(2.0))
    assert clean.z is z  # not copied


# -- linear algebra -----------------------------------------------------------------------------------

def test_wrap_angle_interval():
    a = np.array([np.pi, -np.pi, 3 * np.pi, 0.5, -3.5, 7.0])
    w = wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    np.testing.assert_allclose(np.exp(1j * w), np.exp(1j * a), atol=1e-12)
    assert w[0] == np.pi and w[1] == np.pi


def _random_spd(rng, b, n):
    a = rng.standard_normal((b, n, n))
    return a @ np.swapaxes(a, -1, -2) + n * np.eye(n)


def test_cholupdate_update_and_downdate_match_refactorisation():
    rng = np.random.default_rng(0)
    P = _random_spd(rng, 5, 4)
    S = np.linalg.cholesky(P)
    u = rng.standard_normal((5, 4))
    up, failed = cholupdate(S, u, 1.0)
    np.testing.assert_allclose(up, np.linalg.cholesky(P + np.einsum("bi,bj->bij", u, u)), atol=1e-10)
    assert not failed.any()
    small = 0.3 * u
    down, failed = cholupdate(S, small, -1.0)
    np.testing.assert_allclose(down @ np.swapaxes(down, -1, -2), P - np.einsum("bi,bj->bij", small, small),
                               atol=1e-10)
    assert not failed.any()


def test_cholupdate_counts_the_fallback_when_a_downdate_fails():
    S = np.eye(2)[None].repeat(2, axis=0)
    u = np.array([[2.0, 0.0], [0.1, 0.0]])  # item 0 would become indefinite
    out, failed = cholupdate(S, u, -1.0)
    assert failed.tolist() == [True, False]
    assert np.all(np.isfinite(out))


def test_tria_gives_the_cholesky_factor_of_a_a_transpose():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 4, 9))
    np.testing.assert_allclose(tria(A), np.linalg.cholesky(A @ np.swapaxes(A, -1, -2)), atol=1e-10)


def test_joseph_form_equals_standard_form_for_the_optimal_gain():
    rng = np.random.default_rng(2)
    P = _random_spd(rng, 3, 4)
    H = rng.standard_normal((2, 4))
    R = np.diag([0.5, 2.0])
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    np.testing.assert_allclose(joseph_update(P, K, H, R), (np.eye(4) - K @ H) @ P, atol=1e-9)
    np.testing.assert_allclose(psd_solve(S, np.eye(2)[None].repeat(3, 0)), np.linalg.inv(S), atol=1e-10)


def test_safe_cholesky_counts_jitter():
    bad = np.array([[[1.0, 1.0], [1.0, 1.0]], [[2.0, 0.0], [0.0, 2.0]]])
    L, fixed = safe_cholesky(bad)
    assert fixed == 1 and np.all(np.isfinite(L))


# -- models -------------------------------------------------------------------------------------------

def test_constant_velocity_matches_the_dwna_formula():
    m = constant_velocity(3, 2.0, [1.0, 2.0, 3.0])
    T = 2.0
    q_axis = np.array([[T**4 / 4, T**3 / 2], [T**3 / 2, T**2]])
    for axis, s in enumerate([1.0, 2.0, 3.0]):
        idx = [axis, axis + 3]
        np.testing.assert_allclose(m.Q[np.ix_(idx, idx)], s**2 * q_axis)
    assert m.Q[0, 1] == 0 and m.F[0, 3] == T
    np.testing.assert_allclose(m.Q_sqrt @ m.Q_sqrt.T, m.Q, atol=1e-12)


def test_random_walk_velocity_has_exactly_zero_position_noise():
    m = random_walk_velocity(2, 1.0, 0.1)
    assert np.all(m.Q[:2] == 0) and np.allclose(m.Q[2:, 2:], 0.01 * np.eye(2))
    r = range_rate_model(0.5, 1.0)
    np.testing.assert_allclose(r.F, [[1, 0.5], [0, 1]])


def test_range_bearing_jacobian_matches_finite_differences():
    x = np.array([[100.0, 50.0, -1.0, 1.0], [-30.0, -0.001, 2.0, 0.0]])
    model = range_bearing(1.0, 0.1)
    J = range_bearing_jacobian(x)
    eps = 1e-6
    for j in range(4):
        d = np.zeros(4)
        d[j] = eps
        fd = model.residual(model.h(x + d), model.h(x - d)) / (2 * eps)
        np.testing.assert_allclose(J[:, :, j], fd, atol=1e-6)


@pytest.mark.parametrize("sensor", [(0.0, 0.0), (250.5, -1e3 / 3)])
def test_range_bearing_one_track_path_gives_the_array_code_numbers_bit_for_bit(sensor):
    """h and the Jacobian of one float64 state (B = 1: Python floats, the EKF's one-track update) against the same
    rows computed in a batch (the array code): exactly equal, for ordinary states, a state on the sensor (the
    1e-300 floor), tiny, huge, signed-zero, infinite and NaN offsets, and a 6-D state."""
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.normal(0.0, 1e4, (300, 4)), rng.normal(0.0, 1e-3, (50, 4)),
                        rng.normal(0.0, 1e150, (20, 4))])
    special = np.array([[sensor[0], sensor[1], 1.0, 2.0], [sensor[0] + 1e-160, sensor[1], 0.0, 0.0],
                        [-0.0, 0.0, 0.0, 0.0], [np.inf, 5.0, 0.0, 0.0], [np.nan, 5.0, 0.0, 0.0],
                        [3.0, -np.inf, 0.0, 0.0], [1e300, 1e300, 0.0, 0.0]])
    x = np.concatenate([x, special])
    model = range_bearing(1.0, 0.1, sensor=sensor)
    with np.errstate(all="ignore"):
        batch_h, batch_j = model.h(x), range_bearing_jacobian(x, sensor)
        for i in range(x.shape[0]):
            one_h, one_j = model.h(x[i:i + 1]), range_bearing_jacobian(x[i:i + 1], sensor)
            assert one_h.shape == (1, 2) and one_j.shape == (1, 2, 4)
            np.testing.assert_array_equal(one_h.view(np.int64), batch_h[i:i + 1].view(np.int64))  # NaN bits too
            np.testing.assert_array_equal(one_j.view(np.int64), batch_j[i:i + 1].view(np.int64))
        x6 = np.concatenate([x[:40], rng.normal(size=(40, 2))], axis=1)
        batch_j6 = range_bearing_jacobian(x6, sensor)
        for i in range(40):
            np.testing.assert_array_equal(range_bearing_jacobian(x6[i:i + 1], sensor), batch_j6[i:i + 1])
    # float32 states take the array code (its float32 arithmetic), as before
    x32 = x[:5].astype(np.float32)
    np.testing.assert_array_equal(model.h(x32[:1]), model.h(x32)[:1])


def test_angle_aware_mean_across_pi():
    model = range_bearing(1.0, 0.1)
    y = np.array([[[10.0, np.pi - 0.1], [12.0, -np.pi + 0.1]]])
    m = model.mean(y, np.array([0.5, 0.5]))
    assert m[0, 0] == pytest.approx(11.0)
    assert abs(abs(m[0, 1]) - np.pi) < 1e-12  # not 0, which a plain average gives


# -- truth and random streams -------------------------------------------------------------------------

def test_coordinated_turn_keeps_speed_and_turns_by_rate_times_time():
    truth = piecewise_trajectory([0, 0, 1000], [200, 0, 0], [Leg("straight", 10), Leg("turn", 10, np.deg2rad(9)),
                                                            Leg("climb", 5, climb_rate=-40)], 1.0)
    v = truth.states[0, :, 3:]
    np.testing.assert_allclose(np.linalg.norm(v[:, :2], axis=1), 200.0)
    heading = np.degrees(np.arctan2(v[20, 1], v[20, 0]))
    assert heading == pytest.approx(90.0)
    assert truth.states[0, -1, 2] == pytest.approx(1000 - 5 * 40)
    with pytest.raises(InputError, match="leg kind"):
        Leg("loop", 3)


def test_streams_are_reproducible_and_independent_of_chunking():
    a = generator(5, "paper", 3).standard_normal(4)
    b = generator(5, "paper", 3).standard_normal(4)
    c = generator(5, "paper", 4).standard_normal(4)
    assert np.array_equal(a, b) and not np.allclose(a, c)
    assert chunk_bounds(10, 4) == [(0, 4), (4, 8), (8, 10)]
    with pytest.raises(ValueError):
        generator(-1)


def test_sample_motion_statistics():
    m = constant_velocity(1, 1.0, 1.0)
    truth = sample_motion(np.zeros((20000, 2)), m, 2, generator(0))
    np.testing.assert_allclose(np.cov(truth.states[:, 1].T), m.Q, rtol=0.05, atol=0.01)
