"""``workbench bench`` group ``core`` and the fast particle-filter pieces it measures.

No timing is asserted: the benchmark must run and report every figure; the pieces made fast for it
are held to plain textbook references (``searchsorted`` resampling, ``x F^T + e G^T``, SciPy's
``logsumexp`` and Gaussian log-density, ``np.cov`` with weights).
"""

import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from workbench import bench_core
from workbench.models import random_walk_velocity, range_bearing
from workbench.plugins import load_host
from workbench.resampling import (effective_sample_size, normalise_log_weights, resample_where, systematic_counts,
                                  systematic_resample)
from workbench.types import BLAS_MOMENT_PARTICLES, Gaussian, Particles
from workbench_filters import particle

# -- the benchmark group -----------------------------------------------------------------------------


def _expected_fields(stonesoup: bool, ukf: bool) -> dict:
    """Every figure of ``core --quick`` -> ``"number"`` or the one string it may be instead."""
    fields = {"cpu_count": "number", "load_avg_1min": "number", "speedup_target": "number",
              "numpy_version": "string", "stonesoup_version": "string", "peak_rss_mib": "number",
              "group_wall_s": "number"}
    for n in bench_core.PF_SIZES["quick"]:
        for key in ("pf_ns_per_particle_step", "pf_floor_ns_per_particle_step", "pf_pos_rmse_m"):
            fields[f"{key}_N{n}"] = "number"
    for n in bench_core.PEER_SIZES:
        for key in ("stonesoup_ns_per_particle_step", "stonesoup_pos_rmse_m", "pf_over_stonesoup",
                    "pf_speedup_vs_stonesoup"):
            fields[f"{key}_N{n}"] = "number" if stonesoup else "not installed"
    fields["pf_speedup_target_met"] = "bool" if stonesoup else "not installed"
    for b in bench_core.UKF_BATCHES["quick"]:
        fields[f"ukf_ns_per_run_step_B{b}"] = "number" if ukf else "ukf not installed"
    return fields


def test_bench_quick_core_reports_every_figure(tmp_path):
    out = tmp_path / "bench.json"
    code = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", code, "bench", "--quick", "--only", "core", "--json", str(out)],
                          capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(out.read_text())
    assert report["quick"] is True and list(report["groups"]) == ["core"]
    core = report["groups"]["core"]
    assert "error" not in core, core.get("error")
    stonesoup = importlib.util.find_spec("stonesoup") is not None
    ukf = "ukf" in load_host().filters
    expected = _expected_fields(stonesoup, ukf)
    assert set(core) == set(expected), f"missing {set(expected) - set(core)}, unexpected {set(core) - set(expected)}"
    for key, kind in expected.items():
        value = core[key]
        if kind == "number":
            assert isinstance(value, (int, float)) and not isinstance(value, bool), (key, value)
            assert math.isfinite(value) and value >= 0, (key, value)
        elif kind == "bool":
            assert isinstance(value, bool), (key, value)
        elif kind == "string":
            assert isinstance(value, str) and value, (key, value)
        else:
            assert value == kind, (key, value)
    for n in bench_core.PF_SIZES["quick"]:
        assert core[f"pf_ns_per_particle_step_N{n}"] > 0
        # the filter tracks: its position error stays within a few range-noise sigmas of the truth
        assert core[f"pf_pos_rmse_m_N{n}"] < 20.0
    assert core["stonesoup_version"] != "not installed" if stonesoup else core["stonesoup_version"] == "not installed"
    if stonesoup:
        n = 100_000
        assert core[f"pf_over_stonesoup_N{n}"] == pytest.approx(1.0 / core[f"pf_speedup_vs_stonesoup_N{n}"])
        assert core["pf_speedup_target_met"] == (core[f"pf_speedup_vs_stonesoup_N{n}"] >= bench_core.SPEEDUP_TARGET)
        # Stone Soup solved the same problem: its error is of the same size as ours
        assert core[f"stonesoup_pos_rmse_m_N{n}"] < 3.0 * core[f"pf_pos_rmse_m_N{n}"] + 1.0


def test_sir_every_step_resamples_at_every_update():
    host = load_host()
    spec = bench_core.sir_every_step(host, 300)
    assert spec.params["particles"] == 300 and spec.params["threshold"] == math.inf
    truth, scans, prior, motion, model = bench_core.problem(2, 6)
    rng = np.random.default_rng(0)
    state = spec.init(prior, rng)
    assert state.cloud.particles.shape == (2, 300, 4)
    for k in range(6):
        if k:
            state = spec.predict(state, motion, rng)
        state = spec.update(state, scans.scan(k).for_filter(), model, rng)
    assert spec.diagnostics(state)["resamples"] == 2 * 6


# -- resampling ----------------------------------------------------------------------------------------


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


