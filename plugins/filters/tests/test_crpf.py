"""The cost-reference particle filter against hand-computed references (Table 6 of paper 003)."""

import numpy as np
import pytest

from workbench.filtering import run_filter
from workbench.models import MeasurementModel, linear_measurement, random_walk_velocity, range_bearing
from workbench.plugins import load_host
from workbench.resampling import systematic_resample
from workbench.rng import generator
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, InputError, Scan
from workbench_filters.crpf import CRPFParams, incremental_cost, log_pmf, make_crpf

HOST = load_host()


def _wrap(a):
    return np.angle(np.exp(1j * a))


def test_selection_pmf_is_finite_with_huge_costs():
    costs = np.array([
        [1e300, 0.0, 1e308, 5.0],
        [1e300, 1e300 * 1.5, 1.7e308, 1e299],  # all huge: the PMF still favours the smallest
        [np.inf, 3.0, np.inf, 4.0],  # overflowed costs get weight zero
        [np.inf, np.inf, np.inf, np.inf],  # nothing to choose from: uniform, not NaN
    ])
    lp = log_pmf(costs, beta=2.0, delta=0.01)
    assert not np.any(np.isnan(lp))
    w = np.exp(lp - lp.max(axis=1, keepdims=True))
    w /= w.sum(axis=1, keepdims=True)
    assert np.all(np.isfinite(w)) and np.allclose(w.sum(axis=1), 1.0)
    assert np.argmax(w[0]) == 1 and np.argmax(w[1]) == 3
    assert w[2, 0] == 0.0 and w[2, 2] == 0.0
    assert np.allclose(w[3], 0.25)
    # where the direct formula is representable it agrees: pi ~ (C - min C + delta)^-beta
    direct = (np.array([0.0, 2.0, 7.0]) + 0.01) ** -2.0
    lp2 = log_pmf(np.array([[3.0, 5.0, 10.0]]), 2.0, 0.01)[0]
    assert np.allclose(np.exp(lp2 - lp2.max()) / np.exp(lp2 - lp2.max()).sum(), direct / direct.sum())
    # systematic resampling of a huge-cost row never picks a zero-weight particle
    idx = systematic_resample(lp, np.random.default_rng(0))
    assert not np.any(np.isin(idx[2], [0, 2]))
    # the relative offset: delta_C = delta (mean C - min C) over the finite costs, and the same guarantees
    lr = log_pmf(costs, beta=2.0, delta=0.3, relative=True)
    assert not np.any(np.isnan(lr)) and lr[2, 0] == -np.inf and np.allclose(lr[3], lr[3, 0])
    row = np.array([3.0, 5.0, 10.0])
    lr2 = log_pmf(row[None], 2.0, 0.3, relative=True)[0]
    direct = (row - 3.0 + 0.3 * (row.mean() - 3.0)) ** -2.0
    assert np.allclose(np.exp(lr2 - lr2.max()) / np.exp(lr2 - lr2.max()).sum(), direct / direct.sum())


def test_systematic_resampling_preserves_expected_counts():
    rng = np.random.default_rng(1)
    costs = rng.exponential(3.0, size=(1, 50))
    lp = log_pmf(costs, 2.0, 0.01)
    w = np.exp(lp - lp.max())
    w = (w / w.sum())[0]
    N = 50
    draws = 4000
    idx = systematic_resample(np.repeat(lp, draws, axis=0), rng)
    counts = np.stack([np.bincount(row, minlength=N) for row in idx])
    # every draw gives floor(N w) or ceil(N w) copies ...
    assert np.all(counts >= np.floor(N * w) - 1e-9) and np.all(counts <= np.ceil(N * w) + 1e-9)
    # ... and the expected count is exactly N w: the count is floor(N w) + Bernoulli(frac(N w)), so the
    # mean over draws lies within 5 standard errors sqrt(p (1 - p) / draws) of N w
    frac = N * w - np.floor(N * w)
    se = np.sqrt(frac * (1 - frac) / draws)
    assert np.all(np.abs(counts.mean(axis=0) - N * w) <= 5 * se + 1e-12)


