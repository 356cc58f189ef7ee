"""The plugin test kit: named conformance checks for filter plugins.

Checks are chosen by a filter's declared capabilities (:data:`workbench.specs.CAPABILITIES`), never
by its name.  Each check is a plain function ``check(spec)`` that raises ``AssertionError`` with a
readable message; use them from pytest (:func:`workbench.testing.parametrize_with_checks`) or without
it (:func:`run_checks`, ``workbench check-plugin NAME``).

The reference problems are built here, independently of every plugin: a 2-D constant-velocity target
with position measurements (linear-Gaussian, with a closed-form Kalman filter written out below) and
the same target seen in range and bearing.
"""

from __future__ import annotations

import numpy as np

from ..metrics import chi2_band, nees
from ..models import MeasurementModel, constant_velocity, linear_measurement, range_bearing
from ..rng import generator
from ..specs import FilterSpec
from ..tracking import Direct, run
from ..trajectory import sample_motion
from ..types import Gaussian, Scan, Scans
from ._common import Check, Outcome, run_kit

__all__ = ["Check", "CHECKS", "checks_for", "run_checks", "Outcome", "reference_kalman"]

_DT = 1.0
_STEPS = 25


# -- reference problems -------------------------------------------------------------------------------


def _motion():
    return constant_velocity(2, _DT, 0.5)


def _linear_model():
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    return linear_measurement(H, np.diag([4.0, 4.0]), name="kit-position", frame="cartesian-2d", std=(2.0, 2.0))


def _polar_model():
    return range_bearing(2.0, 0.02)


def _uses_polar(spec: FilterSpec) -> bool:
    return "range_bearing_input" in spec.capabilities


def _uses_3d(spec: FilterSpec) -> bool:
    return "position_doppler_3d" in spec.capabilities


def _position_doppler_model():
    """``h(s) = [x, y, z, (p . v) / |p|]`` for ``s = [x, y, z, vx, vy, vz]``, radar at the origin."""

    def h(s):
        p, v = s[..., :3], s[..., 3:]
        r = np.linalg.norm(p, axis=-1, keepdims=True)
        return np.concatenate([p, np.sum(p * v, axis=-1, keepdims=True) / r], axis=-1)

    def jac(s):
        p, v = s[:, :3], s[:, 3:]
        r = np.linalg.norm(p, axis=-1, keepdims=True)
        out = np.zeros((s.shape[0], 4, 6))
        out[:, :3, :3] = np.eye(3)
        out[:, 3, :3] = v / r - np.sum(p * v, axis=-1, keepdims=True) * p / r**3
        out[:, 3, 3:] = p / r
        return out

    from ..sensing.radar import RadarParameters, detection_model

    return MeasurementModel("kit-position-doppler", h, np.diag([100.0**2] * 3 + [2.0**2]), jac,
                            frame="position-doppler-3d", std=(100.0, 100.0, 100.0, 2.0),
                            sensor_position=(0.0, 0.0, 0.0), detection=detection_model(RadarParameters(), 2.0))


def _problem(spec: FilterSpec, batch: int, seed: int, steps: int = _STEPS, nonlinear: bool = False):
    """Truth, scans, prior and models for ``batch`` runs, chosen by the filter's capabilities:
    2-D constant velocity seen in position (linear) or range-bearing, or 3-D constant velocity seen in
    position and radial velocity with SNR."""
    rng = generator(seed, "kit", batch)
    if _uses_3d(spec):
        motion = constant_velocity(3, _DT, 2.0)
        model = _position_doppler_model()
        x0 = np.array([30e3, 5e3, 3e3, -200.0, 0.0, 0.0])
        P0 = np.diag([200.0**2] * 3 + [10.0**2] * 3)
    else:
        motion = _motion()
        polar = _uses_polar(spec) or (nonlinear and "linear_only" not in spec.capabilities)
        model = _polar_model() if polar else _linear_model()
        x0 = np.array([300.0, 200.0, -3.0, 4.0])
        P0 = np.diag([25.0, 25.0, 4.0, 4.0])
    n = x0.shape[0]
    start = x0 + rng.standard_normal((batch, n)) @ np.linalg.cholesky(P0).T
    truth = sample_motion(start, motion, steps, rng)
    noise = rng.standard_normal((batch, steps, model.dim)) @ np.linalg.cholesky(model.R).T
    z = model.h(truth.states) + noise
    z = np.where(model.angle_mask, (z + np.pi) % (2 * np.pi) - np.pi, z)
    snr = np.full((batch, steps, 1), 15.0) if _uses_3d(spec) else None
    scans = Scans(z[:, :, None, :], np.ones((batch, steps, 1), dtype=bool), truth.times, snr=snr)
    prior = Gaussian.broadcast(x0, P0, batch)
    return truth, scans, prior, motion, model


