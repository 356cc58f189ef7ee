"""The compiled bootstrap-filter steps (workbench.kernels.particle_numba) against their NumPy twins in
workbench.particle_core and workbench.resampling: the same draws, the same particles, weights to round-off."""

import numpy as np
import pytest

from workbench import particle_core as core
from workbench.kernels.backend import numba_available
from workbench.kernels.particle_numpy import EXP_UNDERFLOW, poly_exp
from workbench.models import MeasurementModel, random_walk_velocity, range_bearing
from workbench.resampling import effective_sample_size, normalise_log_weights, resample_where
from workbench.types import Gaussian, InputError, Particles, Scan

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba is not installed")


def kernels():
    from workbench.kernels import particle_numba

    return particle_numba


def cloud(rng, B=3, N=700, n=4, layout="component-major"):
    x = rng.normal(size=(B, N, n)) * [30.0, 30.0, 2.0, 2.0][:n] + [100.0, 50.0, -1.0, 1.0][:n]
    if layout == "component-major":
        x = np.ascontiguousarray(np.moveaxis(x, 2, 0)).transpose(1, 2, 0)
    return x


def test_poly_exp_is_within_an_ulp_of_the_library_and_zero_below_the_floor():
    x = -np.concatenate([np.linspace(0.0, 708.0, 300_001), np.geomspace(1e-300, 1.0, 1000)])
    assert np.max(np.abs(poly_exp(x) / np.exp(x) - 1.0)) <= 2.3e-16
    assert poly_exp(np.array([-np.inf, EXP_UNDERFLOW - 1e-9]))[:2].tolist() == [0.0, 0.0]
    assert np.isnan(poly_exp(np.array([np.nan])))[0]
    # the compiled exp (with fused multiply-adds) against its twin: an ulp apart at most
    out = np.empty_like(x)
    kernels()._exp_shifted(x, 0.0, out)
    assert np.max(np.abs(out / poly_exp(x) - 1.0)) <= 2.3e-16


@pytest.mark.parametrize("layout", ["component-major", "particle-major"])
def test_compiled_predict_draws_the_same_numbers_and_gives_the_same_particles(layout):
    rng = np.random.default_rng(1)
    x = cloud(rng, layout=layout)
    lw = normalise_log_weights(rng.normal(size=x.shape[:2]))
    state = core.ParticleState(Particles(x, lw))
    for motion in (random_walk_velocity(2, 1.0, 0.1), random_walk_velocity(2, 0.5, 3.0)):
        a, b = np.random.default_rng(7), np.random.default_rng(7)
        ref = core.predict(state, motion, a)
        got = core.predict(state, motion, b, backend="numba")
        np.testing.assert_array_equal(got.cloud.particles, ref.cloud.particles)  # bit for bit
        assert got.cloud.log_weights is state.cloud.log_weights
        assert a.random() == b.random()  # the generator is left where NumPy leaves it
        assert got.cloud.particles.base is not None and np.moveaxis(got.cloud.particles, 2, 0).flags.c_contiguous


def test_combine_follows_the_plan_of_combine_columns_bit_for_bit():
    rng = np.random.default_rng(2)
    L, n, k = 3000, 4, 3
    x = rng.normal(size=(n, L))
    e = rng.normal(size=(L, k))
    # zeros skipped, ones exact, a row with no term, a row of units only, negative and tiny coefficients
    M = np.array([[1.0, 0.0, 0.25, 0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                  [1.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0], [-3.0, 1e-300, 0.0, 2.0, 0.0, -1.0, 0.0]])
    ref = core.combine_columns(np.empty((L, 4)), M, x.T, e)
    plan = core._plan_arrays(M.tobytes(), *M.shape)
    out = np.empty((4, L))
    kernels().combine(out, x, e, *plan)
    np.testing.assert_array_equal(out.T, ref)


def _models():
    plain = range_bearing(1.0, 0.1)
    offset = range_bearing(3.0, 0.02, sensor=(40.0, -25.0))
    # a correlated R: L^-1 has an off-diagonal entry
    corr = MeasurementModel("rb-corr", plain.h, np.array([[4.0, 0.03], [0.03, 0.01]]), angular=(False, True),
                            frame="range-bearing", sensor_position=(0.0, 0.0))
    return {"plain": plain, "offset": offset, "correlated": corr}


@pytest.mark.parametrize("which", ["plain", "offset", "correlated"])
def test_fused_range_bearing_log_weights_equal_the_model_likelihood(which):
    model = _models()[which]
    rng = np.random.default_rng(3)
    x = cloud(rng, B=4, N=900)
    x[2, :, :2] = [-100.0, 0.5] + rng.normal(size=(900, 2))  # bearings around +-pi: the residual wraps
    z = np.stack([model.h(x[:, 0])[:, 0] + 2.0, model.h(x[:, 0])[:, 1] - 0.05], axis=-1)
    z[2, 1] = -np.pi + 0.01
    prev = normalise_log_weights(rng.normal(size=(4, 900)))
    assert core._plane_range_bearing(model) is not None
    got = core.weighted_log_likelihood(z, x, model, prev, backend="numba")
    ref = core.weighted_log_likelihood(z, x, model, prev, backend="numpy")
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9)
    # both against the range-bearing Gaussian written out here in extended precision (not the model's h, residual
    # or Cholesky factor): prev - 1/2 nu^T R^-1 nu with the bearing residual wrapped into [-pi, pi)
    exact = _range_bearing_log_weights(z, x, model.R, model.sensor_position, prev)
    assert np.ptp(exact - prev) > 100.0  # the likelihood term is far from negligible beside the weights
    for path in (got, ref):
        np.testing.assert_allclose(path, exact.astype(float), rtol=1e-12, atol=1e-9)


