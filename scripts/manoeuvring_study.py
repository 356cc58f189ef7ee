"""The manoeuvring study of docs/imm.md: CV (EKF, UKF), CT-only and the IMM on examples/scenarios/manoeuvring.toml
(clean) and manoeuvring_clutter.toml (in clutter), over 500 runs.

Prints per filter the position RMSE overall and in the turns, the mean NEES (4-D state, over runs and scans) with
the chi-square 95 % band of a mean of ``runs`` NEES values, the mean NEES on the straight legs and in the turns, the
share of scans whose run-averaged NEES lies in that band and the share of runs lost (more than 200 m off at the last
scan); in clutter also the share of scans updated with a detection (the file's nearest neighbour, gated).

    .venv/bin/python scripts/manoeuvring_study.py            # 500 runs, clean and clutter (a few minutes)
    .venv/bin/python scripts/manoeuvring_study.py --runs 100 --clean
    .venv/bin/python scripts/manoeuvring_study.py --seed 24601 --clutter --imm-gates mixture --imm-only
    .venv/bin/python scripts/manoeuvring_study.py --imm 'turn_rate=3 deg/s, turn_sigma_a=0.4, switch_probability=0.05'

``--imm`` replaces the file's IMM parameters (the CT-only filter keeps the registered imm's turn rate and noise);
In clutter the IMM is gated on its modes' own predictions (the file's nearest neighbour: every IMM declares
``FilterSpec.gate_candidates``; docs/imm.md, "Gating on the modes"); ``--imm-gates mixture`` gates it on its
moment-matched mixture instead (``NearestNeighbour(gate, filter_candidates=False)``), as before that default.
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
    parser.add_argument("--clutter", action="store_true", help="only the cluttered scenario")
    parser.add_argument("--imm", default="", help="the IMM's parameters instead of the file's, e.g. "
                        "'turn_rate=3 deg/s, turn_sigma_a=0.4, switch_probability=0.05'")
    parser.add_argument("--imm-gates", default="modes", choices=("mixture", "modes"),
                        help="in clutter, gate the IMM on its modes (the default: the file's nearest neighbour) or "
                        "on its moment-matched mixture")
    parser.add_argument("--imm-only", action="store_true", help="run only the IMM (not the single-model filters)")
    parser.add_argument("--workers", type=int, default=1, help="2: the clean and the cluttered study in parallel")
    args = parser.parse_args(argv)
    if args.clean and args.clutter:
        parser.error("--clean and --clutter exclude each other")
    cases = (False,) if args.clean else (True,) if args.clutter else (False, True)
    if args.workers > 1 and len(cases) > 1:
        import functools
        import multiprocessing

        with multiprocessing.get_context("fork").Pool(min(args.workers, len(cases))) as pool:
            results = pool.map(functools.partial(_study, args=args), cases)
    else:
        results = [_study(c, args) for c in cases]
    for text in results:
        print(text)
    return 0


def _imm_override(text: str) -> dict:
    out = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--imm: expected key=value, got {item!r}")
        value = value.strip()
        try:
            out[key.strip()] = int(value) if value.isdigit() else float(value)
        except ValueError:
            out[key.strip()] = value
    return out


def _study(clutter: bool, args) -> str:
    m = scenario_module()
    from workbench.plugins import load_host

    host = load_host()
    lines: list[str] = []
    write = lines.append  # the tables are returned and printed by main, in order
    scenario = m.load(host, clutter=clutter)
    t0 = time.perf_counter()
    imm = host.filter(next(f.label for f in scenario.filters if f.plugin == "imm"))
    if args.imm:
        imm = imm.configure(**_imm_override(args.imm))
    res = m.evaluate(scenario, args.runs, args.seed, host=host, imm=imm, imm_gates=args.imm_gates,
                     only=(m.IMM,) if args.imm_only else None)
    lo, hi = next(iter(res.values()))["band"]
    if clutter:
        c = scenario.clutter[0]
        title = (f"in clutter ({c.plugin}, {c.params['rate']:g} per scan; nearest neighbour, gate "
                 f"{scenario.gate:g}; the IMM gated on its {args.imm_gates})")
    else:
        title = "clean (direct)"
    write(f"\n{scenario.path.name}, {title}: {args.runs} runs x {scenario.steps} scans, seed {args.seed} "
          f"({time.perf_counter() - t0:.0f} s)")
    write("imm: " + ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
                              for k, v in imm.params.items()))
    write(f"NEES 95 % band of a {args.runs}-run mean: [{lo:.2f}, {hi:.2f}]")
    extra = " updated |" if clutter else ""
    write(f"| filter | RMSE (m) | RMSE in turns (m) | mean NEES | inside band | NEES straight | NEES turns | "
          f"scans in band | runs lost |{extra}")
    write("|---|---|---|---|---|---|---|---|---|" + ("---|" if clutter else ""))
    for label, f in res.items():
        inside = "yes" if lo <= f["mean_nees"] <= hi else "no"
        row = (f"| {label} | {f['rmse_m']:.2f} | {f['rmse_turns_m']:.2f} | {f['mean_nees']:.3g} | {inside} | "
               f"{f['nees_straight']:.3g} | {f['nees_turns']:.3g} | {100 * f['nees_in_band']:.0f} % | "
               f"{100 * f['lost']:.1f} % |")
        if clutter:
            row += f" {100 * f['updated']:.0f} % |"
        write(row)
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
