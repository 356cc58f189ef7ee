"""The built-in filters' benchmark group ``core`` (``workbench bench --only core``) and the bootstrap PF it times,
held to a textbook particle filter making the same draws."""

import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp

from workbench.plugins import load_host
from workbench.types import BLAS_MOMENT_PARTICLES
from workbench_filters import benchmarks as bench_core
from workbench_filters import particle


def _expected_fields(stonesoup: bool, ukf: bool, filterpy: bool) -> dict:
    """Every figure of ``core --quick`` -> ``"number"`` or the one string it may be instead."""
    n = bench_core.TARGET_N
    fields = {"cpu_count": "number", "load_avg_1min": "number", "numpy_version": "string", "pf_backend": "string",
              "stonesoup_version": "string", "peak_rss_mib": "number", "group_wall_s": "number",
              "kernel_arch": "string", "load_avg_1min_start_pf_end": "list", "curves": "list",
              f"target_pf_over_floor_N{n}": "string", f"measured_pf_over_floor_N{n}": "number",
              f"met_pf_over_floor_N{n}": "bool", f"note_pf_over_floor_N{n}": "string",
              f"target_pf_speedup_vs_stonesoup_N{n}": "string",
              f"measured_pf_speedup_vs_stonesoup_N{n}": "number" if stonesoup else "not installed",
              f"met_pf_speedup_vs_stonesoup_N{n}": "bool" if stonesoup else "not installed"}
    for n in bench_core.PF_SIZES["quick"]:
        for key in ("pf_ns_per_particle_step", "pf_floor_ns_per_particle_step", "pf_pos_rmse_m",
                    "pf_floor_numpy_draws_ns_per_particle_step", "pf_floor_compiled_draws_ns_per_particle_step",
                    "pf_over_floor", "pf_over_numpy_draws_floor"):
            fields[f"{key}_N{n}"] = "number"
    for n in bench_core.PEER_SIZES["quick"]:
        for key in ("stonesoup_ns_per_particle_step", "stonesoup_pos_rmse_m", "pf_over_stonesoup",
                    "pf_speedup_vs_stonesoup"):
            fields[f"{key}_N{n}"] = "number" if stonesoup else "not installed"
    for b in bench_core.UKF_BATCHES["quick"]:
        fields[f"ukf_ns_per_run_step_B{b}"] = "number" if ukf else "ukf not installed"
    fields["filterpy_ukf_ns_per_run_step"] = ("number" if filterpy else "not installed") if ukf else "ukf not installed"
    if ukf:
        for name in ("ekf", "ukf"):
            fields[f"{name}_one_track_us_per_step"] = "number"
            fields[f"filterpy_{name}_us_per_step"] = "number" if filterpy else "not installed"
            if filterpy:
                fields[f"target_{name}_one_track_over_filterpy"] = "string"
                fields[f"measured_{name}_one_track_over_filterpy"] = "number"
                fields[f"met_{name}_one_track_over_filterpy"] = "bool"
                fields[f"note_{name}_one_track_over_filterpy"] = "string"
    return fields


