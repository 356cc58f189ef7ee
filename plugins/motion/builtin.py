"""The built-in motion models, registered as a plugin through the entry point ``motion_models`` (group
``workbench``), exactly as a third-party plugin registers its own.

Each model declares its parameters once (name, default, unit dimension, range), how many position axes its state
has, and a typical start state for the filter kit's truths.  Scenario files and references name them with their
parameters: ``"cv2d(sigma_a=0.5)"``, ``"ct(omega=3 deg/s)"``, ``"ct-rate(sigma_omega=0.01)"``.
"""

from __future__ import annotations

import math

from workbench import hookimpl
from workbench.models import (constant_acceleration, constant_velocity, coordinated_turn, coordinated_turn_rate,
                              growth_model, random_walk_velocity, singer)
from workbench.params import Param
from workbench.specs import MotionModelSpec
from workbench.types import InputError

_SIGMA_A = Param("sigma_a", 0.5, "standard deviation of the white-noise acceleration", unit="acceleration",
                 minimum=0.0)


def _cv(dims: int):
    def build(dt, sigma_a):
        return constant_velocity(dims, dt, sigma_a)
    return build


def _rwv(dims: int):
    def build(dt, sigma_v):
        return random_walk_velocity(dims, dt, sigma_v)
    return build


def _ca(dims: int):
    def build(dt, sigma_j):
        return constant_acceleration(dims, dt, sigma_j)
    return build


def _singer(dims: int):
    def build(dt, sigma_m, tau):
        return singer(dims, dt, sigma_m, tau)
    return build


def _ct(dt, omega, sigma_a):
    return coordinated_turn(dt, omega, sigma_a)


def _ct_rate(dt, sigma_a, sigma_omega):
    return coordinated_turn_rate(dt, sigma_a, sigma_omega)


def _growth(dt, sigma_v):
    model = growth_model(sigma_v)
    if abs(dt - model.dt) > 1e-9 * model.dt:
        raise InputError(f"motion model 'growth' is a discrete-time model with steps of {model.dt:g} (one time "
                         f"index per step), got dt = {dt:g}")
    return model


def _position(dims: int, axes: int):
    """A typical start state with ``axes`` blocks of ``dims`` components (positions, velocities, accelerations) and
    its spread: 300 m, 200 m (100 m up), moving at (-3, 4, 1) m/s, not accelerating."""
    blocks = [(300.0, 200.0, 100.0), (-3.0, 4.0, 1.0), (0.0, 0.0, 0.0)][:axes]
    spread = [5.0, 2.0, 0.5][:axes]
    return (tuple(v for block in blocks for v in block[:dims]), tuple(s for s in spread for _ in range(dims)))


def _spec(name, summary, build, parameters, dims, layout):
    state, std = layout
    return MotionModelSpec(name, summary, build, params={p.name: p.default for p in parameters},
                           parameters=tuple(parameters), dims=dims, example_state=state, example_std=std)


def _specs() -> list[MotionModelSpec]:
    sigma_v = Param("sigma_v", 0.1, "standard deviation of each step's velocity increment", unit="speed",
                    minimum=0.0)
    sigma_j = Param("sigma_j", 0.1, "amplitude of the continuous white-noise jerk (its spectral density is "
                    "sigma_j^2)", unit="jerk_noise", minimum=0.0)
    sigma_m = Param("sigma_m", 1.0, "standard deviation of the manoeuvre acceleration (Singer)",
                    unit="acceleration", minimum=0.0)
    tau = Param("tau", 20.0, "manoeuvre time constant (the acceleration's correlation time)", unit="time",
                above=0.0)
    omega = Param("omega", math.radians(3.0), "the known turn rate (positive: anticlockwise)", unit="angular_rate",
                  minimum=-math.pi, maximum=math.pi)
    sigma_omega = Param("sigma_omega", 0.01, "amplitude of the turn rate's continuous random walk (its spectral "
                        "density is sigma_omega^2)", unit="angular_rate_noise", minimum=0.0)
    sigma_growth = Param("sigma_v", math.sqrt(10.0), "standard deviation of the process noise", unit="state",
                         minimum=0.0)
    # a target at 25 m/s turning at 0.1 rad/s (2.5 m/s^2, far beyond sigma_a): a filter that ignores the turn lags
    turn_state = ((1000.0, 600.0, -15.0, 20.0, 0.1), (10.0, 10.0, 2.0, 2.0, 0.02))
    out = []
    for dims in (2, 3):
        out.append(_spec(f"cv{dims}d", f"constant velocity in {dims}-D, discrete white-noise acceleration",
                         _cv(dims), (_SIGMA_A,), dims, _position(dims, 2)))
    out.append(_spec("rwv2d", "2-D random-walk velocity (exact zero position noise)", _rwv(2), (sigma_v,), 2,
                     _position(2, 2)))
    for dims in (2, 3):
        out.append(_spec(f"ca{dims}d", f"constant acceleration in {dims}-D, white-noise jerk", _ca(dims), (sigma_j,),
                         dims, _position(dims, 3)))
    for dims in (2, 3):
        out.append(_spec(f"singer{dims}d", f"Singer manoeuvre model in {dims}-D (exponentially correlated "
                         f"acceleration)", _singer(dims), (sigma_m, tau), dims, _position(dims, 3)))
    out.append(_spec("ct", "coordinated turn at a known rate (linear, 4-D)", _ct, (omega, _SIGMA_A), 2,
                     _position(2, 2)))
    out.append(_spec("ct-rate", "coordinated turn with the turn rate in the state (nonlinear, 5-D)", _ct_rate,
                     (_SIGMA_A, sigma_omega), 2, turn_state))
    out.append(_spec("growth", "univariate growth model of Gordon, Salmond & Smith (1993), time-varying", _growth,
                     (sigma_growth,), None, ((0.1,), (math.sqrt(5.0),))))
    return out


@hookimpl
def workbench_motion_models():
    return _specs()
