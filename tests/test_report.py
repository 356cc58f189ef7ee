"""Report engine: outputs, figure data, caching and resuming after an interruption."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from workbench.report.cache import load_arrays
from workbench.report.engine import resolve_filters, run_report
from workbench.plugins import UnknownComponent

TESTS = Path(__file__).parent


def test_report_writes_index_figures_data_and_tables(tmp_path, demo_host):
    report = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False, command="workbench report")
    paper = report.papers[0]
    assert not paper.errors
    index = (tmp_path / "index.html").read_text()
    for section in ("Paper demo", "Reproduced if", "table1", "fig1", "Provenance", "seed", "package numpy",
                    "published", "workbench report"):
        assert section in index
    assert "data:image/png;base64," in index
    for ext in ("png", "svg", "npz", "csv"):
        assert (tmp_path / "paperdemo" / f"fig1.{ext}").stat().st_size > 0
    data = load_arrays(tmp_path / "paperdemo" / "fig1.npz")
    assert data["mse"].shape == (2, 15) and list(data["filters"]) == ["ekf", "kf"]
    # KF and EKF are the same filter on a linear model: identical curves behind the figure.
    np.testing.assert_allclose(data["mse"][0], data["mse"][1], rtol=1e-9)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["papers"][0]["criteria"][0]["met"] is True
    assert summary["papers"][0]["tables"][0]["columns"][2].startswith("published")


def test_second_run_reuses_cache_and_a_changed_filter_set_recomputes_only_the_new_task(tmp_path, demo_host):
    run_report(demo_host, tmp_path, papers=["demo"], progress=False)
    again = run_report(demo_host, tmp_path, papers=["demo"], progress=False)
    assert all(t["cached"] for t in again.papers[0].tasks)
    more = run_report(demo_host, tmp_path, papers=["demo"], filters="+sir", progress=False)
    status = {t["key"]: t["cached"] for t in more.papers[0].tasks}
    assert status == {"mse-kf": True, "mse-ekf": True, "mse-sir": False}
    other_seed = run_report(demo_host, tmp_path, papers=["demo"], seed=9, progress=False)
    assert not any(t["cached"] for t in other_seed.papers[0].tasks)


def test_resolve_filters(demo_host):
    assert resolve_filters(("kf", "ekf"), None, demo_host) == ("kf", "ekf")
    assert resolve_filters(("kf", "ekf"), "+sir,-ekf", demo_host) == ("kf", "sir")
    assert resolve_filters(("kf", "ekf"), "sir", demo_host) == ("sir",)
    with pytest.raises(UnknownComponent, match="no filter named 'nope'"):
        resolve_filters(("kf",), "+nope", demo_host)


def test_failed_task_is_reported_and_the_rest_kept(tmp_path, demo_host):
    from fixtures import demo_plugin

    def boom(ctx):
        raise RuntimeError("solver exploded")

    recipe = demo_plugin.RECIPE
    from dataclasses import replace
    from workbench.report.engine import run_recipe

    broken = replace(recipe, tasks=lambda o: [*demo_plugin._tasks(o)[:1], demo_plugin.Task("bad", {}, boom)])
    outcome = run_recipe(broken, demo_host, tmp_path, progress=False)
    assert any("task 'bad' failed: RuntimeError: solver exploded" in e for e in outcome.errors)
    assert (tmp_path / "cache" / "paperdemo").exists()
    assert [t["key"] for t in outcome.tasks if not t["error"]] == ["mse-kf"]


def _demo_distribution(tmp_path):
    site = tmp_path / "site"
    info = site / "demo_fixture-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: demo-fixture\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[workbench]\ndemo = fixtures.demo_plugin\n")
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(TESTS), os.environ.get("PYTHONPATH", "")]))


def test_interrupted_report_resumes_and_loses_nothing(tmp_path):
    env = _demo_distribution(tmp_path)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "workbench.cli", "report", "--paper", "demo", "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, env=dict(env, WORKBENCH_TEST_SLOW_TASK="ekf"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    cache_dir = out / "cache" / "paperdemo"
    deadline = time.time() + 60
    while time.time() < deadline and not list(cache_dir.glob("mse-kf-*.npz")):
        time.sleep(0.1)
    time.sleep(0.3)
    assert proc.poll() is None, "the report finished before it could be interrupted"
    proc.kill()
    proc.wait()
    assert list(cache_dir.glob("mse-kf-*.npz")) and not list(cache_dir.glob("mse-ekf-*.npz"))
    assert not (out / "index.html").exists()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    tasks = {t["key"]: t["cached"] for t in json.loads((out / "summary.json").read_text())["papers"][0]["tasks"]}
    assert tasks == {"mse-kf": True, "mse-ekf": False}
    assert (out / "index.html").exists()
