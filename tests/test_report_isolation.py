"""Nothing lost: a component that fails inside a shared task, plugins that come and go, a damaged cache entry
and two reports into one folder."""

import errno
import json
import os
import socket
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fixtures import demo_distribution_env

from workbench import hookimpl
from workbench.plugins import load_host
from workbench.report.cache import DEPS_ARRAY, load_arrays
from workbench.report.engine import LOCK_FILE, ReportFolderBusy, component_failure, run_recipe, run_report
from workbench.specs import RecipeSpec, Table, TableSpec, Task, TaskContext
from workbench.types import InputError

_BASE = load_host()
KF = _BASE.filter("kf")


def _update_that_raises(state, scan, model, rng=None):
    """The KF, except inside a tracker's batch (more than one track): a bug that shows only in the real loop."""
    if state.batch > 1:
        raise RuntimeError("deliberate failure inside the tracker")
    return KF.update(state, scan, model, rng)


BOOM = replace(KF, name="boom-kf", update=_update_that_raises)


def _always_raises(state, scan, model, rng=None):
    raise RuntimeError("deliberate failure inside the tracker")


BOOM_EKF = replace(_BASE.filter("ekf"), name="boom-ekf", update=_always_raises)


def _plugin(*filters):
    return SimpleNamespace(workbench_filters=hookimpl(lambda: list(filters)))


# -- a filter that raises inside paper 001's shared simulation task -------------------------------------------

#: The runs of each seed block in the paper-001 tests below: what they check holds at any count of runs.
SMALL_RUNS = 2


def test_a_filter_raising_inside_paper_001s_tracker_loses_only_its_own_rows(tmp_path):
    host = load_host(extra_plugins=[("boom", _plugin(BOOM))])
    recipe = host.recipe("001")
    # the recipe as it is, with a small size of its own (2 runs: the fewest with a spread), and its figures' data
    # computed and saved but drawn blank: matplotlib's layout of 11 figures would take most of the time, and drawing
    # only reads the data
    small = {"runs": SMALL_RUNS, "seeds": 1, "tuning_runs": SMALL_RUNS, "variant_seeds": 1}
    recipe = replace(recipe, sizes={**recipe.sizes, "small": small},
                     figures=tuple(replace(f, draw=_blank, size=(1.0, 1.0)) for f in recipe.figures))
    outcome = run_recipe(recipe, host, tmp_path, size="small", seed=2, filters="+boom-kf", progress=False)

    # the failure is named once, with its task, its component and its message; nothing else went wrong
    assert outcome.errors == ["task 'sim/0': filter:boom-kf failed: RuntimeError: deliberate failure inside the "
                              "tracker (the task's other results are kept)"]
    sim = next(t for t in outcome.tasks if t["key"] == "sim/0")
    assert sim["error"] == "" and sim["partial"] == ["filter:boom-kf failed: RuntimeError: deliberate failure "
                                                     "inside the tracker"]
    # every figure, table and criterion of the paper is there
    assert [f["id"] for f in outcome.figures] == [f.id for f in recipe.figures]
    assert [t["id"] for t in outcome.tables] == [t.id for t in recipe.tables]
    assert [c.id for c in outcome.criteria] == ["1", "2", "3"]
    for f in outcome.figures:
        assert Path(f["png"]).stat().st_size > 0 and load_arrays(Path(f["data"]))
    # the rows table: every arm of the paper with its numbers, and the failed filter marked, not silently absent
    rows = {r[0]: r for r in next(t for t in outcome.tables if t["id"] == "rows")["rows"]}
    for arm in ("paper", "principled", "tuned", "previous"):
        (row,) = [r for label, r in rows.items() if label.startswith(arm)]
        assert "%" in row[1] and row[-1] == SMALL_RUNS
    assert rows["filter:boom-kf"][1].startswith("FAILED, no rows: sim/0: RuntimeError: deliberate failure")

    # the rows kept are the rows the task gives without the failing filter: run the task alone, without it
    task = next(t for t in recipe.tasks(_options(recipe, "small", 2, ("cmkf-l",))) if t.key == "sim/0")
    alone = task.run(TaskContext(params=task.params, seed=2, host=_BASE))
    (entry,) = (tmp_path / "cache" / "paper001").glob("sim_0-*.npz")
    kept = load_arrays(entry)
    assert not [k for k in kept if k.startswith("filter:boom-kf/")]
    assert str(kept["error/filter:boom-kf"]) == "RuntimeError: deliberate failure inside the tracker"
    assert set(alone) == set(kept) - {"error/filter:boom-kf", DEPS_ARRAY}
    for name, value in alone.items():
        np.testing.assert_array_equal(kept[name], np.asarray(value), err_msg=name)

    # blocking plugins that no task of paper 001 uses keeps every finished task; the partial one is run again (a
    # failure is never replayed from the cache), fails the same way here and gives the same tables
    blocked = load_host(extra_plugins=[("boom", _plugin(BOOM))], block=["lband_radar", "radar_clutter", "paper003"])
    again = run_recipe(recipe, blocked, tmp_path, size="small", seed=2, filters="+boom-kf", progress=False)
    assert [(t["key"], t["cached"]) for t in again.tasks] == [(t["key"], t["key"] != "sim/0") for t in outcome.tasks]
    assert again.errors == outcome.errors and again.tables == outcome.tables


