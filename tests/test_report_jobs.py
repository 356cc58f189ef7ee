"""Tasks on local worker processes (``workbench report --jobs N``): bit-identical to one process, the longest task
first, a failing task or a dying worker reported by name with the finished tasks kept."""

import json
import os
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fixtures import demo_plugin

from workbench import hookimpl, memory
from workbench.cli import EXIT, main
from workbench.report.cache import load_arrays
from workbench.report.engine import (InProcess, LocalProcesses, WorkerHostMismatch, longest_first, previous_seconds,
                                     run_recipe, run_report, side_by_side)
from workbench.specs import Task
from workbench.types import InputError

TESTS = Path(__file__).parent


@pytest.fixture(scope="module")
def installed_host(tmp_path_factory):
    """The installed plugins and the demo plugin, installed through an entry point (a dist-info folder) that this
    process and the worker processes (PYTHONPATH) both see, so that a worker's ``load_host()`` builds this host."""
    from workbench.plugins import load_host

    site = demo_plugin.write_entry_point_site(tmp_path_factory.mktemp("site"))
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(site))
        mp.setenv("PYTHONPATH", os.pathsep.join([str(site), str(TESTS), os.environ.get("PYTHONPATH", "")]))
        host = load_host()
        assert "demo" in host.recipes
        yield host


@pytest.fixture(scope="module")
def two_workers(installed_host):
    """One pool of two worker processes, shared by the tests of this module that do not break it (starting a worker
    costs seconds: it imports the workbench and builds its plugin host)."""
    with LocalProcesses(installed_host, 2) as pool:
        yield pool


def _numbers(out: Path) -> dict:
    """Every number a report's summary gives of its papers' criteria and tables, and the figure data."""
    summary = json.loads((out / "summary.json").read_text())
    paper = summary["papers"][0]
    return {"criteria": [{k: v for k, v in c.items()} for c in paper["criteria"]],
            "tables": [t["rows"] for t in paper["tables"]]}


@pytest.mark.slow
def test_two_worker_processes_give_the_numbers_of_one_process_bit_for_bit(tmp_path, installed_host, two_workers):
    one = run_report(installed_host, tmp_path / "one", papers=["demo"], filters="+sir", seed=4, progress=False)
    two = run_report(installed_host, tmp_path / "two", papers=["demo"], filters="+sir", seed=4, progress=False,
                     executor=two_workers)
    assert {"mse-kf", "mse-ekf", "mse-sir"} <= set(two_workers.used)  # every task ran on a worker
    assert not one.papers[0].errors and not two.papers[0].errors
    a, b = load_arrays(tmp_path / "one" / "paperdemo" / "fig1.npz"), load_arrays(tmp_path / "two" / "paperdemo" /
                                                                                 "fig1.npz")
    assert list(a["filters"]) == list(b["filters"]) == ["ekf", "kf", "sir"]
    assert np.array_equal(a["mse"], b["mse"])  # bit-identical, the particle filter included
    assert _numbers(tmp_path / "one") == _numbers(tmp_path / "two")
    assert {t["key"] for t in two.papers[0].tasks} == {"mse-kf", "mse-ekf", "mse-sir"}
    assert all(t["seconds"] > 0 and not t["cached"] for t in two.papers[0].tasks)


def _recipe_with(*extra):
    return replace(demo_plugin.RECIPE, tasks=lambda o: [*demo_plugin._tasks(o)[:1], *extra])


@pytest.mark.slow
def test_a_failing_task_is_retried_in_its_worker_and_one_failing_always_is_named(tmp_path, installed_host,
                                                                                  two_workers):
    recipe = _recipe_with(Task("flaky", {"marker": str(tmp_path / "marker")}, demo_plugin.flaky_task),
                          Task("doomed", {}, demo_plugin.always_fails))
    outcome = run_recipe(recipe, installed_host, tmp_path / "out", progress=False, executor=two_workers)
    status = {t["key"]: t["error"] for t in outcome.tasks}
    assert status["mse-kf"] == "" and status["flaky"] == ""  # flaky failed once, then passed on its retry
    assert "RuntimeError: this chunk always fails" in status["doomed"]
    doomed = next(t for t in outcome.tasks if t["key"] == "doomed")
    assert "always_fails" in doomed["traceback"]  # the worker's own traceback
    cached = sorted(p.name.split("-")[0] for p in (tmp_path / "out" / "cache" / "paperdemo").glob("*.npz"))
    assert cached == ["flaky", "mse"]


