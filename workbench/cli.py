"""The ``workbench`` command line.

Error policy: every expected failure ends the command with one line on stderr naming what went wrong (the
file, key, line, column or plugin, and what was expected) and an exit status per class; ``--debug`` shows
the traceback instead.

====  =================================================================================================
exit  meaning
====  =================================================================================================
0     done
1     done, but some work failed (a task, a figure, a filter): the rest is written and the failures named
2     bad input: a scenario, data file, option, parameter or component name
3     an operating-system error: a file or folder that cannot be read or written, a full disk
4     a plugin failed to load or raised where it should not have
5     the network: a Dask scheduler that cannot be reached, or a cluster that lost its workers
70    an internal error (a bug: please report it with the ``--debug`` traceback)
130   interrupted (Ctrl-C)
====  =================================================================================================
"""

from __future__ import annotations

import argparse
import difflib
import errno
import os
import shlex
import sys
import traceback
import warnings
from pathlib import Path

from .memory import keep_freed_memory
from .plugins import BLOCK_ENV, PluginHost, UnknownComponent, load_host
from .types import InputError

__all__ = ["main", "build_parser", "EXIT", "NetworkError", "PluginFailure"]

#: Exit status per class of failure (see the module docstring).
EXIT = {"ok": 0, "partial": 1, "input": 2, "os": 3, "plugin": 4, "network": 5, "internal": 70, "interrupted": 130}


class NetworkError(RuntimeError):
    """A service the command needs (a Dask scheduler) cannot be reached."""


class PluginFailure(RuntimeError):
    """A plugin failed to load, or raised where it should not have; the message names it."""


#: ``workbench report``'s default number of worker processes is the usable cores, at most this many (each worker
#: holds its own plugin host and its tasks' arrays).
DEFAULT_JOBS_CAP = 8
#: The environment variable that sets the report's default number of worker processes (``--jobs`` overrides it).
JOBS_VARIABLE = "WORKBENCH_JOBS"


def _default_jobs(cores: int) -> int:
    """The report's worker processes without ``--jobs``: :data:`JOBS_VARIABLE` where set (a whole number >= 1,
    else refused by name), else the usable cores up to :data:`DEFAULT_JOBS_CAP`."""
    text = os.environ.get(JOBS_VARIABLE, "").strip()
    if not text:
        return min(cores, DEFAULT_JOBS_CAP)
    try:
        jobs = int(text)
    except ValueError:
        jobs = 0
    if jobs < 1:
        raise InputError(f"{JOBS_VARIABLE}={text!r}: expected a whole number of worker processes >= 1 "
                         "(1: the tasks run one after another in the report's own process)")
    return jobs


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {value}")
    return value


