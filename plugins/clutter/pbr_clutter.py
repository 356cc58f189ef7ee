"""Passive-radar clutter: false candidates of a range-Doppler map, and the zero-Doppler notch.

Generator ``pbr-false-alarms`` (per frame, per Monte Carlo run):

- zero-Doppler residue (direct path and static clutter left after cancellation): ``Poisson(3)``
  candidates with ``R ~ U(0, range_max)``, ``Rdot ~ N(0, 0.3^2)`` m/s, strong (``N(25, 3^2)`` dB);
- false alarms: ``Poisson(4)`` candidates uniform on the map, ``R ~ U(0, range_max)``,
  ``Rdot ~ U(-20, 20)`` m/s, just above the CFAR threshold: a noise cell (exponential power, unit
  mean) that exceeds the CA-CFAR threshold ``ln(1/Pfa)`` has power ``ln(1/Pfa) + Exp(1)``
  (memoryless), so its strength is ``10 log10(ln(1/Pfa) + Exp(1))`` dB (about 9.6-11 dB at ``Pfa = 1e-4``).

Remover ``pbr-zero-doppler``: drops every candidate with ``|f_D| < bins * doppler_bin_hz`` (the
zero-Doppler bins, where the direct path and static clutter live) before association.  It reads only
``doppler``, never ``origin``, and each frame's decision uses that frame alone (causal).

Doppler and range-rate follow :mod:`workbench.sensing.bistatic`: ``Rdot = -lambda f_D``.
"""

from __future__ import annotations

import numpy as np

from scipy.stats import norm

from workbench import hookimpl
from workbench.params import Param
from workbench.sensing.bistatic import range_rate_to_doppler, wavelength
from workbench.specs import ClutterGeneratorSpec, ClutterRemoverSpec
from workbench.types import CLUTTER, InputError, Scans, Truth

GENERATOR_DEFAULTS = {
    "frequency_hz": 701e6,
    "residue_rate": 3.0,
    "residue_sigma_range_rate": 0.3,
    "residue_strength_db": 25.0,
    "residue_strength_sigma_db": 3.0,
    "false_alarm_rate": 4.0,
    "false_alarm_range_rate_max": 20.0,
    "false_alarm_pfa": 1e-4,
    "range_max": 3000.0,
}

REMOVER_DEFAULTS = {
    "doppler_bin_hz": 2.0,  # 1 / CPI for a 0.5 s coherent processing interval
    "bins": 1.0,  # exclude |f_D| < bins * doppler_bin_hz
}


def _check(params: dict, defaults: dict, who: str) -> dict:
    unknown = set(params) - set(defaults)
    if unknown:
        raise InputError(f"{who}: unknown parameter(s) {sorted(unknown)}; known: {sorted(defaults)}")
    return {**defaults, **params}


def _block(counts: np.ndarray) -> tuple[np.ndarray, int]:
    """Validity mask ``(B, T, M)`` for per-frame counts ``(B, T)``, ``M = max(counts)``."""
    m = int(counts.max()) if counts.size else 0
    return np.arange(m) < counts[..., None], m


def generate(truth: Truth, rng: np.random.Generator, **params) -> Scans:
    """Zero-Doppler residue and uniform false alarms for every frame of ``truth``: ``z (B, T, M, 2)``."""
    p = _check(params, GENERATOR_DEFAULTS, "pbr-false-alarms")
    if p["residue_rate"] < 0 or p["false_alarm_rate"] < 0:
        raise InputError("pbr-false-alarms: residue_rate and false_alarm_rate must be >= 0")
    if not 0.0 < p["false_alarm_pfa"] < 1.0:
        raise InputError(f"pbr-false-alarms: false_alarm_pfa must be in (0, 1), got {p['false_alarm_pfa']}")
    B, T = truth.batch, truth.steps
    lam = wavelength(p["frequency_hz"])

    # the draws in their fixed order, each written straight into its slice of the output (3,000 full-size runs:
    # no second copy of the candidates is held)
    n_res = rng.poisson(p["residue_rate"], (B, T))
    valid_res, m_res = _block(n_res)
    z_res = np.empty((B, T, m_res, 2))
    snr_res = np.empty((B, T, m_res))
    z_res[..., 0] = rng.uniform(0.0, p["range_max"], (B, T, m_res))
    z_res[..., 1] = p["residue_sigma_range_rate"] * rng.standard_normal((B, T, m_res))
    snr_res[...] = p["residue_strength_db"] + p["residue_strength_sigma_db"] * rng.standard_normal((B, T, m_res))

    n_fa = rng.poisson(p["false_alarm_rate"], (B, T))
    valid_fa, m_fa = _block(n_fa)
    M = m_res + m_fa
    z = np.empty((B, T, M, 2))
    snr = np.empty((B, T, M))
    z[:, :, :m_res], snr[:, :, :m_res] = z_res, snr_res
    del z_res, snr_res
    z[:, :, m_res:, 0] = rng.uniform(0.0, p["range_max"], (B, T, m_fa))
    vmax = p["false_alarm_range_rate_max"]
    z[:, :, m_res:, 1] = rng.uniform(-vmax, vmax, (B, T, m_fa))
    # strength of an exponential noise cell above the threshold ln(1/Pfa): 10 log10(ln(1/Pfa) + Exp(1))
    snr[:, :, m_res:] = 10.0 * np.log10(np.log(1.0 / p["false_alarm_pfa"]) + rng.exponential(1.0, (B, T, m_fa)))
    valid = np.concatenate([valid_res, valid_fa], axis=2)
    z[~valid] = 0.0  # padding rows zeroed here, in place
    return Scans(z, valid, truth.times, snr=snr, doppler=range_rate_to_doppler(z[..., 1], lam),
                 origin=np.full(valid.shape, CLUTTER, dtype=int))