def test_jitter_schedule():
    p = CRPFParams(particles=100, kappa=1.0, variance="fixed")
    # fixed: sigma^2 = kappa / N^(2 / dim) = 1 / 100^(1/2)
    assert np.allclose(p.jitter_std(4), np.sqrt(0.1))
    q = CRPFParams(particles=500, kappa=10.0, scale=(1.0, 1.0, 0.1, 0.1), variance="fixed")
    assert np.allclose(q.jitter_std(4), np.sqrt(10.0 / np.sqrt(500.0)) * np.array([1, 1, 0.1, 0.1]))
    # adaptive: every particle starts from sigma_0 = sigma0, whatever N
    assert np.allclose(CRPFParams(particles=500, sigma0=0.7).jitter_std(4), 0.7)
    with pytest.raises(InputError, match="scale has 4 entries"):
        CRPFParams(scale=(1, 1, 1, 1)).jitter_std(6)


@pytest.mark.parametrize("backend", ["numpy", "auto"])
def test_one_particle_follows_table_6(backend):
    # N = 1: selection is trivial, so the cost C_t = lam C_{t-1} + ||y_t - h(x_t)||^q and the variance
    # sigma_t^2 = ((t-1)/t) sigma_{t-1}^2 + ||x_t - f(x_{t-1})||^2 / (t dim) can be checked by hand.
    spec = make_crpf(particles=1, lam=0.8, q=1.5, sigma0=0.5, cost="norm", backend=backend)
    model = range_bearing(1.0, 0.1)
    motion = random_walk_velocity(2, 1.0, 0.1)
    rng = generator(0, "crpf-one")
    prior = Gaussian.broadcast([100.0, 50.0, -1.0, 1.0], np.diag([1.0, 1.0, 0.1, 0.1]), 3)
    state = spec.init(prior, rng)
    assert np.all(state.variances == 0.25)
    zs = [np.array([[111.0, 0.47]] * 3), np.array([[110.0, 0.48]] * 3), np.array([[109.5, 3.1]] * 3),
          np.array([[109.0, 0.5]] * 3)]
    expected, s2 = np.zeros(3), np.full(3, 0.25)
    for k, z in enumerate(zs):
        if k:
            before = state.particles[:, 0].copy()
            state = spec.predict(state, motion, rng)
        state = spec.update(state, Scan.single(z), model, rng)
        x = state.particles[:, 0]
        res = z - np.stack([np.hypot(x[:, 0], x[:, 1]), np.arctan2(x[:, 1], x[:, 0])], axis=-1)
        res[:, 1] = _wrap(res[:, 1])
        inc = np.sum(res ** 2, axis=1) ** 0.75
        expected = 0.8 * expected + inc if k else inc
        assert np.allclose(state.costs[:, 0], expected, rtol=1e-12)
        if k:
            moved = np.sum((x - before @ motion.F.T) ** 2, axis=1)
            s2 = (k - 1) / k * s2 + moved / (k * 4)
            assert np.allclose(state.variances[:, 0], s2, rtol=1e-10) and np.all(state.steps == k)


def test_one_particle_follows_the_cost_recursion_with_a_fixed_variance():
    # N = 1: selection is trivial, so C_t = lam C_{t-1} + ||y_t - h(x_t)||^q can be checked by hand.
    spec = make_crpf(particles=1, lam=0.8, q=1.5, kappa=0.5, variance="fixed", cost="norm")
    model = range_bearing(1.0, 0.1)
    motion = random_walk_velocity(2, 1.0, 0.1)
    rng = generator(0, "crpf-one")
    prior = Gaussian.broadcast([100.0, 50.0, -1.0, 1.0], np.diag([1.0, 1.0, 0.1, 0.1]), 3)
    state = spec.init(prior, rng)
    zs = [np.array([[111.0, 0.47]] * 3), np.array([[110.0, 0.48]] * 3), np.array([[109.5, 3.1]] * 3)]
    expected = np.zeros((3, 1))
    for k, z in enumerate(zs):
        if k:
            before = state.particles.copy()
            state = spec.predict(state, motion, rng)
        state = spec.update(state, Scan.single(z), model, rng)
        x = state.particles[:, 0]
        if k:
            moved = x - before[:, 0] @ motion.F.T
            # propagation noise has the documented per-component std (only 3 x 4 draws: loose bound)
            assert np.all(np.abs(moved) < 6 * np.sqrt(0.5))
        res = z - np.stack([np.hypot(x[:, 0], x[:, 1]), np.arctan2(x[:, 1], x[:, 0])], axis=-1)
        res[:, 1] = _wrap(res[:, 1])
        inc = np.sum(res ** 2, axis=1) ** 0.75
        expected = (0.8 * expected[:, 0] + inc if k else inc)[:, None]
        assert np.allclose(state.costs, expected, rtol=1e-12)


