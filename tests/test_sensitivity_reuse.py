"""The confirmation seed judges the primary values only: a task declared ``sensitivity=True`` (a non-primary grid
value of a declared unknown) is not run again on it.

A tiny fake recipe (registered in a test host, as in tests/test_task_times.py) declares an unknown ``shift`` with
primary 0 and grid {0, 2}; its criterion's verdict at the primary reads the task ``data`` and its ``across`` also
reads ``data@2`` (the same draws shifted by 2, declared a sensitivity point).  The expected statistics are the
draws' means, computed here from the same generator streams (closed forms of the fake tasks).
"""

import json
from dataclasses import replace

import numpy as np
import pytest

from workbench import hookimpl
from workbench.criteria import DeclaredUnknown, criterion_from_runs, judge_across
from workbench.plugins import load_host
from workbench.report.engine import CONFIRMATION_SEED, run_report
from workbench.rng import generator
from workbench.specs import RecipeSpec, Task
from workbench.types import InputError

RUNS = 40
SHIFT = DeclaredUnknown("shift", "", 0.0, (0.0, 2.0), "a test unknown: the primary 0, a sensitivity point at 2")
CALLS: list = []


def _draws(seed):
    return generator(seed, "sensitivity-test", "data").normal(size=RUNS)


def _data_task(ctx):
    CALLS.append((ctx.params["shift"], ctx.seed))
    return {"x": 0.5 + float(ctx.params["shift"]) + _draws(ctx.seed)}


def _judge(x):
    return criterion_from_runs("A", "mean above 0", np.asarray(x), np.mean, 0.0, ">=", min_n=10)


def _criteria(results):
    primary = _judge(results["data"]["x"])
    across = judge_across(SHIFT, {0.0: primary, 2.0: _judge(results["data@2"]["x"])})
    return [replace(primary, across=across)]


def _tasks(options, mark=True):
    return [Task("data", {"shift": 0.0}, _data_task, runs=RUNS),
            Task("data@2", {"shift": 2.0}, _data_task, runs=RUNS, sensitivity=mark)]


def _host(mark=True):
    recipe = RecipeSpec("st", "sensitivity reuse test", {"quick": {}, "full": {}},
                        lambda options: _tasks(options, mark), criteria=_criteria, unknowns=(SHIFT,))

    class _Plugin:
        @hookimpl
        def workbench_report_recipes(self):
            return [recipe]

    return load_host(entry_points=[], extra_plugins=[("st", _Plugin())])


def test_a_sensitivity_task_runs_once_and_the_confirmation_judges_the_primary_on_its_own_seed(tmp_path):
    CALLS.clear()
    report = run_report(_host(), tmp_path, papers=["st"], size="full", seed=7, progress=False)
    # the primary task ran on both seeds, the sensitivity point on the reported seed only
    assert sorted(CALLS) == sorted([(0.0, 7), (2.0, 7), (0.0, CONFIRMATION_SEED)])
    (crit,) = report.papers[0].criteria
    assert crit.ours == pytest.approx(np.mean(0.5 + _draws(7)))
    assert [a.ours for a in crit.across] == pytest.approx([np.mean(0.5 + _draws(7)), np.mean(2.5 + _draws(7))])
    assert crit.confirmation.ours == pytest.approx(np.mean(0.5 + _draws(CONFIRMATION_SEED)))
    rows = {r["task"]: r for r in json.loads((tmp_path / "paperst" / "outcome.json").read_text())
            ["task_times"]["rows"]}
    assert rows["confirmation/data@2"]["status"] == "reused" and rows["confirmation/data@2"]["seconds"] == 0.0
    assert rows["confirmation/data"]["status"] == "computed"
    entries = {e["key"]: e for e in report.papers[0].tasks}
    assert "sensitivity point" in entries["confirmation/data@2"]["reused"]


def test_an_undeclared_grid_task_runs_again_on_the_confirmation_seed(tmp_path):
    CALLS.clear()
    run_report(_host(mark=False), tmp_path, papers=["st"], size="full", seed=7, progress=False)
    assert sorted(CALLS) == sorted([(0.0, 7), (2.0, 7), (0.0, CONFIRMATION_SEED), (2.0, CONFIRMATION_SEED)])


def test_sensitivity_is_declared_true_or_false():
    with pytest.raises(InputError, match="task 'k': sensitivity"):
        Task("k", {}, _data_task, sensitivity="yes")
    assert Task("k", {}, _data_task).sensitivity is False
