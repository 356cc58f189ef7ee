"""The report's time table (task, runs, seconds, share, status) and the confirmation seed's reuse of tasks declared
``seeded=False``.

A tiny fake recipe (registered in a test host, as in tests/test_confirmation_seed.py) has a seeded task its criteria
read, a task on its own fixed tuning seed (declared ``seeded=False``) they also read, and one they do not read.  The
shares are checked against closed forms on hand-given seconds, and against the recorded seconds of a real report
(never against a wall-clock figure: the seconds themselves are whatever the machine took).
"""

import json
import re

import numpy as np
import pytest

from workbench import hookimpl
from workbench.criteria import criterion_from_runs
from workbench.plugins import load_host
from workbench.report.engine import CONFIRMATION_SEED, TASK_STATUSES, run_report, task_time_table
from workbench.rng import generator
from workbench.specs import FigureSpec, RecipeSpec, Table, TableSpec, Task
from workbench.types import InputError

RUNS, TUNE_RUNS, TUNE_SEED = 30, 20, 4242
#: every task run: (task key, the seed it was handed)
CALLS: list = []


def _data_task(ctx):
    CALLS.append(("data", ctx.seed))
    return {"x": 5.0 + generator(ctx.seed, "task-times-test", "data").normal(size=RUNS)}


def _tune_task(ctx):
    CALLS.append(("tune", ctx.seed))
    # draws from its own fixed seed only: the result is the same whatever the report's seed
    return {"t": 1.0 + generator(TUNE_SEED, "task-times-test", "tune").normal(size=TUNE_RUNS)}


def _unread_task(ctx):
    CALLS.append(("unread", ctx.seed))
    return {"y": np.arange(3.0)}


def _criteria(results):
    x, t = np.asarray(results["data"]["x"]), np.asarray(results["tune"]["t"])
    return [criterion_from_runs("A", "data mean above 0", x, np.mean, 0.0, ">=", min_n=10),
            criterion_from_runs("T", "tuning mean above -5", t, np.mean, -5.0, ">=", min_n=10)]


def _tasks(options, tune_params=None):
    return [Task("data", {}, _data_task, runs=RUNS),
            Task("tune", {} if tune_params is None else tune_params(options), _tune_task, runs=TUNE_RUNS,
                 seeded=False),
            Task("unread", {}, _unread_task)]


def _host(tune_params=None):
    recipe = RecipeSpec("tt", "time table test", {"quick": {}, "full": {}},
                        lambda options: _tasks(options, tune_params), criteria=_criteria,
                        figures=(FigureSpec("f1", "data", lambda r: {"x": r["data"]["x"]},
                                            lambda d, fig: fig.add_subplot().plot(d["x"])),),
                        tables=(TableSpec("t1", "tune", lambda r: Table(("n",), ((len(r["tune"]["t"]),),))),))

    class _Plugin:
        @hookimpl
        def workbench_report_recipes(self):
            return [recipe]

    return load_host(entry_points=[], extra_plugins=[("tt", _Plugin())])


# -- the table on hand-given seconds (closed forms) ---------------------------------------------------------------


def test_shares_are_of_the_seconds_spent_with_cached_and_reused_at_zero():
    entries = [{"key": "a", "seconds": 3.0, "cached": False, "error": "", "runs": 7},
               {"key": "b", "seconds": 1.0, "cached": False, "error": ""},
               {"key": "c", "seconds": 5.0, "cached": True, "error": ""},  # a cached entry's seconds never count
               {"key": "d", "seconds": 2.0, "cached": False, "error": "task 'd' failed: boom"},
               {"key": "e", "seconds": 0.0, "cached": False, "error": "", "reused": "the reported seed's result"}]
    table = task_time_table(entries)
    rows = {r["task"]: r for r in table["rows"]}
    # 3 + 1 + 2 = 6 s spent: 3/6, 1/6, 2/6 in hundredths of a percent, the spare hundredth to the largest remainder
    assert {k: r["share_percent"] for k, r in rows.items()} == {"a": 50.0, "b": 16.67, "c": 0.0, "d": 33.33, "e": 0.0}
    assert {k: r["status"] for k, r in rows.items()} == {"a": "computed", "b": "computed", "c": "cached",
                                                          "d": "failed", "e": "reused"}
    assert rows["c"]["seconds"] == 0.0 and rows["a"]["runs"] == 7 and rows["b"]["runs"] is None
    assert [r["task"] for r in table["rows"]] == ["a", "d", "b", "c", "e"]  # the largest first
    assert table["computed_seconds"] == 6.0
    assert table["counts"] == {"computed": 2, "cached": 1, "reused": 1, "failed": 1}