@pytest.mark.parametrize("mode", ["absolute", "relative"])
def test_estimate_is_the_cost_weighted_mean_and_covariance(mode):
    spec = make_crpf(particles=200, beta=2.0, delta=0.01 if mode == "absolute" else 0.3, delta_mode=mode)
    model = range_bearing(1.0, 0.1)
    rng = generator(0, "crpf-estimate")
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 2)
    state = spec.update(spec.init(prior, rng), Scan.single(np.array([[111.8, 0.46], [112.0, 0.45]])), model, rng)
    est = spec.estimate(state)
    c = state.costs
    offset = 0.01 if mode == "absolute" else 0.3 * (c.mean(axis=1, keepdims=True) - c.min(axis=1, keepdims=True))
    w = (c - c.min(axis=1, keepdims=True) + offset) ** -2.0
    w /= w.sum(axis=1, keepdims=True)
    mean = np.einsum("bn,bni->bi", w, state.particles)
    d = state.particles - mean[:, None, :]
    assert np.allclose(est.mean, mean)
    assert np.allclose(est.cov, np.einsum("bn,bni,bnj->bij", w, d, d))


def test_initial_particles_fill_the_documented_box():
    spec = make_crpf(particles=20000)
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 1)
    x = spec.init(prior, generator(0, "box")).particles[0]
    lo, hi = x.min(axis=0), x.max(axis=0)
    assert np.allclose(lo, [100.0, 30.0, -2.0, -2.0], atol=0.05) and np.allclose(hi, [120.0, 50.0, 2.0, 2.0], atol=0.05)


def test_noise_statistics_are_never_read():
    # Same h, different Q and R: identical output (the CRPF uses F, h and the residual only).
    rng = generator(0, "crpf-noise")
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (4, 1)), random_walk_velocity(2, 1.0, 0.1), 15, rng)
    scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=1.0, sigma_theta=0.1)
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 4)
    spec = HOST.filter("crpf-100")
    a = run_filter(spec, prior, random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1), scans, generator(1, "f"))
    b = run_filter(spec, prior, random_walk_velocity(2, 1.0, 5.0), range_bearing(30.0, 0.9), scans, generator(1, "f"))
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)


def test_tracks_with_accurate_measurements():
    rng = generator(0, "crpf-track")
    B = 20
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (B, 1)), random_walk_velocity(2, 1.0, 0.01), 40, rng)
    scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=0.1, sigma_theta=0.01)
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), B)
    est = run_filter(HOST.filter("crpf-100"), prior, random_walk_velocity(2, 1.0, 0.1),
                     range_bearing(1.0, 0.1), scans, generator(0, "crpf-track-filter"))
    err = np.hypot(*(est.mean[..., :2] - truth.states[..., :2]).transpose(2, 0, 1))
    assert np.median(err[:, -10:]) < 3.0  # started 14 m off
    assert est.diagnostics["selections"] == B * 39


def test_arc_length_cost():
    model = range_bearing(1.0, 0.1)
    p = CRPFParams(q=3.0, cost="arc-length")
    z = np.array([[100.0, 0.5]])
    x = np.array([[[np.cos(0.45) * 98.0, np.sin(0.45) * 98.0, 0.0, 0.0]]])
    got = incremental_cost(z, x, model, p)
    assert np.allclose(got, ((100.0 - 98.0) ** 2 + (100.0 * 0.05) ** 2) ** 1.5)
    positions = linear_measurement(np.eye(2, 4), np.eye(2))
    with pytest.raises(InputError, match="one range component"):
        incremental_cost(z, x, positions, p)