_BLOCK = {"now": None}  # the seed block whose simulation task is running (set by _telling_the_block)


def _update_raising_in_block_one(state, scan, model, rng=None):
    """The KF, except inside the second seed block's simulation (a failure that only some data brings out)."""
    if _BLOCK["now"] == 1:
        raise RuntimeError("deliberate failure in seed block 1")
    return KF.update(state, scan, model, rng)


BOOM_IN_ONE = replace(KF, name="boom-in-one", update=_update_raising_in_block_one)


def _telling_the_block(recipe):
    """The recipe, its simulation tasks setting :data:`_BLOCK` while they run."""
    def told(run):
        def run_telling(ctx):
            _BLOCK["now"] = int(ctx.params["block"])
            try:
                return run(ctx)
            finally:
                _BLOCK["now"] = None
        return run_telling

    def tasks(options):
        return [replace(t, run=told(t.run)) if t.key.startswith("sim/") else t for t in recipe.tasks(options)]

    return replace(recipe, tasks=tasks)


def test_a_filter_raising_in_a_later_seed_block_of_paper_001_loses_only_its_own_rows(tmp_path):
    host = load_host(extra_plugins=[("boom", _plugin(BOOM_IN_ONE))])
    recipe = _telling_the_block(host.recipe("001"))
    small = {"runs": SMALL_RUNS, "seeds": 2, "tuning_runs": SMALL_RUNS, "variant_seeds": 1}
    recipe = replace(recipe, sizes={**recipe.sizes, "small": small},
                     figures=tuple(replace(f, draw=_blank, size=(1.0, 1.0)) for f in recipe.figures))
    outcome = run_recipe(recipe, host, tmp_path, size="small", seed=2, filters="+boom-in-one", progress=False)

    # the filter ran in block 0 and raised in block 1 only: that one failure is named, nothing else went wrong
    assert outcome.errors == ["task 'sim/1': filter:boom-in-one failed: RuntimeError: deliberate failure in seed "
                              "block 1 (the task's other results are kept)"]
    assert {t["key"]: t.get("partial", []) for t in outcome.tasks if t["key"].startswith("sim/")} == {
        "sim/0": [], "sim/1": ["filter:boom-in-one failed: RuntimeError: deliberate failure in seed block 1"]}
    # every figure, table and criterion of the paper is there, on both blocks
    assert [f["id"] for f in outcome.figures] == [f.id for f in recipe.figures]
    assert [t["id"] for t in outcome.tables] == [t.id for t in recipe.tables]
    assert [c.id for c in outcome.criteria] == ["1", "2", "3"]
    assert all(f"2 seed block(s) of {SMALL_RUNS} runs" in c.detail for c in outcome.criteria)
    tables = {t["id"]: t["rows"] for t in outcome.tables}
    # the paper's arms keep their rows over both blocks (2 x SMALL_RUNS runs); the filter, with rows in block 0 only, has no
    # numbers (half its runs would be a different experiment) and is marked FAILED, naming the block
    for arm in ("paper", "principled", "tuned", "previous"):
        (row,) = [r for r in tables["rows"] if r[0].startswith(arm)]
        assert "%" in row[1] and row[-1] == 2 * SMALL_RUNS
    (failed,) = [r for r in tables["rows"] if "boom-in-one" in r[0]]
    assert failed[0] == "filter:boom-in-one"
    assert failed[1].startswith("FAILED, no rows: sim/1: RuntimeError: deliberate failure in seed block 1")
    (failed,) = [r for r in tables["removal-rate"] if "boom-in-one" in r[1]]
    assert failed[:2] == ["simulation", "filter:boom-in-one"] and failed[2].startswith("FAILED, no rows: sim/1")
    gospa = tables["gospa"]
    assert not [r for r in gospa if "boom-in-one" in r[0]]
    assert [r[1] for r in gospa if r[0].startswith("paper")] == ["before", "after"] and gospa[0][-1] == 2 * SMALL_RUNS


