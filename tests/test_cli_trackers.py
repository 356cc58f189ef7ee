"""``--trackers`` on the command line: ``workbench report`` hands the trackers to every recipe that compares
trackers (``RecipeSpec.default_trackers`` -> ``RecipeOptions.trackers``) with the rules of ``--filters``, refuses
it for a paper that compares none, and ``workbench run`` applies it to a scenario's ``[trackers]``; an unknown
tracker is one line naming it and the installed ones (exit 2)."""

import json

import numpy as np
import pytest

import workbench.cli as cli
from fixtures import demo_plugin
from workbench import hookimpl
from workbench.cli import main
from workbench.plugins import load_host
from workbench.report.engine import tracker_papers
from workbench.rng import generator
from workbench.specs import RecipeSpec, Table, TableSpec, Task
from workbench.types import InputError, Scans

#: What the tracker recipe's tasks saw: (tracker label, its configured prune where it has one), one per task run
SEEN: list[tuple[str, float | None]] = []
#: The RecipeOptions.trackers each call of the recipe's tasks() got
OPTIONS: list[tuple[str, ...]] = []


def _scene(runs: int, steps: int) -> Scans:
    rng = generator(3, "cli trackers scene")
    k = np.arange(float(steps))[:, None]
    truth = np.stack([k * [4.0, 1.0], [0.0, 20.0] + k * [4.0, -1.0]]).transpose(1, 0, 2)  # (T, 2, 2)
    z = truth[None] + 0.5 * rng.standard_normal((runs, steps, 2, 2))
    return Scans(z, np.ones((runs, steps, 2), bool), np.arange(float(steps)))


def _run_tracker(ctx):
    from workbench.models import constant_velocity

    name = ctx.params["tracker"]
    spec = ctx.host.tracker(name)
    SEEN.append((name, spec.params.get("prune")))
    model = ctx.host.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=0.5)
    log = spec.run(_scene(ctx.params["runs"], ctx.params["steps"]), ctx.host.filter("kf"),
                   constant_velocity(2, 1.0, 0.1), model, seed=ctx.seed)
    return {"rows": np.array(log.mean.shape[0]), "tracker": np.array(name)}


def _tasks(options):
    OPTIONS.append(tuple(options.trackers))
    v = options.values
    return [Task(f"track/{name}", {"tracker": name, "runs": v["runs"], "steps": v["steps"]}, _run_tracker)
            for name in options.trackers]


def _table(results):
    return Table(("tracker", "rows"), tuple((str(r["tracker"]), int(r["rows"])) for r in results.values()))


RECIPE = RecipeSpec(paper="t01", title="Trackers compared (test fixture)",
                    sizes={"quick": {"runs": 2, "steps": 6}, "full": {"runs": 2, "steps": 6}}, tasks=_tasks,
                    tables=(TableSpec("rows", "rows per tracker", _table),), default_trackers=("mofn",))


class TrackerPaper:
    @hookimpl
    def workbench_report_recipes(self):
        return [RECIPE]


@pytest.fixture
def host(monkeypatch):
    """The installed plugins, the demo recipe (which compares no trackers) and the tracker recipe ``t01``, as the
    command line's host."""
    made = load_host(extra_plugins=[("demo", demo_plugin), ("trackerpaper", TrackerPaper())])
    monkeypatch.setattr(cli, "load_host", lambda block=(): made)
    SEEN.clear()
    OPTIONS.clear()
    return made


def _report(tmp_path, *args):
    return main(["report", "--quick", "--paper", "t01", "--out", str(tmp_path / "r"), "--no-progress", *args])


def test_report_trackers_adds_to_the_recipe_s_defaults(host, tmp_path, capsys):
    assert _report(tmp_path, "--trackers", "+gm-phd") == 0
    assert OPTIONS == [("mofn", "gm-phd")]
    assert sorted(name for name, _ in SEEN) == ["gm-phd", "mofn"]
    rows = json.loads((tmp_path / "r" / "summary.json").read_text())["papers"][0]["tables"][0]["rows"]
    assert sorted(r[0] for r in rows) == ["gm-phd", "mofn"]


def test_report_trackers_with_values_reach_the_tracker_configured(host, tmp_path):
    assert _report(tmp_path, "--trackers", "+gm-phd(prune=1e-4)") == 0
    assert OPTIONS == [("mofn", "gm-phd(prune=1e-4)")]
    assert ("gm-phd(prune=1e-4)", 1e-4) in SEEN
    # its own default, however spelled, is the same tracker: added once
    OPTIONS.clear()
    assert _report(tmp_path, "--trackers", "+gm-phd(prune=1e-5),+gm-phd") == 2


def test_report_trackers_replace_and_remove(host, tmp_path):
    assert _report(tmp_path, "--trackers", "gnn,gm-phd") == 0
    assert OPTIONS[-1] == ("gnn", "gm-phd")
    # '-name' right after the option (argparse would read it as an option otherwise)
    assert _report(tmp_path, "--trackers", "-mofn,+gnn") == 0
    assert OPTIONS[-1] == ("gnn",)


