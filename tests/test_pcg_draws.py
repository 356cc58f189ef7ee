"""NumPy's normals drawn inside the linear models' compiled particle passes (workbench/kernels/particle_numba.py
through workbench/kernels/pcg_numba.py): on PCG64 the generator's state stepped in registers, held to NumPy's own
``Generator.standard_normal`` bit for bit (the same numbers in the same order, the generator left where NumPy leaves
it); and the predicted state's estimate taken inside the range-bearing pass, held to ``estimate`` (the moments
kernel) bit for bit and to NumPy's weighted moments."""

import importlib.util

import numpy as np
import pytest

from workbench import particle_core as core
from workbench.kernels.backend import using
from workbench.models import random_walk_velocity, range_bearing
from workbench.types import Particles

needs_numba = pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed")


def _generators(bits):
    """Two generators in the same state: PCG64 (also one holding a waiting 32-bit half) or Philox (drawn by NumPy
    before the particle kernels, which copy the normals)."""
    def make():
        if bits == "philox":
            return np.random.Generator(np.random.Philox(5))
        rng = np.random.default_rng(5)
        if bits == "pcg64 holding a 32-bit half":
            rng.integers(0, 2**32, size=1, dtype=np.uint32)
        return rng
    return make(), make()


def _spy(monkeypatch):
    """Records the length of the stream words each compiled pass got (4: PCG64 in registers, 0: Numba's
    Generator)."""
    from workbench.kernels import particle_numba

    seen = []
    real = particle_numba.pcg64_stream

    def spy(*args, **kwargs):
        cm = real(*args, **kwargs)

        class Wrap:
            def __enter__(self):
                words = cm.__enter__()
                seen.append(words.shape[0])
                return words

            def __exit__(self, *exc):
                return cm.__exit__(*exc)
        return Wrap()

    monkeypatch.setattr(particle_numba, "pcg64_stream", spy)
    return seen


@needs_numba
@pytest.mark.parametrize("bits", ["pcg64", "pcg64 holding a 32-bit half", "philox"])
def test_the_range_bearing_pass_draws_numpys_normals_bit_for_bit(bits, monkeypatch):
    # a plan whose rows are the noise itself (out_j = e_j, coefficient 1: exact), so the moved particles are the
    # draws; 3 x 2,500 x 4 = 30,000 normals (above PCG_MIN_DRAWS), enough to reach the ziggurat's wedges and tail
    from workbench.kernels import particle_numba as k

    seen = _spy(monkeypatch)
    B, N, n = 3, 2500, 4
    matrix = np.hstack([np.zeros((n, n)), np.eye(n)])
    plan = core._plan_arrays(matrix.tobytes(), *matrix.shape)
    x = np.zeros((n, B * N))
    out, log_w, top = np.empty((n, B * N)), np.empty((B, N)), np.full(B, -1.0)
    prev = np.full((B, N), -np.log(N))
    a, b = _generators(bits)
    k.propagate_range_bearing(out, x, a, n, *plan, np.array([True, False, True]), np.array([[10.0, 0.1]] * B),
                              np.zeros(2), np.eye(2), prev, log_w, top)
    assert seen == [0 if bits == "philox" else 4]
    e = b.standard_normal((B, N, n))
    assert np.abs(e).max() > 3.6  # the tail (beyond the ziggurat's last box, 3.44) was reached
    np.testing.assert_array_equal(out.reshape(n, B, N), e.transpose(2, 0, 1))
    assert repr(a.bit_generator.state) == repr(b.bit_generator.state)  # left where NumPy leaves it
    assert a.random() == b.random()


