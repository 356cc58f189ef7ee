"""The fused CRPF step kernel (workbench.kernels.crpf_step) against its NumPy twin and the plugin's array code."""

import numpy as np
import pytest

from workbench.filtering import run_filter
from workbench.kernels.crpf_step import (atan2_poly, crpf_step, crpf_step_numpy, numba_available,
                                        propagation_normals)
from workbench.models import random_walk_velocity, range_bearing
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, Scans
from workbench_filters.crpf import make_crpf

BACKENDS = ["taichi"] + (["numba"] if numba_available() else [])
F = random_walk_velocity(2, 1.0, 0.1).F


def _inputs(B=7, N=64, seed=0):
    rng = np.random.default_rng(seed)
    x = np.array([100.0, 50.0, -1.0, 1.0]) + rng.normal(size=(B, N, 4)) * [10.0, 10.0, 2.0, 2.0]
    c = rng.exponential(2.0, (B, N))
    z = np.stack([np.full(B, 110.0), np.full(B, 3.1)], axis=1) + rng.normal(size=(B, 2)) * [1.0, 0.1]
    z[:, 1] = np.angle(np.exp(1j * z[:, 1]))  # bearings near +-pi: the residual must wrap
    x[:, :, 1] *= np.sign(rng.normal(size=(B, N)))  # particles on both sides of the -x axis
    return x, c, z, int(rng.integers(2 ** 63)), rng.random(B), np.sqrt(0.1) * np.array([0.5, 0.5, 1.0, 1.0])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("q, beta, arc", [(2.0, 2.0, False), (1.5, 3.0, False), (2.0, 2.0, True), (3.0, 1.0, True)])
def test_kernel_matches_the_numpy_twin(backend, q, beta, arc):
    x, c, z, key, u0, std = _inputs()
    ref = crpf_step_numpy(x, c, F, z, key, u0, std, 0.9, beta, 0.01, q, arc, sensor=(5.0, -3.0))
    got = crpf_step(x, c, F, z, key, u0, std, 0.9, beta, 0.01, q, arc, sensor=(5.0, -3.0), backend=backend)
    for a, b in zip(ref, got):
        assert np.allclose(a, b, rtol=1e-11, atol=1e-11)


def test_polynomial_atan2_matches_the_library_to_an_ulp_or_two():
    rng = np.random.default_rng(5)
    y = rng.normal(size=200_000) * np.exp(rng.normal(size=200_000) * 6)
    x = rng.normal(size=200_000) * np.exp(rng.normal(size=200_000) * 6)
    edges = np.array([0.0, 1.0, -1.0, 1e-300, 1e300, np.tan(np.pi / 8), 1.0 - 1e-16])
    y = np.concatenate([y, np.repeat(edges, edges.size), -np.repeat(edges, edges.size)])
    x = np.concatenate([x, np.tile(edges, edges.size), -np.tile(edges, edges.size)])
    ref = np.arctan2(y, x)
    got = atan2_poly(y, x)
    assert np.max(np.abs(got - ref)) <= 2 * np.spacing(np.pi)
    assert np.all(np.abs(got) <= np.pi)
    assert np.array_equal(np.signbit(got), np.signbit(ref))  # signed zeros: atan2(-0, -1) = -pi


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
def test_kernel_atan2_is_the_numpy_twin_of_the_polynomial():
    # N = 1 and zero noise: the cost is (z_r - |x|)^2 + wrap(z_t - atan2(x_y, x_x))^2, the kernel's atan2
    B = 4000
    rng = np.random.default_rng(6)
    x = np.zeros((B, 1, 4))
    x[:, 0, :2] = rng.normal(size=(B, 2)) * np.exp(rng.normal(size=(B, 1)) * 4)
    z = np.zeros((B, 2))
    _, cn, _, _ = crpf_step(x, np.zeros((B, 1)), np.eye(4), z, 0, np.zeros(B), np.zeros(4), 1.0, 2.0, 0.01,
                            backend="numba")
    theta = atan2_poly(x[:, 0, 1], x[:, 0, 0])
    assert np.allclose(cn[:, 0], np.hypot(x[:, 0, 0], x[:, 0, 1]) ** 2 + theta ** 2, rtol=1e-14, atol=0)