def _range_bearing_log_weights(z, x, R, sensor, prev):
    """``prev_bi - 1/2 nu_bi^T R^-1 nu_bi`` with ``nu = z_b - [|p_bi - s|, atan2(p_bi - s)]`` (bearing wrapped), in
    ``np.longdouble``, with the 2 x 2 inverse in closed form."""
    L = np.longdouble
    pi = L(np.pi)
    dx, dy = x[..., 0].astype(L) - L(sensor[0]), x[..., 1].astype(L) - L(sensor[1])
    nu_r = z[:, None, 0].astype(L) - np.sqrt(dx * dx + dy * dy)
    nu_b = z[:, None, 1].astype(L) - np.arctan2(dy, dx)
    nu_b = np.mod(nu_b + pi, 2 * pi) - pi
    a, b, d = L(R[0, 0]), L(R[0, 1]), L(R[1, 1])
    quad = (d * nu_r * nu_r - 2 * b * nu_r * nu_b + a * nu_b * nu_b) / (a * d - b * b)
    return prev.astype(L) - quad / 2


def test_an_infinite_particle_gets_zero_weight_not_nan():
    model = _models()["plain"]
    x = cloud(np.random.default_rng(4), B=1, N=16)
    x[0, 3, 0] = np.inf
    z = model.h(x[:, 0])
    lw = np.zeros((1, 16))
    for backend in ("numpy", "numba"):
        out = core.weighted_log_likelihood(z, x, model, lw, backend=backend)
        assert out[0, 3] == -np.inf and np.all(np.isfinite(np.delete(out[0], 3))), backend


def test_a_model_that_declares_the_frame_but_computes_another_bearing_takes_the_general_path():
    plain = range_bearing(1.0, 0.1)

    def compass(x):  # bearing clockwise from north: not the frame's convention
        return np.stack([np.hypot(x[..., 0], x[..., 1]), np.arctan2(x[..., 0], x[..., 1])], axis=-1)

    liar = MeasurementModel("compass", compass, plain.R, angular=(False, True), frame="range-bearing",
                            sensor_position=(0.0, 0.0))
    assert core._plane_range_bearing(liar) is None and core._plane_range_bearing(plain) is not None
    x = cloud(np.random.default_rng(5), B=2, N=50)
    z = compass(x[:, 0])
    lw = np.zeros((2, 50))
    np.testing.assert_array_equal(core.weighted_log_likelihood(z, x, liar, lw, backend="numba"),
                                  core.log_likelihood(z, x, liar))


def _log_weights(rng, B, N):
    lw = rng.normal(size=(B, N)) * rng.uniform(0.5, 8.0, (B, 1))
    lw[rng.random((B, N)) < 0.1] = -np.inf
    lw[:, 0] = np.maximum(lw[:, 0], 0.0)
    return lw