class _Once(argparse.Action):
    """An option that may be given once: a second ``--filters`` is refused instead of silently replacing the
    first (a list is written comma-separated, in one option)."""

    def __call__(self, parser, namespace, values, option_string=None):
        earlier = getattr(namespace, self.dest, None)
        if earlier is not None:
            parser.error(f"{option_string} is given twice ({earlier!r} and {values!r}): give one comma-separated "
                         f"list")
        setattr(namespace, self.dest, values)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds >= 0, got {text!r}") from None
    if not 0.0 <= value <= 86400.0:
        raise argparse.ArgumentTypeError(f"expected a number of seconds from 0 to 86400, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from .kernels import backend as kernel_policy  # the one list of arch names (the standard library only)

    parser = argparse.ArgumentParser(
        prog="workbench",
        description="Simulate, compare and accelerate target-tracking algorithms in clutter and at low SNR.")
    parser.add_argument("--version", action="store_true",
                        help="print the version of the workbench and of each installed plugin distribution")
    parser.add_argument("--block", action="append", default=[], metavar="PLUGIN",
                        help=f"do not load this plugin (repeatable; also the {BLOCK_ENV} environment variable)")
    parser.add_argument("--debug", action="store_true", help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command")  # required unless --version (checked in main)

    plg = sub.add_parser("plugins", help="list installed plugins; with a NAME, that component's parameters")
    plg.add_argument("name", nargs="?", default=None,
                     help="a component name: print its kind, summary, capabilities and declared parameters")

    rep = sub.add_parser("report", help="regenerate the papers' figures and tables")
    rep.add_argument("--paper", action="append", default=[], help="only this paper (repeatable), e.g. 003")
    size = rep.add_mutually_exclusive_group()
    size.add_argument("--full", dest="size", action="store_const", const="full",
                      help="the papers' full sizes, with the declared unknowns' grids and the confirmation seed: "
                           "firm verdicts (default)")
    size.add_argument("--quick", dest="size", action="store_const", const="quick",
                      help="a smoke run at small sizes: its verdicts are indicative only (never met), "
                           "no confirmation seed")
    rep.set_defaults(size="full")
    rep.add_argument("--out", default="workbench-report", help="output folder (default: ./workbench-report)")
    rep.add_argument("--filters", default=None, action=_Once,
                     help="comma-separated filters, each 'name' or 'name(key=value, ...)': '+name' adds to each "
                          "recipe's defaults, '-name' or '~name' removes one, a plain list replaces them "
                          "(e.g. --filters '+sir(particles=2000),~ekf')")
    rep.add_argument("--trackers", default=None, action=_Once,
                     help="comma-separated multi-target trackers, as --filters: '+name' adds to the defaults of each "
                          "recipe that compares trackers, '-name' or '~name' removes one, a plain list replaces them "
                          "(e.g. --trackers '+gm-phd(prune=1e-5)'); refused for a --paper that compares none")
    rep.add_argument("--seed", type=int, default=0, help="base seed of every random stream (default 0)")
    rep.add_argument("--arch", default="cpu", choices=list(kernel_policy.ARCHES),
                     help="Taichi backend for kernels (default cpu; auto falls back to cpu; a GPU arch speeds up "
                          "large kernel calls, not the papers' report, whose calls are small)")
    rep.add_argument("--no-progress", action="store_true", help="no progress bars")
    rep.add_argument("--wait", type=_seconds, default=0.0, metavar="SECONDS",
                     help="if another report is writing into --out, wait up to this long for it (default: refuse at "
                          "once, naming it)")
    rep.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="send the tasks to this Dask distributed scheduler (pip install -e '.[dask]')")
    rep.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                     help="start a local Dask cluster of N worker processes for the tasks")
    rep.add_argument("--jobs", type=_positive_int, default=None, metavar="N",
                     help="run the tasks on N local worker processes, bit-identical to one (default: $WORKBENCH_JOBS, else the usable "
                          f"cores, at most {DEFAULT_JOBS_CAP}; --jobs 1 runs them one after another in this process)")

    run = sub.add_parser("run", help="run one scenario file: a results file and its plots")
    run.add_argument("scenario", help="scenario TOML file")
    run.add_argument("--out", default=None, help="output folder (default: next to the scenario, <name>-results)")
    run.add_argument("--seed", type=int, default=None, help="override the scenario's seed")
    run.add_argument("--trackers", default=None, action=_Once,
                     help="comma-separated installed trackers applied to the scenario's [trackers] names, as "
                          "'workbench report --trackers': '+name' adds, '-name' or '~name' removes, a plain list "
                          "replaces (e.g. --trackers '+gm-phd(prune=1e-5)'); refused for a scenario without "
                          "[trackers]")

    chk = sub.add_parser("check-plugin", help="run the test kit that fits an installed filter, sensor, clutter "
                                              "generator, clutter remover, motion model or tracker")
    chk.add_argument("name", help="component name (as listed by 'workbench plugins')")
    chk.add_argument("--kind", choices=sorted(KIT_KINDS), default=None,
                     help="which kind of component NAME is, where two kinds share the name (default: every kind "
                          "that has one)")

    bench = sub.add_parser("bench", help="run the benchmark suite and print a table")
    bench.add_argument("--quick", action="store_true", help="small sizes (seconds, for CI)")
    bench.add_argument("--json", default="workbench-bench.json", help="write the figures here as JSON")
    bench.add_argument("--only", action="append", default=[], help="only this benchmark group (repeatable)")
    bench.add_argument("--repeats", type=int, default=None, metavar="R",
                       help="run each group R times, each in a fresh process, and report every figure's median with "
                            "its min and max; targets are judged on the median (default: 3, with --quick 1)")
    bench.add_argument("--arch", default="cpu", choices=list(kernel_policy.RUN_ARCHES),
                       help="run the Taichi kernels on this arch (cuda: the GPU; default: cpu)")
    bench.add_argument("--plot", default=None, metavar="DIR",
                       help="draw the scaling figures (PNG, SVG and CSV per figure) into DIR")
    bench.add_argument("--from", dest="from_json", default=None, metavar="JSON",
                       help="run nothing: draw the figures of a saved --json file (needs --plot)")
    return parser


