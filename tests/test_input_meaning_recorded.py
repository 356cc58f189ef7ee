"""Recorded inputs are checked for meaning, not only shape (issue 29, classes 2, 3 and 6), and ``workbench run``
into an existing ``--out`` leaves no stale result beside the new ones.

Class 2: a scenario key that the recorded file also supplies is honoured or refused naming both sources.
Class 3: recorded metadata is checked for plausibility and against the sensor that uses it.
Class 6: readers check content (one time per step, increasing times, variances >= 0, PSD covariances).
Each bad input goes through the CLI (exit 2 and one ``workbench: error:`` line naming the problem) or the public
API (a named ``InputError``, a warning with the numbers, or a result checked against an independent value).
"""

import json
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from fixtures.candidates import IRREGULAR

from workbench.cli import EXIT, main
from workbench.plugins import load_host
from workbench.scenario import load_scenario
from workbench.recorded import (ImplausibleValueWarning, load_pcl_candidates, load_sonar_recording,
                                write_pcl_candidates)
from workbench.tracks_io import TrackFile, read_tracks, write_tracks
from workbench.types import InputError

ROOT = Path(__file__).parents[1]
EXAMPLES = ROOT / "examples" / "scenarios"
DATA = ROOT / "examples" / "data"
C = 299_792_458.0  # speed of light (m/s), written out here independently of workbench.sensing


def _scenario(tmp_path, example: str, *edits, data: Path | None = None, name: str = "s.toml") -> Path:
    """An example scenario with its data path made absolute (or pointed at ``data``) and ``edits`` applied."""
    text = (EXAMPLES / f"{example}.toml").read_text()
    text = re.sub(r'file = "\.\./data/([^"]+)"', lambda m: f'file = "{data or DATA / m.group(1)}"', text)
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


