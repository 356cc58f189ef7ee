"""The tuning of the registered imm's defaults (docs/imm.md, "Tuning the defaults"): rule v1 below was written down
before any of its results were seen; rule v2 (after it) was written after v1's clutter result at seed 23 was seen.
Neither uses the reported seed 23 (nor the fresh seed 24601) for tuning.

Rule v1:

Candidates (:data:`CANDIDATES`, 100): the turn modes' fastest rate ``turn_rate`` in {3, 4} deg/s times
``turn_modes`` in {1, 2} (turn modes at ``+-turn_rate * k / turn_modes``: {+-3}, {+-4}, {+-1.5, +-3} or {+-2, +-4}
deg/s) times ``turn_sigma_a`` in {0.1, 0.2, 0.3, 0.4, 0.6} m/s^2 times ``switch_probability`` in {0.01, 0.02,
0.03, 0.05, 0.08} per second; ``quiet_probability`` (0.9) and the EKF modes are not tuned.

Data: the clean manoeuvring scenario (examples/scenarios/manoeuvring.toml, each run's prior drawn around its truth,
as the study does), tuning seeds :data:`SEEDS` (1000 to 1004) with :data:`RUNS` (100) runs each: 500 runs, as many
as the study, so the pooled mean NEES has the study's 95 % band (chi^2(4 x 500) / 500 = [3.76, 4.25]).

Score and choice, in this order:

1. ``NEES`` = the mean NEES over the 500 tuning runs and all scans (the figure the issue's done-when reads);
   ``J`` = mean over scans and seeds of ``|log(NEES_k / 4)|``, ``NEES_k`` the run-averaged NEES of scan ``k``
   (consistency scan by scan: an optimistic and a conservative scan cost alike).
2. Candidates whose ``NEES`` lies inside the band come first, ordered by ``J``; then the others, ordered by
   ``|log(NEES / 4)|``.
3. The filter kit (:func:`workbench.testing.run_checks`, every check that applies) is run on the candidates in that
   order; the first that passes it is chosen and the defaults are set to it whatever it is.  (The kit takes about
   half a minute a candidate, so it is run only until the first pass; the rows below the chosen one say "not run".)

Rule v2 (``--rule v2``, the default since; written AFTER rule v1's choice was seen to lose 2 of 500 runs on the
cluttered scenario at the reported seed 23, and after those two runs were diagnosed (docs/imm.md, "Why two runs are
lost in clutter"), so seed 23 is no longer a clean hold-out for v2; it is judged on seed 23 and on the fresh seed
:data:`FRESH_SEED` (24601), used by no tuning and by no earlier study):

1. As v1's steps 1 and 2 (the same candidates, clean data, ``NEES``, ``J`` and order).
2. Requirement in clutter: walking down that order, each candidate is also run on the cluttered scenario
   (examples/scenarios/manoeuvring_clutter.toml, the file's nearest-neighbour tracker and gate) on the same tuning
   seeds with :data:`CLUTTER_RUNS` (500) runs each, 2,500 runs in all (five times the study's 500, so that a loss
   rate like v1's 2 in 500 at seed 23 would show some 10 lost runs: it passes with probability about e^-10); it is
   admitted only if **no run is lost** (more than 200 m off at the last scan).
3. The first admitted candidate that passes the filter kit is chosen (the kit is run only on admitted candidates).
   The clutter runs are made only until that choice (the rows below it say "not run").

Outcome of v2 (docs/imm.md, "Rule v2"): every candidate it reached loses 1 or more of the 2,500 cluttered runs, so
it chose nothing and the defaults stay rule v1's (the rule did not say beforehand what happens when nothing is
admitted; keeping the defaults is the only choice that does not pick a candidate by its seed-23 result).

    .venv/bin/python scripts/imm_tuning.py          # rule v2: 100 candidates x 5 seeds x 100 runs clean, then clutter
    .venv/bin/python scripts/imm_tuning.py --workers 2   # the candidates shared among 2 processes (same numbers)
    .venv/bin/python scripts/imm_tuning.py --rule v1     # rule v1 (clean only; about 15 minutes on one process)
    .venv/bin/python scripts/imm_tuning.py --v1-band-only   # rule v2 over V1_BAND only (see there)
    .venv/bin/python scripts/imm_tuning.py --cache clean.json   # keep / reuse the clean figures of all candidates

Prints one row per candidate (NEES, inside the band or not, J, the mean NEES on the straight legs and in the turns,
the RMSE in the turns, each over the tuning seeds; with v2 the lost runs, mean NEES and RMSE in the turns in
clutter; and the kit's verdict), in the order of the rule, and the chosen candidate.
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TURN_RATES_DEG = (3.0, 4.0)
TURN_MODES = (1, 2)
SIGMAS = (0.1, 0.2, 0.3, 0.4, 0.6)
SWITCHES = (0.01, 0.02, 0.03, 0.05, 0.08)
#: ``(turn_rate in deg/s, turn_modes, turn_sigma_a, switch_probability)``
CANDIDATES = tuple(itertools.product(TURN_RATES_DEG, TURN_MODES, SIGMAS, SWITCHES))
SEEDS = (1000, 1001, 1002, 1003, 1004)
RUNS = 100
#: The 15 candidates whose clean tuning NEES rule v1's run put inside the band (docs/imm.md), in v1's order.  Every
#: one of them precedes every other candidate in the order of both rules, so where rule v2 admits one of them, a run
#: over these alone (``--v1-band-only``) makes the same choice as the full run; where it admits none, it says so.
V1_BAND = ((4.0, 2, 0.1, 0.08), (4.0, 1, 0.1, 0.08), (4.0, 2, 0.2, 0.03), (4.0, 1, 0.2, 0.03), (4.0, 1, 0.1, 0.05),
           (4.0, 1, 0.3, 0.02), (4.0, 1, 0.4, 0.02), (4.0, 2, 0.3, 0.02), (3.0, 1, 0.2, 0.08), (3.0, 1, 0.4, 0.03),
           (3.0, 1, 0.3, 0.05), (3.0, 1, 0.4, 0.02), (3.0, 2, 0.6, 0.02), (3.0, 2, 0.4, 0.03), (3.0, 2, 0.3, 0.05))
#: Rule v2: runs per tuning seed on the cluttered scenario (2,500 in all).
CLUTTER_RUNS = 500
#: Rule v2 is judged on this seed besides 23; no tuning and no earlier study used it.
FRESH_SEED = 24601
RULES = ("v1", "v2")


def scenario_module():
    spec = importlib.util.spec_from_file_location("manoeuvring", ROOT / "examples" / "scenarios" / "manoeuvring.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def score(per_scan_nees: np.ndarray) -> float:
    """``J``: ``mean |log(NEES_k / 4)|`` over the scans (and seeds) of run-averaged NEES values ``(..., T)``."""
    return float(np.mean(np.abs(np.log(np.asarray(per_scan_nees, dtype=float) / 4.0))))


def order(rows: list[dict], band: tuple[float, float]) -> list[dict]:
    """The rule's order: inside the band first, by ``J``; then the others by ``|log(NEES / 4)|``."""
    lo, hi = band

    def key(row):
        inside = lo <= row["nees"] <= hi
        return (0, row["J"]) if inside else (1, abs(math.log(row["nees"] / 4.0)))
    return sorted(rows, key=key)


