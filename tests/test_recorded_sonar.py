"""Recorded active-sonar detections (``workbench.recorded.sonar``): round trips and one clear error per bad input."""

import numpy as np
import pytest

from workbench.recorded.sonar import load_sonar_csv, write_sonar_csv
from workbench.rng import generator
from workbench.types import InputError, Scans


def test_csv_round_trip_and_polar_columns(tmp_path):
    rng = generator(8, "csv")
    z = rng.uniform(0, 250, (1, 4, 3, 2)).round(3)
    valid = np.array([[[1, 1, 0], [0, 0, 0], [1, 1, 1], [1, 0, 0]]], bool)
    snr = rng.normal(10, 2, (1, 4, 3)).round(3)
    scans = Scans(z, valid, np.arange(4.0), snr=snr)
    back = load_sonar_csv(write_sonar_csv(tmp_path / "a.csv", scans, comments=["hello"]))
    assert back.steps == 4
    assert np.array_equal(back.valid.sum(axis=2), valid.sum(axis=2))
    assert np.allclose(np.sort(back.z[back.valid], axis=0), np.sort(z[valid], axis=0))
    assert np.allclose(np.sort(back.snr[back.valid]), np.sort(snr[valid]))
    polar = load_sonar_csv(write_sonar_csv(tmp_path / "p.csv", scans, frame="polar", digits=9))
    assert np.allclose(np.sort(polar.z[polar.valid], axis=0), np.sort(z[valid], axis=0), atol=1e-6)
    # times, a math bearing in degrees from +x
    f = tmp_path / "t.csv"
    f.write_text("time,range,bearing\n0.5,10,90\n0.5,20,0\n2.0,5,180\n")
    t = load_sonar_csv(f)
    assert np.allclose(t.times, [0.5, 2.0]) and np.allclose(t.z[0, 0][t.valid[0, 0]], [[0, 10], [20, 0]], atol=1e-12)
    assert np.allclose(t.z[0, 1, 0], [-5, 0], atol=1e-12) and np.all(np.isnan(t.snr[t.valid]))


@pytest.mark.parametrize("text, match", [
    ("ping,x,y,level\n0,1,2,3\n1,4,abc,3\n", "line 3, column 'y'"),
    ("# c\nping,x,y\n0,1,2\n-1,1,2\n", "line 4, column 'ping'"),
    ("ping,x,y\n0.5,1,2\n", "line 2, column 'ping'"),
    ("ping,x,y\n0,1\n", "line 2: expected 3 fields"),
    ("ping,x,y\n0,nan,2\n", "line 2, column 'x'"),
    ("ping,range,bearing\n0,-3,10\n", "line 2, column 'range'"),
    ("ping,x,z\n0,1,2\n", "line 1: unknown column 'z'"),
    ("ping,x\n0,1\n", "line 1: the header needs both"),
    ("ping,time,x,y\n0,0,1,2\n", "exactly one of 'ping' or 'time'"),
    ("# only comments\n", "no header"),
])
def test_csv_errors_name_the_line_and_column(tmp_path, text, match):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        load_sonar_csv(f)
    assert str(f) in str(info.value)
