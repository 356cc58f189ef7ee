"""Paper 003: the range-bearing sensor, the scenario, the recipe's tasks, and the report content behind every figure
and table."""

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.filtering import run_filter
from workbench.models import random_walk_velocity
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.specs import RecipeOptions, TaskContext
from workbench.testing.bootstrap import loop_statistics, same_numbers
from workbench.trajectory import sample_motion
from workbench.types import InputError
from workbench_papers.paper003 import judging
from workbench_papers.paper003 import reading as p3_reading
from workbench_papers.paper003 import tables as p3_tables
from workbench_papers.paper003 import tasks as p3_tasks
from workbench_papers.paper003 import scenario

HOST = load_host()
RECIPE = HOST.recipe("003")
TINY = {"runs": 6, "steps": 30, "chunk": 3, "examples": 6, "grid_runs": 2, "change_runs": 2, "tuning_runs": 2,
        "reference_runs": 4, "reference_check_runs": 3, "timing_runs": 2, "timing_repeats": 2,
        "particle_budget": 600, "delta_runs": 4}


def _run_all(filters=None, values=TINY, seed=1, keep=lambda key: True):
    filters = RECIPE.default_filters if filters is None else filters
    options = RecipeOptions(size="test", values=values, seed=seed, filters=tuple(filters))
    tasks = [t for t in RECIPE.tasks(options) if keep(t.key)]
    results = {t.key: {k: np.asarray(v) for k, v in t.run(TaskContext(params=t.params, seed=seed, host=HOST)).items()}
               for t in tasks}
    return tasks, results


@pytest.fixture(scope="module")
def tiny():
    return _run_all()


# -- sensor and scenario ------------------------------------------------------------------------------------


def test_sensor_draws_the_documented_noise():
    sensor = HOST.sensor("range-bearing")
    rng = generator(0, "sensor-test")
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (400, 1)), random_walk_velocity(2, 1.0, 0.1), 50, rng)
    scans = sensor.simulate(truth, rng, sigma_r=2.0, sigma_theta=0.05)
    assert scans.z.shape == (400, 50, 1, 2) and scans.valid.all() and np.all(scans.origin == 0)
    model = sensor.measurement_model(sigma_r=2.0, sigma_theta=0.05)
    assert np.allclose(model.R, np.diag([4.0, 0.0025])) and model.angular == (False, True)
    res = model.residual(scans.z[:, :, 0], model.h(truth.states))
    n = res.shape[0] * res.shape[1]
    for j, sigma in enumerate((2.0, 0.05)):
        var = res[..., j].var()
        # sample variance of n normals: relative standard error sqrt(2 / n)
        assert abs(var / sigma**2 - 1) < 5 * np.sqrt(2 / n)
        assert abs(res[..., j].mean()) < 5 * sigma / np.sqrt(n)


def test_sensor_wraps_measured_bearings():
    sensor = HOST.sensor("range-bearing")
    rng = generator(0, "wrap-test")
    truth = sample_motion(np.tile([-100.0, 0.0, 0.0, 0.0], (200, 1)), random_walk_velocity(2, 1.0, 0.0), 3, rng)
    z = sensor.simulate(truth, rng, sigma_r=1.0, sigma_theta=1.0).z[..., 1]
    assert np.all(z > -np.pi) and np.all(z <= np.pi)
    with pytest.raises(InputError):
        sensor.simulate(truth, rng, sigma_r=-1.0, sigma_theta=0.1)


def test_degrees_reading_scales_only_the_bearing_noise():
    for level, (st, sr, sa) in scenario.LEVELS.items():
        assert scenario.level_sigmas("rad", level) == (st, sr, sa)
        dst, dsr, dsa = scenario.level_sigmas("deg", level)
        assert dst == pytest.approx(np.deg2rad(st)) and (dsr, dsa) == (sr, sa)
    # the degrees reading's nominal (mismatched) models are its own L2, not the radians L2
    _, model = scenario.filter_models(HOST, scenario.level_sigmas("deg", "L3"), "mismatched", "deg")
    assert np.allclose(model.R, np.diag([1.0, np.deg2rad(0.1) ** 2]))


def test_lost_rule_uses_one_measurements_own_error():
    # the closed form of the rms error of one converted measurement against a Monte Carlo of it
    rng = np.random.default_rng(0)
    for r, sr, st in ((120.0, 0.1, 0.01), (150.0, 1.0, 0.1), (300.0, 10.0, 1.0)):
        e1, e2 = rng.standard_normal((2, 400_000))
        zr, zt = r + sr * e1, 0.7 + st * e2
        err = np.hypot(zr * np.cos(zt) - r * np.cos(0.7), zr * np.sin(zt) - r * np.sin(0.7))
        rms = np.sqrt(np.mean(err ** 2))
        assert scenario.measurement_error_rms(np.array(r), sr, st) == pytest.approx(rms, rel=0.01)
    final = np.array([[60.0, 80.0, 0.0, 0.0]])  # 100 m from the sensor
    rho = np.sqrt(1.0 + 2 * 100.0 ** 2 * (1 - np.exp(-0.1 ** 2 / 2)))
    assert scenario.lost_threshold(final, (0.1, 1.0, 0.1), 100)[0] == pytest.approx(scenario.LOST_FACTOR * rho)


