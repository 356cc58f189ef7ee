"""The tuning of the registered imm's defaults (docs/imm.md, "Tuning the defaults"): the rule was written down before
any of its results were seen.

Candidates: ``turn_sigma_a`` in :data:`SIGMAS` (m/s^2) times ``switch_probability`` in :data:`SWITCHES` (per second);
the other parameters at their defaults.  Data: the clean manoeuvring scenario (examples/scenarios/manoeuvring.toml,
each run's prior drawn around its truth), tuning seeds :data:`SEEDS` with :data:`RUNS` runs each, never the
reported seed 23.  Score: ``J = mean over scans and seeds of |log(NEES_k / 4)|`` with ``NEES_k`` the run-averaged
NEES of scan ``k``.  The pair with the smallest ``J`` among those with which the registered imm passes the filter
kit (:func:`workbench.testing.run_checks`, every check that applies) is chosen.

    .venv/bin/python scripts/imm_tuning.py          # 25 candidates x 5 seeds x 100 runs (a few minutes)

Prints one row per candidate (J, the mean NEES on the straight legs and in the turns, the RMSE in the turns, each
over the tuning seeds, and the kit's failed checks), sorted by J, and the chosen pair.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIGMAS = (0.2, 0.3, 0.4, 0.6, 0.8)
SWITCHES = (0.01, 0.02, 0.03, 0.05, 0.08)
SEEDS = (1000, 1001, 1002, 1003, 1004)
RUNS = 100


def scenario_module():
    spec = importlib.util.spec_from_file_location("manoeuvring", ROOT / "examples" / "scenarios" / "manoeuvring.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def score(per_scan_nees: np.ndarray) -> float:
    """``mean |log(NEES_k / 4)|`` over the scans (and seeds) of run-averaged NEES values ``(..., T)``."""
    return float(np.mean(np.abs(np.log(np.asarray(per_scan_nees, dtype=float) / 4.0))))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=RUNS)
    args = parser.parse_args(argv)
    if 23 in SEEDS:
        raise SystemExit("the reported seed 23 is not a tuning seed")
    m = scenario_module()
    from workbench.plugins import load_host

    host = load_host()
    scenario = m.load(host)
    base = host.filter("imm")
    t0 = time.perf_counter()
    rows = []
    for sigma in SIGMAS:
        for switch in SWITCHES:
            imm = base.configure(turn_sigma_a=sigma, switch_probability=switch)
            per_scan, straight, turns, rmse_turns = [], [], [], []
            for seed in SEEDS:
                f = m.evaluate(scenario, args.runs, seed, host=host, only=(m.IMM,), imm=imm)[m.IMM]
                per_scan.append(f["per_scan_nees"])
                straight.append(f["nees_straight"])
                turns.append(f["nees_turns"])
                rmse_turns.append(f["rmse_turns_m"])
            rows.append((score(np.stack(per_scan)), sigma, switch, float(np.mean(straight)), float(np.mean(turns)),
                         float(np.sqrt(np.mean(np.square(rmse_turns))))))
    rows.sort()
    from workbench.testing import run_checks

    kit = {}
    for row in rows:
        outcomes = run_checks(base.configure(turn_sigma_a=row[1], switch_probability=row[2]))
        kit[row[1:3]] = [o.check for o in outcomes if o.status not in ("passed", "skipped", "xfailed")]
    print(f"imm tuning: {len(rows)} candidates x seeds {SEEDS} x {args.runs} runs, clean manoeuvring scenario "
          f"({time.perf_counter() - t0:.0f} s)")
    print("| turn_sigma_a (m/s^2) | switch_probability (1/s) | J = mean abs log(NEES_k / 4) | NEES straight | "
          "NEES turns | RMSE in turns (m) | kit |")
    print("|---|---|---|---|---|---|---|")
    for j, sigma, switch, straight, turns, rmse in rows:
        failed = kit[sigma, switch]
        print(f"| {sigma:g} | {switch:g} | {j:.4f} | {straight:.3g} | {turns:.3g} | {rmse:.2f} | "
              f"{'fails ' + ', '.join(failed) if failed else 'passes'} |")
    passing = [row for row in rows if not kit[row[1:3]]]
    if not passing:
        print("no candidate passes the filter kit: nothing chosen")
        return 1
    j, sigma, switch = passing[0][:3]
    print(f"chosen: turn_sigma_a = {sigma:g} m/s^2, switch_probability = {switch:g} per s (J = {j:.4f}; the smallest "
          f"J of the {len(passing)} candidates that pass the filter kit)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