def remove_zero_doppler(scans: Scans, **params) -> Scans:
    """Keep candidates with ``|f_D| >= bins * doppler_bin_hz`` (needs ``scans.doppler``)."""
    p = _check(params, REMOVER_DEFAULTS, "pbr-zero-doppler")
    if scans.doppler is None:
        raise InputError("pbr-zero-doppler needs scans with a doppler field (Hz)")
    bad = scans.valid & ~np.isfinite(scans.doppler)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"pbr-zero-doppler: valid candidate {idx} (run, frame, row) has no Doppler value")
    # keep |f_D| >= bins * (1 / CPI)
    keep = np.abs(np.nan_to_num(scans.doppler)) >= p["bins"] * p["doppler_bin_hz"]
    return scans.with_valid(keep)


GENERATOR_PARAMETERS = (
    Param("frequency_hz", 701e6, "carrier frequency (for the Doppler of each candidate)", unit="frequency", above=0.0),
    Param("residue_rate", 3.0, "mean zero-Doppler residue candidates per frame", unit="dimensionless", minimum=0.0,
          maximum=1e6),
    Param("residue_sigma_range_rate", 0.3, "range-rate spread of the residue", unit="speed", minimum=0.0),
    Param("residue_strength_db", 25.0, "mean strength of a residue candidate", unit="decibel"),
    Param("residue_strength_sigma_db", 3.0, "strength spread of the residue", unit="decibel", minimum=0.0),
    Param("false_alarm_rate", 4.0, "mean false alarms per frame", unit="dimensionless", minimum=0.0, maximum=1e6),
    Param("false_alarm_range_rate_max", 20.0, "false-alarm range rates are uniform in +-this", unit="speed",
          minimum=0.0),
    Param("false_alarm_pfa", 1e-4, "the CA-CFAR's false-alarm probability (sets the false alarms' strength)",
          unit="dimensionless", above=0.0, maximum=1.0),
    Param("range_max", 3000.0, "range extent of the map", unit="length", above=0.0),
)
REMOVER_PARAMETERS = (
    Param("doppler_bin_hz", 2.0, "Doppler bin width (1 / CPI)", unit="frequency", above=0.0),
    Param("bins", 1.0, "drop candidates with |f_D| < bins x doppler_bin_hz", unit="dimensionless", minimum=0.0,
          maximum=1e6),
)

#: How far (in residue sigmas) the declared region reaches for the Gaussian zero-Doppler residue.
RESIDUE_REACH = 8.0


def expected_count(truth: Truth, **params) -> np.ndarray:
    """Mean candidates per frame, ``(B, T)``: ``residue_rate + false_alarm_rate``."""
    p = {**GENERATOR_DEFAULTS, **params}
    return np.full((truth.batch, truth.steps), p["residue_rate"] + p["false_alarm_rate"])


def region(truth: Truth, **params) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``[R, Rdot]``: ``R`` in ``[0, range_max]``, ``|Rdot|`` within the false alarms' range or 8 residue
    sigmas (the residue is Gaussian), ``(B, T, 2)`` twice."""
    p = {**GENERATOR_DEFAULTS, **params}
    vmax = max(p["false_alarm_range_rate_max"], RESIDUE_REACH * p["residue_sigma_range_rate"])
    shape = (truth.batch, truth.steps, 1)
    return (np.concatenate([np.zeros(shape), np.full(shape, -vmax)], axis=-1),
            np.concatenate([np.full(shape, p["range_max"]), np.full(shape, vmax)], axis=-1))


def amplitude_cdf(snr_db, **params) -> np.ndarray:
    """``P(strength <= s)``: the rate-weighted mixture of the residue's ``N(25, 3^2)`` dB and the false alarms'
    ``10 log10(ln(1/Pfa) + Exp(1))``."""
    p = {**GENERATOR_DEFAULTS, **params}
    s = np.asarray(snr_db, dtype=float)
    res = norm.cdf((s - p["residue_strength_db"]) / max(p["residue_strength_sigma_db"], 1e-300))
    fa = 1.0 - np.exp(-np.maximum(10.0 ** (s / 10.0) - np.log(1.0 / p["false_alarm_pfa"]), 0.0))
    total = p["residue_rate"] + p["false_alarm_rate"]
    if total == 0:
        return np.zeros_like(s)
    return (p["residue_rate"] * res + p["false_alarm_rate"] * fa) / total


PBR_FALSE_ALARMS = ClutterGeneratorSpec(
    name="pbr-false-alarms",
    summary="Passive-radar map clutter: zero-Doppler residue Poisson(3) + uniform false alarms Poisson(4) per frame",
    generate=generate,
    params=GENERATOR_DEFAULTS,
    parameters=GENERATOR_PARAMETERS,
    frame="bistatic-range-rate",
    expected_count=expected_count,
    region=region,
    amplitude_cdf=amplitude_cdf,
)

PBR_ZERO_DOPPLER = ClutterRemoverSpec(
    name="pbr-zero-doppler",
    summary="Drop candidates in the zero-Doppler bins (|f_D| < 1 bin) before association",
    remove=remove_zero_doppler,
    params=REMOVER_DEFAULTS,
    parameters=REMOVER_PARAMETERS,
)


@hookimpl
def workbench_clutter_generators():
    return [PBR_FALSE_ALARMS]


@hookimpl
def workbench_clutter_removers():
    return [PBR_ZERO_DOPPLER]
