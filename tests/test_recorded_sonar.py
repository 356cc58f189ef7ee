"""Recorded active-sonar detections (``workbench.recorded.sonar``): round trips, the own ship and each detection's
accuracy, a Kalman filter consistent on a recording from a moving ship, and one clear error per bad input."""

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

import workbench as wb
from workbench.recorded.sonar import OwnShip, load_sonar_csv, load_sonar_recording, write_sonar_csv
from workbench.recorded import ImplausibleValueWarning
from workbench.rng import generator
from workbench.types import InputError, Scans

DATA = Path(__file__).parents[1] / "examples" / "data"


def _example():
    spec = importlib.util.spec_from_file_location("sonar_moving_ship", DATA / "sonar_moving_ship.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


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
    ("ping,x,y,level\n0,1,,3\n", "line 2, column 'y': empty field"),
    ("time,x,y,own_x,own_y\n0,1,2,0,0\n0,3,4,0,1\n", "line 3: the own ship's position or heading of time 0"),
    ("#! bearing: relative\nping,range,bearing\n0,1,2\n", "needs range,bearing detections and a 'heading'"),
    ("#! bearing: north\nping,x,y\n0,1,2\n", "line 1: a '#!' line"),
    ("#! bearing: true\n#! bearing: true\nping,x,y\n0,1,2\n", "line 2: the bearing reference is declared twice"),
    ("ping,x,y,sigma_x\n0,1,2,3\n", "give both 'sigma_x' and 'sigma_y'"),
    ("ping,x,y,sigma_range,sigma_bearing\n0,1,2,3,4\n", "'sigma_range' belongs to range,bearing files"),
    ("ping,x,y,sigma_x,sigma_y\n0,1,2,0,1\n", "line 2, column 'sigma_x': an accuracy"),
    ("ping,range,bearing,sigma_range,sigma_bearing\n0,0,2,1,1\n", "line 2, column 'range': a detection at range 0"),
    ("ping,range,bearing,heading\n0,1,2,3\n", "'heading' needs the own ship's position"),
    ("ping,x,y,own_x\n0,1,2,3\n", "give both 'own_x' and 'own_y'"),
    ("ping,x,y,own_x,own_y\n0,1,2,0,0\n2,1,2,0,0\n", "ping 1 has no row, so no own-ship position"),
    ("ping,x,y\n0,1,2\n1,1,2\n100000,1,2\n", "line 4, column 'ping': ping 100000 would make 100001 pings"),
])
def test_csv_errors_name_the_line_and_column(tmp_path, text, match):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        load_sonar_csv(f)
    assert str(f) in str(info.value)


def test_bom_quoting_and_a_non_utf8_file(tmp_path):
    f = tmp_path / "q.csv"
    f.write_bytes('\ufeff# exported\n"ping","x","y"\n0,"1.5",2\n'.encode("utf-8"))
    scans = load_sonar_csv(f)
    assert np.allclose(scans.z[0, 0, 0], [1.5, 2.0])
    f.write_bytes(b"ping,x,y\n0,1,2\n1,\xb5,2\n")
    with pytest.raises(InputError, match="not UTF-8 text"):
        load_sonar_csv(f)
    # a sparse file is accepted when the ping count is asked for
    f.write_text("ping,x,y\n0,1,2\n5000,1,2\n")
    assert load_sonar_csv(f, pings=5001).steps == 5001


