"""The fused CRPF step kernel (workbench_filters.crpf.crpf_step) against its NumPy twin and the plugin's array code."""


import math

import numpy as np
import pytest

from workbench.filtering import run_filter
from workbench_filters.crpf.crpf_step import (atan2_poly, crpf_step, crpf_step_numpy, numba_available, pmf_offset,
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
    s2 = rng.exponential(0.1, (B, N))  # every particle its own propagation variance
    t = rng.integers(1, 50, B).astype(float)  # every run its own step index
    return x, c, s2, t, z, int(rng.integers(2 ** 63)), rng.random(B), np.array([0.5, 0.5, 1.0, 1.0])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("q, beta, arc, adaptive, relative", [
    (2.0, 2.0, False, False, False),  # the previous CRPF
    (1.5, 3.0, False, True, False),
    (2.0, 2.0, True, True, True),  # the paper CRPF
    (3.0, 1.0, True, False, True),
])
def test_kernel_matches_the_numpy_twin(backend, q, beta, arc, adaptive, relative):
    x, c, s2, t, z, key, u0, shape = _inputs()
    ref = crpf_step_numpy(x, c, s2, t, F, z, key, u0, shape, 0.9, beta, 0.3, q, arc, (5.0, -3.0), adaptive, relative)
    got = crpf_step(x, c, s2, t, F, z, key, u0, shape, 0.9, beta, 0.3, q, arc, (5.0, -3.0), adaptive, relative,
                    backend=backend)
    for a, b in zip(ref, got):
        assert np.allclose(a, b, rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("B, N", [(7, 64), (4, 50_000), (4096, 32)], ids=["small", "large-N", "large-B"])
@pytest.mark.parametrize("q, beta, arc, adaptive, relative", [
    (2.0, 2.0, False, False, False),  # the previous CRPF
    (2.0, 2.0, True, True, True),  # the paper CRPF
], ids=["previous", "paper"])
def test_crpf_step_on_test_arch_matches_the_numpy_twin(test_arch, B, N, q, beta, arc, adaptive, relative):
    # one run per parallel iteration: many particles in a run (its scratch row), and many runs (the launch)
    x, c, s2, t, z, key, u0, shape = _inputs(B=B, N=N, seed=9)
    args = (x, c, s2, t, F, z, key, u0, shape, 0.9, beta, 0.3, q, arc, (5.0, -3.0), adaptive, relative)
    ref = crpf_step_numpy(*args)
    got = crpf_step(*args, backend="taichi", arch=test_arch)
    for a, b in zip(ref, got):
        assert a.shape == b.shape and np.all(np.isfinite(b))
        np.testing.assert_allclose(b, a, rtol=1e-11, atol=1e-11)


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
def test_numba_serial_and_parallel_paths_agree():
    # below PARALLEL_FROM runs the kernel runs on one thread; the runs are independent, so a batch split in two
    # gives the same numbers as the whole batch (run b's normals depend on the key and b only: pass the rows of
    # the second half with their own row index by running the whole batch on each path)
    from workbench_filters.crpf import crpf_numba

    x, c, s2, t, z, key, u0, shape = _inputs(B=40, N=30, seed=4)
    args = (x, c, s2, t, F, z, key, u0, shape, 0.95, 2.0, 0.3, 2.0, True, (0.0, 0.0), True, True)
    whole = crpf_step(*args, backend="numba")
    saved = crpf_numba.PARALLEL_FROM
    try:
        crpf_numba.PARALLEL_FROM = 10 ** 9  # every batch serial
        serial = crpf_step(*args, backend="numba")
    finally:
        crpf_numba.PARALLEL_FROM = saved
    for a, b in zip(whole, serial):
        assert np.array_equal(a, b)


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
    # relative to the angle itself: within two of its own ulps everywhere (small angles included), against the C
    # library's atan2 (math.atan2: NumPy's arctan2 may dispatch to a SIMD version of a few ulps on AVX-512 CPUs)
    libm = np.array([math.atan2(b, a) for b, a in zip(y, x)])
    assert np.all(np.abs(got - libm) <= 2 * np.spacing(np.abs(libm)))
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
    _, cn, _, _, _ = crpf_step(x, np.zeros((B, 1)), np.zeros((B, 1)), 1.0, np.eye(4), z, 0, np.zeros(B), np.ones(4),
                               1.0, 2.0, 0.01, adaptive=False, relative=False, backend="numba")
    theta = atan2_poly(x[:, 0, 1], x[:, 0, 0])
    assert np.allclose(cn[:, 0], np.hypot(x[:, 0, 0], x[:, 0, 1]) ** 2 + theta ** 2, rtol=1e-14, atol=0)


def test_numpy_twin_follows_the_formulas():
    # N = 1: selection is trivial; x' = F x + shape sigma e, C' = lam C + ||z - h(x')||^q with a wrapped bearing,
    # sigma'^2 = ((t - 1) / t) sigma^2 + ||(x' - F x) / shape||^2 / (t n), written out here from Table 6
    x, c, s2, t, z, key, u0, shape = _inputs(B=5, N=1)
    xn, cn, s2n, mean, cov = crpf_step_numpy(x, c, s2, t, F, z, key, u0, shape, 0.8, 2.0, 0.01, 3.0)
    e = propagation_normals(key, 5, 1, 4)
    assert np.allclose(xn, x @ F.T + shape * np.sqrt(s2)[..., None] * e)
    assert np.allclose(s2n[:, 0], (t - 1) / t * s2[:, 0] + s2[:, 0] * np.sum(e[:, 0] ** 2, axis=1) / (4 * t))
    h = range_bearing(1.0, 1.0).h(xn[:, 0])
    dt = np.angle(np.exp(1j * (z[:, 1] - h[:, 1])))
    assert np.allclose(cn[:, 0], 0.8 * c[:, 0] + ((z[:, 0] - h[:, 0]) ** 2 + dt ** 2) ** 1.5)
    assert np.allclose(mean, xn[:, 0]) and np.allclose(cov, 0.0)
    # the fixed variance keeps the parent's
    assert np.array_equal(crpf_step_numpy(x, c, s2, t, F, z, key, u0, shape, 0.8, 2.0, 0.01, adaptive=False)[2], s2)


def test_adaptive_variance_is_the_running_mean_of_the_lineage_moves():
    # Table 6's recursion from sigma_0^2 over t = 1..T with one particle is the mean of the T squared moves / n:
    # sigma_T^2 = (1/T) sum_t ||x_t - F x_{t-1}||^2 / n, and each move has E||.||^2 = n sigma_{t-1}^2
    x, c, s2, _, z, key, u0, shape = _inputs(B=3, N=1)
    shape = np.ones(4)
    moves = []
    for t in range(1, 9):
        xn, c, s2, _, _ = crpf_step_numpy(x, c, s2, float(t), F, z, key + t, u0, shape, 0.9, 2.0, 0.01)
        moves.append(np.sum((xn[:, 0] - x[:, 0] @ F.T) ** 2, axis=1) / 4)
        x = xn
    assert np.allclose(s2[:, 0], np.mean(moves, axis=0), rtol=1e-12)


def test_relative_offset_makes_the_pmf_scale_free():
    # delta_R = delta * (mean R - min R) over the finite R: scaling every cost by k scales the offset by k, so the
    # PMF (C - min C + delta_R)^-beta, normalised, does not change; with an absolute delta it does
    _, c, *_ = _inputs(B=6, N=40, seed=2)
    assert np.allclose(pmf_offset(c, 0.3, True)[:, 0], 0.3 * (c.mean(axis=1) - c.min(axis=1)))
    assert np.allclose(pmf_offset(c, 0.3, False), 0.3)
    offsets = pmf_offset(np.array([[1.0, 1.0, 1.0], [2.0, np.inf, 4.0], [np.nan, 1.0, 2.0]]), 0.5, True)[:, 0]
    assert np.allclose(offsets, [0.5, 0.5, 0.25])  # no spread: delta itself; the mean over the finite costs only

    def pmf(costs, relative):
        w = (costs - costs.min(axis=1, keepdims=True) + pmf_offset(costs, 0.3, relative)) ** -2.0
        return w / w.sum(axis=1, keepdims=True)

    assert np.allclose(pmf(1e4 * c, True), pmf(c, True), rtol=1e-10)
    assert not np.allclose(pmf(1e4 * c, False), pmf(c, False), rtol=1e-3)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("relative", [False, True])
def test_selection_counts_and_degenerate_rows(backend, relative):
    x, c, s2, t, z, key, u0, shape = _inputs(B=4, N=50, seed=3)
    c[1, ::2] = np.inf  # infinite cost: never selected
    c[2] = np.inf  # no finite cost: uniform selection
    c[3, :] = 0.0
    c[3, 7] = -1e6  # one dominant particle: every child descends from it
    s2 = np.zeros_like(s2)  # no propagation noise: each child sits on its parent's prediction
    xn, cn, s2n, _, _ = crpf_step(x, c, s2, t, F, z, key, u0, shape, 1.0, 2.0, 0.01, relative=relative,
                                  backend=backend)
    xf = x @ F.T
    parent = np.array([[np.flatnonzero(np.all(xf[b] == xn[b, j], axis=1))[0] for j in range(50)] for b in range(4)])
    assert np.all(parent[1] % 2 == 1)
    assert np.array_equal(np.sort(parent[2]), np.arange(50))  # uniform systematic: each once
    assert np.all(parent[3] == 7)
    assert np.all(s2n == 0.0)
    # row 0: each particle drawn floor(N pi) or ceil(N pi) times with pi ~ (R - min R + delta_R)^-beta
    ref = crpf_step_numpy(x, c, s2, t, F, z, key, u0, shape, 1.0, 2.0, 0.01, relative=relative)
    assert np.allclose(ref[0], xn, rtol=1e-12)
    risk = c[0] + ((z[0, 0] - np.hypot(xf[0, :, 0], xf[0, :, 1])) ** 2
                   + np.angle(np.exp(1j * (z[0, 1] - np.arctan2(xf[0, :, 1], xf[0, :, 0])))) ** 2)
    delta = 0.01 * (risk.mean() - risk.min()) if relative else 0.01
    w = (risk - risk.min() + delta) ** -2.0
    w /= w.sum()
    k = np.bincount(parent[0], minlength=50)
    assert np.all(k >= np.floor(50 * w) - 1e-9) and np.all(k <= np.ceil(50 * w) + 1e-9)


def test_plugin_gives_the_same_run_with_and_without_the_kernel(monkeypatch):
    # the plugin takes its array code silently wherever the kernel does not apply: count the kernel's calls per
    # backend, so that two runs of the array code cannot pass for a kernel that agrees with it
    from workbench_filters import crpf as crpf_plugin

    calls = []

    def counting(*args, backend="auto", **kwargs):
        calls.append(backend)
        return crpf_step(*args, backend=backend, **kwargs)

    monkeypatch.setattr(crpf_plugin, "crpf_step", counting)
    host = load_host()
    rng = generator(0, "crpf-kernel")
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (12, 1)), random_walk_velocity(2, 1.0, 0.1), 25, rng)
    scans = host.sensor("range-bearing").simulate(truth, rng, sigma_r=1.0, sigma_theta=0.1)
    scans = Scans(scans.z, scans.valid.copy(), scans.times)
    scans.valid[3, 5] = False  # a missed detection takes the array path for that step
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 12)
    motion, model = random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1)
    for kw in (dict(), dict(variance="fixed", scale=(0.5, 0.5, 1.0, 1.0), cost="norm", delta_mode="absolute",
                            delta=0.01), dict(sigma0=0.3, delta=1.0, scale=(0.5, 0.5, 1.0, 1.0))):
        runs = {}
        for b in ["numpy"] + BACKENDS:
            calls.clear()
            runs[b] = run_filter(make_crpf(60, backend=b, **kw), prior, motion, model, scans, generator(1, "f"))
            # numpy: never the kernel; a kernel backend: every step but the first (no propagation) and the one
            # with a missed detection
            assert calls == ([] if b == "numpy" else [b] * (scans.steps - 2)), (b, calls)
        for b in BACKENDS:
            assert np.allclose(runs[b].mean, runs["numpy"].mean, rtol=1e-9, atol=1e-9)
            assert np.allclose(runs[b].cov, runs["numpy"].cov, rtol=1e-9, atol=1e-9)


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
def test_one_numba_thread_runs_the_serial_compilation_at_any_batch(monkeypatch):
    # a report worker has one Numba thread: the threaded compilation would never run anything in parallel there,
    # so it is never called (nor compiled); the numbers are the threaded path's
    import numba
    from workbench_filters.crpf import crpf_numba

    x, c, s2, t, z, key, u0, shape = _inputs(B=40, N=30, seed=4)
    args = (x, c, s2, t, F, z, key, u0, shape, 0.95, 2.0, 0.3, 2.0, True, (0.0, 0.0), True, True)
    saved = numba.get_num_threads()
    whole = crpf_step(*args, backend="numba")

    def refuse(*a):
        raise AssertionError("the threaded compilation ran on one thread")

    monkeypatch.setattr(crpf_numba, "kernel_parallel", refuse)
    monkeypatch.setattr(crpf_numba, "kernel_parallel4", refuse)
    numba.set_num_threads(1)
    try:
        serial = crpf_step(*args, backend="numba")
    finally:
        numba.set_num_threads(saved)
    for a, b in zip(whole, serial):
        assert np.array_equal(a, b)
    if saved > 1:  # more than one thread: a batch this size takes the threaded compilation
        with pytest.raises(AssertionError, match="threaded compilation ran"):
            crpf_step(*args, backend="numba")


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
@pytest.mark.parametrize("n", [4, 6])
@pytest.mark.parametrize("B", [5, 20], ids=["serial", "threaded-where-it-runs"])
def test_numba_kernel_is_picked_by_the_state_size(monkeypatch, n, B):
    # the 4-D kernels (their loops over components written out) for n == 4, the general ones otherwise, each a
    # compilation of its own: the other pair is never called (a refusing stand-in), and the numbers are the twin's
    from workbench_filters.crpf import crpf_numba

    def refuse(*a):
        raise AssertionError("the kernel of the other state size ran")

    for name in (("kernel_serial", "kernel_parallel") if n == 4 else ("kernel_serial4", "kernel_parallel4")):
        monkeypatch.setattr(crpf_numba, name, refuse)
    rng = np.random.default_rng(11)
    Fn = np.eye(n)
    Fn[:n // 2, n // 2:] = np.eye(n // 2)  # constant velocity in n / 2 dimensions, position x, y first
    x = np.r_[[100.0, 50.0], np.zeros(n - 2)] + rng.normal(size=(B, 30, n)) * np.r_[[10.0, 10.0], np.ones(n - 2)]
    c = rng.exponential(2.0, (B, 30))
    z = np.stack([np.full(B, 110.0), np.full(B, 0.4)], axis=1)
    args = (x, c, rng.exponential(0.1, (B, 30)), np.full(B, 3.0), Fn, z, 77, rng.random(B), np.linspace(0.5, 1.5, n),
            0.9, 2.0, 0.3, 2.0, True, (5.0, -3.0), True, True)
    ref = crpf_step_numpy(*args)
    got = crpf_step(*args, backend="numba")
    for a, b in zip(ref, got):
        assert a.shape == b.shape
        np.testing.assert_allclose(b, a, rtol=1e-11, atol=1e-11)
