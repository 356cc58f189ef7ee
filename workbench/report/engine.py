"""Run report recipes: tasks (cached), then figures, tables and criteria from the saved results.

Output folder layout::

    OUT/index.html                 at a glance (one row per paper, its verdicts counted, a link to its page), provenance
    OUT/paper-NNN.html             the paper's page: scoreboard first, unknowns, what differs, figures (the PNG files
                                   below, linked), tables (ours beside published), published values, time table
    OUT/summary.json               machine-readable: criteria, tables, task timings, errors
    OUT/paperNNN/FIG.png|.svg      each figure (the formats: :data:`FIGURE_FORMATS`, or ``formats``, or the
                                   environment variable ``WORKBENCH_REPORT_FORMATS``, e.g. ``png``)
    OUT/paperNNN/FIG.npz, FIG.csv  the data behind it
    OUT/paperNNN/TABLE.csv         each table
    OUT/paperNNN/outcome.json      the paper's rendered outcome (tables, figure paths, criteria, tasks, notes,
                                   published values, errors, timings), so that ``--paper X`` into this folder
                                   keeps the other papers' sections
    OUT/cache/...                  finished task results (reused by the next run; an unreadable entry is
                                   renamed ``*.corrupt``, named in the report's warnings and recomputed)
    OUT/.workbench-report.lock     while a report runs: who holds the folder (pid, host, command, start);
                                   a second report into the same folder is refused, naming the holder

A component that fails inside a task shared with others (one filter among several run on the same
detections) does not take the task down when the task isolates it: the task returns its other results and
a string array ``error/<what>`` (:func:`component_failure`), which the report names in the paper's errors.
Such a partial result is never reused from the cache: the next report runs the task again, so a one-off
failure (a ``MemoryError``, a race) is not replayed until the code changes.

Only the full size gives firm verdicts: the criteria of any other size (the quick report) are marked
indicative (:meth:`workbench.criteria.Criterion.as_indicative`), so a quick report never says *met*.

The confirmation seed: the full report judges every criterion once more on :data:`CONFIRMATION_SEED`, a seed no
tuning and no design choice has seen.  It reruns only the tasks the recipe's criteria read (recorded while they
judge the reported seed's results), with that seed in place of the report's, judges the criteria again unchanged
and records, per criterion, the verdict there and whether it agrees
(:class:`workbench.criteria.Confirmation`); the confirmation tasks are cached under their own seed like any other.
A task declared ``seeded=False`` (:class:`workbench.specs.Task`: a tuning task on its own fixed tuning seed) is not
run again: the confirmation reuses its result on the reported seed; nor is a task declared ``sensitivity=True`` (a
non-primary grid value of a declared unknown), since the confirmation judges the primary values only.  A quick report runs no confirmation (its verdicts
are indications already).

Papers side by side: a report of several papers hands every paper's tasks on the reported seed to the workers in
one batch (the longest first, by the last report's times), judges each paper's criteria, then hands every paper's
confirmation tasks over in one more batch, which the workers run while this process draws the figures and tables;
each paper's results, time table and verdicts are those of the paper run alone (a task's result depends on its
seed and parameters only).  A paper's ``seconds`` is then the wall time from its start to its end, beside the
others; the command line prints each paper's own task seconds and the report's wall time.

The time table: every task the report runs (on the reported seed, at the declared unknowns' grid points, on the
confirmation seed) records its seconds and, where the task declares it, its number of runs;
:func:`task_time_table` turns them into a table per paper (task, runs, seconds, share of the paper's task compute,
computed / cached / reused / failed), written into ``outcome.json`` and ``summary.json`` (``task_times``) and shown,
collapsed, on the paper's page (``paper-NNN.html``); the ``report`` benchmark prints the report's top tasks by share.
"""

from __future__ import annotations

import csv
import dataclasses
import errno
import json
import os
import socket
import sys
import threading
import time
import traceback
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Mapping, Sequence

import numpy as np

from ..plugins import PluginHost, UnknownComponent
from ..criteria import Criterion, DeclaredUnknown, confirm
from ..memory import malloc_env
from ..specs import RecipeOptions, RecipeSpec, Table, Task, TaskContext
from ..types import InputError
if TYPE_CHECKING:
    from ..references import FilterReference
from .cache import (CacheEntryUnreadable, TaskCache, code_version, components_digest, save_arrays, task_key,
                    write_text_atomic)
from .tables import TASK_STATUSES, _jsonable, _task_status, paper_time_table, task_time_table

__all__ = ["resolve_filters", "resolve_trackers", "tracker_request", "tracker_papers", "PaperOutcome", "ReportOutcome", "run_recipe", "run_report", "figure_data_csv",
           "save_outcome", "load_outcome", "saved_outcomes", "OUTCOME_FILE", "InProcess", "DaskExecutor",
           "dask_executor", "component_failure", "component_errors", "COMPONENT_ERROR_PREFIX", "LOCK_FILE", "ReportFolderBusy",
           "report_lock", "recording_host", "side_by_side", "LocalProcesses", "WorkerHostMismatch", "usable_cores", "ONE_THREAD_ENV", "DaskClusterLost", "NO_WORKER_GRACE", "FIGURE_FORMATS", "FORMATS_VARIABLE", "figure_formats",
           "CONFIRMATION_SEED", "CONFIRMATION_SPAN", "check_report_seed", "judged_tasks", "task_time_table",
           "paper_time_table", "TASK_STATUSES"]

#: The file, inside ``OUT/paperNNN``, that keeps a paper's rendered outcome.
OUTCOME_FILE = "outcome.json"
#: The size whose verdicts are firm; every other size's criteria are marked indicative.
FIRM_SIZE = "full"
#: A task's result arrays named ``error/<what>`` name a component that failed inside the task (its other results
#: are kept): see :func:`component_failure`.
COMPONENT_ERROR_PREFIX = "error/"
#: The lock file, inside the report folder, held while a report writes into it.
LOCK_FILE = ".workbench-report.lock"
#: The confirmation seed (the one place it is declared): the full report judges every criterion once more on it.
#: No tuning and no design choice has seen it: the recipes' tuning seeds (paper 000: 101-104, paper 002: 7002,
#: paper 003: 20031; paper 001 tunes on its own stream) and the default report seed 0 lie far from it
#: (tests/test_confirmation_seed.py checks that every recipe's declared tuning seed differs from it).
CONFIRMATION_SEED = 770_001
#: Recipes derive further seeds from the report's as ``seed + j`` (paper 001's seed blocks): a report seed within
#: this distance of :data:`CONFIRMATION_SEED` would share data with the confirmation, and is refused.
CONFIRMATION_SPAN = 1000


def check_report_seed(seed: int, confirmation_seed: int | None = CONFIRMATION_SEED) -> None:
    """Refuse (one :class:`InputError` line) a report seed that is not an integer >= 0, or one within
    :data:`CONFIRMATION_SPAN` of the confirmation seed (its runs would not be independent of the confirmation)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"--seed {seed!r}: a seed is an integer >= 0")
    if confirmation_seed is not None and abs(int(seed) - int(confirmation_seed)) < CONFIRMATION_SPAN:
        raise InputError(f"--seed {seed}: within {CONFIRMATION_SPAN} of the confirmation seed {confirmation_seed} "
                         f"(the recipes derive seed + j from the report's seed, so its runs would overlap the "
                         f"confirmation's); choose a seed below {int(confirmation_seed) - CONFIRMATION_SPAN + 1} or "
                         f"above {int(confirmation_seed) + CONFIRMATION_SPAN - 1}")


class _ReadRecorder(Mapping):
    """A recipe's results, recording the task keys read through ``results[key]`` or ``results.get(key)``
    (a membership test or a look at the keys reads nothing)."""

    def __init__(self, results: Mapping):
        self._results, self.read = results, set()

    def __getitem__(self, key):
        value = self._results[key]
        self.read.add(key)
        return value

    def __contains__(self, key):
        return key in self._results

    def __iter__(self):
        return iter(self._results)

    def __len__(self):
        return len(self._results)


def judged_tasks(criteria: Callable[[Mapping], Sequence[Criterion]], results: Mapping) -> tuple[list[Criterion],
                                                                                                 set[str]]:
    """Judge ``criteria(results)`` and record which tasks' results it read: ``(criteria, task keys)``."""
    recorder = _ReadRecorder(results)
    judged = list(criteria(recorder))
    return judged, set(recorder.read)


#: The formats every figure is saved in by default: PNG (shown on the paper's page) and SVG (linked from it).
FIGURE_FORMATS = ("png", "svg")
#: The environment variable that chooses the formats where the caller does not (``png`` or ``png,svg``): the test
#: suite saves PNG only, drawing each figure once instead of twice.
FORMATS_VARIABLE = "WORKBENCH_REPORT_FORMATS"


def figure_formats(formats: Sequence[str] | str | None = None) -> tuple[str, ...]:
    """The figure formats of a report: ``formats`` (a sequence or ``"png,svg"``), else
    ``$WORKBENCH_REPORT_FORMATS``, else :data:`FIGURE_FORMATS`.

    PNG is always among them (the page embeds it); an unknown or repeated format, or one without PNG, is refused
    with an :class:`~workbench.types.InputError` naming where it came from.
    """
    where = "formats"
    if formats is None:
        text = os.environ.get(FORMATS_VARIABLE)
        if text is None:
            return FIGURE_FORMATS
        formats, where = text, f"{FORMATS_VARIABLE}={text!r}"
    if isinstance(formats, str):
        formats = [f for f in formats.split(",")]
    chosen = tuple(str(f).strip().lower() for f in formats)
    unknown = [f for f in chosen if f not in FIGURE_FORMATS]
    if unknown or not chosen:
        raise InputError(f"{where}: figure formats are {' and '.join(FIGURE_FORMATS)} (comma-separated), got "
                         f"{', '.join(repr(f) for f in unknown) or 'none'}")
    if len(set(chosen)) != len(chosen):
        raise InputError(f"{where}: a figure format is named twice ({', '.join(chosen)})")
    if "png" not in chosen:
        raise InputError(f"{where}: png is needed (the report page embeds each figure's PNG)")
    return tuple(f for f in FIGURE_FORMATS if f in chosen)


