"""Scenario files with several objects per run: [[targets]], [births] and [trackers]; examples/multi_target.toml
run small, its track files with covariances, GOSPA finite and below the no-track value; every key refused by name."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from workbench.plugins import load_host
from workbench.scenario import load_scenario, run_scenario
from workbench.tracks_io import read_tracks
from workbench.types import InputError

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "scenarios" / "multi_target.toml"


@pytest.fixture(scope="module")
def host():
    return load_host()


@pytest.mark.slow  # about 8 s on 2 shared cores: the first Kalman predict's compile and the plot
def test_example_runs_small_with_covariances_and_gospa(host, tmp_path):
    scenario = dataclasses.replace(load_scenario(EXAMPLE, host), runs=3, steps=30)
    assert [t.label for t in scenario.trackers] == ["gnn", "mofn"]
    assert [(t.first, t.last) for t in scenario.targets] == [(0, None), (0, 25), (10, None)]
    result = run_scenario(scenario, host, tmp_path)
    assert not result.failed
    summary = json.loads((tmp_path / "summary.json").read_text())
    no_tracks = summary["gospa"]["no_tracks"]
    # no track at all: every live object missed, GOSPA^2 = n_live c^2 / 2 per scan (c = 10 m); at least the two
    # listed objects alive over scans 0-25 -> at least 10 m there
    assert no_tracks >= 10.0
    arrays = np.load(tmp_path / "results.npz")
    alive = arrays["alive"]
    expect = np.sqrt(alive.sum(axis=2) * 100.0 / 2.0).mean()
    assert no_tracks == pytest.approx(expect, rel=1e-12)
    for label in ("gnn/kf", "mofn/kf"):
        g = arrays[f"gospa_{label}"]
        assert g.shape == (3, 30) and np.all(np.isfinite(g))
        assert result.gospa[label] == pytest.approx(g.mean())
        assert result.gospa[label] < 0.6 * no_tracks
        tracks = read_tracks(tmp_path / f"tracks-{label.replace('/', '_')}.csv")
        assert tracks.cov is not None and tracks.cov.shape == (tracks.mean.shape[0], 4, 4)
        assert np.all(np.linalg.eigvalsh(tracks.cov) > 0)
    # the truth in results.npz: objects alive over their declared scans
    assert alive[:, :10, 2].sum() == 0 and alive[:, 10:, 2].all()
    assert alive[:, :26, 1].all() and alive[:, 26:, 1].sum() == 0


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


BASE = """
[scenario]
name = "m"
steps = 10
dt = "1 s"
{scenario}
[motion]
model = "constant_velocity"
dims = 2
sigma_a = 0.1

{objects}

[sensor]
plugin = "{sensor}"

[filters]
names = ["kf"]
{trackers}
"""
TARGET = "[[targets]]\ninitial_state = [0.0, 0.0, 1.0, 1.0]\n"
TRACKERS = '[trackers]\nnames = ["gnn"]\n'


def _load(host, tmp_path, objects=TARGET, trackers=TRACKERS, scenario="", sensor="active-sonar"):
    return load_scenario(_write(tmp_path, BASE.format(objects=objects, trackers=trackers, scenario=scenario,
                                                      sensor=sensor)), host)


@pytest.mark.parametrize("objects, trackers, scenario, match", [
    (TARGET, "", "", r"missing table \[trackers\]"),
    ("", TRACKERS, "", r"\[trackers\] runs installed trackers on several objects"),
    (TARGET + "[truth]\ninitial_state = [0.0, 0.0, 1.0, 1.0]\n", TRACKERS, "", r"\[truth\] holds one object"),
    (TARGET + "[prior]\nmean = [0.0, 0.0, 1.0, 1.0]\n", TRACKERS, "", r"\[prior\] is not used"),
    (TARGET, TRACKERS, 'tracker = "multi-target"', r"\[scenario\] tracker: with \[\[targets\]\]"),
    (TARGET + "p_d = 1.5\n", TRACKERS, "", r"\[targets\[0\]\] p_d: expected a probability"),
    (TARGET + "first = 5\nlast = 3\n", TRACKERS, "", r"\[targets\[0\]\] last: scan 3 comes before first"),
    (TARGET + "last = 10\n", TRACKERS, "", r"\[targets\[0\]\] last: scan 10 is past"),
    (TARGET + "speed = 3\n", TRACKERS, "", r"\[targets\[0\]\] unknown key\(s\) \['speed'\]"),
    (TARGET, '[trackers]\nnames = ["no-such-tracker"]\n', "", r"\[trackers\] names\[0\]: .*no-such-tracker"),
    (TARGET, '[trackers]\nnames = ["gnn(gate_probability=2)"]\n', "", r"names\[0\].*gate_probability"),
    (TARGET, '[trackers]\nnames = ["gnn", {name = "gnn"}]\n', "", r"names\[1\]: tracker 'gnn' is listed twice"),
    (TARGET, '[trackers]\nnames = ["gnn"]\norder = 0.5\n', "", r"\[trackers\] order"),
    ('[births]\nrate = 0.1\nregion = [[0, 10]]\nvelocity_std = 1\nmax_objects = 3\n', TRACKERS, "",
     r"\[births\] region: 1 axes"),
    ('[births]\nrate = -1\nregion = [[0, 10], [0, 10]]\nvelocity_std = 1\nmax_objects = 3\n', TRACKERS, "",
     r"\[births\] rate"),
    ('[births]\nrate = 0.1\nregion = [[0, 10], [0, 10]]\nvelocity_std = 1\n', TRACKERS, "",
     r"\[births\] max_objects: missing"),
])
def test_multi_target_keys_are_refused_by_name(host, tmp_path, objects, trackers, scenario, match):
    with pytest.raises(InputError, match=match):
        _load(host, tmp_path, objects, trackers, scenario)


def test_own_p_d_needs_a_sensor_that_declares_pd(host, tmp_path):
    with pytest.raises(InputError, match=r"\[targets\[0\]\] p_d = 0.5, but sensor 'range-bearing' declares no "):
        _load(host, tmp_path, TARGET + "p_d = 0.5\n", sensor="range-bearing")


def test_a_cartesian_tracker_refuses_other_detections_by_name(host, tmp_path):
    with pytest.raises(InputError, match=r"tracker 'gnn' takes Cartesian"):
        _load(host, tmp_path, sensor="range-bearing")


def test_births_and_targets_load_with_units_and_configured_trackers(host, tmp_path):
    births = ('[births]\nrate = 0.2\nregion = [["0 m", "1 km"], ["-1 km", "0 m"]]\nvelocity_std = "2 m/s"\n'
              'velocity_mean = ["1 m/s", 0]\nmax_objects = 4\nsurvival = 0.9\n')
    trackers = '[trackers]\nnames = ["gnn(gate_probability=0.95)", {name = "mofn", confirm_hits = 2}]\ncutoff = "20 m"\n'
    s = _load(host, tmp_path, TARGET + births, trackers)
    assert s.multi and len(s.targets) == 1
    np.testing.assert_allclose(s.births.region, [[0.0, 1000.0], [-1000.0, 0.0]])
    np.testing.assert_allclose(s.births.velocity_mean, [1.0, 0.0])
    assert (s.births.max_objects, s.births.survival, s.cutoff, s.order) == (4, 0.9, 20.0, 2.0)
    assert [t.label for t in s.trackers] == ["gnn(gate_probability=0.95)", "mofn(confirm_hits=2)"]
    assert dict(s.trackers[1].params) == {"confirm_hits": 2}
