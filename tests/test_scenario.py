"""Scenario files: every problem names the file and the key; a good file runs end to end."""

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from workbench.scenario import load_scenario, run_scenario
from workbench.types import InputError

GOOD = """
[scenario]
name = "demo"
seed = 3
runs = 30
steps = 20
dt = "1 s"

[motion]
model = "constant_velocity"
dims = 2
sigma_a = "0.5 m/s^2"

[truth]
initial_state = [0.0, 0.0, 1.0, 1.0]
initial_std = [1.0, 1.0, 0.1, 0.1]

[sensor]
plugin = "demo-position"
sigma = 2.0

[prior]
mean = [0.0, 0.0, 1.0, 1.0]
std = [2.0, 2.0, 0.2, 0.2]

[filters]
names = ["kf", "ekf"]
"""


def _write(tmp_path, text):
    path = tmp_path / "s.toml"
    path.write_text(textwrap.dedent(text))
    return path


def test_good_scenario_runs_and_writes_results(tmp_path, demo_host):
    sc = load_scenario(_write(tmp_path, GOOD), demo_host)
    assert sc.dt == 1.0 and sc.motion.dim == 4 and sc.filters == ("kf", "ekf")
    result = run_scenario(sc, demo_host, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    # KF and EKF coincide on a linear model; the RMSE is of the order of the measurement noise.
    assert summary["position_rmse"]["kf"] == pytest.approx(summary["position_rmse"]["ekf"], rel=1e-9)
    assert 0.5 < result.rmse["kf"] < 3.0
    data = np.load(tmp_path / "out" / "results.npz")
    assert data["mean_kf"].shape == (30, 20, 4) and (tmp_path / "out" / "tracks.png").stat().st_size > 0


@pytest.mark.parametrize("old, new, message", [
    ('dt = "1 s"', 'dt = "1 m"', r"\[scenario\] dt: '1 m' is a length, but this key expects a time"),
    ('dt = "1 s"', 'dt = "1 fortnight"', r"\[scenario\] dt: unknown unit 'fortnight'"),
    ('sigma = 2.0', 'sigma = 2.0\nsigmaa = 1', r"\[sensor\] unknown parameter 'sigmaa' for sensor 'demo-position'"),
    ('plugin = "demo-position"', 'plugin = "sonar-9000"', r"\[sensor\] plugin: no sensor named 'sonar-9000'"),
    ('std = [2.0, 2.0, 0.2, 0.2]', 'std = [2.0, -1.0, 0.2, 0.2]', r"\[prior\] std: standard deviations must be >= 0"),
    ('std = [2.0, 2.0, 0.2, 0.2]', 'std = [1.0, 1.0]', r"\[prior\] std: expected 4 values"),
    ('names = ["kf", "ekf"]', 'names = ["kf", "ufk"]', r"\[filters\] names: no filter named 'ufk'"),
    ('model = "constant_velocity"', 'model = "warp"', r"\[motion\] model: expected one of"),
    ('runs = 30', 'runs = 30\nrunz = 4', r"\[scenario\] unknown key\(s\) \['runz'\]"),
    ('[prior]', '[priors]', r"unknown table\(s\) \['priors'\]"),
    ('names = ["kf", "ekf"]', 'names = ["kf", "ekf"', r"not valid TOML"),
])
def test_bad_scenarios_name_the_file_and_key(tmp_path, demo_host, old, new, message):
    path = _write(tmp_path, GOOD.replace(old, new))
    with pytest.raises(InputError, match=message) as info:
        load_scenario(path, demo_host)
    assert str(path) in str(info.value)


def test_missing_file(tmp_path, demo_host):
    with pytest.raises(InputError, match="no such scenario file"):
        load_scenario(tmp_path / "nope.toml", demo_host)


def test_cli_reports_errors_without_traceback(tmp_path, capsys):
    from workbench.cli import main

    path = _write(tmp_path, GOOD.replace('dt = "1 s"', 'dt = -1'))
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert "workbench: error:" in err and "Traceback" not in err


EXAMPLES = Path(__file__).parents[1] / "examples" / "scenarios"


@pytest.mark.parametrize("name", ["range_bearing", "sonar_recorded", "pcl_recorded"])
def test_example_scenarios_run(tmp_path, name):
    from workbench.cli import main

    assert main(["run", str(EXAMPLES / f"{name}.toml"), "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    data = np.load(tmp_path / "results.npz")
    if name == "sonar_recorded":
        # The multi-target tracker confirms tracks on the recorded file once the Hough window has filled.
        counts = data["cmkf-l_status"]
        assert summary["tracker"] == "multi-target" and (counts == 1).any()
    elif name == "pcl_recorded":
        # No truth in a recorded file: the track must follow the candidates it chose (a smooth track).
        mean = data["mean_kf"][0]
        assert mean.shape == (120, 2) and np.all(np.isfinite(mean))
        assert np.std(np.diff(mean[:, 0])) < 10.0
        assert summary["diagnostics"]["kf"]["frames_updated"] > 90
    else:
        assert summary["position_rmse"]["ekf"] < summary["position_rmse"]["sir"] < 50


def test_recorded_detections_need_an_associating_tracker(tmp_path, demo_host):
    text = (EXAMPLES / "pcl_recorded.toml").read_text().replace('tracker = "nearest-neighbour"', 'tracker = "direct"')
    path = tmp_path / "s.toml"
    path.write_text(text.replace("../data/", str(EXAMPLES.parent / "data") + "/"))
    with pytest.raises(InputError, match="need a tracker that associates"):
        load_scenario(path, demo_host)
