"""Fault injection: every class of bad input or fault gets one named error line and its exit status, or a correct
result, and finished work is never lost.  (The classes of the reliability issue; each test names its class.)

Exit statuses (workbench.cli.EXIT): 1 some work failed (the rest written), 2 bad input, 3 operating system,
4 plugin, 5 network, 130 interrupted.
"""

import errno
import json
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench import hookimpl
from workbench.cli import EXIT, main
from workbench.params import Param
from workbench.plugins import load_host
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Particles, Scans

ROOT = Path(__file__).parents[1]
EXAMPLES = ROOT / "examples" / "scenarios"
GOOD = (EXAMPLES / "range_bearing.toml").read_text().replace("runs = 200", "runs = 4").replace("steps = 100",
                                                                                                  "steps = 12")


def _scenario(tmp_path, text=GOOD, name="s.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def _one_error_line(capsys, *fragments) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("workbench: error:")]
    assert len(lines) == 1, err
    assert "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


# -- 1. ordinary faults give one named line, never a traceback ------------------------------------------------


def test_a_scenario_that_is_not_utf8(tmp_path, capsys):
    path = tmp_path / "latin1.toml"
    path.write_bytes(GOOD.replace("# Paper", "# caf\xe9").encode("latin-1") + "# caf\xe9\n".encode("latin-1"))
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == EXIT["input"]
    _one_error_line(capsys, str(path), "not UTF-8")


def test_a_recorded_csv_that_is_not_utf8(tmp_path, capsys):
    data = tmp_path / "dets.csv"
    source = (ROOT / "examples" / "data" / "sonar_sea_trial_surrogate.csv").read_text()
    data.write_bytes(source.replace("# SYNTHETIC", "# SYNTH\xc9TIQUE", 1).encode("latin-1"))
    text = (EXAMPLES / "sonar_recorded.toml").read_text()
    text = text.replace("../data/sonar_sea_trial_surrogate.csv", str(data))
    assert main(["run", str(_scenario(tmp_path, text)), "--out", str(tmp_path / "o")]) == EXIT["input"]
    _one_error_line(capsys, "dets.csv", "UTF-8")


def test_run_given_a_folder(tmp_path, capsys):
    assert main(["run", str(tmp_path)]) == EXIT["input"]
    _one_error_line(capsys, "is a folder")


def test_out_that_is_an_existing_file(tmp_path, capsys):
    blocker = tmp_path / "taken"
    blocker.write_text("not a folder")
    assert main(["run", str(_scenario(tmp_path)), "--out", str(blocker)]) == EXIT["input"]
    _one_error_line(capsys, str(blocker), "not a folder")


def test_a_folder_that_cannot_be_written(tmp_path, capsys, monkeypatch):
    # As root a read-only folder is still writable, so the operating system's refusal is injected.
    real = Path.mkdir

    def refuse(self, *args, **kwargs):
        if "locked" in str(self):
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", refuse)
    assert main(["run", str(_scenario(tmp_path)), "--out", str(tmp_path / "locked")]) == EXIT["os"]
    _one_error_line(capsys, "locked", "Permission denied")


def test_a_full_disk(tmp_path, capsys, monkeypatch):
    import workbench.report.cache as cache

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "o" / "results.npz"))

    monkeypatch.setattr(cache.np, "savez_compressed", full)
    assert main(["run", str(_scenario(tmp_path)), "--out", str(tmp_path / "o")]) == EXIT["os"]
    _one_error_line(capsys, "no space left on the device")