def test_no_measurement_spread_against_dead_reckoning():
    # the closed form (the prior's covariance carried by the matrix recursion) against a Monte Carlo: start states
    # drawn from the prior, paths sampled with the level's motion, the error of the prior mean carried by F
    rng = np.random.default_rng(1)
    steps, B = 60, 40_000
    for sigma_a in (0.01, 1.0):
        x0 = rng.multivariate_normal(scenario.XHAT0, np.diag(scenario.P0), B)
        truth = sample_motion(x0, random_walk_velocity(2, scenario.DT, sigma_a), steps, rng)
        t = (steps - 1) * scenario.DT
        mean_xy = np.array(scenario.XHAT0[:2]) + t * np.array(scenario.XHAT0[2:])
        rms = np.sqrt(np.mean(np.sum((truth.states[:, -1, :2] - mean_xy) ** 2, axis=1)))
        assert scenario.no_measurement_rms(sigma_a, steps) == pytest.approx(rms, rel=0.02)


def test_lost_rule_marks_a_diverged_run_lost_and_a_tracking_one_not_at_every_level():
    # tracking runs: the UKF given the level's true noise (a filter that follows the target); diverged runs: the
    # same estimates drifting away at 20 m/s from the start (an EKF-style divergence).  The rule (written before
    # the reported results) must tell them apart at every level of both readings, L3 in radians included, where
    # the former 10 x one-measurement rule (about 6 km) could not mark a diverged run.
    steps, runs = 100, 20
    ukf = HOST.filter("ukf")
    drift = 20.0 * np.arange(steps) * scenario.DT
    for reading in scenario.READINGS:
        for level in scenario.LEVELS:
            sigmas = scenario.level_sigmas(reading, level)
            truth, scans = scenario.simulate_chunk(HOST, 11, f"lost-test-{reading}-{level}", sigmas, 0, runs, steps)
            motion, model = scenario.filter_models(HOST, sigmas, "matched")
            est = run_filter(ukf, scenario.prior(runs), motion, model, scans, np.random.default_rng(0)).mean
            final = truth.states[:, -1]
            good = np.hypot(*(est[:, -1, :2] - final[:, :2]).T)
            assert scenario.is_lost(good, final, sigmas, steps).sum() <= 1, (reading, level)
            diverged_xy = est[:, :, :2].copy()
            diverged_xy[:, :, 0] += drift
            bad = np.hypot(*(diverged_xy[:, -1] - final[:, :2]).T)
            assert scenario.is_lost(bad, final, sigmas, steps).all(), (reading, level)
            if level == "L1":  # precise measurements: a track 20 m off (2 x the prior's spread) has lost the target
                off = np.hypot(*(est[:, -1, :2] + [20.0, 0.0] - final[:, :2]).T)
                assert scenario.is_lost(off, final, sigmas, steps).all(), reading


def test_common_random_numbers():
    # the same (seed, case, chunk) gives the same truths and measurements, whichever task asks
    a = scenario.simulate_chunk(HOST, 3, "L2", scenario.LEVELS["L2"], 1, 5, 20)
    b = scenario.simulate_chunk(HOST, 3, "L2", scenario.LEVELS["L2"], 1, 5, 20)
    c = scenario.simulate_chunk(HOST, 3, "L2", scenario.LEVELS["L2"], 2, 5, 20)
    assert np.array_equal(a[0].states, b[0].states) and np.array_equal(a[1].z, b[1].z)
    assert not np.array_equal(a[0].states, c[0].states)
    assert np.allclose(a[0].states[:, 0], scenario.X0)
    # a prefix of the runs is the same data as those runs in a task on all of them
    cases = [scenario.make_case("L2", scenario.LEVELS["L2"])]
    whole, _ = scenario.simulate_units(HOST, 3, cases, scenario.units(cases, 10, 4), 20)
    prefix, _ = scenario.simulate_units(HOST, 3, cases, scenario.units(cases, 6, 4, of_runs=10), 20)
    assert np.array_equal(prefix.states, whole.states[:6])


# -- tasks --------------------------------------------------------------------------------------------------