def _check_block(block: list[str]) -> None:
    """``--block`` follows the rules of every list: no empty name, no plugin named twice."""
    from .references import refuse_repeats

    for name in block:
        if not name.strip():
            raise InputError(f"--block {name!r}: expected a plugin name (see 'workbench plugins')")
    refuse_repeats(((name, name) for name in block), "--block", "plugin")


def _host(args) -> PluginHost:
    _check_block(args.block)
    host = load_host(block=args.block)
    for p in host.broken:
        print(f"workbench: warning: plugin {p.name} ({p.distribution} {p.version}) is broken: {p.error}",
              file=sys.stderr)
    for warning in host.warnings:
        print(f"workbench: warning: {warning}", file=sys.stderr)
    known = {p.name for p in host.plugins}
    for name in args.block:
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else f" (plugins: {', '.join(sorted(known))})"
            print(f"workbench: warning: --block {name!r} matches no installed plugin{hint}", file=sys.stderr)
    return host


def _unavailable(host: PluginHost, name: str) -> str:
    """``": the filter 'ss-ukf' needs ..."`` where a loaded plugin says why it cannot provide ``name`` here."""
    reasons = [f"the {kind} {comp!r} {why}" for (kind, comp), why in host.unavailable.items() if comp == name]
    return (": " + "; ".join(reasons)) if reasons else ""


def _describe_component(host: PluginHost, name: str) -> int:
    from .params import describe

    found = host.find(name)
    if not found:
        everything = sorted({n for table in host.components.values() for n in table})
        close = difflib.get_close_matches(name, everything, n=3)
        raise UnknownComponent(f"no component named {name!r} is installed" + _unavailable(host, name)
                               + (f"; did you mean {', '.join(close)}?" if close else ""))
    for kind, spec in found:
        label = getattr(spec, "name", None) or getattr(spec, "paper", None) or getattr(spec, "group", name)
        print(f"{kind} {label}: {getattr(spec, 'summary', '') or getattr(spec, 'title', '')}")
        caps = sorted(getattr(spec, "capabilities", ()) or ())
        if caps:
            print(f"  capabilities: {', '.join(caps)}")
        frame = spec.detection_frame() if hasattr(spec, "detection_frame") else ""
        if frame:
            print(f"  frame of its detections: {frame}")
        if hasattr(spec, "declared"):
            rows = [(*r[:4], r[4] + (f" [{p.role}]" if p.role else ""))  # what a sensor's parameter reaches
                    for r, p in zip(describe(spec.declared, spec.params), spec.declared)]
            if rows:
                head = ("parameter", "type", "unit", "value", "meaning")
                widths = [max(len(str(r[i])) for r in rows + [head]) for i in range(4)]
                print("  " + "  ".join(str(v).ljust(widths[i]) for i, v in enumerate(head[:4])) + "  " + head[4])
                for r in rows:
                    print("  " + "  ".join(str(v).ljust(widths[i]) for i, v in enumerate(r[:4])) + "  " + r[4])
            else:
                print("  no parameters")
        owner = next((p for p in host.plugins if (kind, label) in p.provides), None)
        if owner is not None:
            print(f"  from plugin {owner.name} ({owner.distribution} {owner.version})")
    return 0


def cmd_plugins(args) -> int:
    host = _host(args)
    if args.name:
        return _describe_component(host, args.name)
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


def _check_papers(host: PluginHost, papers: list[str]) -> None:
    """``--paper`` follows the rules of every list: each an installed paper (refused with the installed ones),
    none named twice; checked before any paper runs."""
    from .references import refuse_repeats

    refuse_repeats(((p, p) for p in papers), "--paper", "paper")
    for paper in papers:
        if paper not in host.recipes:
            close = difflib.get_close_matches(paper, sorted(host.recipes), n=3)
            raise InputError(f"--paper {paper!r}: no paper {paper!r} is installed (installed: "
                             f"{', '.join(sorted(host.recipes)) or 'none'})"
                             + (f"; did you mean {', '.join(close)}?" if close else ""))