def test_compiled_normalisation_and_ess_equal_the_twins():
    rng = np.random.default_rng(6)
    lw = _log_weights(rng, 6, 500)
    lw[1] = -np.inf  # every weight underflowed
    lw[2, 7] = np.nan
    lw[3, 9] = np.inf
    fallback = normalise_log_weights(rng.normal(size=(6, 500)))
    present = np.array([True, True, True, True, True, False])
    out, dead = np.empty_like(lw), np.empty(6, dtype=bool)
    kernels().normalise(lw, np.max(lw, axis=1), present, fallback, out, dead)
    ref = np.where(present[:, None], normalise_log_weights(lw, fallback=fallback), fallback)
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13)
    assert dead.tolist() == [False, True, True, True, False, False]
    ok = normalise_log_weights(_log_weights(rng, 4, 300))
    ess = kernels().effective_sample_size(ok, np.max(ok, axis=1), np.empty(4))
    np.testing.assert_allclose(ess, effective_sample_size(ok), rtol=1e-12)
    np.testing.assert_allclose(ess, 1.0 / np.sum(np.exp(ok) ** 2, axis=1), rtol=1e-12)


@pytest.mark.parametrize("rows", [[0, 1, 2, 3], [1, 3]])
def test_compiled_systematic_resampling_draws_the_same_particles(rows):
    rng = np.random.default_rng(8)
    B, N = 4, 999
    x = cloud(rng, B=B, N=N)
    lw = normalise_log_weights(_log_weights(rng, B, N))
    mask = np.isin(np.arange(B), rows)
    ref_x, ref_lw = resample_where(mask, x, lw, np.random.default_rng(3))
    u0 = np.random.default_rng(3).random((len(rows), 1))  # the draw resample_where made
    out = np.empty((4, B, N))
    kernels().systematic_gather(lw, np.max(lw, axis=1), np.array(rows), u0[:, 0], core._rows(x), out, np.empty(N),
                                np.empty(N + 1, dtype=np.int64))
    np.testing.assert_array_equal(out.transpose(1, 2, 0), ref_x)


def test_a_row_without_a_finite_weight_is_resampled_uniformly():
    x = cloud(np.random.default_rng(9), B=1, N=8)
    out = np.empty((4, 1, 8))
    kernels().systematic_gather(np.full((1, 8), -np.inf), np.array([-np.inf]), np.array([0]), np.array([0.5]),
                                core._rows(x), out, np.empty(8), np.empty(9, dtype=np.int64))
    np.testing.assert_array_equal(out.transpose(1, 2, 0), x)  # counts 1 each: the same particles in order