@pytest.mark.parametrize("request_, message", [
    ("+nope", r"--trackers 'nope': no tracker named 'nope' is installed \(installed: [^)]*gm-phd[^)]*gnn[^)]*mofn"),
    ("~gnn", r"--trackers: cannot remove 'gnn': it is not among mofn"),
    ("-mofn", r"--trackers '-mofn' leaves no tracker to compare"),
    ("+gm-phd(prune=2)", r"--trackers 'gm-phd\(prune=2\)': tracker 'gm-phd': prune: must be <= 1"),
    ("+gm-phd(bogus=1)", r"--trackers 'gm-phd\(bogus=1\)'.*bogus"),
    ("+kf", r"--trackers 'kf': 'kf' is a filter, not a tracker"),
    ("+gnn,gnn", r"--trackers: the same tracker is listed twice"),
    (",", r"--trackers: expected a non-empty list of trackers"),
])
def test_report_trackers_mistakes_are_one_line_exit_2_before_anything_runs(host, tmp_path, capsys, request_,
                                                                          message):
    assert _report(tmp_path, "--trackers", request_) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if "warning" not in ln]
    assert len(err) == 1 and err[0].startswith("workbench: error: "), err
    assert __import__("re").search(message, err[0]), err[0]
    assert OPTIONS == [] and SEEN == []


def test_report_trackers_for_a_paper_that_compares_none_is_refused_by_name(host, tmp_path, capsys):
    code = main(["report", "--quick", "--paper", "t01", "--paper", "demo", "--out", str(tmp_path / "r"), "--no-progress",
                 "--trackers", "+gm-phd"])
    err = capsys.readouterr().err
    assert code == 2
    assert "workbench: error: --trackers '+gm-phd': paper demo compares no installed multi-target trackers" in err
    assert "papers that take --trackers: t01" in err
    assert OPTIONS == [] and not (tmp_path / "r" / "paperdemo").exists()


def test_without_paper_the_trackers_go_to_the_papers_that_compare_trackers(host):
    demo, t01 = host.recipe("demo"), host.recipe("t01")
    assert tracker_papers([demo, t01], "+gm-phd", host, named=False) == {"demo": None, "t01": "+gm-phd"}
    assert tracker_papers([demo, t01], None, host, named=False) == {"demo": None, "t01": None}
    with pytest.raises(InputError, match=r"paper demo compares no installed multi-target trackers"):
        tracker_papers([demo], "+gm-phd", host, named=False)
    with pytest.raises(InputError, match=r"no tracker named 'nope'"):  # the request's own mistakes first
        tracker_papers([demo, t01], "+nope", host, named=False)


# -- workbench run ----------------------------------------------------------------------------------------------

MULTI = """
[scenario]
name = "two"
seed = 3
runs = 2
steps = 8
dt = "1 s"

[motion]
model = "constant_velocity"
dims = 2
sigma_a = "0.05 m/s^2"

[[targets]]
label = "A"
initial_state = [0.0, 0.0, 4.0, 1.0]

[[targets]]
label = "B"
initial_state = [0.0, 60.0, 4.0, -1.0]

[sensor]
plugin = "active-sonar"
pd = 0.95
sigma_pos = "0.5 m"

[filters]
names = ["kf"]

[trackers]
names = ["gnn"]
"""


def test_run_trackers_applies_to_the_scenario_s_trackers(host, tmp_path, capsys):
    path = tmp_path / "two.toml"
    path.write_text(MULTI)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--trackers", "+gm-phd(birth_rate=0.2)"]) == 0
    summary = capsys.readouterr().out
    assert "gnn/kf" in summary and "gm-phd(birth_rate=0.2)/kf" in summary
    assert main(["run", str(path), "--out", str(tmp_path / "out2"), "--trackers", "-gnn,+mofn"]) == 0
    summary = capsys.readouterr().out
    assert "mofn/kf" in summary and "gnn/kf" not in summary


def test_run_trackers_mistakes_and_a_scenario_without_trackers(host, tmp_path, capsys):
    path = tmp_path / "two.toml"
    path.write_text(MULTI)
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--trackers", "+nope"]) == 2
    assert "workbench: error: --trackers 'nope': no tracker named 'nope' is installed" in capsys.readouterr().err
    single = tmp_path / "one.toml"
    single.write_text("""
[scenario]
name = "one"
runs = 2
steps = 5
dt = "1 s"

[motion]
model = "constant_velocity"
dims = 2
sigma_a = "0.05 m/s^2"

[truth]
initial_state = [0.0, 0.0, 1.0, 1.0]

[sensor]
plugin = "active-sonar"

[prior]
mean = [0.0, 0.0, 1.0, 1.0]
std = [1.0, 1.0, 1.0, 1.0]

[filters]
names = ["kf"]
""")
    assert main(["run", str(single), "--out", str(tmp_path / "o1"), "--trackers", "+gm-phd"]) == 2
    err = capsys.readouterr().err
    assert f"--trackers '+gm-phd': scenario {single} runs no installed multi-target trackers" in err
    assert not (tmp_path / "o1").exists()
    # the request's own mistake is named first, whatever the scenario
    assert main(["run", str(single), "--out", str(tmp_path / "o1"), "--trackers", "+nope"]) == 2
    assert "--trackers 'nope': no tracker named 'nope' is installed" in capsys.readouterr().err