def cmd_report(args) -> int:
    from .report.engine import filter_request, run_report

    host = _host(args)
    _check_papers(host, args.paper)
    if args.filters is not None:
        filter_request(args.filters, host)  # the whole request checked before any paper runs
    if args.trackers is not None:
        from .report.engine import tracker_papers

        tracker_papers([host.recipe(p) for p in (args.paper or sorted(host.recipes))], args.trackers, host,
                       named=bool(args.paper))
    if args.arch != "cpu":
        from .kernels.runtime import TaichiUnavailable, ensure_taichi

        try:
            args.arch = ensure_taichi(args.arch)  # "auto" resolves here, with a notice if it falls back
        except TaichiUnavailable as exc:
            raise InputError(str(exc)) from None
    command = "workbench " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    executor = None
    if args.jobs is not None and (args.scheduler or args.workers):
        raise InputError(f"--jobs {args.jobs} and --{'scheduler' if args.scheduler else 'workers'}: the tasks run "
                         "either on local worker processes (--jobs) or on Dask (--workers, --scheduler), not both")
    if not (args.scheduler or args.workers):
        from .report.engine import LocalProcesses, WorkerHostMismatch, usable_cores

        jobs = args.jobs if args.jobs is not None else _default_jobs(usable_cores())
        if jobs > 1:
            executor = LocalProcesses(host, jobs, block=args.block)
            try:
                executor.check_host()  # refused now, before any paper runs
            except WorkerHostMismatch as exc:
                if args.jobs is not None:  # asked for by name: refused by name
                    raise InputError(f"--jobs {args.jobs}: {exc}") from None
                executor = None  # the default on a host built in this process only: its tasks run here
    if args.scheduler or args.workers:
        from .report.engine import dask_executor

        try:
            executor = dask_executor(host, args.scheduler, args.workers, block=args.block)
        except InputError:
            raise
        except (OSError, TimeoutError) as exc:
            raise NetworkError(f"cannot reach the Dask scheduler {args.scheduler or '(local cluster)'}: "
                               f"{exc}") from None
    from .report.engine import DaskClusterLost

    try:
        report = run_report(host, Path(args.out), papers=args.paper or None, size=args.size, seed=args.seed,
                            filters=args.filters, arch=args.arch, progress=not args.no_progress, command=command,
                            trackers=args.trackers,
                            executor=executor, wait=args.wait)
    except DaskClusterLost as exc:  # the cluster went away mid-run: the network's exit code, as an unreachable one
        raise NetworkError(str(exc)) from None
    finally:
        if executor is not None:
            executor.close()
    for p in report.papers:
        counts = {}
        for c in p.criteria:
            counts[c.verdict] = counts.get(c.verdict, 0) + 1
        verdicts = ", ".join(f"{n} {v}" for v, n in counts.items()) or "none"
        marker = " (indicative: quick run)" if any(c.indicative for c in p.criteria) else ""
        computed = sum(float(t.get("seconds") or 0.0) for t in p.tasks if not t.get("cached") and not t.get("reused"))
        # the papers run side by side (their tasks share the workers): each paper's own compute, the wall at the end
        print(f"paper {p.paper}: {len(p.figures)} figures, {len(p.tables)} tables, "
              f"criteria: {verdicts}{marker}, {computed:.1f} s of tasks"
              + (f", {len(p.errors)} problems" if p.errors else ""))
        for err in p.errors:
            print(f"  not done: {err}", file=sys.stderr)
    if not report.papers:
        print("no report recipes are installed", file=sys.stderr)
    print(f"report: {report.out / 'index.html'} ({report.seconds:.1f} s wall)")
    return 1 if report.failed else 0


def cmd_run(args) -> int:
    from .scenario import load_scenario, run_scenario
    from .textfields import ImplausibleValueWarning

    host = _host(args)
    with warnings.catch_warnings():  # printed below, as the command line's own warning lines
        warnings.simplefilter("ignore", ImplausibleValueWarning)
        scenario = load_scenario(Path(args.scenario), host)
    if args.trackers is not None:
        scenario = _scenario_trackers(scenario, args.trackers, host)
    for note in scenario.notes:
        print(f"workbench: warning: {note}", file=sys.stderr)
    out = Path(args.out) if args.out else Path(args.scenario).with_name(f"{scenario.name}-results")
    result = run_scenario(scenario, host, out, seed=args.seed)
    print(result.summary_text())
    if result.failed:
        print(f"workbench: {len(result.failed)} of {len(scenario.filters)} filters failed "
              f"({', '.join(result.failed)}); the others' results are written", file=sys.stderr)
        return EXIT["partial"]
    return 0