def test_task_layout_and_third_party_filters():
    options = RecipeOptions(size="quick", values=RECIPE.sizes["quick"], seed=0,
                            filters=RECIPE.default_filters + ("sir",))
    tasks = RECIPE.tasks(options)
    keys = [t.key for t in tasks]
    assert len(keys) == len(set(keys))
    for name in RECIPE.default_filters + ("sir",):
        for prefix in ("", "deg-"):
            assert f"mc/{prefix}L1/{name}/mismatched" in keys and f"mc/{prefix}L3/{name}/matched" in keys
            assert f"mc/{prefix}L2/{name}/matched" not in keys  # L2: matched = nominal
        assert f"grid/{name}" in keys
    # one timing task for every filter, the third-party one included (timed interleaved, compared in one run)
    timing = [t for t in tasks if t.key == "timing"]
    assert len(timing) == 1 and list(timing[0].params["filters"]) == list(RECIPE.default_filters + ("sir",))
    for case in ("L1", "L2", "L3", "deg-L1", "deg-L2", "deg-L3"):
        assert f"reference/{case}" in keys and f"ablation/{case}" in keys
    # the reference runs on a prefix of the level's runs, chunked as the other tasks are, with the true models
    ref = next(t for t in tasks if t.key == "reference/L3")
    mc = next(t for t in tasks if t.key == "mc/L3/ukf/mismatched")
    assert ref.params["variant"] == "matched" and ref.params["of_runs"] == mc.params["runs"]
    assert ref.params["chunk"] == mc.params["chunk"] and ref.params["runs"] < mc.params["runs"]
    # its convergence check: 4 x the particles on the same first runs, at the levels criterion 4 reads
    assert [k for k in keys if k.startswith("reference4n/")] == ["reference4n/L2", "reference4n/L3",
                                                                 "reference4n/deg-L2", "reference4n/deg-L3"]
    check = next(t for t in tasks if t.key == "reference4n/L3")
    assert check.params["configure"] == {"particles": 4 * ref.params["configure"]["particles"]}
    assert {k: v for k, v in check.params.items() if k not in ("configure", "label", "runs")} == \
        {k: v for k, v in ref.params.items() if k not in ("configure", "label", "runs")}
    assert check.params["runs"] == min(RECIPE.sizes["quick"]["reference_check_runs"], ref.params["runs"])
    assert RECIPE.sizes["full"]["reference_check_runs"] == RECIPE.sizes["full"]["reference_runs"] == 100
    assert len([k for k in keys if k.startswith("tune/")]) == 2 * len(p3_tasks.TUNE_SIGMA0) * len(p3_tasks.TUNE_DELTA)
    # the tuning runs use their own seed and stream, never the report's
    tune = next(t for t in tasks if t.key.startswith("tune/"))
    assert tune.params["data_seed"] == p3_tasks.TUNING_SEED and tune.params["stream"] != scenario.STREAM


def test_tasks_recompute_independently_and_reproducibly(tiny):
    tasks, results = tiny
    task = next(t for t in tasks if t.key == "mc/L3/crpf-100/mismatched")
    again = task.run(TaskContext(params=task.params, seed=1, host=HOST))
    for k, v in results[task.key].items():
        if k != "seconds":
            assert np.array_equal(np.asarray(again[k]), v), k


def test_filters_see_the_same_data(tiny):
    _, results = tiny
    # SR-UKF and UKF agree run by run only if they filtered the same truths and measurements
    for case in ("L1", "L2", "L3", "deg-L1", "deg-L2", "deg-L3"):
        a, b = results[f"mc/{case}/ukf/mismatched"], results[f"mc/{case}/sr-ukf/mismatched"]
        assert np.allclose(a["run_mse"], b["run_mse"], rtol=1e-8)
        # the reference and the ablation row ran on the same truths: their lost thresholds (a function of the
        # final true position) are those of the first runs
        ref, abl = results[f"reference/{case}"], results[f"ablation/{case}"]
        assert np.array_equal(ref["lost_threshold"], a["lost_threshold"][: len(ref["lost_threshold"])])
        assert np.array_equal(abl["lost_threshold"], a["lost_threshold"])
        assert np.array_equal(results[f"scenario/{case}"]["lost_threshold"], a["lost_threshold"])
        if not case.endswith("L1"):  # the convergence check (L2, L3) ran on the reference's first runs
            check = results[f"reference4n/{case}"]
            assert len(check["run_mse"]) == TINY["reference_check_runs"]
            assert np.array_equal(check["lost_threshold"], ref["lost_threshold"][: TINY["reference_check_runs"]])
    assert "same_as_mismatched" in results["mc/L1/crpf-300/matched"]
    assert not np.allclose(results["mc/L3/ukf/matched"]["mse_t"], results["mc/L3/ukf/mismatched"]["mse_t"])


def test_rows_are_the_filters_they_claim(tiny):
    _, results = tiny
    ref = json.loads(str(results["reference/L2"]["filter_params"]))
    assert ref["particles"] == 5000
    assert json.loads(str(results["reference4n/L2"]["filter_params"]))["particles"] == 20000
    abl = json.loads(str(results["ablation/L2"]["filter_params"]))
    assert (abl["variance"], abl["cost"], abl["delta_mode"], abl["delta"]) == ("fixed", "norm", "absolute", 0.01)
    paper = json.loads(str(results["mc/L2/crpf-100/mismatched"]["filter_params"]))
    assert (paper["variance"], paper["cost"], paper["delta_mode"]) == ("adaptive", "arc-length", "relative")
    # the lost flags follow the stored thresholds
    res = results["mc/L3/ekf/mismatched"]
    assert np.array_equal(res["lost"], res["final_err"] > res["lost_threshold"])