def _run(spec: FilterSpec, prior, scans, motion, model, seed: int = 0):
    """The filter over the scans through the one time loop (:func:`workbench.tracking.run`, ``Direct``
    association): the estimates ``mean (B, T, n)`` and ``cov (B, T, n, n)``."""
    track = run(spec, scans, motion, model, association=Direct(), prior=prior, rng=generator(seed, "kit-filter"))
    return track.mean, track.cov


def reference_kalman(prior: Gaussian, scans: Scans, F, Q, H, R):
    """A closed-form Kalman filter written out with explicit inverses, one item at a time.

    Deliberately plain (and slow) so it shares no code with any plugin.
    """
    B, T = scans.batch, scans.steps
    n = F.shape[0]
    means = np.empty((B, T, n))
    covs = np.empty((B, T, n, n))
    for b in range(B):
        x, P = prior.mean[b].copy(), prior.cov[b].copy()
        for k in range(T):
            if k > 0:
                x = F @ x
                P = F @ P @ F.T + Q
            if scans.valid[b, k, 0]:
                S = H @ P @ H.T + R
                K = P @ H.T @ np.linalg.inv(S)
                x = x + K @ (scans.z[b, k, 0] - H @ x)
                P = (np.eye(n) - K @ H) @ P
            means[b, k], covs[b, k] = x, P
    return means, covs


# -- checks -------------------------------------------------------------------------------------------


def check_shapes(spec: FilterSpec) -> None:
    """init/predict/update/estimate keep shapes (B, n) and (B, n, n) for B = 1 and B = 7."""
    for batch in (1, 7):
        _, scans, prior, motion, model = _problem(spec, batch, seed=1, steps=3)
        rng = generator(0, "shapes")
        state = spec.init(prior, rng)
        for stage, fn in (("init", None), ("predict", lambda s: spec.predict(s, motion, rng)),
                          ("update", lambda s: spec.update(s, scans.scan(1).for_filter(), model, rng))):
            if fn is not None:
                state = fn(state)
            est = spec.estimate(state)
            assert isinstance(est, Gaussian), f"estimate() after {stage} returned {type(est).__name__}, not Gaussian"
            n = prior.dim
            assert est.mean.shape == (batch, n), f"after {stage} with B={batch}: mean shape {est.mean.shape}, expected {(batch, n)}"
            assert est.cov.shape == (batch, n, n), f"after {stage} with B={batch}: cov shape {est.cov.shape}, expected {(batch, n, n)}"


def check_batch_consistency(spec: FilterSpec) -> None:
    """A batch of 7 gives the same estimates as each item run alone."""
    _, scans, prior, motion, model = _problem(spec, 7, seed=2, steps=8)
    mean, cov = _run(spec, prior, scans, motion, model)
    for b in range(7):
        one = Scans(scans.z[b:b + 1], scans.valid[b:b + 1], scans.times)
        m1, c1 = _run(spec, prior.take(b), one, motion, model)
        err = np.max(np.abs(m1[0] - mean[b]))
        assert np.allclose(m1[0], mean[b], rtol=1e-9, atol=1e-9), \
            f"item {b} run alone differs from the batch: max |mean difference| = {err:.3g}"
        assert np.allclose(c1[0], cov[b], rtol=1e-9, atol=1e-9), f"item {b} run alone: covariance differs from the batch"


def _freeze(*arrays):
    for a in arrays:
        if isinstance(a, np.ndarray):
            a.flags.writeable = False


