"""Counter-based normals (workbench.kernels.counter_normals), the float32 generator of counter_normals_numpy's
docstring: its float32 log and sine / cosine against float64 math, the normals against a plain float64
Box-Muller of hand-hashed counters, the normal law, and the Numba twin against the NumPy twin bit for bit."""

import functools
import math

import numpy as np
import pytest
from scipy.stats import kstest

from workbench.kernels.backend import numba_available
from workbench.kernels.counter_normals import counter_normals
from workbench.kernels.counter_normals_numpy import (box_muller_words, counter_normals_numpy, draw_key, log_poly,
                                                     pair_words, sincos_poly, unit24)
from workbench.rng import generator

MASK64 = 2 ** 64 - 1


def _splitmix64(state: int) -> int:
    """SplitMix64's output function on Python integers (mod 2^64), written from its published constants."""
    z = state & MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    return z ^ (z >> 31)


def _float32_ulps(got, exact):
    """|got - exact| in units of the float32 spacing at ``exact`` (float64 reference)."""
    return np.abs(got.astype(np.float64) - exact) / np.spacing(np.abs(exact).astype(np.float32)).astype(np.float64)


def test_uniform_grid_is_exact_and_log_is_within_an_ulp_of_float64_log_on_every_p():
    k = np.arange(2 ** 23, dtype=np.uint32)  # every p the generator can make
    p = unit24(k)
    assert p.dtype == np.float32
    assert np.array_equal(p.astype(np.float64), (2.0 * k + 1.0) * 2.0 ** -24)  # (2 k + 1) 2^-24, exact
    got = log_poly(p)
    assert got.dtype == np.float32
    assert np.max(_float32_ulps(got, np.log(p.astype(np.float64)))) <= 0.86  # the docstring's bound


def test_sine_and_cosine_are_within_two_ulps_of_float64_on_every_angle_fraction():
    u = unit24(np.arange(2 ** 23, dtype=np.uint32))
    quadrant = generator(0, "sincos").integers(0, 4, u.size)
    cos, sin = sincos_poly(quadrant, u)
    assert cos.dtype == np.float32 and sin.dtype == np.float32
    theta = (quadrant + u.astype(np.float64)) * (math.pi / 2)
    assert np.max(_float32_ulps(cos, np.cos(theta))) <= 1.74  # the docstring's bound
    assert np.max(_float32_ulps(sin, np.sin(theta))) <= 1.74


def test_normals_are_box_muller_of_one_hashed_counter_per_pair():
    key, rows, count = 0xDEADBEEF12345, 3, 9  # an odd count: the last pair's sine is dropped
    pairs = 5
    got = counter_normals_numpy(key, rows, count)
    assert got.shape == (rows, count) and got.dtype == np.float64
    assert np.array_equal(got.astype(np.float32).astype(np.float64), got)  # float32 values, stored exactly
    ref = np.empty((rows, 2 * pairs))
    for g in range(rows * pairs):
        w = _splitmix64(key + (g + 1) * 0x9E3779B97F4A7C15)  # one word per pair
        p = (2 * (w >> 41) + 1) / 2.0 ** 24
        u = (2 * ((w >> 16) & (2 ** 23 - 1)) + 1) / 2.0 ** 24
        theta = (((w >> 39) & 3) + u) * (math.pi / 2)
        rad = math.sqrt(-2.0 * math.log(p))
        ref.reshape(-1)[2 * g: 2 * g + 2] = rad * math.cos(theta), rad * math.sin(theta)
    # float32 arithmetic: a few float32 ulps of numbers below 6
    assert np.max(np.abs(got - ref[:, :count])) < 3e-6
    assert np.array_equal(counter_normals(key, rows, count), got)  # whichever implementation serves it
    # row b's numbers do not depend on how many rows are drawn
    assert np.array_equal(counter_normals_numpy(key, 1, count)[0], got[0])


def test_the_largest_normal_is_the_smallest_p_and_the_tail_is_cut_there():
    # k = 0 gives p = 2^-24 and rad = sqrt(48 ln 2) = 5.77; no normal is larger
    n0, n1 = box_muller_words(np.array([0, 2 ** 41 - 1], dtype=np.uint64))
    bound = math.sqrt(48.0 * math.log(2.0))
    assert abs(float(np.hypot(n0[0], n1[0])) - bound) < 1e-5
    assert float(np.hypot(n0[1], n1[1])) == pytest.approx(bound, abs=1e-5)  # the other bits do not matter
    z = counter_normals(7, 50, 20_000)
    assert np.max(np.abs(z)) <= bound + 1e-6