def _error(capsys, *fragments) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("workbench: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _run(path, out) -> int:
    return main(["run", str(path), "--out", str(out)])


# -- class 2: scenario keys that the recorded file supplies ---------------------------------------------------

PCL = str(DATA / "pcl_candidates_synthetic.csv")


@pytest.mark.parametrize("edit, fragments", [
    (("steps = 120", "steps = 100"), ["[scenario] steps = 100", PCL, "holds 120 frames"]),
    (('dt = "0.5 s"', 'dt = "2 s"'), ["[scenario] dt = 2 s", PCL, "column 'time_s'", "0.5 s apart"]),
    (("steps = 120", "steps = 120\nruns = 3"), ["[scenario] runs = 3", PCL, "holds one run"]),
    (('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\nfrequency_hz = "650 MHz"'),
     ["[sensor] frequency_hz = 650 MHz (given)", PCL, "declares carrier_hz 7.01e+08 Hz (701 MHz)"]),
    (('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\ntx = [0.0, -9000.0, 420.0]'),
     ["[sensor] tx = (0, -9000, 420) m (given)", PCL, "declares transmitter_m (0, -8400, 420) m"]),
    (("[filters]", '[truth]\ninitial_state = [0.0, 0.0]\n\n[filters]'), ["[truth] is not used with recorded", PCL]),
    (("[filters]", '[[clutter]]\nplugin = "pbr-clutter"\n\n[filters]'), ["[[clutter]] adds simulated clutter", PCL]),
])
def test_a_scenario_key_the_recorded_file_overrides_is_refused_naming_both(tmp_path, capsys, edit, fragments):
    path = _scenario(tmp_path, "pcl_recorded", edit)
    assert _run(path, tmp_path / "o") == EXIT["input"]
    _error(capsys, str(path), *fragments)
    assert not (tmp_path / "o").exists()  # refused on load, before anything is written


def test_a_polar_model_fixed_at_one_point_and_a_moving_own_ship_are_refused(tmp_path, capsys):
    path = _scenario(tmp_path, "sonar_moving_ship", ('frame = "cartesian"', 'frame = "polar"'),
                     ('tracker = "nearest-neighbour"', 'tracker = "multi-target"'), ("gate = 9.21\n", ""))
    assert _run(path, tmp_path / "o") == EXIT["input"]
    _error(capsys, str(path), "[sensor] sensor = (0, 0) (the default of sensor 'active-sonar')",
           "sonar_moving_ship_synthetic.csv gives the own ship's position per ping")


def test_dt_of_a_ping_numbered_file_is_honoured(tmp_path):
    # the surrogate numbers its pings; the scenario's dt is their spacing: times = ping * dt
    path = _scenario(tmp_path, "sonar_recorded", ('dt = "1 s"', 'dt = "2.5 s"'))
    assert _run(path, tmp_path / "o") == 0
    pings = sorted({int(line.split(",")[0]) for line in (DATA / "sonar_sea_trial_surrogate.csv").read_text()
                    .splitlines() if line[:1].isdigit()})
    times = np.load(tmp_path / "o" / "results.npz")["times"]
    np.testing.assert_array_equal(times, 2.5 * np.arange(max(pings) + 1))


def test_the_sensor_position_of_a_polar_file_without_own_ship_is_honoured(tmp_path):
    # range/bearing rows measured from a sensor at (300, -200): the scenario says where it is
    rows, sensor = [], (300.0, -200.0)
    for k in range(12):
        x, y = 400.0 + 3.0 * k, 100.0 + 2.0 * k
        r, b = math.hypot(x - sensor[0], y - sensor[1]), math.degrees(math.atan2(y - sensor[1], x - sensor[0]))
        rows.append(f"{k},{r!r},{b!r}")
    data = tmp_path / "polar.csv"
    data.write_text("ping,range,bearing\n" + "\n".join(rows) + "\n")
    path = _scenario(tmp_path, "sonar_recorded", ('frame = "polar"', 'frame = "polar"\nsensor = [300.0, -200.0]'),
                     ("steps = 20", "steps = 12"), ("[[remover]]\nplugin = \"hough\"\n", ""), data=data)
    assert _run(path, tmp_path / "o") == 0
    z = np.load(tmp_path / "o" / "results.npz")["z"][0, :, 0]
    np.testing.assert_allclose(z, [(400.0 + 3.0 * k, 100.0 + 2.0 * k) for k in range(12)], atol=1e-9)


def test_a_file_without_a_carrier_takes_the_sensors(tmp_path):
    # no '#! carrier_hz' line: the configured sensor's 650 MHz converts Doppler to range-rate (lambda = c / f)
    text = (DATA / "pcl_candidates_synthetic.csv").read_text()
    data = tmp_path / "cands.csv"
    data.write_text("\n".join(line for line in text.splitlines() if not line.startswith("#! carrier_hz")) + "\n")
    path = _scenario(tmp_path, "pcl_recorded", ('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\nfrequency_hz = "650 MHz"'),
                     data=data)
    assert _run(path, tmp_path / "o") == 0
    first = next(line for line in text.splitlines() if line[:1].isdigit() and line.split(",")[3])
    doppler = float(first.split(",")[3])
    z = np.load(tmp_path / "o" / "results.npz")["z"]
    assert z[0, int(first.split(",")[0]), 0, 1] == pytest.approx(-C / 650e6 * doppler, rel=1e-12)


# -- class 3: recorded metadata, plausible and agreeing with the sensor ---------------------------------------

def _pcl_with_carrier(tmp_path, carrier: str) -> Path:
    text = (DATA / "pcl_candidates_synthetic.csv").read_text()
    data = tmp_path / "cands.csv"
    data.write_text(text.replace("#! carrier_hz: 701000000.0", f"#! carrier_hz: {carrier}"))
    return data


def test_a_carrier_off_by_a_million_is_refused_with_the_numbers(tmp_path, capsys):
    data = _pcl_with_carrier(tmp_path, "701")  # MHz written where the format wants Hz
    assert _run(_scenario(tmp_path, "pcl_recorded", data=data), tmp_path / "o") == EXIT["input"]
    _error(capsys, str(data), "carrier_hz", "carrier 701 Hz is not a passive-radar illuminator's carrier",
           "given in MHz? 701 MHz is 7.01e+08 Hz")
    with pytest.raises(InputError, match=r"carrier 7.01e\+14 Hz .* off by a factor 1e\+06"):
        load_pcl_candidates(_pcl_with_carrier(tmp_path, "701e12"))
    with pytest.raises(InputError, match=r"write_pcl_candidates: frequency_hz: carrier 701 Hz"):
        write_pcl_candidates(tmp_path / "w.csv", load_pcl_candidates(DATA / "pcl_candidates_synthetic.csv"),
                             frequency_hz=701)
    assert not (tmp_path / "w.csv").exists()


def test_a_file_and_the_configured_sensor_that_disagree_on_the_carrier_are_refused(tmp_path, capsys):
    data = _pcl_with_carrier(tmp_path, "650e6")
    path = _scenario(tmp_path, "pcl_recorded", data=data)
    assert _run(path, tmp_path / "o") == EXIT["input"]
    _error(capsys, str(path), "[sensor] frequency_hz = 701 MHz (the default of sensor 'dtv-pbr')", str(data),
           "declares carrier_hz 6.5e+08 Hz (650 MHz)")
    # and agreeing ones run, converting with the file's 650 MHz
    agree = _scenario(tmp_path, "pcl_recorded", ('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\nfrequency_hz = 650e6'),
                      data=data, name="agree.toml")
    assert _run(agree, tmp_path / "o2") == 0


def _moving_ship(tmp_path, edit) -> Path:
    """The shipped moving-ship file with ``edit(fields)`` applied to every data row."""
    out = []
    for line in (DATA / "sonar_moving_ship_synthetic.csv").read_text().splitlines():
        if line[:1].isdigit():
            fields = line.split(",")
            edit(fields)
            line = ",".join(fields)
        out.append(line)
    path = tmp_path / "ship.csv"
    path.write_text("\n".join(out) + "\n")
    return path


def test_a_compass_heading_where_the_math_convention_is_wanted_is_a_warning_with_the_numbers(tmp_path, capsys):
    # the file's ship turns from 30 to 120 degrees (math convention) and sails along its heading
    def compass(fields):
        fields[7] = repr(90.0 - float(fields[7]))

    data = _moving_ship(tmp_path, compass)
    with pytest.warns(ImplausibleValueWarning, match=r"heading differs from its course over ground .* median of "
                                                     r"\d+\.\d degrees over 59 legs"):
        load_sonar_recording(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ImplausibleValueWarning)
        load_sonar_recording(DATA / "sonar_moving_ship_synthetic.csv")  # the true headings pass
    path = _scenario(tmp_path, "sonar_moving_ship", data=data)
    capsys.readouterr()
    with pytest.warns(ImplausibleValueWarning, match="a compass heading?"):  # the Python API: a warning, no print
        scenario = load_scenario(path, load_host())
    assert capsys.readouterr().err == "" and any("a compass heading?" in note for note in scenario.notes)
    assert _run(path, tmp_path / "o") == 0
    err = capsys.readouterr().err
    assert "workbench: warning:" in err and "a compass heading?" in err and str(data) in err
    assert err.count("a compass heading?") == 1  # the command line's own line, not also Python's warning display
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert any("course over ground" in note for note in summary["input_warnings"])


def test_an_own_ship_too_fast_to_be_a_ship_is_a_warning_with_the_numbers(tmp_path):
    # positions written in millimetres: the file's 5 m/s own ship reads 5000 per second
    def millimetres(fields):
        fields[5], fields[6] = repr(1000 * float(fields[5])), repr(1000 * float(fields[6]))

    with pytest.warns(ImplausibleValueWarning, match=r"a speed of 5000 \(over 100 m/s"):
        load_sonar_recording(_moving_ship(tmp_path, millimetres))


def test_bearings_given_in_radians_are_a_warning(tmp_path):
    rows = [f"{k},{1000 + k},{0.3 * math.sin(k)!r}" for k in range(12)]
    path = tmp_path / "rad.csv"
    path.write_text("ping,range,bearing\n" + "\n".join(rows) + "\n")
    with pytest.warns(ImplausibleValueWarning, match=r"all 12 bearings lie within \+-2 pi \(largest \|bearing\| "
                                                     r"0\.3, line 13\)"):
        load_sonar_recording(path)


@pytest.mark.parametrize("column, value, fragment", [
    (2, "400", "line 4, column 'bearing': a bearing in degrees lies within +-360, got '400'"),
    (4, "200", "line 4, column 'sigma_bearing': a bearing accuracy in degrees must be below 180"),
    (7, "-725", "line 4, column 'heading': a heading in degrees lies within +-360, got '-725'"),
])
def test_angles_out_of_their_range_are_refused_with_line_and_column(tmp_path, column, value, fragment):
    lines = (DATA / "sonar_moving_ship_synthetic.csv").read_text().splitlines()
    fields = lines[3].split(",")
    fields[column] = value
    lines[3] = ",".join(fields)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as err:
        load_sonar_recording(path)
    assert str(path) in str(err.value) and fragment in str(err.value)


# -- class 6: readers check content ----------------------------------------------------------------------------

TRACKS = """# format: workbench-tracks 1
# state: x [m], y [m]
# covariance: upper triangle
# runs: 1
# steps: 2
run,track,step,time,status,updated,x,y,cov_x_x,cov_x_y,cov_y_y
0,0,0,0.0,confirmed,1,1.0,2.0,4.0,1.0,9.0
0,3,1,1.0,tentative,1,3.0,4.0,4.0,-2.0,9.0
"""


@pytest.mark.parametrize("old, new, fragment", [
    ("4.0,-2.0,9.0", "-4.0,-2.0,9.0", "line 8, column 'cov_x_x': -4.0 is the variance of x of track 3 (run 0, step 1) "
                                      "and must be >= 0"),
    # |cov_x_y| = 7 > sqrt(4 * 9) = 6: a correlation of -7/6, so eigenvalues (13 -+ sqrt(25 + 196)) / 2 < 0
    ("4.0,-2.0,9.0", "4.0,-7.0,9.0", "line 8: the covariance of track 3 (run 0, step 1) is not positive "
                                     f"semi-definite (smallest eigenvalue {(13 - math.sqrt(221)) / 2:.6g}"),
    ("0,3,1,1.0", "0,3,0,0.5", "line 8, column 'time': step 0 has time 0.0 on line 7 but 0.5 here (track 3, run 0)"),
    ("0,3,1,1.0", "0,3,1,-1.0", "line 8, column 'time': step 1 has time -1.0, not after step 0's 0.0 (line 7)"),
])
def test_a_track_file_with_impossible_content_is_refused(tmp_path, old, new, fragment):
    good = tmp_path / "good.csv"
    good.write_text(TRACKS)
    assert read_tracks(good).rows == 2
    bad = tmp_path / "bad.csv"
    bad.write_text(TRACKS.replace(old, new))
    with pytest.raises(InputError) as err:
        read_tracks(bad)
    assert str(bad) in str(err.value) and fragment in str(err.value)


def test_a_track_file_is_not_written_with_a_covariance_no_reader_would_accept(tmp_path):
    good = tmp_path / "good.csv"
    good.write_text(TRACKS)
    back = read_tracks(good)
    cov = back.cov.copy()
    cov[1] = [[4.0, -7.0], [-7.0, 9.0]]
    bad = TrackFile(back.names, back.units, back.runs, back.steps, back.run, back.track, back.step, back.time,
                    back.status, back.updated, back.mean, cov)
    with pytest.raises(InputError, match=r"track 3 \(run 0, step 1\) is not positive semi-definite"):
        write_tracks(tmp_path / "out.csv", bad)
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("old, new, fragment", [
    ("2,1.3,993.6", "2,1.6,993.6", "line 9, column 'time_s': frame 3 time 1.5 is not after frame 2's 1.6"),
    ("3,1.5,992.4", "2,1.5,992.4", "line 9, column 'time_s': frame 2 has time 1.3 on line 8 but 1.5 here"),
    ("20,15,0.6", "20,0,0.6", "line 10, column 'sigma_range_m': each candidate needs its accuracy, a number > 0"),
])
def test_a_candidate_file_with_impossible_content_is_refused(tmp_path, old, new, fragment):
    text = IRREGULAR
    ok = tmp_path / "ok.csv"
    ok.write_text(text)
    assert load_pcl_candidates(ok).steps == 5
    bad = tmp_path / "bad.csv"
    bad.write_text(text.replace(old, new))
    with pytest.raises(InputError) as err:
        load_pcl_candidates(bad)
    assert str(bad) in str(err.value) and fragment in str(err.value)


def test_a_sonar_file_with_a_non_positive_accuracy_is_refused(tmp_path):
    path = tmp_path / "acc.csv"
    path.write_text("time,x,y,sigma_x,sigma_y\n0.0,1.0,2.0,1.0,1.0\n1.0,1.5,2.5,-1.0,1.0\n")
    with pytest.raises(InputError, match=r"acc.csv line 3, column 'sigma_x': an accuracy is a standard deviation > 0"):
        load_sonar_recording(path)


# -- run into an existing --out: no stale file beside the new results ------------------------------------------

RANGE_BEARING = [("runs = 200", "runs = 3"), ("steps = 100", "steps = 8")]


def test_a_rerun_removes_the_files_its_earlier_run_wrote_and_nothing_else(tmp_path, capsys):
    out = tmp_path / "o"
    first = _scenario(tmp_path, "range_bearing", *RANGE_BEARING, ('names = ["ekf", "sir"]', 'names = ["ekf", "ukf"]'))
    assert _run(first, out) == 0
    assert (out / "tracks-ukf.csv").exists() and (out / "tracks-ekf.csv").exists()
    (out / "my-notes.txt").write_text("mine")  # a user's file, which the workbench never wrote
    second = _scenario(tmp_path, "range_bearing", *RANGE_BEARING, ('names = ["ekf", "sir"]', 'names = ["ekf"]'),
                       name="second.toml")
    assert _run(second, out) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["my-notes.txt", "results.npz", "summary.json", "tracks-ekf.csv", "tracks.npz", "tracks.png",
                     "workbench-run.json"]
    manifest = json.loads((out / "workbench-run.json").read_text())
    assert sorted(manifest["files"]) == [n for n in names if n not in ("my-notes.txt", "workbench-run.json")]
    assert "mean_ukf" not in np.load(out / "results.npz").files


def test_a_result_file_no_run_recorded_writing_is_named_and_kept(tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    stray = out / "tracks-pda.csv"  # looks like a result, but no manifest says the workbench wrote it
    stray.write_text("someone else's")
    path = _scenario(tmp_path, "range_bearing", *RANGE_BEARING, ('names = ["ekf", "sir"]', 'names = ["ekf"]'))
    assert _run(path, out) == EXIT["input"]
    _error(capsys, str(out), "holds tracks-pda.csv", "workbench-run.json does not list it")
    assert stray.read_text() == "someone else's" and sorted(p.name for p in out.iterdir()) == ["tracks-pda.csv"]


# -- class 2: [sensor] keys that only shape a simulation the recorded file replaces ---------------------------

SONAR = str(DATA / "sonar_sea_trial_surrogate.csv")
MOVING = str(DATA / "sonar_moving_ship_synthetic.csv")


def _pcl_text(drop: str = "", accuracy: bool = False) -> str:
    """The shipped candidate file without its ``#!`` lines that start with ``drop``; ``accuracy`` adds each
    candidate's own standard deviations (12 m, 0.7 m/s) as the two accuracy columns."""
    out = []
    for line in (DATA / "pcl_candidates_synthetic.csv").read_text().splitlines():
        if drop and line.startswith(drop):
            continue
        if accuracy and line.startswith("frame,"):
            line += ",sigma_range_m,sigma_range_rate_mps"
        elif accuracy and line[:1].isdigit():
            line += ",," if line.split(",")[2] == "" else ",12,0.7"
        out.append(line)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("example, edit, fragments", [
    ("pcl_recorded", ('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\npd = 0.5\nstrength_db = 12'),
     ["[sensor] pd = 0.5, strength_db = 12 dB only shape simulated detections", "declares them simulation-only",
      f"the recorded file {PCL} replaces the simulation"]),
    # the simulated candidates' noise, not the filters' R (model_sigma_range)
    ("pcl_recorded", ('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\nsigma_range = "30 m"'),
     ["[sensor] sigma_range = 30 m only shapes simulated detections", f"the recorded file {PCL}"]),
    ("sonar_recorded", ('frame = "polar"', 'frame = "polar"\nlevel_db = 10'),
     ["[sensor] level_db = 10 dB only shapes simulated detections", f"the recorded file {SONAR}"]),
    # the polar model's R is sigma_r, sigma_b_deg: sigma_pos would only shape the (replaced) simulation
    ("sonar_recorded", ('frame = "polar"', 'frame = "polar"\nsigma_pos = 3.0'),
     ["[sensor] sigma_pos = 3 m enters the measurement model of sensor 'active-sonar' only if frame = cartesian, "
      "sigma_xy = none (here frame = polar)", f"the recorded file {SONAR} replaces"]),
    # an x-y file without own ship: neither the reader nor the Cartesian model has a sensor position
    ("sonar_recorded", ('frame = "polar"', 'frame = "cartesian"\nsensor = [10.0, 20.0]'),
     ["[sensor] sensor = (10, 20) m enters the measurement model", "only if frame = polar (here frame = cartesian)",
      SONAR]),
    # the file's per-detection accuracy replaces R: a sigma for R beside it would be ignored
    ("sonar_moving_ship", ('frame = "cartesian"', 'frame = "cartesian"\nsigma_xy = 3.0'),
     ["[sensor] sigma_xy = 3 m sets the filters' measurement noise R", f"the recorded file {MOVING} gives each "
      "detection its own accuracy (columns sigma_range, sigma_bearing)"]),
])
def test_a_sensor_key_the_recorded_run_would_not_use_is_refused_naming_both(tmp_path, capsys, example, edit,
                                                                              fragments):
    path = _scenario(tmp_path, example, edit)
    assert _run(path, tmp_path / "o") == EXIT["input"]
    _error(capsys, str(path), *fragments)
    assert not (tmp_path / "o").exists()
    # the same scenario without the key runs
    assert _run(_scenario(tmp_path, example, name="plain.toml"), tmp_path / "plain") == 0


def test_the_filters_r_beside_a_candidate_files_own_accuracy_is_refused_naming_both(tmp_path, capsys):
    data = tmp_path / "cands.csv"
    data.write_text(_pcl_text(accuracy=True))
    sigma = ('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\nmodel_sigma_range = 20.0\nmodel_sigma_range_rate = 0.6')
    path = _scenario(tmp_path, "pcl_recorded", sigma, data=data)
    assert _run(path, tmp_path / "o") == EXIT["input"]
    _error(capsys, str(path), "[sensor] model_sigma_range = 20 m, model_sigma_range_rate = 0.6 m/s set the filters' "
           f"measurement noise R, but the recorded file {data} gives each detection its own accuracy (columns "
           "sigma_range_m, sigma_range_rate_mps)")
    # without the file's accuracy columns the same keys set R (below), and without the keys the file's accuracy
    # is used
    assert _run(_scenario(tmp_path, "pcl_recorded", data=data, name="plain.toml"), tmp_path / "plain") == 0


def test_tx_and_rx_pass_where_the_file_declares_them_and_are_refused_where_nothing_uses_them(tmp_path, capsys):
    tx = ('plugin = "dtv-pbr"', 'plugin = "dtv-pbr"\ntx = [0.0, -8400.0, 420.0]')
    # the file declares transmitter_m: the scenario's tx is held to it (and agrees)
    assert _run(_scenario(tmp_path, "pcl_recorded", tx), tmp_path / "a") == 0
    # a file without it: the model takes no geometry, so nothing would use tx
    data = tmp_path / "cands.csv"
    data.write_text(_pcl_text(drop="#! transmitter_m"))
    path = _scenario(tmp_path, "pcl_recorded", tx, data=data, name="b.toml")
    assert _run(path, tmp_path / "b") == EXIT["input"]
    _error(capsys, str(path), "[sensor] tx = (0, -8400, 420) m only shapes simulated detections", str(data))


def test_a_sensor_sigma_for_r_is_honoured_with_recorded_detections(tmp_path):
    # the Kalman update in information form, P+^-1 = P-^-1 + R^-1 (H = I): two runs that differ only in the
    # range sigma of R share P- at frame 1 (the prior and the motion are the same), so their P+^-1 differ by
    # diag(1/a^2 - 1/b^2, 0) exactly when the filter used the scenario's sigma (both wide enough for the target's
    # candidate of frame 1 to fall in the 99 % gate, so that both runs update there)
    covs = {}
    for sigma in (30.0, 60.0):
        path = _scenario(tmp_path, "pcl_recorded", ('plugin = "dtv-pbr"', f'plugin = "dtv-pbr"\nmodel_sigma_range = '
                                                    f'"{sigma} m"'), name=f"s{sigma:g}.toml")
        assert _run(path, tmp_path / f"o{sigma:g}") == 0
        covs[sigma] = np.load(tmp_path / f"o{sigma:g}" / "results.npz")["cov_kf"][0, 1]
    diff = np.linalg.inv(covs[30.0]) - np.linalg.inv(covs[60.0])
    np.testing.assert_allclose(diff, np.diag([1 / 30.0**2 - 1 / 60.0**2, 0.0]), rtol=1e-9, atol=1e-12)


# The declarations themselves, held to what each built-in sensor's measurement model does with the value.

STATE_DIM = {"range-bearing": 4, "active-sonar": 4, "dtv-pbr": 2, "lband-radar": 6}


def _other(param, value):
    """A valid value of ``param`` other than ``value``."""
    if param.choices:
        return next(c for c in param.choices if c != value)
    if value is None:
        return 3.0
    if param.type in ("vector", "vector?"):
        return tuple(v + 1.0 for v in value)
    if param.type == "int":
        return value + 1
    new = 1.5 * value + 1.0
    return new if new <= param.bounds[1] else 0.5 * (value + param.bounds[1])


def _model_view(model, n: int) -> dict:
    """Everything a filter can read from a measurement model, evaluated at fixed points; ``R`` and ``std`` apart."""
    x = np.array([[1200.0, -800.0, 30.0, 5.0, 100.0, 2.0], [-300.0, 2500.0, -7.0, 1.0, 40.0, -3.0]])[:, :n]
    view = {"name": model.name, "frame": model.frame, "h": model.h(x), "sensor": model.sensor_position,
            "R": model.R, "std": model.std}
    if model.jacobian is not None:
        view["jacobian"] = model.jacobian(x)
    d = model.detection
    if d is not None:
        snr, nominal = np.array([8.0, 15.0]), np.array([10.0, 12.0])
        view.update(log_pd=d.log_pd(snr), position_sigma=d.position_sigma(snr, np.array([5e3, 2e4])),
                    doppler_sigma=d.doppler_sigma, pfa=d.pfa)
        for name, args in (("nominal_snr_db", (x[:, :3],)), ("log_detection", (nominal,)),
                           ("log_snr_density", (snr, nominal))):
            if getattr(d, name) is not None:
                view[name] = getattr(d, name)(*args)
    return view


def _changed(a: dict, b: dict) -> set:
    """The entries of two model views that differ."""
    def same(x, y):
        if x is None or y is None or isinstance(x, str) or isinstance(y, str):
            return x == y
        return np.array_equal(np.asarray(x, dtype=float), np.asarray(y, dtype=float))

    return {key for key in a.keys() | b.keys() if key not in a or key not in b or not same(a[key], b[key])}


@pytest.mark.parametrize("sensor", sorted(STATE_DIM))
def test_each_sensor_parameter_affects_what_it_declares(sensor):
    # every parameter is changed in the defaults and in each configuration that another parameter chooses (a
    # frame, a value or none): a "simulation" one never changes the model, a "noise" one changes R (and std) only,
    # a "model" one something besides, each where its declared conditions hold, and nothing where they do not
    from workbench.plugins import load_host

    spec = load_host().sensor(sensor)
    declared = {p.name: p for p in spec.declared}
    assert declared and all(key in declared for p in declared.values() for key, _ in p.when)
    configs = [dict(spec.params)] + [
        {**spec.params, q.name: value} for q in declared.values() if q.choices or q.type.endswith("?")
        for value in ([c for c in q.choices if c != spec.params[q.name]] if q.choices else
                      [None if spec.params[q.name] is not None else _other(q, None)])]

    def view(values):
        return _model_view(spec.measurement_model(**values), STATE_DIM[sensor])

    for p in declared.values():
        reached = False
        for config in configs:
            changed = _changed(view(config), view({**config, p.name: _other(p, config[p.name])}))
            where = (sensor, p.name, {k: config[k] for k in config if config[k] != spec.params[k]}, changed)
            if not p.reaches_model(config):
                assert not changed, where
            elif p.affects == "noise":
                assert "R" in changed and changed <= {"R", "std"}, where
            else:
                assert changed - {"R", "std"}, where
            reached |= p.reaches_model(config)
        assert reached or p.affects == "simulation", (sensor, p.name, "never reaches the model in any configuration")