def component_failure(what: str, exc: BaseException) -> dict[str, np.ndarray]:
    """The result arrays that record that ``what`` (e.g. ``"filter:ukf"``) raised ``exc`` inside a task.

    A task that runs several components on shared inputs catches each one's exception, drops that component's
    partial results and adds these arrays to its result; the task's other results are kept, and the report
    names the failure in the paper's errors (``task 'sim/0': filter:ukf failed: RuntimeError: ...``).
    """
    return {f"{COMPONENT_ERROR_PREFIX}{what}": np.array(f"{type(exc).__name__}: {exc}")}


def component_errors(arrays: Mapping[str, np.ndarray]) -> list[tuple[str, str]]:
    """``[(what, message), ...]`` of the component failures recorded in a task's result."""
    return [(name[len(COMPONENT_ERROR_PREFIX):], str(np.asarray(value).reshape(-1)[0]) if np.size(value) else "")
            for name, value in arrays.items() if name.startswith(COMPONENT_ERROR_PREFIX)]


def split_references(text: str) -> list[str]:
    """Split a comma-separated list of component references, keeping ``name(a=1, b=2)`` whole; empty entries
    are kept (as ``""``) so that :func:`filter_request` can refuse them."""
    from ..references import split_list

    return split_list(text)


def filter_request(request: str, host: PluginHost) -> list[tuple[str, "FilterReference"]]:
    """``--filters`` read and checked on its own (before any recipe's defaults): ``[(sign, reference), ...]``
    with ``sign`` one of ``""``, ``"+"``, ``"-"`` (``~`` reads as ``-``).

    The same rules as a scenario file's ``[filters] names``, with the same messages
    (:mod:`workbench.references`): not empty, no empty entry, every name an installed filter (a sensor's name is
    refused as a sensor), values checked against its declarations, no filter added twice or removed twice (in any
    spelling; ``ekf,-ekf`` adds and then removes it).
    """
    from ..references import FILTER_FORMS, filter_reference

    return _signed_references(request, "--filters", "filter", FILTER_FORMS,
                               lambda text: filter_reference(host, text, f"--filters {text!r}"))


def _signed_references(request: str, option: str, kind: str, forms: str, reference) -> list:
    """``option``'s comma-separated entries as ``[(sign, reference(text)), ...]`` (sign ``"+"``, ``"-"`` for
    ``-`` or ``~``, or ``""``): not empty, no empty entry, no sign without a name, none added or removed twice."""
    from ..references import refuse_repeats, require_entries

    parts = split_references(request)
    require_entries(parts, option, kind, forms)
    out = []
    for i, part in enumerate(parts):
        sign = {"+": "+", "-": "-", "~": "-"}.get(part[:1], "")
        text = part[1:].strip() if sign else part
        if sign and not text:
            raise InputError(f"{option}: entry {i + 1} of {request!r} ({part!r}) has no {kind} name after "
                             f"{part[0]!r}")
        out.append((sign, reference(text)))
    refuse_repeats(((ref.text, ref.key) for sign, ref in out if sign != "-"), option, kind)
    refuse_repeats(((sign + ref.text, ref.key) for sign, ref in out if sign == "-"), option, kind)
    return out


def resolve_filters(default: Sequence[str], request: str | None, host: PluginHost) -> tuple[str, ...]:
    """Apply ``--filters`` to a recipe's default list.

    ``request`` is a comma-separated list of filter references (``name`` or ``name(key=value, ...)``, a configured
    filter); entries starting with ``+`` are added to the defaults, and ``-name`` (or ``~name``, which a shell
    cannot mistake for an option) removes one; if any entry has no sign, the list replaces the defaults.  The
    request follows a scenario file's rules (:func:`filter_request`); every removed filter must be in the list,
    and the result must not be empty.  A filter is matched by what it is, not how it is spelled: ``+sir`` adds
    nothing to a list that holds ``sir`` already, and ``-sir(particles=100)`` removes ``sir( particles=100 )``.
    """
    from ..references import filter_reference

    if request is None:
        return tuple(default)
    return _apply_request(filter_request(request, host), request, "--filters", "filter",
                          lambda: [filter_reference(host, name, f"the recipe's default filter {name!r}")
                                   for name in default])


def _apply_request(entries, request: str, option: str, kind: str, defaults) -> tuple[str, ...]:
    """``entries`` (sign, reference) of a ``--filters`` / ``--trackers`` request applied to the references
    ``defaults()`` (read only where the request keeps them): a list without signs replaces them, ``+`` adds one not yet there, ``-`` removes one that is (by what
    it is, not how it is spelled); the result is not empty."""
    plain = [ref for sign, ref in entries if not sign]
    chosen = [(ref.text, ref.key) for ref in (plain or defaults())]
    for sign, ref in entries:
        keys = [key for _, key in chosen]
        if sign == "+" and ref.key not in keys:
            chosen.append((ref.text, ref.key))
        elif sign == "-":
            if ref.key not in keys:
                raise InputError(f"{option}: cannot remove {ref.text!r}: it is not among "
                                 f"{', '.join(text for text, _ in chosen) or 'none'}")
            del chosen[keys.index(ref.key)]
    if not chosen:
        raise InputError(f"{option} {request!r} leaves no {kind} to compare")
    return tuple(text for text, _ in chosen)


#: How a tracker list is written; the message for an empty list shows it.
TRACKER_FORMS = "each a name such as 'gnn' or a configured tracker such as 'gm-phd(prune=1e-5)'"


def tracker_reference(host: PluginHost, text: str, where: str) -> "FilterReference":
    """One tracker reference, ``"name"`` or ``"name(key=value, ...)"``, checked against the installed trackers and
    their declarations (an unknown one is refused naming the installed ones); errors are prefixed by ``where``.
    The reference's ``key`` is the configured tracker's label (``base`` when no value differs from its defaults),
    which decides whether two entries are the same tracker."""
    from ..params import parse_reference
    from ..references import FilterReference, UnknownReference

    if not text.strip():
        raise InputError(f"{where}: an empty entry where a tracker belongs ({TRACKER_FORMS})")
    base, values = parse_reference(text, where)
    try:
        spec = host.tracker(base)
        checked = spec.check(**values)
    except UnknownComponent as exc:
        raise UnknownReference(f"{where}: {exc}") from None
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    changed = spec.changed(checked)
    return FilterReference(text.strip(), base, spec.configure(**changed).name if changed else base, changed)


def tracker_request(request: str, host: PluginHost) -> list[tuple[str, "FilterReference"]]:
    """``--trackers`` read and checked on its own (before any recipe's or scenario's defaults): ``[(sign,
    reference), ...]``, the rules of ``--filters`` (:func:`filter_request`) for installed trackers: not empty, no
    empty entry, every name an installed tracker, values checked against its declarations, none added or removed
    twice (in any spelling)."""
    return _signed_references(request, "--trackers", "tracker", TRACKER_FORMS,
                               lambda text: tracker_reference(host, text, f"--trackers {text!r}"))


def resolve_trackers(default: Sequence[str], request: str | None, host: PluginHost,
                     whose: str = "the recipe's") -> tuple[str, ...]:
    """Apply ``--trackers`` to a default list of trackers (a recipe's ``default_trackers``, a scenario's
    ``[trackers]``), as :func:`resolve_filters` applies ``--filters``: ``+name`` adds, ``-name`` / ``~name``
    removes one that is in the list, a list without signs replaces the defaults; the result is not empty.  A tracker
    is matched by what it is (its configured label), not how it is spelled."""
    if request is None:
        return tuple(default)
    return _apply_request(tracker_request(request, host), request, "--trackers", "tracker",
                          lambda: [tracker_reference(host, name, f"{whose} default tracker {name!r}")
                                   for name in default])


def tracker_papers(recipes: Sequence[RecipeSpec], request: str | None, host: PluginHost,
                   named: bool) -> dict[str, str | None]:
    """Which recipes ``--trackers`` goes to, checked before any paper runs: ``{paper: request or None}``.

    A recipe takes it when it declares ``default_trackers`` (its tasks run :attr:`RecipeOptions.trackers`).
    Papers the user ``named`` (``--paper``) must each take it, or the request is refused naming them; without
    ``--paper`` it goes to every paper that takes it (the others compare no trackers and run as they are), and is
    refused when none does.  The request itself is checked first (:func:`tracker_request`)."""
    if request is None:
        return {r.paper: None for r in recipes}
    tracker_request(request, host)
    takers = [r.paper for r in recipes if r.default_trackers]
    refused = [r.paper for r in recipes if not r.default_trackers]
    if (named and refused) or not takers:
        which = refused if named else [r.paper for r in recipes]
        raise InputError(f"--trackers {request!r}: paper{'s' if len(which) > 1 else ''} {', '.join(which)} "
                         f"compare{'' if len(which) > 1 else 's'} no installed multi-target trackers (no "
                         f"default_trackers declared), so the request would be ignored"
                         + (f"; papers that take --trackers: {', '.join(takers)}" if takers else ""))
    resolved = {}
    for r in recipes:
        if r.default_trackers:
            resolve_trackers(r.default_trackers, request, host, f"paper {r.paper}'s")  # refused now, not mid-report
        resolved[r.paper] = request if r.default_trackers else None
    return resolved


@dataclass
class PaperOutcome:
    """One paper's rendered outcome: what ``index.html`` and ``summary.json`` show of it.

    ``figures`` entries hold ``id, caption, png, svg, data`` (paths), ``tables`` entries ``id, caption,
    columns, rows, csv``, ``tasks`` entries ``key, seconds, cached, error``; ``unknowns`` are the recipe's
    declared unknowns (the criteria's verdicts across them are in ``Criterion.across``).  ``saved`` is True for an
    outcome read back from an earlier run's ``outcome.json`` (a paper not re-run this time).
    """

    paper: str
    title: str
    size: str
    filters: tuple[str, ...]
    notes: str
    published: Mapping
    figures: list[dict] = field(default_factory=list)  # id, caption, png, svg, data
    tables: list[dict] = field(default_factory=list)  # id, caption, columns, rows, csv
    criteria: list[Criterion] = field(default_factory=list)
    tasks: list[dict] = field(default_factory=list)  # key, seconds, cached, error
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # e.g. a cache entry that could not be read
    seconds: float = 0.0
    seed: int | None = None
    command: str = ""
    finished: str = ""  # UTC time stamp
    saved: bool = False
    unknowns: list[DeclaredUnknown] = field(default_factory=list)
    #: The seed the criteria were judged on once more (``Criterion.confirmation``); None where none ran.
    confirmation_seed: int | None = None
    #: Seconds spent outside the tasks, by stage (``"figures and tables"``, ``"criteria"``): the time table's margin.
    stage_seconds: dict = field(default_factory=dict)
    #: Seconds of each figure and table, by part: ``{"figure fig3": {"data": s, "csv": s, "draw and png": s,
    #: "svg": s}, "table t1": {"make and csv": s}}``.
    item_seconds: dict = field(default_factory=dict)


