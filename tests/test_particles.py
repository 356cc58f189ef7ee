"""The resampling and bootstrap particle-filter pieces of the core (:mod:`workbench.resampling`,
:mod:`workbench.particle_core`), against SciPy and NumPy references."""

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from workbench import particle_core as particle
from workbench.models import random_walk_velocity, range_bearing
from workbench.resampling import (effective_sample_size, normalise_log_weights, resample_where, systematic_counts,
                                  systematic_resample)
from workbench.types import BLAS_MOMENT_PARTICLES, Gaussian, Particles


def _reference_systematic(log_w, u0, count):
    """Textbook systematic resampling: ``u_j = (u0 + j) / M`` looked up in the CDF with ``searchsorted``."""
    w = np.exp(log_w - logsumexp(log_w))
    cdf = np.cumsum(w)
    cdf[-1] = 1.0
    return np.searchsorted(cdf, (u0 + np.arange(count)) / count, side="right").clip(0, len(w) - 1)


def _random_log_weights(rng, batch, n):
    log_w = rng.standard_normal((batch, n)) * rng.uniform(0.0, 8.0)
    log_w[rng.random((batch, n)) < 0.1] = -np.inf  # some particles with zero weight
    log_w[:, 0] = np.maximum(log_w[:, 0], 0.0)  # at least one finite weight per row
    return log_w


def test_systematic_counts_are_floor_or_ceil_of_m_w():
    rng = np.random.default_rng(11)
    for trial in range(200):
        batch, n = int(rng.integers(1, 5)), int(rng.integers(1, 200))
        count = n if trial % 2 else int(rng.integers(1, 300))
        log_w = _random_log_weights(rng, batch, n)
        u0 = rng.random(batch)
        k = systematic_counts(log_w, u0, count)
        assert k.shape == (batch, n) and k.dtype.kind == "i"
        assert np.all(k.sum(axis=1) == count)
        mw = count * np.exp(log_w - logsumexp(log_w, axis=1, keepdims=True))
        assert np.all((k == np.floor(mw)) | (k == np.ceil(mw)) | np.isclose(k, mw, atol=1e-9)), trial
        assert np.all(k[np.isneginf(log_w)] == 0)


def test_systematic_resample_matches_searchsorted_reference():
    rng = np.random.default_rng(12)
    for trial in range(200):
        batch, n = int(rng.integers(1, 5)), int(rng.integers(1, 200))
        count = None if trial % 2 else int(rng.integers(1, 300))
        log_w = _random_log_weights(rng, batch, n)
        idx = systematic_resample(log_w, np.random.default_rng(trial), count)
        u0 = np.random.default_rng(trial).random((batch, 1))  # the same draw systematic_resample made
        ref = np.stack([_reference_systematic(log_w[b], u0[b, 0], count or n) for b in range(batch)])
        np.testing.assert_array_equal(idx, ref)
        assert np.all(np.diff(idx, axis=1) >= 0)


def test_systematic_counts_treat_a_row_without_finite_weight_as_uniform():
    k = systematic_counts(np.array([[-np.inf, -np.inf, -np.inf, -np.inf], [0.0, -np.inf, 0.0, -np.inf]]),
                          np.array([0.5, 0.5]), 8)
    np.testing.assert_array_equal(k, [[2, 2, 2, 2], [4, 0, 4, 0]])


@pytest.mark.parametrize("layout", ["particle-major", "component-major"])
def test_resample_where_gathers_rows_and_keeps_layout(layout):
    rng = np.random.default_rng(13)
    B, N, n = 5, 64, 3
    x = rng.standard_normal((B, N, n))
    if layout == "component-major":
        x = np.ascontiguousarray(np.moveaxis(x, 2, 0)).transpose(1, 2, 0)
    extra = rng.standard_normal((B, N, 2, 2))
    log_w = normalise_log_weights(rng.standard_normal((B, N)) * 3)
    before = (x.copy(), log_w.copy(), extra.copy())
    for mask in (np.ones(B, bool), np.array([True, False, True, False, False])):
        new_x, new_lw, new_extra = resample_where(mask, x, log_w, np.random.default_rng(1), extra)
        rows = np.flatnonzero(mask)
        idx = systematic_resample(log_w[rows], np.random.default_rng(1))
        np.testing.assert_array_equal(new_x[rows], np.stack([x[r][i] for r, i in zip(rows, idx)]))
        np.testing.assert_array_equal(new_extra[rows], np.stack([extra[r][i] for r, i in zip(rows, idx)]))
        np.testing.assert_array_equal(new_x[~mask], x[~mask])
        np.testing.assert_array_equal(new_lw[~mask], log_w[~mask])
        np.testing.assert_allclose(new_lw[rows], -np.log(N))
        assert new_x.strides == x.strides  # the memory layout is kept
    for a, b in zip((x, log_w, extra), before):
        np.testing.assert_array_equal(a, b)  # inputs untouched


