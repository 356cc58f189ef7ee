"""Paper 003: the range-bearing sensor, the recipe's tasks, and the report content behind Figs 4-7."""

import numpy as np
import pytest

from workbench.models import random_walk_velocity
from workbench.plugins import load_host
from workbench_papers.paper003 import recipe as p3
from workbench.rng import generator
from workbench.specs import RecipeOptions, TaskContext
from workbench.trajectory import sample_motion
from workbench.types import InputError

HOST = load_host()
RECIPE = HOST.recipe("003")
TINY = {"runs": 6, "steps": 30, "chunk": 3, "examples": 6, "grid_runs": 2, "ablation_runs": 2, "timing_runs": 2,
        "particle_budget": 600, "lost_m": 50.0}


def _run_all(filters=None, values=TINY, seed=1):
    filters = RECIPE.default_filters if filters is None else filters
    options = RecipeOptions(size="test", values=values, seed=seed, filters=tuple(filters))
    tasks = RECIPE.tasks(options)
    results = {t.key: {k: np.asarray(v) for k, v in t.run(TaskContext(params=t.params, seed=seed, host=HOST)).items()}
               for t in tasks}
    return tasks, results


@pytest.fixture(scope="module")
def tiny():
    return _run_all()


# -- sensor -----------------------------------------------------------------------------------------------


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


# -- scenario and tasks -----------------------------------------------------------------------------------


def test_common_random_numbers():
    # the same (seed, case, chunk) gives the same truths and measurements, whichever task asks
    a = p3.simulate_chunk(HOST, 3, "L2", p3.LEVELS["L2"], 1, 5, 20)
    b = p3.simulate_chunk(HOST, 3, "L2", p3.LEVELS["L2"], 1, 5, 20)
    c = p3.simulate_chunk(HOST, 3, "L2", p3.LEVELS["L2"], 2, 5, 20)
    assert np.array_equal(a[0].states, b[0].states) and np.array_equal(a[1].z, b[1].z)
    assert not np.array_equal(a[0].states, c[0].states)
    assert np.allclose(a[0].states[:, 0], p3.X0)


def test_task_layout_and_third_party_filters():
    options = RecipeOptions(size="quick", values=RECIPE.sizes["quick"], seed=0,
                            filters=RECIPE.default_filters + ("sir",))
    keys = [t.key for t in RECIPE.tasks(options)]
    assert len(keys) == len(set(keys))
    for name in RECIPE.default_filters + ("sir",):
        assert f"mc/L1/{name}/mismatched" in keys and f"mc/L3/{name}/matched" in keys
        assert f"mc/L2/{name}/mismatched" in keys and f"mc/L2/{name}/matched" not in keys  # L2: matched = nominal
        assert f"grid/{name}" in keys and f"timing/{name}" in keys
    assert RECIPE.sizes["full"]["runs"] == 3000 and RECIPE.sizes["full"]["steps"] == 100
    assert RECIPE.sizes["full"]["timing_runs"] == 200


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
    for lv in p3.LEVELS:
        a, b = results[f"mc/{lv}/ukf/mismatched"], results[f"mc/{lv}/sr-ukf/mismatched"]
        assert np.allclose(a["run_mse"], b["run_mse"], rtol=1e-8)
    assert "same_as_mismatched" in results["mc/L1/crpf-300/matched"]
    assert not np.allclose(results["mc/L3/ukf/matched"]["mse_t"], results["mc/L3/ukf/mismatched"]["mse_t"])


# -- report content ---------------------------------------------------------------------------------------


def _figure(fid):
    return next(f for f in RECIPE.figures if f.id == fid)


def test_mse_figures_have_one_curve_per_filter(tiny):
    _, results = tiny
    F = len(RECIPE.default_filters)
    for fid, level in (("fig4", "L1"), ("fig5", "L2"), ("fig6", "L3")):
        data = _figure(fid).data(results)
        assert str(data["level"]) == level
        assert list(data["filters"]) == list(RECIPE.default_filters)
        assert data["mse_t"].shape == (F, TINY["steps"]) and data["time"].shape == (TINY["steps"],)
        assert np.all(data["mse_t"] > 0)
        # the curve is the mean over runs of the squared position error stored by the task
        assert np.allclose(data["mse_t"][1], results[f"mc/{level}/ukf/mismatched"]["mse_t"])


def test_timing_figure(tiny):
    _, results = tiny
    data = _figure("fig7").data(results)
    F = len(RECIPE.default_filters)
    assert data["unbatched_s_per_run"].shape == (F,) and data["batched_s_per_run"].shape == (F,)
    assert np.all(data["unbatched_s_per_run"] > 0) and np.all(data["batched_s_per_run"] > 0)
    assert np.all(data["timing_runs"] == TINY["timing_runs"])
    ekf = list(data["filters"]).index("ekf")
    assert data["unbatched_s_per_run"][ekf] == pytest.approx(np.mean(results["timing/ekf"]["per_run_s"]))


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
    # Fig 2 shows a run with the fewest lost filters among the example runs of L1 and L2
    fig2 = _figure("fig2").data(results)
    fewest = min(int(sum(results[f"mc/{lv}/{n}/mismatched"]["lost"][r] for n in RECIPE.default_filters))
                 for lv in ("L1", "L2") for r in range(TINY["examples"]))
    assert int(fig2["lost"].sum()) == fewest