def test_own_ship_relative_bearing_and_accuracy_by_hand(tmp_path):
    f = tmp_path / "own.csv"
    f.write_text("#! bearing: relative\n"
                 "time,range,bearing,sigma_range,sigma_bearing,own_x,own_y,heading\n"
                 "0.0,100,90,2,1,10,20,0\n"
                 "0.0,50,0,3,0.5,10,20,0\n"
                 "2.5,,,,,30,20,90\n"
                 "7.0,100,-90,2,1,30,40,90\n")
    rec = load_sonar_recording(f)
    scans, own = rec.scans, rec.own_ship
    assert rec.bearing == "relative" and np.array_equal(scans.times, [0.0, 2.5, 7.0])
    assert np.array_equal(scans.valid.sum(axis=2)[0], [2, 0, 1])  # the ping without detections is kept
    # bow at 0 deg, 90 deg to port: straight up from (10, 20); bow at 90 deg, 90 deg to starboard: +x from (30, 40)
    np.testing.assert_allclose(scans.z[0, 0, :2], [[10, 120], [60, 20]], atol=1e-12)
    np.testing.assert_allclose(scans.z[0, 2, 0], [130, 40], atol=1e-12)
    np.testing.assert_array_equal(own.position, [[10, 20], [30, 20], [30, 40]])
    np.testing.assert_array_equal(own.heading_deg, [0, 90, 90])
    # along the line of sight the range's variance, across it (r sigma_b)^2
    sb = math.radians(1.0)
    np.testing.assert_allclose(scans.cov[0, 0, 0], np.diag([(100 * sb) ** 2, 4.0]), atol=1e-9)
    np.testing.assert_allclose(scans.cov[0, 2, 0], np.diag([4.0, (100 * sb) ** 2]), atol=1e-9)
    with pytest.raises(InputError, match="sensor= applies to files without it"):
        load_sonar_recording(f, sensor=(1.0, 0.0))


def test_writer_round_trips_irregular_times_own_ship_and_accuracy(tmp_path):
    rng = generator(3, "writer")
    T, M = 6, 3
    own = OwnShip(np.arange(T) * 1.0, rng.normal(0, 50, (T, 2)), rng.uniform(-180, 180, T))
    times = np.cumsum(rng.uniform(0.5, 3.0, T))
    valid = rng.random((1, T, M)) < 0.7
    valid[0, 2] = False
    r = rng.uniform(100, 1000, (1, T, M))
    b = rng.uniform(-np.pi, np.pi, (1, T, M))
    z = own.position[None, :, None, :] + r[..., None] * np.stack([np.cos(b), np.sin(b)], axis=-1)
    sr, sb = rng.uniform(1, 5, (1, T, M)), rng.uniform(0.001, 0.02, (1, T, M))
    c, s = np.cos(b), np.sin(b)
    J = np.stack([np.stack([c, -r * s], -1), np.stack([s, r * c], -1)], -2)
    cov = J @ (np.stack([sr ** 2, (r * 0 + sb) ** 2], -1)[..., None] * np.eye(2)) @ np.swapaxes(J, -1, -2)
    scans = Scans(z, valid, times, cov=cov)
    for frame, bearing in (("polar", "relative"), ("polar", "true"), ("xy", "true")):
        if frame == "xy":
            scans = Scans(z, valid, times, cov=np.broadcast_to(np.diag([4.0, 9.0]), (1, T, M, 2, 2)).copy())
        path = write_sonar_csv(tmp_path / f"{frame}-{bearing}.csv", scans, frame=frame, key="time", own_ship=own,
                               bearing=bearing, accuracy=True, digits=9)
        # the own ship's headings are drawn at random, not along its track: the loader says so, with the numbers
        with pytest.warns(ImplausibleValueWarning, match=r"heading differs from its course over ground .* median"):
            back = load_sonar_recording(path)
        np.testing.assert_array_equal(back.scans.times, times)
        np.testing.assert_array_equal(back.scans.valid.sum(axis=2), valid.sum(axis=2))
        np.testing.assert_allclose(back.scans.z[back.scans.valid], scans.z[valid], atol=1e-5)
        # the accuracies are written to 6 significant digits
        np.testing.assert_allclose(back.scans.cov[back.scans.valid], scans.cov[valid], rtol=1e-5,
                                   atol=1e-5 * np.abs(scans.cov[valid]).max())
        np.testing.assert_array_equal(back.own_ship.position, own.position)
    bad = Scans(z, valid, times, cov=np.broadcast_to([[4.0, 1.0], [1.0, 9.0]], (1, T, M, 2, 2)).copy())
    with pytest.raises(InputError, match="not diagonal in x, y"):
        write_sonar_csv(tmp_path / "bad.csv", bad, accuracy=True)


