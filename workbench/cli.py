"""The ``workbench`` command line."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from .plugins import BLOCK_ENV, PluginHost, UnknownComponent, load_host
from .types import InputError

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="workbench",
        description="Simulate, compare and accelerate target-tracking algorithms in clutter and at low SNR.")
    parser.add_argument("--block", action="append", default=[], metavar="PLUGIN",
                        help=f"do not load this plugin (repeatable; also the {BLOCK_ENV} environment variable)")
    sub = parser.add_subparsers(dest="command", required=True)

    sub.add_parser("plugins", help="list installed plugins: kind, name, distribution, version, status")

    rep = sub.add_parser("report", help="regenerate the papers' figures and tables")
    rep.add_argument("--paper", action="append", default=[], help="only this paper (repeatable), e.g. 003")
    size = rep.add_mutually_exclusive_group()
    size.add_argument("--quick", dest="size", action="store_const", const="quick", help="quick sizes (default)")
    size.add_argument("--full", dest="size", action="store_const", const="full", help="the papers' full sizes")
    rep.set_defaults(size="quick")
    rep.add_argument("--out", default="workbench-report", help="output folder (default: ./workbench-report)")
    rep.add_argument("--filters", default=None,
                     help="comma-separated filter names: '+name' adds to each recipe's defaults, '-name' "
                          "removes one, a plain list replaces them")
    rep.add_argument("--seed", type=int, default=0, help="base seed of every random stream (default 0)")
    rep.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "auto"],
                     help="Taichi backend for kernels (default cpu; auto falls back to cpu)")
    rep.add_argument("--no-progress", action="store_true", help="no progress bars")
    rep.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="send the tasks to this Dask distributed scheduler (pip install -e '.[dask]')")
    rep.add_argument("--workers", type=int, default=None, metavar="N",
                     help="start a local Dask cluster of N worker processes for the tasks")

    run = sub.add_parser("run", help="run one scenario file: a results file and its plots")
    run.add_argument("scenario", help="scenario TOML file")
    run.add_argument("--out", default=None, help="output folder (default: next to the scenario, <name>-results)")
    run.add_argument("--seed", type=int, default=None, help="override the scenario's seed")

    chk = sub.add_parser("check-plugin", help="run the plugin test kit on an installed filter")
    chk.add_argument("name", help="filter name (as listed by 'workbench plugins')")

    bench = sub.add_parser("bench", help="run the benchmark suite and print a table")
    bench.add_argument("--quick", action="store_true", help="small sizes (seconds, for CI)")
    bench.add_argument("--json", default="workbench-bench.json", help="write the figures here as JSON")
    bench.add_argument("--only", action="append", default=[], help="only this benchmark group (repeatable)")
    return parser


def _host(args) -> PluginHost:
    host = load_host(block=args.block)
    for p in host.broken:
        print(f"workbench: warning: plugin {p.name} ({p.distribution} {p.version}) is broken: {p.error}",
              file=sys.stderr)
    return host


def cmd_plugins(args) -> int:
    host = _host(args)
    rows = []
    for p in host.plugins:
        if p.provides:
            for kind, name in p.provides:
                rows.append((kind, name, p.name, p.distribution, p.version, p.status))
        else:
            rows.append(("-", "-", p.name, p.distribution, p.version, p.status + (f": {p.error}" if p.error else "")))
    header = ("kind", "name", "plugin", "distribution", "version", "status")
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(5)]
    line = lambda r: "  ".join(str(v).ljust(widths[i]) for i, v in enumerate(r[:5])) + "  " + str(r[5])  # noqa: E731
    print(line(header))
    for r in sorted(rows, key=lambda r: (r[0] == "-", r[0], r[1])):
        print(line(r))
    return 0


def cmd_report(args) -> int:
    from .report.engine import run_report

    host = _host(args)
    if args.arch != "cpu":
        from .kernels.runtime import TaichiUnavailable, ensure_taichi

        try:
            args.arch = ensure_taichi(args.arch)  # "auto" resolves here, with a notice if it falls back
        except TaichiUnavailable as exc:
            raise InputError(str(exc)) from None
    command = "workbench " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    executor = None
    if args.scheduler or args.workers:
        from .report.engine import dask_executor

        executor = dask_executor(host, args.scheduler, args.workers, block=args.block)
    try:
        report = run_report(host, Path(args.out), papers=args.paper or None, size=args.size, seed=args.seed,
                            filters=args.filters, arch=args.arch, progress=not args.no_progress, command=command,
                            executor=executor)
    finally:
        if executor is not None:
            executor.close()
    for p in report.papers:
        counts = {}
        for c in p.criteria:
            counts[c.verdict] = counts.get(c.verdict, 0) + 1
        verdicts = ", ".join(f"{n} {v}" for v, n in counts.items()) or "none"
        marker = " (indicative: quick run)" if any(c.indicative for c in p.criteria) else ""
        print(f"paper {p.paper}: {len(p.figures)} figures, {len(p.tables)} tables, "
              f"criteria: {verdicts}{marker}, {p.seconds:.1f} s"
              + (f", {len(p.errors)} problems" if p.errors else ""))
        for err in p.errors:
            print(f"  not done: {err}", file=sys.stderr)
    if not report.papers:
        print("no report recipes are installed", file=sys.stderr)
    print(f"report: {report.out / 'index.html'} ({report.seconds:.1f} s)")
    return 1 if report.failed else 0


def cmd_run(args) -> int:
    from .scenario import load_scenario, run_scenario

    host = _host(args)
    scenario = load_scenario(Path(args.scenario), host)
    out = Path(args.out) if args.out else Path(args.scenario).with_name(f"{scenario.name}-results")
    result = run_scenario(scenario, host, out, seed=args.seed)
    print(result.summary_text())
    return 0


def cmd_check_plugin(args) -> int:
    from .testing.kit import run_checks

    host = _host(args)
    spec = host.filter(args.name)
    outcomes = run_checks(spec)
    failed = 0
    for o in outcomes:
        print(f"{o.status.upper():8s} {spec.name}-{o.check}" + (f": {o.message}" if o.message else ""))
        failed += o.status == "failed"
    passed = sum(o.status == "passed" for o in outcomes)
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


def cmd_bench(args) -> int:
    from .bench import run_bench

    host = _host(args)
    return run_bench(host, quick=args.quick, json_path=Path(args.json), only=args.only, block=tuple(args.block))


COMMANDS = {"plugins": cmd_plugins, "report": cmd_report, "run": cmd_run, "check-plugin": cmd_check_plugin,
            "bench": cmd_bench}


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except (InputError, UnknownComponent, FileNotFoundError) as exc:
        print(f"workbench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("workbench: interrupted; finished work is cached and will be reused", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
