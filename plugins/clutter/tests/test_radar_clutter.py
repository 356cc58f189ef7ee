"""The ``radar-clutter`` generator: Poisson counts thinned at the threshold, Rayleigh amplitude (exponential power),
uniform Doppler, the altitude band, and the intensity each detection carries."""

import numpy as np
import pytest
from scipy import integrate

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.sensing.radar import exponential_power_log_density, from_db
from workbench.types import CLUTTER, Truth


@pytest.fixture(scope="module")
def gen():
    return load_host().clutter_generator("radar-clutter")


def _truth(runs=50, steps=40):
    return Truth(np.broadcast_to([20e3, 0.0, 3e3, 0, 0, 0], (runs, steps, 6)).copy(), np.arange(float(steps)))


def test_counts_power_and_doppler(gen):
    truth = _truth()
    wide = gen.generate(truth, generator(0, "clutter"), z_min=-1e9, z_max=1e9)
    per_scan = wide.valid.sum(axis=2)
    # 1000 candidates, P(power >= 5 dB) = exp(-10^0.5 / 2)
    mean = 1000 * np.exp(-from_db(5.0) / 2)
    assert per_scan.mean() == pytest.approx(mean, abs=3 * np.sqrt(mean / per_scan.size) + 0.5)
    assert per_scan.var() == pytest.approx(mean, rel=0.1)  # Poisson
    snr = wide.snr[wide.valid]
    assert snr.min() >= 5.0
    # memoryless thinning: P(power >= 7 dB | power >= 5 dB) = exp(-(10^0.7 - 10^0.5) / 2)
    assert np.mean(snr >= 7.0) == pytest.approx(np.exp(-(from_db(7.0) - from_db(5.0)) / 2), abs=0.01)
    pos = wide.z[wide.valid][:, :3] - [20e3, 0.0, 3e3]
    assert np.all(np.abs(pos) <= 5000.0) and np.all(wide.origin[wide.valid] == CLUTTER)
    assert np.abs(wide.doppler[wide.valid]).max() <= 300.0
    np.testing.assert_array_equal(wide.doppler[wide.valid], wide.z[wide.valid][:, 3])
    band = gen.generate(truth, generator(0, "clutter"))
    kept = band.z[band.valid][:, 2]
    assert kept.min() >= 0.0 and kept.max() <= 6000.0
    assert band.valid.sum(axis=2).mean() == pytest.approx(mean * 0.6, rel=0.03)  # z in [-2, 8] km, band 0..6


def test_declared_count_region_and_amplitude_law_match_the_draws(gen):
    truth = _truth(runs=200, steps=10)
    scans = gen.generate(truth, generator(1, "clutter"))
    count = gen.expected_count(truth, **gen.params)
    assert scans.valid.sum(axis=2).mean() == pytest.approx(count.mean(), rel=0.02)
    low, high = gen.region(truth, **gen.params)
    inside = (scans.z >= low[:, :, None, :]) & (scans.z <= high[:, :, None, :])
    assert np.all(inside.all(axis=-1)[scans.valid])
    # the intensity each detection carries is the declared count over the declared region's volume
    density = count / np.prod(high - low, axis=-1)
    np.testing.assert_allclose(scans.clutter_density[scans.valid],
                               np.broadcast_to(density[..., None], scans.valid.shape)[scans.valid], rtol=1e-12)
    assert density[0, 0] == pytest.approx(1000 * np.exp(-from_db(5.0) / 2) / 1e12 / 600.0, rel=1e-12)
    # the amplitude law: the declared CDF, the core's exponential-power density and the drawn SNRs agree
    s = scans.snr[scans.valid]
    for q in (6.0, 8.0, 10.0):
        cdf = float(gen.amplitude_cdf(np.array(q), **gen.params))
        assert np.mean(s <= q) == pytest.approx(cdf, abs=0.01)
        area, _ = integrate.quad(lambda v: np.exp(exponential_power_log_density(v, 2.0, 5.0)), 5.0, q)
        assert area == pytest.approx(cdf, rel=1e-8)


def test_generated_at_a_lower_threshold_and_cut_is_the_same_law(gen):
    truth = _truth(runs=100, steps=20)
    low = gen.generate(truth, generator(2, "clutter"), threshold_db=3.0)
    cut = low.valid & (np.nan_to_num(low.snr, nan=-np.inf) >= 5.0)
    direct = gen.generate(truth, generator(3, "clutter"), threshold_db=5.0)
    assert cut.sum(axis=2).mean() == pytest.approx(direct.valid.sum(axis=2).mean(), rel=0.03)
    assert np.mean(low.snr[cut] >= 8.0) == pytest.approx(np.mean(direct.snr[direct.valid] >= 8.0), abs=0.015)