def test_tuning_data_do_not_depend_on_the_report_seed():
    options = RecipeOptions(size="test", values=TINY, seed=0, filters=RECIPE.default_filters)
    task = next(t for t in RECIPE.tasks(options) if t.key.startswith("tune/rad/"))
    a = task.run(TaskContext(params=task.params, seed=0, host=HOST))
    b = task.run(TaskContext(params=task.params, seed=99, host=HOST))
    assert np.array_equal(a["L2:run_mse"], b["L2:run_mse"])
    # and they are not the reported runs: the reported data of seed 20031 differ from the tuning data
    truth_tune, _ = scenario.simulate_chunk(HOST, p3_tasks.TUNING_SEED, "L2", scenario.LEVELS["L2"], 0, 2, 5, p3_tasks.TUNING_STREAM)
    truth_rep, _ = scenario.simulate_chunk(HOST, p3_tasks.TUNING_SEED, "L2", scenario.LEVELS["L2"], 0, 2, 5)
    assert not np.array_equal(truth_tune.states, truth_rep.states)


# -- report content -----------------------------------------------------------------------------------------


def _figure(fid):
    return next(f for f in RECIPE.figures if f.id == fid)


def test_mse_figures_have_one_curve_per_row(tiny):
    _, results = tiny
    F = len(RECIPE.default_filters)
    for fid, level in (("fig4", "L1"), ("fig5", "L2"), ("fig6", "L3")):
        data = _figure(fid).data(results)
        assert str(data["level"]) == level
        assert list(data["filters"][:F]) == list(RECIPE.default_filters)
        assert list(data["kind"]) == ["filter"] * F + ["ablation", "reference"]
        assert data["mse_t"].shape == (F + 2, TINY["steps"]) and data["time"].shape == (TINY["steps"],)
        assert np.all(data["mse_t"] > 0)
        # the curves are the mean over runs of the squared position error stored by the tasks
        assert np.allclose(data["mse_t"][1], results[f"mc/{level}/ukf/mismatched"]["mse_t"])
        assert np.allclose(data["mse_t"][-1], results[f"reference/{level}"]["mse_t"])
        assert np.allclose(data["mse_t"][-2], results[f"ablation/{level}"]["mse_t"])


def test_degrees_figure(tiny):
    _, results = tiny
    data = _figure("fig8").data(results)
    for level in scenario.LEVELS:
        labels = list(data[f"{level}:filters"])
        assert labels[: len(RECIPE.default_filters)] == list(RECIPE.default_filters)
        assert np.allclose(data[f"{level}:mse_t"][0], results[f"mc/deg-{level}/ekf/mismatched"]["mse_t"])
        assert np.allclose(data[f"{level}:mse_t"][-1], results[f"reference/deg-{level}"]["mse_t"])
    # a smaller bearing noise: the degrees reading's L3 MSE of the UKF is below the radians reading's
    assert np.mean(data["L3:mse_t"][1]) < np.mean(results["mc/L3/ukf/mismatched"]["mse_t"])


def test_timing_figure(tiny):
    _, results = tiny
    data = _figure("fig7").data(results)
    F = len(RECIPE.default_filters)
    assert data["unbatched_s_per_run"].shape == (F,) and data["batched_s_per_run"].shape == (F,)
    assert np.all(data["unbatched_s_per_run"] > 0) and np.all(data["batched_s_per_run"] > 0)
    assert np.all(data["timing_runs"] == TINY["timing_runs"]) and np.all(data["batched_repeats"] == 2)
    ekf = list(data["filters"]).index("ekf")
    assert data["unbatched_s_per_run"][ekf] == pytest.approx(np.median(results["timing"]["ekf:per_run_s"]))
    assert data["batched_s_per_run"][ekf] == pytest.approx(np.median(results["timing"]["ekf:batched_per_run_s"]))


def test_timing_interleaves_the_filters_run_by_run(monkeypatch):
    # every filter times run r before any filter times run r + 1 (the order rotated by one filter per run), and the
    # batched repetitions likewise: a drift of the machine's load falls on every filter alike
    calls = []

    def recording(spec, prior, motion, model, scans, rng):
        calls.append((spec.name, scans.z.shape[0]))
        return run_filter(spec, prior, motion, model, scans, rng)

    monkeypatch.setattr(p3_tasks, "run_filter", recording)
    names = ["ekf", "ukf", "cdkf"]
    ctx = TaskContext(params={"filters": names, "timing_runs": 4, "steps": 5, "timing_repeats": 2}, seed=0,
                      host=load_host(), arch="cpu")
    out = p3_tasks.run_timing(ctx)
    timed = calls[2 * len(names):]  # after each filter's two warm-up calls
    one_by_one = [n for n, batch in timed if batch == 1]
    assert one_by_one == [names[(j + r) % 3] for r in range(4) for j in range(3)]
    batched = [n for n, batch in timed if batch == 4]
    assert batched == [names[(j + k) % 3] for k in range(2) for j in range(3)]
    for n in names:
        assert out[f"{n}:per_run_s"].shape == (4,) and np.all(out[f"{n}:per_run_s"] > 0)
        assert out[f"{n}:batched_per_run_s"].shape == (2,) and np.all(out[f"{n}:per_run_cpu_s"] >= 0)
    assert p3_reading.timing_arrays({"timing": out}, "ukf")["per_run_s"] is out["ukf:per_run_s"]
    assert p3_reading.timing_arrays({"timing": out}, "sir") is None