def test_an_unreachable_scheduler(tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed", reason="the dask extra is not installed")
    from workbench.report import engine

    # the connection is refused at once, and Dask retries it until the timeout: a shorter one names the same fault
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", "1s")
    code = main(["report", "--quick", "--paper", "003", "--out", str(tmp_path), "--no-progress", "--scheduler", "tcp://127.0.0.1:9"])
    assert code == EXIT["network"]
    _one_error_line(capsys, "cannot reach the Dask scheduler tcp://127.0.0.1:9")


def test_a_cluster_that_loses_its_workers_mid_report_is_a_network_failure(tmp_path, capsys, monkeypatch):
    """The engine's DaskClusterLost (workers gone while tasks wait) leaves the command line with the network's exit
    code and its one line, as an unreachable scheduler does."""
    from workbench.report import engine

    def lost(*args, **kwargs):
        raise engine.DaskClusterLost("tcp://10.0.0.1:8786", 3, 7, 30.0)

    monkeypatch.setattr(engine, "run_report", lost)
    code = main(["report", "--quick", "--paper", "003", "--out", str(tmp_path), "--no-progress"])
    assert code == EXIT["network"]
    _one_error_line(capsys, "tcp://10.0.0.1:8786", "no worker for 30 s while 3 of 7 tasks wait")


def test_a_list_where_a_sensor_number_belongs(tmp_path, capsys):
    path = _scenario(tmp_path, GOOD.replace('sigma_r = "1 m"', "sigma_r = [1, 2]"))
    assert main(["run", str(path)]) == EXIT["input"]
    _one_error_line(capsys, "[sensor]", "sigma_r", "expected a number")


def test_a_component_name_with_a_path_in_it(capsys):
    assert main(["check-plugin", "../kalman"]) == EXIT["input"]
    _one_error_line(capsys, "../kalman")


def test_a_filter_spec_missing_a_function_makes_its_plugin_broken():
    bad = FilterSpec("half", "no update", lambda p, r: p, lambda s, m, r: s, None, lambda s: s)
    host = load_host(extra_plugins=[("half", SimpleNamespace(workbench_filters=hookimpl(lambda: [bad])))])
    info = next(p for p in host.plugins if p.name == "half")
    assert info.status == "broken" and "'update' is not a function" in info.error
    assert "kf" in host.filters


def test_a_filter_spec_whose_optional_hook_is_not_a_function_makes_its_plugin_broken():
    import dataclasses

    kf = load_host().filter("kf")
    bad = dataclasses.replace(kf, name="kf-bad-gate", gate_candidates=13.8)
    host = load_host(extra_plugins=[("badgate", SimpleNamespace(workbench_filters=hookimpl(lambda: [bad])))])
    info = next(p for p in host.plugins if p.name == "badgate")
    assert info.status == "broken" and "optional 'gate_candidates' is neither a function nor None" in info.error
    assert "kf" in host.filters and "kf-bad-gate" not in host.filters


# -- 2. unbounded requests are refused before any allocation, naming the key and the memory --------------------


def test_a_trillion_runs(tmp_path, capsys):
    assert main(["run", str(_scenario(tmp_path, GOOD.replace("runs = 4", "runs = 1000000000000")))]) == EXIT["input"]
    _one_error_line(capsys, "runs = 1000000000000", "GiB")


def test_a_trillion_particles_named_by_the_filter_declaration():
    from workbench.models import random_walk_velocity, range_bearing
    from workbench.tracking import run

    host = load_host()
    base = host.filter("kf")
    greedy = FilterSpec("greedy", "declares a particle count", base.init, base.predict, base.update, base.estimate,
                        params={"particles": 10 ** 12},
                        parameters=(Param("particles", 100, "particles per run", "int", minimum=1, footprint=32.0),))
    scans = Scans(np.zeros((2, 3, 1, 2)), np.ones((2, 3, 1), bool), np.arange(3.0))
    with pytest.raises(InputError, match=r"filter 'greedy': particles = 1e\+12 for 2 runs needs about .* GiB"):
        run(greedy, scans, random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1),
            prior=Gaussian.broadcast(np.zeros(4), np.eye(4), 2))


# -- 3. component parameters are checked on load ---------------------------------------------------------------


@pytest.mark.parametrize("value, fragment", [('"1 s"', "is a time, but this key expects a length"),
                                             ("nan", "expected a finite number"),
                                             ("-1.0", "must be >= 0")])
def test_sensor_parameters_with_a_wrong_unit_nan_or_out_of_range(tmp_path, capsys, value, fragment):
    path = _scenario(tmp_path, GOOD.replace('sigma_r = "1 m"', f"sigma_r = {value}"))
    assert main(["run", str(path)]) == EXIT["input"]
    _one_error_line(capsys, str(path), "[sensor]", "sigma_r", fragment)


def test_clutter_parameters_are_checked_too(tmp_path, capsys):
    text = (EXAMPLES / "sonar_recorded.toml").read_text()
    assert "[[remover]]" in text
    path = _scenario(tmp_path, text.replace("../data/", str(ROOT / "examples" / "data") + "/")
                     .replace('plugin = "hough"', 'plugin = "hough"\nwindow = "five"'))
    assert main(["run", str(path)]) == EXIT["input"]
    _one_error_line(capsys, "[remover[0]]", "window", "expected an integer")


# -- 4. one failing filter does not lose the others' results ----------------------------------------------------


