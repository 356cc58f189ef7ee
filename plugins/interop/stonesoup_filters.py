"""Stone Soup's filters as workbench filters: ``ss-kf``, ``ss-ekf``, ``ss-ukf``, ``ss-ckf`` and ``ss-pf``.

Each wraps one Stone Soup predictor/updater pair (``stonesoup.predictor`` / ``stonesoup.updater``):

- ``ss-kf``: ``KalmanPredictor`` / ``KalmanUpdater`` (Gaussian; linear measurement models);
- ``ss-ekf``: ``ExtendedKalmanPredictor`` / ``ExtendedKalmanUpdater`` (Gaussian);
- ``ss-ukf``: ``UnscentedKalmanPredictor`` / ``UnscentedKalmanUpdater`` (Gaussian; ``alpha``, ``beta``, ``kappa``);
- ``ss-ckf``: ``CubatureKalmanPredictor`` / ``CubatureKalmanUpdater`` (Gaussian);
- ``ss-pf``: ``ParticlePredictor`` / ``ParticleUpdater`` (particles; ``particles``, ``ess_threshold``).

The models are converted at every step (:mod:`workbench_interop.stonesoup_models`): the workbench motion model's
``F, Q`` for the step's interval become a Stone Soup linear-Gaussian transition, the measurement model (``h``,
``R``, Jacobian, angular components) a Stone Soup Gaussian measurement model; a detection's own covariance
(``Scan.cov``) replaces ``R`` for that detection.

**Batch first at the boundary only.**  The filter's state is batch-first (a :class:`~workbench.types.Gaussian`
``(B, n)``, or :class:`~workbench.types.Particles` ``(B, N, n)``), so it works with every driver, the test kit and
the multi-target tracker; inside ``predict`` and ``update`` the adapter loops over the batch in Python, one Stone
Soup call per item, because Stone Soup's predictors and updaters take one state at a time.  Expect it to be
10-1000x slower than the workbench's own filters on large batches.

The particle filter draws its process noise (Stone Soup's transition model ``rvs``) and its systematic
resampling offsets from the workbench's ``rng`` argument, so a seed reproduces it; it resamples when the
effective sample size falls below ``ess_threshold * N`` (1: after every update).

Without Stone Soup (``pip install "workbench[stonesoup]"``) this plugin registers no filter and stays quiet:
:data:`AVAILABLE` is False and :data:`REASON` says why and how to install it.  Asking for an ``ss-*`` filter by
name (``--filters ss-ukf``, a scenario file) then says that it needs Stone Soup and how to install it
(:data:`WORKBENCH_UNAVAILABLE`), and building one (:func:`make_gaussian`, :func:`make_particle`) raises
:class:`StoneSoupMissing` saying the same, instead of a filter that fails with ``ModuleNotFoundError`` when it runs.
"""

from __future__ import annotations

from datetime import timedelta
from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import single_measurement
from workbench.models import require_linear
from workbench.params import Param
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Particles, Scan

from .stonesoup_available import AVAILABLE, EPOCH, REASON, StoneSoupMissing, require_stonesoup

__all__ = ["AVAILABLE", "REASON", "StoneSoupMissing", "require_stonesoup", "make_gaussian", "make_particle",
           "filters", "workbench_filters", "WORKBENCH_UNAVAILABLE"]

#: name -> (Stone Soup predictor, updater, summary)
GAUSSIAN = {
    "ss-kf": ("KalmanPredictor", "KalmanUpdater", "Stone Soup's Kalman filter (linear measurement models)"),
    "ss-ekf": ("ExtendedKalmanPredictor", "ExtendedKalmanUpdater", "Stone Soup's extended Kalman filter"),
    "ss-ukf": ("UnscentedKalmanPredictor", "UnscentedKalmanUpdater", "Stone Soup's unscented Kalman filter"),
    "ss-ckf": ("CubatureKalmanPredictor", "CubatureKalmanUpdater", "Stone Soup's cubature Kalman filter"),
}