def test_example_figures(tiny):
    _, results = tiny
    for fid in ("fig2", "fig3"):
        data = _figure(fid).data(results)
        F = len(RECIPE.default_filters)
        assert data["est_xy"].shape == (F, TINY["steps"], 2)
        assert data["truth_xy"].shape == data["meas_xy"].shape == (TINY["steps"], 2)
        level, run = str(data["level"]), int(data["run"])
        # measurements converted to Cartesian sit within a few sigma of the truth at L1/L2
        if level in ("L1", "L2"):
            assert np.median(np.hypot(*(data["meas_xy"] - data["truth_xy"]).T)) < 50
        assert np.array_equal(data["lost"], [bool(results[f"mc/{level}/{n}/mismatched"]["lost"][run])
                                             for n in data["filters"]])
        assert float(data["lost_threshold_m"]) == results[f"scenario/{level}"]["lost_threshold"][run]
    # Fig 2 shows a run with the fewest lost filters among the example runs of L1 and L2
    fig2 = _figure("fig2").data(results)
    fewest = min(int(sum(results[f"mc/{lv}/{n}/mismatched"]["lost"][r] for n in RECIPE.default_filters))
                 for lv in ("L1", "L2") for r in range(TINY["examples"]))
    assert int(fig2["lost"].sum()) == fewest


def _line(ax, gid):
    found = [ln for ln in ax.lines if ln.get_gid() == gid]
    assert len(found) == 1, (gid, [ln.get_gid() for ln in ax.lines])
    return np.column_stack([found[0].get_xdata(), found[0].get_ydata()]).astype(float)


def _plain_ticks(ax) -> bool:
    ax.figure.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels(minor=False) + ax.get_yticklabels(minor=True)]
    return any(labels) and all(t == "" or t.replace(".", "", 1).isdigit() for t in labels)


def test_figures_draw_their_data_through_workbench_plot():
    """Each drawn figure holds its data (hand-made here, of the data functions' shapes): the example runs'
    truth and estimates (one colour and line style per filter), the MSE curves per row on a log axis with plain
    tick labels, the timings' log axis."""
    from matplotlib.figure import Figure

    rng = generator(3, "test", "figures")
    T, names = 10, ["ekf", "ukf", "sr-ukf"]
    truth = np.cumsum(rng.normal(size=(T, 2)), axis=0) + [100.0, 50.0]
    example = {"level": np.array("L2"), "run": np.array(4), "why": np.array("all filters track"),
               "filters": np.array(names), "truth_xy": truth, "meas_xy": truth + rng.normal(size=(T, 2)),
               "est_xy": truth + rng.normal(size=(3, T, 2)), "lost": np.array([False, True, False]),
               "lost_threshold_m": np.array(80.0)}
    fig = Figure()
    _figure("fig2").draw(example, fig)
    ax = fig.axes[0]
    np.testing.assert_array_equal(_line(ax, "truth:truth"), truth)
    np.testing.assert_array_equal(_line(ax, "measurements"), example["meas_xy"])
    drawn = []
    for name, xy, label in zip(names, example["est_xy"], ["ekf", "ukf (lost)", "sr-ukf"]):
        np.testing.assert_array_equal(_line(ax, f"estimate:{label}"), xy)
        np.testing.assert_array_equal(_line(ax, f"estimate-start:{label}"), xy[:1])
        drawn += [ln for ln in ax.lines if ln.get_gid() == f"estimate:{label}"]
    assert len({ln.get_color() for ln in drawn}) == len({ln.get_linestyle() for ln in drawn}) == 3
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    assert ax.get_title().startswith("L2 run 4: all filters track")
    curves = rng.random((5, T)) * 100 + 1
    mse = {"level": np.array("L2"), "reading": np.array("rad"), "time": np.arange(T) * scenario.DT, "mse_t": curves,
           "filters": np.array(names + ["crpf-100 previous (ablation)", "pf-5000 (true noise), first 4 runs"]),
           "kind": np.array(["filter"] * 3 + ["ablation", "reference"])}
    fig = Figure()
    _figure("fig5").draw(mse, fig)
    ax = fig.axes[0]
    for name, curve in zip(mse["filters"], curves):
        np.testing.assert_array_equal(_line(ax, f"error:{name}"), np.column_stack([mse["time"], curve]))
    assert [ln.get_linestyle() for ln in ax.lines if str(ln.get_gid()).startswith("error:")] == \
        ["-", "-", "--", ":", "--"]  # sr- filters dashed, the ablation dotted, the reference dashed black
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (s)", "position MSE (m$^2$)")
    assert ax.get_yscale() == "log" and _plain_ticks(ax)
    deg = {"time": mse["time"]}
    for i, level in enumerate(scenario.LEVELS):
        deg.update({f"{level}:filters": mse["filters"], f"{level}:kind": mse["kind"],
                    f"{level}:mse_t": curves * (i + 1)})
    fig = Figure()
    _figure("fig8").draw(deg, fig)
    for i, ax in enumerate(fig.axes):
        np.testing.assert_array_equal(_line(ax, "error:ukf")[:, 1], curves[1] * (i + 1))
        assert ax.get_ylabel() == "position MSE (m$^2$)" and ax.get_yscale() == "log"
    timing = {"filters": np.array(names), "unbatched_s_per_run": np.array([0.02, 0.5, 0.04]),
              "batched_s_per_run": np.array([0.001, 0.01, 0.002]), "timing_runs": np.array([2, 2, 2]),
              "batched_repeats": np.array([2, 2, 2])}
    fig = Figure()
    _figure("fig7").draw(timing, fig)
    ax = fig.axes[0]
    heights = np.array([bar.get_height() for bar in ax.patches])
    np.testing.assert_allclose(heights, np.concatenate([timing["unbatched_s_per_run"],
                                                        timing["batched_s_per_run"]]) * 1e3, rtol=1e-12)
    assert ax.get_yscale() == "log" and _plain_ticks(ax)