def test_numpy_twin_follows_the_formulas():
    # N = 1: selection is trivial; x' = F x + std e, C' = lam C + ||z - h(x')||^q with a wrapped bearing
    x, c, z, key, u0, std = _inputs(B=5, N=1)
    xn, cn, mean, cov = crpf_step_numpy(x, c, F, z, key, u0, std, 0.8, 2.0, 0.01, 3.0)
    assert np.allclose(xn, x @ F.T + std * propagation_normals(key, 5, 1, 4))
    h = range_bearing(1.0, 1.0).h(xn[:, 0])
    dt = np.angle(np.exp(1j * (z[:, 1] - h[:, 1])))
    assert np.allclose(cn[:, 0], 0.8 * c[:, 0] + ((z[:, 0] - h[:, 0]) ** 2 + dt ** 2) ** 1.5)
    assert np.allclose(mean, xn[:, 0]) and np.allclose(cov, 0.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_selection_counts_and_degenerate_rows(backend):
    x, c, z, key, u0, std = _inputs(B=4, N=50, seed=3)
    c[1, ::2] = np.inf  # infinite cost: never selected
    c[2] = np.inf  # no finite cost: uniform selection
    c[3, :] = 0.0
    c[3, 7] = -1e6  # one dominant particle: every child descends from it
    std0 = np.zeros(4)
    xn, cn, _, _ = crpf_step(x, c, F, z, key, u0, std0, 1.0, 2.0, 0.01, backend=backend)
    xf = x @ F.T
    parent = np.array([[np.flatnonzero(np.all(xf[b] == xn[b, j], axis=1))[0] for j in range(50)] for b in range(4)])
    assert np.all(parent[1] % 2 == 1)
    assert np.array_equal(np.sort(parent[2]), np.arange(50))  # uniform systematic: each once
    assert np.all(parent[3] == 7)
    # row 0: each particle drawn floor(N pi) or ceil(N pi) times with pi ~ (R - min R + delta)^-beta
    ref = crpf_step_numpy(x, c, F, z, key, u0, std0, 1.0, 2.0, 0.01)
    assert np.allclose(ref[0], xn, rtol=1e-12)
    risk = c[0] + ((z[0, 0] - np.hypot(xf[0, :, 0], xf[0, :, 1])) ** 2
                   + np.angle(np.exp(1j * (z[0, 1] - np.arctan2(xf[0, :, 1], xf[0, :, 0])))) ** 2)
    w = (risk - risk.min() + 0.01) ** -2.0
    w /= w.sum()
    k = np.bincount(parent[0], minlength=50)
    assert np.all(k >= np.floor(50 * w) - 1e-9) and np.all(k <= np.ceil(50 * w) + 1e-9)


def test_plugin_gives_the_same_run_with_and_without_the_kernel():
    host = load_host()
    rng = generator(0, "crpf-kernel")
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (12, 1)), random_walk_velocity(2, 1.0, 0.1), 25, rng)
    scans = host.sensor("range-bearing").simulate(truth, rng, sigma_r=1.0, sigma_theta=0.1)
    scans = Scans(scans.z, scans.valid.copy(), scans.times)
    scans.valid[3, 5] = False  # a missed detection takes the array path for that step
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 12)
    motion, model = random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1)
    for kw in (dict(scale=(0.5, 0.5, 1.0, 1.0)), dict(cost="arc-length", kappa=10.0)):
        runs = {b: run_filter(make_crpf(60, backend=b, **kw), prior, motion, model, scans, generator(1, "f"))
                for b in ["numpy"] + BACKENDS}
        for b in BACKENDS:
            assert np.allclose(runs[b].mean, runs["numpy"].mean, rtol=1e-9, atol=1e-9)
            assert np.allclose(runs[b].cov, runs["numpy"].cov, rtol=1e-9, atol=1e-9)
