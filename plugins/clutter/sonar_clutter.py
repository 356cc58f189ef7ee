"""Active-sonar clutter (paper 001): Poisson count, uniform positions, Rayleigh levels.

Per ping and run::

    N ~ Poisson(lambda),  lambda = rate_scale * pfa * N_cells,  N_cells = area / cell_area
    (x, y) ~ Uniform(area)
    A ~ Rayleigh with E[A^2] = 10^(mean_snr_db / 10)  ->  level = 10 log10(A^2) dB   (stored as ``snr``)

With the defaults (``pfa = 5e-4``, area ``[0, 250]^2``, unit cells) ``lambda = 31.25`` per ping.  The
clutter power ``A^2`` is exponential with mean 10 (10 dB).  The level is stored, not thresholded.

Optional persistent point clutter (the paper-001 sea-trial surrogate: static seabed features):
``persistent_sites`` positions drawn uniformly once per run, each re-detected with probability
``persistent_pd`` per ping at ``site + N(0, persistent_sigma^2 I)``, with a Rayleigh level as above.

Shapes: ``z (B, T, M, 2)``, ``valid``, ``snr``, ``origin`` ``(B, T, M)`` with ``M`` the largest count
over the batch (padding rows invalid); ``origin = CLUTTER``.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.params import AtLeast, Param
from workbench.specs import ClutterGeneratorSpec
from workbench.types import CLUTTER, InputError, Scans, Truth

DEFAULTS = {
    "pfa": 5e-4,
    "area": (0.0, 250.0, 0.0, 250.0),
    "cell_area": 1.0,
    "mean_snr_db": 10.0,
    "rate_scale": 1.0,
    "persistent_sites": 0,
    "persistent_pd": 0.7,
    "persistent_sigma": 2.0,
}


def clutter_rate(pfa: float, area, cell_area: float, rate_scale: float = 1.0) -> float:
    """``lambda = rate_scale * pfa * (area / cell_area)``: the mean clutter count per ping."""
    x0, x1, y0, y1 = (float(v) for v in area)
    return rate_scale * pfa * (x1 - x0) * (y1 - y0) / cell_area


def rayleigh_level_db(rng: np.random.Generator, shape, mean_snr_db: float) -> np.ndarray:
    """Levels in dB of Rayleigh amplitudes with mean power ``10^(mean_snr_db/10)``."""
    # A^2 ~ Exponential(mean = 10^(snr/10))  <=>  A Rayleigh with E[A^2] = 10^(snr/10)
    power = rng.exponential(10.0 ** (mean_snr_db / 10.0), size=shape)
    return 10.0 * np.log10(np.maximum(power, 1e-300))


def generate(truth: Truth, rng: np.random.Generator, pfa: float = 5e-4, area=(0.0, 250.0, 0.0, 250.0),
             cell_area: float = 1.0, mean_snr_db: float = 10.0, rate_scale: float = 1.0, persistent_sites: int = 0,
             persistent_pd: float = 0.7, persistent_sigma: float = 2.0) -> Scans:
    """Clutter detections for every run and ping of ``truth``."""
    area = tuple(float(v) for v in area)
    if len(area) != 4 or not (area[1] > area[0] and area[3] > area[2]):
        raise InputError(f"sonar-poisson: area must be (xmin, xmax, ymin, ymax) with max > min, got {area}")
    if not (pfa >= 0 and cell_area > 0 and rate_scale >= 0):
        raise InputError(f"sonar-poisson: need pfa >= 0, cell_area > 0, rate_scale >= 0; got {pfa}, {cell_area}, "
                         f"{rate_scale}")
    if int(persistent_sites) != persistent_sites or persistent_sites < 0 or not 0 <= persistent_pd <= 1 \
            or persistent_sigma < 0:
        raise InputError(f"sonar-poisson: persistent_sites must be an integer >= 0, persistent_pd in [0, 1], "
                         f"persistent_sigma >= 0; got {persistent_sites}, {persistent_pd}, {persistent_sigma}")
    B, T = truth.batch, truth.steps
    lam = clutter_rate(pfa, area, cell_area, rate_scale)
    counts = rng.poisson(lam, size=(B, T))
    M = int(counts.max()) if counts.size else 0
    lo = np.array([area[0], area[2]])
    span = np.array([area[1] - area[0], area[3] - area[2]])
    z = lo + span * rng.random((B, T, M, 2))
    valid = np.arange(M) < counts[..., None]
    level = rayleigh_level_db(rng, (B, T, M), mean_snr_db)
    S = int(persistent_sites)
    if S:
        sites = lo + span * rng.random((B, 1, S, 2))
        zs = sites + persistent_sigma * rng.standard_normal((B, T, S, 2))
        seen = rng.random((B, T, S)) < persistent_pd
        z = np.concatenate([z, zs], axis=2)
        valid = np.concatenate([valid, seen], axis=2)
        level = np.concatenate([level, rayleigh_level_db(rng, (B, T, S), mean_snr_db)], axis=2)
    return Scans(z, valid, truth.times, snr=level, origin=np.full(valid.shape, CLUTTER))


PARAMETERS = (
    Param("pfa", 5e-4, "false-alarm probability per resolution cell", unit="dimensionless", minimum=0.0, maximum=1.0),
    Param("area", (0.0, 250.0, 0.0, 250.0), "surveillance area (xmin, xmax, ymin, ymax)", "vector", unit="length",
          length=4),
    Param("cell_area", 1.0, "area of one resolution cell", unit="area", above=0.0),
    Param("mean_snr_db", 10.0, "mean clutter level (Rayleigh amplitude)", unit="decibel"),
    Param("rate_scale", 1.0, "factor on the clutter rate", unit="dimensionless", minimum=0.0, maximum=1e6),
    Param("persistent_sites", 0, "stationary clutter sites per run (e.g. wrecks, rocks)", "int", unit="dimensionless",
          minimum=0, maximum=10**6),
    # these two shape the clutter only where there is at least one site
    Param("persistent_pd", 0.7, "probability that a site is seen per ping", unit="dimensionless", minimum=0.0,
          maximum=1.0, when={"persistent_sites": AtLeast(1)}),
    Param("persistent_sigma", 2.0, "position noise of a site's detections", unit="length", minimum=0.0,
          when={"persistent_sites": AtLeast(1)}),
)

#: How far (in site sigmas) the declared region reaches beyond the area for the persistent sites' detections.
SITE_REACH = 8.0


def expected_count(truth: Truth, **params) -> np.ndarray:
    """Mean clutter count per ping, ``(B, T)``: ``pfa x cells x rate_scale + persistent_sites x persistent_pd``."""
    p = {**DEFAULTS, **params}
    lam = clutter_rate(p["pfa"], p["area"], p["cell_area"], p["rate_scale"])
    return np.full((truth.batch, truth.steps), lam + int(p["persistent_sites"]) * p["persistent_pd"])


def region(truth: Truth, **params) -> tuple[np.ndarray, np.ndarray]:
    """The area (widened by 8 site sigmas when there are persistent sites), ``(B, T, 2)`` twice."""
    p = {**DEFAULTS, **params}
    x0, x1, y0, y1 = (float(v) for v in p["area"])
    reach = SITE_REACH * p["persistent_sigma"] if int(p["persistent_sites"]) else 0.0
    shape = (truth.batch, truth.steps, 2)
    return (np.broadcast_to([x0 - reach, y0 - reach], shape).copy(),
            np.broadcast_to([x1 + reach, y1 + reach], shape).copy())


def amplitude_cdf(level_db, **params) -> np.ndarray:
    """``P(level <= s)`` of Rayleigh amplitudes: ``1 - exp(-10^(s/10) / 10^(mean/10))``."""
    p = {**DEFAULTS, **params}
    power = 10.0 ** (np.asarray(level_db, dtype=float) / 10.0)
    return 1.0 - np.exp(-power / 10.0 ** (p["mean_snr_db"] / 10.0))


SONAR_POISSON = ClutterGeneratorSpec(
    name="sonar-poisson",
    summary="Active-sonar clutter: Poisson(pfa x cells) uniform points, Rayleigh levels; optional persistent sites",
    generate=generate,
    params=DEFAULTS,
    parameters=PARAMETERS,
    frame="cartesian-2d",
    expected_count=expected_count,
    region=region,
    amplitude_cdf=amplitude_cdf,
)


@hookimpl
def workbench_clutter_generators():
    return [SONAR_POISSON]