def test_shares_sum_to_exactly_100_and_are_all_zero_when_nothing_ran():
    thirds = task_time_table([{"key": k, "seconds": 1.0} for k in "xyz"])["rows"]
    assert [r["share_percent"] for r in thirds] == [33.34, 33.33, 33.33]
    rng = np.random.default_rng(5)
    for _ in range(50):
        seconds = rng.exponential(size=int(rng.integers(1, 40))) * 10.0 ** rng.integers(-3, 3)
        rows = task_time_table([{"key": str(i), "seconds": float(s)} for i, s in enumerate(seconds)])["rows"]
        hundredths = [round(r["share_percent"] * 100) for r in rows]
        assert sum(hundredths) == 10_000 and all(0 <= h <= 10_000 for h in hundredths)
        for r in rows:  # each within a hundredth of a percent of its exact share
            assert abs(r["share_percent"] - 100.0 * seconds[int(r["task"])] / seconds.sum()) <= 0.01 + 1e-9
    cached = task_time_table([{"key": "a", "seconds": 4.0, "cached": True}, {"key": "b", "seconds": 0.0}])
    assert [r["share_percent"] for r in cached["rows"]] == [0.0, 0.0] and cached["computed_seconds"] == 0.0


def test_a_task_declares_runs_and_seeded_or_is_refused_by_name():
    with pytest.raises(InputError, match="task 'k': runs"):
        Task("k", {}, _data_task, runs=0)
    with pytest.raises(InputError, match="task 'k': runs"):
        Task("k", {}, _data_task, runs=2.5)
    with pytest.raises(InputError, match="task 'k': seeded"):
        Task("k", {}, _data_task, seeded="no")
    assert Task("k", {}, _data_task).seeded is True and Task("k", {}, _data_task).runs is None


# -- a report of the fake recipe --------------------------------------------------------------------------------


def _check_table(table, expected_status):
    rows = {r["task"]: r for r in table["rows"]}
    assert {k: r["status"] for k, r in rows.items()} == expected_status
    assert {k: r["runs"] for k, r in rows.items()} == {"data": RUNS, "tune": TUNE_RUNS, "unread": None,
                                                       "confirmation/data": RUNS, "confirmation/tune": TUNE_RUNS}
    spent = {k: r["seconds"] for k, r in rows.items() if r["status"] in ("computed", "failed")}
    assert table["computed_seconds"] == pytest.approx(sum(spent.values()))
    hundredths = [round(r["share_percent"] * 100) for r in rows.values()]
    assert all(0 <= h <= 10_000 for h in hundredths)
    assert sum(hundredths) == (10_000 if table["computed_seconds"] > 0 else 0)
    for k, r in rows.items():
        if r["status"] in ("cached", "reused"):
            assert r["seconds"] == 0.0 and r["share_percent"] == 0.0
        elif table["computed_seconds"] > 0:
            assert abs(r["share_percent"] - 100.0 * r["seconds"] / table["computed_seconds"]) <= 0.01 + 1e-9
    return rows