@dataclass
class ReportOutcome:
    """A report run: ``papers`` are the papers run now; ``saved`` the other papers found in ``out``."""

    out: Path
    papers: list[PaperOutcome]
    seconds: float
    command: str
    seed: int
    size: str
    saved: list[PaperOutcome] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def failed(self) -> bool:
        return any(p.errors for p in self.papers)

    @property
    def all_papers(self) -> list[PaperOutcome]:
        """Every paper the report shows: those run now and the saved ones, ordered by paper id."""
        return sorted([*self.papers, *self.saved], key=lambda p: p.paper)


def _rel(path: Path | str | None, out: Path) -> str | None:
    if path is None:
        return None
    path = Path(path)
    try:
        return path.relative_to(out).as_posix()
    except ValueError:
        return str(path)


def outcome_dict(outcome: PaperOutcome, out: Path) -> dict:
    """``outcome`` as JSON data, with file paths relative to the report folder ``out``."""
    return {
        "format": 1,
        "paper": outcome.paper, "title": outcome.title, "size": outcome.size, "filters": list(outcome.filters),
        "notes": outcome.notes, "published": _jsonable(outcome.published),
        "seed": outcome.seed, "confirmation_seed": outcome.confirmation_seed, "command": outcome.command,
        "finished": outcome.finished,
        "seconds": outcome.seconds, "errors": list(outcome.errors), "warnings": list(outcome.warnings),
        "figures": [{"id": f["id"], "caption": f["caption"],
                     **{k: _rel(f.get(k), out) for k in ("png", "svg", "data")}} for f in outcome.figures],
        "tables": [{"id": t["id"], "caption": t["caption"], "columns": _jsonable(t["columns"]),
                    "rows": _jsonable(t["rows"]), "csv": _rel(t.get("csv"), out)} for t in outcome.tables],
        "criteria": [c.to_dict() for c in outcome.criteria],
        "unknowns": [u.to_dict() for u in outcome.unknowns],
        "tasks": [_jsonable(t) for t in outcome.tasks],
        "task_times": _jsonable(paper_time_table(outcome)),
    }


def save_outcome(outcome: PaperOutcome, out: Path) -> Path:
    """Write ``out/paperNNN/outcome.json`` atomically and return its path."""
    path = Path(out) / f"paper{outcome.paper}" / OUTCOME_FILE
    write_text_atomic(path, json.dumps(outcome_dict(outcome, Path(out)), indent=1, allow_nan=True))
    return path


def load_outcome(path: Path, out: Path) -> PaperOutcome:
    """Read a paper's outcome written by :func:`save_outcome` (paths resolved against ``out``).

    Raises
    ------
    ValueError, KeyError, TypeError, OSError
        When the file is missing, not JSON, or not an outcome.
    """
    out = Path(out)
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    if not isinstance(data, dict) or data.get("format") != 1:
        raise ValueError("not a workbench paper outcome (format 1)")
    at = lambda rel: None if rel is None else out / rel  # noqa: E731
    return PaperOutcome(
        paper=str(data["paper"]), title=str(data["title"]), size=str(data["size"]),
        filters=tuple(data.get("filters", ())), notes=str(data.get("notes", "")),
        published=dict(data.get("published") or {}),
        figures=[{"id": f["id"], "caption": f["caption"], "png": at(f["png"]), "svg": at(f.get("svg")),
                  "data": at(f.get("data"))} for f in data.get("figures", [])],
        tables=[{"id": t["id"], "caption": t["caption"], "columns": list(t["columns"]),
                 "rows": [list(r) for r in t["rows"]], "csv": at(t.get("csv"))} for t in data.get("tables", [])],
        criteria=[Criterion.from_dict(c) for c in data.get("criteria", [])],
        tasks=list(data.get("tasks", [])), errors=list(data.get("errors", [])),
        warnings=list(data.get("warnings", [])),
        seconds=float(data.get("seconds", 0.0)), seed=data.get("seed"), command=str(data.get("command", "")),
        finished=str(data.get("finished", "")), saved=True,
        unknowns=[DeclaredUnknown.from_dict(u) for u in data.get("unknowns", [])],
        confirmation_seed=data.get("confirmation_seed"),
        stage_seconds=dict((data.get("task_times") or {}).get("other_seconds") or {}),
        item_seconds={str(i["what"]): dict(i.get("parts") or {}) for i in (data.get("task_times") or {}).get("items", [])})


def saved_outcomes(out: Path, skip: Iterable[str] = ()) -> tuple[list[PaperOutcome], list[str]]:
    """The papers saved in ``out`` (``paper*/outcome.json``) other than those in ``skip``.

    Returns
    -------
    (list of PaperOutcome, list of str)
        The outcomes, and one warning line per saved outcome that could not be read (it is skipped).
    """
    out, skip = Path(out), set(skip)
    found, warnings = [], []
    for path in sorted(out.glob(f"paper*/{OUTCOME_FILE}")):
        if path.parent.name[len("paper"):] in skip:
            continue
        try:
            outcome = load_outcome(path, out)
        except Exception as exc:  # noqa: BLE001 - a damaged file must not take the report down
            warnings.append(f"skipped the saved outcome {path}: {type(exc).__name__}: {exc}")
            continue
        if outcome.paper in skip:
            continue
        found.append(outcome)
    return found, warnings


def figure_data_csv(data: Mapping[str, np.ndarray], path: Path) -> None:
    """Write the data behind a figure as a long CSV: ``name, index, value`` (strings kept as is)."""
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["name", "index", "value"])
        for name, value in data.items():
            arr = np.asarray(value)
            if arr.ndim == 0:
                writer.writerow([name, "", arr.item()])
                continue
            for idx in np.ndindex(arr.shape):
                writer.writerow([name, ";".join(map(str, idx)), arr[idx]])


def _write_table(table: Table, path: Path) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(table.columns)
        writer.writerows(table.rows)


def run_recipe(recipe: RecipeSpec, host: PluginHost, out: Path, *, size: str = "quick", seed: int = 0,
               filters: str | None = None, arch: str = "cpu", progress: bool = True, trackers: str | None = None,
               on_task: Callable[[str], None] | None = None, executor: "Executor | None" = None,
               command: str = "", formats: Sequence[str] | str | None = None,
               confirmation_seed: int | None | str = "auto") -> PaperOutcome:
    """Run one recipe into ``out/paperNNN`` using the cache in ``out/cache``.

    The criteria of any size but ``"full"`` are marked indicative (never *met*), and the outcome is saved
    to ``out/paperNNN/outcome.json``.  Figures are saved in ``formats`` (:func:`figure_formats`: by default PNG
    and SVG).  ``confirmation_seed``: the seed every criterion is judged on once more (``"auto"``:
    :data:`CONFIRMATION_SEED` for the full size, none for any other; ``None``: none); only the tasks the criteria
    read are rerun with it.
    """
    return _run_papers([recipe], host, out, size=size, seed=seed, filters=filters, arch=arch, progress=progress,
                       trackers={recipe.paper: trackers}, on_task=on_task, executor=executor, command=command,
                       formats=formats, confirmation_seed=confirmation_seed)[0]


@dataclass
class _Batch:
    """One recipe's tasks on one seed: run beside the other recipes' batches of the same seed (:func:`_execute`),
    their results and time-table entries kept apart."""

    recipe: RecipeSpec
    tasks: list
    seed: int
    size: str
    arch: str
    version: str
    outcome: PaperOutcome  # where the batch's task entries, errors and warnings go
    previous: Mapping[str, float]  # task key -> seconds it took in the last report into the folder
    results: dict = field(default_factory=dict)
    pending: list = field(default_factory=list)  # (task, cache digest) of the tasks not in the cache


@dataclass
class _PaperRun:
    """One recipe's report: its options, its reported seed's batch and, after the criteria, its confirmation's."""

    recipe: RecipeSpec
    options: RecipeOptions
    outcome: PaperOutcome
    paper_dir: Path
    version: str
    main: _Batch
    confirmation_seed: int | None
    start: float
    previous_confirmation: Mapping[str, float]
    formats: tuple
    read: set = field(default_factory=set)
    confirmation: _Batch | None = None
    reused: list = field(default_factory=list)  # (task, why) the confirmation takes from the reported seed
    rejudged: tuple | None = None  # the criteria on the confirmation seed: ("ok", criteria) or ("error", why)


def _begin(recipe: RecipeSpec, host: PluginHost, out: Path, *, size: str, seed: int, filters: str | None, arch: str,
           trackers: str | None, command: str, formats: tuple, confirmation_seed: int | None | str) -> _PaperRun:
    """Everything about one recipe's report that comes before its tasks run: the checks, the options, its tasks."""
    start = time.perf_counter()
    if confirmation_seed == "auto":
        confirmation_seed = CONFIRMATION_SEED if size == FIRM_SIZE else None
    check_report_seed(seed, confirmation_seed)
    if size not in recipe.sizes:
        raise InputError(f"recipe {recipe.paper} has no size {size!r} (sizes: {', '.join(recipe.sizes)})")
    chosen = resolve_filters(recipe.default_filters, filters, host) if recipe.default_filters else ()
    if trackers is not None and not recipe.default_trackers:
        tracker_papers([recipe], trackers, host, named=True)  # refused, naming the paper
    chosen_trackers = (resolve_trackers(recipe.default_trackers, trackers, host, f"paper {recipe.paper}'s")
                       if recipe.default_trackers else ())
    options = RecipeOptions(size=size, values=dict(recipe.sizes[size]), seed=seed, filters=chosen, arch=arch,
                            trackers=chosen_trackers)
    outcome = PaperOutcome(recipe.paper, recipe.title, size, chosen, recipe.notes, dict(recipe.published),
                           seed=seed, command=command, unknowns=list(getattr(recipe, "unknowns", ()) or ()))
    paper_dir = out / f"paper{recipe.paper}"
    paper_dir.mkdir(parents=True, exist_ok=True)

    tasks = list(recipe.tasks(options))
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise InputError(f"recipe {recipe.paper} declares duplicate task keys: {sorted({k for k in keys if keys.count(k) > 1})}")
    # A task's key covers the core and the recipe's own code, never the host's whole plugin list: the components a
    # task asks the host for are recorded when it runs and checked when its entry is read (TaskCache.get), so a
    # plugin the task does not use can come, go or be blocked without discarding its result.
    modules = {recipe.tasks.__module__} | {getattr(t.run, "__module__", None) for t in tasks}
    module_files = tuple(sorted(f for m in modules if m and (f := getattr(sys.modules.get(m), "__file__", None))))
    version = code_version(module_files)
    # the seconds of the last report into this folder, read before this one overwrites them: the order of the tasks
    # on workers that run side by side (longest first)
    main = _Batch(recipe, tasks, seed, size, arch, version, outcome, previous_seconds(out, recipe.paper))
    return _PaperRun(recipe, options, outcome, paper_dir, version, main,
                     None if confirmation_seed is None else int(confirmation_seed), start,
                     previous_seconds(out, recipe.paper, "confirmation/"), formats)