def _scenario_trackers(scenario, request: str, host: PluginHost):
    """The scenario with ``--trackers`` applied to its ``[trackers]`` names (:func:`workbench.report.engine.
    resolve_trackers`), each checked against its declarations and against the scenario's detections as the file's
    own are; refused, naming the file, for a scenario that runs no installed trackers."""
    import dataclasses

    from .params import parse_reference
    from .report.engine import resolve_trackers, tracker_request
    from .scenario import INSTALLED_TRACKERS, Component, _check_frames

    tracker_request(request, host)  # the request's own mistakes first, whatever the scenario
    if scenario.tracker != INSTALLED_TRACKERS:
        raise InputError(f"--trackers {request!r}: scenario {scenario.path} runs no installed multi-target trackers "
                         f"(it has no [trackers] table: list its objects in [[targets]] or declare [births], and name "
                         f"the trackers in [trackers]), so the request would be ignored")
    chosen = resolve_trackers([c.label for c in scenario.trackers], request, host, f"{scenario.path} [trackers]")
    components = []
    for text in chosen:
        base, values = parse_reference(text, f"--trackers {text!r}")
        spec = host.tracker(base)
        changed = spec.changed(spec.check(**values))
        components.append(Component(base, changed, spec.configure(**changed).name if changed else base))
    _check_frames(scenario.path, host, scenario.sensor, scenario.clutter, scenario.removers, scenario.tracker,
                  scenario.detections_format, tuple(host.tracker(c.plugin) for c in components))
    return dataclasses.replace(scenario, trackers=tuple(components))


#: ``--kind`` value -> the kind label of :data:`workbench.plugins.KINDS` of the components that have a test kit.
KIT_KINDS = {"filter": "filter", "sensor": "sensor", "clutter-generator": "clutter generator",
             "clutter-remover": "clutter remover", "motion-model": "motion model", "tracker": "tracker"}

#: outcome status -> the word printed for it
_STATUS = {"passed": "PASSED", "failed": "FAILED", "xfailed": "XFAIL", "xpassed": "XPASS", "skipped": "SKIPPED"}


def check_plugin(host: PluginHost, name: str, kind: str | None = None, out=print) -> int:
    """Run the kit that fits component ``name`` (every kind that has one, or only ``kind``): one line per check,
    then a count; 1 when a check failed, else 0."""
    from .testing import run_checks

    labels = set(KIT_KINDS.values()) if kind is None else {KIT_KINDS[kind]}
    found = [(label, spec) for label, spec in host.find(name) if label in labels]
    if not found:
        what = ("filter, sensor, clutter generator, clutter remover, motion model or tracker" if kind is None
                else KIT_KINDS[kind])
        known = sorted({n for label in labels for n in _names(host, label)})
        raise UnknownComponent(f"no {what} named {name!r} is installed" + _unavailable(host, name)
                               + f" (installed: {', '.join(known) or 'none'})")
    if len(found) > 1:
        out(f"{name!r} is a {' and a '.join(label for label, _ in found)}: running each kit (choose one with "
            f"--kind)")
    counts = {status: 0 for status in _STATUS}
    for label, spec in found:
        owner = next((p for p in getattr(host, "plugins", ()) if (label, spec.name) in p.provides), None)
        out(f"-- {label} {spec.name}" + (f" (plugin {owner.name}, {owner.distribution} {owner.version})"
                                          if owner is not None else ""))
        # a motion model's kit checks the MotionModel it builds with its own values (over 1 s)
        checked = spec.model() if label == "motion model" else spec
        for o in run_checks(checked):
            out(f"{_STATUS[o.status]:8s} {spec.name}-{o.check}" + (f": {o.message}" if o.message else ""))
            counts[o.status] += 1
    extra = "".join(f", {counts[s]} {s}" for s in ("xfailed", "xpassed", "skipped") if counts[s])
    out(f"{counts['passed']} passed, {counts['failed']} failed{extra}")
    return 1 if counts["failed"] else 0


def _names(host: PluginHost, label: str) -> list[str]:
    from .plugins import KINDS

    return [n for hook, (lab, _, _) in KINDS.items() if lab == label for n in host.components.get(hook, {})]


def cmd_check_plugin(args) -> int:
    return check_plugin(_host(args), args.name, args.kind)