def check_no_mutation(spec: FilterSpec) -> None:
    """Inputs (prior, scans, model matrices) are never modified in place."""
    _, scans, prior, motion, model = _problem(spec, 3, seed=3, steps=4)
    scan = scans.scan(1).for_filter()
    before = [a.copy() for a in (prior.mean, prior.cov, scan.z, scan.valid, motion.F, motion.Q, model.R)]
    _freeze(prior.mean, prior.cov, scan.z, scan.valid, motion.F, motion.Q, motion.Q_sqrt, model.R)
    rng = generator(0, "mutation")
    try:
        state = spec.init(prior, rng)
        state = spec.predict(state, motion, rng)
        state = spec.update(state, scan, model, rng)
        spec.estimate(state)
    except ValueError as exc:
        if "read-only" in str(exc):
            raise AssertionError(f"the filter wrote into one of its inputs in place: {exc}") from None
        raise
    after = (prior.mean, prior.cov, scan.z, scan.valid, motion.F, motion.Q, model.R)
    for name, a, b in zip(("prior.mean", "prior.cov", "scan.z", "scan.valid", "F", "Q", "R"), before, after):
        assert np.array_equal(a, b), f"the filter modified {name}"


def check_covariance_psd(spec: FilterSpec) -> None:
    """Estimated covariances stay symmetric positive definite over a run (the range-bearing problem,
    unless the filter is linear-only)."""
    _, scans, prior, motion, model = _problem(spec, 5, seed=4, nonlinear=True)
    _, cov = _run(spec, prior, scans, motion, model)
    asym = np.max(np.abs(cov - np.swapaxes(cov, -1, -2)) / np.maximum(np.abs(cov).max(), 1e-300))
    assert asym < 1e-8, f"covariance not symmetric: relative asymmetry {asym:.3g}"
    eig = np.linalg.eigvalsh(cov)
    worst = np.unravel_index(np.argmin(eig[..., 0]), eig.shape[:2])
    assert np.all(eig[..., 0] > 0), \
        f"covariance not positive definite at run {worst[0]}, step {worst[1]}: smallest eigenvalue {eig[worst][0]:.3g}"


def check_empty_scan(spec: FilterSpec) -> None:
    """An update with no valid measurement (M = 0, or M = 2 all masked) leaves the estimate as predicted."""
    _, scans, prior, motion, model = _problem(spec, 4, seed=5, steps=2)
    rng = generator(0, "empty")
    state = spec.predict(spec.update(spec.init(prior, rng), scans.scan(0).for_filter(), model, rng), motion, rng)
    before = spec.estimate(state)
    for label, scan in (("M = 0", Scan.empty(4, model.dim)),
                        ("all rows masked", Scan(np.ones((4, 2, model.dim)), np.zeros((4, 2), dtype=bool),
                                                 snr=np.full((4, 2), 15.0)))):
        after = spec.estimate(spec.update(state, scan, model, rng))
        assert np.allclose(after.mean, before.mean, rtol=0, atol=1e-12) and np.allclose(after.cov, before.cov, rtol=0, atol=1e-12), \
            f"update with an empty scan ({label}) changed the estimate (max change {np.max(np.abs(after.mean - before.mean)):.3g})"


def check_same_seed(spec: FilterSpec) -> None:
    """The same seed gives bit-identical output."""
    _, scans, prior, motion, model = _problem(spec, 3, seed=6, steps=6)
    m1, c1 = _run(spec, prior, scans, motion, model, seed=11)
    m2, c2 = _run(spec, prior, scans, motion, model, seed=11)
    assert np.array_equal(m1, m2) and np.array_equal(c1, c2), "two runs with the same seed gave different output"


def check_matches_kalman(spec: FilterSpec) -> None:
    """On a linear-Gaussian model the filter equals a closed-form Kalman filter (to 1e-8 relative)."""
    truth, scans, prior, motion, model = _problem(spec, 4, seed=7)
    valid = scans.valid.copy()
    valid[:, 5] = False  # one missed detection: predict only
    scans = Scans(scans.z, valid, scans.times)
    mean, cov = _run(spec, prior, scans, motion, model)
    ref_mean, ref_cov = reference_kalman(prior, scans, motion.F, motion.Q, model.H, model.R)
    dm = np.abs(mean - ref_mean) / (1.0 + np.abs(ref_mean))
    dc = np.abs(cov - ref_cov) / (1.0 + np.abs(ref_cov))
    if dm.max() > 1e-8 or dc.max() > 1e-8:
        b, k = np.unravel_index(np.argmax(dm.max(axis=-1) + dc.max(axis=(-1, -2))), dm.shape[:2])
        raise AssertionError(
            f"differs from the closed-form Kalman filter: first at run {b}, step {k}: max relative mean error "
            f"{dm.max():.3g}, covariance error {dc.max():.3g} (e.g. P[0,0] = {cov[b, k, 0, 0]:.6g}, "
            f"Kalman {ref_cov[b, k, 0, 0]:.6g})")