def test_bench_quick_core_reports_every_figure_and_its_targets(tmp_path):
    out = tmp_path / "bench.json"
    code = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", code, "bench", "--quick", "--only", "core", "--json", str(out),
                           "--plot", str(tmp_path / "figs")],
                          capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(out.read_text())
    assert report["quick"] is True and list(report["groups"]) == ["core"]
    core = report["groups"]["core"]
    assert "error" not in core, core.get("error")
    stonesoup = importlib.util.find_spec("stonesoup") is not None
    filterpy = importlib.util.find_spec("filterpy") is not None
    ukf = "ukf" in load_host().filters
    expected = _expected_fields(stonesoup, ukf, filterpy)
    assert set(core) == set(expected), f"missing {set(expected) - set(core)}, unexpected {set(core) - set(expected)}"
    for key, kind in expected.items():
        value = core[key]
        if kind == "number":
            assert isinstance(value, (int, float)) and not isinstance(value, bool), (key, value)
            assert math.isfinite(value) and value >= 0, (key, value)
        elif kind == "bool":
            assert isinstance(value, bool), (key, value)
        elif kind == "string":
            assert isinstance(value, str) and value, (key, value)
        elif kind == "list":
            assert isinstance(value, list) and value, (key, value)
        else:
            assert value == kind, (key, value)
    assert core["pf_backend"] == ("numba" if importlib.util.find_spec("numba") else "numpy")
    for n in bench_core.PF_SIZES["quick"]:
        assert core[f"pf_ns_per_particle_step_N{n}"] > 0
        # the filter tracks: its position error stays within a few range-noise sigmas of the truth
        assert core[f"pf_pos_rmse_m_N{n}"] < 20.0
    assert core["stonesoup_version"] != "not installed" if stonesoup else core["stonesoup_version"] == "not installed"
    n = bench_core.TARGET_N
    if stonesoup:
        # Stone Soup solved the same problem: its error is of the same size as ours
        assert core[f"stonesoup_pos_rmse_m_N{n}"] < 3.0 * core[f"pf_pos_rmse_m_N{n}"] + 1.0
    # (the arithmetic from timings to figures and verdicts: test_core_figures_from_hand_made_timings)
    # the printed table: one line per target, indicative in quick mode
    table = proc.stdout[proc.stdout.index("targets (quick"):].splitlines()
    lines = [line.split() for line in table[2:] if line.startswith("core ")]
    expected_targets = [(f"pf_over_floor_N{n}", "indicative"), (f"pf_speedup_vs_stonesoup_N{n}", "indicative")]
    if filterpy and ukf:
        expected_targets += [("ekf_one_track_over_filterpy", "indicative"), ("ukf_one_track_over_filterpy", "indicative")]
    assert sorted((line[1], line[-1]) for line in lines) == sorted(expected_targets)
    assert "GPU figures need" in proc.stdout
    # the scaling figures: the PF against N beside Stone Soup and the floor, the UKF against B beside FilterPy
    figs = {c["id"]: c for c in core["curves"]}
    assert {s["role"] for s in figs["pf_vs_particles"]["series"]} == ({"ours", "peer", "limit", "reference"}
                                                                      if stonesoup else {"ours", "limit", "reference"})
    if ukf:
        assert figs["ukf_vs_batch"]["series"][0]["x"] == list(bench_core.UKF_BATCHES["quick"])
    for curve in core["curves"]:
        assert (tmp_path / "figs" / f"core_{curve['id']}.png").is_file()


def test_paired_times_are_medians_and_the_ratio_the_median_of_the_pairs(monkeypatch):
    # a warm-up each, then a, b, a, b, ...: a = 1, 3, 2 s and b = 1, 1, 2 s give medians 2 and 1 s and the pairs'
    # ratios 1, 3, 1 (median 1, not the ratio of the medians, 2)
    times = iter([9.0, 9.0, 1.0, 1.0, 3.0, 1.0, 2.0, 2.0])
    monkeypatch.setattr(bench_core, "median_time", lambda fn, repeat, warmup: next(times))
    assert bench_core.paired_times(None, None, 3) == (2.0, 1.0, 1.0)


@pytest.mark.parametrize("compiled_s, numpy_s, floor_ns, over_floor, met_floor",
                         [(0.8, 1.2, 800.0, 2.5, False), (1.5, 1.2, 1200.0, 2.0 / 1.2, False),
                          (1.5, 1.4, 1400.0, 2.0 / 1.4, True)])