UKF_PARAMETERS = (
    Param("alpha", 0.5, "primary sigma-point spread (Stone Soup's default)", unit="dimensionless", above=0.0,
          maximum=10.0),
    Param("beta", 2.0, "prior-knowledge weight of the centre point (2 is optimal for a Gaussian)",
          unit="dimensionless", minimum=0.0, maximum=10.0),
    Param("kappa", None, "secondary spread; none: Stone Soup's default 3 - n", type="float?",
          unit="dimensionless", minimum=-100.0, maximum=100.0),
)
PF_PARAMETERS = (
    Param("particles", 1000, "number of particles per run", type="int", unit="dimensionless", minimum=10,
          footprint=40.0),
    Param("ess_threshold", 0.5, "resample when the effective sample size falls below this fraction of the "
                                "particles (1: after every update)", unit="dimensionless", minimum=0.0,
          maximum=1.0),
)

_BATCH_NOTE = " (adapter: one Stone Soup call per batch item)"


def _classes(predictor: str, updater: str):
    import stonesoup.predictor.kalman as pk
    import stonesoup.updater.kalman as uk

    return getattr(pk, predictor), getattr(uk, updater)


def _measurements(scan: Scan, who: str):
    """The one valid measurement per item (``z (B, m)``, ``present (B,)``) and its own covariance or None."""
    z, present = single_measurement(scan, who)
    if not np.all(np.isfinite(z[present])):
        raise InputError(f"{who}: a valid measurement holds a non-finite value (NaN or inf)")
    cov = None
    if scan.cov is not None and scan.z.shape[1]:
        first = np.argmax(scan.valid, axis=1)
        cov = scan.cov[np.arange(scan.batch), first]
    return z, present, cov


def _ss():
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.detection import Detection

    from .stonesoup_models import measurement_model, transition_model, typed_vector

    return SingleHypothesis, Detection, measurement_model, transition_model, typed_vector


# -- Gaussian filters --------------------------------------------------------------------------------


def _g_init(prior: Gaussian, rng) -> Gaussian:
    return Gaussian(prior.mean.copy(), prior.cov.copy())


_LINEAR_ONLY = "'ukf', 'sir' or another workbench filter that follows f (the adapter hands Stone Soup F and Q only)"


def _g_predict(state: Gaussian, motion, rng, *, predictor: str, options: dict, name: str) -> Gaussian:
    from stonesoup.types.state import GaussianState

    require_linear(motion, name, _LINEAR_ONLY)
    _, _, _, transition_model, _ = _ss()
    P, _ = _classes(predictor, "KalmanUpdater")
    pred = P(transition_model(motion), **options)
    when = EPOCH + timedelta(seconds=float(motion.dt))
    mean, cov = np.empty_like(state.mean), np.empty_like(state.cov)
    for b in range(state.batch):  # Stone Soup predicts one state at a time
        out = pred.predict(GaussianState(state.mean[b][:, None].copy(), state.cov[b].copy(), timestamp=EPOCH),
                           timestamp=when)
        mean[b] = np.asarray(out.state_vector, dtype=float)[:, 0]
        cov[b] = np.asarray(out.covar, dtype=float)
    return Gaussian(mean, 0.5 * (cov + np.swapaxes(cov, 1, 2)))


def _g_update(state: Gaussian, scan: Scan, model, rng, *, updater: str, options: dict, name: str) -> Gaussian:
    from stonesoup.types.prediction import GaussianStatePrediction

    SingleHypothesis, Detection, measurement_model, _, typed_vector = _ss()
    if updater == "KalmanUpdater" and model.H is None:
        raise InputError(f"{name} (Stone Soup's KalmanUpdater) needs a linear measurement model (H); "
                         f"{model.name!r} has none: use ss-ekf, ss-ukf or ss-ckf")
    z, present, own_cov = _measurements(scan, name)
    _, U = _classes("KalmanPredictor", updater)
    n = state.dim
    shared = measurement_model(model, n)
    upd = U(shared, **options)
    mean, cov = state.mean.copy(), state.cov.copy()
    for b in np.flatnonzero(present):  # an item without a measurement stays as predicted
        mm = shared if own_cov is None else measurement_model(model, n, own_cov[b])
        prediction = GaussianStatePrediction(state.mean[b][:, None].copy(), state.cov[b].copy(), timestamp=EPOCH)
        detection = Detection(typed_vector(z[b], model.angular), timestamp=EPOCH, measurement_model=mm)
        out = upd.update(SingleHypothesis(prediction, detection))
        mean[b] = np.asarray(out.state_vector, dtype=float)[:, 0]
        cov[b] = np.asarray(out.covar, dtype=float)
    return Gaussian(mean, 0.5 * (cov + np.swapaxes(cov, 1, 2)))


