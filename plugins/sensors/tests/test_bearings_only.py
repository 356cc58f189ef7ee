"""The built-in bearings-only sensor: it passes the sensor kit through ``workbench check-plugin``, draws bearings with
the declared (and the configured) spread and detection probability, its Jacobian is the derivative of its ``h``,
and its residuals wrap across +-pi."""

import math

import numpy as np
import pytest
from scipy import stats

from workbench.cli import check_plugin
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.types import InputError, Truth

HOST = load_host()
SENSOR = HOST.sensor("bearings-only")
SENSOR_AT = (150.0, -40.0)


def _truth(B=50, T=40, seed=1, centre=SENSOR_AT):
    """Straight paths 200 m to 20 km from ``centre``, every direction, [x, y, vx, vy]."""
    rng = np.random.default_rng(seed)
    r = np.exp(rng.uniform(np.log(200.0), np.log(20e3), B))
    a = rng.uniform(-np.pi, np.pi, B)
    p0 = np.asarray(centre) + np.stack([r * np.cos(a), r * np.sin(a)], -1)
    v = rng.normal(0.0, 10.0, (B, 2))
    t = np.arange(T, dtype=float)
    pos = p0[:, None, :] + v[:, None, :] * t[None, :, None]
    return Truth(np.concatenate([pos, np.broadcast_to(v[:, None, :], pos.shape)], -1), t)


def _bearings(states, s):
    """Reference bearing, written out: atan2 of the offset from the sensor (math convention)."""
    return np.arctan2(states[..., 1] - s[1], states[..., 0] - s[0])


def _two_sided_chi2_p(total, dof):
    return 2.0 * min(stats.chi2.cdf(total, dof), stats.chi2.sf(total, dof))


def test_it_passes_the_sensor_kit_through_check_plugin(capsys):
    assert check_plugin(HOST, "bearings-only") == 0
    out = capsys.readouterr().out
    assert "6 passed, 0 failed" in out and "'bearing' detections of dimension 1" in out


@pytest.mark.parametrize("sigma", [None, "2 deg"])
def test_simulated_bearings_have_the_declared_spread_and_detection_probability(sigma):
    spec = SENSOR.configure(position=SENSOR_AT) if sigma is None else \
        SENSOR.configure(position=SENSOR_AT, sigma_theta=sigma, pd=0.6)
    sd = spec.params["sigma_theta"]
    pd = spec.params["pd"]
    assert sd == (0.01 if sigma is None else pytest.approx(math.radians(2.0)))
    truth = _truth()
    scans = spec.simulate(truth, generator(3, "bearings-only-test"))
    assert scans.z.shape == (50, 40, 1, 1) and scans.valid.shape == (50, 40, 1)
    valid = scans.valid[..., 0]
    n = int(valid.sum())
    # detection probability: the count is Binomial(B T, pd)
    p_count = stats.binomtest(n, valid.size, pd).pvalue
    assert p_count > 1e-3, (n, valid.size, pd, p_count)
    # spread: sum of (wrapped residual / sigma)^2 over the detections is chi-square(n)
    r = np.angle(np.exp(1j * (scans.z[..., 0, 0] - _bearings(truth.states, SENSOR_AT))))[valid]
    total = float(np.sum((r / sd) ** 2))
    assert _two_sided_chi2_p(total, n) > 1e-3, (total, n)
    assert abs(r.mean()) < 4 * sd / math.sqrt(n)
    # a spread 20 % off is far outside the test (what the test would catch)
    assert _two_sided_chi2_p(float(np.sum((r / (1.2 * sd)) ** 2)), n) < 1e-6
    # the published model carries the same sigma and position
    model = spec.measurement_model()
    assert model.R.tolist() == [[sd * sd]] and model.sensor_position == SENSOR_AT and model.frame == "bearing"


def test_h_and_jacobian_against_hand_values_and_central_differences():
    model = SENSOR.configure(position=SENSOR_AT).measurement_model()
    sx, sy = SENSOR_AT
    # hand values: north-east, due west (+pi), due south
    pts = np.array([[sx + 5.0, sy + 5.0, 1.0, 2.0], [sx - 3.0, sy, 0.0, 0.0], [sx, sy - 7.0, 0.0, 0.0]])
    assert model.h(pts)[:, 0] == pytest.approx([math.pi / 4, math.pi, -math.pi / 2])
    x = _truth(B=20, T=1, seed=5).states[:, 0, :]
    jac = model.jacobian(x)
    assert jac.shape == (20, 1, 4)
    eps = 1e-3
    numeric = np.zeros((20, 1, 4))
    for j in range(4):
        d = np.zeros(4)
        d[j] = eps
        numeric[:, :, j] = model.residual(model.h(x + d), model.h(x - d)) / (2 * eps)
    assert np.allclose(jac, numeric, rtol=1e-6, atol=1e-12)
    assert np.all(jac[:, 0, 2:] == 0.0)  # no dependence on the velocity
    # at the sensor itself the bearing has no derivative: NaN, not a number that looks like one
    at_sensor = model.jacobian(np.array([[sx, sy, 0.0, 0.0]]))[0, 0]
    assert np.isnan(at_sensor[:2]).all() and np.all(at_sensor[2:] == 0.0)


def test_bearings_near_pi_wrap_and_residuals_wrap_them():
    # targets due west of the sensor, so the true bearing is +-pi and noisy bearings straddle the cut
    spec = SENSOR.configure(position=SENSOR_AT, sigma_theta=0.05, pd=1.0)
    B, T = 40, 25
    x = np.zeros((B, T, 4))
    x[..., 0] = SENSOR_AT[0] - 1000.0
    x[..., 1] = SENSOR_AT[1] + np.linspace(-1.0, 1.0, B)[:, None]  # within 1 mrad of the cut
    truth = Truth(x, np.arange(T, dtype=float))
    z = spec.simulate(truth, generator(4, "bearings-only-wrap")).z[..., 0, 0]
    assert np.all((z > -math.pi) & (z <= math.pi))
    assert (z > 3.0).any() and (z < -3.0).any()  # both sides of the cut
    model = spec.measurement_model()
    r = model.residual(z[..., None], model.h(x))[..., 0]
    assert np.abs(r).max() < 6 * 0.05  # wrapped: no 2 pi jumps
    assert np.abs(z - model.h(x)[..., 0]).max() > 6.0  # the plain difference has them
    # the angle-aware mean of bearings around the cut lies at the cut, not near 0
    m = model.mean(z.reshape(1, -1, 1), np.full(B * T, 1.0 / (B * T)))[0, 0]
    assert abs(abs(m) - math.pi) < 0.01


def test_wrong_values_are_refused_by_name():
    with pytest.raises(InputError, match="sigma_theta"):
        SENSOR.configure(sigma_theta="1 m")
    with pytest.raises(InputError, match="pd"):
        SENSOR.configure(pd=1.5)
    with pytest.raises(InputError, match="position"):
        SENSOR.configure(position=(0.0, float("nan")))
    with pytest.raises(InputError, match="x, y first"):
        SENSOR.simulate(Truth(np.zeros((2, 3, 1)), np.arange(3.0)), generator(1, "x"))