def test_mse_tables(tiny):
    _, results = tiny
    tables = {t.id: t.make(results) for t in RECIPE.tables if t.id in ("mse", "mse-deg")}
    F = len(RECIPE.default_filters)
    for tid, prefix in (("mse", ""), ("mse-deg", "deg-")):
        table = tables[tid]
        cols = list(table.columns)
        assert len(table.rows) == 3 * (F + 2) + 2  # the 4N reference at L2 and L3
        row = next(r for r in table.rows if r[0] == "ekf" and r[1] == f"{prefix}L3")
        res = results[f"mc/{prefix}L3/ekf/mismatched"]
        ours = float(np.mean(res["mse_t"]))
        assert float(row[cols.index("MSE (m^2)")]) == pytest.approx(ours, rel=1e-3)
        assert float(row[cols.index("median run MSE")]) == pytest.approx(np.median(res["run_mse"]), rel=1e-3)
        assert float(row[cols.index("lost %")]) == pytest.approx(100 * np.mean(res["lost"]), abs=0.06)
        kept = res["run_mse"][~res["lost"]]
        cell = row[cols.index("MSE over runs not lost")]
        assert (cell == "n/a") if not kept.size else float(cell) == pytest.approx(kept.mean(), rel=1e-3)
        ref = results[f"reference/{prefix}L3"]["run_mse"]
        ratio = res["run_mse"][: len(ref)].mean() / ref.mean()
        assert float(row[cols.index("MSE / reference (same runs)")]) == pytest.approx(ratio, rel=1e-3)
        labels = [r[0] for r in table.rows]
        assert any(label.startswith(p3_reading.REFERENCE["label"]) for label in labels) and p3_tasks.PREVIOUS["label"] in labels
        # the 4N reference's ratio to the reference is on the runs both ran
        row = next(r for r in table.rows if r[0].startswith(p3_reading.REFERENCE_4N["label"]) and r[1] == f"{prefix}L3")
        check = results[f"reference4n/{prefix}L3"]["run_mse"]
        assert float(row[cols.index("MSE / reference (same runs)")]) == pytest.approx(
            check.mean() / ref[: len(check)].mean(), rel=1e-3)


def test_other_tables(tiny):
    _, results = tiny
    wanted = ("grid", "timing", "scenario", "changes", "checks", "tuning")  # the claims table has tests of its own
    tables = {t.id: t.make(results) for t in RECIPE.tables if t.id in wanted}
    assert set(tables) == set(wanted)
    assert len(tables["grid"].rows) == 9 and len(tables["grid"].columns) == 2 + len(RECIPE.default_filters)
    assert len(tables["timing"].rows) == len(RECIPE.default_filters)
    assert len(tables["scenario"].rows) == 6
    changes = tables["changes"]
    assert [r[0] for r in changes.rows] == [label for label, _ in p3_tasks.CHANGES]
    first = changes.rows[0][2]  # paper setting, L1 = the registered crpf-100 on the first change_runs runs
    mse = float(np.mean(results[f"changes/rad/{p3_tasks.CHANGES[0][0]}"]["L1:mse_t"]))
    assert first.startswith(f"{mse:.4g}")
    # the brief's criterion 3 is a check beside the criteria: the SR forms equal the full forms to round-off
    chk = tables["checks"]
    assert [r[1] for r in chk.rows] == ["rad", "deg"] and all(r[4] == "holds" for r in chk.rows)
    assert all(float(r[2]) < 1e-6 for r in chk.rows)
    tuning = tables["tuning"]
    assert len(tuning.rows) == len(p3_tasks.TUNE_SIGMA0) * len(p3_tasks.TUNE_DELTA)
    scores = p3_tables.tuning_scores(results)
    best = min(scores, key=lambda k: scores[k][1])
    marked = [r for r in tuning.rows if "chosen by the rule" in r[-1]]
    assert len(marked) == 1 and (float(marked[0][0]), float(marked[0][1])) == best
    in_use = [r for r in tuning.rows if "in use" in r[-1]]
    assert len(in_use) == 1 and (float(in_use[0][0]), float(in_use[0][1])) == p3_tables.setting_in_use(results)
    # the geometric mean column is the rule's score
    for r in tuning.rows:
        vals = [float(x) for x in r[2:8]]
        assert float(r[8]) == pytest.approx(np.exp(np.mean(np.log(vals))), rel=2e-3)


