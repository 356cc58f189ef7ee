"""The Numba CRPF step beyond paper 003's shapes: the general state path (n != 4) and runs of 1, 2 or a few
particles, each held to the NumPy twin (crpf_step_numpy), on one thread and on the threaded compilation."""

import numpy as np
import pytest

from workbench_filters.crpf.crpf_step import crpf_step, crpf_step_numpy, numba_available

pytestmark = pytest.mark.skipif(not numba_available(), reason="Numba is not installed")


def _constant_velocity(n):
    # [positions, velocities] with n // 2 of each (n odd: one extra position-like component, no velocity)
    F = np.eye(n)
    half = n // 2
    for k in range(half):
        F[k, k + half] = 1.0
    return F


def _inputs(B, N, n, seed):
    rng = np.random.default_rng(seed)
    centre = np.zeros(n)
    centre[:2] = [600.0, -300.0]
    x = centre + rng.normal(size=(B, N, n)) * np.r_[[20.0, 20.0], np.full(n - 2, 1.5)]
    c = rng.exponential(5.0, (B, N))
    s2 = rng.exponential(0.5, (B, N))
    t = rng.integers(1, 30, B).astype(float)
    d = centre[:2] + rng.normal(size=(B, 2)) * 10.0 - [2.0, 1.0]
    z = np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])], axis=1)
    shape = np.linspace(0.5, 2.0, n)
    return x, c, s2, t, z, int(rng.integers(2 ** 62)), rng.random(B), shape


@pytest.mark.parametrize("n", [2, 3, 6])
@pytest.mark.parametrize("N", [1, 2, 7, 40])
@pytest.mark.parametrize("q, beta, arc, adaptive, relative", [
    (2.0, 2.0, True, True, True),  # the paper CRPF
    (1.5, 3.0, False, False, False),
])
def test_general_state_and_few_particles_match_the_numpy_twin(n, N, q, beta, arc, adaptive, relative):
    from workbench_filters.crpf import crpf_numba

    F = _constant_velocity(n)
    x, c, s2, t, z, key, u0, shape = _inputs(B=20, N=N, n=n, seed=100 * n + N)
    args = (x, c, s2, t, F, z, key, u0, shape, 0.9, beta, 0.2, q, arc, (2.0, 1.0), adaptive, relative)
    ref = crpf_step_numpy(*args)
    saved = crpf_numba.PARALLEL_FROM
    try:
        for threshold in (10 ** 9, 1):  # every batch on one thread, then the threaded compilation where it runs
            crpf_numba.PARALLEL_FROM = threshold
            got = crpf_step(*args, backend="numba")
            for a, b in zip(ref, got):
                assert a.shape == b.shape and np.all(np.isfinite(b))
                np.testing.assert_allclose(b, a, rtol=1e-11, atol=1e-11)
    finally:
        crpf_numba.PARALLEL_FROM = saved
    if N == 1:  # one particle: it is its own parent, the estimate is that particle with zero spread
        np.testing.assert_allclose(got[3], got[0][:, 0], rtol=1e-12)
        assert np.all(got[4] == 0.0)
