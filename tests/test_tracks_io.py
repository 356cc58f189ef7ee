"""Track files (workbench.tracks_io): exact round trips of a tracker's log and a filter's track, the documented
example, and a clear error for each kind of malformed file."""

import re
from pathlib import Path

import numpy as np
import pytest

from workbench.models import constant_velocity, linear_measurement
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking import CONFIRMED, TENTATIVE, NearestNeighbour, TrackLog, run
from workbench.tracks_io import read_tracks, state_layout, write_track, write_track_log, write_tracks
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, InputError, Scans

DOCS = Path(__file__).parents[1] / "docs" / "recorded-data.md"

# values whose text form is easy to get wrong: thirds, extremes, subnormals, negative zero
AWKWARD = np.array([1 / 3, -2 / 3, 0.1 + 0.2, 1e-300, 5e-324, 1.7976931348623157e308, -0.0, 123456789.123456789,
                    np.pi * 1e10, -np.e * 1e-10])


def _log(rng, runs=3, pings=7, n=4):
    rows = {"run": [], "ping": [], "track_id": [], "status": [], "hit": []}
    for b in range(runs):
        for k in range(pings):
            for i in rng.choice(6, size=int(rng.integers(0, 4)), replace=False):
                rows["run"].append(b)
                rows["ping"].append(k)
                rows["track_id"].append(int(i))
                rows["status"].append(CONFIRMED if rng.random() < 0.6 else TENTATIVE)
                rows["hit"].append(bool(rng.random() < 0.7))
    R = len(rows["run"])
    mean = rng.normal(size=(R, n)) * 10.0 ** rng.integers(-5, 6, size=(R, n))
    mean.flat[: AWKWARD.size] = AWKWARD
    return TrackLog(np.array(rows["run"]), np.array(rows["ping"]), np.array(rows["track_id"]),
                    np.array(rows["status"], dtype=np.int8), np.array(rows["hit"]), mean, runs, pings)


def _cov(rng, R, n):
    a = rng.normal(size=(R, n, n))
    return a @ np.swapaxes(a, 1, 2) + np.eye(n) / 3


def test_a_tracker_log_with_covariances_reads_back_exactly(tmp_path):
    rng = np.random.default_rng(1)
    log = _log(rng)
    cov = _cov(rng, log.run.size, 4)
    times = np.cumsum(rng.uniform(0.5, 1.5, size=log.pings)) / 3  # irregular, not short decimals
    path = write_track_log(tmp_path / "tracks.csv", log, times, motion=constant_velocity(2, 1.0, 0.1), cov=cov,
                           notes=["simulated", "seed 1"])
    back = read_tracks(path)
    assert back.names == ("x", "y", "vx", "vy") and back.units == ("m", "m", "m/s", "m/s")
    assert back.runs == log.runs and back.steps == log.pings and back.notes == ("simulated", "seed 1")
    assert np.array_equal(back.mean, log.mean) and np.array_equal(back.cov, cov)
    assert np.array_equal(np.signbit(back.mean), np.signbit(log.mean))  # even -0.0 survives
    assert np.array_equal(back.time, times[log.ping])
    again = back.to_track_log()
    for key in ("run", "ping", "track_id", "status", "hit", "mean"):
        assert np.array_equal(getattr(again, key), getattr(log, key)), key
    assert (again.runs, again.pings) == (log.runs, log.pings)
    # writing what was read gives the same file, byte for byte
    write_tracks(tmp_path / "again.csv", back)
    assert (tmp_path / "again.csv").read_bytes() == path.read_bytes()


def test_the_file_layout(tmp_path):
    rng = np.random.default_rng(2)
    log = _log(rng, runs=1, pings=3)
    path = write_track_log(tmp_path / "t.csv", log, np.arange(3.0), motion=constant_velocity(2, 1.0, 0.1),
                           cov=_cov(rng, log.run.size, 4))
    lines = path.read_text().splitlines()
    assert lines[:6] == ["# workbench track file", "# format: workbench-tracks 1",
                         "# state: x [m], y [m], vx [m/s], vy [m/s]", "# covariance: upper triangle", "# runs: 1",
                         "# steps: 3"]
    header = lines[6].split(",")
    assert header[:10] == ["run", "track", "step", "time", "status", "updated", "x", "y", "vx", "vy"]
    assert header[10:] == ["cov_x_x", "cov_x_y", "cov_x_vx", "cov_x_vy", "cov_y_y", "cov_y_vx", "cov_y_vy",
                           "cov_vx_vx", "cov_vx_vy", "cov_vy_vy"]
    assert len(lines) == 7 + log.run.size
    # without covariances: no covariance columns, and the header says so
    bare = read_tracks(write_track_log(tmp_path / "bare.csv", log, np.arange(3.0)))
    assert bare.cov is None and bare.names == ("s0", "s1", "s2", "s3") and bare.units == ("",) * 4
    assert "# covariance: none" in (tmp_path / "bare.csv").read_text()