@pytest.mark.slow
@pytest.mark.skipif(not memory._glibc(), reason="the thresholds are glibc's")
def test_the_workers_start_with_the_malloc_thresholds_of_the_command_line(tmp_path, installed_host, two_workers):
    """The report's worker processes keep freed blocks for reuse (:mod:`workbench.memory`) from their first line."""
    recipe = _recipe_with(Task("malloc", {}, demo_plugin.malloc_settings))
    outcome = run_recipe(recipe, installed_host, tmp_path / "out", progress=False, executor=two_workers)
    assert {t["key"]: t["error"] for t in outcome.tasks} == {"mse-kf": "", "malloc": ""}
    got = load_arrays(next((tmp_path / "out" / "cache" / "paperdemo").glob("malloc-*.npz")))
    assert int(got["pid"]) != os.getpid()
    assert {name: str(int(got[name])) for name in memory.MALLOC_ENV} == memory.MALLOC_ENV


@pytest.mark.slow
def test_a_task_that_cannot_be_sent_to_a_worker_runs_in_this_process(tmp_path, installed_host, two_workers):
    """A recipe written elsewhere may give a closure as a task's function: it cannot be pickled to a worker, so it
    runs in the report's own process (with the same seed) while the workers run the others; never a failure."""
    pid = os.getpid()

    def here(ctx):  # a closure: pickle refuses it
        from workbench.rng import generator

        return {"pid": np.array(os.getpid()), "draw": generator(ctx.seed, "closure").standard_normal(3)}

    recipe = _recipe_with(Task("closure", {}, here))
    outcome = run_recipe(recipe, installed_host, tmp_path / "out", progress=False, executor=two_workers)
    assert {t["key"]: t["error"] for t in outcome.tasks} == {"mse-kf": "", "closure": ""}
    run_recipe(recipe, installed_host, tmp_path / "inline", progress=False, executor=InProcess(installed_host))
    got = [load_arrays(next((tmp_path / d / "cache" / "paperdemo").glob("closure-*.npz"))) for d in ("out", "inline")]
    assert int(got[0]["pid"]) == pid and np.array_equal(got[0]["draw"], got[1]["draw"])
    assert "mse-kf" in two_workers.used  # the other task still ran on a worker


@pytest.mark.slow
def test_a_worker_that_dies_fails_its_task_by_name_and_the_finished_tasks_are_kept(tmp_path, installed_host,
                                                                                   monkeypatch):
    """The ``sir`` task blocks in its worker (the demo task's hook) until the test kills the worker, once the two
    other tasks are cached: no wall clock decides anything, however loaded the machine.  One worker: it takes the
    tasks in order (kf, ekf, then sir, which blocks)."""
    monkeypatch.setenv("WORKBENCH_TEST_SLOW_TASK", "sir")
    cache = tmp_path / "out" / "cache" / "paperdemo"
    pool = LocalProcesses(installed_host, 1)
    killed = []

    def kill_when_two_are_cached():
        while len(list(cache.glob("*.npz"))) < 2:
            time.sleep(0.05)
        for proc in list(pool._pool._processes.values()):
            os.kill(proc.pid, signal.SIGKILL)
            killed.append(proc.pid)

    watcher = threading.Thread(target=kill_when_two_are_cached, daemon=True)
    watcher.start()
    try:
        outcome = run_recipe(demo_plugin.RECIPE, installed_host, tmp_path / "out", progress=False, executor=pool,
                             filters="+sir")
    finally:
        pool.close()
    watcher.join(timeout=60)
    assert killed
    status = {t["key"]: t["error"] for t in outcome.tasks}
    assert status["mse-kf"] == "" and status["mse-ekf"] == ""
    assert "the worker process running it died" in status["mse-sir"]
    assert any("mse-sir" in e and "died" in e for e in outcome.errors)
    assert sorted(p.name.split("-")[1] for p in cache.glob("*.npz")) == ["ekf", "kf"]
    # the next report into the folder reuses the finished tasks and runs only the lost one
    monkeypatch.delenv("WORKBENCH_TEST_SLOW_TASK")
    outcome = run_recipe(demo_plugin.RECIPE, installed_host, tmp_path / "out", progress=False, filters="+sir")
    assert {t["key"]: t["cached"] for t in outcome.tasks} == {"mse-kf": True, "mse-ekf": True, "mse-sir": False}
    assert not outcome.errors


def _task(key):
    return Task(key, {}, demo_plugin.always_fails)