def test_core_figures_from_hand_made_timings(monkeypatch, compiled_s, numpy_s, floor_ns, over_floor, met_floor):
    # every run 10 steps; per pair of timings (ours, theirs, median ratio) in seconds: Stone Soup (2.0, 30.0, 2/30),
    # NumPy's draws (2.0, numpy_s, 2/numpy_s), the compiled draws (2.0, compiled_s, 2/compiled_s)
    def runner(tag):
        return lambda *args, **kwargs: (tag, 10, lambda: 1.5 if tag == "ours" else 2.0)

    pairs = {"stonesoup": (2.0, 30.0, 2.0 / 30.0), "numpy": (2.0, numpy_s, 2.0 / numpy_s),
             "compiled": (2.0, compiled_s, 2.0 / compiled_s)}
    monkeypatch.setattr(bench_core, "pf_runner", runner("ours"))
    monkeypatch.setattr(bench_core, "stonesoup_version", lambda: "1.0")
    monkeypatch.setattr(bench_core, "stonesoup_runner", runner("stonesoup"))
    monkeypatch.setattr(bench_core, "floor_runner",
                        lambda n, compiled=False: ("compiled" if compiled else "numpy", 10))
    monkeypatch.setattr(bench_core, "paired_times", lambda a, b, repeats: pairs[b])
    monkeypatch.setattr(bench_core, "time_ukf", lambda host, b, repeats: 123.0)
    monkeypatch.setattr(bench_core, "filterpy_ukf_time", lambda host, runs, repeats: 456.0)
    monkeypatch.setattr(bench_core, "one_track_latency", lambda host, repeats, steps: {})
    monkeypatch.setattr(bench_core, "curves", lambda out, size: [])
    monkeypatch.setattr("workbench.kernels.backend.numba_available", lambda: True)
    out = bench_core.bench(quick=True)
    n = 100_000  # ns per particle-step = seconds / 10 steps / 1e5 particles * 1e9
    assert out[f"pf_ns_per_particle_step_N{n}"] == pytest.approx(2000.0)
    assert out[f"stonesoup_ns_per_particle_step_N{n}"] == pytest.approx(30000.0)
    assert out[f"pf_over_stonesoup_N{n}"] == pytest.approx(1 / 15) and out[f"pf_speedup_vs_stonesoup_N{n}"] == 15.0
    assert out[f"met_pf_speedup_vs_stonesoup_N{n}"] is True  # 15 >= 10
    assert out[f"pf_floor_numpy_draws_ns_per_particle_step_N{n}"] == pytest.approx(numpy_s * 1000.0)
    assert out[f"pf_floor_compiled_draws_ns_per_particle_step_N{n}"] == pytest.approx(compiled_s * 1000.0)
    assert out[f"pf_floor_ns_per_particle_step_N{n}"] == pytest.approx(floor_ns)  # the faster of the two
    assert out[f"pf_over_floor_N{n}"] == pytest.approx(over_floor) and out[f"met_pf_over_floor_N{n}"] is met_floor
    assert out[f"pf_over_numpy_draws_floor_N{n}"] == pytest.approx(2.0 / numpy_s)
    assert out[f"pf_pos_rmse_m_N{n}"] == 1.5 and out[f"stonesoup_pos_rmse_m_N{n}"] == 2.0
    assert out["pf_ns_per_particle_step_N1000"] == pytest.approx(2e5)  # the same seconds over 1000 particles
    assert out["ukf_ns_per_run_step_B3000"] == 123.0 and out["filterpy_ukf_ns_per_run_step"] == 456.0


def test_sir_every_step_resamples_at_every_update():
    host = load_host()
    spec = bench_core.sir_every_step(host, 300)
    assert spec.params["particles"] == 300 and spec.params["threshold"] > 1.0
    truth, scans, prior, motion, model = bench_core.problem(2, 6)
    rng = np.random.default_rng(0)
    state = spec.init(prior, rng)
    assert state.cloud.particles.shape == (2, 300, 4)
    for k in range(6):
        if k:
            state = spec.predict(state, motion, rng)
        state = spec.update(state, scans.scan(k).for_filter(), model, rng)
    assert spec.diagnostics(state)["resamples"] == 2 * 6


# -- resampling ----------------------------------------------------------------------------------------