def _g_estimate(state: Gaussian) -> Gaussian:
    return state


#: Checks a Stone Soup filter fails because of Stone Soup itself; the adapter reproduces the library as it is.
KNOWN_FAILURES = {
    "ss-ckf": {"check_bearing_wrap": "Stone Soup 1.9.1's cubature2gauss forms the predicted covariance from raw second "
                                     "moments without wrapping the cubature points' bearings, so near +-pi its "
                                     "bearing variance comes out negative (-0.0367 rad^2 at (-400, 0.5) with "
                                     "P = diag(25, 25, 4, 4), where its UKF gives 0.000556) and the track diverges"},
}


def make_gaussian(name: str = "ss-ukf", **params) -> FilterSpec:
    """The Stone Soup Gaussian filter ``name`` (``ss-kf``, ``ss-ekf``, ``ss-ukf``, ``ss-ckf``) as a
    :class:`~workbench.specs.FilterSpec`; ``ss-ukf`` takes ``alpha``, ``beta``, ``kappa``."""
    if name not in GAUSSIAN:
        raise InputError(f"unknown Stone Soup Gaussian filter {name!r} (known: {', '.join(GAUSSIAN)})")
    require_stonesoup(f"filter {name!r}")
    predictor, updater, summary = GAUSSIAN[name]
    declared = UKF_PARAMETERS if name == "ss-ukf" else ()
    values = {p.name: params.get(p.name, p.default) for p in declared}
    unknown = set(params) - set(values)
    if unknown:
        raise InputError(f"filter {name!r}: unknown parameter(s) {sorted(unknown)}")
    options = {k: v for k, v in values.items() if v is not None}
    caps = {"gaussian", "exact_linear", "detection_covariance"} | ({"linear_only"} if name == "ss-kf" else set())
    return FilterSpec(
        name=name, summary=summary + _BATCH_NOTE, init=_g_init,
        predict=partial(_g_predict, predictor=predictor, options=options, name=name),
        update=partial(_g_update, updater=updater, options=options, name=name), estimate=_g_estimate,
        capabilities=frozenset(caps), params=values, parameters=declared,
        build=lambda **v: make_gaussian(name, **v), expected_failures=KNOWN_FAILURES.get(name, {}))


# -- particle filter -----------------------------------------------------------------------------------


def _resampler(rng: np.random.Generator, threshold: float):
    """A Stone Soup resampler drawing its systematic offset from ``rng``: resample when
    ``ESS = 1 / sum w_i^2 < threshold * N`` (always for threshold 1)."""
    from stonesoup.resampler.base import Resampler
    from stonesoup.types.array import StateVectors

    class _Systematic(Resampler):
        def resample(self, particles, nparts=None):
            lw = np.asarray(particles.log_weight, dtype=float)
            N = lw.size
            w = np.exp(lw - lw.max())
            w /= w.sum()
            if threshold < 1.0 and 1.0 / np.sum(w * w) >= threshold * N:
                return particles
            # positions u_k = (u + k) / N, u ~ U[0, 1); particle i is taken for every u_k in its CDF slot
            positions = (rng.random() + np.arange(N)) / N
            index = np.minimum(np.searchsorted(np.cumsum(w), positions, side="right"), N - 1)
            sv = StateVectors(np.asarray(particles.state_vector)[:, index])
            return particles.from_state(particles, state_vector=sv, log_weight=np.full(N, -np.log(N)))

    return _Systematic()


