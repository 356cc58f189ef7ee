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
    assert sc.dt == 1.0 and sc.motion.dim == 4 and sc.filter_names == ("kf", "ekf")
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
    ('sigma = 2.0', 'sigma = 2.0\nsigmaa = 1', r"\[sensor\] sensor 'demo-position': unknown parameter 'sigmaa'"),
    ('sigma = 2.0', 'sigma = "2 s"', r"\[sensor\] sensor 'demo-position': sigma: '2 s' is a time, but this key expects a length"),
    ('sigma = 2.0', 'sigma = nan', r"\[sensor\] sensor 'demo-position': sigma: expected a finite number"),
    ('sigma = 2.0', 'sigma = [1, 2]', r"\[sensor\] sensor 'demo-position': sigma: expected a number"),
    ('plugin = "demo-position"', 'plugin = "sonar-9000"', r"\[sensor\] plugin: no sensor named 'sonar-9000'"),
    ('plugin = "demo-position"', 'plugin = "kf"', r"\[sensor\] plugin: 'kf' is a filter, not a sensor \(installed sensors: "),
    ('std = [2.0, 2.0, 0.2, 0.2]', 'std = [2.0, -1.0, 0.2, 0.2]', r"\[prior\] std: standard deviations must be >= 0"),
    ('std = [2.0, 2.0, 0.2, 0.2]', 'std = [1.0, 1.0]', r"\[prior\] std: expected 4 values"),
    ('names = ["kf", "ekf"]', 'names = ["kf", "ufk"]', r"\[filters\] names\[1\]: no filter named 'ufk'"),
    ('names = ["kf", "ekf"]', 'names = ["kf", {name = "sir", particles = 0}]',
     r"\[filters\] names\[1\]: filter 'sir': particles: must be >= 1"),
    ('names = ["kf", "ekf"]', 'names = ["kf", "sir(partcles=3)"]', r"names\[1\]: filter 'sir': unknown parameter 'partcles'"),
    ('names = ["kf", "ekf"]', 'names = ["kf", "kf"]', r"the same filter is listed twice"),
    ('runs = 30', 'runs = 1000000000000', r"runs = 1000000000000 x steps = 20 needs about .* GiB"),
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


@pytest.mark.parametrize("name", ["range_bearing", "sonar_recorded", "pcl_recorded", "sonar_moving_ship"])
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
    elif name == "sonar_moving_ship":
        # irregular pings and a turning own ship: the track follows the target the file was made from, and the
        # figure draws the own ship where the file puts it
        import importlib.util
        import sys

        spec = importlib.util.spec_from_file_location("sonar_moving_ship", EXAMPLES.parent / "data" /
                                                      "sonar_moving_ship.py")
        example = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = example
        spec.loader.exec_module(example)
        scene = example.scene()
        mean = data["mean_kf"][0]
        np.testing.assert_array_equal(data["times"], scene.times)
        error = np.linalg.norm(mean[10:, :2] - scene.target[10:, :2], axis=1)
        assert np.median(error) < 40.0 and summary["diagnostics"]["kf"]["frames_updated"] >= 45
        plot = np.load(tmp_path / "tracks.npz")
        np.testing.assert_array_equal(plot["own_ship_xy"], scene.own_ship.position)
    else:
        assert summary["position_rmse"]["ekf"] < summary["position_rmse"]["sir"] < 50


def test_recorded_detections_need_an_associating_tracker(tmp_path, demo_host):
    text = (EXAMPLES / "pcl_recorded.toml").read_text().replace('tracker = "nearest-neighbour"', 'tracker = "direct"')
    path = tmp_path / "s.toml"
    path.write_text(text.replace("../data/", str(EXAMPLES.parent / "data") + "/"))
    with pytest.raises(InputError, match="need a tracker that associates"):
        load_scenario(path, demo_host)


def test_filters_take_their_own_parameters_and_the_results_name_them(tmp_path, demo_host):
    text = GOOD.replace('names = ["kf", "ekf"]', 'names = ["kf", {name = "sir", particles = 300}, "sir(particles=800)"]')
    sc = load_scenario(_write(tmp_path, text), demo_host)
    assert sc.filter_names == ("kf", "sir(particles=300)", "sir(particles=800)")
    assert sc.filters[1].params == {"particles": 300}
    result = run_scenario(sc, demo_host, tmp_path / "out")
    data = np.load(tmp_path / "out" / "results.npz")
    assert "mean_sir(particles=300)" in data.files and "mean_sir(particles=800)" in data.files
    assert set(result.rmse) == {"kf", "sir(particles=300)", "sir(particles=800)"}
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["filters"]["sir(particles=300)"] == {"plugin": "sir", "params": {"particles": 300}}