def test_longest_first_puts_unknown_tasks_first_then_the_longest_keeping_the_declared_order_in_ties():
    tasks = [_task(k) for k in ("a", "b", "c", "d", "e", "f")]
    seconds = {"a": 1.0, "b": 30.0, "d": 30.0, "e": 5.0}  # c and f never computed here
    # written out by hand: the unknown ones in declared order, then 30 (b before d), 5, 1
    assert [t.key for t in longest_first(tasks, seconds)] == ["c", "f", "b", "d", "e", "a"]
    assert [t.key for t in longest_first(tasks, {})] == ["a", "b", "c", "d", "e", "f"]


class _Recording:
    """An executor that records the order it is handed the tasks in (and runs them in this process)."""

    def __init__(self, host):
        self.inner, self.order = InProcess(host), []
        self.used = self.inner.used

    def execute(self, tasks, seed, arch, on_task=None):
        tasks = list(tasks)
        self.order.append([t.key for t in tasks])
        yield from self.inner.execute(tasks, seed, arch, on_task)


def _rerun_with_times(out, host, saved, times) -> list:
    """Run the demo recipe again into ``out`` (its cache emptied) after a report whose time table gave ``times``;
    the order the executor was handed the tasks in."""
    for entry in saved["tasks"]:
        if entry["key"] in times:
            entry["seconds"] = times[entry["key"]]
    (out / "paperdemo" / "outcome.json").write_text(json.dumps(saved))
    for f in (out / "cache" / "paperdemo").glob("*.npz"):
        f.unlink()
    recording = _Recording(host)
    run_recipe(demo_plugin.RECIPE, host, out, progress=False, filters="+sir", executor=recording)
    return recording.order


def test_workers_get_the_tasks_longest_first_by_the_last_report_s_time_table(tmp_path, demo_host):
    out = tmp_path / "out"
    run_recipe(demo_plugin.RECIPE, demo_host, out, progress=False, filters="+sir")  # in process: declared order
    saved = json.loads((out / "paperdemo" / "outcome.json").read_text())
    assert [t["key"] for t in saved["tasks"]] == ["mse-kf", "mse-ekf", "mse-sir"]
    saved["tasks"].append({"key": "confirmation/mse-kf", "seconds": 2.0, "cached": False, "error": ""})
    saved["tasks"].append({"key": "mse-old", "seconds": 7.0, "cached": True, "error": ""})  # cached: no time
    assert _rerun_with_times(out, demo_host, saved, {"mse-kf": 1.0, "mse-ekf": 9.0, "mse-sir": 5.0}) == [
        ["mse-ekf", "mse-sir", "mse-kf"]]
    saved = json.loads((out / "paperdemo" / "outcome.json").read_text())
    saved["tasks"].append({"key": "confirmation/mse-kf", "seconds": 2.0, "cached": False, "error": ""})
    (out / "paperdemo" / "outcome.json").write_text(json.dumps(saved))
    assert previous_seconds(out, "demo", "confirmation/") == {"mse-kf": 2.0}
    assert _rerun_with_times(out, demo_host, saved, {"mse-kf": 3.0, "mse-ekf": 2.0, "mse-sir": 4.0}) == [
        ["mse-sir", "mse-kf", "mse-ekf"]]
    assert previous_seconds(out / "nowhere", "demo") == {}


class HereOnly:
    """A plugin registered in this process only (no entry point names it): the demo recipe as paper ``here``."""

    @hookimpl
    def workbench_report_recipes(self):
        return [replace(demo_plugin.RECIPE, paper="here")]


def test_a_host_with_plugins_registered_in_this_process_only_is_refused_by_name(demo_host):
    from workbench.plugins import load_host

    pool = LocalProcesses(load_host(extra_plugins=[("registered-here-only", HereOnly())]), 2)
    with pytest.raises(WorkerHostMismatch, match="would not load"):
        pool.check_host()
    with pytest.raises(InputError, match="jobs: a whole number"):
        LocalProcesses(demo_host, 0)


def _one_error_line(capsys, *parts):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("workbench: error: "), err
    for part in parts:
        assert part in err[0]


