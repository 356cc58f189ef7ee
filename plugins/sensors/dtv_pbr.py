"""DTV passive bistatic radar (paper 002), detection level: one target candidate per frame with P_D.

The measurement is ``z = [R, Rdot]``: bistatic range (excess path, m) and bistatic range-rate (m/s),
with ``Rdot = -lambda f_D`` (positive Doppler = approaching, see :mod:`workbench.sensing.bistatic`).  The
scans also carry ``doppler`` (Hz, the same sign convention) and ``snr`` (candidate strength, dB).

Truth states are ``[p, v]`` in local ENU metres (2-D ``[x, y, vx, vy]`` or 3-D ``[x, y, z, vx, vy, vz]``).
Measurement model on the filter state ``[R, Rdot]``:
``z = I_2 x + v``, ``v ~ N(0, diag(sigma_R^2, sigma_Rdot^2))``; the motion model that goes with it is
:func:`workbench.models.range_rate_model`.
"""

from __future__ import annotations


import numpy as np

from workbench import hookimpl
from workbench.sensing.bistatic import range_and_rate, range_rate_to_doppler, wavelength
from workbench.models import MeasurementModel, linear_measurement
from workbench.params import Param
from workbench.specs import SensorSpec
from workbench.types import InputError, Scans, Truth

#: Defaults from the paper-002 brief: Hwangryeongsan transmitter ~8.4 km south of the PNU receiver.
DEFAULTS = {
    "tx": (0.0, -8400.0, 420.0),
    "rx": (0.0, 0.0, 60.0),
    "frequency_hz": 701e6,
    "pd": 0.9,
    "sigma_range": 15.0,  # simulated candidate noise (m)
    "sigma_range_rate": 0.4,  # simulated candidate noise (m/s)
    "model_sigma_range": 15.0,  # filter R (m), about half a 30 m range bin
    "model_sigma_range_rate": 0.5,  # filter R (m/s), about half a Doppler bin at CPI 0.5 s
    "strength_db": 18.0,  # mean target candidate strength (dB above the CFAR noise estimate)
    "strength_sigma_db": 2.0,
    "range_max": 3000.0,  # range-Doppler map extent: 0..range_max (m)
    "range_rate_max": 50.0,  # and +-range_rate_max (m/s)
}