def _blank(data, fig):
    assert data  # every figure's data is there
    fig.add_subplot()


def _options(recipe, size, seed, filters):
    from workbench.specs import RecipeOptions

    return RecipeOptions(size=size, values=dict(recipe.sizes[size]), seed=seed, filters=filters)


def test_a_filter_raising_in_paper_000s_shared_task_loses_only_its_row():
    from workbench_papers.paper000 import tasks as paper000

    host = load_host(extra_plugins=[("boom", _plugin(BOOM_EKF))])
    task = paper000.Task("t", {"runs": 1, "rcs": paper000.PRIMARY_RCS, "stream": "", "threshold_db": 5.0,
                               "combos": [["boom-ekf", 600, 1000.0], ["ekf", 600, 1000.0]]}, paper000._runs_task)
    out = task.run(TaskContext(params=task.params, seed=1, host=host))
    assert str(out["error/filter:boom-ekf (N=600, R=1000 m)"]) == "RuntimeError: deliberate failure inside the tracker"
    rows = paper000.runs_of({"table@-20dBsm": out})
    assert list(rows) == [("A", 600, 1000.0)] and set(rows[("A", 600, 1000.0)]) == set(paper000.FIELDS)


# -- a failure inside a task is retried by the next report, never replayed from the cache ---------------------


def _flaky_recipe(fails: list):
    """A recipe with a shared task whose second component raises a MemoryError on the first ``len(fails)`` runs
    (a one-off failure), and a plain task."""
    def shared(ctx):
        out = {"steady": np.arange(3.0)}
        try:
            if fails:
                raise fails.pop()
            out["flaky"] = np.full(2, 7.0)
        except MemoryError as exc:
            out.update(component_failure("filter:flaky", exc))
        return out

    def tasks(options):
        return [Task("shared", {}, shared), Task("other", {}, lambda ctx: {"other": np.ones(1)})]

    def table(results):
        return Table(("task", "arrays"), tuple((k, ", ".join(sorted(v))) for k, v in sorted(results.items())))

    return RecipeSpec("flaky", "a shared task with a one-off failure", {"quick": {}}, tasks,
                      tables=(TableSpec("arrays", "the arrays of each task", table),))


def test_a_one_off_failure_inside_a_task_is_retried_by_the_next_report_not_replayed(tmp_path):
    fails = [MemoryError("one-off")]
    recipe = _flaky_recipe(fails)
    first = run_recipe(recipe, _BASE, tmp_path, progress=False)
    assert first.errors == ["task 'shared': filter:flaky failed: MemoryError: one-off (the task's other results "
                            "are kept)"]
    assert first.tables[0]["rows"] == [["other", "other"], ["shared", "error/filter:flaky, steady"]]

    second = run_recipe(recipe, _BASE, tmp_path, progress=False)  # the failure does not happen again
    assert {t["key"]: t["cached"] for t in second.tasks} == {"shared": False, "other": True}
    assert second.errors == [] and second.tables[0]["rows"] == [["other", "other"], ["shared", "flaky, steady"]]
    # the whole result is cached now, and reused
    third = run_recipe(recipe, _BASE, tmp_path, progress=False)
    assert all(t["cached"] for t in third.tasks) and third.tables == second.tables and not fails


# -- the cache keys each task on what it uses -----------------------------------------------------------------