def test_the_command_line_jobs_option(tmp_path, capsys, monkeypatch):
    import workbench.cli as cli
    from workbench.plugins import load_host

    here_only = load_host(extra_plugins=[("registered-here-only", HereOnly())])
    monkeypatch.delenv("WORKBENCH_JOBS", raising=False)  # the default of a plain command line (tests/conftest.py sets 1)

    assert main(["report", "--quick", "--jobs", "2", "--workers", "2", "--out", str(tmp_path / "a")]) == EXIT["input"]
    _one_error_line(capsys, "--jobs 2 and --workers", "not both")
    with pytest.raises(SystemExit):
        main(["report", "--quick", "--jobs", "0"])
    assert "expected a whole number >= 1, got 0" in capsys.readouterr().err
    # a host with a plugin registered in this process only: --jobs 2 is refused by name, before any paper runs ...
    monkeypatch.setattr(cli, "load_host", lambda block=(): here_only)
    code = main(["report", "--quick", "--paper", "here", "--jobs", "2", "--out", str(tmp_path / "b"), "--no-progress"])
    assert code == EXIT["input"]
    _one_error_line(capsys, "--jobs 2:", "would not load", "--jobs 1")
    assert not (tmp_path / "b" / "paperhere").exists()
    # ... and the default (no --jobs) runs its tasks in this process, whatever the machine's cores
    assert main(["report", "--quick", "--paper", "here", "--out", str(tmp_path / "c"), "--no-progress"]) == 0
    assert (tmp_path / "c" / "paperhere" / "fig1.png").exists()


def test_the_jobs_variable_sets_the_default_and_a_bad_value_is_refused_by_name(tmp_path, capsys, monkeypatch):
    import workbench.report.engine as engine
    from workbench.cli import JOBS_VARIABLE, _default_jobs

    monkeypatch.delenv(JOBS_VARIABLE, raising=False)
    assert _default_jobs(3) == 3 and _default_jobs(64) == 8
    monkeypatch.setenv(JOBS_VARIABLE, " 5 ")
    assert _default_jobs(2) == 5
    for bad in ("0", "-2", "two", "1.5"):
        monkeypatch.setenv(JOBS_VARIABLE, bad)
        assert main(["report", "--quick", "--paper", "003", "--out", str(tmp_path / bad), "--no-progress"]) == EXIT["input"]
        _one_error_line(capsys, f"{JOBS_VARIABLE}={bad!r}", "whole number of worker processes >= 1")
        assert not (tmp_path / bad).exists()
    # WORKBENCH_JOBS=1: no worker pool is started; --jobs still overrides it (refused here with --workers, by name)
    started = []
    monkeypatch.setattr(engine, "LocalProcesses", lambda *a, **k: started.append(a) or pytest.fail("pool started"))
    monkeypatch.setenv(JOBS_VARIABLE, "1")
    assert main(["report", "--quick", "--paper", "here", "--out", str(tmp_path / "one"), "--no-progress"]) == EXIT["input"]
    assert not started


def test_the_report_command_gives_firm_verdicts_by_default_and_quick_only_on_request():
    from workbench.cli import build_parser
    parser = build_parser()
    assert parser.parse_args(["report"]).size == "full"
    assert parser.parse_args(["report", "--quick"]).size == "quick"
    assert parser.parse_args(["report", "--full"]).size == "full"
    with pytest.raises(SystemExit):  # one size or the other, never both
        parser.parse_args(["report", "--quick", "--full"])


class TwoPapers:
    """The demo recipe twice more, as papers ``twin-a`` and ``twin-b`` (the same task keys in both)."""

    @hookimpl
    def workbench_report_recipes(self):
        return [replace(demo_plugin.RECIPE, paper="twin-a"), replace(demo_plugin.RECIPE, paper="twin-b")]