def _judge(pr: _PaperRun) -> None:
    """After the reported seed's tasks: their entries in the declared order, the components that failed inside a
    task, and the criteria (with the set of tasks they read)."""
    outcome, keys = pr.outcome, [t.key for t in pr.main.tasks]
    outcome.tasks.sort(key=lambda t: keys.index(t["key"]))
    for entry in outcome.tasks:  # components that failed inside a task whose other results were kept
        failed = component_errors(pr.main.results.get(entry["key"], {}))
        if failed:
            entry["partial"] = [f"{what} failed: {msg}" for what, msg in failed]
            outcome.errors.extend(f"task {entry['key']!r}: {what} failed: {msg} (the task's other results are kept)"
                                  for what, msg in failed)
    if pr.recipe.criteria is not None:
        t0 = time.perf_counter()
        try:
            outcome.criteria, pr.read = judged_tasks(pr.recipe.criteria, pr.main.results)
        except Exception as exc:  # noqa: BLE001
            outcome.errors.append(f"criteria not evaluated: {type(exc).__name__}: {exc}")
        outcome.stage_seconds["criteria"] = time.perf_counter() - t0


def _confirmation_batch(pr: _PaperRun) -> _Batch | None:
    """The tasks the criteria read, again with the confirmation seed (cached under it), less those whose result on
    the reported seed stands for the confirmation's: a task declared ``seeded=False`` (its result on the reported
    seed is the result on any seed, where the reported seed's task with that key had the same parameters and
    finished) and a task declared ``sensitivity=True`` (a non-primary grid value of a declared unknown: the
    confirmation records the verdicts at the primary values only (:func:`workbench.criteria.confirm`), which such a
    task does not feed; the re-judged criteria read the reported seed's result for it, and their ``across`` is
    discarded).  ``None`` where there is no confirmation (no criteria, or no confirmation seed)."""
    if not pr.outcome.criteria or pr.confirmation_seed is None:
        return None
    seed = pr.confirmation_seed
    again_options = dataclasses.replace(pr.options, seed=seed)
    reported = {t.key: t for t in pr.main.tasks}
    results = pr.main.results

    def why_reused(task: Task) -> str:
        """Why ``task`` is not run again on the confirmation seed ('' where it is)."""
        before = reported.get(task.key)
        if before is None or task.key not in results:
            return ""
        if not task.seeded and not before.seeded and dict(before.params) == dict(task.params):
            return "the reported seed's result (seeded=False)"
        if task.sensitivity and before.sensitivity:
            return "the reported seed's result (sensitivity point: the confirmation judges the primary values)"
        return ""

    wanted = [t for t in pr.recipe.tasks(again_options) if t.key in pr.read]
    pr.reused = [(t, why_reused(t)) for t in wanted if why_reused(t)]
    tasks = [t for t in wanted if not why_reused(t)]
    note = PaperOutcome(pr.recipe.paper, pr.recipe.title, pr.options.size, pr.options.filters, "", {})
    # the order on side-by-side workers: the seconds each task took on the confirmation seed in the last report
    # into this folder, else the seconds the same task just took on the reported seed (the same work on other data)
    just = {e["key"]: float(e["seconds"]) for e in pr.outcome.tasks
            if _task_status(e) == "computed" and float(e.get("seconds") or 0.0) > 0.0}
    pr.confirmation = _Batch(pr.recipe, tasks, seed, pr.options.size, pr.options.arch, pr.version, note,
                             {**just, **pr.previous_confirmation})
    return pr.confirmation


def _finish(pr: _PaperRun, out: Path) -> PaperOutcome:
    """The confirmation's verdicts beside the reported ones, the indicative mark below the firm size, the outcome
    saved."""
    outcome, batch, seed = pr.outcome, pr.confirmation, pr.confirmation_seed
    if batch is not None:
        for task, why in pr.reused:
            outcome.tasks.append({"key": f"confirmation/{task.key}", "seconds": 0.0, "cached": False, "error": "",
                                  "runs": task.runs, "seed": seed, "reused": why})
        note = batch.outcome
        order = [t.key for t in batch.tasks]
        for entry in sorted(note.tasks, key=lambda e: order.index(e["key"])):
            outcome.tasks.append({**entry, "key": f"confirmation/{entry['key']}", "seed": seed})
        outcome.warnings.extend(note.warnings)
        outcome.warnings.extend(f"paper {pr.recipe.paper}, confirmation seed {seed}: {line}" for line in note.errors)
        lost = [t.key for t in batch.tasks if t.key not in batch.results]
        if lost:
            why = (f"the task(s) {', '.join(lost)} failed on the confirmation seed {seed}: "
                   + "; ".join(note.errors or ["a component failed inside them"]))
            outcome.warnings.append(f"paper {pr.recipe.paper}: no confirmation: {why}")
            outcome.criteria = confirm(outcome.criteria, None, seed, why)
        else:
            status, value = pr.rejudged or _rejudge(pr)
            if status == "error":  # the reported verdicts stand; the confirmation says why not
                outcome.warnings.append(f"paper {pr.recipe.paper}: no confirmation: {value}")
                outcome.criteria = confirm(outcome.criteria, None, seed, value)
            else:
                outcome.criteria = confirm(outcome.criteria, value, seed)
    if pr.options.size != FIRM_SIZE:
        outcome.criteria = [c.as_indicative() for c in outcome.criteria]
    outcome.confirmation_seed = seed
    outcome.seconds = time.perf_counter() - pr.start
    outcome.finished = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    save_outcome(outcome, out)
    return outcome


def _rejudge(pr: _PaperRun) -> tuple:
    """The criteria on the confirmation seed (its batch complete): ``("ok", criteria)``, or ``("error", why)`` where
    they raise."""
    try:
        return "ok", list(pr.recipe.criteria({**pr.main.results, **pr.confirmation.results}))
    except Exception as exc:  # noqa: BLE001 - reported by _finish
        return "error", (f"the criteria raised on the confirmation seed {pr.confirmation_seed}: "
                         f"{type(exc).__name__}: {exc}")


def _draw(pr: _PaperRun) -> None:
    t0 = time.perf_counter()
    _draw_and_tabulate(pr.recipe, pr.main.results, pr.outcome, pr.paper_dir, pr.formats)
    pr.outcome.stage_seconds["figures and tables"] = time.perf_counter() - t0