def test_full_report_writes_the_time_table_into_its_metadata_and_page(tmp_path):
    CALLS.clear()
    report = run_report(_host(), tmp_path, papers=["tt"], size="full", seed=3, progress=False)
    # the task declared seeded=False ran once; the seeded task the criteria read ran on both seeds
    assert sorted(CALLS) == sorted([("data", 3), ("tune", 3), ("unread", 3), ("data", CONFIRMATION_SEED)])
    # the confirmation judged T on the reused tuning result: the same draws, so the same statistic
    conf = {c.id: c.confirmation for c in report.papers[0].criteria}
    assert conf["T"].ours == pytest.approx(np.mean(1.0 + generator(TUNE_SEED, "task-times-test", "tune")
                                                   .normal(size=TUNE_RUNS)))
    assert conf["A"].ours == pytest.approx(np.mean(5.0 + generator(CONFIRMATION_SEED, "task-times-test", "data")
                                                   .normal(size=RUNS)))
    first = {"data": "computed", "tune": "computed", "unread": "computed", "confirmation/data": "computed",
             "confirmation/tune": "reused"}
    summary = json.loads((tmp_path / "summary.json").read_text())
    _check_table(summary["papers"][0]["task_times"], first)
    outcome = json.loads((tmp_path / "papertt" / "outcome.json").read_text())
    rows = _check_table(outcome["task_times"], first)
    assert set(outcome["task_times"]["other_seconds"]) == {"figures and tables", "criteria"}
    # the time outside the tasks, per figure and table and by part (the suite saves PNG only: no SVG part)
    items = {i["what"]: i for i in outcome["task_times"]["items"]}
    assert {k: set(i["parts"]) for k, i in items.items()} == {"figure f1": {"data", "csv", "draw and png"},
                                                              "table t1": {"make and csv"}}
    assert all(i["seconds"] == pytest.approx(sum(i["parts"].values())) for i in items.values())
    # the page: the time table, collapsed, in the paper's section, one row per task with its share
    page = (tmp_path / "paper-tt.html").read_text()  # the paper's own page of the report
    block = re.search(r"<details id='papertt-tasks'>(.*?)</details>", page, re.S)
    assert block is not None and "Time per task: 5 tasks (4 computed, 1 reused)" in block.group(1)
    assert "<td>figure f1</td>" in block.group(1) and "<td>table t1</td>" in block.group(1)
    for name, r in rows.items():
        assert re.search(rf"<td>{re.escape(name)}</td><td class='num'>{r['runs'] if r['runs'] else '-'}</td>"
                         rf"<td class='num'>[^<]*</td><td class='num'>{r['share_percent']:.2f} %</td>"
                         rf"<td>{r['status']}</td>", block.group(1)), name
    # a second report into the folder: every task cached (or reused), 0 s, no share
    CALLS.clear()
    run_report(_host(), tmp_path, papers=["tt"], size="full", seed=3, progress=False)
    assert CALLS == []
    again = json.loads((tmp_path / "summary.json").read_text())["papers"][0]["task_times"]
    _check_table(again, {**{k: "cached" for k in first}, "confirmation/tune": "reused"})
    assert again["computed_seconds"] == 0.0 and again["counts"]["cached"] == 4
    assert set(again["counts"]) == set(TASK_STATUSES)


def test_an_unseeded_task_whose_parameters_follow_the_seed_runs_again(tmp_path):
    """The reuse needs the same parameters on both seeds: a declaration the parameters contradict is not trusted."""
    CALLS.clear()
    run_report(_host(lambda options: {"s": options.seed}), tmp_path, papers=["tt"], size="full", seed=3,
               progress=False)
    assert sorted(CALLS) == sorted([("data", 3), ("tune", 3), ("unread", 3), ("data", CONFIRMATION_SEED),
                                    ("tune", CONFIRMATION_SEED)])


