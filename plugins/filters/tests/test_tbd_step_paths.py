"""The shortcuts of tbd-pf's update step and of the gate around it (paper 000's tracking loop), each held to the code
it stands in for: the compiled systematic resampling to :func:`workbench.resampling.resample_where` bit for bit,
the packing of a gated (front-packed) scan to the general gather, the radius gate to a hand-written row-by-row
gate and to a checked :class:`~workbench.types.Scan`, and the cached two-mode prediction plan to the NumPy twin."""

import numpy as np
import pytest

from workbench.models import constant_velocity
from workbench.resampling import resample_where
from workbench.rng import generator
from workbench.tracking.single import radius_gate
from workbench.types import InputError, Particles, Scan
from workbench_filters.tbd import ModeState, predict_jump_markov, predict_jump_markov_numpy, resample_rows
from workbench_filters.tbd.tbd_weights_numpy import pack_measurements


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _same_position(g1, g2) -> bool:
    return np.array_equal(g1.bit_generator.random_raw(4), g2.bit_generator.random_raw(4))


@pytest.mark.parametrize("mask", ["all", "some"])
@pytest.mark.parametrize("component_major", [True, False])
def test_compiled_resampling_is_resample_where_bit_for_bit(mask, component_major):
    B, N, n = 6, 257, 6
    rng = np.random.default_rng(5)
    x = rng.normal(size=(B, N, n)) * 100.0
    if component_major:
        x = np.ascontiguousarray(x.transpose(2, 0, 1)).transpose(1, 2, 0)
    log_w = rng.normal(size=(B, N)) * 6.0
    log_w[1, :200] = -np.inf  # a few particles hold every weight
    log_w[2] = -np.inf  # every weight underflowed: drawn uniformly
    log_w[3, 7] = 40.0  # one particle holds (almost) all the weight
    mode = (rng.random((B, N)) < 0.3).astype(float)
    rows = np.ones(B, dtype=bool) if mask == "all" else np.array([True, False, True, True, False, True])
    g1, g2 = generator(3, "twins"), generator(3, "twins")
    got = resample_rows(rows, x, log_w, g1, mode, backend="numba")
    want = resample_where(rows, x, log_w, g2, mode)
    for a, b in zip(got, want):
        assert _same_bits(a, b) and a.strides == b.strides
    assert _same_position(g1, g2)
    # the draws are systematic: item 3 is (almost) all copies of particle 7, untouched items are kept as they are
    assert np.sum(np.all(got[0][3] == x[3, 7], axis=1)) >= N - 1
    if mask == "some":
        assert got[0][1] is not x[1] and np.array_equal(got[0][1], x[1]) and np.array_equal(got[1][1], log_w[1])
    # nothing to resample: the inputs come back, no draw
    g3 = generator(3, "twins")
    out = resample_rows(np.zeros(B, dtype=bool), x, log_w, g3, mode, backend="numba")
    assert out[0] is x and out[1] is log_w and _same_position(g3, generator(3, "twins"))


def test_packing_a_front_packed_scan_is_the_general_gather():
    rng = np.random.default_rng(8)
    B, M = 5, 7
    counts = np.array([3, 0, 7, 1, 3])
    front = np.arange(M) < counts[:, None]
    z = np.where(front[..., None], rng.normal(size=(B, M, 4)) * [3e3, 3e3, 1e3, 50.0], 0.0)
    log_pd = np.where(front, -rng.random((B, M)), 0.0)
    sigma_p = 50.0 + 100.0 * rng.random((B, M))
    origin = rng.normal(size=(B, 3)) * 1e3
    # the same detections in another row order (the general path's gather), and narrower padding
    perm = np.stack([rng.permutation(M) for _ in range(B)])
    shuffled = [np.take_along_axis(a, perm if a.ndim == 2 else perm[..., None], axis=1)
                for a in (z, front, log_pd, sigma_p)]
    inverse_order = [np.flatnonzero(shuffled[1][b]) for b in range(B)]
    for b in range(B):  # the general path keeps the valid rows' order: put them back in the front order
        shuffled[0][b, inverse_order[b]] = z[b, : counts[b]]
        shuffled[2][b, inverse_order[b]] = log_pd[b, : counts[b]]
        shuffled[3][b, inverse_order[b]] = sigma_p[b, : counts[b]]
    for precision in ("float64", "float32"):
        fast = pack_measurements(z, front, log_pd, sigma_p, 15.0, precision, origin)
        general = pack_measurements(*shuffled, 15.0, precision, origin)
        assert not np.array_equal(shuffled[1], front)
        assert all(_same_bits(a, b) for a, b in zip(fast, general))
        # and against the packing written out for one detection (float64: T = 2 a q / ln 2)
        if precision == "float64":
            a = 0.5 / sigma_p[2, 4] ** 2
            np.testing.assert_allclose(fast[0][2, :3, 4], 2 * a * (z[2, 4, :3] - origin[2]) / np.log(2.0), rtol=1e-15)


