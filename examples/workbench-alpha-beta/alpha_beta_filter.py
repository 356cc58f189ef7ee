"""An alpha-beta filter: a fixed-gain tracker, written as a third-party workbench plugin.

Per axis, with sampling time T::

    predict   p- = p + T v               v- = v
    update    p  = p- + alpha (z - p-)   v  = v- + (beta / T) (z - p-)

The gain is fixed, so the filter is cheaper than a Kalman filter but not optimal.  Its covariance is
still exact for the gain used: the Joseph form ``P = (I - K H) P- (I - K H)^T + K R K^T`` holds for any
gain, so the reported covariance (and hence NEES) stays honest.

Measurements: positions (a linear model with ``H = [I 0]``), or range and bearing, which are converted
to a Cartesian position with the linearised conversion covariance.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.linalg import joseph_update, symmetrise
from workbench.models import converted_covariance, polar_to_cartesian, require_linear
from workbench.params import Param
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError


def init(prior, rng=None):
    return prior


def predict(state, motion, rng=None):
    F = require_linear(motion, "alpha-beta")  # the transition matrix, or a named refusal of a nonlinear model
    return Gaussian(state.mean @ F.T, symmetrise(F @ state.cov @ F.T + motion.Q))


def _position_measurement(z, model, d):
    """Cartesian position ``(B, d)`` and its covariance ``(B, d, d)`` from the sensor's measurement."""
    if model.H is not None:
        if not np.allclose(model.H, np.eye(d, 2 * d)):
            raise InputError(f"alpha-beta needs position measurements (H = [I 0]); model {model.name!r} measures "
                             "something else")
        return z, np.broadcast_to(model.R, (z.shape[0], d, d))
    if d == 2 and model.frame == "range-bearing":
        sensor = model.sensor_position or (0.0, 0.0)
        sigma_r, sigma_b = model.stated_std
        cov = converted_covariance(z[:, 0], z[:, 1], sigma_r, sigma_b)
        return polar_to_cartesian(z, sensor), cov
    raise InputError(f"alpha-beta cannot use measurement model {model.name!r}: it takes positions or range-bearing")


def update(state, scan, model, rng=None, alpha=0.5, beta=0.2, dt=1.0):
    z, present = single_measurement(scan, "alpha-beta")
    if not present.any():
        return state
    d = state.dim // 2
    pos, R = _position_measurement(z, model, d)
    H = np.eye(d, 2 * d)
    # K = [alpha I; (beta / T) I]: the fixed gain of the alpha-beta filter
    K = np.vstack([alpha * np.eye(d), (beta / dt) * np.eye(d)])
    mean = state.mean + (pos - state.mean[:, :d]) @ K.T
    cov = joseph_update(state.cov, np.broadcast_to(K, (state.batch, 2 * d, d)), H, R)
    return Gaussian(keep_where(present, mean, state.mean), keep_where(present, cov, state.cov))


PARAMETERS = (
    Param("alpha", 0.5, "position gain", unit="dimensionless", above=0.0, maximum=1.0),
    Param("beta", 0.2, "velocity gain (times T); stable for beta < 4 - 2 alpha", unit="dimensionless", above=0.0,
          maximum=2.0),
    Param("dt", 1.0, "sampling time T the velocity gain is scaled by", unit="time", above=0.0),
)


def make_alpha_beta(alpha: float = 0.5, beta: float = 0.2, dt: float = 1.0) -> FilterSpec:
    if not (0 < alpha < 1 and 0 < beta < 4 - 2 * alpha):
        raise InputError(f"alpha-beta gains outside the stable region: alpha={alpha}, beta={beta}")
    return FilterSpec(
        name="alpha-beta",
        summary=f"Alpha-beta fixed-gain tracker (alpha={alpha}, beta={beta})",
        init=init,
        predict=predict,
        update=partial(update, alpha=alpha, beta=beta, dt=dt),
        estimate=lambda state: state,
        capabilities=frozenset({"gaussian"}),
        params={"alpha": alpha, "beta": beta, "dt": dt},
        parameters=PARAMETERS,
        build=make_alpha_beta,
    )


@hookimpl
def workbench_filters():
    return [make_alpha_beta()]