def test_the_shipped_moving_ship_recording_is_its_generators_output(tmp_path):
    example = _example()
    shipped = DATA / "sonar_moving_ship_synthetic.csv"
    assert example.write(tmp_path / "again.csv").read_text() == shipped.read_text()
    assert shipped.read_text().startswith("# SYNTHETIC")
    rec, scene = load_sonar_recording(shipped), example.scene()
    assert rec.bearing == "relative" and np.ptp(np.diff(rec.scans.times)) > 4  # irregular pings
    np.testing.assert_array_equal(rec.scans.times, scene.times)
    np.testing.assert_array_equal(rec.own_ship.position, scene.own_ship.position)
    v = scene.scans.valid
    np.testing.assert_array_equal(rec.scans.valid, v)
    assert not v[0, 40].any()  # the ping without detections is kept
    np.testing.assert_allclose(rec.scans.z[v], scene.scans.z[v], atol=0.02)  # 1e-4 deg at 6 km
    np.testing.assert_allclose(rec.scans.cov[v], scene.scans.cov[v], rtol=1e-4,
                               atol=1e-4 * np.abs(scene.scans.cov[v]).max())


def test_a_kalman_filter_on_recordings_from_a_moving_ship_is_consistent(tmp_path):
    """The target's detections read back from files of irregular pings, relative bearings and per-detection accuracy,
    filtered with each detection's covariance and the motion rebuilt per interval: the NEES against the truth is
    chi-square with 4 degrees of freedom.  Read as if the bearings were true and the sensor fixed, the same
    detections lie kilometres off."""
    example = _example()
    host = wb.load_host()
    kf = host.filter("kf")
    model = host.sensor("active-sonar").measurement_model(frame="cartesian")
    values, wrong = [], []
    for seed in range(30):
        scene = example.scene(seed)
        path = example.write(tmp_path / f"s{seed}.csv", seed)
        rec = load_sonar_recording(path).scans
        target = rec.valid[..., :1] & (scene.scans.origin[..., :1] == 0)
        scans = Scans(rec.z[:, :, :1], target, rec.times, cov=rec.cov[:, :, :1])
        x0 = scene.target[0]
        prior = wb.Gaussian.broadcast(x0 + [40.0, -30.0, 0.5, -0.5], np.diag([100.0 ** 2] * 2 + [2.0 ** 2] * 2), 1)
        track = wb.run(kf, scans, wb.constant_velocity(2, 4.0, example.SIGMA_A), model, prior=prior)
        values.append(wb.nees(scene.target, track.mean[0], track.cov[0])[10:])
        # the same file read without its own ship (sensor at the origin, bearings taken as true)
        d = np.linalg.norm(_naive(path)[:, :1][target[0]] - scene.target[target[0, :, 0], :2], axis=-1)
        wrong.append(np.median(d))
    # one mean per recording (the NEES of one track is correlated in time; the recordings are independent): their
    # average is 4, the chi-square's degrees of freedom, within 3 standard errors, and no recording is far off
    per = np.array([v.mean() for v in values])
    assert abs(per.mean() - 4.0) < 3.0 * per.std(ddof=1) / np.sqrt(per.size), per
    assert per.max() < chi2.ppf(0.9999, 4 * 50) / 50 * 2.0
    assert np.median(wrong) > 1000.0


def _naive(path: Path) -> np.ndarray:
    """Range and bearing of a recording converted from the origin with the bearing taken as true, ``(T, M, 2)``."""
    import csv

    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    rows = list(csv.DictReader(lines))
    times = sorted({float(r["time"]) for r in rows})
    out = np.full((len(times), max(sum(1 for r in rows if float(r["time"]) == t) for t in times), 2), np.nan)
    slot = dict.fromkeys(times, 0)
    for r in rows:
        if r["range"] == "":
            continue
        t = float(r["time"])
        k, j = times.index(t), slot[t]
        b = math.radians(float(r["bearing"]))
        out[k, j] = float(r["range"]) * math.cos(b), float(r["range"]) * math.sin(b)
        slot[t] += 1
    return out
