"""Radar clutter along the target's path (paper 000): Poisson points with Rayleigh amplitude.

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
from workbench.radar import clutter_pass_fraction, db, from_db
from workbench.specs import ClutterGeneratorSpec
from workbench.types import CLUTTER, InputError, Scans, Truth

PARAMS = {
    "rate": 1000.0,  # lambda_c: mean number of candidates per scan in the cube
    "cube": 10_000.0,  # side of the cube around the target (m)
    "z_min": 0.0,
    "z_max": 6000.0,
    "mean_power": 2.0,  # mean clutter-to-noise ratio, linear (3 dB)
    "doppler_max": 300.0,  # m/s
    "threshold_db": 5.0,  # SNR threshold; None keeps every candidate
}


def generate(truth: Truth, rng: np.random.Generator, **params) -> Scans:
    """Clutter detections ``z (B, T, M, 4)`` padded to the largest count, ``origin = CLUTTER``."""
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
    u = rng.random((B, T, M, 3)) - 0.5
    pos = x[:, :, None, :3] + p["cube"] * u
    # discard candidates outside the altitude band
    valid = live & (pos[..., 2] >= p["z_min"]) & (pos[..., 2] <= p["z_max"])
    power = t_lin + rng.exponential(p["mean_power"], size=(B, T, M))  # memoryless: t + Exp(mean)
    vr = rng.uniform(-p["doppler_max"], p["doppler_max"], size=(B, T, M))
    z = np.concatenate([pos, vr[..., None]], axis=-1)
    return Scans(z, valid, truth.times, snr=db(power), doppler=vr, origin=np.full((B, T, M), CLUTTER))


RADAR_CLUTTER = ClutterGeneratorSpec(
    name="radar-clutter",
    summary="Poisson clutter in a cube around the target, Rayleigh amplitude, uniform Doppler, SNR threshold",
    generate=generate,
    params=PARAMS,
)


@hookimpl
def workbench_clutter_generators():
    return [RADAR_CLUTTER]