def test_papers_run_side_by_side_in_one_batch_per_seed_with_the_numbers_of_one_paper_alone(tmp_path):
    """Every paper's tasks on the reported seed go to the workers in one call (longest first across papers), then
    every paper's confirmation tasks in one more (run by a thread while the figures are drawn); each paper's results,
    time table and verdicts are those of the paper run alone, in process."""
    from workbench.plugins import load_host

    host = load_host(extra_plugins=[("demo", demo_plugin), ("twins", TwoPapers())])
    recording = _Recording(host)
    report = run_report(host, tmp_path / "both", papers=["twin-a", "twin-b"], size="full", filters="+sir",
                        progress=False, executor=recording)
    keys = [e["key"] for e in report.papers[0].tasks if not e["key"].startswith("confirmation/")]
    assert keys == ["mse-kf", "mse-ekf", "mse-sir"]
    # one call per seed, whatever the number of papers; never run before here, so in the declared order, the papers'
    # tasks in turn
    assert len(recording.order) == 2 and recording.order[0] == [k for k in keys for _ in range(2)]
    read = [e["key"].removeprefix("confirmation/") for e in report.papers[0].tasks
            if e["key"].startswith("confirmation/") and not e.get("reused")]
    # the confirmation: the longest first by the seconds the same tasks just took on the reported seed
    took = [{e["key"]: e["seconds"] for e in paper.tasks} for paper in report.papers]
    expected = sorted(((-took[p][k], p, i, k) for p in range(2) for i, k in enumerate(read)))
    assert read and recording.order[1] == [k for *_, k in expected]
    for paper in report.papers:
        alone = run_recipe(replace(demo_plugin.RECIPE, paper=paper.paper), host, tmp_path / f"alone-{paper.paper}",
                           size="full", filters="+sir", progress=False)
        assert [c.to_dict() for c in paper.criteria] == [c.to_dict() for c in alone.criteria]
        assert all(c.confirmation is not None and c.confirmation.verdict for c in paper.criteria)
        assert [(e["key"], e["cached"], e.get("reused")) for e in paper.tasks] == [
            (e["key"], e["cached"], e.get("reused")) for e in alone.tasks]
        assert [f["id"] for f in paper.figures] == [f["id"] for f in alone.figures] and paper.figures
    # a second report into the folder: every task from the cache, nothing handed to the workers
    recording.order.clear()
    run_report(host, tmp_path / "both", papers=["twin-a", "twin-b"], size="full", filters="+sir", progress=False,
               executor=recording)
    assert all(not batch for batch in recording.order)


def test_side_by_side_takes_the_tasks_without_a_time_of_each_batch_in_turn_then_the_longest_then_timed_ones():
    a = [_task(k) for k in ("a1", "a2", "a3", "a4")]
    b = [_task(k) for k in ("b1", "b2")]
    c = [_task(k) for k in ("c1", "c2", "c3")]
    # a new folder: no times at all -> a1 b1 c1 a2 b2 c2 a3 c3 a4 (written out by hand)
    assert [t.key for t in side_by_side([(a, {}), (b, {}), (c, {})])] == [
        "a1", "b1", "c1", "a2", "b2", "c2", "a3", "c3", "a4"]
    # tasks with a time after every one without, the longest first; a tie keeps the batches' order
    got = side_by_side([(a, {"a1": 3.0, "a3": 9.0}), (b, {"b1": 3.0, "b2": 1.0}), (c, {"c2": 20.0})])
    assert [t.key for t in got] == ["c1", "a2", "c3", "a4", "c2", "a3", "a1", "b1", "b2"]
    # a task declared timed (wall-clock measurements) after every other one, however long, by the same rules
    a[0], c[1] = Task("a1", {}, demo_plugin.always_fails, timed=True), Task("c2", {}, demo_plugin.always_fails,
                                                                            timed=True)
    got = side_by_side([(a, {"a1": 3.0, "a3": 9.0}), (b, {"b1": 3.0, "b2": 1.0}), (c, {"c2": 20.0})])
    assert [t.key for t in got] == ["c1", "a2", "c3", "a4", "a3", "b1", "b2", "c2", "a1"]
    assert [t.key for t in side_by_side([(a, {}), (b, {}), (c, {})])] == [
        "b1", "c1", "a2", "b2", "a3", "c3", "a4", "a1", "c2"]
    # or before every other one (the reported seed, where the report's own process only waits)
    got = side_by_side([(a, {"a1": 3.0, "a3": 9.0}), (b, {"b1": 3.0, "b2": 1.0}), (c, {"c2": 20.0})], timed_last=False)
    assert [t.key for t in got] == ["c2", "a1", "c1", "a2", "c3", "a4", "a3", "b1", "b2"]
    with pytest.raises(InputError, match="timed is True or False"):
        Task("x", {}, demo_plugin.always_fails, timed=1)


class TimedTwin:
    """The demo recipe as paper ``timed-twin``, its ``mse-sir`` task declared timed (wall-clock measurements)."""

    @hookimpl
    def workbench_report_recipes(self):
        def tasks(options):
            return [replace(t, timed=True) if t.key == "mse-sir" else t for t in demo_plugin._tasks(options)]

        return [replace(demo_plugin.RECIPE, paper="timed-twin", tasks=tasks)]