def _run_papers(recipes: Sequence[RecipeSpec], host: PluginHost, out: Path, *, size: str, seed: int,
                filters: str | None, arch: str, progress: bool, trackers: Mapping[str, str | None],
                on_task: Callable[[str], None] | None, executor: "Executor | None", command: str,
                formats: Sequence[str] | str | None, confirmation_seed: int | None | str = "auto"
                ) -> list[PaperOutcome]:
    """Run ``recipes`` side by side: every paper's tasks on the reported seed as one batch (longest first on
    workers that run side by side), then each paper's criteria, then every paper's confirmation tasks as one batch;
    on side-by-side workers the figures and tables are drawn here while the workers run the confirmation.  Each
    paper's results, time table and outcome are its own, as if it had run alone (the same numbers: a task's result
    depends on its seed and parameters only)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    formats = figure_formats(formats)
    cache = TaskCache(out / "cache")
    run = executor if executor is not None else InProcess(host)
    runs = [_begin(r, host, out, size=size, seed=seed, filters=filters, arch=arch, trackers=trackers.get(r.paper),
                   command=command, formats=formats, confirmation_seed=confirmation_seed) for r in recipes]
    label = (f"paper {recipes[0].paper} ({size})" if len(recipes) == 1
             else f"papers {', '.join(r.paper for r in recipes)} ({size})")
    # the reported seed: this process only waits, so a timed task goes first (no worker idle at the batch's end);
    # the confirmation seed: it draws the figures beside the workers at first, so a timed task goes last, or (an
    # executor that holds timed tasks) on the next free worker once the figures are drawn; each paper is judged as
    # soon as its tasks are back, while the workers run the other papers' tasks (_execute's on_done)
    paper_of = {id(pr.main): pr for pr in runs}
    _execute([pr.main for pr in runs], host, cache, run, progress=progress, on_task=on_task, label=label,
             timed_last=False, on_done=lambda batch: _judge(paper_of[id(batch)]))
    again = [b for pr in runs if (b := _confirmation_batch(pr)) is not None]
    confirming = {id(pr.confirmation): pr for pr in runs if pr.confirmation is not None}

    def rejudge(batch: _Batch) -> None:  # a paper's confirmation judged as soon as its tasks are back
        pr = confirming[id(batch)]
        if all(t.key in batch.results for t in batch.tasks):
            pr.rejudged = _rejudge(pr)

    conf_label = f"{label[:-1]}, confirmation seed {again[0].seed})" if again else ""

    drawn = threading.Event()  # set once this process has drawn the figures: the timed tasks may start then

    def confirm_all():
        _execute(again, host, cache, run, progress=progress, on_task=on_task, label=conf_label, hold=drawn,
                 on_done=rejudge)

    if again and not isinstance(run, InProcess):
        # the workers run the confirmation while this process draws the figures and tables
        failure: list[BaseException] = []

        def background():
            try:
                confirm_all()
            except BaseException as exc:  # noqa: BLE001 - raised again in the calling thread below
                failure.append(exc)

        worker = threading.Thread(target=background, name="workbench-confirmation", daemon=True)
        worker.start()
        try:
            for pr in runs:
                _draw(pr)
        finally:
            drawn.set()
            worker.join()
        if failure:
            raise failure[0]
    else:
        for pr in runs:
            _draw(pr)
        drawn.set()
        if again:
            confirm_all()
    return [_finish(pr, out) for pr in runs]


def _task_cost(task: Task, seconds: Mapping[str, float], i: int, batch: int = 0, timed_last: bool = True) -> tuple:
    """The sort key of ``task``, the ``i``-th of batch ``batch``: the tasks without a time first, the batches taken
    in turn (the first task of every batch, then the second of every batch...), then the longest first; ties keep
    the declared order; a ``timed`` task after every other one (``timed_last``) or before (the same rules among
    them)."""
    known = seconds.get(task.key)
    group = (1 if timed_last else 0) if task.timed else (0 if timed_last else 1)
    return (group, 0, i, batch) if known is None else (group, 1, -float(known), batch, i)


def side_by_side(batches: Sequence[tuple[Sequence[Task], Mapping[str, float]]],
                 timed_last: bool = True) -> list[Task]:
    """The tasks of several batches (each its tasks and ``seconds``, task key -> the seconds it took last time) in
    the order a pool of workers should take them: the tasks without a time first, a task of each batch in turn
    (each batch's in its declared order), so that workers starting side by side mostly run different batches'
    tasks; then every task with a time, the longest first (ties: the batches' order, then the declared order); the
    tasks declared ``timed`` (wall-clock measurements, :class:`~workbench.specs.Task`) apart, by the same rules:
    after every other task (``timed_last``: while the report's own process works beside the workers at first, as it
    does during the confirmation seed) or before them (the reported seed: the report's process waits, and a timed
    task at the start leaves no worker idle at the batch's end)."""
    keyed = [(_task_cost(task, seconds, i, b, timed_last), task) for b, (tasks, seconds) in enumerate(batches)
             for i, task in enumerate(tasks)]
    return [task for _, task in sorted(keyed, key=lambda item: item[0])]


def longest_first(tasks: Sequence[Task], seconds: Mapping[str, float]) -> list[Task]:
    """``tasks`` in the order a pool of workers should take them so that they finish together: the longest first,
    by ``seconds`` (task key -> the seconds it took last time).  A task without a time (never computed here) goes
    first, in the declared order (it may be long); ties keep the declared order."""
    return side_by_side([(tasks, seconds)])


def previous_seconds(out: Path, paper: str, prefix: str = "") -> dict[str, float]:
    """The seconds each task of ``paper`` took when it was last computed into the report folder ``out`` (its saved
    ``outcome.json``: computed tasks only, keys starting with ``prefix`` with the prefix cut off); empty when there is
    none or it cannot be read."""
    try:
        data = json.loads((Path(out) / f"paper{paper}" / OUTCOME_FILE).read_text(encoding="utf-8"))
        entries = data.get("tasks") or []
    except (OSError, ValueError, AttributeError):
        return {}
    found = {}
    for entry in entries:
        try:
            key, sec = str(entry.get("key")), float(entry.get("seconds") or 0.0)
        except (AttributeError, TypeError, ValueError):
            continue
        if key.startswith(prefix) and _task_status(entry) == "computed" and sec > 0.0:
            found[key[len(prefix):]] = sec
    return found


def _execute(batches: Sequence[_Batch], host: PluginHost, cache: TaskCache, run, *, progress: bool, on_task,
             label: str, timed_last: bool = True, hold=None,
             on_done: Callable[[_Batch], None] | None = None) -> None:
    """Run the tasks of ``batches`` (every batch of one seed and arch): each finished one cached at once, a cached
    one reused; each batch's results (in its declared order) in ``batch.results``, its tasks' timing in its
    ``outcome.tasks`` and failures in its ``outcome.errors``.  An executor that runs tasks side by side gets the
    tasks of every batch in one call, the longest first (by each batch's ``previous``: the seconds each took in the
    last report into this folder), so that its workers finish together; the tasks without a time (a new folder) go
    first, a task of each batch in turn, so that workers starting side by side mostly run different papers' tasks
    (which compile different kernels) instead of two neighbours of one paper (which compile the same ones twice);
    the tasks declared ``timed`` after the others (``timed_last``) or before them (:func:`side_by_side`); an
    executor that takes ``hold`` (``holds_timed``, :meth:`LocalProcesses.execute`) starts them once ``hold`` is set.
    ``on_done(batch)`` is called (in this thread) for each batch once its tasks have all come back and no ``timed``
    task of the run is left (work done here meanwhile would load the cores a timing measures): the report judges a
    paper there while the workers run the other papers' tasks."""
    if not batches:
        return
    if len({(b.seed, b.arch) for b in batches}) != 1:
        raise ValueError("one run of tasks takes batches of one seed and arch")
    seed, arch = batches[0].seed, batches[0].arch
    bar = _progress_bar(sum(len(b.tasks) for b in batches), label, progress)
    owner: dict[int, tuple[_Batch, str]] = {}  # id(task) -> its batch and cache digest (keys repeat across papers)
    pending: list[list[Task]] = [[] for _ in batches]
    for b, batch in enumerate(batches):
        recipe, outcome = batch.recipe, batch.outcome
        for task in batch.tasks:
            digest = task_key(recipe.paper, task.key, task.params, seed, batch.version, size=batch.size, arch=arch)
            try:
                cached = cache.get(recipe.paper, task.key, digest, host)
            except CacheEntryUnreadable as exc:
                outcome.warnings.append(f"paper {recipe.paper}, task {task.key!r}: {exc}")
                cached = None
            if cached is not None and component_errors(cached):
                # a component failed inside this task (a one-off MemoryError, a race...): never replayed from the
                # cache, the task runs again (its finished parts with it) and its entry is overwritten
                cached = None
            if cached is not None:
                batch.results[task.key] = cached
                outcome.tasks.append({"key": task.key, "seconds": 0.0, "cached": True, "error": "",
                                      "runs": task.runs})
                bar.update(1)
            else:
                owner[id(task)] = (batch, digest)
                pending[b].append(task)
    if isinstance(run, InProcess):  # one after another: the order changes nothing
        order = [task for tasks in pending for task in tasks]
    else:  # side by side: longest first, the batches of tasks without a time in turn
        order = side_by_side([(tasks, batch.previous) for tasks, batch in zip(pending, batches)], timed_last)
    held = {"hold": hold} if hold is not None and getattr(run, "holds_timed", False) else {}
    left = {id(b): len(tasks) for b, tasks in zip(batches, pending)}
    ready = [b for b in batches if not left[id(b)]]  # complete, not yet handed to on_done
    timed_left = sum(1 for t in order if t.timed)

    def hand_on() -> None:
        while on_done is not None and ready and not timed_left:
            batch = ready.pop(0)
            _declared_order(batch)
            on_done(batch)

    hand_on()
    for task, arrays, seconds, error in run.execute(order, seed, arch, on_task, **held):
        batch, digest = owner[id(task)]
        recipe, outcome = batch.recipe, batch.outcome
        if error is None:
            used = getattr(run, "used", {}).get(task.key)
            if used is None:  # an executor that does not say what the task used: every component counts
                used = {(hook, "*") for hook in host.components}
            # saved the moment it finishes, with the fingerprints of the components it used
            cache.put(recipe.paper, task.key, digest, arrays, components_digest(host, used))
            batch.results[task.key] = {k: np.asarray(v) for k, v in arrays.items()}
            outcome.tasks.append({"key": task.key, "seconds": seconds, "cached": False, "error": "",
                                  "runs": task.runs})
        else:
            msg = f"task {task.key!r} failed: {error[0]}"
            outcome.errors.append(msg)
            outcome.tasks.append({"key": task.key, "seconds": seconds, "cached": False, "error": msg,
                                  "runs": task.runs, "traceback": error[1]})
        bar.update(1)
        left[id(batch)] -= 1
        timed_left -= bool(task.timed)
        if not left[id(batch)]:
            ready.append(batch)
        hand_on()
    bar.close()
    for batch in batches:
        _declared_order(batch)
    timed_left = 0
    hand_on()


def _declared_order(batch: _Batch) -> None:
    """``batch.results`` in the declared order, however the tasks came back (from the cache, or from workers)."""
    batch.results = {t.key: batch.results[t.key] for t in batch.tasks if t.key in batch.results}


#: The report's figures are drawn (and laid out) at the PNG's resolution; the SVG embeds its rasterized artists
#: (:data:`SVG_RASTER_MIN_MARKS`) at the same resolution.
FIGURE_DPI = 110

#: An artist that puts more marks than this into an SVG (a scatter's points, a line's markers, a mesh's cells: one SVG
#: element each) is drawn there as a bitmap at :data:`FIGURE_DPI`; axes, text, legends and sparse artists stay vector.
#: Why 1,000: a cloud of 1,000 points of 1-4 pt in a 6.4-inch figure is a texture, not marks read one by one, while
#: each mark costs the SVG a ``<use>`` element (about 100 bytes; writing a 5,000-point 3D scatter took 0.8 s and
#: 1 MiB, rasterized 0.16 s and 56 KiB).  Everything below it in the report's figures (markers of a few hundred
#: points, a colorbar's 256 cells) keeps its vectors.
SVG_RASTER_MIN_MARKS = 1_000

#: A line without markers is one SVG path however long: it is rasterized only past this many vertices, some 30 times
#: the PNG's width in pixels (a 6.4-inch figure at :data:`FIGURE_DPI` is 704 pixels wide), far below what it can show.
SVG_RASTER_MIN_VERTICES = 20_000


def _lay_out_once(fig) -> None:
    """Run ``fig``'s layout engine once, at the figure's dpi, then take the engine off: the axes keep the positions
    it computed, and neither save (PNG, SVG) lays the figure out again.

    ``savefig`` with an engine set first draws the whole figure without output to lay it out, then draws it again
    for real; with none set it draws once (``FigureCanvasBase.print_figure``).  The engine is run here as
    ``Figure.draw`` runs it (only with axes; a ``ValueError`` ignored), with a renderer at the figure's dpi, the
    PNG's, as ``savefig`` would: so the positions are those ``savefig(dpi=FIGURE_DPI)`` computes.
    """
    import matplotlib as mpl

    layout = fig.get_layout_engine()
    if layout is None:
        return
    if fig.axes:
        with suppress(ValueError):
            layout.execute(fig)
    # None removes the engine (``"none"`` would leave a place holder, and savefig lays out again for any engine);
    # the rc settings that would turn None into an engine are held off for the call
    with mpl.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)


def _marks(artist) -> tuple[int, int]:
    """How many separate marks ``artist`` writes into an SVG, and the vertices of its paths (0 where not counted)."""
    from matplotlib.collections import Collection

    if isinstance(artist, Collection):
        offsets = artist.get_offsets()
        paths = artist.get_paths()
        return max(0 if offsets is None else len(offsets), len(paths)), sum(len(p.vertices) for p in paths)
    points = int(np.size(artist.get_xdata()))  # a Line2D (Line3D included)
    has_markers = artist.get_marker() not in (None, "None", "none", "", " ")
    return (points if has_markers else 1), points


def _rasterize_dense(fig) -> list:
    """Mark the artists of ``fig`` that are too dense to be worth vectors (:data:`SVG_RASTER_MIN_MARKS`,
    :data:`SVG_RASTER_MIN_VERTICES`) as rasterized; returns them.

    Vector outputs (SVG) then embed a bitmap of just those artists; PNG output is unchanged (matplotlib ignores the
    setting for pixel output).  Images are left alone: an SVG already embeds them as bitmaps.
    """
    import warnings

    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D

    dense = [a for a in fig.findobj(lambda a: isinstance(a, (Collection, Line2D)))
             if a.get_visible() and not a.get_rasterized()
             and ((m := _marks(a))[0] > SVG_RASTER_MIN_MARKS or m[1] > SVG_RASTER_MIN_VERTICES)]
    with warnings.catch_warnings():
        # mplot3d's Path3DCollection.draw lacks matplotlib's rasterization marker, so set_rasterized warns it is
        # ignored, but it calls PathCollection.draw, which honours it (tests/test_figure_saving.py checks the image)
        warnings.filterwarnings("ignore", message="Rasterization of .* will be ignored")
        for artist in dense:
            artist.set_rasterized(True)
    return dense


def _draw_and_tabulate(recipe: RecipeSpec, results: Mapping, outcome: PaperOutcome, paper_dir: Path,
                       formats: Sequence[str]) -> None:
    """The recipe's figures (data, PNG and SVG) and tables from ``results``, into ``paper_dir`` and ``outcome``.

    Each figure is laid out once (:func:`_lay_out_once`) for both saves, and its dense artists are rasterized in
    the SVG (:func:`_rasterize_dense`)."""
    from matplotlib.figure import Figure

    for spec in recipe.figures:
        try:
            parts, t0 = {}, time.perf_counter()
            data = {k: np.asarray(v) for k, v in spec.data(results).items()}
            save_arrays(paper_dir / f"{spec.id}.npz", data)
            parts["data"], t0 = time.perf_counter() - t0, time.perf_counter()
            figure_data_csv(data, paper_dir / f"{spec.id}.csv")
            parts["csv"], t0 = time.perf_counter() - t0, time.perf_counter()
            fig = Figure(figsize=spec.size, dpi=FIGURE_DPI, layout="constrained")
            spec.draw(data, fig)
            _lay_out_once(fig)
            fig.savefig(paper_dir / f"{spec.id}.png", dpi=FIGURE_DPI)
            parts["draw and png"], t0 = time.perf_counter() - t0, time.perf_counter()
            svg = paper_dir / f"{spec.id}.svg"
            if "svg" in formats:
                _rasterize_dense(fig)
                fig.savefig(svg, dpi=FIGURE_DPI)
                parts["svg"] = time.perf_counter() - t0
            else:
                svg.unlink(missing_ok=True)  # never link an SVG of an earlier report beside this PNG
            outcome.item_seconds[f"figure {spec.id}"] = parts
            outcome.figures.append({"id": spec.id, "caption": spec.caption, "png": paper_dir / f"{spec.id}.png",
                                    "svg": svg if "svg" in formats else None, "data": paper_dir / f"{spec.id}.npz"})
        except Exception as exc:  # noqa: BLE001
            outcome.errors.append(f"figure {spec.id} not produced: {type(exc).__name__}: {exc}")
    for spec in recipe.tables:
        try:
            t0 = time.perf_counter()
            table = spec.make(results)
            _write_table(table, paper_dir / f"{spec.id}.csv")
            outcome.item_seconds[f"table {spec.id}"] = {"make and csv": time.perf_counter() - t0}
            outcome.tables.append({"id": spec.id, "caption": spec.caption, "columns": list(table.columns),
                                   "rows": [list(r) for r in table.rows], "csv": paper_dir / f"{spec.id}.csv"})
        except Exception as exc:  # noqa: BLE001
            outcome.errors.append(f"table {spec.id} not produced: {type(exc).__name__}: {exc}")


class _UsageTable(Mapping):
    """One hook's components, recording every name asked for (``"*"`` for a look at the whole table)."""

    def __init__(self, hook: str, table: Mapping, used: set):
        self._hook, self._table, self._used = hook, table, used

    def __getitem__(self, name):
        self._used.add((self._hook, name))
        return self._table[name]

    def __contains__(self, name):
        self._used.add((self._hook, name))
        return name in self._table

    def __iter__(self):
        self._used.add((self._hook, "*"))
        return iter(self._table)

    def __len__(self):
        self._used.add((self._hook, "*"))
        return len(self._table)


@dataclass(frozen=True)
class _RecordingHost(PluginHost):
    """A :class:`PluginHost` that records which components are asked for (``used``: ``(hook, name)`` pairs)."""

    used: set = field(default_factory=set, compare=False, hash=False)

    def filter(self, name: str):
        if "(" in name:  # a configured filter: its label (with its values) is part of what the task used
            self.used.add(("workbench_filters", name))
        return super().filter(name)


def recording_host(host: PluginHost) -> tuple[PluginHost, set]:
    """``host`` as seen by one task, and the set that collects the ``(hook, name)`` of every component it asks
    for (the report cache keys the task's result on those components only)."""
    used: set = set()
    fields = {f.name: getattr(host, f.name) for f in dataclasses.fields(PluginHost)}
    fields["components"] = {hook: _UsageTable(hook, table, used) for hook, table in host.components.items()}
    return _RecordingHost(**fields, used=used), used


def _call_task(run, params, seed, host, arch) -> tuple[dict, set]:
    """Run one task with the kernels on ``arch`` (the one backend policy, :mod:`workbench.kernels.backend`);
    returns its arrays and the ``(hook, name)`` of the components it asked the host for."""
    from ..kernels.backend import using

    seen, used = recording_host(host)
    with using(arch):
        result = run(TaskContext(params=params, seed=seed, host=seen, arch=arch))
    return {k: np.asarray(v) for k, v in dict(result).items()}, set(used)


class InProcess:
    """Run tasks one after another in this process (the default; results are batched inside tasks).

    A task that raises is tried ``retries`` more times before it is reported as failed.
    """

    def __init__(self, host: PluginHost, retries: int = 1):
        self.host, self.retries = host, retries
        self.used: dict[str, set] = {}  # task key -> the (hook, name) of the components it used

    def execute(self, tasks, seed, arch, on_task=None):
        for task in tasks:
            if on_task is not None:
                on_task(task.key)
            t0 = time.perf_counter()
            for attempt in range(self.retries + 1):
                try:
                    arrays, self.used[task.key] = _call_task(task.run, task.params, seed, self.host, arch)
                    yield task, arrays, time.perf_counter() - t0, None
                    break
                except (KeyboardInterrupt, SystemExit):
                    raise
                except Exception as exc:  # noqa: BLE001 - reported, the others carry on
                    if attempt == self.retries:
                        yield task, None, time.perf_counter() - t0, (f"{type(exc).__name__}: {exc}",
                                                                     traceback.format_exc())


_WORKER_HOSTS: dict[tuple[str, ...], PluginHost] = {}

#: The environment of a worker process of :class:`LocalProcesses` (and of a local Dask cluster's workers): one
#: thread per worker, kernels included, since the workers already share the cores between them and threaded kernels
#: (Numba, BLAS) in every worker would oversubscribe them.  Read by those libraries when they load, so it is set
#: before a worker starts (in its environment), never after.
ONE_THREAD_ENV = {name: "1" for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                         "MKL_NUM_THREADS")}


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system gives one, else the CPU count)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):  # pragma: no cover - no affinity on this system
        return max(os.cpu_count() or 1, 1)