def test_missed_detection_moves_the_cloud_blindly():
    spec = make_crpf(particles=50)
    model = range_bearing(1.0, 0.1)
    motion = random_walk_velocity(2, 1.0, 0.1)
    rng = generator(0, "crpf-blind")
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 2)
    state = spec.update(spec.init(prior, rng), Scan.single(np.array([[111.8, 0.46]] * 2)), model, rng)
    pred = spec.predict(state, motion, rng)
    assert spec.update(pred, Scan.single(np.zeros((2, 2)), present=np.array([False, False])), model, rng) is pred
    missed = spec.update(pred, Scan.single(np.array([[111.0, 0.45]] * 2), present=np.array([True, False])), model, rng)
    assert missed.pending.tolist() == [False, True]
    again = spec.predict(missed, motion, rng)
    assert spec.diagnostics(again)["blind_moves"] == 1
    assert np.allclose(again.costs[1], 0.95 * state.costs[1])  # C <- lam C without a measurement
    # the blind move is a propagation: item 1 has moved as often as item 0 and its variances were updated
    assert again.steps.tolist() == [1, 1] and not np.array_equal(again.variances[1], missed.variances[1])


def test_parameters_are_validated():
    for bad in (dict(lam=0.0), dict(q=0.5), dict(beta=0.0), dict(delta=0.0), dict(kappa=-1.0), dict(cost="l1"),
                dict(particles=0), dict(scale=(1.0, -1.0, 1.0, 1.0)), dict(sigma0=0.0), dict(variance="running"),
                dict(delta_mode="median"), dict(scale=(1.0, 1.0, 0.0, 0.0))):  # adaptive divides by the scale
        with pytest.raises(InputError, match="crpf"):
            make_crpf(**{"particles": 10, **bad})
    make_crpf(particles=10, variance="fixed", scale=(1.0, 1.0, 0.0, 0.0))  # a fixed variance may zero a component
    with pytest.raises(InputError, match="variance"):
        HOST.filter("crpf-100").configure(variance="running")


def test_nan_measurement_is_refused():
    spec = make_crpf(particles=10)
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 2)
    scan = Scan.single(np.array([[1.0, 0.1], [2.0, 0.2]]))
    object.__setattr__(scan, "z", np.array([[[1.0, 0.1]], [[np.nan, 0.2]]]))
    with pytest.raises(InputError, match="not finite"):
        spec.update(spec.init(prior, generator(0, "nan")), scan, range_bearing(1.0, 0.1), generator(0, "nan"))


def test_works_for_any_measurement_model():
    # The plain cost needs only h and residual: a custom model with a 3-D measurement.
    model = MeasurementModel("xyz", h=lambda x: np.concatenate([x[..., :2], x[..., 2:3] * 2], axis=-1),
                             R=np.eye(3))
    spec = make_crpf(particles=30, cost="norm")
    prior = Gaussian.broadcast([1.0, 2.0, 0.0, 0.0], np.eye(4), 3)
    rng = generator(0, "xyz")
    state = spec.update(spec.init(prior, rng), Scan.single(np.ones((3, 3))), model, rng)
    assert state.costs.shape == (3, 30) and np.all(np.isfinite(spec.estimate(state).mean))