def test_run_writes_every_finished_filter_and_names_the_failed_one(tmp_path, capsys):
    path = _scenario(tmp_path, GOOD.replace('names = ["ekf", "sir"]', 'names = ["ekf", "kf", "sir"]'))
    code = main(["run", str(path), "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert code == EXIT["partial"]
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert set(summary["position_rmse"]) == {"ekf", "sir"} and list(summary["failed"]) == ["kf"]
    assert "kf" in captured.err and "linear measurement model" in summary["failed"]["kf"] and "others' results are written" in captured.err
    assert "FAILED" in captured.out


# -- 5. silent misreadings become errors or warnings -------------------------------------------------------------


def test_workers_below_one_is_refused(capsys):
    with pytest.raises(SystemExit) as info:
        main(["report", "--quick", "--workers", "-1"])
    assert info.value.code == 2 and "expected a whole number >= 1" in capsys.readouterr().err


def test_a_header_only_csv_is_refused(tmp_path, capsys):
    data = tmp_path / "empty.csv"
    lines = (ROOT / "examples" / "data" / "sonar_sea_trial_surrogate.csv").read_text().splitlines()
    data.write_text("\n".join(line for line in lines if line.startswith("#") or line.startswith("ping")) + "\n")
    text = (EXAMPLES / "sonar_recorded.toml").read_text().replace("../data/sonar_sea_trial_surrogate.csv", str(data))
    assert main(["run", str(_scenario(tmp_path, text))]) == EXIT["input"]
    _one_error_line(capsys, "empty.csv")


def test_filters_minus_name_can_be_typed_and_removing_the_last_is_an_error(tmp_path, capsys):
    from workbench.cli import _normalise_argv

    assert _normalise_argv(["report", "--filters", "-ekf"]) == ["report", "--filters=-ekf"]
    code = main(["report", "--quick", "--paper", "003", "--out", str(tmp_path), "--no-progress", "--filters",
                 "ekf,-ekf"])
    assert code == EXIT["input"]
    _one_error_line(capsys, "leaves no filter")


def test_a_misspelt_block_is_reported(capsys):
    assert main(["--block", "kalmann", "plugins"]) == 0
    assert "--block 'kalmann' matches no installed plugin; did you mean kalman?" in capsys.readouterr().err


def test_ctrl_c_during_run_says_what_was_kept(tmp_path, capsys, monkeypatch):
    import workbench.scenario as scenario

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(scenario, "run_scenario", interrupted)
    assert main(["run", str(_scenario(tmp_path))]) == EXIT["interrupted"]
    err = capsys.readouterr().err
    assert "interrupted; nothing of this run was written" in err and "cached" not in err


def test_a_third_party_name_collision_keeps_the_builtin_and_warns(capsys):
    impostor = FilterSpec("kf", "an impostor", lambda p, r: p, lambda s, m, r: s, lambda s, sc, m, r: s,
                          lambda s: s)
    host = load_host(extra_plugins=[("aaa", SimpleNamespace(workbench_filters=hookimpl(lambda: [impostor])))])
    assert host.filter("kf").summary.startswith("Kalman")
    assert any("'kf'" in w and "reserved" in w for w in host.warnings)


# -- 6. records refuse invalid state -----------------------------------------------------------------------------


@pytest.mark.parametrize("cov, fragment", [
    (np.array([[[1.0, 0.5], [0.0, 1.0]]]), "not symmetric"),
    (np.array([[[1.0, 0.0], [0.0, -1.0]]]), "not positive semi-definite"),
    (np.array([[[1.0, 2.0], [2.0, 1.0]]]), "not positive semi-definite"),
])
def test_invalid_covariances(cov, fragment):
    with pytest.raises(InputError, match=fragment):
        Gaussian(np.zeros((1, 2)), cov)
    Gaussian(np.zeros((1, 2)), np.zeros((1, 2, 2)))  # semi-definite (a known state) is fine


def test_invalid_particles():
    with pytest.raises(InputError, match="non-finite"):
        Particles(np.array([[[np.nan, 0.0]]]), np.zeros((1, 1)))
    with pytest.raises(InputError, match="not normalised"):
        Particles(np.zeros((1, 3, 2)), np.zeros((1, 3)))
    with pytest.raises(InputError, match="at least one particle"):
        Particles(np.zeros((1, 0, 2)), np.zeros((1, 0)))
    Particles(np.zeros((1, 4, 2)), np.full((1, 4), -np.log(4)))


def test_invalid_times():
    with pytest.raises(InputError, match="non-finite"):
        Scans(np.zeros((1, 2, 1, 2)), np.ones((1, 2, 1), bool), np.array([0.0, np.nan]))
    with pytest.raises(InputError, match="strictly increasing"):
        Scans(np.zeros((1, 3, 1, 2)), np.ones((1, 3, 1), bool), np.array([0.0, 2.0, 1.0]))