def test_claims_table_never_says_met_below_the_full_size(tiny, monkeypatch):
    _, results = tiny
    # let every criterion be decided on these few runs: C1 (MSE grows with the noise level, by 100 x) is then met
    monkeypatch.setattr(judging, "_MIN", {"runs": 2, "ref": 2, "timed": 2, "repeats": 2})
    verdicts = {c.id: c.verdict for c in judging.criteria(results)}
    assert verdicts["C1"] == "met" and verdicts["C1-deg"] == "met"
    rows = RECIPE.tables[-1].make(results).rows
    crit_rows = [r for r in rows if not r[1].startswith("check:")]
    assert {r[1] for r in crit_rows} == set(verdicts)
    for r in crit_rows:
        assert not r[2].startswith("met") and r[2].endswith("(indicative: quick size)")
    # the SR identity is a check beside them (the brief's claim "same accuracy as the non-SR forms")
    assert [(r[1], r[2]) for r in rows if r[1].startswith("check:")] == [
        ("check: SR = full (rad reading)", "check holds"), ("check: SR = full (deg reading)", "check holds")]


def test_criteria_carry_n_interval_and_verdict(tiny):
    _, results = tiny
    crit = RECIPE.criteria(results)
    ids = [c.id for c in crit]
    assert ids == ["C1", "C2", "C4-L2", "C4-L3", "C4-N", "C1-deg", "C2-deg", "C4-L2-deg",
                   "C4-L3-deg", "C4-N-deg", "C5-linear", "C5-slower", "C5-linear-batched", "C5-slower-batched", "C6"]
    for c in crit:
        assert c.n is not None and c.n > 0 and c.interval is not None and c.verdict == "inconclusive"  # too few runs
        assert c.interval[0] <= c.ours <= c.interval[1] or not np.isfinite(c.ours)
    # the statistic of C4-L2 is CRPF-100 over the best Kalman-type filter's mean MSE, on the same runs
    c4 = {c.id: c for c in crit}["C4-L2"]
    crpf = results["mc/L2/crpf-100/mismatched"]["run_mse"].mean()
    best = min(results[f"mc/L2/{n}/mismatched"]["run_mse"].mean() for n in judging.KALMAN_TYPE)
    assert c4.ours == pytest.approx(crpf / best)


def test_batched_criteria_give_the_per_resample_loops_numbers(tiny, monkeypatch):
    """Every criterion's interval, verdict and detail (across delta and the reference included) from the batched
    statistics equal the per-resample loop's, on the tiny runs with every criterion decided (120 resamples)."""
    import workbench.criteria as wc

    _, results = tiny
    monkeypatch.setattr(judging, "_MIN", {"runs": 2, "ref": 2, "timed": 2, "repeats": 2})
    monkeypatch.setattr(judging, "RESAMPLES", 120)
    fast = judging.criteria(results)
    monkeypatch.setattr(wc, "_batched_statistics", loop_statistics)
    slow = judging.criteria(results)
    assert [c.id for c in fast] == [c.id for c in slow]
    finite = [c.id for c in fast if c.interval is not None and np.all(np.isfinite(c.interval))]
    assert {"C1", "C2", "C4-L2", "C4-L3", "C4-N", "C5-linear", "C5-slower", "C6"} <= set(finite)
    assert any(c.across for c in fast)
    for a, b in zip(fast, slow):
        same_numbers(a.to_dict(), b.to_dict(), a.id)


def test_third_party_filter_joins_the_figures():
    _, results = _run_all(filters=("ekf", "ukf", "sir"), values={**TINY, "runs": 3, "examples": 3, "chunk": 3,
                                                                 "reference_runs": 2},
                          keep=lambda k: k.split("/")[0] in ("mc", "scenario", "reference", "ablation"))
    data = _figure("fig5").data(results)
    assert list(data["filters"][:3]) == ["ekf", "ukf", "sir"] and data["mse_t"].shape == (5, TINY["steps"])
    crit = {c.id: c for c in RECIPE.criteria(results)}
    assert crit["C4-L2"].verdict == "inconclusive" and "missing" in crit["C4-L2"].detail


def test_size_values_are_checked():
    options = RecipeOptions(size="quick", values={"runs": 3}, seed=0, filters=("ekf",))
    with pytest.raises(InputError, match="lacks the value"):
        RECIPE.tasks(options)


def test_notes_and_docs_record_the_choices():
    doc = (Path(__file__).parents[4] / "docs" / "paper003.md").read_text()
    for word in ("mismatched", "arc-length", "adaptive", "relative", "lost", "un-batched", "degrees", "reference",
                 "tuning"):
        assert word in RECIPE.notes.lower() and word in doc.lower()
    # the rule of the tuning is written in the docs with its candidates and seed
    assert str(p3_tasks.TUNING_SEED) in doc and "geometric mean" in doc


