"""Radar clutter along the target's path: Poisson points with Rayleigh amplitude.

Each scan has Poisson(``rate``) clutter candidates, uniform in a cube of side ``cube`` (m) centred on
the *true* target position; candidates with altitude outside ``[z_min, z_max]`` are discarded.
Clutter power is exponential with mean ``mean_power`` (linear; Rayleigh amplitude, mean CNR
``10 log10(mean_power)`` dB), ``snr_dB = 10 log10(power)``; radial velocity ~ U(-doppler_max, doppler_max).

Only candidates whose SNR reaches ``threshold_db`` are returned.  They are drawn by thinning, which
is exact for this amplitude law: the passing count is Poisson(``rate exp(-t / mean_power)``) and,
the exponential being memoryless, a passing power is ``t + Exp(mean_power)``.  So a scan generated at
3 dB and cut at 5 dB has the same law as one generated at 5 dB.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.params import Param, defaults
from workbench.sensing.radar import clutter_pass_fraction, db, from_db
from workbench.specs import ClutterGeneratorSpec
from workbench.types import CLUTTER, InputError, Scans, Truth

PARAMETERS = (
    Param("rate", 1000.0, "mean number of candidates per scan in the cube (before the threshold)",
          unit="dimensionless", minimum=0.0, maximum=1e7),
    Param("cube", 10_000.0, "side of the cube around the true target position", unit="length", above=0.0),
    Param("z_min", 0.0, "lowest altitude of a candidate", unit="length"),
    Param("z_max", 6000.0, "highest altitude of a candidate", unit="length"),
    Param("mean_power", 2.0, "mean clutter-to-noise power ratio, linear (2 = 3 dB)", unit="dimensionless", above=0.0,
          maximum=1e30),
    Param("doppler_max", 300.0, "radial velocities are uniform in +-doppler_max", unit="speed", minimum=0.0),
    Param("threshold_db", 5.0, "SNR threshold (none keeps every candidate)", "float?", unit="decibel"),
)
PARAMS = defaults(PARAMETERS)


def intensity(**params) -> float:
    """The clutter intensity per unit ``(x, y, z, vr)`` volume inside the cube and the altitude band (m^-3 (m/s)^-1):
    ``rate P(power >= t) / (cube^3 2 doppler_max)``."""
    p = {**PARAMS, **params}
    passing = 1.0 if p["threshold_db"] is None else float(clutter_pass_fraction(p["threshold_db"], p["mean_power"]))
    return float(p["rate"] * passing / (p["cube"] ** 3 * 2.0 * p["doppler_max"])) if p["doppler_max"] > 0 else np.inf


def generate(truth: Truth, rng: np.random.Generator, **params) -> Scans:
    """Clutter detections ``z (B, T, M, 4)`` padded to the largest count, ``origin = CLUTTER``; every detection
    carries the intensity of the law it was drawn from (``clutter_density``, :func:`intensity`)."""
    unknown = set(params) - set(PARAMS)
    if unknown:
        raise InputError(f"radar-clutter: unknown parameter(s) {sorted(unknown)}; known: {sorted(PARAMS)}")
    p = {**PARAMS, **params}
    if p["rate"] < 0 or p["cube"] <= 0 or p["mean_power"] <= 0 or p["z_max"] < p["z_min"]:
        raise InputError(f"radar-clutter: need rate >= 0, cube > 0, mean_power > 0, z_max >= z_min; got {p}")
    x = truth.states
    B, T, _ = x.shape
    t_lin = 0.0 if p["threshold_db"] is None else float(from_db(p["threshold_db"]))
    # thinning: candidates passing the threshold are Poisson(rate P(power >= t))
    lam = p["rate"] * (1.0 if p["threshold_db"] is None else float(clutter_pass_fraction(p["threshold_db"],
                                                                                          p["mean_power"])))
    count = rng.poisson(lam, size=(B, T))
    M = int(count.max()) if count.size else 0
    live = np.arange(M)[None, None, :] < count[..., None]
    z = np.empty((B, T, M, 4))
    # position uniform in the cube around the true position: p = x + cube (u - 1/2)
    pos = z[..., :3]
    pos[...] = rng.random((B, T, M, 3))
    pos -= 0.5
    pos *= p["cube"]
    pos += x[:, :, None, :3]
    # discard candidates outside the altitude band
    valid = live & (pos[..., 2] >= p["z_min"]) & (pos[..., 2] <= p["z_max"])
    power = rng.exponential(p["mean_power"], size=(B, T, M))
    power += t_lin  # memoryless: t + Exp(mean)
    z[..., 3] = rng.uniform(-p["doppler_max"], p["doppler_max"], size=(B, T, M))
    density = np.broadcast_to(intensity(**p), valid.shape)
    return Scans(z, valid, truth.times, snr=db(power), doppler=z[..., 3], origin=np.full((B, T, M), CLUTTER),
                 clutter_density=density)


def _inside_band(truth: Truth, p: dict) -> np.ndarray:
    """Fraction of the cube around each true position that lies inside the altitude band, ``(B, T)``."""
    zc = truth.states[..., 2]
    half = p["cube"] / 2
    return np.clip(np.minimum(zc + half, p["z_max"]) - np.maximum(zc - half, p["z_min"]), 0.0, None) / p["cube"]


def expected_count(truth: Truth, **params) -> np.ndarray:
    """Mean clutter count per scan, ``(B, T)``: ``rate x P(power >= t) x`` the cube's share inside the band."""
    p = {**PARAMS, **params}
    passing = 1.0 if p["threshold_db"] is None else float(clutter_pass_fraction(p["threshold_db"], p["mean_power"]))
    return p["rate"] * passing * _inside_band(truth, p)


def region(truth: Truth, **params) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of every component ``[x, y, z, vr]`` per run and scan: ``(B, T, 4)`` twice."""
    p = {**PARAMS, **params}
    pos = truth.states[..., :3]
    half = p["cube"] / 2
    low = np.concatenate([pos - half, np.full(pos.shape[:2] + (1,), -p["doppler_max"])], axis=-1)
    high = np.concatenate([pos + half, np.full(pos.shape[:2] + (1,), p["doppler_max"])], axis=-1)
    low[..., 2] = np.maximum(low[..., 2], p["z_min"])
    high[..., 2] = np.minimum(high[..., 2], p["z_max"])
    return low, high


def amplitude_cdf(snr_db, **params) -> np.ndarray:
    """``P(SNR <= s)`` of a returned candidate: its power is ``t + Exp(mean_power)`` above the threshold ``t``."""
    p = {**PARAMS, **params}
    t = 0.0 if p["threshold_db"] is None else float(from_db(p["threshold_db"]))
    excess = np.maximum(from_db(np.asarray(snr_db, dtype=float)) - t, 0.0)
    return 1.0 - np.exp(-excess / p["mean_power"])


RADAR_CLUTTER = ClutterGeneratorSpec(
    name="radar-clutter",
    summary="Poisson clutter in a cube around the target, Rayleigh amplitude, uniform Doppler, SNR threshold",
    generate=generate,
    params=PARAMS,
    parameters=PARAMETERS,
    frame="position-doppler-3d",
    expected_count=expected_count,
    region=region,
    amplitude_cdf=amplitude_cdf,
)


@hookimpl
def workbench_clutter_generators():
    return [RADAR_CLUTTER]
