"""Run report recipes: tasks (cached), then figures, tables and criteria from the saved results.

Output folder layout::

    OUT/index.html                 figures embedded, tables (ours beside published), provenance
    OUT/summary.json               machine-readable: criteria, tables, task timings, errors
    OUT/paperNNN/FIG.png|.svg      each figure
    OUT/paperNNN/FIG.npz, FIG.csv  the data behind it
    OUT/paperNNN/TABLE.csv         each table
    OUT/paperNNN/outcome.json      the paper's rendered outcome (tables, figure paths, criteria, tasks, notes,
                                   published values, errors, timings), so that ``--paper X`` into this folder
                                   keeps the other papers' sections
    OUT/cache/...                  finished task results (reused by the next run)

Only the full size gives firm verdicts: the criteria of any other size (the quick report) are marked
indicative (:meth:`workbench.criteria.Criterion.as_indicative`), so a quick report never says *met*.
"""

from __future__ import annotations

import csv
import json
import sys
import time
import traceback
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from ..plugins import PluginHost, UnknownComponent
from ..criteria import Criterion
from ..specs import RecipeOptions, RecipeSpec, Table, TaskContext
from ..types import InputError
from .cache import TaskCache, code_version, save_arrays, task_key, write_text_atomic

__all__ = ["resolve_filters", "PaperOutcome", "ReportOutcome", "run_recipe", "run_report", "figure_data_csv",
           "save_outcome", "load_outcome", "saved_outcomes", "OUTCOME_FILE", "InProcess", "DaskExecutor",
           "dask_executor"]

#: The file, inside ``OUT/paperNNN``, that keeps a paper's rendered outcome.
OUTCOME_FILE = "outcome.json"
#: The size whose verdicts are firm; every other size's criteria are marked indicative.
FIRM_SIZE = "full"


def split_references(text: str) -> list[str]:
    """Split a comma-separated list of component references, keeping ``name(a=1, b=2)`` whole."""
    parts, depth, current = [], 0, ""
    for ch in text:
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(current.strip())
            current = ""
            continue
        current += ch
    parts.append(current.strip())
    return [p for p in parts if p]


def resolve_filters(default: Sequence[str], request: str | None, host: PluginHost) -> tuple[str, ...]:
    """Apply ``--filters`` to a recipe's default list.

    ``request`` is a comma-separated list of filter references (``name`` or ``name(key=value, ...)``, a configured
    filter); entries starting with ``+`` are added to the defaults, and ``-name`` (or ``~name``, which a shell
    cannot mistake for an option) removes one; if any entry has no sign, the list replaces the defaults.  Every
    name must be an installed filter, every removed one must be in the list, and the result must not be empty.
    """
    if not request:
        return tuple(default)
    parts = split_references(request)
    plain = [p for p in parts if p[0] not in "+-~"]
    chosen = list(plain) if plain else list(default)
    for p in parts:
        if p.startswith("+") and p[1:] not in chosen:
            chosen.append(p[1:])
        elif p[0] in "-~":
            if p[1:] not in chosen:
                raise InputError(f"--filters: cannot remove {p[1:]!r}: it is not among {', '.join(chosen) or 'none'}")
            chosen.remove(p[1:])
    if not chosen:
        raise InputError(f"--filters {request!r} leaves no filter to compare")
    for name in chosen:
        host.filter(name)  # raises UnknownComponent naming what is installed, or InputError for bad parameters
    return tuple(chosen)