def _reference_sir(prior, scans, motion, model, rng, particles, threshold):
    """A textbook bootstrap PF (particle-major arrays, BLAS products, SciPy logsumexp, searchsorted
    resampling) making the same random draws in the same order as the built-in ``sir``."""
    B, n = prior.mean.shape
    N = particles
    x = prior.mean[:, None, :] + rng.standard_normal((B, N, n)) @ np.swapaxes(np.linalg.cholesky(prior.cov), 1, 2)
    log_w = np.full((B, N), -np.log(N))
    g = motion.Q_sqrt[:, np.any(motion.Q_sqrt != 0, axis=0)]
    r_inv = np.linalg.inv(model.R)
    means, covs = [], []
    for k in range(scans.steps):
        if k:
            x = x @ motion.F.T + rng.standard_normal((B, N, g.shape[1])) @ g.T
        nu = scans.z[:, k, 0][:, None, :] - model.h(x)
        nu[..., 1] = np.angle(np.exp(1j * nu[..., 1]))  # bearing wrapped to (-pi, pi]
        log_w = log_w - 0.5 * np.einsum("bni,ij,bnj->bn", nu, r_inv, nu)
        log_w = log_w - logsumexp(log_w, axis=1, keepdims=True)
        rows = np.flatnonzero(1.0 / np.sum(np.exp(2 * log_w), axis=1) < threshold * N)
        if rows.size:
            u0 = rng.random((rows.size, 1))
            for r, u in zip(rows, u0[:, 0]):
                cdf = np.cumsum(np.exp(log_w[r]))
                cdf[-1] = 1.0
                x[r] = x[r][np.searchsorted(cdf, (u + np.arange(N)) / N, side="right")]
                log_w[r] = -np.log(N)
        w = np.exp(log_w)
        means.append(np.stack([np.average(x[b], axis=0, weights=w[b]) for b in range(B)]))
        covs.append(np.stack([np.cov(x[b].T, aweights=w[b], bias=True) for b in range(B)]))
    return np.stack(means, axis=1), np.stack(covs, axis=1)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("particles, threshold", [(400, 0.5), (BLAS_MOMENT_PARTICLES + 904, 0.5), (3000, 2.0)])
def test_sir_equals_a_textbook_particle_filter_with_the_same_draws(particles, threshold, backend):
    if backend == "numba" and importlib.util.find_spec("numba") is None:
        pytest.skip("numba is not installed")
    truth, scans, prior, motion, model = bench_core.problem(3, 8, seed=4)
    spec = particle.make_sir(particles, threshold, backend=backend)
    rng = np.random.default_rng(21)
    state = spec.init(prior, rng)
    means, covs = [], []
    for k in range(scans.steps):
        if k:
            state = spec.predict(state, motion, rng)
        state = spec.update(state, scans.scan(k).for_filter(), model, rng)
        est = spec.estimate(state)
        means.append(est.mean)
        covs.append(est.cov)
    ref_mean, ref_cov = _reference_sir(prior, scans, motion, model, np.random.default_rng(21), particles, threshold)
    np.testing.assert_allclose(np.stack(means, axis=1), ref_mean, rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.stack(covs, axis=1), ref_cov, rtol=1e-8, atol=1e-8)
    assert 0 < state.resamples <= 3 * 8


def test_bench_problem_measurements_are_h_of_truth_plus_noise_of_r():
    # the timed problem is a real range-bearing tracking problem: whitened residuals of the measurements about
    # h(truth) are standard normal (a chi-square test of their squared sum) and the bearings are wrapped
    truth, scans, prior, motion, model = bench_core.problem(40, 25, seed=3)
    assert scans.z.shape == (40, 25, 1, 2) and np.all(np.abs(scans.z[..., 1]) <= np.pi)
    resid = model.residual(scans.z[:, :, 0], model.h(truth.states))
    white = resid / np.sqrt(np.diag(model.R))
    dof = white.size
    assert stats.chi2.sf(np.sum(white**2), dof) > 1e-3 and stats.chi2.cdf(np.sum(white**2), dof) > 1e-3
    # the truth moves as the motion model says: velocity increments have the model's process noise
    dv = np.diff(truth.states[..., 2:], axis=1) / motion.Q_sqrt[2, 2]
    assert stats.kstest(dv.ravel(), "norm").pvalue > 1e-3


