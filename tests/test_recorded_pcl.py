"""Recorded passive-radar candidates (``workbench.recorded.pcl``): the CSV format, round trips, and one clear error
naming the file, the line and the column for every malformed input."""

from pathlib import Path

import numpy as np
import pytest

from workbench.models import linear_measurement, range_rate_model
from workbench.plugins import load_host
from workbench.recorded.pcl import load_pcl_candidates, write_pcl_candidates
from workbench.rng import generator
from workbench.sensing.bistatic import doppler_to_range_rate, wavelength
from workbench.tracking import GATE_99, NearestNeighbour, run, strongest_candidate_prior
from workbench.types import CLUTTER, InputError
from fixtures.candidates import IRREGULAR, frames

ROOT = Path(__file__).parents[1]
LAM = wavelength(701e6)


def test_shipped_example_loads_is_labelled_synthetic_and_tracks():
    path = ROOT / "examples" / "data" / "pcl_candidates_synthetic.csv"
    assert "SYNTHETIC" in path.read_text().splitlines()[0]
    scans = load_pcl_candidates(path)
    assert scans.batch == 1 and scans.steps == 120 and scans.origin is None
    np.testing.assert_allclose(np.diff(scans.times), 0.5)
    np.testing.assert_allclose(scans.z[..., 1][scans.valid], doppler_to_range_rate(scans.doppler[scans.valid], LAM))
    assert np.all(np.abs(scans.doppler[scans.valid]) >= 2.0)
    # a nearest-neighbour Kalman tracker runs on recorded candidates unchanged
    model = linear_measurement(np.eye(2), np.diag([15.0 ** 2, 0.5 ** 2]))
    prior, idx = strongest_candidate_prior(scans.scan(0), np.diag([50.0 ** 2, 5.0 ** 2]), [1500.0, 0.0])
    tr = run(load_host().filter("kf"), scans, range_rate_model(0.5, 1.0), model,
             association=NearestNeighbour(GATE_99, idx, 6), prior=prior, rng=generator(0))
    assert tr.records["updated"][0].sum() > 60


@pytest.mark.parametrize("columns", ["doppler", "range_rate", "both"])
def test_write_load_round_trip(tmp_path, columns):
    scans = frames([[(445.0, -5.0, 0), (1200.0, 12.0, CLUTTER)], [], [(440.0, -5.1, 0)]])
    path = write_pcl_candidates(tmp_path / "c.csv", scans, comments=["SYNTHETIC test"], columns=columns)
    back = load_pcl_candidates(path)
    np.testing.assert_array_equal(back.valid, scans.valid)
    np.testing.assert_allclose(back.z[back.valid], scans.z[scans.valid], atol=2e-3)
    np.testing.assert_allclose(back.times, scans.times)
    np.testing.assert_allclose(back.snr[back.valid], 10.0)
    assert path.read_text().startswith("# SYNTHETIC test\n")


def test_write_rejects_an_unknown_column_choice(tmp_path):
    with pytest.raises(InputError, match="columns must be"):
        write_pcl_candidates(tmp_path / "c.csv", frames([[(445.0, -5.0, 0)]]), columns="speed")


GOOD = "# c\nframe,time_s,bistatic_range_m,doppler_hz,strength_db\n0,0.0,445.0,12.0,18\n0,0.0,900,-3,10\n1,0.5,,,\n"


def test_the_good_file_reads_as_written(tmp_path):
    path = tmp_path / "good.csv"
    path.write_text(GOOD)
    scans = load_pcl_candidates(path)
    assert scans.z.shape == (1, 2, 2, 2)
    np.testing.assert_array_equal(scans.valid[0], [[True, True], [False, False]])
    np.testing.assert_allclose(scans.z[0, 0], [[445.0, -12.0 * LAM], [900.0, 3.0 * LAM]])
    np.testing.assert_allclose(scans.snr[0, 0], [18.0, 10.0])


@pytest.mark.parametrize("text,line,column", [
    (GOOD.replace("445.0", "abc"), 3, "bistatic_range_m"),
    (GOOD.replace("445.0", "nan"), 3, "bistatic_range_m"),
    (GOOD.replace("445.0", "-5"), 3, "bistatic_range_m"),
    (GOOD.replace(",-3,", ",inf,"), 4, "doppler_hz"),
    (GOOD.replace("0,0.0,900", "0.5,0.0,900"), 4, "frame"),
    (GOOD.replace("0,0.0,900", "0,0.1,900"), 4, "time_s"),
    (GOOD.replace("1,0.5,,,", "1,0.0,,,"), 5, "time_s"),
    (GOOD.replace(",-3,10", ",,10"), 4, "doppler_hz"),
    (GOOD.replace("0,0.0,445.0,12.0,18", "0,0.0,,12.0,18"), 3, "bistatic_range_m"),
])
def test_malformed_csv_names_line_and_column(tmp_path, text, line, column):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=rf"bad.csv line {line}, column '{column}'"):
        load_pcl_candidates(path)