def candidate(base, rate_deg: float, modes: int, sigma: float, switch: float):
    return base.configure(turn_rate=f"{rate_deg:g} deg/s", turn_modes=modes, turn_sigma_a=sigma,
                          switch_probability=switch)


_WORKER: dict = {}


def _init_worker() -> None:
    if not _WORKER:
        from workbench.plugins import load_host

        m = scenario_module()
        host = load_host()
        _WORKER.update(m=m, host=host, scenario=m.load(host), clutter=m.load(host, clutter=True),
                       base=host.filter("imm"))


def evaluate_candidate(cand: tuple, runs: int) -> dict:
    """One candidate's figures over the tuning seeds (``NEES``, ``J``, NEES straight and in the turns, RMSE in the
    turns)."""
    _init_worker()
    m, host, scenario = _WORKER["m"], _WORKER["host"], _WORKER["scenario"]
    imm = candidate(_WORKER["base"], *cand)
    per_scan, means, straight, turns, rmse_turns = [], [], [], [], []
    for seed in SEEDS:
        f = m.evaluate(scenario, runs, seed, host=host, only=(m.IMM,), imm=imm)[m.IMM]
        per_scan.append(f["per_scan_nees"])
        means.append(f["mean_nees"])
        straight.append(f["nees_straight"])
        turns.append(f["nees_turns"])
        rmse_turns.append(f["rmse_turns_m"])
    return {"candidate": cand, "nees": float(np.mean(means)), "J": score(np.stack(per_scan)),
            "straight": float(np.mean(straight)), "turns": float(np.mean(turns)),
            "rmse_turns": float(np.sqrt(np.mean(np.square(rmse_turns))))}