def _reference_sir(prior, scans, motion, model, rng, particles, threshold):
    """A textbook bootstrap PF (particle-major arrays, BLAS products, SciPy logsumexp, searchsorted
    resampling) making the same random draws in the same order as the built-in ``sir``."""
    B, n = prior.mean.shape
    N = particles
    x = prior.mean[:, None, :] + rng.standard_normal((B, N, n)) @ np.swapaxes(np.linalg.cholesky(prior.cov), 1, 2)
    log_w = np.full((B, N), -np.log(N))
    g = motion.Q_sqrt[:, np.any(motion.Q_sqrt != 0, axis=0)]
    r_inv = np.linalg.inv(model.R)
    means, covs = [], []
    for k in range(scans.steps):
        if k:
            x = x @ motion.F.T + rng.standard_normal((B, N, g.shape[1])) @ g.T
        nu = scans.z[:, k, 0][:, None, :] - model.h(x)
        nu[..., 1] = np.angle(np.exp(1j * nu[..., 1]))  # bearing wrapped to (-pi, pi]
        log_w = log_w - 0.5 * np.einsum("bni,ij,bnj->bn", nu, r_inv, nu)
        log_w = log_w - logsumexp(log_w, axis=1, keepdims=True)
        rows = np.flatnonzero(1.0 / np.sum(np.exp(2 * log_w), axis=1) < threshold * N)
        if rows.size:
            u0 = rng.random((rows.size, 1))
            for r, u in zip(rows, u0[:, 0]):
                cdf = np.cumsum(np.exp(log_w[r]))
                cdf[-1] = 1.0
                x[r] = x[r][np.searchsorted(cdf, (u + np.arange(N)) / N, side="right")]
                log_w[r] = -np.log(N)
        w = np.exp(log_w)
        means.append(np.stack([np.average(x[b], axis=0, weights=w[b]) for b in range(B)]))
        covs.append(np.stack([np.cov(x[b].T, aweights=w[b], bias=True) for b in range(B)]))
    return np.stack(means, axis=1), np.stack(covs, axis=1)


@pytest.mark.parametrize("particles, threshold", [(400, 0.5), (BLAS_MOMENT_PARTICLES + 904, 0.5), (3000, math.inf)])
def test_sir_equals_a_textbook_particle_filter_with_the_same_draws(particles, threshold):
    truth, scans, prior, motion, model = bench_core.problem(3, 8, seed=4)
    spec = particle.make_sir(particles, threshold)
    rng = np.random.default_rng(21)
    state = spec.init(prior, rng)
    means, covs = [], []
    for k in range(scans.steps):
        if k:
            state = spec.predict(state, motion, rng)
        state = spec.update(state, scans.scan(k).for_filter(), model, rng)
        est = spec.estimate(state)
        means.append(est.mean)
        covs.append(est.cov)
    ref_mean, ref_cov = _reference_sir(prior, scans, motion, model, np.random.default_rng(21), particles, threshold)
    np.testing.assert_allclose(np.stack(means, axis=1), ref_mean, rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.stack(covs, axis=1), ref_cov, rtol=1e-8, atol=1e-8)
    assert 0 < state.resamples <= 3 * 8


def test_bench_problem_is_paper_003():
    truth, scans, prior, motion, model = bench_core.problem(3, 10)
    np.testing.assert_allclose(truth.states[:, 0], np.tile(bench_core.X0, (3, 1)))
    np.testing.assert_allclose(motion.Q_sqrt[2:, 2:], 0.1 * np.eye(2))
    np.testing.assert_allclose(model.R, np.diag([1.0, 0.01]))
    assert scans.z.shape == (3, 10, 1, 2) and np.all(np.abs(scans.z[..., 1]) <= np.pi)
    # the measurements are h(truth) plus noise of the model's size
    resid = scans.z[:, :, 0] - model.h(truth.states)
    resid[..., 1] = (resid[..., 1] + np.pi) % (2 * np.pi) - np.pi
    assert np.all(np.abs(resid[..., 0]) < 6 * 1.0) and np.all(np.abs(resid[..., 1]) < 6 * 0.1)


def test_paper003_monte_carlo_figures_add_up():
    from workbench import bench_paper003
    from workbench.recipes import paper003 as recipe

    out = bench_paper003.monte_carlo_wall_time("quick")
    assert out["mc_runs_per_level"] == recipe.SIZES["quick"]["runs"] and out["mc_filters"] == len(recipe.DEFAULT_FILTERS)
    per_filter = [out[f"mc_filter_s[{name}]"] for name in recipe.DEFAULT_FILTERS]
    assert all(s > 0 for s in per_filter) and sum(per_filter) <= out["mc_wall_s"]
    assert out["mc_crpf_backend"] in ("numba", "taichi")
    assert "mc_target_met" not in out  # the target is about the full size only