def test_registered_filters_and_configured_variants():
    crpf = sorted(n for n in HOST.filters if n.startswith("crpf"))
    assert crpf == ["crpf-100", "crpf-300", "crpf-500"]
    for n in (100, 300, 500):
        p = HOST.filter(f"crpf-{n}").params
        assert p["particles"] == n and p["variance"] == "adaptive" and p["cost"] == "arc-length"
        assert p["delta_mode"] == "relative"
        assert "range_bearing_input" in HOST.filter(f"crpf-{n}").capabilities
    # the previous reconstruction is a configuration of crpf-100, named as asked, and the same filter as make_crpf's
    previous = HOST.filter("crpf-100").configure(name="crpf-100 previous", variance="fixed", kappa=1.0,
                                                 scale=[0.5, 0.5, 1.0, 1.0], cost="norm", delta_mode="absolute",
                                                 delta=0.01)
    assert previous.name == "crpf-100 previous" and "range_bearing_input" not in previous.capabilities
    direct = make_crpf(100, variance="fixed", kappa=1.0, scale=(0.5, 0.5, 1.0, 1.0), cost="norm",
                       delta_mode="absolute", delta=0.01)
    rng = generator(0, "crpf-configure")
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (3, 1)), random_walk_velocity(2, 1.0, 0.1), 10, rng)
    scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=1.0, sigma_theta=0.1)
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), 3)
    motion, model = random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1)
    a = run_filter(previous, prior, motion, model, scans, generator(1, "f"))
    b = run_filter(direct, prior, motion, model, scans, generator(1, "f"))
    assert np.array_equal(a.mean, b.mean)
    # and differs from the paper setting on the same data and random numbers
    c = run_filter(HOST.filter("crpf-100"), prior, motion, model, scans, generator(1, "f"))
    assert not np.allclose(a.mean, c.mean)


def test_the_adaptive_variance_follows_the_process_noise():
    # Table 6's variance is carried through selection: lineages whose moves fit the measurements survive, so with
    # a process noise far above sigma0 the particles' sigma grows over the run, and with none it stays small
    B = 30
    motion_truth = {1.0: random_walk_velocity(2, 1.0, 1.0), 0.0: random_walk_velocity(2, 1.0, 0.0)}
    sigma = {}
    for sa, motion in motion_truth.items():
        rng = generator(3, "crpf-adapt", sa)
        truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (B, 1)), motion, 60, rng)
        scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=0.5, sigma_theta=0.005)
        spec = make_crpf(100, sigma0=0.3)
        state = spec.init(Gaussian.broadcast([100.0, 50.0, -1.0, 1.0], np.diag([1.0, 1.0, 0.1, 0.1]), B), rng)
        for k in range(60):
            if k:
                state = spec.predict(state, motion, rng)
            state = spec.update(state, scans.scan(k).for_filter(), range_bearing(0.5, 0.005), rng)
        sigma[sa] = float(np.median(np.sqrt(state.variances)))
    assert sigma[1.0] > 0.3 > sigma[0.0]


# -- the parameters are declared once (PARAMETERS): the factory's signature, checks, setting and params follow it ----


def _module_with(path, old, new, monkeypatch):
    """The module at ``path`` executed afresh with ``old`` (which occurs once) replaced by ``new``."""
    import importlib.util
    import sys

    text = path.read_text(encoding="utf-8")
    assert text.count(old) == 1, old
    # a module of the plugin's package (its relative imports of the package's kernels resolve there)
    name = f"workbench_filters.{path.parent.name}._patched" if path.name == "__init__.py" else \
        f"workbench_filters._patched_{path.stem}"
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader(name, loader=None))
    monkeypatch.setitem(sys.modules, name, module)
    exec(compile(text.replace(old, new), str(path), "exec"), module.__dict__)
    return module


def _crpf_problem(B=3, steps=5):
    rng = generator(8, "crpf-declared")
    motion, model = random_walk_velocity(2, 1.0, 0.3), range_bearing(1.0, 0.02, sensor=(0.0, 0.0))
    truth = sample_motion(np.tile([150.0, 80.0, 1.0, -1.0], (B, 1)), motion, steps, rng)
    scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=1.0, sigma_theta=0.02)
    return Gaussian.broadcast([152.0, 78.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), B), motion, model, scans