def _p_init(prior: Gaussian, rng, *, particles: int) -> Particles:
    # x_i ~ N(mean, P): mean + L e_i with P = L L^T (eigen-factor: also for a singular P)
    vals, vecs = np.linalg.eigh(prior.cov)
    L = vecs * np.sqrt(np.maximum(vals, 0.0))[:, None, :]
    e = rng.standard_normal((prior.batch, particles, prior.dim))
    x = prior.mean[:, None, :] + np.einsum("bij,bnj->bni", L, e)
    return Particles(x, np.full((prior.batch, particles), -np.log(particles)))


def _p_state(state: Particles, b: int, cls):
    from stonesoup.types.array import StateVectors

    return cls(StateVectors(state.particles[b].T.copy()), log_weight=state.log_weights[b].copy(), timestamp=EPOCH)


def _p_predict(state: Particles, motion, rng) -> Particles:
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.types.state import ParticleState

    require_linear(motion, "ss-pf", _LINEAR_ONLY)
    _, _, _, transition_model, _ = _ss()
    pred = ParticlePredictor(transition_model(motion, rng))
    when = EPOCH + timedelta(seconds=float(motion.dt))
    x = np.empty_like(state.particles)
    lw = np.empty_like(state.log_weights)
    for b in range(state.particles.shape[0]):
        out = pred.predict(_p_state(state, b, ParticleState), timestamp=when)
        x[b] = np.asarray(out.state_vector, dtype=float).T
        lw[b] = np.asarray(out.log_weight, dtype=float)
    return Particles(x, lw)


def _p_update(state: Particles, scan: Scan, model, rng, *, threshold: float) -> Particles:
    from stonesoup.types.prediction import ParticleStatePrediction
    from stonesoup.updater.particle import ParticleUpdater

    SingleHypothesis, Detection, measurement_model, _, typed_vector = _ss()
    z, present, own_cov = _measurements(scan, "ss-pf")
    n = state.particles.shape[2]
    shared = measurement_model(model, n)
    upd = ParticleUpdater(shared, resampler=_resampler(rng, threshold))
    x, lw = state.particles.copy(), state.log_weights.copy()
    for b in np.flatnonzero(present):
        mm = shared if own_cov is None else measurement_model(model, n, own_cov[b])
        detection = Detection(typed_vector(z[b], model.angular), timestamp=EPOCH, measurement_model=mm)
        out = upd.update(SingleHypothesis(_p_state(state, b, ParticleStatePrediction), detection))
        x[b] = np.asarray(out.state_vector, dtype=float).T
        lw[b] = np.asarray(out.log_weight, dtype=float)
    return Particles(x, lw)


def _p_estimate(state: Particles) -> Gaussian:
    return state.to_gaussian()


def make_particle(particles: int = 1000, ess_threshold: float = 0.5) -> FilterSpec:
    """Stone Soup's bootstrap particle filter (``ParticlePredictor`` / ``ParticleUpdater``) as ``ss-pf``."""
    require_stonesoup("filter 'ss-pf'")
    return FilterSpec(
        name="ss-pf", summary="Stone Soup's bootstrap particle filter" + _BATCH_NOTE,
        init=partial(_p_init, particles=int(particles)), predict=_p_predict,
        update=partial(_p_update, threshold=float(ess_threshold)), estimate=_p_estimate,
        capabilities=frozenset({"stochastic", "detection_covariance"}),
        params={"particles": int(particles), "ess_threshold": float(ess_threshold)}, parameters=PF_PARAMETERS,
        build=make_particle)


def filters() -> list[FilterSpec]:
    """Every Stone Soup filter this plugin provides ([] without Stone Soup)."""
    if not AVAILABLE:
        return []
    return [make_gaussian(name) for name in GAUSSIAN] + [make_particle()]


#: What this plugin would provide with Stone Soup, and why it does not here (read by the plugin host: asking for
#: one of these names says so, instead of "no filter named ... is installed").
WORKBENCH_UNAVAILABLE = {} if AVAILABLE else {("filter", name): f"needs Stone Soup: {REASON}"
                                               for name in (*GAUSSIAN, "ss-pf")}


@hookimpl
def workbench_filters():
    return filters()