@dataclass
class PaperOutcome:
    """One paper's rendered outcome: what ``index.html`` and ``summary.json`` show of it.

    ``figures`` entries hold ``id, caption, png, svg, data`` (paths), ``tables`` entries ``id, caption,
    columns, rows, csv``, ``tasks`` entries ``key, seconds, cached, error``.  ``saved`` is True for an
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
    seconds: float = 0.0
    seed: int | None = None
    command: str = ""
    finished: str = ""  # UTC time stamp
    saved: bool = False


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


def _jsonable(value, strict: bool = False):
    """``value`` as plain JSON data (numpy scalars and arrays, tuples, paths converted; others as str).

    With ``strict``, non-finite floats become ``None`` (standard JSON has no NaN or infinity).
    """
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v, strict) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v, strict) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist(), strict)
    if isinstance(value, np.generic):
        return _jsonable(value.item(), strict)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and strict and not np.isfinite(value):
        return None
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return str(value)


def outcome_dict(outcome: PaperOutcome, out: Path) -> dict:
    """``outcome`` as JSON data, with file paths relative to the report folder ``out``."""
    return {
        "format": 1,
        "paper": outcome.paper, "title": outcome.title, "size": outcome.size, "filters": list(outcome.filters),
        "notes": outcome.notes, "published": _jsonable(outcome.published),
        "seed": outcome.seed, "command": outcome.command, "finished": outcome.finished,
        "seconds": outcome.seconds, "errors": list(outcome.errors),
        "figures": [{"id": f["id"], "caption": f["caption"],
                     **{k: _rel(f.get(k), out) for k in ("png", "svg", "data")}} for f in outcome.figures],
        "tables": [{"id": t["id"], "caption": t["caption"], "columns": _jsonable(t["columns"]),
                    "rows": _jsonable(t["rows"]), "csv": _rel(t.get("csv"), out)} for t in outcome.tables],
        "criteria": [c.to_dict() for c in outcome.criteria],
        "tasks": [_jsonable(t) for t in outcome.tasks],
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
        seconds=float(data.get("seconds", 0.0)), seed=data.get("seed"), command=str(data.get("command", "")),
        finished=str(data.get("finished", "")), saved=True)


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
               filters: str | None = None, arch: str = "cpu", progress: bool = True,
               on_task: Callable[[str], None] | None = None, executor: "Executor | None" = None,
               command: str = "") -> PaperOutcome:
    """Run one recipe into ``out/paperNNN`` using the cache in ``out/cache``.

    The criteria of any size but ``"full"`` are marked indicative (never *met*), and the outcome is saved
    to ``out/paperNNN/outcome.json``.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    start = time.perf_counter()
    if size not in recipe.sizes:
        raise InputError(f"recipe {recipe.paper} has no size {size!r} (sizes: {', '.join(recipe.sizes)})")
    chosen = resolve_filters(recipe.default_filters, filters, host) if recipe.default_filters else ()
    options = RecipeOptions(size=size, values=dict(recipe.sizes[size]), seed=seed, filters=chosen, arch=arch)
    outcome = PaperOutcome(recipe.paper, recipe.title, size, chosen, recipe.notes, dict(recipe.published),
                           seed=seed, command=command)
    paper_dir = out / f"paper{recipe.paper}"
    paper_dir.mkdir(parents=True, exist_ok=True)
    cache = TaskCache(out / "cache")
    modules = {recipe.tasks.__module__} | {p.module.split(":")[0] for p in host.plugins if p.status == "ok"}
    module_files = tuple(sorted(f for m in modules if (f := getattr(sys.modules.get(m), "__file__", None))))
    version = code_version(module_files)

    tasks = list(recipe.tasks(options))
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise InputError(f"recipe {recipe.paper} declares duplicate task keys: {sorted({k for k in keys if keys.count(k) > 1})}")
    results: dict[str, dict[str, np.ndarray]] = {}
    bar = _progress_bar(len(tasks), f"paper {recipe.paper} ({size})", progress)
    pending = []
    for task in tasks:
        digest = task_key(recipe.paper, task.key, task.params, seed, version)
        cached = cache.get(recipe.paper, task.key, digest)
        if cached is not None:
            results[task.key] = cached
            outcome.tasks.append({"key": task.key, "seconds": 0.0, "cached": True, "error": ""})
            bar.update(1)
        else:
            pending.append((task, digest))
    run = executor if executor is not None else InProcess(host)
    for task, arrays, seconds, error in run.execute([t for t, _ in pending], seed, arch, on_task):
        digest = next(d for t, d in pending if t.key == task.key)
        if error is None:
            cache.put(recipe.paper, task.key, digest, arrays)  # saved the moment it finishes
            results[task.key] = {k: np.asarray(v) for k, v in arrays.items()}
            outcome.tasks.append({"key": task.key, "seconds": seconds, "cached": False, "error": ""})
        else:
            msg = f"task {task.key!r} failed: {error[0]}"
            outcome.errors.append(msg)
            outcome.tasks.append({"key": task.key, "seconds": seconds, "cached": False, "error": msg,
                                  "traceback": error[1]})
        bar.update(1)
    bar.close()
    outcome.tasks.sort(key=lambda t: keys.index(t["key"]))

    for spec in recipe.figures:
        try:
            data = {k: np.asarray(v) for k, v in spec.data(results).items()}
            save_arrays(paper_dir / f"{spec.id}.npz", data)
            figure_data_csv(data, paper_dir / f"{spec.id}.csv")
            fig = Figure(figsize=spec.size, layout="constrained")
            spec.draw(data, fig)
            fig.savefig(paper_dir / f"{spec.id}.png", dpi=110)
            fig.savefig(paper_dir / f"{spec.id}.svg")
            outcome.figures.append({"id": spec.id, "caption": spec.caption, "png": paper_dir / f"{spec.id}.png",
                                    "svg": paper_dir / f"{spec.id}.svg", "data": paper_dir / f"{spec.id}.npz"})
        except Exception as exc:  # noqa: BLE001
            outcome.errors.append(f"figure {spec.id} not produced: {type(exc).__name__}: {exc}")
    for spec in recipe.tables:
        try:
            table = spec.make(results)
            _write_table(table, paper_dir / f"{spec.id}.csv")
            outcome.tables.append({"id": spec.id, "caption": spec.caption, "columns": list(table.columns),
                                   "rows": [list(r) for r in table.rows], "csv": paper_dir / f"{spec.id}.csv"})
        except Exception as exc:  # noqa: BLE001
            outcome.errors.append(f"table {spec.id} not produced: {type(exc).__name__}: {exc}")
    if recipe.criteria is not None:
        try:
            outcome.criteria = list(recipe.criteria(results))
        except Exception as exc:  # noqa: BLE001
            outcome.errors.append(f"criteria not evaluated: {type(exc).__name__}: {exc}")
        if size != FIRM_SIZE:
            outcome.criteria = [c.as_indicative() for c in outcome.criteria]
    outcome.seconds = time.perf_counter() - start
    outcome.finished = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    save_outcome(outcome, out)
    return outcome