def test_state_layout_from_the_motion_model_and_overrides():
    assert state_layout(6, constant_velocity(3, 1.0, 1.0))[0] == ("x", "y", "z", "vx", "vy", "vz")
    assert state_layout(2, constant_velocity(1, 1.0, 1.0)) == (("x", "vx"), ("m", "m/s"))
    assert state_layout(2, names=("R", "Rdot"), units=("m", "m/s")) == (("R", "Rdot"), ("m", "m/s"))
    with pytest.raises(InputError, match="motion model"):
        state_layout(4, constant_velocity(3, 1.0, 1.0))


def test_a_single_target_filter_track_reads_back_exactly(tmp_path):
    host = load_host()
    motion = constant_velocity(2, 1.0, 0.5)
    model = linear_measurement(np.eye(2, 4), np.eye(2) * 4.0, frame="cartesian-2d")
    rng = generator(4, "tracks-io")
    truth = sample_motion(np.tile([0.0, 0.0, 3.0, -1.0], (3, 1)), motion, 12, rng)
    z = truth.states[..., :2] + rng.normal(scale=2.0, size=(3, 12, 2))
    valid = rng.random((3, 12, 1)) < 0.8
    scans = Scans(z[:, :, None, :], valid, truth.times)
    prior = Gaussian.broadcast([0.0, 0.0, 3.0, -1.0], np.diag([4.0, 4.0, 1.0, 1.0]), 3)
    track = run(host.filter("kf"), scans, motion, model, association=NearestNeighbour(), prior=prior, rng=rng)
    path = write_track(tmp_path / "kf.csv", track, truth.times, motion=motion, notes=["kf on 3 runs"])
    back = read_tracks(path)
    mean, cov = back.single_target()
    assert np.array_equal(mean, track.mean) and np.array_equal(cov, track.cov)
    assert np.array_equal(back.updated.reshape(3, 12), track.records["updated"].astype(int))
    assert np.all(back.status == CONFIRMED) and np.all(back.track == 0)
    # a track without an 'updated' record leaves the column empty (unknown), which a TrackLog refuses
    direct = run(host.filter("kf"), scans.take(0), motion, model, prior=prior.take(0), rng=rng)
    unknown = read_tracks(write_track(tmp_path / "direct.csv", direct, truth.times))
    assert np.all(unknown.updated == -1)
    with pytest.raises(InputError, match="updated"):
        unknown.to_track_log()


def _documented_example() -> str:
    text = DOCS.read_text(encoding="utf-8")
    section = text[text.index("## Track files"):]
    return re.search(r"```csv\n(.*?)```", section, re.S).group(1)


def test_the_documented_example_reads(tmp_path):
    path = tmp_path / "example.csv"
    path.write_text(_documented_example())
    tracks = read_tracks(path)
    assert tracks.rows >= 3 and tracks.cov is not None and tracks.names[:2] == ("x", "y")
    assert np.allclose(tracks.cov, np.swapaxes(tracks.cov, 1, 2))
    assert set(tracks.status.tolist()) <= {TENTATIVE, CONFIRMED}


def test_a_byte_order_mark_and_windows_line_ends_are_read(tmp_path):
    rng = np.random.default_rng(3)
    log = _log(rng, runs=2, pings=3)
    src = write_track_log(tmp_path / "a.csv", log, np.arange(3.0), cov=_cov(rng, log.run.size, 4))
    dst = tmp_path / "b.csv"
    dst.write_bytes(b"\xef\xbb\xbf" + src.read_bytes().replace(b"\n", b"\r\n"))
    back = read_tracks(dst)
    assert np.array_equal(back.mean, log.mean)