def version_lines(host: PluginHost) -> list[str]:
    """The workbench's version, then each installed plugin distribution with its version and its plugins (a
    plugin not loaded says why: blocked or broken)."""
    from . import __version__

    lines = [f"workbench {__version__}"]
    dists: dict[tuple[str, str], list[str]] = {}
    for p in host.plugins:
        if p.distribution == "-":
            continue
        dists.setdefault((p.distribution, p.version), []).append(p.name + ("" if p.status == "ok"
                                                                          else f" ({p.status})"))
    if dists:
        lines.append("plugin distributions:")
        width = max(len(f"{d} {v}") for d, v in dists)
        for (dist, ver), names in sorted(dists.items(), key=lambda kv: (kv[0][0] != "workbench", kv[0])):
            lines.append(f"  {f'{dist} {ver}'.ljust(width)}  plugins: {', '.join(names)}")
    else:
        lines.append("plugin distributions: none installed")
    return lines


def cmd_version(args) -> int:
    _check_block(args.block)
    for line in version_lines(load_host(block=args.block)):
        print(line)
    return 0


def cmd_bench(args) -> int:
    from .bench import replot, run_bench

    if args.from_json is not None:
        if args.plot is None:
            raise InputError("bench --from JSON draws figures: give --plot DIR as well")
        if not Path(args.from_json).is_file():
            raise InputError(f"bench --from: no such file {args.from_json!r}")
        return replot(Path(args.from_json), Path(args.plot))
    if args.repeats is not None and args.repeats < 1:
        raise InputError(f"bench --repeats: expected a whole number >= 1, got {args.repeats}")
    if args.arch != "cpu":
        from .kernels.runtime import taichi_available_arches

        if args.arch not in taichi_available_arches():
            raise InputError(f"bench --arch {args.arch}: Taichi finds no {args.arch} device on this machine, so GPU "
                             f"figures are not available here; run it where a GPU is lent, or use --arch cpu")
    host = _host(args)
    return run_bench(host, quick=args.quick, json_path=Path(args.json), only=args.only, block=tuple(args.block),
                     arch=args.arch, plot_dir=None if args.plot is None else Path(args.plot), repeats=args.repeats)


COMMANDS = {"plugins": cmd_plugins, "report": cmd_report, "run": cmd_run, "check-plugin": cmd_check_plugin,
            "bench": cmd_bench, "version": cmd_version}


def _normalise_argv(argv: list[str]) -> list[str]:
    """``--filters -ekf`` as ``--filters=-ekf`` (and ``--trackers -gnn`` likewise): a value that starts with '-'
    would otherwise read as an option."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in ("--filters", "--trackers") and i + 1 < len(argv) and argv[i + 1].startswith("-") \
                and argv[i + 1] != "--":
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


def _os_message(exc: OSError) -> str:
    what = exc.strerror or str(exc)
    if exc.errno == errno.ENOSPC:
        what = "no space left on the device"
    where = f" {exc.filename}" if exc.filename else ""
    return f"cannot use{where}: {what}"


def main(argv: list[str] | None = None) -> int:
    argv = _normalise_argv(list(sys.argv[1:] if argv is None else argv))
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = getattr(args, "debug", False)
    if args.version:
        args.command = "version"
    elif args.command is None:
        parser.error("the following arguments are required: command (or --version)")

    def fail(kind: str, message: str) -> int:
        if debug:
            traceback.print_exc()
        print(f"workbench: error: {message}", file=sys.stderr)
        return EXIT[kind]

    keep_freed_memory()  # this process's freed blocks reused, not faulted in again (workbench.memory)
    try:
        return COMMANDS[args.command](args)
    except (InputError, UnknownComponent) as exc:
        return fail("input", str(exc))
    except UnicodeDecodeError as exc:
        return fail("input", f"a file is not UTF-8 text ({exc.reason} at byte {exc.start}); save it as UTF-8")
    except NetworkError as exc:
        return fail("network", str(exc))
    except PluginFailure as exc:
        return fail("plugin", str(exc))
    except OSError as exc:
        return fail("os", _os_message(exc))
    except MemoryError:
        return fail("input", "the request needs more memory than this machine has; ask for fewer runs, steps or "
                             "particles")
    except KeyboardInterrupt:
        if debug:
            traceback.print_exc()
        what = {"report": "finished tasks are cached in the output folder and will be reused",
                "run": "nothing of this run was written", "bench": "no benchmark table was written"}
        print(f"workbench: interrupted; {what.get(args.command, 'nothing was written')}", file=sys.stderr)
        return EXIT["interrupted"]
    except Exception as exc:  # noqa: BLE001 - a bug: one line, the traceback with --debug
        frames = traceback.extract_tb(exc.__traceback__)
        at = f" at {Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else ""
        return fail("internal", f"internal error {type(exc).__name__}: {exc}{at} (run with --debug for the "
                                "traceback, and please report it)")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