def _host_signature(host: PluginHost) -> dict:
    """What a worker's host must match to run a task as this process would: every component by hook and name, with
    the plugin that provides it, and every plugin with its status."""
    return {"components": {hook: sorted((str(name), str(host.owner.get((hook, name), ""))) for name in table)
                           for hook, table in host.components.items()},
            "plugins": sorted((p.name, p.module, p.status) for p in host.plugins)}


def _process_task(run, params, seed, arch, block, retries):
    """Runs in a :class:`LocalProcesses` worker: build (once per process) the worker's own plugin host, then the
    task, tried ``retries`` more times when it raises.  Returns ``("ok", arrays, seconds, used)`` or ``("error",
    message, seconds, traceback text)``: a failure comes back as data with the worker's own traceback.  Either way
    the worker's own peak resident set size (KiB) comes with it, as a fifth item."""
    from ..bench import own_peak_kib
    from ..plugins import load_host

    key = tuple(sorted(block))
    if key not in _WORKER_HOSTS:
        _WORKER_HOSTS[key] = load_host(block=block)
    t0 = time.perf_counter()
    for attempt in range(int(retries) + 1):
        try:
            arrays, used = _call_task(run, params, seed, _WORKER_HOSTS[key], arch)
            return "ok", arrays, time.perf_counter() - t0, sorted(used), own_peak_kib()
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - reported, the others carry on
            if attempt == int(retries):
                return ("error", f"{type(exc).__name__}: {exc}", time.perf_counter() - t0, traceback.format_exc(),
                        own_peak_kib())
    raise AssertionError("unreachable")  # pragma: no cover


