"""The confirmation seed: the full report judges every criterion once more on a seed no tuning has seen.

A tiny fake recipe (registered in a test host) has a task its criteria read and one they do not; the expected
verdicts on each seed are computed here from the generator directly (brute force), never by the engine.
"""

import json

import numpy as np
import pytest

from workbench import hookimpl
from workbench.criteria import Confirmation, Criterion, confirm, criterion_from_runs
from workbench.plugins import load_host
from workbench.report.engine import CONFIRMATION_SEED, CONFIRMATION_SPAN, check_report_seed, run_report
from workbench.rng import generator
from workbench.specs import RecipeSpec, Task
from workbench.types import InputError

RUNS = 60
#: every task run: (task key, seed), to check which tasks the confirmation reran
CALLS: list = []


def _draws(seed: int) -> np.ndarray:
    return generator(seed, "confirmation-test", "data").normal(size=RUNS)


def _data_task(ctx):
    CALLS.append(("data", ctx.seed))
    return {"x": 5.0 + _draws(ctx.seed)}


def _unread_task(ctx):
    CALLS.append(("unread", ctx.seed))
    return {"y": np.arange(3.0)}


def _criteria(results):
    x = np.asarray(results["data"]["x"])
    return [
        # holds on any seed: the mean of N(5, 1) over 60 runs is far above 0
        criterion_from_runs("A", "mean above 0", x, np.mean, 0.0, ">=", min_n=10),
        # the sign of the first draw: a verdict that changes with the data
        Criterion("B", "first draw above 5", "met" if x[0] > 5.0 else "not met", ours=float(x[0])),
    ]


RECIPE = RecipeSpec("cf", "confirmation test", {"quick": {}, "full": {}},
                    lambda options: [Task("data", {}, _data_task), Task("unread", {}, _unread_task)],
                    criteria=_criteria)


class _Plugin:
    @hookimpl
    def workbench_report_recipes(self):
        return [RECIPE]


def _host():
    return load_host(entry_points=[], extra_plugins=[("cf", _Plugin())])


def _seed_with_other_sign() -> int:
    """A report seed whose first draw lies on the other side of 0 than the confirmation seed's (brute force)."""
    target = _draws(CONFIRMATION_SEED)[0] > 0
    return next(s for s in range(200) if (_draws(s)[0] > 0) != target)


def _seed_with_same_sign() -> int:
    target = _draws(CONFIRMATION_SEED)[0] > 0
    return next(s for s in range(200) if (_draws(s)[0] > 0) == target)


def test_full_report_judges_again_on_the_confirmation_seed_and_shows_agreement(tmp_path):
    seed = _seed_with_other_sign()
    CALLS.clear()
    report = run_report(_host(), tmp_path, papers=["cf"], size="full", seed=seed, progress=False)
    # only the task the criteria read was rerun, with the confirmation seed
    assert sorted(CALLS) == sorted([("data", seed), ("unread", seed), ("data", CONFIRMATION_SEED)])
    crit = {c.id: c for c in report.papers[0].criteria}
    a, b = crit["A"].confirmation, crit["B"].confirmation
    assert a.seed == b.seed == CONFIRMATION_SEED
    assert crit["A"].verdict == "met" and a.verdict == "met" and a.agrees
    # B: the verdicts on each seed from the draws themselves
    expected = {s: "met" if _draws(s)[0] > 0 else "not met" for s in (seed, CONFIRMATION_SEED)}
    assert crit["B"].verdict == expected[seed] and b.verdict == expected[CONFIRMATION_SEED]
    assert b.agrees is False and b.primary == expected[seed]
    assert b.ours == pytest.approx(5.0 + _draws(CONFIRMATION_SEED)[0])
    assert a.ours == pytest.approx(np.mean(5.0 + _draws(CONFIRMATION_SEED)))
    page = (tmp_path / "paper-cf.html").read_text()  # the paper's page: its scoreboard
    assert "confirmation" in page and "DIFFERS" in page and "agrees" in page
    assert f"seed {CONFIRMATION_SEED}: 1 of 2 agree" in (tmp_path / "index.html").read_text()  # at a glance
    summary = json.loads((tmp_path / "summary.json").read_text())
    got = {c["id"]: c["confirmation"] for c in summary["papers"][0]["criteria"]}
    assert got["A"]["agrees"] is True and got["B"]["agrees"] is False
    assert got["B"]["verdict"] == expected[CONFIRMATION_SEED]
    # the saved outcome keeps the confirmation (a later report of another paper shows it unchanged)
    saved = json.loads((tmp_path / "papercf" / "outcome.json").read_text())
    assert saved["confirmation_seed"] == CONFIRMATION_SEED
    assert Criterion.from_dict(saved["criteria"][1]).confirmation == b
    # a second full report reuses the cached confirmation task
    CALLS.clear()
    run_report(_host(), tmp_path, papers=["cf"], size="full", seed=seed, progress=False)
    assert CALLS == []


