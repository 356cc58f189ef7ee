"""Counter-based normals (workbench.kernels.counter_normals): the NumPy twin against library functions and
the normal law, the Numba twin against the NumPy twin."""

import functools

import numpy as np
import pytest
from scipy.stats import kstest

from workbench.kernels.counter_normals import counter_normals
from workbench.kernels.counter_normals_numpy import (_splitmix, _unit, counter_normals_numpy, draw_key,
                                               log_poly, sincos_poly)
from workbench.kernels.backend import numba_available
from workbench.rng import generator


def test_log_and_sincos_polynomials_match_the_library_to_about_an_ulp():
    rng = np.random.default_rng(0)
    x = np.exp(rng.uniform(-745.0 + 40.0, 700.0, 200_000))
    x = np.concatenate([x, [2.0 ** -53, 0.5, 1.0 - 2.0 ** -53, 1.0, np.sqrt(2.0), np.nextafter(np.sqrt(2.0), 3.0)]])
    assert np.max(np.abs(log_poly(x) - np.log(x)) / np.maximum(np.abs(np.log(x)), 1.0)) < 4e-16
    w = np.concatenate([rng.random(200_000), [2.0 ** -53, 0.5, 1.0 - 2.0 ** -53]])
    quadrant = rng.integers(0, 4, w.size)
    cos, sin = sincos_poly(quadrant, w)
    theta = (quadrant + w) * (np.pi / 2)
    assert np.max(np.abs(cos - np.cos(theta))) < 2e-15 and np.max(np.abs(sin - np.sin(theta))) < 2e-15


def test_normals_are_box_muller_of_the_hashed_counters():
    rows, count = 3, 9  # an odd count: the last pair's sine is dropped
    pairs = 5
    g = np.arange(rows * pairs, dtype=np.uint64)
    a, c = _splitmix(11, 2 * g + 1), _splitmix(11, 2 * g + 2)
    theta = ((c >> np.uint64(62)).astype(float) + _unit(c << np.uint64(2))) * (np.pi / 2)
    rad = np.sqrt(-2.0 * np.log(_unit(a)))
    ref = np.stack([rad * np.cos(theta), rad * np.sin(theta)], axis=1).reshape(rows, 2 * pairs)[:, :count]
    got = counter_normals_numpy(11, rows, count)
    assert got.shape == (rows, count) and np.max(np.abs(got - ref)) < 1e-14
    assert np.array_equal(counter_normals(11, rows, count), got)  # whichever implementation serves it
    # row b's numbers do not depend on how many rows are drawn
    assert np.array_equal(counter_normals_numpy(11, 1, count)[0], got[0])


def test_normals_follow_the_standard_normal_law():
    z = counter_normals(draw_key(generator(3, "normals")), 400, 2500).ravel()
    n = z.size
    assert abs(z.mean()) < 5 / np.sqrt(n) and abs(z.var() - 1.0) < 5 * np.sqrt(2.0 / n)
    assert abs(np.mean(z ** 3)) < 5 * np.sqrt(15.0 / n) and abs(np.mean(z ** 4) - 3.0) < 5 * np.sqrt(96.0 / n)
    assert kstest(z, "norm").pvalue > 1e-3
    # neighbours (the two halves of a pair, consecutive pairs) are uncorrelated
    for lag in (1, 2, 3):
        assert abs(np.corrcoef(z[:-lag], z[lag:])[0, 1]) < 5 / np.sqrt(n)
    # other keys give other numbers
    assert not np.allclose(counter_normals(1, 2, 10), counter_normals(2, 2, 10))


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
        words = np.empty(out.shape[1] + 1, dtype=np.uint64)
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
def test_numba_twin_counters_are_exact_beyond_two_to_the_53():
    """Pair counters above 2^53 (a row far into the stream): the uint64 arithmetic of both loops, not a float."""
    key, count = 12345, 6
    b = 2 ** 53 // 3 + 7  # pairs 3 b .. 3 b + 2, counters 2 g + 1, 2 g + 2 above 2^54
    g = np.arange(3 * b, 3 * b + 3, dtype=np.uint64)
    a, c = _splitmix(key, 2 * g + 1), _splitmix(key, 2 * g + 2)
    rad = np.sqrt(-2.0 * log_poly(_unit(a)))
    cos, sin = sincos_poly((c >> np.uint64(62)).astype(np.int64), _unit(c << np.uint64(2)))
    ref = np.stack([rad * cos, rad * sin], axis=1).ravel()
    assert not np.array_equal(_splitmix(key, 2 * g + 1), _splitmix(key, (2 * g + 1).astype(float)))
    for split in (True, False):
        out = np.empty((1, count))
        _numba_fill()(np.uint64(key), out, split, b)
        assert np.array_equal(out[0], ref), split