def test_normalise_and_ess_match_scipy():
    rng = np.random.default_rng(14)
    log_w = rng.standard_normal((6, 50)) * 30 - 500
    log_w[2] = -np.inf  # every weight underflowed
    fallback = np.log(np.full((6, 50), 1 / 50))
    out = normalise_log_weights(log_w, fallback=fallback)
    finite = [0, 1, 3, 4, 5]
    np.testing.assert_allclose(out[finite], log_w[finite] - logsumexp(log_w[finite], axis=1, keepdims=True),
                               rtol=0, atol=1e-10)
    np.testing.assert_array_equal(out[2], fallback[2])
    np.testing.assert_allclose(effective_sample_size(out[finite]), 1 / np.sum(np.exp(out[finite]) ** 2, axis=1),
                               rtol=1e-12)
    assert effective_sample_size(np.full((1, 8), -np.log(8)))[0] == pytest.approx(8.0)


# -- the particle filter's pieces --------------------------------------------------------------------


def test_combine_columns_matches_matrix_product():
    rng = np.random.default_rng(15)
    for _ in range(50):
        r, c1, c2 = rng.integers(1, 6, 3)
        M = rng.choice([0.0, 1.0, 0.5, -2.0], size=(r, c1 + c2), p=[0.4, 0.3, 0.2, 0.1])
        a, b = rng.standard_normal((3, 7, c1)), rng.standard_normal((3, 7, c2))
        out = particle.combine_columns(particle.component_major(3, 7, r), M, a, b)
        np.testing.assert_allclose(out, np.concatenate([a, b], axis=-1) @ M.T, rtol=1e-13, atol=1e-13)


def test_predict_is_f_x_plus_q_sqrt_e_with_the_same_draws():
    motion = random_walk_velocity(2, 0.7, 0.3)
    rng = np.random.default_rng(16)
    x = rng.standard_normal((3, 40, 4)) * 10
    state = particle.ParticleState(Particles(x, np.full((3, 40), -np.log(40))))
    moved = particle.predict(state, motion, np.random.default_rng(5)).cloud.particles
    e = np.random.default_rng(5).standard_normal((3, 40, 2))  # Q_sqrt has two non-zero columns
    np.testing.assert_allclose(moved, x @ motion.F.T + e @ motion.Q_sqrt[:, 2:].T, rtol=1e-13, atol=1e-12)
    assert moved.base is not None and moved.transpose(2, 0, 1).flags.c_contiguous  # component-major storage


def test_log_likelihood_matches_gaussian_logpdf_with_wrapped_bearing():
    model = range_bearing(2.0, 0.05)
    rng = np.random.default_rng(17)
    B, N = 2, 5000  # large enough for the component-at-a-time residual path
    x = rng.standard_normal((B, N, 4)) * 20 + [-100.0, 1.0, 0.0, 0.0]  # bearings near +-pi
    z = np.array([[100.0, np.pi - 0.01], [101.0, -np.pi + 0.02]])
    got = particle.log_likelihood(z, x, model)
    h = model.h(x)
    nu = z[:, None, :] - h
    nu[..., 1] = (nu[..., 1] + np.pi) % (2 * np.pi) - np.pi
    ref = multivariate_normal(np.zeros(2), model.R).logpdf(nu.reshape(-1, 2)).reshape(B, N)
    # equal up to the normalising constant of N(0, R)
    const = multivariate_normal(np.zeros(2), model.R).logpdf(np.zeros(2))
    np.testing.assert_allclose(got, ref - const, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("N", [50, BLAS_MOMENT_PARTICLES + 1000])
@pytest.mark.parametrize("layout", ["particle-major", "component-major"])
def test_to_gaussian_matches_weighted_np_cov(N, layout):
    rng = np.random.default_rng(18)
    B, n = 3, 4
    x = rng.standard_normal((B, N, n)) * [1.0, 5.0, 0.1, 2.0] + [1e4, -3e3, 5.0, 0.0]
    if layout == "component-major":
        x = np.ascontiguousarray(np.moveaxis(x, 2, 0)).transpose(1, 2, 0)
    log_w = normalise_log_weights(rng.standard_normal((B, N)))
    g = Particles(x, log_w).to_gaussian()
    assert isinstance(g, Gaussian)
    for b in range(B):
        w = np.exp(log_w[b])
        np.testing.assert_allclose(g.mean[b], np.average(x[b], axis=0, weights=w), rtol=1e-12)
        np.testing.assert_allclose(g.cov[b], np.cov(x[b].T, aweights=w, bias=True), rtol=1e-8, atol=1e-10)
        np.testing.assert_array_equal(g.cov[b], g.cov[b].T)
