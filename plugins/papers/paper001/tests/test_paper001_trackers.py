"""Paper 001's tracker comparison (issue 25 item 4): the paper's M-of-N rows beside the GNN, JIPDA and GM-PHD
extension rows on the same runs, before and after the Hough remover.  The table's and the figure's GOSPA and counts
are recomputed here from the saved confirmed tracks and the truth by hand-written references (GOSPA of one target
in closed form; true and false tracks by their definition), and ``--trackers`` adds and removes rows end to end."""

import json
from dataclasses import replace

import numpy as np
import pytest

import workbench.cli as cli
from workbench import hookimpl
from workbench.cli import main
from workbench.plugins import load_host
from workbench.report.engine import resolve_trackers
from workbench.specs import RecipeOptions, TaskContext, TrackerSpec
from workbench.tracking import CONFIRMED, TrackLog
from workbench_papers.paper001 import recipe as paper_recipe
from workbench_papers.paper001 import scenario
from workbench_papers.paper001 import tasks as paper_tasks


def _echo(scans, filt, motion, model, *, seed=0, key=(), **params):
    """A tiny tracker for the test: every valid detection is a confirmed track for its one ping."""
    run, ping, slot = np.nonzero(scans.valid)
    mean = np.concatenate([scans.z[run, ping, slot], np.zeros((run.size, 2))], axis=1)
    return TrackLog(run, ping, np.arange(run.size), np.full(run.size, CONFIRMED), np.ones(run.size, bool), mean,
                    scans.batch, scans.steps)


class EchoTracker:
    @hookimpl
    def workbench_trackers(self):
        return [TrackerSpec("echo", "every detection a track (test)", _echo)]


HOST = load_host(extra_plugins=[("echo", EchoTracker())])
#: runs of the comparison below (the quick size has 10; the checks recompute from these runs whatever their count)
RUNS = 3
C, P = scenario.GOSPA_C, scenario.GOSPA_P
POST = np.arange(scenario.PINGS) >= 5  # the pings after the Hough warm-up (pings 6-20)


@pytest.fixture(scope="module")
def compared():
    """The simulation block (the paper's rows) and the trackers block of the default trackers and ``echo`` on
    ``RUNS`` runs."""
    recipe = HOST.recipe("001")
    options = RecipeOptions(size="test", values={**recipe.sizes["quick"], "runs": RUNS}, seed=2,
                            filters=recipe.default_filters, trackers=recipe.default_trackers + ("echo",))
    results = {}
    for task in recipe.tasks(options):
        if task.key in ("sim/0", "trackers/0"):
            out = task.run(TaskContext(params=task.params, seed=2, host=HOST))
            results[task.key] = {k: np.asarray(v) for k, v in out.items()}
    return recipe, results


def _saved_log(results, ref, phase) -> TrackLog:
    return TrackLog.from_arrays(results["trackers/0"], f"tracker:{ref}/{phase}/log/")


def _gospa_one_target(log: TrackLog, truth: np.ndarray) -> np.ndarray:
    """GOSPA (alpha 2) of the confirmed tracks against one target, every (run, ping), written out: with ``m``
    estimates the best assignment gives the target its nearest estimate, so ``d^p = min(d_min, c)^p + (m - 1)
    c^p / 2`` (``m >= 1``; a nearest estimate beyond ``c`` costs a miss and a false one, ``c^p``), and ``c^p / 2``
    (one miss) for ``m = 0``."""
    out = np.empty(truth.shape[:2])
    for b in range(truth.shape[0]):
        for k in range(truth.shape[1]):
            sel = (log.run == b) & (log.ping == k) & (log.status == CONFIRMED)
            m = int(sel.sum())
            if m == 0:
                out[b, k] = (C ** P / 2) ** (1 / P)
                continue
            d = min(np.sqrt(((log.mean[sel, :2] - truth[b, k]) ** 2).sum(axis=1)).min(), C)
            out[b, k] = (d ** P + (m - 1) * C ** P / 2) ** (1 / P)
    return out


def _counts_by_definition(log: TrackLog, truth: np.ndarray):
    """False tracks and whether the target is held, every (run, ping), from the definitions: a confirmed track is
    true when it is within 6 units of the truth at >= 80 % of its confirmed pings; false tracks are the other
    confirmed tracks; the target is held where a true track is confirmed."""
    false = np.zeros(truth.shape[:2], int)
    held = np.zeros(truth.shape[:2], bool)
    for run, tid in sorted({(int(r), int(t)) for r, t in zip(log.run, log.track_id)}):
        rows = np.flatnonzero((log.run == run) & (log.track_id == tid) & (log.status == CONFIRMED))
        near = [np.hypot(*(log.mean[i, :2] - truth[run, log.ping[i]])) <= scenario.TRUE_RADIUS for i in rows]
        true = np.mean(near) >= scenario.TRUE_FRACTION
        for i in rows:
            if true:
                held[run, log.ping[i]] = True
            else:
                false[run, log.ping[i]] += 1
    return false, held


