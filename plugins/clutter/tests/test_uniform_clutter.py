"""The uniform clutter generator against its closed forms: Poisson counts (mean and variance equal to the declared
rate), each component uniform over its declared bounds (Kolmogorov-Smirnov against the uniform cdf written here),
Rayleigh levels, and every configured value (frame, bounds with units, rate) honoured or refused by name."""

import math
import re

import numpy as np
import pytest
from scipy import stats

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.testing.clutter import run_generator_checks
from workbench.types import CLUTTER, InputError, Truth

HOST = load_host()
SPEC = HOST.clutter_generator("uniform-clutter")


def _truth(runs: int, steps: int) -> Truth:
    # the generator never reads the states; any (B, T, 4) truth serves
    return Truth(np.zeros((runs, steps, 4)), np.arange(steps, dtype=float))


def _points(scans):
    return scans.z[scans.valid]


def test_it_is_installed_and_declares_its_frame():
    assert SPEC.detection_frame() == "cartesian-2d"
    assert SPEC.configure(frame="range-bearing").detection_frame() == "range-bearing"


def test_counts_are_poisson_with_the_declared_rate():
    spec = SPEC.configure(rate=7.5)
    scans = spec.generate(_truth(100, 40), generator(5, "uniform-clutter-test", "counts"))
    counts = scans.valid.sum(axis=2).ravel()
    n = counts.size  # 4,000 scans
    # mean 7.5 +- sqrt(7.5 / 4000) = 0.043; sample variance of a Poisson(7.5): 7.5 +- sqrt((2 lam^2 + lam) / n) = 0.17
    assert abs(counts.mean() - 7.5) < 4 * math.sqrt(7.5 / n)
    assert abs(counts.var(ddof=1) - 7.5) < 4 * math.sqrt((2 * 7.5**2 + 7.5) / n)
    # the whole distribution: chi-square goodness of fit against the Poisson pmf, bins 0..15 and a tail bin
    k = np.arange(16)
    expected = np.append(stats.poisson.pmf(k, 7.5), stats.poisson.sf(15, 7.5)) * n
    observed = np.append(np.bincount(np.minimum(counts, 16), minlength=17)[:16], (counts >= 16).sum())
    assert stats.chisquare(observed, expected).pvalue > 1e-3
    assert np.array_equal(spec.expected_count(_truth(2, 3)), np.full((2, 3), 7.5))


@pytest.mark.parametrize("frame, bounds", [
    ("cartesian-2d", {"x": (-200.0, 300.0), "y": (1000.0, 1100.0)}),
    ("range-bearing", {"range": (1000.0, 4500.0), "bearing": (-1.3, 0.5)}),
])
def test_each_component_is_uniform_over_its_declared_bounds(frame, bounds):
    spec = SPEC.configure(frame=frame, rate=20.0, **bounds)
    scans = spec.generate(_truth(20, 30), generator(6, "uniform-clutter-test", frame))
    z = _points(scans)
    assert z.shape[0] > 10_000 and z.shape[1] == 2
    for i, (lo, hi) in enumerate(bounds.values()):
        assert z[:, i].min() >= lo and z[:, i].max() <= hi
        # KS against U(lo, hi): cdf (s - lo) / (hi - lo)
        p = stats.kstest(z[:, i], lambda s, lo=lo, hi=hi: np.clip((s - lo) / (hi - lo), 0.0, 1.0)).pvalue
        assert p > 1e-3, (frame, i, p)
    # the two components are drawn independently: their correlation is within 4 standard errors of 0
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 4 / math.sqrt(z.shape[0])
    assert np.all(scans.origin[scans.valid] == CLUTTER)
    # density per unit measurement volume: rate / the region's volume
    volume = np.prod([hi - lo for lo, hi in bounds.values()])
    assert np.allclose(scans.clutter_density[scans.valid], 20.0 / volume)


def test_levels_are_rayleigh_with_the_declared_mean_power():
    spec = SPEC.configure(mean_snr_db=6.0)
    scans = spec.generate(_truth(20, 30), generator(7, "uniform-clutter-test", "levels"))
    power = 10.0 ** (scans.snr[scans.valid] / 10.0)
    # the power A^2 of a Rayleigh amplitude is exponential: KS against Exp(mean 10^0.6)
    assert stats.kstest(power, stats.expon(scale=10.0**0.6).cdf).pvalue > 1e-3


def test_bounds_are_read_with_their_units():
    spec = SPEC.configure(frame="range-bearing", range=("1 km", "4.5 km"), bearing=("-75 deg", "30 deg"))
    low, high = spec.region(_truth(1, 1))
    assert np.allclose(low, [1000.0, math.radians(-75.0)]) and np.allclose(high, [4500.0, math.radians(30.0)])
    z = _points(spec.generate(_truth(5, 10), generator(8, "uniform-clutter-test", "units")))
    assert np.all((z >= low) & (z <= high))


def test_the_kit_passes_in_the_range_bearing_frame_too():
    spec = SPEC.configure(frame="range-bearing", range=(500.0, 3000.0), bearing=(-2.0, 2.5), rate=3.0)
    outcomes = run_generator_checks(spec)
    failed = [o for o in outcomes if o.status != "passed"]
    assert outcomes and not failed, failed


@pytest.mark.parametrize("values, words", [
    ({"x": (10.0, 10.0)}, "x must be (low, high) with low < high"),
    ({"y": (5.0, -5.0)}, "y must be (low, high) with low < high"),
    ({"frame": "range-bearing", "range": (3000.0, 1000.0)}, "range must be (low, high)"),
    ({"frame": "range-bearing", "bearing": (0.5, -0.5)}, "bearing must be (low, high)"),
])
def test_an_empty_region_is_refused_by_name(values, words):
    spec = SPEC.configure(**values)
    with pytest.raises(InputError, match=re.escape(words)):
        spec.generate(_truth(2, 3), generator(1, "uniform-clutter-test", "refused"))


@pytest.mark.parametrize("values, words", [
    ({"frame": "cartesian-3d"}, "frame"),
    ({"bearing": (-4.0, 0.0)}, "bearing"),
    ({"range": (-1.0, 10.0)}, "range"),
    ({"rate": -1.0}, "rate"),
    ({"x": ("1 s", "2 s")}, "x"),
    ({"region": (0.0, 1.0)}, "region"),
])
def test_bad_values_are_refused_where_they_come_in(values, words):
    with pytest.raises(InputError, match=words):
        SPEC.configure(**values)
