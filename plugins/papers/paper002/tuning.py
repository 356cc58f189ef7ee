"""Paper 002's one tuned setting: the gated tracker's restart delay, chosen by a rule written down before the result,
on tuning runs only (docs/paper002.md, "Tuning")."""

from __future__ import annotations

import numpy as np

from workbench.metrics import association_log
from workbench.rng import generator
from workbench.sensing.bistatic import range_and_rate
from workbench.types import InputError

from .judging import stat_on_target, stat_track_share
from .methods import on_target, on_track, run_variants
from .scenario import (CLUTTER_PFA, FRAME_DT, RESTART_CANDIDATES, SIGMA_A, TUNING_SEED, TUNING_TIE,
                       detection_scans, drone_truth)

# -- tuning (docs/paper002.md, "Tuning": the rule was written before the result) ---------------------------------


def choose_restart(candidates, scores, tie: float = TUNING_TIE) -> int:
    """The tuning rule (written down before any result): the delay with the highest score wins; scores within
    ``tie`` of the best tie, and a tie goes to the shortest delay.  Non-finite scores never win; all non-finite
    is refused by name.

    ``candidates``: delays (frames), in any order; ``scores``: one per candidate (criterion 1's track share).
    """
    candidates = np.asarray(candidates, dtype=int)
    scores = np.asarray(scores, dtype=float)
    if candidates.ndim != 1 or candidates.shape != scores.shape or not candidates.size:
        raise InputError(f"choose_restart needs one score per candidate delay, got delays of shape "
                         f"{candidates.shape} and scores of shape {scores.shape}")
    if not np.isfinite(scores).any():
        raise InputError("choose_restart: no candidate delay has a finite score (no tuning frames?)")
    best = np.nanmax(scores)
    tied = np.isfinite(scores) & (scores >= best - tie)
    return int(candidates[tied].min())


def tune_restart(host, filter_name: str, runs: int, frames: int, sigma_a: float = SIGMA_A
                 ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The restart delay of the gated tracker, chosen by the documented rule on tuning runs only.

    Rule (docs/paper002.md, "Tuning"; fixed before the result): over ``runs`` runs drawn from seed
    :data:`TUNING_SEED` under the stream key ``"tuning"`` (no reported run uses that key, whatever the report's
    seed), on the primary false-alarm map, run the gated range / range-rate tracker with each delay of
    :data:`RESTART_CANDIDATES`; score each by criterion 1's statistic, the share of frames ``k >= 1`` whose track
    estimate lies within 3 sigma of the truth in R and Rdot (:func:`stat_track_share`); the highest share wins,
    shares within :data:`TUNING_TIE` of the best tie, and a tie goes to the shortest delay
    (:func:`choose_restart`).

    Returns the chosen delay and, per candidate ``(len(RESTART_CANDIDATES),)``: the track share (the rule's
    score) and, for information only (the rule reads neither), the track range RMSE over all frames and the
    candidate-choice share (the former score).
    """
    sensor = host.sensor("dtv-pbr")
    tx, rx = sensor.params["tx"], sensor.params["rx"]
    truth = drone_truth(generator(TUNING_SEED, "paper002", "tuning", "truth"), runs, frames, FRAME_DT)
    scans = detection_scans(host, truth, TUNING_SEED, CLUTTER_PFA, stream=("tuning",))
    truth_rr = range_and_rate(truth.states, tx, rx)
    model = sensor.measurement_model()
    shares, rmse, chosen_on = [], [], []
    for delay in RESTART_CANDIDATES:
        (track, sc), = run_variants(host.filter(filter_name), scans, model, FRAME_DT, sigma_a, TUNING_SEED,
                                    variants=("rr-gate",), restart_after=delay, stream=("tuning",)).values()
        log = association_log(track, sc)
        inside = on_track(track.mean, truth_rr, model.stated_std)[:, 1:]
        shares.append(stat_track_share(inside.sum(axis=1), np.full(runs, frames - 1)))
        on = log.target_present & on_target(track.records["chosen_z"], truth_rr, model.stated_std)
        chosen_on.append(stat_on_target(on[:, 1:].sum(axis=1), log.target_present[:, 1:].sum(axis=1)))
        rmse.append(float(np.sqrt(np.mean((track.mean[:, 1:, 0] - truth_rr[:, 1:, 0]) ** 2))))
    shares = np.asarray(shares)
    return choose_restart(RESTART_CANDIDATES, shares), shares, np.asarray(rmse), np.asarray(chosen_on)