def check_nees_consistency(spec: FilterSpec) -> None:
    """On a matched linear-Gaussian model, the run-averaged NEES lies inside its 95 % chi-square band at
    >= 85 % of the steps (95 % expected)."""
    runs = 200
    truth, scans, prior, motion, model = _problem(spec, runs, seed=8, steps=30)
    # Draw the start states from the prior so the prior itself is consistent.
    mean, cov = _run(spec, prior, scans, motion, model)
    e = nees(truth.states, mean, cov).mean(axis=0)
    lo, hi = chi2_band(4, runs)
    inside = np.mean((e >= lo) & (e <= hi))
    assert inside >= 0.85, (f"NEES inconsistent: run-averaged NEES inside the 95 % band [{lo:.2f}, {hi:.2f}] at only "
                            f"{100 * inside:.0f} % of steps (mean NEES {e.mean():.2f}, expected 4)")


def check_nan_rejected(spec: FilterSpec) -> None:
    """A NaN measurement is refused by the Scan record, and one smuggled past it makes the filter raise a
    clear error rather than return NaN."""
    _, scans, prior, motion, model = _problem(spec, 2, seed=9, steps=2)
    z = scans.z[:, 0].copy()
    z[1, 0, 0] = np.nan
    try:
        Scan(z, scans.valid[:, 0])
    except ValueError as exc:
        assert "NaN" in str(exc), f"Scan rejected NaN with an unclear message: {exc}"
    else:
        raise AssertionError("Scan accepted a NaN measurement")
    scan = scans.scan(0).for_filter()
    object.__setattr__(scan, "z", z)  # bypass validation, as a buggy caller might
    rng = generator(0, "nan")
    try:
        est = spec.estimate(spec.update(spec.init(prior, rng), scan, model, rng))
    except ValueError as exc:
        msg = str(exc)
        assert "NaN" in msg or "non-finite" in msg or "finite" in msg, f"NaN raised an unclear error: {msg}"
        return
    assert np.all(np.isfinite(est.mean)), "a NaN measurement propagated silently into the estimate"


CHECKS: tuple[Check, ...] = (
    Check("check_shapes", check_shapes.__doc__, lambda s: True, check_shapes),
    Check("check_batch_consistency", check_batch_consistency.__doc__,
          lambda s: "stochastic" not in s.capabilities, check_batch_consistency),
    Check("check_no_mutation", check_no_mutation.__doc__, lambda s: True, check_no_mutation),
    Check("check_covariance_psd", check_covariance_psd.__doc__, lambda s: True, check_covariance_psd),
    Check("check_empty_scan", check_empty_scan.__doc__, lambda s: True, check_empty_scan),
    Check("check_same_seed", check_same_seed.__doc__, lambda s: True, check_same_seed),
    Check("check_matches_kalman", check_matches_kalman.__doc__,
          lambda s: "exact_linear" in s.capabilities and not (_uses_polar(s) or _uses_3d(s)), check_matches_kalman),
    Check("check_nees_consistency", check_nees_consistency.__doc__,
          lambda s: "gaussian" in s.capabilities and not (_uses_polar(s) or _uses_3d(s)), check_nees_consistency),
    Check("check_nan_rejected", check_nan_rejected.__doc__, lambda s: True, check_nan_rejected),
)


def checks_for(spec: FilterSpec) -> list[Check]:
    """The checks that apply to ``spec`` given its capabilities."""
    unknown = set(spec.expected_failures) - {c.name for c in CHECKS}
    if unknown:
        raise ValueError(f"filter {spec.name!r} declares expected failures for unknown checks: {sorted(unknown)}")
    return [c for c in CHECKS if c.applies(spec)]


def run_checks(spec: FilterSpec) -> list[Outcome]:
    """Run every applicable check without pytest; expected failures are honoured."""
    checks_for(spec)  # refuses expected failures of unknown checks
    return run_kit(spec, CHECKS)
