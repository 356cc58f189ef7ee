"""Run report recipes: tasks (cached), then figures, tables and criteria from the saved results.

Output folder layout::

    OUT/index.html                 figures embedded, tables (ours beside published), provenance
    OUT/summary.json               machine-readable: criteria, tables, task timings, errors
    OUT/paperNNN/FIG.png|.svg      each figure
    OUT/paperNNN/FIG.npz, FIG.csv  the data behind it
    OUT/paperNNN/TABLE.csv         each table
    OUT/cache/...                  finished task results (reused by the next run)
"""

from __future__ import annotations

import csv
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from ..plugins import PluginHost, UnknownComponent
from ..specs import Criterion, RecipeOptions, RecipeSpec, Table, TaskContext
from ..types import InputError
from .cache import TaskCache, code_version, save_arrays, task_key

__all__ = ["resolve_filters", "PaperOutcome", "ReportOutcome", "run_recipe", "run_report", "figure_data_csv",
           "InProcess", "DaskExecutor", "dask_executor"]


def resolve_filters(default: Sequence[str], request: str | None, host: PluginHost) -> tuple[str, ...]:
    """Apply ``--filters`` to a recipe's default list.

    ``request`` is a comma-separated list; entries starting with ``+`` are added to the defaults, and
    ``-name`` removes one; if any entry has no sign, the list replaces the defaults.  Every name must be
    an installed filter.
    """
    if not request:
        return tuple(default)
    parts = [p.strip() for p in request.split(",") if p.strip()]
    plain = [p for p in parts if p[0] not in "+-"]
    chosen = list(plain) if plain else list(default)
    for p in parts:
        if p.startswith("+") and p[1:] not in chosen:
            chosen.append(p[1:])
        elif p.startswith("-") and p[1:] in chosen:
            chosen.remove(p[1:])
    for name in chosen:
        host.filter(name)  # raises UnknownComponent naming what is installed
    return tuple(chosen)


@dataclass
class PaperOutcome:
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


@dataclass
class ReportOutcome:
    out: Path
    papers: list[PaperOutcome]
    seconds: float
    command: str
    seed: int
    size: str

    @property
    def failed(self) -> bool:
        return any(p.errors for p in self.papers)


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
               on_task: Callable[[str], None] | None = None, executor: "Executor | None" = None) -> PaperOutcome:
    """Run one recipe into ``out/paperNNN`` using the cache in ``out/cache``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    start = time.perf_counter()
    if size not in recipe.sizes:
        raise InputError(f"recipe {recipe.paper} has no size {size!r} (sizes: {', '.join(recipe.sizes)})")
    chosen = resolve_filters(recipe.default_filters, filters, host) if recipe.default_filters else ()
    options = RecipeOptions(size=size, values=dict(recipe.sizes[size]), seed=seed, filters=chosen, arch=arch)
    outcome = PaperOutcome(recipe.paper, recipe.title, size, chosen, recipe.notes, dict(recipe.published))
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
    outcome.seconds = time.perf_counter() - start
    return outcome


def _call_task(run, params, seed, host, arch) -> dict:
    return {k: np.asarray(v) for k, v in dict(run(TaskContext(params=params, seed=seed, host=host, arch=arch))).items()}


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


def dask_executor(host: PluginHost, scheduler: str | None = None, workers: int | None = None,
                  block: Sequence[str] = ()):
    """A :class:`DaskExecutor` on ``scheduler`` (an address), or on a new local cluster of ``workers``."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("running on Dask needs the 'distributed' package: pip install -e \".[dask]\"") from None
    if scheduler:
        return DaskExecutor(Client(scheduler), block)
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
    """Run the chosen recipes (default: every registered one) and write ``index.html`` and ``summary.json``."""
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
                                   progress=progress, executor=executor))
    report = ReportOutcome(out, outcomes, time.perf_counter() - start, command, seed, size)
    write_index(report, host)
    write_summary(report, host)
    return report