def evaluate_clutter(cand: tuple, runs: int) -> dict:
    """Rule v2's clutter figures of one candidate over the tuning seeds: ``lost`` (count of runs more than 200 m off
    at the last scan, of ``runs * len(SEEDS)``), ``nees`` (mean NEES), ``rmse_turns`` and ``updated``."""
    _init_worker()
    m, host, scenario = _WORKER["m"], _WORKER["host"], _WORKER["clutter"]
    imm = candidate(_WORKER["base"], *cand)
    lost, nees, rmse_turns, updated = 0, [], [], []
    for seed in SEEDS:
        f = m.evaluate(scenario, runs, seed, host=host, only=(m.IMM,), imm=imm)[m.IMM]
        lost += int(round(f["lost"] * runs))
        nees.append(f["mean_nees"])
        rmse_turns.append(f["rmse_turns_m"])
        updated.append(f["updated"])
    return {"candidate": cand, "lost": lost, "runs": runs * len(SEEDS), "nees": float(np.mean(nees)),
            "rmse_turns": float(np.sqrt(np.mean(np.square(rmse_turns)))), "updated": float(np.mean(updated))}


def kit_verdict(spec) -> str:
    from workbench.testing import run_checks

    outcomes = run_checks(spec)
    failed = [o.check for o in outcomes if o.status not in ("passed", "skipped", "xfailed")]
    return "fails " + ", ".join(failed) if failed else "passes"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=RUNS)
    parser.add_argument("--clutter-runs", type=int, default=CLUTTER_RUNS, help="rule v2: runs per seed in clutter")
    parser.add_argument("--workers", type=int, default=1, help="processes sharing the candidates")
    parser.add_argument("--rule", choices=RULES, default="v2", help="the tuning rule (module docstring)")
    parser.add_argument("--cache", help="a JSON file keeping the clean figures of every candidate (reused if there)")
    parser.add_argument("--v1-band-only", action="store_true",
                        help="evaluate only the 15 candidates rule v1 found inside the band (V1_BAND)")
    args = parser.parse_args(argv)
    if 23 in SEEDS or FRESH_SEED in SEEDS:
        raise SystemExit("the reported seeds 23 and 24601 are not tuning seeds")
    m = scenario_module()
    from workbench.plugins import load_host

    host = load_host()
    base = host.filter("imm")
    band = m.nees_band(args.runs * len(SEEDS))
    t0 = time.perf_counter()
    pool = None
    if args.workers > 1:
        import multiprocessing

        pool = multiprocessing.get_context("fork").Pool(args.workers)
    try:
        rows = _clean_rows(args, pool)
        rows = order(rows, band)
        t_clean = time.perf_counter() - t0
        chosen = None
        clutter_iter = None
        if args.rule == "v2":
            import functools

            todo = [row["candidate"] for row in rows]
            work = functools.partial(evaluate_clutter, runs=args.clutter_runs)
            # in the rule's order, lazily (two candidates at a time with --workers 2); stopped at the choice
            clutter_iter = pool.imap(work, todo, chunksize=1) if pool is not None else map(work, todo)
        for row in rows:
            if chosen is not None:
                row["kit"] = "not run"
                if args.rule == "v2":
                    row["clutter"] = None
                continue
            if args.rule == "v2":
                c = next(clutter_iter)
                assert c["candidate"] == row["candidate"]
                row["clutter"] = c
                print(f"  clutter {row['candidate']}: {c['lost']} of {c['runs']} lost, NEES {c['nees']:.3g} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
                if c["lost"]:
                    row["kit"] = "not run (runs lost in clutter)"
                    continue
            row["kit"] = kit_verdict(candidate(base, *row["candidate"]))
            if row["kit"] == "passes":
                chosen = row
    finally:
        if pool is not None:
            pool.terminate()
            pool.join()
    print(f"imm tuning, rule {args.rule}: {len(rows)} candidates{' (V1_BAND)' if args.v1_band_only else ''} x seeds {SEEDS} x {args.runs} runs, clean "
          f"manoeuvring scenario ({t_clean:.0f} s); band of the {args.runs * len(SEEDS)}-run mean NEES: "
          f"[{band[0]:.2f}, {band[1]:.2f}]" + (f"; in clutter {args.clutter_runs} runs per seed, in the rule's "
                                               f"order until the choice ({time.perf_counter() - t0:.0f} s in all)"
                                               if args.rule == "v2" else ""))
    head = ("| turn_rate (deg/s) | turn_modes | turn_sigma_a (m/s^2) | switch_probability (1/s) | NEES | inside band | "
            "J = mean abs log(NEES_k / 4) | NEES straight | NEES turns | RMSE in turns (m) |")
    if args.rule == "v2":
        head += " clutter: runs lost | clutter: NEES | clutter: RMSE in turns (m) |"
    print(head + " kit |")
    print("|---" * (head.count("|")) + "|")
    for row in rows:
        rate, modes, sigma, switch = row["candidate"]
        inside = "yes" if band[0] <= row["nees"] <= band[1] else "no"
        line = (f"| {rate:g} | {modes} | {sigma:g} | {switch:g} | {row['nees']:.3g} | {inside} | {row['J']:.4f} | "
                f"{row['straight']:.3g} | {row['turns']:.3g} | {row['rmse_turns']:.2f} |")
        if args.rule == "v2":
            c = row.get("clutter")
            line += (f" {c['lost']} of {c['runs']} | {c['nees']:.3g} | {c['rmse_turns']:.2f} |" if c else
                     " not run | | |")
        print(line + f" {row['kit']} |")
    if chosen is None:
        print("no candidate passes the rule: nothing chosen" + (" among V1_BAND (run without --v1-band-only)"
                                                                  if args.v1_band_only else ""))
        return 1
    if args.v1_band_only:
        outside = [row["candidate"] for row in rows if not band[0] <= row["nees"] <= band[1]]
        if outside:
            print(f"V1_BAND candidates outside the band now: {outside} (run without --v1-band-only)")
            return 1
    rate, modes, sigma, switch = chosen["candidate"]
    inside = band[0] <= chosen["nees"] <= band[1]
    print(f"chosen (rule {args.rule}): turn_rate = {rate:g} deg/s, turn_modes = {modes}, turn_sigma_a = {sigma:g} "
          f"m/s^2, switch_probability = {switch:g} per s (tuning NEES {chosen['nees']:.3g}, "
          f"{'inside' if inside else 'outside'} the band; J = {chosen['J']:.4f})")
    return 0


def _clean_rows(args, pool) -> list[dict]:
    """Every candidate's clean figures (read from / written to ``--cache`` where given: the same numbers)."""
    import json

    if args.cache and Path(args.cache).exists():
        rows = json.loads(Path(args.cache).read_text())
        for row in rows:
            row["candidate"] = tuple(row["candidate"])
        todo = V1_BAND if args.v1_band_only else CANDIDATES
        if [row["candidate"] for row in rows] == list(todo) and all(r["runs"] == args.runs for r in rows):
            return rows
    import functools

    work = functools.partial(evaluate_candidate, runs=args.runs)
    todo = V1_BAND if args.v1_band_only else CANDIDATES
    rows = pool.map(work, todo, chunksize=1) if pool is not None else [work(c) for c in todo]
    for row in rows:
        row["runs"] = args.runs
    if args.cache:
        Path(args.cache).write_text(json.dumps(rows))
    return rows


if __name__ == "__main__":
    sys.exit(main())
