"""The settings of paper 000 that were chosen by a search, the rule that chose them, and the search itself.

The rule (also in docs/paper000.md, written before the search was run):

- **Seeds.**  The search runs on the tuning seeds :data:`TUNING_SEEDS`, each one the paper's protocol (20 Monte
  Carlo runs, N = 600 particles, gate R = 1 km, 5 dB threshold, reference RCS -20 dBsm).  The report's runs (seed 0
  and its independent replications) never serve the search.
- **Score.**  For a candidate, the number of lost runs of the method it belongs to over all tuning runs (E_error >
  3 km for 5 scans), then, between equal counts, the mean whole-track error over the runs not lost.  The lowest
  score wins; between equal scores, the candidate listed first.
- **Order.**  One setting at a time, in the order of :data:`STEPS`; each step keeps the choices of the steps before
  it, every other setting at its value before the search.  Settings shared by every method (the process noise) are
  chosen on method C, the proposed method, and used by all.

**Calibration of the withheld scene values** (issue 24 item 2; :data:`CALIBRATION_RULE`, written down, here and in
docs/paper000.md, before its result was seen): the paper publishes its baselines' numbers (Table 3: A 236 m and
B 214 m, whole track), so the values it withholds (the reference RCS and the clutter rate, the declared unknowns of
:mod:`.scenario`) are calibrated against them on the tuning seed :data:`CALIBRATION_SEED`, never on the report's
seeds: the candidate ``(RCS, rate)`` minimising ``|ln(A / 236)| + |ln(B / 214)|`` over the literal A and B's mean
whole-track errors (lost runs included, as the paper's means) wins; ties go to the primary, then to the candidate
listed first (:func:`calibrate`).  The criteria are then judged at the chosen values on the report's seeds.

Run ``python -m workbench_papers.paper000.tuning`` to repeat the search (about 10 minutes on 2 cores); it prints one
line per candidate and the choice of each step as JSON.  The report's "tuning" table shows the rule, the seeds, the
candidates and the values the filters use.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["TUNING_SEEDS", "RULE", "Step", "STEPS", "score", "run_search", "CALIBRATION_SEED", "CALIBRATION_RULE",
           "CALIBRATION_RUNS", "CALIBRATED_POINT", "calibration_scores", "calibrate"]

#: Seeds of the search; the report uses seed 0 (its runs and replications come from seed 0's streams).
TUNING_SEEDS = (101, 102, 103, 104)
RULE = ("fewest lost runs of the step's method over the tuning runs (4 seeds x 20 runs, N = 600, R = 1 km, 5 dB, "
        "-20 dBsm), then the lowest mean whole-track error over the runs not lost; ties: the candidate listed first; "
        "one setting at a time in the listed order, each keeping the earlier choices")

#: The tuning seed the withheld scene values are calibrated on (one of :data:`TUNING_SEEDS`; never a report seed).
CALIBRATION_SEED = TUNING_SEEDS[0]
#: Runs of the calibration at each candidate (the paper's protocol).
CALIBRATION_RUNS = 20
#: The point the calibration chose on :data:`CALIBRATION_SEED` ((reference RCS dBsm, clutter rate per scan); score
#: 1.08: A 105 m, B 280 m), declared so that the report knows before it runs which grid point the calibrated criteria
#: read (that point's runs are judged, and run again on the confirmation seed; the other grid points are
#: sensitivities).  The full report recomputes the calibration and judges the calibrated criteria only where its
#: choice is this point.
CALIBRATED_POINT = (-15.0, 50.0)
CALIBRATION_RULE = (f"on tuning seed {CALIBRATION_SEED} ({CALIBRATION_RUNS} runs, N = 600, R = 1 km, 5 dB), each "
                    "candidate (reference RCS, clutter rate) scores |ln(A / 236 m)| + |ln(B / 214 m)| with A and B the "
                    "literal rows' mean whole-track errors (lost runs included, as the paper's Table 3 means); the "
                    "lowest score wins; ties go to the primary values, then to the candidate listed first")


def calibration_scores(whole_a, whole_b, published=(236.0, 214.0)) -> np.ndarray:
    """``|ln(a / A_pub)| + |ln(b / B_pub)|`` per candidate, from the literal A and B's mean whole-track errors
    ``whole_a, whole_b (P,)`` (m); ``inf`` where either is not a positive finite number."""
    a, b = np.asarray(whole_a, dtype=float), np.asarray(whole_b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.abs(np.log(a / published[0])) + np.abs(np.log(b / published[1]))
    return np.where(ok, s, np.inf)


def calibrate(candidates, whole_a, whole_b, primary, published=(236.0, 214.0)) -> int:
    """The index of the candidate :data:`CALIBRATION_RULE` chooses: the lowest :func:`calibration_scores`; between
    equal scores (to 1e-12 relative) the primary candidate ``primary`` where it is among them, else the first listed.
    Raises ``ValueError`` where no candidate has a finite score."""
    candidates = [tuple(c) for c in candidates]
    scores = calibration_scores(whole_a, whole_b, published)
    if len(scores) != len(candidates):
        raise ValueError(f"calibrate: {len(candidates)} candidates but {len(scores)} scores")
    if not np.isfinite(scores).any():
        raise ValueError("calibrate: no candidate has a finite score")
    best = float(np.min(scores))
    tied = [j for j, s in enumerate(scores) if np.isfinite(s) and abs(s - best) <= 1e-12 * max(1.0, abs(best))]
    primary = tuple(primary)
    return next((j for j in tied if candidates[j] == primary), tied[0])


@dataclass(frozen=True)
class Step:
    """One setting of the search: ``name``, the method row it is scored on (``method``, a key of
    :data:`~.methods.METHODS`), where it lives (``target``: ``"filter"`` parameters of that row's filter or
    ``"motion"``/``"clutter_term"`` of the recipe) and the candidates, each a dict of values."""

    name: str
    method: str
    target: str
    candidates: tuple[dict, ...]


STEPS = (
    Step("floor_scale (amplitude floor of C, x the clutter density)", "C", "filter",
         tuple({"floor_scale": v} for v in (1.0, 4.0, 16.0, 64.0, 256.0))),
    Step("process noise: quiet sigma_a (m/s^2) and two-mode switching (on, off, x scale)", "C", "motion",
         tuple({"sigma_a": sa, "switch_on": on, "switch_off": off, "manoeuvre_scale": sc}
               for sa in ((8.0, 8.0, 4.0), (10.0, 10.0, 5.0), (15.0, 15.0, 5.0))
               for on, off, sc in ((0.05, 0.2, 4.0), (0.05, 0.3, 4.0), (0.1, 0.2, 3.0)))),
    Step("regularisation of C (x h_opt)", "C", "filter", tuple({"regularisation": v} for v in (0.0, 0.25, 0.5, 1.0))),
    Step("clutter term of our A", "A+", "clutter_term",
         tuple({"clutter_term": v} for v in ("none", "flat", "amplitude", "pd-amplitude"))),
    Step("clutter term of our B", "B+", "clutter_term",
         tuple({"clutter_term": v} for v in ("none", "flat", "amplitude", "pd-amplitude"))),
    Step("regularisation of our B (x h_opt)", "B+", "filter", tuple({"regularisation": v} for v in (0.0, 0.5))),
)


def score(lost: np.ndarray, whole: np.ndarray) -> tuple[int, float]:
    """``(lost runs, mean whole-track error over the runs not lost)`` of per-run flags and errors ``(R,)``."""
    lost = np.asarray(lost, dtype=bool)
    whole = np.asarray(whole, dtype=float)
    return int(lost.sum()), float(whole[~lost].mean()) if (~lost).any() else float("inf")


def _evaluate(host, data, method, values: dict, settings: dict) -> tuple[int, float]:
    from .methods import METHODS, run_method

    row = next(m for m in METHODS if m.key == method)
    filt = dict(settings["filter"].get(method, {}))
    motion = dict(settings["motion"])
    term = settings["clutter_term"].get(method)
    for key, value in values.items():
        if key == "sigma_a":
            motion["sigma_a"] = value
        elif key == "clutter_term":
            term = value
        elif key in ("switch_on", "switch_off", "manoeuvre_scale"):
            motion[key] = value
        else:
            filt[key] = value
    # the process noise is shared: every two-mode filter and the proposed filter's moment match use it
    shared = {k: motion[k] for k in ("switch_on", "switch_off", "manoeuvre_scale") if k in motion}
    base = host.filter(row.filter)
    spec = base.configure(**{**({k: v for k, v in shared.items() if k in base.params}), **filt})
    proposed = host.filter("tbd-pf").configure(**shared) if shared else None
    lost, whole = [], []
    for seed, (truth, scans, model) in data.items():
        out = run_method(host, row, scans, truth.states, model, radius=1000.0, particles=600, seed=seed,
                         sigma_a=motion.get("sigma_a"), proposed=proposed, spec=spec, clutter_term=term,
                         record=False)
        lost.append(out["lost"])
        whole.append(out["error"][:, 1:].mean(axis=1))
    return score(np.concatenate(lost), np.concatenate(whole))


def run_search(seeds=TUNING_SEEDS, runs: int = 20, steps=STEPS, out=sys.stdout) -> dict:
    """Run the search of :data:`STEPS` on ``seeds``; returns ``{step name: {"candidates": [...], "scores": [...],
    "chosen": {...}}}``."""
    from workbench.plugins import load_host

    from .methods import SIGMA_A
    from .scenario import scenario_truth, simulate_scans, tracking_model

    host = load_host()
    data = {}
    for seed in seeds:
        truth = scenario_truth(runs)
        data[seed] = (truth, simulate_scans(host, truth, seed, 5.0), tracking_model(host))
    settings: dict[str, Any] = {"filter": {}, "motion": {"sigma_a": SIGMA_A}, "clutter_term": {}}
    result = {}
    for step in steps:
        scores = []
        for values in step.candidates:
            t0 = time.perf_counter()
            s = _evaluate(host, data, step.method, values, settings)
            scores.append(s)
            print(json.dumps({"step": step.name, "candidate": values, "lost": s[0], "not_lost_whole_m": round(s[1], 1),
                              "seconds": round(time.perf_counter() - t0, 1)}), file=out, flush=True)
        best = min(range(len(scores)), key=lambda j: (scores[j][0], scores[j][1], j))
        chosen = step.candidates[best]
        for key, value in chosen.items():
            if key == "clutter_term":
                settings["clutter_term"][step.method] = value
            elif key in ("sigma_a", "switch_on", "switch_off", "manoeuvre_scale"):
                settings["motion"][key] = value
            else:
                settings["filter"].setdefault(step.method, {})[key] = value
        result[step.name] = {"candidates": list(step.candidates), "scores": scores, "chosen": chosen}
        print(json.dumps({"step": step.name, "chosen": chosen}), file=out, flush=True)
    return result


if __name__ == "__main__":  # pragma: no cover - manual use
    run_search()
