"""The manoeuvring study of docs/imm.md: CV (EKF, UKF), CT-only and the IMM on examples/scenarios/manoeuvring.toml
(clean) and manoeuvring_clutter.toml (in clutter), over 500 runs.

Prints per filter the position RMSE overall and in the turns, the mean NEES (4-D state, over runs and scans) with
the chi-square 95 % band of a mean of ``runs`` NEES values, the mean NEES on the straight legs and in the turns, the
share of scans whose run-averaged NEES lies in that band and the share of runs lost (more than 200 m off at the last
scan); in clutter also the share of scans updated with a detection (the file's nearest neighbour, gated).

    .venv/bin/python scripts/manoeuvring_study.py            # 500 runs, clean and clutter (a few minutes)
    .venv/bin/python scripts/manoeuvring_study.py --runs 100 --clean
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def scenario_module():
    spec = importlib.util.spec_from_file_location("manoeuvring", ROOT / "examples" / "scenarios" / "manoeuvring.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--seed", type=int, default=23)
    parser.add_argument("--clean", action="store_true", help="only the clean scenario")
    args = parser.parse_args(argv)
    m = scenario_module()
    from workbench.plugins import load_host

    host = load_host()
    for clutter in (False,) if args.clean else (False, True):
        scenario = m.load(host, clutter=clutter)
        t0 = time.perf_counter()
        res = m.evaluate(scenario, args.runs, args.seed, host=host)
        lo, hi = next(iter(res.values()))["band"]
        if clutter:
            c = scenario.clutter[0]
            title = (f"in clutter ({c.plugin}, {c.params['rate']:g} per scan; nearest neighbour, gate "
                     f"{scenario.gate:g})")
        else:
            title = "clean (direct)"
        print(f"\n{scenario.path.name}, {title}: {args.runs} runs x {scenario.steps} scans, seed {args.seed} "
              f"({time.perf_counter() - t0:.0f} s)")
        imm = host.filter(next(f.label for f in scenario.filters if f.plugin == "imm"))
        print("imm: " + ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
                                  for k, v in imm.params.items()))
        print(f"NEES 95 % band of a {args.runs}-run mean: [{lo:.2f}, {hi:.2f}]")
        extra = " updated |" if clutter else ""
        print(f"| filter | RMSE (m) | RMSE in turns (m) | mean NEES | inside band | NEES straight | NEES turns | "
              f"scans in band | runs lost |{extra}")
        print("|---|---|---|---|---|---|---|---|---|" + ("---|" if clutter else ""))
        for label, f in res.items():
            inside = "yes" if lo <= f["mean_nees"] <= hi else "no"
            row = (f"| {label} | {f['rmse_m']:.2f} | {f['rmse_turns_m']:.2f} | {f['mean_nees']:.3g} | {inside} | "
                   f"{f['nees_straight']:.3g} | {f['nees_turns']:.3g} | {100 * f['nees_in_band']:.0f} % | "
                   f"{100 * f['lost']:.1f} % |")
            if clutter:
                row += f" {100 * f['updated']:.0f} % |"
            print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