def _table(recipe, results, table_id="trackers"):
    return next(t for t in recipe.tables if t.id == table_id).make(results)


def test_the_trackers_table_is_gospa_and_counts_of_the_saved_tracks(compared):
    recipe, results = compared
    table = _table(recipe, results)
    rows = {(r[0], r[3]): r for r in table.rows}
    truth = scenario.target_truth(RUNS).states[..., :2]
    for ref in ("gnn", "jipda", "gm-phd", "echo"):
        for phase in ("before", "after"):
            log = _saved_log(results, ref, phase)
            assert log.runs == RUNS and log.pings == scenario.PINGS
            assert ref == "echo" or log.cov.shape == (log.run.size, 4, 4)
            g = _gospa_one_target(log, truth)
            np.testing.assert_allclose(results["trackers/0"][f"tracker:{ref}/{phase}/gospa"], g, rtol=1e-12,
                                       atol=1e-12)
            false, held = _counts_by_definition(log, truth)
            row = rows[(ref, phase)]
            assert row[2].startswith("EXTENSION") and row[9] == RUNS
            assert row[4].startswith(f"{g[:, POST].mean(axis=1).mean():.2f} [")
            assert row[5].startswith(f"{false[:, POST].mean(axis=1).mean():.2f}")
            assert row[6].startswith(f"{100 * held[:, POST].mean(axis=1).mean():.1f} %")
            if phase == "after":  # removal rate: 1 - sum F_after / sum F_before over the runs and pings 6-20
                before, _ = _counts_by_definition(_saved_log(results, ref, "before"), truth)
                if before[:, POST].sum():
                    assert row[8].startswith(f"{100 * (1 - false[:, POST].sum() / before[:, POST].sum()):.1f} %")
    # the paper's M-of-N rows are its judged and stated-accuracy arms, read from the simulation block
    sim = results["sim/0"]
    for arm, label in (("paper", scenario.ARM_LABELS["paper"]), ("stated", scenario.ARM_LABELS["stated"])):
        for phase in ("before", "after"):
            row = next(r for r in table.rows if r[0] == "mofn" and r[3] == phase and label in r[1])
            assert row[2].startswith("paper's method")
            assert row[4].startswith(f"{sim[f'{arm}/{phase}/gospa'][:, POST].mean(axis=1).mean():.2f}")
    assert [r[0] for r in table.rows] == ["mofn"] * 4 + ["gnn"] * 2 + ["jipda"] * 2 + ["gm-phd"] * 2 + ["echo"] * 2


def test_the_trackers_figure_has_every_tracker_before_and_after(compared):
    recipe, results = compared
    fig = next(f for f in recipe.figures if f.id == "gospa-trackers").data(results)
    assert fig["rows"].tolist() == ["mofn (paper rows)", "mofn (stated R)", "gnn", "jipda", "gm-phd", "echo"]
    truth = scenario.target_truth(RUNS).states[..., :2]
    for i, ref in enumerate(fig["rows"].tolist()):
        for phase in ("before", "after"):
            if ref.startswith("mofn"):
                arm = "paper" if "paper" in ref else "stated"
                expected = results["sim/0"][f"{arm}/{phase}/gospa"].mean(axis=0)
            else:
                expected = _gospa_one_target(_saved_log(results, ref, phase), truth).mean(axis=0)
            np.testing.assert_allclose(fig[f"gospa_{phase}"][i], expected, rtol=1e-12, atol=1e-12)
    # the paper rows here are those of the paper's own GOSPA figure; nothing is confirmed during the warm-up after
    # removal: every tracker misses the target there, one miss being c / sqrt 2
    own = next(f for f in recipe.figures if f.id == "gospa-per-ping").data(results)
    np.testing.assert_allclose(fig["gospa_before"][0], own["gospa_before"])
    np.testing.assert_allclose(fig["gospa_after"][:, :5], C / np.sqrt(2.0), rtol=1e-12)