def test_a_failing_filter_is_named_and_the_others_are_written(tmp_path, demo_host):
    from dataclasses import replace

    from workbench.plugins import load_host
    from fixtures import demo_plugin
    from workbench import hookimpl
    from types import SimpleNamespace

    kf = demo_host.filter("kf")

    def nan_update(state, scan, model, rng=None):
        out = kf.update(state, scan, model, rng)
        return type(out)(np.full_like(out.mean, np.nan), out.cov) if False else out.__class__(
            np.where(np.arange(out.mean.shape[1]) == 0, np.nan, out.mean), out.cov) if scan.time > 5 else out

    def raising_update(state, scan, model, rng=None):
        raise RuntimeError("the solver exploded")

    broken = SimpleNamespace(workbench_filters=hookimpl(lambda: [
        replace(kf, name="kf-boom", update=raising_update), replace(kf, name="kf-nan", update=nan_update)]))
    host = load_host(extra_plugins=[("demo", demo_plugin), ("broken-filters", broken)])
    text = GOOD.replace('names = ["kf", "ekf"]', 'names = ["kf-boom", "kf", "kf-nan", "ekf"]')
    sc = load_scenario(_write(tmp_path, text), host)
    result = run_scenario(sc, host, tmp_path / "out")
    assert set(result.failed) == {"kf-boom", "kf-nan"}
    assert "the solver exploded" in result.failed["kf-boom"] and "NaN" in result.failed["kf-nan"]
    data = np.load(tmp_path / "out" / "results.npz")
    assert {"mean_kf", "mean_ekf"} <= set(data.files) and "mean_kf-boom" not in data.files
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert set(summary["failed"]) == {"kf-boom", "kf-nan"} and set(summary["position_rmse"]) == {"kf", "ekf"}
    assert "FAILED" in result.summary_text()


def test_a_frame_mismatch_is_refused_naming_both(tmp_path):
    from workbench.plugins import load_host

    text = (EXAMPLES / "range_bearing.toml").read_text() + \
        '\n[[clutter]]\nplugin = "sonar-poisson"\n'
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(InputError, match="sensor 'range-bearing' makes range-bearing detections but clutter "
                                         "generator 'sonar-poisson' makes cartesian-2d detections"):
        load_scenario(path, load_host())


def test_run_plots_in_the_sensor_frame_converted_to_positions(tmp_path):
    from workbench.plugins import load_host

    host = load_host()
    text = (EXAMPLES / "range_bearing.toml").read_text().replace("runs = 200", "runs = 5").replace(
        "steps = 100", "steps = 30")
    path = tmp_path / "s.toml"
    path.write_text(text)
    result = run_scenario(load_scenario(path, host), host, tmp_path / "out")
    plot = result.plot
    assert [str(v) for v in plot["left_labels"][:2]] == ["x (m)", "y (m)"]
    assert [str(v) for v in plot["right_labels"][:2]] == ["time (s)", "position RMSE (m)"]
    # the range-bearing detections are drawn as positions: near the true path, not at (range, bearing)
    truth = plot["truth_xy"]
    d = plot["detections_xy"]
    nearest = np.min(np.linalg.norm(d[:, None, :] - truth[None, :, :], axis=-1), axis=1)
    assert np.median(nearest) < 30.0 and np.all(np.abs(d[:, 1]) > 5.0)  # bearings would be |y| < pi
    assert plot["track_ekf"].shape == (30, 2) and plot["rmse_ekf"].shape == (30,)
    saved = np.load(tmp_path / "out" / "tracks.npz")
    np.testing.assert_array_equal(saved["detections_xy"], d)


def test_run_writes_a_track_file_per_filter_that_reads_back(tmp_path, demo_host):
    from workbench.tracks_io import read_tracks

    sc = load_scenario(_write(tmp_path, GOOD), demo_host)
    run_scenario(sc, demo_host, tmp_path / "out")
    data = np.load(tmp_path / "out" / "results.npz")
    for name in ("kf", "ekf"):
        tracks = read_tracks(tmp_path / "out" / f"tracks-{name}.csv")
        mean, cov = tracks.single_target()
        np.testing.assert_array_equal(mean, data[f"mean_{name}"])  # repr-exact floats
        np.testing.assert_array_equal(cov, data[f"cov_{name}"])
        assert tracks.names[:2] == ("x", "y") and tracks.units[:4] == ("m", "m", "m/s", "m/s")


# -- motion models named as plugins, with parameters ---------------------------------------------------------------

TURN = """
[scenario]
name = "turn"
runs = 3
steps = 6
dt = "2 s"

[motion]
model = "ct-rate(sigma_omega=0.01)"

[truth]
initial_state = [1000.0, 600.0, -15.0, 20.0, 0.1]

[sensor]
plugin = "range-bearing"

[prior]
mean = [1000.0, 600.0, -15.0, 20.0, 0.1]
std = [10.0, 10.0, 2.0, 2.0, 0.02]

[filters]
names = ["ukf"]
"""