@contextmanager
def _environment(values: Mapping[str, str]):
    """``os.environ`` with ``values`` set while the block runs (the worker processes started in it inherit them),
    restored after."""
    before = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class WorkerHostMismatch(InputError):
    """The plugin host a worker process would build (the installed plugins, less the blocked ones) is not the host
    the report was given (one built with plugins registered in this process only): the workers cannot run its tasks
    as this process would."""


def _picklable(fn) -> bool:
    """Whether ``fn`` can be sent to a worker process (pickled by reference: a module-level function or a
    ``functools.partial`` of one)."""
    import pickle

    try:
        pickle.dumps(fn)
    except Exception:  # noqa: BLE001 - any failure to pickle means: run it here
        return False
    return True


class LocalProcesses:
    """Run tasks on ``jobs`` local worker processes (``concurrent.futures`` with the ``spawn`` start method), each
    with one thread for Numba and BLAS (:data:`ONE_THREAD_ENV`) and its own plugin host built once
    (``load_host(block=block)``); finished tasks come back as they complete.

    Every task's random streams come from the seed and the task's own identity, never from the worker or the
    order, so results are bit-identical to :class:`InProcess`.  The workers take the tasks in the caller's order
    (the report hands them the longest first, so that they finish together).  A task that raises is tried
    ``retries`` more times in its worker, then reported as failed with the worker's traceback; a worker that dies
    (killed, out of memory) fails the tasks still waiting with one line each, and the tasks finished before it come
    back as usual (the report caches each one the moment it arrives); the next batch starts new workers.

    The workers start at the first batch that has a task to run (a report read wholly from the cache starts none)
    and stay up for the report's later batches (its other papers, the confirmation seed) until :meth:`close`.
    The host given must be the one a worker builds (the installed plugins less ``block``): a host with plugins
    registered in this process only is refused with :class:`WorkerHostMismatch` (``workbench report --jobs 1`` runs
    such a host in this process).

    ``worker_peak_kib``: the largest peak resident set size (KiB) a worker of this executor reported (its own
    ``VmHWM``); :attr:`largest_worker_kib`, the largest of every executor in this process (the report benchmark
    prints it beside the report process's own peak).
    """

    #: The largest worker peak (KiB) of any :class:`LocalProcesses` in this process.
    largest_worker_kib: float = 0.0

    def __init__(self, host: PluginHost, jobs: int, block: Sequence[str] = (), retries: int = 1,
                 start_method: str = "spawn"):
        if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
            raise InputError(f"jobs: a whole number of worker processes >= 1, got {jobs!r}")
        self.host, self.jobs, self.block, self.retries = host, int(jobs), tuple(block), int(retries)
        self.start_method = start_method
        self.used: dict[str, set] = {}  # task key -> the (hook, name) of the components it used
        self._pool = None
        self._checked = False
        self.worker_peak_kib = 0.0

    def check_host(self) -> None:
        """Refuse (:class:`WorkerHostMismatch`) a host that the workers would not rebuild: its components and
        plugins against a fresh ``load_host(block=block)``'s."""
        if self._checked:
            return
        from ..plugins import load_host

        if _host_signature(load_host(block=self.block)) != _host_signature(self.host):
            raise WorkerHostMismatch("the report's plugin host has plugins or components that a worker process "
                                     "would not load (registered in this process only, not installed): run its "
                                     "tasks in this process (--jobs 1)")
        self._checked = True

    def _start(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self.check_host()
            self._pool = ProcessPoolExecutor(max_workers=self.jobs,
                                             mp_context=multiprocessing.get_context(self.start_method))
        return self._pool

    def close(self) -> None:
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    #: :meth:`execute` takes ``hold`` (the report's confirmation seed holds its timed tasks while it draws).
    holds_timed = True

    def execute(self, tasks, seed, arch, on_task=None, hold=None):
        """Run ``tasks`` on the workers, which take them in this order, and yield ``(task, arrays, seconds, error)``
        as each finishes.  ``hold`` (a :class:`threading.Event`, optional): a task declared ``timed`` is not started
        while ``hold`` is unset and an untimed task waits; once it is set, the timed tasks go first (the report's
        confirmation seed: its timing waits until the report's own process has drawn the figures, then starts on
        the next free worker instead of after every other task, which left the other worker idle at the end)."""
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        tasks = list(tasks)
        if not tasks:
            return
        # a task whose function cannot be sent to a worker (a closure or a lambda of a recipe written elsewhere) runs
        # here, in this process, while the workers run the others: the same numbers, never a failure for it
        here = [t for t in tasks if not _picklable(t.run)]
        waiting = [t for t in tasks if _picklable(t.run)]
        pool = self._start() if waiting else None
        futures, pending = {}, {}  # every task submitted (to cancel), and those not yet handed back

        def submit_next() -> None:
            task = waiting.pop(_next_index(waiting, hold))
            if on_task is not None:
                on_task(task.key)
            # the workers start as the tasks are submitted (spawn: one per submission while none is idle), so the
            # one-thread environment is theirs from their first line
            with _environment({**ONE_THREAD_ENV, **malloc_env()}):
                fut = pool.submit(_process_task, task.run, dict(task.params), seed, arch, self.block, self.retries)
            futures[fut] = pending[fut] = task

        try:
            # one task more in flight than there are workers (a free worker takes it at once, even while the caller
            # works on a finished task's result); each next one is chosen when a task finishes
            while waiting and len(pending) <= self.jobs:
                submit_next()
            if here:
                local = InProcess(self.host, self.retries)
                yield from local.execute(here, seed, arch, on_task)
                self.used.update(local.used)
            while pending:
                done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for fut in [f for f in pending if f in done]:  # in the order they were submitted
                    task = pending.pop(fut)
                    if waiting and not isinstance(fut.exception(), BrokenProcessPool):
                        submit_next()
                    try:
                        status, value, seconds, extra, peak = fut.result()
                        self.worker_peak_kib = max(self.worker_peak_kib, float(peak))
                        LocalProcesses.largest_worker_kib = max(LocalProcesses.largest_worker_kib, float(peak))
                    except BrokenProcessPool as exc:
                        self._pool = None  # the next batch starts new workers
                        yield task, None, 0.0, (f"the worker process running it died ({exc or 'BrokenProcessPool'}"
                                                f"): killed, or out of memory", traceback.format_exc())
                        continue
                    except (KeyboardInterrupt, SystemExit):
                        raise
                    except Exception as exc:  # noqa: BLE001 - e.g. a result that cannot be sent back
                        yield task, None, 0.0, (f"{type(exc).__name__}: {exc}", traceback.format_exc())
                        continue
                    if status == "ok":
                        self.used[task.key] = {tuple(u) for u in extra}
                        yield task, value, seconds, None
                    else:
                        yield task, None, seconds, (value, extra)
            for task in waiting:  # left over where the pool broke: each fails by name, as the submitted ones did
                yield task, None, 0.0, ("the worker processes died before it started (killed, or out of memory)", "")
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise


def _next_index(waiting: Sequence[Task], hold) -> int:
    """Which of ``waiting`` (in the caller's order) a free worker takes: the first, except that with a ``hold``
    event a ``timed`` task waits while it is unset and an untimed task remains, and goes first once it is set."""
    if hold is None:
        return 0
    released = hold.is_set() or all(t.timed for t in waiting)
    for i, task in enumerate(waiting):
        if task.timed == released:
            return i
    return 0


def _remote_task(run, params, seed, arch, block):
    """Runs on a Dask worker: build (once per process) the worker's own plugin host, then the task."""
    from ..plugins import load_host

    key = tuple(sorted(block))
    if key not in _WORKER_HOSTS:
        _WORKER_HOSTS[key] = load_host(block=block)
    t0 = time.perf_counter()
    arrays, used = _call_task(run, params, seed, _WORKER_HOSTS[key], arch)
    return arrays, time.perf_counter() - t0, sorted(used)


class DaskExecutor:
    """Send tasks to a Dask distributed scheduler; finished tasks come back as they complete.

    Every task's random streams come from the seed and the task's own identity, never from the worker
    or the order, so results are bit-identical to an in-process run.  Dask retries a failing task
    ``retries`` times; one that fails for good is reported and the other tasks' results are kept.  A cluster left
    without any worker for ``no_worker_grace`` seconds while tasks wait ends the report with
    :class:`DaskClusterLost` (one line naming the cluster), instead of waiting for ever.
    """

    def __init__(self, client, block: Sequence[str] = (), retries: int = 1, cluster=None,
                 no_worker_grace: float | None = None, poll: float = 1.0):
        self.client, self.block, self.retries, self.cluster = client, tuple(block), retries, cluster
        self.used: dict[str, set] = {}  # task key -> the (hook, name) of the components it used
        #: How long the cluster may have no worker at all while tasks wait, before the report gives up
        #: (:class:`DaskClusterLost`); default :data:`NO_WORKER_GRACE`.
        self.no_worker_grace = NO_WORKER_GRACE if no_worker_grace is None else float(no_worker_grace)
        self.poll = float(poll)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def _where(self) -> str:
        try:
            return f"the Dask cluster {self.client.scheduler.address}"
        except Exception:  # noqa: BLE001 - only for the message
            return "the Dask cluster"

    def _workers(self) -> int:
        """The workers the scheduler has now (0 where the scheduler cannot be asked)."""
        try:
            return len(self.client.nthreads())
        except Exception:  # noqa: BLE001 - a scheduler that cannot answer has no worker for us
            return 0

    def execute(self, tasks, seed, arch, on_task=None):
        from distributed import wait

        futures = {}
        for i, task in enumerate(tasks):
            # priority: the workers take the tasks in the caller's order (e.g. largest first, so that they
            # finish together); without it the scheduler may leave the longest task for last
            fut = self.client.submit(_remote_task, task.run, dict(task.params), seed, arch, self.block,
                                     pure=False, retries=self.retries, key=f"{task.key}-{time.time_ns()}",
                                     priority=len(tasks) - i)
            futures[fut] = task
        pending = dict(futures)
        workerless_since = None
        while pending:
            try:
                done = set(wait(list(pending), timeout=self.poll, return_when="FIRST_COMPLETED").done)
            except TimeoutError:
                done = set()
            if not done:
                # nothing finished: a cluster whose workers are all gone would leave us waiting for ever
                if self._workers():
                    workerless_since = None
                elif workerless_since is None:
                    workerless_since = time.monotonic()
                elif time.monotonic() - workerless_since >= self.no_worker_grace:
                    for fut in pending:
                        fut.cancel()
                    raise DaskClusterLost(self._where(), len(pending), len(futures), self.no_worker_grace)
                continue
            workerless_since = None
            for fut in [f for f in pending if f in done]:  # in the caller's order within a batch
                task = pending.pop(fut)
                try:
                    arrays, seconds, used = fut.result()
                    self.used[task.key] = {tuple(u) for u in used}
                    yield task, arrays, seconds, None
                except (KeyboardInterrupt, SystemExit):
                    raise
                except Exception as exc:  # noqa: BLE001
                    yield task, None, 0.0, (f"{type(exc).__name__}: {exc}", traceback.format_exc())


#: Seconds a Dask cluster may have no worker at all while a report's tasks wait, before the report gives up
#: (:class:`DaskClusterLost`): long enough for a worker's restart, short of hanging for ever.
NO_WORKER_GRACE = 30.0


class DaskClusterLost(ConnectionError):
    """The Dask cluster a report runs on has had no worker for :data:`NO_WORKER_GRACE` seconds while its tasks
    wait (the workers died or were stopped, or the scheduler cannot be asked): one line naming it, the finished
    tasks already cached."""

    def __init__(self, where: str, waiting: int, total: int, grace: float):
        super().__init__(errno.ENOTCONN, f"no worker for {grace:g} s while {waiting} of {total} tasks wait (its "
                                         "workers died or were stopped); the finished tasks are cached for the next "
                                         "report", where)

    def __str__(self) -> str:
        return f"{self.filename}: {self.strerror}"


Executor = InProcess | LocalProcesses | DaskExecutor


#: Seconds to wait for a Dask scheduler before the report gives up with a network error.
CONNECT_TIMEOUT = "10s"


def dask_executor(host: PluginHost, scheduler: str | None = None, workers: int | None = None,
                  block: Sequence[str] = ()):
    """A :class:`DaskExecutor` on ``scheduler`` (an address), or on a new local cluster of ``workers``."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("running on Dask needs the 'distributed' package: pip install -e \".[dask]\"") from None
    if scheduler:
        if "://" not in scheduler and ":" not in scheduler:
            raise InputError(f"--scheduler {scheduler!r}: expected an address such as tcp://host:8786")
        # a scheduler that cannot be reached fails within CONNECT_TIMEOUT, not after Dask's default 30 s
        return DaskExecutor(Client(scheduler, timeout=CONNECT_TIMEOUT), block)
    # One thread per worker process, kernels included (ONE_THREAD_ENV).
    env = dict(ONE_THREAD_ENV)
    # Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536 (its pre-spawn environment, read by
    # glibc at process start).  Any explicit value also turns off glibc's dynamic mmap threshold, so
    # every freed array of the particle filters goes back to the system and the next step page-faults it
    # in again: the paper-003 CRPF ran 1.7x slower in a worker than in a plain process.  The workers of
    # this short-lived local cluster allocate as a plain Python process does (the variable unset).
    spawn_env = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ", {}).items()
                 if not k.startswith("MALLOC_")}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": spawn_env}):
        cluster = LocalCluster(n_workers=workers or 2, threads_per_worker=1, processes=True,
                               dashboard_address=None, env=env)
    return DaskExecutor(Client(cluster), block, cluster=cluster)


def _progress_bar(total: int, desc: str, enabled: bool):
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        enabled = False
    if not enabled:
        class _Null:
            def update(self, n=1):
                pass

            def close(self):
                pass

        return _Null()
    return tqdm(total=total, desc=desc, unit="task", leave=False, file=sys.stderr)


class ReportFolderBusy(InputError):
    """Another report holds the report folder's lock; the message names it (pid, host, command, start)."""

    def __init__(self, message: str, holder: Mapping):
        super().__init__(message)
        self.holder = dict(holder)


def _holder_text(holder: Mapping) -> str:
    return (f"pid {holder.get('pid', '?')} on host {holder.get('host', '?')}, started {holder.get('started', '?')}, "
            f"command: {holder.get('command') or '?'}")


def _read_holder(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError, ValueError, TypeError, OverflowError):
        return True  # someone else's process, or a pid we cannot check: assume it runs
    return True


#: The errors of a non-blocking ``flock`` that mean "another process holds it" (EACCES on some systems).
_LOCK_BUSY = frozenset({errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES})


def _lock_unsupported(out: Path, path: Path, exc: OSError) -> InputError:
    """The one-line error for a report folder whose filesystem cannot lock ``path`` (``exc`` from ``flock``)."""
    unsupported = {getattr(errno, n) for n in ("EOPNOTSUPP", "ENOTSUP", "ENOSYS") if hasattr(errno, n)}
    if exc.errno in unsupported:
        problem = "its filesystem does not support file locks"
    elif exc.errno == errno.ENOLCK:
        problem = "its filesystem gives no file locks, as a network filesystem without a lock service does"
    else:
        problem = "its filesystem refused the lock"
    reason = exc.strerror or str(exc)
    return InputError(f"cannot lock the report folder {out}: {problem} ({reason}, on {path}); write the report "
                      f"into a folder on a local disk (--out)")


@contextmanager
def report_lock(out: Path, command: str = "", wait: float = 0.0, poll: float = 0.2):
    """Hold the lock of the report folder ``out`` (the file :data:`LOCK_FILE`, naming this process).

    Two reports into one folder would mix their tables; the second one waits up to ``wait`` seconds for the
    first, then raises :class:`ReportFolderBusy` naming the holder (pid, host, command, start).  The lock is an
    OS lock on the file (``flock``), released when its process ends however it ends, so a lock file left by a
    process that is gone is taken over (yields the list of notes saying so); without ``flock`` (Windows) the
    file is created exclusively and a lock of a dead pid on this host is taken over.  A filesystem that cannot
    lock (``flock`` failing with anything but "would block", e.g. ``ENOLCK`` on NFS or ``EOPNOTSUPP``) raises
    an :class:`InputError` naming the folder and the problem, never "in use by another report".
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK_FILE
    me = {"pid": os.getpid(), "host": socket.gethostname(), "command": command or " ".join(sys.argv),
          "started": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")}
    deadline = time.monotonic() + max(float(wait), 0.0)
    notes: list[str] = []
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        fcntl = None
    while True:
        if fcntl is not None:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno not in _LOCK_BUSY:  # not another report: the filesystem cannot lock (NFS, FUSE...)
                    with suppress(OSError):
                        if path.stat().st_size == 0:  # the empty file just created: no stale lock file left
                            path.unlink()
                    raise _lock_unsupported(out, path, exc) from None
                holder = _read_holder(path)
            else:
                try:
                    same = os.fstat(fd).st_ino == os.stat(path).st_ino
                except FileNotFoundError:
                    same = False
                if not same:  # the holder removed the file as we opened it: try again on the new one
                    os.close(fd)
                    continue
                old = _read_holder(path)
                if old.get("pid") not in (None, me["pid"]):
                    notes.append(f"took over the report folder's lock {path} left by a process that is gone "
                                 f"({_holder_text(old)})")
                os.ftruncate(fd, 0)
                os.write(fd, json.dumps(me).encode())
                break
        else:  # pragma: no cover - Windows
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
                os.write(fd, json.dumps(me).encode())
                break
            except FileExistsError:
                holder = _read_holder(path)
                if holder.get("host") == me["host"] and not _pid_alive(holder.get("pid")):
                    notes.append(f"took over the report folder's lock {path} left by a process that is gone "
                                 f"({_holder_text(holder)})")
                    path.unlink(missing_ok=True)
                    continue
        if time.monotonic() >= deadline:
            raise ReportFolderBusy(f"the report folder {out} is in use by another report ({_holder_text(holder)}); "
                                   f"wait for it to finish or write into another --out (its lock: {path})", holder)
        time.sleep(poll)
    try:
        yield notes
    finally:
        try:
            path.unlink(missing_ok=True)  # removed while still held, so no one locks a file about to vanish
        finally:
            os.close(fd)


def run_report(host: PluginHost, out: Path, *, papers: Iterable[str] | None = None, size: str = "quick",
               seed: int = 0, filters: str | None = None, arch: str = "cpu", progress: bool = True,
               trackers: str | None = None,
               command: str = "", executor: "Executor | None" = None, wait: float = 0.0,
               formats: Sequence[str] | str | None = None) -> ReportOutcome:
    """Run the chosen recipes (default: every registered one) and write ``index.html`` and ``summary.json``.

    The page and the summary show every paper of ``out``: the ones run now, and the others from their
    saved ``outcome.json`` (an unreadable one is skipped with a warning on stderr).  The folder is locked
    while the report runs (:func:`report_lock`): a second report into it waits up to ``wait`` seconds, then
    is refused with a message naming the report that holds it.  Figures are saved in ``formats``
    (:func:`figure_formats`: by default PNG and SVG).
    """
    from .html import write_index, write_summary

    out = Path(out)
    formats = figure_formats(formats)  # refused before any paper runs
    wanted = sorted(host.recipes) if not papers else list(papers)
    recipes = []
    for paper in wanted:
        try:
            recipes.append(host.recipe(paper))
        except UnknownComponent as exc:
            raise InputError(str(exc)) from None
    routed = tracker_papers(recipes, trackers, host, named=bool(papers))  # --trackers refused before any paper runs
    with report_lock(out, command, wait) as notes:
        start = time.perf_counter()
        outcomes = _run_papers(recipes, host, out, size=size, seed=seed, filters=filters, arch=arch, progress=progress,
                               trackers=routed, on_task=None, executor=executor, command=command, formats=formats)
        saved, warnings = saved_outcomes(out, skip=[o.paper for o in outcomes])
        warnings = [*notes, *(w for o in outcomes for w in o.warnings), *warnings]
        for line in warnings:
            print(f"workbench report: warning: {line}", file=sys.stderr)
        report = ReportOutcome(out, outcomes, time.perf_counter() - start, command, seed, size, saved, warnings)
        write_index(report, host)
        write_summary(report, host)
    return report