def test_filterpy_ukf_of_the_benchmark_tracks_as_our_ukf_does():
    # the peer of the UKF figure solves the same problem with the same sigma points: its estimates agree with ours
    pytest.importorskip("filterpy")
    host = load_host()
    spec = host.filter("ukf")
    truth, scans, prior, motion, model = bench_core.problem(2, 30, seed=5)
    rng = np.random.default_rng(0)
    state = spec.init(prior, rng)
    ours = []
    for k in range(scans.steps):
        if k:
            state = spec.predict(state, motion, rng)
        state = spec.update(state, scans.scan(k).for_filter(), model, rng)
        ours.append(spec.estimate(state).mean)
    p = spec.params
    for r in range(2):
        ukf = bench_core._filterpy_ukf(prior.take(r), motion, model, p["alpha"], p["beta"], p["kappa"])
        ukf.update(scans.z[r, 0, 0])
        theirs = [ukf.x.copy()]
        for k in range(1, scans.steps):
            ukf.predict()
            ukf.update(scans.z[r, k, 0])
            theirs.append(ukf.x.copy())
        np.testing.assert_allclose(np.array(theirs), np.stack(ours, axis=1)[r], rtol=1e-6, atol=1e-6)
    # the shared builder (workbench.bench.peers) refuses a sensor it does not model
    from dataclasses import replace

    from workbench.bench.peers import filterpy_range_bearing_ukf

    with pytest.raises(ValueError, match="sensor at the origin"):
        filterpy_range_bearing_ukf(prior.mean[0], prior.cov[0], motion, replace(model, sensor_position=(5.0, 0.0)),
                                   p["alpha"], p["beta"], p["kappa"])


