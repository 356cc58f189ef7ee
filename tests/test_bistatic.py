"""Bistatic geometry (``workbench.sensing.bistatic``): the excess path, its rate, and the one Doppler sign convention.

References: the triangle inequality and the baseline, central finite differences of the bistatic range, the
ellipse of constant bistatic range, and ``c = lambda f``.
"""

import numpy as np
import pytest

from workbench.sensing.bistatic import (SPEED_OF_LIGHT, bistatic_range, bistatic_range_rate, doppler_to_range_rate,
                                        monostatic_velocity, range_and_rate, range_rate_to_doppler, wavelength)

TX = np.array([0.0, -8400.0, 420.0])
RX = np.array([0.0, 0.0, 60.0])


def test_wavelength_is_c_over_f_and_the_conversions_are_inverse_with_one_sign():
    for f in (100e6, 701e6, 2.4e9):
        assert wavelength(f) * f == pytest.approx(SPEED_OF_LIGHT)
    assert SPEED_OF_LIGHT == 299_792_458.0  # exact by the definition of the metre
    lam = wavelength(701e6)
    f = np.array([[-30.0, 0.0, 12.5]])
    np.testing.assert_allclose(range_rate_to_doppler(doppler_to_range_rate(f, lam), lam), f)
    # f_D = -Rdot / lambda: positive Doppler is a decreasing bistatic range
    assert doppler_to_range_rate(10.0, lam) == pytest.approx(-10.0 * lam)
    # the monostatic reading differs by the physical factor 1/2 only
    assert monostatic_velocity(10.0, lam) == pytest.approx(0.5 * doppler_to_range_rate(10.0, lam))


def test_bistatic_range_is_excess_path_zero_on_baseline_and_vectorised():
    on_baseline = TX + 0.3 * (RX - TX)
    assert bistatic_range(on_baseline, TX, RX) == pytest.approx(0.0, abs=1e-9)
    p = np.random.default_rng(0).uniform(-2000, 2000, (4, 5, 3))
    R = bistatic_range(p, TX, RX)
    assert R.shape == (4, 5)
    ref = np.linalg.norm(p - TX, axis=-1) + np.linalg.norm(p - RX, axis=-1) - np.linalg.norm(TX - RX)
    np.testing.assert_allclose(R, ref)
    assert np.all(R >= -1e-9)  # triangle inequality
    # [p, v] states in 2-D: range_and_rate uses the horizontal components of Tx and Rx
    states = np.concatenate([p[..., :2], np.ones((4, 5, 2))], axis=-1)
    rr = range_and_rate(states, TX, RX)
    np.testing.assert_allclose(rr[..., 0], bistatic_range(p[..., :2], TX[:2], RX[:2]))
    np.testing.assert_allclose(rr[..., 1], bistatic_range_rate(p[..., :2], np.ones(2), TX[:2], RX[:2]))


def test_points_on_an_ellipse_with_foci_tx_rx_share_one_bistatic_range():
    # 2-D ellipse with foci Tx, Rx and major axis 2a: |p - Tx| + |p - Rx| = 2a, so R = 2a - |Tx - Rx|
    tx, rx = TX[:2], RX[:2]
    c = np.linalg.norm(tx - rx) / 2
    a = c + 400.0
    b = np.sqrt(a * a - c * c)
    centre, u = (tx + rx) / 2, (rx - tx) / np.linalg.norm(rx - tx)
    v = np.array([-u[1], u[0]])
    t = np.linspace(0, 2 * np.pi, 13)
    p = centre + a * np.cos(t)[:, None] * u + b * np.sin(t)[:, None] * v
    np.testing.assert_allclose(bistatic_range(p, tx, rx), 800.0, atol=1e-6)
    # moving along the ellipse (tangent) leaves the bistatic range unchanged: zero range-rate
    tangent = -a * np.sin(t)[:, None] * u + b * np.cos(t)[:, None] * v
    np.testing.assert_allclose(bistatic_range_rate(p, tangent, tx, rx), 0.0, atol=1e-6)


def test_range_rate_equals_finite_difference_of_bistatic_range():
    rng = np.random.default_rng(1)
    p0 = rng.uniform([100, -300, 30], [900, 400, 200], (6, 3))
    v = rng.uniform(-15, 15, (6, 3))
    h = 1e-3
    fd = (bistatic_range(p0 + v * h, TX, RX) - bistatic_range(p0 - v * h, TX, RX)) / (2 * h)
    np.testing.assert_allclose(bistatic_range_rate(p0, v, TX, RX), fd, rtol=1e-6, atol=1e-7)


def test_approaching_target_has_negative_range_rate_and_positive_doppler():
    # a drone flying straight at the receiver from the east (and slightly towards the transmitter)
    p = np.array([600.0, 100.0, 60.0])
    v = -8.0 * (p - RX) / np.linalg.norm(p - RX)
    rdot = bistatic_range_rate(p, v, TX, RX)
    assert rdot < 0
    assert range_rate_to_doppler(rdot, wavelength(701e6)) > 0