def test_the_extension_rows_see_the_paper_rows_detections(compared):
    """Common random numbers: ``echo`` makes every detection a confirmed track, so its tracks per ping after removal
    are the detections the remover kept in the trackers block; they are those the simulation block's paper rows
    were tracked on (its detections per ping after removal, mean over runs), and before removal every detection."""
    recipe, results = compared
    per_ping = {}
    for phase in ("before", "after"):
        log = _saved_log(results, "echo", phase)
        per_ping[phase] = np.bincount(log.ping, minlength=scenario.PINGS) / RUNS
    np.testing.assert_allclose(per_ping["after"], results["sim/0"]["detections_per_ping"], rtol=1e-12)
    assert np.all(per_ping["after"][:5] == 0)  # the warm-up keeps nothing
    scans = scenario.simulate_scans(HOST, 2, "sim", RUNS)  # the report's seed, block 0
    np.testing.assert_allclose(per_ping["before"], scans.valid.sum(axis=2).mean(axis=0), rtol=1e-12)
    params = next(t.params for t in recipe.tasks(RecipeOptions("test", {**recipe.sizes["quick"], "runs": RUNS}, 2,
                                                               recipe.default_filters, trackers=("gnn",)))
                  if t.key == "trackers/0")
    assert params["filter"] == "kf" and params["model"] == {"frame": "cartesian"} and params["trackers"] == ["gnn"]


# -- --trackers end to end -------------------------------------------------------------------------------------------


class SmallPaper001:
    """Paper 001 cut down to its simulation and trackers tasks on 2 runs, and the tracker table and figure."""

    @hookimpl
    def workbench_report_recipes(self):
        r = paper_recipe.RECIPE
        small = {"quick": {**r.sizes["quick"], "runs": 2}, "full": {**r.sizes["quick"], "runs": 2}}
        return [replace(r, sizes=small, criteria=None,
                        tasks=lambda o: [t for t in paper_tasks.tasks(o) if t.key in ("sim/0", "trackers/0")],
                        tables=tuple(t for t in r.tables if t.id == "trackers"),
                        figures=tuple(f for f in r.figures if f.id == "gospa-trackers"))]


def _boom(scans, filt, motion, model, *, seed=0, key=(), **params):
    raise RuntimeError("boom at the first scan")


class BoomTracker:
    @hookimpl
    def workbench_trackers(self):
        return [TrackerSpec("boom", "always raises (test)", _boom)]


def test_a_tracker_that_raises_loses_its_own_rows_only():
    host = load_host(extra_plugins=[("echo", EchoTracker()), ("boom", BoomTracker())])
    options = RecipeOptions("test", {**scenario.SIZES["quick"], "runs": 1}, 2, ("cmkf-l",), trackers=("boom", "echo"))
    task = next(t for t in paper_tasks.tasks(options) if t.key == "trackers/0")
    results = {"trackers/0": task.run(TaskContext(params=task.params, seed=2, host=host))}
    assert str(results["trackers/0"]["error/tracker:boom"]) == "RuntimeError: boom at the first scan"
    rows = _table(host.recipe("001"), results).rows
    assert [(r[0], r[3]) for r in rows] == [("echo", "before"), ("echo", "after"), ("boom", "")]
    assert rows[2][1] == "FAILED, no rows: trackers/0: RuntimeError: boom at the first scan"


@pytest.mark.slow
def test_trackers_option_adds_an_installed_tracker_and_removes_a_default_one(monkeypatch, tmp_path):
    host = load_host(block=("paper001",), extra_plugins=[("small001", SmallPaper001()), ("echo", EchoTracker())])
    monkeypatch.setattr(cli, "load_host", lambda block=(): host)
    # -gnn alone: the trackers block runs the others
    chosen = resolve_trackers(scenario.DEFAULT_TRACKERS, "-gnn", host)
    assert chosen == ("mofn", "jipda", "gm-phd")
    out = tmp_path / "r"
    assert main(["report", "--paper", "001", "--quick", "--out", str(out), "--no-progress",
                 "--trackers", "+echo,-gnn"]) == 0
    paper = json.loads((out / "summary.json").read_text())["papers"][0]
    assert not paper["errors"]
    rows = next(t for t in paper["tables"] if t["id"] == "trackers")["rows"]
    assert [(r[0], r[3]) for r in rows] == [("mofn", "before"), ("mofn", "after")] * 2 + [
        ("jipda", "before"), ("jipda", "after"), ("gm-phd", "before"), ("gm-phd", "after"), ("echo", "before"),
        ("echo", "after")]
    echo = {r[3]: r for r in rows if r[0] == "echo"}
    assert echo["before"][2].startswith("EXTENSION") and echo["before"][9] == 2
    # every detection a track: its false tracks per ping are the clutter detections per ping (and the target's)
    assert float(echo["before"][5].split()[0]) > 20 > float(echo["after"][5].split()[0])
    data = np.load(out / "paper001" / "gospa-trackers.npz")
    assert data["rows"].tolist() == ["mofn (paper rows)", "mofn (stated R)", "jipda", "gm-phd", "echo"]