def test_plugins_a_task_does_not_use_keep_its_cached_result_and_those_it_uses_do_not(tmp_path):
    from fixtures import broken_filters, demo_plugin

    plain = replace(KF, name="shared")
    other = replace(broken_filters.NAN_TO_ZERO, name="shared")  # the same name, another plugin's code
    host = load_host(extra_plugins=[("demo", demo_plugin), ("extra", _plugin(plain))])
    first = run_report(host, tmp_path, papers=["demo"], filters="+shared", progress=False)
    assert not any(t["cached"] for t in first.papers[0].tasks)

    # block plugins the demo tasks do not use: a sensor, a clutter generator, a paper and the extra test plugin
    blocked = load_host(extra_plugins=[("demo", demo_plugin), ("extra", _plugin(plain))],
                        block=["lband_radar", "radar_clutter", "paper000", "extra"])
    assert {p.name for p in blocked.plugins if p.status == "blocked"} == {"lband_radar", "radar_clutter",
                                                                          "paper000", "extra"}
    again = run_report(blocked, tmp_path, papers=["demo"], progress=False)
    assert {t["key"]: t["cached"] for t in again.papers[0].tasks} == {"mse-kf": True, "mse-ekf": True}

    # a plugin added beside them changes nothing either; the filter a task runs, from other code, is recomputed
    swapped = load_host(extra_plugins=[("demo", demo_plugin), ("other", _plugin(other))])
    third = run_report(swapped, tmp_path, papers=["demo"], filters="+shared", progress=False)
    assert {t["key"]: t["cached"] for t in third.papers[0].tasks} == {"mse-kf": True, "mse-ekf": True,
                                                                      "mse-shared": False}
    # and the original is still known: back to the first plugin, its own entry is recomputed (one entry per task)
    back = run_report(host, tmp_path, papers=["demo"], filters="+shared", progress=False)
    assert {t["key"]: t["cached"] for t in back.papers[0].tasks} == {"mse-kf": True, "mse-ekf": True,
                                                                     "mse-shared": False}


# -- a damaged cache entry -------------------------------------------------------------------------------------


def test_an_unreadable_cache_entry_is_named_set_aside_and_recomputed(tmp_path, demo_host, capsys):
    first = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    (entry,) = (tmp_path / "cache" / "paperdemo").glob("mse-kf-*.npz")
    computed = load_arrays(entry)
    entry.write_bytes(b"PK\x03\x04 not a whole zip file")
    capsys.readouterr()
    again = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)

    assert {t["key"]: t["cached"] for t in again.papers[0].tasks} == {"mse-kf": False, "mse-ekf": True}
    aside = entry.with_name(entry.name + ".corrupt")
    assert aside.read_bytes() == b"PK\x03\x04 not a whole zip file"  # kept for a look, not deleted
    (line,) = [w for w in again.warnings if "could not be read" in w]
    assert "task 'mse-kf'" in line and str(entry) in line and aside.name in line and "recomputed" in line
    assert line in capsys.readouterr().err and "could not be read" in (tmp_path / "index.html").read_text()
    assert line in json.loads((tmp_path / "summary.json").read_text())["warnings"]
    # recomputed to the same numbers, and saved again: the next run reuses it without a word
    assert again.papers[0].tables[0]["rows"] == first.papers[0].tables[0]["rows"]
    np.testing.assert_array_equal(load_arrays(entry)["mse_runs"], computed["mse_runs"])
    third = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    assert all(t["cached"] for t in third.papers[0].tasks) and not third.warnings


# -- two reports into one folder -------------------------------------------------------------------------------


_HOLDER = """
import sys
from workbench.report.engine import report_lock
with report_lock(sys.argv[1], command="workbench report --paper demo (the holder)"):
    print("held", flush=True)
    sys.stdin.read()
"""


