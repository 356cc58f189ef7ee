"""The active-sonar clutter generator: Poisson counts, uniform positions, Rayleigh levels, persistent sites."""

import numpy as np
import pytest

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import CLUTTER, InputError, Truth

HOST = load_host()


def _truth(runs, steps=20):
    one = piecewise_trajectory((100.0, 100.0), (4.0, 2.0), [Leg("straight", steps - 1.0)], 1.0)
    return Truth(np.repeat(one.states, runs, axis=0), one.times)


def test_sonar_clutter_rate_area_and_levels():
    gen = HOST.clutter_generator("sonar-poisson")
    truth = _truth(200)
    c = gen.generate(truth, generator(2, "clutter"), **gen.params)
    counts = c.valid.sum(axis=2)
    assert abs(counts.mean() - 31.25) < 0.3 and abs(counts.var() - 31.25) < 2.0  # Poisson(5e-4 x 62 500)
    xy = c.z[c.valid]
    assert xy.min() >= 0.0 and xy.max() <= 250.0 and np.all(c.origin == CLUTTER)
    # uniform: each quarter of the area holds a quarter of the points (5 binomial sigmas)
    quarter = np.mean((xy[:, 0] < 125.0) & (xy[:, 1] < 125.0))
    assert abs(quarter - 0.25) < 5 * np.sqrt(0.25 * 0.75 / xy.shape[0])
    power = 10.0 ** (c.snr[c.valid] / 10.0)
    assert abs(power.mean() - 10.0) < 0.15  # Rayleigh amplitude: exponential power with mean 10 dB


def test_persistent_sites_stay_put():
    gen = HOST.clutter_generator("sonar-poisson")
    truth = _truth(200)
    sur = gen.generate(truth, generator(3, "clutter"), rate_scale=2.0, persistent_sites=5, persistent_pd=0.7)
    assert abs(sur.valid.sum(axis=2).mean() - (62.5 + 3.5)) < 0.6
    sites, seen = sur.z[:, :, -5:], sur.valid[:, :, -5:]
    assert abs(seen.mean() - 0.7) < 0.01
    # each site's detections scatter around one place with the site sigma (2.0), ping after ping
    centre = np.nanmean(np.where(seen[..., None], sites, np.nan), axis=1, keepdims=True)
    spread = (sites - centre)[np.broadcast_to(seen[..., None], sites.shape)]
    assert abs(np.std(spread) - 2.0) < 0.1
    with pytest.raises(InputError, match="area"):
        gen.generate(truth, generator(0), area=(0, 0, 0, 1))