def _params(params: dict) -> dict:
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise InputError(f"dtv-pbr: unknown parameter(s) {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    out = {**DEFAULTS, **params}
    if not 0.0 <= out["pd"] <= 1.0:
        raise InputError(f"dtv-pbr: pd must be in [0, 1], got {out['pd']}")
    for key in ("sigma_range", "sigma_range_rate", "model_sigma_range", "model_sigma_range_rate"):
        if out[key] < 0:
            raise InputError(f"dtv-pbr: {key} must be >= 0, got {out[key]}")
    return out


def measurement_model(**params) -> MeasurementModel:
    """``z = x + v`` on the state ``[R, Rdot]`` with ``R = diag(sigma_R^2, sigma_Rdot^2)``."""
    p = _params(params)
    # R_cov = diag(sigma_R^2, sigma_Rdot^2)
    return linear_measurement(np.eye(2), np.diag([p["model_sigma_range"] ** 2, p["model_sigma_range_rate"] ** 2]),
                              name="bistatic-range-rate", frame="bistatic-range-rate",
                              std=(p["model_sigma_range"], p["model_sigma_range_rate"]))


def simulate(truth: Truth, rng: np.random.Generator, **params) -> Scans:
    """The target candidate of every frame: ``(B, T, 1, 2)``, detected with probability ``pd``.

    A target outside the range-Doppler map (``R`` not in ``[0, range_max]`` or ``|Rdot| > range_rate_max``)
    is not detected.
    """
    p = _params(params)
    lam = wavelength(p["frequency_hz"])
    x = range_and_rate(truth.states, p["tx"], p["rx"])
    B, T, _ = x.shape
    noise = rng.standard_normal((B, T, 2)) * np.array([p["sigma_range"], p["sigma_range_rate"]])
    z = x + noise
    detected = rng.random((B, T)) < p["pd"]
    inside = (x[..., 0] >= 0.0) & (x[..., 0] <= p["range_max"]) & (np.abs(x[..., 1]) <= p["range_rate_max"])
    strength = p["strength_db"] + p["strength_sigma_db"] * rng.standard_normal((B, T))
    valid = (detected & inside)[..., None]
    return Scans(z[:, :, None, :], valid, truth.times,
                 snr=strength[..., None],
                 doppler=range_rate_to_doppler(z[..., 1], lam)[..., None],
                 origin=np.zeros((B, T, 1), dtype=int))


def truth_to_state(states: np.ndarray, **params) -> np.ndarray:
    """The model's state ``[R, Rdot]`` of truth states ``[p, v]`` (2-D or 3-D), ``(..., 2)``."""
    p = _params(params)
    return range_and_rate(states, p["tx"], p["rx"])


def noise_cov(truth: Truth, scans: Scans, **params) -> np.ndarray:
    """The simulated candidate noise ``diag(sigma_range^2, sigma_range_rate^2)``, ``(2, 2)``; the filters' ``R`` uses
    ``model_sigma_range`` and ``model_sigma_range_rate`` instead (about half a range and a Doppler bin)."""
    p = _params(params)
    return np.diag([p["sigma_range"] ** 2, p["sigma_range_rate"] ** 2])


PARAMETERS = (
    # the model [R, Rdot] = I x + v takes no geometry: tx, rx (simulation and truth_to_state) and the carrier (the
    # simulated Doppler) shape the simulation; a recorded file's reader checks them against its own metadata
    Param("tx", DEFAULTS["tx"], "transmitter position (x, y, z)", "vector", unit="length", length=3,
          affects="simulation"),
    Param("rx", DEFAULTS["rx"], "receiver position (x, y, z)", "vector", unit="length", length=3,
          affects="simulation"),
    Param("frequency_hz", 701e6, "carrier frequency of the illuminator", unit="frequency", above=0.0,
          affects="simulation"),
    Param("pd", 0.9, "probability that the target's candidate is reported per frame", unit="dimensionless",
          minimum=0.0, maximum=1.0, affects="simulation"),
    Param("sigma_range", 15.0, "simulated candidate range noise", unit="length", minimum=0.0, affects="simulation"),
    Param("sigma_range_rate", 0.4, "simulated candidate range-rate noise", unit="speed", minimum=0.0,
          affects="simulation"),
    Param("model_sigma_range", 15.0, "range sigma of the filters' R (about half a 30 m range bin)", unit="length",
          above=0.0, affects="noise"),
    Param("model_sigma_range_rate", 0.5, "range-rate sigma of the filters' R (about half a Doppler bin)",
          unit="speed", above=0.0, affects="noise"),
    Param("strength_db", 18.0, "mean target candidate strength above the CFAR noise estimate", unit="decibel",
          affects="simulation"),
    Param("strength_sigma_db", 2.0, "candidate strength spread", unit="decibel", minimum=0.0, affects="simulation"),
    Param("range_max", 3000.0, "range extent of the range-Doppler map (0 .. range_max)", unit="length", above=0.0,
          affects="simulation"),
    Param("range_rate_max", 50.0, "range-rate extent of the map (+-range_rate_max)", unit="speed", above=0.0,
          affects="simulation"),
)

DTV_PBR = SensorSpec(
    name="dtv-pbr",
    summary="DTV passive bistatic radar (701 MHz): bistatic range and range-rate candidates with P_D",
    measurement_model=measurement_model,
    simulate=simulate,
    params=DEFAULTS,
    parameters=PARAMETERS,
    frame="bistatic-range-rate",
    truth_to_state=truth_to_state,
    noise_cov=noise_cov,
)


@hookimpl
def workbench_sensors():
    return [DTV_PBR]