def test_delta_grid_tasks_share_the_main_rows_data():
    # the declared unknown delta: every CRPF at each non-primary grid value, on a prefix of the same runs (same
    # seed, stream and chunking as the main rows), only the filter's delta configured
    assert RECIPE.unknowns == (scenario.DELTA,)
    assert HOST.filter("crpf-100").params["delta"] == scenario.DELTA.primary  # the registered default is the primary
    options = RecipeOptions(size="full", values=RECIPE.sizes["full"], seed=0, filters=RECIPE.default_filters)
    tasks = {t.key: t for t in RECIPE.tasks(options)}
    keys = [k for k in tasks if k.startswith("delta/")]
    assert sorted(keys) == sorted(p3_reading.delta_key(r, v, n) for r in scenario.READINGS for v in (0.3, 1.0)
                                  for n in judging.CRPF_FILTERS)
    d, m = tasks[p3_reading.delta_key("rad", 1.0, "crpf-300")].params, tasks["mc/L2/crpf-300/mismatched"].params
    assert d["configure"] == {"delta": 1.0} and d["runs"] == RECIPE.sizes["full"]["delta_runs"] == 1000
    assert d["of_runs"] == m["runs"] and d["chunk"] == m["chunk"] and "data_seed" not in d and "stream" not in d
    assert [c["case"] for c in d["cases"]] == ["L1", "L2", "L3"]
    # at the quick size too (fewer grid runs than a chunk: the chunking must still be the main rows')
    quick = {t.key: t for t in RECIPE.tasks(RecipeOptions(size="quick", values=RECIPE.sizes["quick"], seed=0,
                                                          filters=RECIPE.default_filters))}
    dq, mq = quick[p3_reading.delta_key("deg", 0.3, "crpf-100")].params, quick["mc/deg-L3/crpf-100/mismatched"].params
    assert dq["runs"] < mq["chunk"] and (dq["chunk"], dq["of_runs"]) == (mq["chunk"], mq["runs"])
    # the same chunks: the first 1000 runs of the delta task are the first 1000 runs of the main task
    assert scenario.units(d["cases"], d["runs"], d["chunk"], d["of_runs"])[:4] == \
        [(0, k, 250, 250) for k in range(4)]


def test_sensitivity_tasks_feed_only_the_across_of_the_criteria(tiny, monkeypatch):
    # the tasks declared sensitivity=True (the confirmation seed does not rerun them) are exactly the delta tasks at
    # the non-primary values; replacing their arrays changes each criterion's `across`, never its primary verdict,
    # statistic, interval or n
    monkeypatch.setattr(judging, "RESAMPLES", 200)
    tasks, results = tiny
    marked = {t.key for t in tasks if t.sensitivity}
    assert marked and marked == {t.key for t in tasks if t.key.startswith("delta/")}
    # the one task of wall-clock times is declared so (side-by-side workers take it last in its batch)
    assert [t.key for t in tasks if t.timed] == ["timing"]
    assert all(t.params["configure"]["delta"] != scenario.DELTA.primary for t in tasks if t.sensitivity)
    rng = np.random.default_rng(5)
    changed = dict(results)
    for key in marked:  # every run's error scaled by its own random factor: other means, another order of filters
        arrays = dict(results[key])
        for name in [k for k in arrays if k.endswith(":run_mse") or k.endswith(":mse_t")]:
            arrays[name] = arrays[name] * rng.uniform(0.01, 100.0, arrays[name].shape)
        changed[key] = arrays
    before = {c.id: c for c in RECIPE.criteria(results)}
    after = {c.id: c for c in RECIPE.criteria(changed)}
    assert before.keys() == after.keys()
    moved = 0
    for cid, c in before.items():
        primary_after, primary_before = after[cid].to_dict(), c.to_dict()
        across_after, across_before = primary_after.pop("across"), primary_before.pop("across")
        # verdict, statistic, interval, n, preconditions and detail at the primary values: unchanged
        same_numbers(primary_after, primary_before, cid)
        moved += across_after != across_before
    assert moved > 0  # the replaced arrays are what `across` reads


def test_delta_table_and_across_in_a_tiny_report(tiny, monkeypatch):
    monkeypatch.setattr(judging, "RESAMPLES", 200)  # no interval is asserted here
    _, results = tiny
    table = next(t for t in RECIPE.tables if t.id == "delta").make(results)
    assert len(table.rows) == 2 * 3 * 3  # readings x CRPFs x grid values
    row = next(r for r in table.rows if r[:3] == ("rad", "crpf-100", "1"))
    mse = results[p3_reading.delta_key("rad", 1.0, "crpf-100")]["L3:run_mse"][:TINY["delta_runs"]].mean()
    assert row[3] == TINY["delta_runs"] and row[6].startswith(f"{mse:.4g}")
    crit = {c.id: c for c in RECIPE.criteria(results)}
    assert [a.value for a in crit["C4-L3"].across] == [0.1, 0.3, 1.0]
    assert all(a.n == TINY["delta_runs"] for a in crit["C4-N-deg"].across)