def _gate_reference(scan: Scan, centre: np.ndarray, radius: float, dims: int):
    """Row by row: the kept detections (valid, within ``radius``) in their order, padded with the first unkept rows."""
    B, M = scan.valid.shape
    keep = np.zeros((B, M), dtype=bool)
    for b in range(B):
        for m in range(M):
            d = scan.z[b, m, :dims] - centre[b]
            keep[b, m] = scan.valid[b, m] and float(np.sum(d * d)) <= radius * radius
    width = int(keep.sum(axis=1).max())
    order = np.array([[*np.flatnonzero(keep[b]), *np.flatnonzero(~keep[b])][:width] for b in range(B)],
                     dtype=int).reshape(B, width)
    return keep, order


@pytest.mark.parametrize("dims, with_cov", [(3, False), (2, True), (9, False)])
def test_radius_gate_against_a_row_by_row_gate_and_a_checked_scan(dims, with_cov):
    rng = np.random.default_rng(12)
    B, M, m = 4, 60, max(4, dims)
    radius = 500.0
    centre = rng.normal(size=(B, dims)) * 1e3
    z = rng.normal(size=(B, M, m)) * 700.0
    z[..., :dims] += centre[:, None, :]
    # detections exactly on the sphere (up to rounding) and an ulp either side: the squared distance's rounding
    # decides them, so the gate must add the squares as np.sum does
    u = rng.normal(size=(B, 12, dims))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    z[:, :12, :dims] = centre[:, None, :] + u * radius * np.array([1 - 1e-16, 1.0, 1 + 1e-16] * 4)[None, :, None]
    valid = rng.random((B, M)) < 0.8
    z = np.where(valid[..., None], z, 0.0)
    snr = rng.normal(size=(B, M)) * 5 + 10
    origin = rng.integers(-1, 3, size=(B, M))
    cov = None
    if with_cov:
        a = rng.normal(size=(B, M, m, m))
        cov = a @ np.swapaxes(a, -1, -2) + np.eye(m)
    scan = Scan(z, valid, snr=snr, origin=origin, time=np.float64(2.5), cov=cov,
                clutter_density=np.where(valid, rng.random((B, M)), 0.0))
    gated, keep = radius_gate(scan, centre, radius, dims)
    want_keep, order = _gate_reference(scan, centre, radius, dims)
    exact = np.sum((z[..., :dims] - centre[:, None, :]) ** 2, axis=-1) <= radius * radius
    assert np.array_equal(keep, want_keep) and np.array_equal(keep, valid & exact)
    assert 0 < keep[:, :12].sum() < keep[:, :12].size  # the boundary cases fall both ways
    rows = np.arange(B)[:, None]
    # what a checked Scan makes of the gathered rows: padding rows zeroed, identity covariances
    checked = Scan(z[rows, order], keep[rows, order], snr=snr[rows, order], origin=origin[rows, order],
                   time=2.5, cov=None if cov is None else cov[rows, order],
                   clutter_density=scan.clutter_density[rows, order])
    for field in ("z", "valid", "snr", "doppler", "origin", "cov", "clutter_density"):
        a, b = getattr(gated, field), getattr(checked, field)
        assert (a is None and b is None) or _same_bits(a, b), field
    assert type(gated.time) is float and gated.time == 2.5
    assert np.all(gated.z[~gated.valid] == 0.0)


def test_two_mode_prediction_plan_follows_each_motion_model():
    rng = np.random.default_rng(4)
    B, N = 2, 300
    x = rng.normal(size=(B, N, 6)) * 50.0
    state = ModeState(Particles(x, np.full((B, N), -np.log(N))), 0, 0, (rng.random((B, N)) < 0.3).astype(float))
    kw = dict(switch_on=0.05, switch_off=0.2, scale=4.0)
    # the same F with other noise, then back: each prediction uses its own model's columns
    for sigma in ((8.0, 8.0, 4.0), (1.0, 2.0, 0.0), (8.0, 8.0, 4.0), (0.0, 0.0, 3.0)):
        motion = constant_velocity(3, 1.0, sigma)
        g1, g2 = generator(6, "twins"), generator(6, "twins")
        fast = predict_jump_markov(state, motion, g1, backend="numba", **kw)
        ref = predict_jump_markov_numpy(state, motion, g2, **kw)
        assert _same_bits(np.ascontiguousarray(fast.cloud.particles), np.ascontiguousarray(ref.cloud.particles))
        assert _same_bits(fast.mode, ref.mode) and _same_position(g1, g2)


def test_radius_gate_refuses_more_dims_than_the_scan_has():
    scan = Scan(np.zeros((2, 3, 4)), np.ones((2, 3), dtype=bool))
    with pytest.raises(InputError, match="gate dims 5 exceeds the scan's 4"):
        radius_gate(scan, np.zeros((2, 5)), 10.0, 5)
