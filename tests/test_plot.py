"""workbench.plot (issue 27 item 1): what each function draws, read back from the Axes (the lines' data against the
input records or a hand computation, markers at first and last points, chi-square band limits against
scipy.stats.chi2, ellipse vertices on the quadratic form, axis labels with units), the figures of `workbench run`
on the manoeuvring and multi-target examples made small, and docs/plotting.md run as written."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from scipy.stats import chi2  # noqa: E402

import workbench as wb  # noqa: E402
from workbench import plot  # noqa: E402
from workbench.tracking import CONFIRMED, TENTATIVE, TrackLog  # noqa: E402
from workbench.truth import MultiTruth  # noqa: E402
from workbench.types import CLUTTER, InputError, Scans, Truth  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "scenarios"
CV = wb.constant_velocity(2, 1.0, 0.1)


def _ax():
    return Figure().add_subplot(1, 1, 1)


def _lines(ax, prefix: str) -> list:
    return [ln for ln in ax.lines if str(ln.get_gid()).startswith(prefix)]


def _one(ax, gid: str):
    found = [ln for ln in ax.lines if ln.get_gid() == gid]
    assert len(found) == 1, (gid, [ln.get_gid() for ln in ax.lines])
    return found[0]


def _xy(line) -> np.ndarray:
    return np.column_stack([line.get_xdata(), line.get_ydata()]).astype(float)


def _random_truth(B=3, T=12, seed=0) -> Truth:
    rng = np.random.default_rng(seed)
    return Truth(rng.normal(size=(B, T, 4)).cumsum(axis=1), np.arange(T) * 0.5 + 2.0)


def test_the_package_import_does_not_load_matplotlib():
    import subprocess
    import sys

    code = "import sys, workbench; assert 'matplotlib' not in sys.modules and workbench.plot.truth; print('ok')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "ok"


def test_truth_draws_the_chosen_run_with_a_start_marker_and_state_units():
    truth = _random_truth()
    ax = plot.truth(_ax(), truth, run=1, motion=CV)
    line = _one(ax, "truth:truth")
    np.testing.assert_array_equal(_xy(line), truth.states[1, :, :2])
    np.testing.assert_array_equal(_xy(_one(ax, "truth-start:truth")), truth.states[1, :1, :2])
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    # one component over time: x is the truth's times, y the velocity with its unit
    ax = plot.truth(_ax(), truth, run=2, dims=3, motion=CV)
    np.testing.assert_array_equal(_xy(_one(ax, "truth:truth")), np.column_stack([truth.times,
                                                                                 truth.states[2, :, 3]]))
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (s)", "vy (m/s)")
    # without a motion model nothing is guessed
    ax = plot.truth(_ax(), truth)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("state component 0", "state component 1")


def test_multi_truth_draws_one_line_per_live_object_over_its_live_scans():
    B, T, K = 2, 10, 3
    rng = np.random.default_rng(1)
    states = rng.normal(size=(B, T, K, 4)).cumsum(axis=1)
    alive = np.zeros((B, T, K), dtype=bool)
    alive[0, :, 0] = True
    alive[0, 3:7, 1] = True   # born at scan 3, gone after scan 6
    alive[1, :, 2] = True     # object 2 only lives in run 1
    mt = MultiTruth(states, alive, np.arange(T, dtype=float), labels=("a", "b", "c"))
    ax = plot.truth(_ax(), mt, run=0, motion=CV)
    assert sorted(ln.get_gid() for ln in _lines(ax, "truth:")) == ["truth:a", "truth:b"]
    np.testing.assert_array_equal(_xy(_one(ax, "truth:b")), states[0, 3:7, 1, :2])
    np.testing.assert_array_equal(_xy(_one(ax, "truth-start:b")), states[0, 3:4, 1, :2])
    assert [t.get_text() for t in ax.texts] == ["a", "b"]


def _scans_with_origin() -> Scans:
    # two runs, three scans, up to three detections: target 0, target 1 and clutter mixed, some invalid
    z = np.arange(2 * 3 * 3 * 2, dtype=float).reshape(2, 3, 3, 2) + 1.0
    valid = np.ones((2, 3, 3), dtype=bool)
    valid[0, 1, 2] = False
    origin = np.array([[[0, CLUTTER, 1], [CLUTTER, 0, 0], [1, 1, CLUTTER]]] * 2)
    return Scans(z, valid, np.array([0.0, 1.5, 3.0]), origin=origin)


def test_detections_tell_clutter_from_targets_by_origin():
    scans = _scans_with_origin()
    ax = plot.detections(_ax(), scans, frame="cartesian-2d")
    z, v, o = scans.z[0], scans.valid[0], scans.origin[0]
    np.testing.assert_array_equal(_xy(_one(ax, "detections:clutter")), z[v & (o == CLUTTER)])
    np.testing.assert_array_equal(_xy(_one(ax, "detections:target detections")), z[v & (o != CLUTTER)])
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    # no origin (recorded data): one group
    bare = Scans(scans.z, scans.valid, scans.times)
    ax = plot.detections(_ax(), bare, run=1, frame="cartesian-2d")
    assert [ln.get_gid() for ln in ax.lines] == ["detections:detections"]
    assert len(ax.lines[0].get_xdata()) == int(scans.valid[1].sum())


def test_range_bearing_detections_are_drawn_as_positions_from_the_sensor():
    model = wb.range_bearing(1.0, 0.01, sensor=(10.0, -5.0))
    r = np.array([[[100.0], [50.0]]])
    b = np.array([[[0.3], [2.0]]])
    scans = Scans(np.stack([r, b], axis=-1), np.ones((1, 2, 1), dtype=bool), np.array([0.0, 1.0]))  # (1, 2, 1, 2)
    ax = plot.detections(_ax(), scans, model=model)
    # by hand: the sensor position plus range along the bearing, counter-clockwise from +x
    expect = np.array([[10.0 + 100.0 * np.cos(0.3), -5.0 + 100.0 * np.sin(0.3)],
                       [10.0 + 50.0 * np.cos(2.0), -5.0 + 50.0 * np.sin(2.0)]])
    np.testing.assert_allclose(_xy(_one(ax, "detections:detections")), expect, rtol=1e-12)
    # one component over time, labelled by the frame
    ax = plot.detections(_ax(), scans, model=model, component=1)
    np.testing.assert_array_equal(_xy(ax.lines[0]), [[0.0, 0.3], [1.0, 2.0]])
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (s)", "bearing (rad)")
    with pytest.raises(InputError, match="frame 'bearing' gives no position in the plane"):
        plot.detections(_ax(), Scans(b[..., None], np.ones((1, 2, 1), dtype=bool), np.array([0.0, 1.0])),
                        frame="bearing")
    with pytest.raises(InputError, match="unknown measurement frame 'polar-ish'"):
        plot.detections(_ax(), scans, frame="polar-ish")


def _log() -> TrackLog:
    # run 0: track 7 confirmed over pings 1-4 (rows shuffled), track 3 tentative then confirmed, track 9 never
    # confirmed; run 1: track 2
    rows = [  # run, ping, id, status, x, y
        (0, 3, 7, CONFIRMED, 3.0, 30.0), (0, 1, 7, CONFIRMED, 1.0, 10.0), (0, 4, 7, CONFIRMED, 4.0, 40.0),
        (0, 2, 7, CONFIRMED, 2.0, 20.0), (0, 0, 3, TENTATIVE, -1.0, 0.0), (0, 1, 3, CONFIRMED, -2.0, 1.0),
        (0, 2, 3, CONFIRMED, -3.0, 2.0), (0, 2, 9, TENTATIVE, 50.0, 50.0), (1, 0, 2, CONFIRMED, 0.0, 0.0),
        (1, 1, 2, CONFIRMED, 1.0, 1.0)]
    a = np.array(rows, dtype=float)
    mean = np.column_stack([a[:, 4], a[:, 5], np.zeros(len(a)), np.zeros(len(a))])
    return TrackLog(a[:, 0].astype(int), a[:, 1].astype(int), a[:, 2].astype(int), a[:, 3].astype(int),
                    np.ones(len(a), dtype=bool), mean, runs=2, pings=5)


def test_tracks_draw_one_line_per_identity_in_ping_order_with_start_and_end_markers():
    log = _log()
    ax = plot.tracks(_ax(), log, motion=CV, label="mofn")
    tracks = _lines(ax, "track:mofn:")
    assert sorted(ln.get_gid() for ln in tracks) == ["track:mofn:3", "track:mofn:7"]   # 9 was never confirmed
    np.testing.assert_array_equal(_xy(_one(ax, "track:mofn:7")), [[1, 10], [2, 20], [3, 30], [4, 40]])
    np.testing.assert_array_equal(_xy(_one(ax, "track:mofn:3")), [[-2, 1], [-3, 2]])
    np.testing.assert_array_equal(_xy(_one(ax, "track-start:mofn:7")), [[1, 10]])
    np.testing.assert_array_equal(_xy(_one(ax, "track-end:mofn:7")), [[4, 40]])
    assert len({ln.get_color() for ln in tracks}) == 1 and (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    # every identity, tentative rows too
    ax = plot.tracks(_ax(), log, confirmed_only=False, label="all")
    assert len(_lines(ax, "track:all:")) == 3
    np.testing.assert_array_equal(_xy(_one(ax, "track-start:all:3")), [[-1, 0]])
    # over time: x is the pings' times
    ax = plot.tracks(_ax(), log, run=1, dims=1, times=np.arange(5) * 2.0, label="t")
    np.testing.assert_array_equal(_xy(_one(ax, "track:t:2")), [[0, 0], [2, 1]])
    assert ax.get_xlabel() == "time (s)"


def test_estimate_and_its_ellipses_lie_on_the_quadratic_form():
    rng = np.random.default_rng(3)
    B, T = 2, 6
    mean = rng.normal(size=(B, T, 4)) * 10
    L = rng.normal(size=(B, T, 4, 4))
    cov = L @ np.swapaxes(L, -1, -2) + 0.1 * np.eye(4)
    track = wb.Track("kf", mean, cov, mean, {})
    ax = plot.estimate(_ax(), track, run=1, motion=CV, ellipse_steps=[0, 4], n_sigma=2.0)
    np.testing.assert_array_equal(_xy(_one(ax, "estimate:kf")), mean[1, :, :2])
    np.testing.assert_array_equal(_xy(_one(ax, "estimate-start:kf")), mean[1, :1, :2])
    patches = {p.get_gid(): p for p in ax.patches}
    assert sorted(patches) == ["ellipse:0", "ellipse:4"]
    for k in (0, 4):
        v = patches[f"ellipse:{k}"].get_xy()[:-1] - mean[1, k, :2]  # the polygon closes on its first vertex
        P = cov[1, k, :2, :2]
        q = np.einsum("ij,ij->i", v, np.linalg.solve(P, v.T).T)
        np.testing.assert_allclose(q, 4.0, rtol=1e-9)
        # the extent along x is n_sigma sqrt(P_xx) (72 vertices: within 0.1 %)
        assert np.abs(v[:, 0]).max() == pytest.approx(2.0 * np.sqrt(P[0, 0]), rel=2e-3)
    with pytest.raises(InputError, match="ellipse_steps need the estimate's covariances"):
        plot.estimate(_ax(), mean, ellipse_steps=[1])


def test_nees_band_is_the_two_sided_chi2_interval_of_the_run_average():
    rng = np.random.default_rng(4)
    values = rng.chisquare(4, size=(25, 8))
    ax = plot.nees(_ax(), values, dof=4, times=np.arange(8) * 2.0)
    line = _one(ax, "nees:NEES")
    np.testing.assert_allclose(line.get_ydata(), [values[:, k].sum() / 25 for k in range(8)], rtol=1e-12)
    np.testing.assert_array_equal(line.get_xdata(), np.arange(8) * 2.0)
    np.testing.assert_allclose(_one(ax, "band-lower:NEES").get_ydata(), chi2.ppf(0.025, 100) / 25, rtol=1e-12)
    np.testing.assert_allclose(_one(ax, "band-upper:NEES").get_ydata(), chi2.ppf(0.975, 100) / 25, rtol=1e-12)
    assert ax.get_ylabel() == "NEES (dimensionless; 4 dof)" and ax.get_xlabel() == "time (s)"
    # means over a declared number of runs
    ax = plot.nees(_ax(), values.mean(axis=0), dof=4, runs=25)
    np.testing.assert_allclose(_one(ax, "band-upper:NEES").get_ydata(), chi2.ppf(0.975, 100) / 25, rtol=1e-12)
    with pytest.raises(InputError, match="say over how many"):
        plot.nees(_ax(), values.mean(axis=0), dof=4)
    with pytest.raises(InputError, match="hold 25 runs, but runs=3"):
        plot.nees(_ax(), values, dof=4, runs=3)


def test_nis_leaves_out_runs_without_an_update_and_reads_an_innovations_record():
    from workbench.kalman_core import Innovations

    rng = np.random.default_rng(5)
    B, T = 6, 5
    nis = rng.chisquare(2, size=(B, T))
    present = rng.random((B, T)) < 0.7
    present[:, 0] = False   # nobody updated at scan 0
    rec = Innovations(np.zeros((B, T, 2)), np.zeros((B, T, 2, 2)), np.where(present, nis, np.nan),
                      np.zeros((B, T)), present)
    ax = plot.nis(_ax(), rec)
    ys = _one(ax, "nis:NIS").get_ydata()
    lo = _one(ax, "band-lower:NIS").get_ydata()
    for k in range(T):
        n = int(present[:, k].sum())
        if n == 0:
            assert np.isnan(ys[k]) and np.isnan(lo[k])
        else:
            assert ys[k] == pytest.approx(sum(nis[b, k] for b in range(B) if present[b, k]) / n, rel=1e-12)
            assert lo[k] == pytest.approx(chi2.ppf(0.025, 2 * n) / n, rel=1e-12)
    assert ax.get_ylabel() == "NIS (dimensionless; 2 dof)"
    with pytest.raises(InputError, match="dof .the measurement dimension. is needed"):
        plot.nis(_ax(), nis)


def _plain(label: str) -> bool:
    return label == "" or re.fullmatch(r"-?[0-9]+(\.[0-9]+)?", label) is not None


def test_rmse_against_a_hand_loop_on_a_log_axis_with_plain_tick_labels():
    truth = _random_truth(B=4, T=9, seed=6)
    est = truth.states + np.random.default_rng(7).normal(size=truth.states.shape) * np.array([0.3, 40, 0, 0])
    ax = plot.rmse(_ax(), truth, est, motion=CV, label="kf")
    line = _one(ax, "rmse:kf")
    expect = [np.sqrt(np.mean([(truth.states[b, k, 0] - est[b, k, 0]) ** 2 + (truth.states[b, k, 1] - est[b, k, 1])
                               ** 2 for b in range(4)])) for k in range(9)]
    np.testing.assert_allclose(line.get_ydata(), expect, rtol=1e-12)
    np.testing.assert_array_equal(line.get_xdata(), truth.times)
    assert ax.get_yscale() == "log" and ax.get_ylabel() == "position RMSE (m)"
    ax.figure.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels(minor=False) + ax.get_yticklabels(minor=True)]
    assert any(labels) and all(_plain(t) for t in labels), labels
    with pytest.raises(InputError, match="say which components are the position"):
        plot.rmse(_ax(), truth, est)


def test_log_axis_spanning_under_a_decade_labels_its_minor_ticks_plainly():
    ax = _ax()
    ax.plot([1, 2], [0.6, 4.0])
    plot.log_axis(ax)
    ax.figure.canvas.draw()
    minor = [t.get_text() for t in ax.get_yticklabels(minor=True) if t.get_text()]
    assert "0.6" in minor and "2" in minor and all(_plain(t) for t in minor), minor


def test_gospa_and_track_counts_draw_the_mean_over_runs():
    per_scan = np.random.default_rng(8).random((3, 7)) * 10
    ax = plot.gospa(_ax(), per_scan, times=np.arange(7.0), cutoff=10, order=2, unit="m", label="gnn")
    np.testing.assert_allclose(_one(ax, "gospa:gnn").get_ydata(), per_scan.sum(axis=0) / 3, rtol=1e-12)
    assert ax.get_ylabel() == "GOSPA (m; c = 10 m, p = 2, mean over 3 runs)"
    ax = plot.track_counts(_ax(), _log())
    # confirmed tracks per ping, counted by hand from _log: run 0 [0, 2, 2, 1, 1], run 1 [1, 1, 0, 0, 0]
    np.testing.assert_array_equal(_one(ax, "track_counts:confirmed tracks").get_ydata(), [0.5, 1.5, 1, 0.5, 0.5])


def test_bad_arguments_are_refused_by_name():
    truth = _random_truth()
    with pytest.raises(InputError, match=r"plot.truth: run must be an integer in \[0, 3\), got 3"):
        plot.truth(_ax(), truth, run=3)
    with pytest.raises(InputError, match="plot.truth: dims must be one state component"):
        plot.truth(_ax(), truth, dims=(0, 4))
    with pytest.raises(InputError, match="plot.truth: ax must be a Matplotlib Axes or None, got str"):
        plot.truth("ax", truth)
    with pytest.raises(InputError, match="plot.tracks: log must be a TrackLog"):
        plot.tracks(_ax(), truth)


def _distinct_styles(lines) -> bool:
    """Each line its own colour and its own line style (so that one drawn over another leaves it visible)."""
    return len({ln.get_color() for ln in lines}) == len({ln.get_linestyle() for ln in lines}) == len(lines) > 1


@pytest.mark.slow  # about 6 s on 2 shared cores: three filters (IMM included) and the figure
def test_workbench_run_manoeuvring_figure_holds_truth_estimates_and_rmse(tmp_path):
    host = wb.load_host()
    from workbench.scenario import load_scenario, run_scenario

    scenario = dataclasses.replace(load_scenario(EXAMPLES / "manoeuvring.toml", host), runs=2, steps=25)
    result = run_scenario(scenario, host, tmp_path)
    arrays = np.load(tmp_path / "results.npz")
    left, right = result.figure.axes
    np.testing.assert_array_equal(_xy(_one(left, "truth:truth")), arrays["truth"][0, :, :2])
    estimates = [_one(left, f"estimate:{name}") for name in ("ekf", "ukf", "imm")]
    for name, line in zip(("ekf", "ukf", "imm"), estimates):
        np.testing.assert_array_equal(_xy(line), arrays[f"mean_{name}"][0, :, :2])
        np.testing.assert_array_equal(_xy(_one(left, f"estimate-start:{name}")), arrays[f"mean_{name}"][0, :1, :2])
        err = arrays["truth"][..., :2] - arrays[f"mean_{name}"][..., :2]
        np.testing.assert_allclose(_one(right, f"rmse:{name}").get_ydata(),
                                   np.sqrt((err ** 2).sum(axis=-1).mean(axis=0)), rtol=1e-12)
    assert _distinct_styles(estimates) and _distinct_styles(_lines(right, "rmse:"))
    assert len(_lines(left, "detections:")) >= 1
    assert (left.get_xlabel(), left.get_ylabel(), right.get_xlabel(), right.get_ylabel()) == \
        ("x (m)", "y (m)", "time (s)", "position RMSE (m)")
    assert right.get_yscale() == "log" and (tmp_path / "tracks.png").stat().st_size > 0


@pytest.mark.slow  # about 5 s on 2 shared cores: two trackers and the figure
def test_workbench_run_multi_target_figure_holds_objects_tracks_and_gospa(tmp_path):
    host = wb.load_host()
    from workbench.scenario import load_scenario, run_scenario

    scenario = dataclasses.replace(load_scenario(EXAMPLES / "multi_target.toml", host), runs=2, steps=30)
    result = run_scenario(scenario, host, tmp_path)
    arrays = np.load(tmp_path / "results.npz")
    left, right = result.figure.axes
    alive = arrays["alive"][0]
    assert len(_lines(left, "truth:")) == int(alive.any(axis=0).sum())
    for k in np.flatnonzero(alive.any(axis=0)):
        live = np.flatnonzero(alive[:, k])
        starts = [ln for ln in _lines(left, "truth-start:") if np.array_equal(_xy(ln)[0], arrays["truth"][0, live[0],
                                                                                                          k, :2])]
        assert len(starts) == 1
    valid, origin = arrays["valid"][0], arrays["origin"][0]
    assert len(_one(left, "detections:clutter").get_xdata()) == int((valid & (origin == CLUTTER)).sum())
    assert len(_one(left, "detections:target detections").get_xdata()) == int((valid & (origin != CLUTTER)).sum())
    for label in ("gnn/kf", "mofn/kf"):
        log = TrackLog.from_arrays(arrays, prefix=f"{label}_")
        confirmed = (log.run == 0) & (log.status == CONFIRMED)
        assert len(_lines(left, f"track:{label}:")) == np.unique(log.track_id[confirmed]).size > 0
        np.testing.assert_allclose(_one(right, f"gospa:{label}").get_ydata(),
                                   arrays[f"gospa_{label}"].mean(axis=0), rtol=1e-12)
    assert _distinct_styles(_lines(right, "gospa:"))
    assert (left.get_xlabel(), left.get_ylabel(), right.get_xlabel()) == ("x (m)", "y (m)", "time (s)")
    assert right.get_ylabel() == "GOSPA (m; c = 10 m, p = 2, mean over 2 runs)"


@pytest.mark.slow  # about 5 s: the page's three examples
def test_plotting_page_runs_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "plotting.md").read_text(encoding="utf-8"),
                        flags=re.S)
    assert len(blocks) == 3
    ns: dict = {}
    for code in blocks:
        exec(compile(code, "docs/plotting.md", "exec"), ns)  # noqa: S102 - the documented code itself
    assert capsys.readouterr().out.splitlines() == ["x (m) / y (m)", "position RMSE (m)"]
    assert (tmp_path / "one-target.png").stat().st_size > 0
    first = ns["fig"].axes[0]
    np.testing.assert_array_equal(_xy(_one(first, "estimate:ekf")), ns["track"].mean[0, :, :2])
    assert len([p for p in first.patches if str(p.get_gid()).startswith("ellipse:")]) == 3
    log = ns["log"]
    tracks = _lines(ns["fig2"].axes[0], "track:M-of-N:")
    assert len(tracks) == np.unique(log.track_id[(log.run == 0) & (log.status == CONFIRMED)]).size


@pytest.mark.slow  # about 4 s: the recorded file's 120 scans through the nearest-neighbour Kalman tracker
def test_workbench_run_on_recorded_data_prints_its_summary_and_draws_nis(tmp_path):
    host = wb.load_host()
    from workbench.scenario import load_scenario, run_scenario

    result = run_scenario(load_scenario(EXAMPLES / "pcl_recorded.toml", host), host, tmp_path)
    arrays = np.load(tmp_path / "results.npz")
    left, right = result.figure.axes
    # no position in the bistatic range-rate frame: the first measured component over time
    valid = arrays["valid"][0]
    det = _xy(_one(left, "detections:detections"))
    np.testing.assert_array_equal(det[:, 1], arrays["z"][0][valid][:, 0])
    np.testing.assert_array_equal(_xy(_one(left, "estimate:kf")),
                                  np.column_stack([arrays["times"], arrays["mean_kf"][0, :, 0]]))
    assert (left.get_xlabel(), left.get_ylabel()) == ("time (s)", "bistatic range (m)")
    nis = _one(right, "nis:kf").get_ydata()
    updated = np.isfinite(nis)
    # one run: each step's band is that of a single chi-square(2) value
    np.testing.assert_allclose(_one(right, "band-upper:kf").get_ydata()[updated], chi2.ppf(0.975, 2), rtol=1e-12)
    line = [ln for ln in result.summary_text().splitlines() if "recorded data" in ln]
    assert len(line) == 1
    m = re.search(r"recorded data: (\d+) scans, (\d+) detections; tracks: kf: 1 track, updated on (\d+) and coasted "
                  r"on (\d+) scans, mean NIS ([0-9.]+) \((inside|OUTSIDE) the 95 % band \[([0-9.]+), ([0-9.]+)\] of a "
                  r"mean of (\d+) updates, 2 dof\)", line[0])
    assert m, line[0]
    steps, detections, n_up, n_coast, mean, _, lo, hi, n = m.groups()
    assert (int(steps), int(detections)) == (arrays["times"].size, int(arrays["valid"].sum()))
    assert int(n_up) == int(n) == int(updated.sum()) and int(n_up) + int(n_coast) == int(steps) - 1
    N = int(n)
    assert (mean, lo, hi) == tuple(f"{v:.3g}" for v in (nis[updated].mean(), chi2.ppf(0.025, 2 * N) / N,
                                                          chi2.ppf(0.975, 2 * N) / N))


def test_nis_density_draws_the_histogram_and_the_chi2_density_in_closed_form():
    edges = np.linspace(0.0, 12.0, 25)
    samples = wb.generator(20, "plot", "nis-density").chisquare(3, size=4000)
    density = np.histogram(np.minimum(samples, edges[-1] - 1e-9), edges, density=True)[0]
    ax = plot.nis_density(_ax(), density, edges, 3, label="kf", color="C1")
    mid = (edges[1:] + edges[:-1]) / 2
    np.testing.assert_array_equal(_xy(_one(ax, "nis-density:kf")), np.column_stack([mid, density]))
    # the chi-square(3) density in closed form: sqrt(x) exp(-x/2) / sqrt(2 pi)
    ref = _one(ax, "chi2-density:3")
    np.testing.assert_array_equal(ref.get_xdata(), mid)
    np.testing.assert_allclose(ref.get_ydata(), np.sqrt(mid) * np.exp(-mid / 2) / np.sqrt(2 * np.pi), rtol=1e-12)
    assert ref.get_label() == "chi-square, 3 dof"
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("NIS (dimensionless; 3 dof)", "probability density")
    assert ax.get_yscale() == "log"
    ax.figure.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels(minor=False) + ax.get_yticklabels(minor=True)]
    assert any(labels) and all(_plain(t) for t in labels), labels
    # a second histogram on the same Axes leaves the reference out
    plot.nis_density(ax, density / 2, edges, 3, label="other", reference=False)
    assert len(_lines(ax, "chi2-density")) == 1 and len(_lines(ax, "nis-density")) == 2
    with pytest.raises(InputError, match=r"plot.nis_density: density must have one value per bin, shape \(24,\)"):
        plot.nis_density(_ax(), density[:-1], edges, 3)
    with pytest.raises(InputError, match="plot.nis_density: edges must be finite and increasing"):
        plot.nis_density(_ax(), density, edges[::-1], 3)
    with pytest.raises(InputError, match="plot.nis_density: dof must be a positive integer"):
        plot.nis_density(_ax(), density, edges, 0)


def test_error_over_time_draws_the_given_curve_with_its_quantity_and_unit():
    values = wb.generator(21, "plot", "error").random(8) * 50 + 0.5
    times = np.arange(8) * 0.25 + 1.0
    ax = plot.error_over_time(_ax(), values, times=times, quantity="position MSE", unit="m^2", label="ukf",
                              linestyle="--")
    line = _one(ax, "error:ukf")
    np.testing.assert_array_equal(_xy(line), np.column_stack([times, values]))
    assert line.get_linestyle() == "--" and line.get_label() == "ukf"
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (s)", "position MSE (m^2)")
    assert ax.get_yscale() == "log"
    ax.figure.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels(minor=False) + ax.get_yticklabels(minor=True)]
    assert any(labels) and all(_plain(t) for t in labels), labels
    # without times: the step index; without a unit: said so; a linear axis on request
    ax = plot.error_over_time(_ax(), values, log=False)
    np.testing.assert_array_equal(_one(ax, "error:estimate").get_xdata(), np.arange(8))
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("scan", "position RMSE (unit not declared)")
    assert ax.get_yscale() == "linear"
    with pytest.raises(InputError, match=r"plot.error_over_time: values must be one curve \(T,\)"):
        plot.error_over_time(_ax(), values[None])
    with pytest.raises(InputError, match="plot.error_over_time: values must be >= 0"):
        plot.error_over_time(_ax(), -values)
    with pytest.raises(InputError, match=r"plot.error_over_time: times must have shape \(8,\)"):
        plot.error_over_time(_ax(), values, times=times[:-1])