def test_the_one_track_runners_compute_the_same_track_as_filterpy():
    # the latency target compares like with like: our EKF and UKF, step by step at B = 1, end where FilterPy's do
    pytest.importorskip("filterpy", reason="FilterPy (the bench extra) is not installed")
    runs = bench_core.one_track_runners(load_host(), steps=60)
    np.testing.assert_allclose(runs["ekf"]().mean[0], runs["filterpy_ekf"](), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(runs["ukf"]().mean[0], runs["filterpy_ukf"](), rtol=1e-6, atol=1e-6)


# -- group motion ----------------------------------------------------------------------------------------


def _motion_fields(stonesoup: bool, filterpy: bool) -> dict:
    """Every figure of ``motion --quick`` -> ``"number"``, ``"bool"``, ``"string"`` or the one string it may be."""
    fields = {key: "number" for key in ("cpu_count", "load_avg_1min", "peak_rss_mib", "group_wall_s", "ukf_batch",
                                        "ukf_steps", "filterpy_runs", "pf_particles", "pf_steps",
                                        "ukf_ct_ns_per_run_step", "ukf_ct_pos_rmse_m", "sir_ct_ns_per_particle_step",
                                        "sir_ct_pos_rmse_m")}
    fields.update({key: "string" for key in ("numpy_version", "stonesoup_version", "kernel_arch", "pf_backend",
                                             "ct_rate_backend", "target_ukf_ct_speedup_vs_filterpy",
                                             "target_sir_ct_speedup_vs_stonesoup")})
    for K in bench_core.KERNEL_STATES:
        for name in ("f", "jacobian"):
            for key in ("ct_rate_{}_numpy_ns_per_state", "ct_rate_{}_ns_per_state", "ct_rate_{}_speedup_over_numpy"):
                fields[f"{key.format(name)}_K{K}"] = "number"
    for key, kind in (("filterpy_ukf_ct_ns_per_run_step", "number"), ("ukf_ct_max_abs_difference_vs_filterpy", "number"),
                      ("measured_ukf_ct_speedup_vs_filterpy", "number"), ("met_ukf_ct_speedup_vs_filterpy", "bool")):
        fields[key] = kind if filterpy else "not installed"
    if filterpy:
        fields["note_ukf_ct_speedup_vs_filterpy"] = "string"
    for key, kind in (("stonesoup_ct_ns_per_particle_step", "number"), ("stonesoup_ct_pos_rmse_m", "number"),
                      ("measured_sir_ct_speedup_vs_stonesoup", "number"), ("met_sir_ct_speedup_vs_stonesoup", "bool")):
        fields[key] = kind if stonesoup else "not installed"
    if stonesoup:
        fields["note_sir_ct_speedup_vs_stonesoup"] = "string"
    return fields


@pytest.mark.slow
def test_bench_quick_motion_reports_every_figure_and_its_targets(tmp_path):
    out = tmp_path / "bench.json"
    code = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", code, "bench", "--quick", "--only", "motion", "--json", str(out)],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(out.read_text())
    assert report["quick"] is True and list(report["groups"]) == ["motion"]
    motion = report["groups"]["motion"]
    assert "error" not in motion, motion.get("error")
    stonesoup = importlib.util.find_spec("stonesoup") is not None
    filterpy = importlib.util.find_spec("filterpy") is not None
    expected = _motion_fields(stonesoup, filterpy)
    assert set(motion) == set(expected), f"missing {set(expected) - set(motion)}, unexpected {set(motion) - set(expected)}"
    for key, kind in expected.items():
        value = motion[key]
        if kind == "number":
            assert isinstance(value, (int, float)) and not isinstance(value, bool), (key, value)
            assert math.isfinite(value) and value >= 0, (key, value)
        elif kind == "bool":
            assert isinstance(value, bool), (key, value)
        elif kind == "string":
            assert isinstance(value, str) and value, (key, value)
        else:
            assert value == kind, (key, value)
    sizes = bench_core.MOTION_SIZES["quick"]
    assert (motion["ukf_batch"], motion["pf_particles"]) == (sizes["batch"], sizes["particles"])
    assert motion["target_ukf_ct_speedup_vs_filterpy"] == ">= 100"
    assert motion["target_sir_ct_speedup_vs_stonesoup"] == ">= 10"
    assert motion["ct_rate_backend"] == ("numba" if importlib.util.find_spec("numba") else "numpy (the policy's taichi)")
    # both filters track the turn (range noise 5 m, cross-range 0.005 rad x 1.5 km = 7.5 m)
    assert motion["ukf_ct_pos_rmse_m"] < 30.0 and motion["sir_ct_pos_rmse_m"] < 30.0
    if filterpy:  # FilterPy's UKF with the same fx computed the same estimates
        assert motion["ukf_ct_max_abs_difference_vs_filterpy"] < 1e-6
    if stonesoup:  # Stone Soup solved the same problem: its error is of the same size as ours
        assert motion["stonesoup_ct_pos_rmse_m"] < 3.0 * motion["sir_ct_pos_rmse_m"] + 5.0
    # the printed table: one line per target, indicative in quick mode
    table = proc.stdout[proc.stdout.index("targets (quick"):].splitlines()
    lines = [line.split() for line in table[2:] if line.startswith("motion ")]
    assert sorted((line[1], line[-1]) for line in lines) == [("sir_ct_speedup_vs_stonesoup", "indicative"),
                                                             ("ukf_ct_speedup_vs_filterpy", "indicative")]


def test_motion_figures_from_hand_made_timings(monkeypatch):
    # the arithmetic from timings to figures: per pair (ours, theirs, median ratio) in seconds; the UKF batch B and
    # FilterPy's runs differ, so the speed-up per run-step is (B / runs) / ratio; the kernels' ratio is NumPy / ours
    sizes = bench_core.MOTION_SIZES["quick"]
    B, runs, steps = sizes["batch"], sizes["filterpy_runs"], sizes["ukf_steps"]
    N, pf_steps = sizes["particles"], sizes["pf_steps"]

    pytest.importorskip("filterpy")

    def tagged(tag, **attrs):
        def run():
            return None
        run.tag = tag
        run.__dict__.update(attrs)
        return run

    def paired(a, b, repeats):
        # our UKF and FilterPy's, our PF and Stone Soup's; the kernels' runs (untagged): the twin and the policy's
        return {"ukf": (0.3, 0.2, 1.5), "sir": (0.1, 1.2, 1 / 12)}.get(getattr(a, "tag", None), (2.0, 0.5, 4.0))

    def problem_runner(spec, prob, seed, tag):
        means = np.zeros((B, steps, 5)) if tag == "motion-ukf" else None
        return tagged("ukf" if tag == "motion-ukf" else "sir", means=means), lambda: 4.0

    theirs = np.zeros((runs, steps, 5))
    theirs[1, 2, 3] = 2e-9
    monkeypatch.setattr(bench_core, "paired_times", paired)
    monkeypatch.setattr(bench_core, "ct_problem", lambda batch, steps, seed=0: None)
    monkeypatch.setattr(bench_core, "_problem_runner", problem_runner)
    monkeypatch.setattr(bench_core, "filterpy_ct_runner", lambda host, prob, runs: tagged("fp", means=theirs))
    monkeypatch.setattr(bench_core, "stonesoup_version", lambda: "1.0")
    monkeypatch.setattr(bench_core, "ct_stonesoup_runner", lambda n, steps: (tagged("ss"), lambda: 5.0))
    monkeypatch.setattr(bench_core, "KERNEL_STATES", (1000,))
    out = bench_core.bench_motion(quick=True)
    assert out["ukf_ct_ns_per_run_step"] == pytest.approx(0.3 / (B * steps) * 1e9)
    assert out["filterpy_ukf_ct_ns_per_run_step"] == pytest.approx(0.2 / (runs * steps) * 1e9)
    assert out["measured_ukf_ct_speedup_vs_filterpy"] == pytest.approx((B / runs) / 1.5)
    assert out["met_ukf_ct_speedup_vs_filterpy"] is ((B / runs) / 1.5 >= 100)
    assert out["ukf_ct_max_abs_difference_vs_filterpy"] == pytest.approx(2e-9)
    assert out["sir_ct_ns_per_particle_step"] == pytest.approx(0.1 / (N * pf_steps) * 1e9)
    assert out["stonesoup_ct_ns_per_particle_step"] == pytest.approx(1.2 / (N * pf_steps) * 1e9)
    assert out["measured_sir_ct_speedup_vs_stonesoup"] == pytest.approx(12.0)
    assert out["met_sir_ct_speedup_vs_stonesoup"] is True
    assert out["sir_ct_pos_rmse_m"] == 4.0 and out["stonesoup_ct_pos_rmse_m"] == 5.0
    assert out["ct_rate_f_numpy_ns_per_state_K1000"] == pytest.approx(2e6)  # 2 s over 1000 states
    assert out["ct_rate_f_ns_per_state_K1000"] == pytest.approx(5e5)
    assert out["ct_rate_jacobian_speedup_over_numpy_K1000"] == 4.0


def test_motion_peers_compute_what_ours_compute():
    # the UKF's peer, FilterPy's UKF with the model's f as fx, gives our batched UKF's estimates on the same runs; the
    # PF's peer, Stone Soup's ConstantTurn, propagates as our model's f does (noise-free) and carries our Q
    pytest.importorskip("filterpy")
    host = load_host()
    prob = bench_core.ct_problem(4, 8, seed=2)
    ours, _ = bench_core._problem_runner(host.filter("ukf"), prob, 0, "test")
    ours()
    theirs = bench_core.filterpy_ct_runner(host, prob, 2)
    theirs()
    np.testing.assert_allclose(theirs.means, ours.means[:2], rtol=1e-9, atol=1e-9)
    pytest.importorskip("stonesoup")
    import datetime

    from stonesoup.types.state import State

    motion = prob[3]
    turn = bench_core._StoneSoupTurn.build(motion)
    x = np.array([[100.0, -50.0, 12.0, -7.0, 0.3], [10.0, 20.0, -3.0, 4.0, -0.02]])
    order = list(bench_core.STONESOUP_ORDER)
    one_second = datetime.timedelta(seconds=1.0)
    moved = np.stack([np.asarray(turn.function(State(row[order][:, None]), noise=False, time_interval=one_second),
                                 dtype=float)[:, 0] for row in x])
    np.testing.assert_allclose(moved[:, np.argsort(order)], motion.f_numpy(x), rtol=1e-12, atol=1e-9)
    Q = np.asarray(turn.covar(time_interval=datetime.timedelta(seconds=1.0)))
    np.testing.assert_allclose(Q[np.ix_(np.argsort(order), np.argsort(order))], motion.Q, rtol=0, atol=0)
