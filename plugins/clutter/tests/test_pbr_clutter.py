"""The passive-radar clutter plugins: ``pbr-false-alarms`` (zero-Doppler residue + CFAR false alarms) and the
``pbr-zero-doppler`` notch.

References: Poisson means, the uniform distribution on the map, the exponential-cell law of a false alarm's
strength (a Kolmogorov-Smirnov bound against the declared ``amplitude_cdf``), and exact set arithmetic for the
notch.
"""

from dataclasses import replace

import numpy as np
import pytest

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.sensing.bistatic import range_rate_to_doppler, wavelength
from workbench.types import CLUTTER, InputError, Truth

LAM = wavelength(701e6)


@pytest.fixture(scope="module")
def host():
    return load_host()


def _truth(B=300, T=40):
    return Truth(np.zeros((B, T, 6)), 0.5 * np.arange(T))


def test_rates_regions_and_labels(host):
    gen = host.clutter_generator("pbr-false-alarms")
    truth = _truth()
    cl = gen.generate(truth, generator(4, "c"), false_alarm_rate=1.2, false_alarm_range_rate_max=50.0)
    counts = cl.valid.sum(axis=2)
    n = counts.size
    assert counts.mean() == pytest.approx(4.2, abs=4 * np.sqrt(4.2 / n))  # Poisson(3) + Poisson(1.2)
    assert counts.var() == pytest.approx(4.2, rel=0.1)  # a Poisson count: variance = mean
    np.testing.assert_allclose(gen.expected_count(truth, false_alarm_rate=1.2), 4.2)
    assert np.all(cl.origin[cl.valid] == CLUTTER)
    z = cl.z[cl.valid]
    lo, hi = gen.region(truth, false_alarm_range_rate_max=50.0)
    assert np.all(z >= lo[0, 0]) and np.all(z <= hi[0, 0])
    np.testing.assert_allclose(cl.doppler[cl.valid], range_rate_to_doppler(z[:, 1], LAM))
    fa = np.abs(z[:, 1]) > 2.0  # away from the residue: the false alarms, uniform on +-50 m/s
    assert fa.mean() == pytest.approx(1.2 / 4.2 * (1 - 4.0 / 100.0), abs=0.02)
    assert np.mean(z[fa, 0]) == pytest.approx(1500.0, rel=0.03)


def test_strengths_follow_the_declared_amplitude_cdf(host):
    gen = host.clutter_generator("pbr-false-alarms")
    cl = gen.generate(_truth(200, 20), generator(5, "c"))
    s = np.sort(cl.snr[cl.valid])
    ecdf = np.arange(1, s.size + 1) / s.size
    ks = np.max(np.abs(ecdf - gen.amplitude_cdf(s)))
    assert ks < 1.63 / np.sqrt(s.size)  # Kolmogorov-Smirnov at 1 %
    # a false alarm is an exponential cell above ln(1/Pfa): never below the threshold
    fa = cl.snr[cl.valid][np.abs(cl.z[..., 1][cl.valid]) > 3.0]
    assert fa.min() >= 10 * np.log10(np.log(1e4)) - 1e-9


def test_zero_doppler_notch_is_exact_and_causal(host):
    gen = host.clutter_generator("pbr-false-alarms")
    cl = gen.generate(_truth(), generator(6, "c"))
    remover = host.clutter_remover("pbr-zero-doppler")
    kept = remover.remove(replace(cl, origin=None), doppler_bin_hz=2.0)  # never needs origin
    assert np.all(np.abs(kept.doppler[kept.valid]) >= 2.0)
    assert kept.valid.sum() == (cl.valid & (np.abs(cl.doppler) >= 2.0)).sum()
    # the residue (Rdot ~ N(0, 0.3^2), |f_D| < 2 Hz unless |Rdot| > 0.855 m/s) almost never survives
    wide = remover.remove(cl, doppler_bin_hz=2.0, bins=3.0)
    assert np.all(np.abs(wide.doppler[wide.valid]) >= 6.0)
    # causal: each frame's decision uses that frame alone
    half = remover.remove(replace(cl, z=cl.z[:, :20], valid=cl.valid[:, :20], times=cl.times[:20],
                                  snr=cl.snr[:, :20], doppler=cl.doppler[:, :20], origin=cl.origin[:, :20]),
                          doppler_bin_hz=2.0)
    np.testing.assert_array_equal(half.valid, kept.valid[:, :20])


def test_bad_input_is_one_clear_error(host):
    gen = host.clutter_generator("pbr-false-alarms")
    with pytest.raises(InputError, match="unknown parameter"):
        gen.generate(_truth(2, 2), generator(0), rate=3.0)
    with pytest.raises(InputError, match="false_alarm_pfa"):
        gen.generate(_truth(2, 2), generator(0), false_alarm_pfa=2.0)
    cl = gen.generate(_truth(2, 2), generator(0))
    remover = host.clutter_remover("pbr-zero-doppler")
    with pytest.raises(InputError, match="doppler"):
        remover.remove(replace(cl, doppler=None))