@needs_numba
@pytest.mark.parametrize("bits", ["pcg64", "philox"])
def test_propagate_and_the_floor_draw_numpys_normals_bit_for_bit(bits, monkeypatch):
    from workbench.kernels import particle_numba as k

    seen = _spy(monkeypatch)
    a, b = _generators(bits)
    got = k.fill_normals(a, np.empty((6000, 2)))
    np.testing.assert_array_equal(got, b.standard_normal((6000, 2)))
    # propagate: x + G e with G = 0.5 I (products and sums of the plan, one rounding each: NumPy's the same way)
    motion = random_walk_velocity(2, 1.0, 0.5)
    matrix, kk = core._propagation(motion)
    x = np.random.default_rng(3).normal(size=(4, 7000))
    out = np.empty_like(x)
    k.propagate(out, x, a, kk, *core._plan_arrays(matrix.tobytes(), *matrix.shape))
    ref = core.combine_columns(np.empty((7000, 4)), matrix, np.ascontiguousarray(x.T), b.standard_normal((7000, kk)))
    np.testing.assert_array_equal(out.T, ref)
    assert seen == [0, 0] if bits == "philox" else seen == [4, 4]
    assert repr(a.bit_generator.state) == repr(b.bit_generator.state)


@needs_numba
@pytest.mark.parametrize("weights", ["equal", "unequal", "unequal, the heaviest in the last tile"])
def test_the_predicted_estimate_taken_in_the_pass_is_the_estimates_bit_for_bit(weights):
    B, N = 3, 2600  # N not a multiple of the 1,024-particle tile
    rng = np.random.default_rng(2)
    x = core.component_major(B, N, 4)
    x[...] = rng.normal(size=(B, N, 4)) * [30.0, 30.0, 2.0, 2.0] + [1e3, 500.0, -1.0, 1.0]  # far from the origin
    prev = np.full((B, N), -np.log(N))
    if weights != "equal":
        prev = rng.normal(size=(B, N)) * 2.0
        if weights == "unequal, the heaviest in the last tile":
            prev[:, 2500] = 12.0  # the moments' pivot is the heaviest particle
        prev -= np.log(np.exp(prev).sum(axis=1, keepdims=True))
    state = core.ParticleState(Particles.trusted(x, prev))
    motion, model = random_walk_velocity(2, 1.0, 0.3), range_bearing(2.0, 0.05)
    z, present = np.array([[1.1e3, 0.4], [1.2e3, 0.5], [1.1e3, 0.45]]), np.array([True, False, True])
    a, b = np.random.default_rng(8), np.random.default_rng(8)
    with using("cpu"):
        moved, log_w, top, before = core.predict_log_weights(state, motion, a, z, present, model, "numba",
                                                             predicted_estimate=True)
        three = core.predict_log_weights(state, motion, b, z, present, model, "numba")
        ref = core.estimate(core.ParticleState(Particles.trusted(moved, prev)), "numba")
    np.testing.assert_array_equal(moved, three[0])
    np.testing.assert_array_equal(log_w, three[1])
    np.testing.assert_array_equal(before.mean, ref.mean)
    np.testing.assert_array_equal(before.cov, ref.cov)
    # and against NumPy's weighted moments (an independent formula: two passes about the mean)
    w = np.exp(prev)
    for i in range(B):
        mu = np.einsum("n,nj->j", w[i], moved[i]) / w[i].sum()
        d = moved[i] - mu
        np.testing.assert_allclose(before.mean[i], mu, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(before.cov[i], np.einsum("n,nj,nk->jk", w[i], d, d) / w[i].sum(), rtol=1e-9,
                                   atol=1e-9)


@needs_numba
def test_the_pass_refuses_an_estimate_it_cannot_take():
    from workbench.kernels import particle_numba as k

    B, N = 2, 10
    with pytest.raises(ValueError, match="planar state"):
        k.propagate_range_bearing(np.empty((5, B * N)), np.zeros((5, B * N)), np.random.default_rng(0), 0,
                                  *core._plan_arrays(np.eye(5).tobytes(), 5, 5), np.ones(B, bool), np.zeros((B, 2)),
                                  np.zeros(2), np.eye(2), np.zeros((B, N)), np.empty((B, N)), np.empty(B),
                                  np.empty((B, 5)), np.empty((B, 5, 5)))