def test_normals_follow_the_standard_normal_law():
    # about 10^6 normals: three keys, 120 rows each of 2,800 (the moments within 5 standard errors)
    keys = [draw_key(generator(3, "normals", i)) for i in range(3)]
    z = np.concatenate([counter_normals(k, 120, 2800).ravel() for k in keys])
    n = z.size
    assert abs(z.mean()) < 5 / np.sqrt(n)
    assert abs(z.var() - 1.0) < 5 * np.sqrt(2.0 / n)
    assert abs(np.mean(z ** 3)) < 5 * np.sqrt(15.0 / n)  # skewness: E z^6 = 15
    assert abs(np.mean(z ** 4) - 3.0) < 5 * np.sqrt(96.0 / n)  # kurtosis: Var z^4 = 105 - 9
    assert kstest(z, "norm").pvalue > 1e-4
    # the two normals of a pair (cos and sin of one draw) are uncorrelated, and so are their squares
    pair_a, pair_b = z[0::2], z[1::2]
    m = pair_a.size
    assert abs(np.corrcoef(pair_a, pair_b)[0, 1]) < 5 / np.sqrt(m)
    assert abs(np.corrcoef(pair_a ** 2, pair_b ** 2)[0, 1]) < 5 / np.sqrt(m)
    # neighbouring pairs too
    for lag in (2, 3):
        assert abs(np.corrcoef(z[:-lag], z[lag:])[0, 1]) < 5 / np.sqrt(n)
    # rows and keys give other numbers: uncorrelated, not merely different
    rows = counter_normals(keys[0], 2, 200_000)
    assert abs(np.corrcoef(rows[0], rows[1])[0, 1]) < 5 / np.sqrt(200_000)
    other = counter_normals(keys[1], 2, 200_000)
    assert abs(np.corrcoef(rows[0], other[0])[0, 1]) < 5 / np.sqrt(200_000)
    assert not np.any(counter_normals(1, 2, 10) == counter_normals(2, 2, 10))


@functools.cache
def _numba_fill():
    """Every row through the Numba twin's ``row_normals_as``, by the split loops (scalar hash words, then the
    vectorised Box-Muller) or by the fused loop, rows ``first_row ..``: compiled once for all the tests below."""
    import numba

    from workbench.kernels.counter_normals_numba import row_normals_as
    from workbench.kernels.vector_width import wide_vectors

    @numba.njit
    def fill(key, out, split, first_row):
        wide_vectors()  # as row_normals compiles the split loops: vectorised
        words = np.empty(out.shape[1] // 2 + 1, dtype=np.uint64)
        for b in range(out.shape[0]):
            row_normals_as(key, first_row + b, out[b], words, split)

    return fill


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
@pytest.mark.parametrize("split", [True, False])
@pytest.mark.parametrize("count", [1, 2, 3, 8, 1001])
def test_numba_twin_gives_the_same_numbers(count, split):
    key = draw_key(generator(0, "twin"))
    out = np.empty((7, count))
    _numba_fill()(np.uint64(key), out, split, 0)
    assert np.array_equal(out, counter_normals_numpy(key, 7, count))
    assert np.array_equal(counter_normals(key, 7, count), out)  # the threaded fill_rows (the host's choice)


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
def test_numba_twin_gives_the_same_bits_on_many_words():
    # 200,000 pairs of one row: every path of the selects (flip, quadrant, the exponent's halving) many times
    key = draw_key(generator(1, "twin"))
    out = np.empty((1, 400_000))
    for split in (True, False):
        _numba_fill()(np.uint64(key), out, split, 0)
        assert np.array_equal(out, counter_normals_numpy(key, 1, 400_000)), split


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
def test_numba_twin_counters_are_exact_beyond_two_to_the_53():
    """Pair counters above 2^53 (a row far into the stream): the uint64 arithmetic of both loops, not a float."""
    key, count = 12345, 6
    b = 2 ** 53 // 3 + 7  # pairs 3 b .. 3 b + 2, counters g + 1 above 2^53
    g = np.arange(3 * b, 3 * b + 3, dtype=np.uint64)
    n0, n1 = box_muller_words(pair_words(key, g))
    ref = np.stack([n0, n1], axis=1).ravel().astype(np.float64)
    assert not np.array_equal(pair_words(key, g), pair_words(key, g.astype(float)))
    for split in (True, False):
        out = np.empty((1, count))
        _numba_fill()(np.uint64(key), out, split, b)
        assert np.array_equal(out[0], ref), split


@pytest.mark.skipif(not numba_available(), reason="Numba is not installed")
def test_numba_box_muller_computes_in_float32():
    """No float64 arithmetic in the compiled Box-Muller (a Python float constant or a math function on float32
    promotes to float64 in Numba, and the numbers would then differ from the NumPy twin's in rare cases)."""
    import re

    import numba

    from workbench.kernels.counter_normals_numba import box_muller

    @numba.njit(error_model="numpy")
    def one(w):
        return box_muller(w)

    one(np.uint64(0x0123456789ABCDEF))
    sig = one.signatures[0]
    assert str(one.nopython_signatures[0].return_type) == "UniTuple(float32 x 2)"
    ir = one.inspect_llvm()[sig]
    assert re.findall(r"\bf(?:add|sub|mul|div|neg) (?:fast )?float\b", ir)  # the float32 work is there
    assert not re.findall(r"\bf(?:add|sub|mul|div|neg) [a-z ]*double\b", ir)
    assert not re.findall(r"@(?:llvm\.)?(?:sqrt|log|sin|cos)(?:\.f64)?\(double", ir)