@pytest.mark.parametrize("text,match", [
    (GOOD.replace("strength_db", "strength"), "line 2: unknown column 'strength'"),
    (GOOD.replace(",doppler_hz", ",range_m"), "line 2: unknown column"),
    (GOOD.replace("frame,time_s,bistatic_range_m,doppler_hz,strength_db", "frame,time_s,bistatic_range_m,strength_db")
     .replace(",12.0,", ",").replace(",-3,", ",").replace(",,,", ",,"), "need a 'doppler_hz' or a 'range_rate_mps'"),
    (GOOD.replace("0,0.0,900,-3,10", "0,0.0,900,-3"), "line 4: expected 5 fields"),
    (GOOD.replace("1,0.5,,,", "2,1.0,,,"), "frame 1 has no row"),
    ("# only comments\n", "no header"),
    (GOOD.replace("doppler_hz,strength_db", "doppler_hz,range_rate_mps,strength_db").replace("12.0,18", "12.0,1.0,18")
     .replace("-3,10", "-3,1.283,10").replace(",,,", ",,,,"), "line 3, column 'range_rate_mps': 1.0 m/s disagrees"),
])
def test_malformed_csv_structure(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        load_pcl_candidates(path)


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_pcl_candidates(tmp_path / "nope.csv")


# -- metadata, per-candidate accuracy, irregular times ------------------------------------------------------


def _write(tmp_path, text, name="c.csv", bom=False):
    path = tmp_path / name
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
    return path




def test_metadata_accuracy_and_a_byte_order_mark_are_read(tmp_path):
    from workbench.recorded.pcl import pcl_metadata

    path = _write(tmp_path, IRREGULAR, bom=True)
    meta = pcl_metadata(path)
    assert meta.carrier_hz == 701e6 and meta.transmitter_m == (0.0, -8400.0, 420.0)
    assert meta.receiver_m == (0.0, 0.0, 60.0)
    scans = load_pcl_candidates(path)
    np.testing.assert_array_equal(scans.times, [0.0, 0.4, 1.3, 1.5, 2.6])
    np.testing.assert_allclose(scans.cov[0, 2, 0], np.diag([30.0**2, 0.4**2]))
    with pytest.raises(InputError, match="declares carrier_hz 7.01e\\+08, but 6e\\+08 Hz was asked for"):
        load_pcl_candidates(path, frequency_hz=600e6)
    # the writer keeps the metadata and the accuracies: a round trip gives the same scans
    from workbench.recorded.pcl import write_pcl_candidates

    again = write_pcl_candidates(tmp_path / "w.csv", scans, columns="range_rate", transmitter_m=meta.transmitter_m,
                                 receiver_m=meta.receiver_m)
    back = load_pcl_candidates(again)
    np.testing.assert_allclose(back.z, scans.z, atol=1e-3)
    np.testing.assert_allclose(back.cov, scans.cov, rtol=1e-12)
    assert pcl_metadata(again) == meta


@pytest.mark.parametrize("line, fragment", [
    ("#! carrier: 701e6", "a '#!' line declares"),
    ("#! receiver_m: 0, 0, 60, 1", "2 or 3 coordinates"),
    ("#! carrier_hz: -5", "one number > 0"),
])
def test_bad_metadata_is_named(tmp_path, line, fragment):
    path = _write(tmp_path, IRREGULAR.replace("#! carrier_hz: 701e6", line))
    with pytest.raises(InputError, match=fragment):
        load_pcl_candidates(path)


def test_a_candidate_without_its_accuracy_is_refused(tmp_path):
    path = _write(tmp_path, IRREGULAR.replace("2,1.3,993.6,-5.0,20,30,0.4", "2,1.3,993.6,-5.0,20,,0.4"))
    with pytest.raises(InputError, match="line 8, column 'sigma_range_m': each candidate needs its accuracy"):
        load_pcl_candidates(path)


def test_irregular_times_are_honoured_by_the_time_loop(tmp_path):
    # the nearest-neighbour track of a recorded file with irregular times equals a hand-written Kalman filter whose
    # F and Q are built for each actual interval, with each candidate's own R
    from workbench.models import range_rate_model
    from workbench.plugins import load_host
    from workbench.tracking import NearestNeighbour, run
    from workbench.types import Gaussian

    scans = load_pcl_candidates(_write(tmp_path, IRREGULAR))
    host = load_host()
    model = host.sensor("dtv-pbr").measurement_model()
    motion = range_rate_model(0.5, 0.3)
    prior = Gaussian(np.array([[1000.0, -5.0]]), np.diag([100.0, 1.0])[None])
    track = run(host.filter("kf"), scans, motion, model, association=NearestNeighbour(), prior=prior)
    x, P = prior.mean[0], prior.cov[0]
    for k in range(1, scans.steps):
        step = range_rate_model(scans.times[k] - scans.times[k - 1], 0.3)
        x, P = step.F @ x, step.F @ P @ step.F.T + step.Q
        R = scans.cov[0, k, 0]
        S = P + R
        K = P @ np.linalg.inv(S)
        x = x + K @ (scans.z[0, k, 0] - x)
        P = (np.eye(2) - K) @ P @ (np.eye(2) - K).T + K @ R @ K.T
        np.testing.assert_allclose(track.mean[0, k], x, rtol=1e-9)
        np.testing.assert_allclose(track.cov[0, k], P, rtol=1e-9)