GOOD = """# format: workbench-tracks 1
# state: x [m], y [m]
# covariance: none
# runs: 2
# steps: 3
run,track,step,time,status,updated,x,y
0,0,0,0.0,tentative,1,1.5,2.5
1,4,2,2.0,confirmed,,3.0,4.0
"""


@pytest.mark.parametrize("edit, fragment", [
    (lambda s: s.replace("1,4,2,2.0,confirmed,,3.0,4.0", "1,4,2,2.0,confirmed,,3.0"),
     "line 8: expected 8 fields, got 7"),
    (lambda s: s.replace("3.0,4.0", "3.0,abc"), "line 8, column 'y': expected a finite number, got 'abc'"),
    (lambda s: s.replace("3.0,4.0", "nan,4.0"), "line 8, column 'x': expected a finite number, got 'nan'"),
    (lambda s: s.replace("confirmed", "lost"), "line 8, column 'status': expected tentative or confirmed"),
    (lambda s: s.replace("1,4,2", "2,4,2"), "line 8, column 'run': run 2 is not below the header's runs (2)"),
    (lambda s: s.replace("1,4,2", "1,4,3"), "column 'step': step 3 is not below the header's steps (3)"),
    (lambda s: s.replace("1,4,2", "1,-4,2"), "column 'track': expected an integer >= 0, got '-4'"),
    (lambda s: s.replace(",,3.0", ",yes,3.0"), "column 'updated': expected 1, 0 or an empty field"),
    (lambda s: s + "1,4,2,2.0,confirmed,,3.0,4.0\n", "track 4 of run 1 appears twice at step 2 (lines 8 and 9)"),
    (lambda s: s.replace("workbench-tracks 1", "workbench-tracks 2"), "line 1: format version 2 is not supported"),
    (lambda s: s.replace("# format: workbench-tracks 1\n", ""), "not a workbench track file"),
    (lambda s: s.replace("x [m], y [m]", "x [m], y"), "line 2: a state component must read 'name [unit]'"),
    (lambda s: s.replace("# runs: 2", "# runs: two"), "line 4: 'runs' must be an integer"),
    (lambda s: s.replace("# covariance: none", "# covariance: full"), "expected '# covariance: upper triangle'"),
    (lambda s: s.replace("updated,x,y", "updated,x,z"), "line 6: the column header does not match"),
    (lambda s: s.replace("# runs: 2\n", ""), "no '# runs: ...' line"),
    # content, not only structure: one time per step, increasing with the step
    (lambda s: s + "0,1,2,2.5,tentative,1,1.0,1.0\n", "line 9, column 'time': step 2 has time 2.0 on line 8 but 2.5 "
                                                      "here (track 1, run 0)"),
    (lambda s: s.replace("1,4,2,2.0", "1,4,2,-1.0"), "line 8, column 'time': step 2 has time -1.0, not after step 0's "
                                                     "0.0 (line 7)"),
])
def test_a_malformed_file_is_refused_with_its_line_and_column(tmp_path, edit, fragment):
    ok = tmp_path / "ok.csv"
    ok.write_text(GOOD)
    assert read_tracks(ok).rows == 2
    bad = tmp_path / "bad.csv"
    bad.write_text(edit(GOOD))
    with pytest.raises(InputError) as err:
        read_tracks(bad)
    assert fragment in str(err.value) and str(bad) in str(err.value)


def test_writers_refuse_bad_input(tmp_path):
    rng = np.random.default_rng(5)
    log = _log(rng, runs=1, pings=3)
    with pytest.raises(InputError, match="times must have shape"):
        write_track_log(tmp_path / "t.csv", log, np.arange(4.0))
    with pytest.raises(InputError, match="cov must have shape"):
        write_track_log(tmp_path / "t.csv", log, np.arange(3.0), cov=np.zeros((1, 4, 4)))
    with pytest.raises(InputError, match="state name"):
        write_track_log(tmp_path / "t.csv", log, np.arange(3.0), names=("x", "y", "v x", "vy"))


def test_a_track_file_that_is_not_utf8_is_one_named_error(tmp_path):
    from workbench.types import InputError

    path = tmp_path / "t.csv"
    path.write_bytes(b"\xff\xfe# workbench track file\n")
    with pytest.raises(InputError, match="not UTF-8"):
        read_tracks(path)