def test_every_verdict_agrees_where_the_seeds_give_the_same_data_sign(tmp_path):
    seed = _seed_with_same_sign()
    report = run_report(_host(), tmp_path, papers=["cf"], size="full", seed=seed, progress=False)
    assert all(c.confirmation.agrees for c in report.papers[0].criteria)
    assert f"seed {CONFIRMATION_SEED}: 2 of 2 agree" in (tmp_path / "index.html").read_text()


def test_quick_report_runs_no_confirmation(tmp_path):
    CALLS.clear()
    report = run_report(_host(), tmp_path, papers=["cf"], size="quick", seed=1, progress=False)
    assert all(seed == 1 for _, seed in CALLS)
    assert all(c.confirmation is None for c in report.papers[0].criteria)
    assert "off (quick run)" in (tmp_path / "index.html").read_text()


def test_a_report_seed_near_the_confirmation_seed_is_refused(tmp_path):
    for seed in (CONFIRMATION_SEED, CONFIRMATION_SEED - 3, CONFIRMATION_SEED + CONFIRMATION_SPAN - 1):
        with pytest.raises(InputError, match="confirmation seed"):
            run_report(_host(), tmp_path, papers=["cf"], size="full", seed=seed, progress=False)
    check_report_seed(CONFIRMATION_SEED + CONFIRMATION_SPAN)  # far enough
    with pytest.raises(InputError, match="integer >= 0"):
        check_report_seed(-1)


def test_confirmation_seed_differs_from_every_seed_the_recipes_tune_on():
    from workbench_papers.paper000 import tuning as p000
    from workbench_papers.paper001 import scenario as p001
    from workbench_papers.paper002 import scenario as p002
    from workbench_papers.paper003 import tasks as p003

    tuning = [*p000.TUNING_SEEDS, p002.TUNING_SEED, p003.TUNING_SEED, p001.SURROGATE_SEED]
    # recipes derive seed + j (seed blocks, replications): no tuning seed, nor the default report seed 0, is near
    for s in [*tuning, 0]:
        assert abs(s - CONFIRMATION_SEED) >= CONFIRMATION_SPAN, s
    # paper 001 tunes on its own stream of the report's seed, never a reported stream
    assert p001.TUNING_STREAM not in ("sim", "surrogate", "timing", "hough-demo")


def test_confirm_pairs_by_id_and_names_a_missing_verdict():
    met = Criterion("1", "t", "met")
    out = confirm([met, Criterion("2", "t", "not met")], [Criterion("1", "t", "inconclusive")], 9)
    assert out[0].confirmation.verdict == "inconclusive" and out[0].confirmation.agrees is False
    assert out[0].verdict == "met"  # the reported verdict is unchanged
    assert out[1].confirmation.verdict is None and "no criterion '2'" in out[1].confirmation.detail
    with pytest.raises(ValueError, match="say why"):
        Confirmation(9, None, "met")
    assert out[0].as_indicative().confirmation.verdict == "inconclusive"