def test_a_scenario_naming_a_motion_model_with_parameters_builds_that_model(tmp_path, demo_host):
    from workbench.models import coordinated_turn_rate

    text = TURN.replace("sigma_omega=0.01", "sigma_omega=0.03")
    sc = load_scenario(_write(tmp_path, text), demo_host)
    direct = coordinated_turn_rate(2.0, 0.5, 0.03)  # dt from [scenario], sigma_a the registered default
    assert type(sc.motion) is type(direct) and sc.motion.dt == 2.0 and sc.truth_motion is None
    np.testing.assert_array_equal(sc.motion.F, direct.F)
    np.testing.assert_array_equal(sc.motion.Q, direct.Q)
    x = np.array([[1.0, 2.0, 3.0, -4.0, 0.2], [0.0, 0.0, 1.0, 1.0, 0.0]])
    np.testing.assert_array_equal(sc.motion.f(x), direct.f(x))
    # the same model with its parameters as keys beside the name, and a unit string
    keys = _write(tmp_path, TURN.replace('model = "ct-rate(sigma_omega=0.01)"',
                                         'model = "ct-rate"\nsigma_omega = 0.03\nsigma_a = "0.5 m/s^2"'))
    np.testing.assert_array_equal(load_scenario(keys, demo_host).motion.Q, direct.Q)


def test_the_truth_can_move_by_its_own_motion_model(tmp_path, demo_host):
    from workbench.models import coordinated_turn
    from workbench.scenario import simulate

    text = (TURN.replace('model = "ct-rate(sigma_omega=0.01)"', 'model = "cv2d(sigma_a=1)"')
            .replace("[truth]\n", '[truth]\nmotion = "ct(omega=3 deg/s, sigma_a=0)"\n')
            .replace("[1000.0, 600.0, -15.0, 20.0, 0.1]", "[1000.0, 600.0, -15.0, 20.0]")
            .replace("[10.0, 10.0, 2.0, 2.0, 0.02]", "[10.0, 10.0, 2.0, 2.0]"))
    sc = load_scenario(_write(tmp_path, text), demo_host)
    F = coordinated_turn(2.0, np.radians(3.0), 0.0).F
    np.testing.assert_allclose(sc.truth_motion.F, F, rtol=1e-15, atol=0)
    assert sc.motion.name == "cv2d"
    truth, _ = simulate(sc, demo_host, seed=0)
    x = np.array([1000.0, 600.0, -15.0, 20.0])
    for k in range(sc.steps):  # no truth noise: the truth turns exactly as the known-rate turn says
        np.testing.assert_allclose(truth.states[:, k], np.broadcast_to(x, (3, 4)), rtol=1e-12)
        x = F @ x


@pytest.mark.parametrize("old, new, message", [
    ('"ct-rate(sigma_omega=0.01)"', '"ct-rate(sigma_omega=3 deg/s)"',
     r"\[motion\] model: motion model 'ct-rate': sigma_omega: '3 deg/s' carries the unit 'deg/s', but this key takes "
     r"a bare number in rad/s/sqrt\(s\)"),
    ('"ct-rate(sigma_omega=0.01)"', '"ct(omega=3 km)"',
     r"\[motion\] model: motion model 'ct': omega: '3 km' is a length, but this key expects an angular rate"),
    ('"ct-rate(sigma_omega=0.01)"', '"warp(speed=9)"',
     r"\[motion\] model: expected one of the installed motion models \(ca2d, ca3d, ct, ct-rate, cv2d, cv3d, growth, "
     r"rwv2d, singer2d, singer3d\), .* or one of the older forms constant_velocity, random_walk_velocity, range_rate; "
     r"got 'warp\(speed=9\)'"),
    ('"ct-rate(sigma_omega=0.01)"', '"ukf"', r"got 'ukf' \('ukf' is a filter, not a motion model\)"),
    ('"ct-rate(sigma_omega=0.01)"', '"ct-rate(sigma_omega=0.01)"\nsigma_omega = 0.02',
     r"\[motion\] sigma_omega: given twice, here and in the reference 'ct-rate\(sigma_omega=0.01\)'"),
    ('"ct-rate(sigma_omega=0.01)"', '"ct-rate(sigma_omga=0.01)"',
     r"motion model 'ct-rate': unknown parameter 'sigma_omga' \(parameters: sigma_a, sigma_omega\)"),
    ('[truth]\n', '[truth]\nmotion = "cv2d"\n',
     r"\[truth\] motion: the truth's motion model 'cv2d' has a state of 4 components \(x, y, vx, vy\), but \[motion\] "
     r"model 'ct-rate\(sigma_omega=0.01\)' has 5"),
    ('[truth]\n', '[truth]\nlegs = [{kind = "straight", duration = 4}]\n',
     r"\[truth\] legs: legs make states of 2 positions and 2 velocities, but the truth's motion model 'ct-rate' has "
     r"the state \(x, y, vx, vy, omega\)"),
])
def test_bad_motion_models_name_the_file_and_key(tmp_path, demo_host, old, new, message):
    path = _write(tmp_path, TURN.replace(old, new))
    with pytest.raises(InputError, match=message) as info:
        load_scenario(path, demo_host)
    assert str(path) in str(info.value)