def test_tables(tiny):
    _, results = tiny
    tables = {t.id: t.make(results) for t in RECIPE.tables}
    mse = tables["mse"]
    assert len(mse.rows) == 3 * len(RECIPE.default_filters)
    row = next(r for r in mse.rows if r[0] == "ekf" and r[1] == "L3")
    ours = float(np.mean(results["mc/L3/ekf/mismatched"]["mse_t"]))
    assert float(row[2]) == pytest.approx(ours, rel=1e-3) and float(row[3]) == pytest.approx(np.sqrt(ours), rel=1e-3)
    assert len(tables["grid"].rows) == 9 and len(tables["grid"].columns) == 2 + len(RECIPE.default_filters)
    assert len(tables["ablation"].rows) == len(p3.ABLATION_FILTERS) + 1
    assert len(tables["timing"].rows) == len(RECIPE.default_filters)
    assert [r[1] for r in tables["claims"].rows] == ["C1", "C2", "C3", "C4", "C5", "C6"]


def test_criteria_are_computed_from_the_numbers(tiny):
    _, results = tiny
    crit = {c.id: c for c in RECIPE.criteria(results)}
    assert sorted(crit) == ["C1", "C2", "C3", "C4", "C5", "C6"]
    fig = {lv: _figure(f).data(results) for f, lv in (("fig4", "L1"), ("fig5", "L2"), ("fig6", "L3"))}
    mse = {lv: fig[lv]["mse_t"].mean(axis=1) for lv in fig}
    assert crit["C1"].met == bool(np.all((mse["L1"] < mse["L2"]) & (mse["L2"] < mse["L3"])))
    names = list(fig["L1"]["filters"])
    crpf = [names.index(n) for n in ("crpf-100", "crpf-300", "crpf-500")]
    kf = [names.index(n) for n in p3.KALMAN_TYPE]
    c4 = all(mse[lv][crpf[0]] <= mse[lv][kf].min() for lv in ("L2", "L3")) and \
        all(mse[lv][crpf[0]] > mse[lv][crpf[1]] > mse[lv][crpf[2]] for lv in mse)
    assert crit["C4"].met == c4
    t = _figure("fig7").data(results)["unbatched_s_per_run"]
    assert crit["C6"].met == bool(t[names.index("sr-ukf")] < t[names.index("ukf")]
                                  and t[names.index("sr-cdkf")] < t[names.index("cdkf")])
    # SR and non-SR agree to round-off on common random numbers without fallbacks
    assert crit["C3"].met

    # tamper with the numbers: the criteria follow them
    tampered = {k: dict(v) for k, v in results.items()}
    tampered["mc/L1/ekf/mismatched"]["mse_t"] = results["mc/L3/ekf/mismatched"]["mse_t"] * 10
    assert not {c.id: c for c in RECIPE.criteria(tampered)}["C1"].met
    for name in ("crpf-100", "crpf-300", "crpf-500"):
        for lv in p3.LEVELS:
            tampered[f"mc/{lv}/{name}/mismatched"] = dict(results[f"mc/{lv}/{name}/mismatched"])
    for lv, scale in (("L1", 1e-6), ("L2", 1e-6), ("L3", 1e-6)):
        for n, f in (("crpf-100", 3.0), ("crpf-300", 2.0), ("crpf-500", 1.0)):
            tampered[f"mc/{lv}/{n}/mismatched"]["mse_t"] = results[f"mc/{lv}/ekf/mismatched"]["mse_t"] * scale * f
    assert {c.id: c for c in RECIPE.criteria(tampered)}["C4"].met


def test_third_party_filter_joins_the_figures():
    _, results = _run_all(filters=("ekf", "ukf", "sir"), values={**TINY, "runs": 3, "examples": 3, "chunk": 3})
    data = _figure("fig5").data(results)
    assert list(data["filters"]) == ["ekf", "ukf", "sir"] and data["mse_t"].shape == (3, TINY["steps"])
    crit = {c.id: c for c in RECIPE.criteria(results)}
    assert not crit["C4"].met and "missing" in crit["C4"].detail


def test_size_values_are_checked():
    options = RecipeOptions(size="quick", values={"runs": 3}, seed=0, filters=("ekf",))
    with pytest.raises(InputError, match="lacks the value"):
        RECIPE.tasks(options)


def test_notes_and_docs_record_the_choices():
    from pathlib import Path

    doc = (Path(__file__).parents[4] / "docs" / "paper003.md").read_text()
    for word in ("mismatched", "arc-length", "kappa", "lost", "un-batched"):
        assert word in RECIPE.notes.lower() and word in doc.lower()