def test_a_timed_task_goes_first_on_the_reported_seed_and_last_on_the_confirmation_seed(tmp_path):
    """On the reported seed the report's own process only waits: the timed task goes first (no worker idle at the
    end); on the confirmation seed it draws the figures beside the workers at first: the timed task goes last."""
    from workbench.plugins import load_host

    host = load_host(extra_plugins=[("demo", demo_plugin), ("timed-twin", TimedTwin())])
    recording = _Recording(host)
    report = run_report(host, tmp_path / "timed", papers=["timed-twin"], size="full", filters="+sir",
                        progress=False, executor=recording)
    assert len(recording.order) == 2
    assert recording.order[0] == ["mse-sir", "mse-kf", "mse-ekf"]
    assert "mse-sir" in recording.order[1] and recording.order[1][-1] == "mse-sir"
    assert not report.papers[0].errors


def test_a_held_timed_task_waits_while_untimed_ones_remain_and_goes_first_once_released(installed_host):
    """One worker runs the tasks one at a time, so the order they come back in is the order they ran in; two are
    in flight (one waits for the worker), and the next is chosen when one finishes, before it is handed back.  The
    timed task is first in the caller's order: held, the worker takes the untimed ones; released when the first
    result comes back (the report's process has drawn its figures), it runs after the two already in flight;
    never released, it runs once no untimed task is left; without a hold, or released from the start, in the
    caller's order."""
    import threading

    def order(hold, release_after=None):
        tasks = [replace(_task("timing"), timed=True)] + [_task(k) for k in ("a", "b", "c", "d", "e")]
        got = []
        with LocalProcesses(installed_host, 1) as pool:
            for task, _, _, error in pool.execute(tasks, 0, "cpu", hold=hold):
                assert error is not None and "always fails" in error[0]
                got.append(task.key)
                if release_after == task.key:
                    hold.set()
        return got

    assert order(threading.Event(), release_after="a") == ["a", "b", "c", "timing", "d", "e"]
    assert order(threading.Event()) == ["a", "b", "c", "d", "e", "timing"]
    assert order(None) == ["timing", "a", "b", "c", "d", "e"]
    released = threading.Event()
    released.set()
    assert order(released) == ["timing", "a", "b", "c", "d", "e"]


class _Scripted:
    """An executor that hands the tasks back in a scripted order (their arrays made up, nothing run)."""

    def __init__(self, script):
        self.script, self.used = script, {}

    def execute(self, tasks, seed, arch, on_task=None):
        by_key = {t.key: t for t in tasks}
        for key in self.script:
            yield by_key[key], {"x": np.zeros(1)}, 0.0, None


def test_a_batch_is_handed_on_once_its_tasks_are_back_and_never_while_a_timed_task_is_out(tmp_path, demo_host):
    """``_execute``'s ``on_done``: the report judges a paper there while the workers run the other papers' tasks,
    but not while a timed task may still be measuring (judging loads the cores it measures)."""
    from workbench.report.cache import TaskCache
    from workbench.report.engine import PaperOutcome, _Batch, _execute

    def batches(q_timed):
        out = []
        for paper, keys in (("p", ("p1", "p2")), ("q", ("q1", "q2"))):
            tasks = [replace(_task(k), timed=q_timed and k == "q1") for k in keys]
            outcome = PaperOutcome(paper, paper, "quick", (), "", {})
            out.append(_Batch(replace(demo_plugin.RECIPE, paper=paper), tasks, 0, "quick", "cpu", "v", outcome, {}))
        return out

    def handed(script, q_timed):
        seen, log = [], []
        run = _Scripted(script)
        original = run.execute

        def execute(tasks, seed, arch, on_task=None):
            for item in original(tasks, seed, arch, on_task):
                seen.append(item[0].key)
                yield item

        run.execute = execute
        _execute(batches(q_timed), demo_host, TaskCache(tmp_path / "".join(script)), run, progress=False, on_task=None,
                 label="t", on_done=lambda b: log.append((b.recipe.paper, len(seen), sorted(b.results))))
        return log

    # p's two tasks back first: p handed on at once (q's tasks not yet back), each with its results
    assert handed(["p1", "p2", "q1", "q2"], False) == [("p", 2, ["p1", "p2"]), ("q", 4, ["q1", "q2"])]
    # q1 timed and out until the end: p waits for it, then both, in the order they completed
    assert handed(["p1", "q2", "p2", "q1"], True) == [("p", 4, ["p1", "p2"]), ("q", 4, ["q1", "q2"])]
    # the timed task back first: nothing waits
    assert handed(["q1", "p1", "p2", "q2"], True) == [("p", 3, ["p1", "p2"]), ("q", 4, ["q1", "q2"])]