@pytest.mark.parametrize("N", [300, 6000])  # both of Particles.to_gaussian's branches
def test_compiled_moments_equal_to_gaussian(N):
    rng = np.random.default_rng(10)
    x = cloud(rng, B=3, N=N)
    lw = normalise_log_weights(rng.normal(size=(3, N)) * 2)
    state = core.ParticleState(Particles(x, lw))
    ref = core.estimate(state)
    got = core.estimate(state, backend="numba")
    np.testing.assert_allclose(got.mean, ref.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got.cov, ref.cov, rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(got.cov, np.swapaxes(got.cov, 1, 2))


def _compiled_and_extended_moments(x, lw):
    """The compiled estimate of particles ``x (B, N, n)`` (stored component-major) with log-weights ``lw``, and the
    reference mean, covariance and standard deviations computed in extended precision."""
    state = core.ParticleState(Particles(np.ascontiguousarray(np.moveaxis(x, 2, 0)).transpose(1, 2, 0), lw))
    got = core.estimate(state, backend="numba")
    xl, w = x.astype(np.longdouble), np.exp(lw.astype(np.longdouble))
    mean = np.einsum("bn,bni->bi", w, xl)
    d = xl - mean[:, None]
    cov = np.einsum("bn,bni,bnj->bij", w, d, d)
    return got, mean, cov, np.sqrt(np.diagonal(cov, axis1=1, axis2=2))


@pytest.mark.parametrize("far_weight", ["uniform", "light"])
def test_compiled_moments_stay_accurate_with_a_far_first_particle(far_weight):
    # the planar one-pass moments pivot on the heaviest particle (the first, where the weights are equal); a
    # particle k standard deviations off costs k^2 ulps of the variance, and its own weight bounds k^2 by N
    rng = np.random.default_rng(3)
    N = 1000
    x = rng.normal(size=(1, N, 4)) * 1e-3 + [1e6, -2e5, 3.0, -4.0]
    x[0, 0] += [1e3, -1e3, 5.0, 5.0]  # 31 standard deviations out with weight 1/N
    lw = np.full((1, N), -np.log(N))
    if far_weight == "light":
        lw = normalise_log_weights(np.where(np.arange(N) == 0, -30.0, rng.normal(size=(1, N))))
    got, mean, cov, sd = _compiled_and_extended_moments(x, lw)
    np.testing.assert_allclose(got.mean, mean.astype(float), rtol=1e-14)
    err = np.max(np.abs(got.cov - cov) / (sd[:, :, None] * sd[:, None, :]))  # in units of the correlation
    assert err < 10 * N * np.finfo(float).eps  # of order k^2 <= N ulps (measured: 5 N)
    if far_weight == "light":  # pivoting on a heavy particle near the mean: hundreds of ulps, not thousands
        assert err < 1e-13


def test_compiled_moments_of_equal_weights_keep_the_twins_accuracy():
    # equal weights (every step after resampling) take unweighted sums scaled once: summing N equal weights
    # instead would add N correlated round-offs (7e-13 relative in the mean at N = 10^5, measured)
    rng = np.random.default_rng(13)
    N = 100_000
    x = rng.normal(size=(1, N, 4)) * [30.0, 30.0, 2.0, 2.0] + [100.0, 50.0, -1.0, 1.0]
    lw = np.full((1, N), -np.log(N))
    got, mean, cov, sd = _compiled_and_extended_moments(x, lw)
    assert np.max(np.abs(got.mean - mean) / np.abs(mean)) < 1e-14
    assert np.max(np.abs(got.cov - cov) / (sd[:, :, None] * sd[:, None, :])) < 1e-13


@pytest.mark.parametrize("threshold", [0.5, 2.0])
def test_compiled_reweight_equals_the_numpy_path(threshold):
    rng = np.random.default_rng(11)
    B, N = 5, 800
    x = cloud(rng, B=B, N=N)
    previous = normalise_log_weights(rng.normal(size=(B, N)))
    log_w = previous + _log_weights(rng, B, N)
    log_w[2] = -np.inf  # dead: keeps its previous weights
    present = np.array([True, True, True, False, True])
    a, b = np.random.default_rng(4), np.random.default_rng(4)
    ref = core.reweight(x, log_w, previous, present, threshold, a)
    got = core.reweight(x, log_w, previous, present, threshold, b, backend="numba")
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_allclose(got[1], ref[1], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(got[2], ref[2])
    np.testing.assert_array_equal(got[3], ref[3])
    assert got[3].tolist() == [False, False, True, False, False]
    assert a.random() == b.random()


def test_the_same_seed_gives_the_same_filter_on_both_backends():
    from workbench.plugins import load_host

    model = range_bearing(1.0, 0.1)
    motion = random_walk_velocity(2, 1.0, 0.1)
    truth = np.array([[100.0, 50.0, -1.0, 1.0]] * 2)
    prior = Gaussian.broadcast(np.array([110.0, 40.0, 0.0, 0.0]), np.diag([100.0, 100.0, 4.0, 4.0]), 2)
    host = load_host()
    runs = {}
    for backend in ("numpy", "numba"):
        spec = host.filter("sir").configure(particles=2500, threshold=0.5, backend=backend)
        rng = np.random.default_rng(12)
        state = spec.init(prior, rng)
        x = truth.copy()
        means = []
        for k in range(10):
            x = x @ motion.F.T
            scan_z = model.h(x)
            if k:
                state = spec.predict(state, motion, rng)
            state = spec.update(state, Scan(scan_z[:, None, :], np.ones((2, 1), dtype=bool)), model, rng)
            means.append(spec.estimate(state).mean)
        runs[backend] = (state, np.stack(means))
    (s0, m0), (s1, m1) = runs["numpy"], runs["numba"]
    np.testing.assert_array_equal(s1.cloud.particles, s0.cloud.particles)
    np.testing.assert_allclose(m1, m0, rtol=1e-12, atol=1e-10)
    assert spec.diagnostics(s1) == host.filter("sir").configure(particles=2500, backend="numpy").diagnostics(s0)


def test_sir_backend_is_a_declared_checked_parameter():
    from workbench.plugins import load_host

    spec = load_host().filter("sir")
    assert spec.params["backend"] == "auto"
    assert next(p for p in spec.parameters if p.name == "backend").choices == ("auto", "numba", "numpy")
    with pytest.raises(InputError):
        spec.configure(backend="fortran")
    assert spec.configure(backend="numpy").params["backend"] == "numpy"
