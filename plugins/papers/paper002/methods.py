"""Paper 002's trackers: nearest-neighbour tracks of one filter on the range / range-rate candidates (without and
with a gate) and the ablation's monostatic range-velocity reading, with the frame tests the statistics use."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from workbench.models import MeasurementModel, constant_velocity, linear_measurement, range_rate_model
from workbench.rng import generator
from workbench.sensing.bistatic import monostatic_velocity
from workbench.tracking import GATE_99, NearestNeighbour, Track, run, strongest_candidate_prior
from workbench.types import InputError, Scans

from .scenario import FALLBACK, ON_TARGET_SIGMAS, P0, VARIANTS

def as_monostatic_velocity(scans: Scans, wavelength_m: float) -> Scans:
    """The ablation's reading of the candidates: ``z = [R, v]`` with ``v = -lambda f_D / 2`` (monostatic)."""
    if scans.doppler is None:
        raise InputError("as_monostatic_velocity needs scans with a doppler field")
    v = monostatic_velocity(np.nan_to_num(scans.doppler), wavelength_m)
    return replace(scans, z=np.stack([scans.z[..., 0], np.where(scans.valid, v, 0.0)], axis=-1))


def mismatched_model(model_rr: MeasurementModel) -> MeasurementModel:
    """Measurement model of the range-velocity ablation: ``z = [R, v]``, velocity noise = range-rate noise / 2."""
    sigma_r, sigma_rdot = model_rr.stated_std
    sigma_v = sigma_rdot / 2.0
    return linear_measurement(np.eye(2), np.diag([sigma_r ** 2, sigma_v ** 2]),
                              name="range-velocity (monostatic reading)")


def track_nearest_neighbour(spec, prior, motion, model, scans: Scans, rng, *, gate=None, prior_index=None,
                            reinit_after=None) -> Track:
    """The core loop with the nearest-neighbour role (:class:`workbench.tracking.NearestNeighbour`)."""
    return run(spec, scans, motion, model, association=NearestNeighbour(gate, prior_index, reinit_after),
               prior=prior, rng=rng)


def run_variants(spec, scans: Scans, model: MeasurementModel, dt: float, sigma_a: float, seed: int,
                 variants=VARIANTS, wavelength_m: float = 0.0, restart_after: int = 6,
                 stream: tuple = ()) -> dict[str, tuple[Track, Scans]]:
    """NN tracks of one filter for each variant (model x gate) on the same candidates.

    ``rr``: state ``[R, Rdot]``, :func:`~workbench.models.range_rate_model`, the sensor's model.
    ``rv``: state ``[R, v]``, a constant-velocity model with the same ``sigma_a``, candidates read as
    ``v = -lambda f_D / 2``.  ``gate``: ``d2 <= 9.21`` with coasting and a restart after ``restart_after``
    frames without an update (the tuned setting); ``nogate``: always the nearest candidate.
    """
    setups = {"rr": (scans, range_rate_model(dt, sigma_a), model, np.diag(np.square(P0)))}
    if any(v.startswith("rv") for v in variants):
        setups["rv"] = (as_monostatic_velocity(scans, wavelength_m), constant_velocity(1, dt, sigma_a),
                        mismatched_model(model), np.diag(np.square([P0[0], P0[1] / 2.0])))
    out = {}
    for name in variants:
        kind, gated = name.split("-")
        sc, motion, meas, cov0 = setups[kind]
        prior, index = strongest_candidate_prior(sc.scan(0), cov0, FALLBACK)
        gate, reinit = (GATE_99, int(restart_after)) if gated == "gate" else (None, None)
        out[name] = (track_nearest_neighbour(spec, prior, motion, meas, sc,
                                             generator(seed, "paper002", *stream, "filter", name),
                                             gate=gate, prior_index=index, reinit_after=reinit), sc)
    return out


def whitened_innovations(track: Track) -> np.ndarray:
    """``e_k = L_k^-1 (z_k - z^_k)`` with ``S_k = L_k L_k^T`` where updated (NaN elsewhere); ``NIS = |e|^2``.

    Shapes: ``(B, T, m)``.
    """
    rec = track.records
    nu = np.nan_to_num(rec["chosen_z"] - rec["predicted_z"])
    e = np.linalg.solve(np.linalg.cholesky(rec["innovation_cov"]), nu[..., None])[..., 0]
    return np.where(rec["updated"][..., None], e, np.nan)


def on_target(chosen: np.ndarray, truth: np.ndarray, sigma) -> np.ndarray:
    """``(B, T)``: the chosen measurement lies within :data:`ON_TARGET_SIGMAS` sigma of the truth in every
    component (``|z_i - x_i| <= 3 sigma_i``; False where nothing was chosen).  Shapes: ``(B, T, 2)`` twice."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(np.asarray(chosen, float) - truth) <= ON_TARGET_SIGMAS * np.asarray(sigma), axis=-1)


def on_track(est: np.ndarray, truth: np.ndarray, sigma) -> np.ndarray:
    """``(B, T)``: the track's estimate lies within :data:`ON_TARGET_SIGMAS` sigma of the truth in every component
    (``|x_hat_i - x_i| <= 3 sigma_i``: 45 m and 1.5 m/s with the sensor's stated 15 m and 0.5 m/s; False where the
    estimate is not finite).  Criterion 1's frame test.  Shapes: ``(B, T, 2)`` twice."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(np.asarray(est, float) - truth) <= ON_TARGET_SIGMAS * np.asarray(sigma), axis=-1)