def test_a_second_report_into_a_busy_folder_is_refused_naming_the_holder_then_waits(tmp_path, demo_host,
                                                                                    monkeypatch):
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(tmp_path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(ReportFolderBusy) as err:
            run_report(demo_host, tmp_path, papers=["demo"], progress=False)
        text = str(err.value)
        assert isinstance(err.value, InputError)  # the command line prints it as one error line, exit 2
        assert f"pid {holder.pid} on host {socket.gethostname()}" in text
        assert "command: workbench report --paper demo (the holder)" in text and str(tmp_path / LOCK_FILE) in text
        assert not (tmp_path / "index.html").exists() and not (tmp_path / "paperdemo").exists()
        # a report that may wait: the first time it waits, the holder finishes; then it runs
        import workbench.report.engine as engine

        real_sleep, waited = time.sleep, []

        def sleep(seconds):
            waited.append(seconds)
            if len(waited) == 1:
                holder.stdin.close()
                holder.wait(timeout=60)  # (which sleeps in turn: that is why the count comes first)
            real_sleep(seconds)

        monkeypatch.setattr(engine.time, "sleep", sleep)
        report = run_report(demo_host, tmp_path, papers=["demo"], progress=False, wait=120)
        assert waited  # it did wait for the holder
    finally:
        holder.kill()
        holder.wait()
    assert not report.papers[0].errors and (tmp_path / "index.html").exists()
    assert not (tmp_path / LOCK_FILE).exists() and not report.warnings


def test_the_command_line_waits_as_long_as_wait_says_then_names_the_holder(tmp_path, capsys):
    from workbench.cli import EXIT, main

    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(tmp_path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        t0 = time.monotonic()
        code = main(["report", "--quick", "--paper", "000", "--out", str(tmp_path), "--no-progress", "--wait", "0.5"])
        waited = time.monotonic() - t0
    finally:
        holder.kill()
        holder.wait()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT["input"] and len(err) == 1 and err[0].startswith("workbench: error: the report folder")
    assert f"pid {holder.pid}" in err[0]
    assert waited >= 0.5  # a lower bound only: it waited at least as long as asked
    assert not (tmp_path / "paper000").exists()


@pytest.mark.parametrize("code, problem", [(errno.ENOLCK, "its filesystem gives no file locks, as a network "
                                                          "filesystem without a lock service does"),
                                           (errno.EOPNOTSUPP, "its filesystem does not support file locks"),
                                           (errno.ENOSYS, "its filesystem does not support file locks")])
def test_a_folder_whose_filesystem_cannot_lock_is_refused_as_such_not_as_busy(tmp_path, monkeypatch, capsys, code,
                                                                               problem):
    import fcntl

    from workbench.cli import EXIT, main

    def flock(fd, op):  # what flock does on NFS without a lock service, or on a filesystem without locks
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(fcntl, "flock", flock)
    code_ = main(["report", "--quick", "--paper", "000", "--out", str(tmp_path), "--no-progress"])
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert code_ == EXIT["input"]
    assert line.startswith(f"workbench: error: cannot lock the report folder {tmp_path}: {problem} "
                           f"({os.strerror(code)}, on {tmp_path / LOCK_FILE})")
    assert "local disk" in line and "in use" not in line and "another report" not in line
    assert not (tmp_path / LOCK_FILE).exists() and not (tmp_path / "paper000").exists()


def test_a_lock_left_by_a_process_that_is_gone_is_taken_over(tmp_path, demo_host):
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(gone.stdout)
    (tmp_path / LOCK_FILE).write_text(json.dumps({"pid": pid, "host": socket.gethostname(), "command": "killed",
                                                  "started": "2020-01-01 00:00:00 UTC"}))
    report = run_report(demo_host, tmp_path, papers=["demo"], progress=False)
    assert not report.papers[0].errors and (tmp_path / "index.html").exists()
    (note,) = report.warnings
    assert note.startswith("took over the report folder's lock") and f"pid {pid}" in note and "killed" in note


def test_two_report_processes_into_one_folder_never_mix_their_tables(tmp_path):
    """Two command-line reports with different --filters at once: one runs, the other is refused by name."""
    env = demo_distribution_env(tmp_path)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "workbench.cli", "report", "--quick", "--paper", "demo", "--out", str(out), "--no-progress"]
    # the first one sleeps inside its ekf task, holding the folder, until it is killed
    slow = subprocess.Popen([*cmd, "--filters", "kf,ekf"], env=dict(env, WORKBENCH_TEST_SLOW_TASK="ekf"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for _ in range(6000):  # until it has finished its first task (or has ended, which the assert reports)
            if list((out / "cache" / "paperdemo").glob("mse-kf-*.npz")) or slow.poll() is not None:
                break
            time.sleep(0.1)
        assert slow.poll() is None, slow.stderr.read()
        second = subprocess.run([*cmd, "--filters", "kf,sir"], env=env, capture_output=True, text=True)
    finally:
        slow.kill()
        slow.wait()
    assert second.returncode == 2 and second.stderr.startswith("workbench: error: the report folder")
    assert f"pid {slow.pid}" in second.stderr and "--filters kf,ekf" in second.stderr
    assert not (out / "summary.json").exists()  # neither wrote a report; none mixes the two