def test_the_report_benchmark_ranks_the_report_tasks_by_share():
    from workbench_papers.report_bench import top_tasks

    summary = {"papers": [
        {"paper": "000", "tasks": [{"key": "a", "seconds": 6.0, "cached": False, "error": "", "runs": 20},
                                   {"key": "b", "seconds": 9.0, "cached": True, "error": ""}]},
        {"paper": "001", "tasks": [{"key": "c", "seconds": 3.0, "cached": False, "error": ""},
                                   {"key": "confirmation/c", "seconds": 1.0, "cached": False, "error": "",
                                    "reused": "the reported seed's result"},
                                   {"key": "d", "seconds": 1.0, "cached": False, "error": ""}]},
        {"paper": "002", "from_saved": True, "tasks": [{"key": "e", "seconds": 99.0, "cached": False, "error": ""}]},
    ]}
    got = top_tasks(summary, n=3)
    # 6 + 3 + 1 = 10 s spent by the tasks of the papers run now (a saved paper's are not this report's)
    assert got["task_seconds"] == 10.0 and got["tasks"] == 5
    assert got["top"] == {"1": "paper 000 a: 6.0 s, 60.00 % (runs 20, computed)",
                          "2": "paper 001 c: 3.0 s, 30.00 % (computed)",
                          "3": "paper 001 d: 1.0 s, 10.00 % (computed)"}


def test_the_papers_declare_only_their_fixed_seed_tuning_tasks_unseeded():
    """Paper 003's tuning tasks draw from TUNING_SEED alone (held seed-free by its own test,
    test_tuning_data_do_not_depend_on_the_report_seed); paper 000's calibration of its withheld values reads its tuning
    seed 101 alone; paper 002 has no such task (it tunes its restart delay inside its seeded tasks), so every other
    task stays seeded."""
    from workbench.specs import RecipeOptions
    from workbench_papers.paper003 import tasks as p003

    host = load_host()
    for paper in ("000", "001", "002", "003"):
        recipe = host.recipe(paper)
        options = RecipeOptions(size="full", values=dict(recipe.sizes["full"]), seed=0,
                                filters=tuple(recipe.default_filters))
        tasks = list(recipe.tasks(options))
        unseeded = {t.key for t in tasks if not t.seeded}
        expected = {t.key for t in tasks if t.key.startswith("tune/")} if paper == "003" else \
            {"calibration"} if paper == "000" else set()
        assert unseeded == expected, paper
        if paper == "000":  # the calibration of the withheld values reads its own tuning seed (issue 24 item 2)
            from workbench_papers.paper000 import tuning as p000

            assert all(t.params["seed"] == p000.CALIBRATION_SEED for t in tasks if t.key in unseeded)
            continue
        assert all(t.params["data_seed"] == p003.TUNING_SEED for t in tasks if t.key in unseeded)
    assert len(expected) > 0


def test_the_report_benchmark_reads_the_task_times_of_the_report_it_times(monkeypatch):
    """``bench`` reads the summary.json its child report wrote (a fake child here: a report of known task times)."""
    from workbench_papers import report_bench

    summary = {"papers": [{"paper": "900", "tasks": [{"key": "x", "seconds": 1.0, "cached": False, "error": ""},
                                                     {"key": "y", "seconds": 3.0, "cached": False, "error": "",
                                                      "runs": 5}]}]}
    fake = ("import sys, json, pathlib; out = sys.argv[sys.argv.index('--out') + 1]; "
            f"pathlib.Path(out, 'summary.json').write_text(json.dumps({summary!r})); print('paper 900: fake, 4 s')")
    monkeypatch.setattr(report_bench, "_MAIN", fake)
    out = report_bench.bench(quick=True)
    assert out["report_task_seconds"] == 4.0 and out["report_tasks"] == 2
    assert out["top_tasks_by_share"] == {"1": "paper 900 y: 3.0 s, 75.00 % (runs 5, computed)",
                                         "2": "paper 900 x: 1.0 s, 25.00 % (computed)"}