def _call_task(run, params, seed, host, arch) -> dict:
    """Run one task with the kernels on ``arch`` (the one backend policy, :mod:`workbench.kernels.backend`)."""
    from ..kernels.backend import using

    with using(arch):
        result = run(TaskContext(params=params, seed=seed, host=host, arch=arch))
    return {k: np.asarray(v) for k, v in dict(result).items()}


class InProcess:
    """Run tasks one after another in this process (the default; results are batched inside tasks).

    A task that raises is tried ``retries`` more times before it is reported as failed.
    """

    def __init__(self, host: PluginHost, retries: int = 1):
        self.host, self.retries = host, retries

    def execute(self, tasks, seed, arch, on_task=None):
        for task in tasks:
            if on_task is not None:
                on_task(task.key)
            t0 = time.perf_counter()
            for attempt in range(self.retries + 1):
                try:
                    arrays = _call_task(task.run, task.params, seed, self.host, arch)
                    yield task, arrays, time.perf_counter() - t0, None
                    break
                except (KeyboardInterrupt, SystemExit):
                    raise
                except Exception as exc:  # noqa: BLE001 - reported, the others carry on
                    if attempt == self.retries:
                        yield task, None, time.perf_counter() - t0, (f"{type(exc).__name__}: {exc}",
                                                                     traceback.format_exc())


_WORKER_HOSTS: dict[tuple[str, ...], PluginHost] = {}


def _remote_task(run, params, seed, arch, block):
    """Runs on a Dask worker: build (once per process) the worker's own plugin host, then the task."""
    from ..plugins import load_host

    key = tuple(sorted(block))
    if key not in _WORKER_HOSTS:
        _WORKER_HOSTS[key] = load_host(block=block)
    t0 = time.perf_counter()
    arrays = _call_task(run, params, seed, _WORKER_HOSTS[key], arch)
    return arrays, time.perf_counter() - t0


class DaskExecutor:
    """Send tasks to a Dask distributed scheduler; finished tasks come back as they complete.

    Every task's random streams come from the seed and the task's own identity, never from the worker
    or the order, so results are bit-identical to an in-process run.  Dask retries a failing task
    ``retries`` times; one that fails for good is reported and the other tasks' results are kept.
    """

    def __init__(self, client, block: Sequence[str] = (), retries: int = 1, cluster=None):
        self.client, self.block, self.retries, self.cluster = client, tuple(block), retries, cluster

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def execute(self, tasks, seed, arch, on_task=None):
        from distributed import as_completed

        futures = {}
        for i, task in enumerate(tasks):
            # priority: the workers take the tasks in the caller's order (e.g. largest first, so that they
            # finish together); without it the scheduler may leave the longest task for last
            fut = self.client.submit(_remote_task, task.run, dict(task.params), seed, arch, self.block,
                                     pure=False, retries=self.retries, key=f"{task.key}-{time.time_ns()}",
                                     priority=len(tasks) - i)
            futures[fut] = task
        for fut in as_completed(list(futures)):
            task = futures[fut]
            try:
                arrays, seconds = fut.result()
                yield task, arrays, seconds, None
            except (KeyboardInterrupt, SystemExit):
                raise
            except Exception as exc:  # noqa: BLE001
                yield task, None, 0.0, (f"{type(exc).__name__}: {exc}", traceback.format_exc())


Executor = InProcess | DaskExecutor


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
    # One thread per worker process, kernels included: the workers already share the cores between
    # them, and threaded kernels (Numba, BLAS) in every worker would oversubscribe them.
    env = {name: "1" for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
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


def run_report(host: PluginHost, out: Path, *, papers: Iterable[str] | None = None, size: str = "quick",
               seed: int = 0, filters: str | None = None, arch: str = "cpu", progress: bool = True,
               command: str = "", executor: "Executor | None" = None) -> ReportOutcome:
    """Run the chosen recipes (default: every registered one) and write ``index.html`` and ``summary.json``.

    The page and the summary show every paper of ``out``: the ones run now, and the others from their
    saved ``outcome.json`` (an unreadable one is skipped with a warning on stderr).
    """
    from .html import write_index, write_summary

    start = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    wanted = sorted(host.recipes) if not papers else list(papers)
    outcomes = []
    for paper in wanted:
        try:
            recipe = host.recipe(paper)
        except UnknownComponent as exc:
            raise InputError(str(exc)) from None
        outcomes.append(run_recipe(recipe, host, out, size=size, seed=seed, filters=filters, arch=arch,
                                   progress=progress, executor=executor, command=command))
    saved, warnings = saved_outcomes(out, skip=[o.paper for o in outcomes])
    for line in warnings:
        print(f"workbench report: warning: {line}", file=sys.stderr)
    report = ReportOutcome(out, outcomes, time.perf_counter() - start, command, seed, size, saved, warnings)
    write_index(report, host)
    write_summary(report, host)
    return report