def test_a_changed_declared_default_changes_the_built_filter(monkeypatch):
    from pathlib import Path

    import workbench_filters.crpf as crpf

    path = Path(crpf.__file__)
    patched = _module_with(path, 'Param("particles", 100,', 'Param("particles", 7,', monkeypatch)
    spec = patched.make_crpf()
    assert spec.params["particles"] == 7 and spec.name == "crpf-7" and patched.CRPFParams().particles == 7
    state = spec.init(Gaussian.broadcast(np.zeros(4), np.eye(4), 2), generator(0, "x"))
    assert state.particles.shape == (2, 7, 4)
    # a default the factory body never names: lam, through the setting to the filter's numbers
    patched = _module_with(path, 'Param("lam", 0.95,', 'Param("lam", 0.5,', monkeypatch)
    prior, motion, model, scans = _crpf_problem()
    specs = {"patched": patched.make_crpf(particles=30), "asked": make_crpf(particles=30, lam=0.5),
             "default": make_crpf(particles=30)}
    run = {label: run_filter(spec, prior, motion, model, scans, generator(9, "crpf-declared")).mean
           for label, spec in specs.items()}
    assert patched.make_crpf().params["lam"] == 0.5 and patched.CRPFParams().lam == 0.5
    np.testing.assert_array_equal(run["patched"], run["asked"])
    assert not np.allclose(run["patched"], run["default"])


def test_the_factory_comes_from_the_declaration():
    import inspect

    from workbench.params import defaults
    from workbench_filters.crpf import PARAMETERS

    sig = inspect.signature(make_crpf)
    assert [(p.name, p.default) for p in sig.parameters.values()][:-1] == [(p.name, p.default) for p in PARAMETERS]
    assert sig.parameters["name"].kind is inspect.Parameter.KEYWORD_ONLY
    assert make_crpf().params == defaults(PARAMETERS) and list(make_crpf().params) == [p.name for p in PARAMETERS]
    assert make_crpf(300).params["particles"] == 300 and make_crpf(300, 0.9).params["lam"] == 0.9
    assert make_crpf(particles=40.0).params["particles"] == 40  # an integral float, as the declaration allows
    with pytest.raises(InputError, match=r"crpf: unknown parameter 'partcles' \(parameters: backend, "):
        make_crpf(partcles=300)
    with pytest.raises(InputError, match="unknown parameter 'partcles'"):
        HOST.filter("crpf-100").configure(partcles=300)
    with pytest.raises(InputError, match="'particles' is given both by position and by keyword"):
        make_crpf(300, particles=200)
    with pytest.raises(InputError, match="crpf: takes at most 13 positional values"):
        make_crpf(*range(1, 15))
    with pytest.raises(InputError, match="crpf: box: must be <= 1000"):
        CRPFParams(box=2e3)  # the setting holds its declaration too, not only the factory
    assert CRPFParams(particles=12.0).particles == 12 and isinstance(CRPFParams(lam=1).lam, float)


def test_a_default_that_breaks_its_own_declaration_is_refused():
    from workbench.params import Param, declared_factory

    with pytest.raises(InputError, match=r"toy \(declared defaults\): n: must be >= 1, got 0"):
        declared_factory((Param("n", 0, "count", "int", unit="dimensionless", minimum=1),), "toy")


def test_a_non_finite_estimate_from_the_fused_kernel_is_refused_by_name(monkeypatch):
    """The fused step's moments become the belief without a second pass of Gaussian's checks, but only after
    every number is checked finite: a NaN the kernel wrote is refused naming the estimate, never passed on."""
    import workbench_filters.crpf as crpf

    real = crpf.crpf_step
    calls = []

    def poisoned(*args, **kwargs):
        out = real(*args, **kwargs)
        out[3][0, 2] = np.nan  # the mean's vx of item 0
        calls.append(1)
        return out

    spec = make_crpf(particles=20)
    model, motion = range_bearing(1.0, 0.1), random_walk_velocity(2, 1.0, 0.1)
    prior = Gaussian.broadcast([100.0, 50.0, -1.0, 1.0], np.diag([1.0, 1.0, 0.1, 0.1]), 2)
    rng = generator(0, "poisoned")
    state = spec.init(prior, rng)
    state = spec.update(state, Scan.single(np.array([[111.0, 0.46], [111.0, 0.46]])), model, rng)
    state = spec.predict(state, motion, rng)
    monkeypatch.setattr(crpf, "crpf_step", poisoned)
    with pytest.raises(InputError, match=r"Gaussian.mean holds a non-finite value .* index \(0, 2\)"):
        spec.update(state, Scan.single(np.array([[110.0, 0.47], [110.0, 0.47]])), model, rng)
    assert calls  # the fused kernel ran
