"""Cost-reference particle filter (CRPF; Míguez, Bugallo & Djurić 2004; Table 6 of paper 003), batch-first.

The CRPF needs no noise statistics: it never reads ``Q`` or ``R``.  It uses the motion model's ``F``
(the noise-free prediction ``f``), the sensor's ``h`` and the sensor's angle-aware ``residual``.  Its propagation
(the fused kernel and the predicted belief ``F m``, ``F P F^T``) is written for a linear model: a motion model
that overrides ``f`` is refused by name at ``predict``.
Particles carry a cost instead of a likelihood weight, and (Table 6) a propagation variance of their own.
For each measurement ``y_t`` (``t`` counts the propagations, ``t >= 1``)::

    dC(x | y)  = || y - h(x) ||^q                              incremental cost (eq 5), bearing wrapped;
                 arc-length: ((dr)^2 + (r_meas dtheta)^2)^(q/2)
    R_t^(i)    = lam C_{t-1}^(i) + dC(f(x_{t-1}^(i)) | y_t)      risk (eq 6), noise-free prediction
    delta_R    = delta, or delta * (mean_i R_t^(i) - min_k R_t^(k))   relative offset
    pi^(i)    ~  (R_t^(i) - min_k R_t^(k) + delta_R)^-beta       selection PMF (eq 8), in the log domain
    k_i        ~  systematic(pi)                               select N parents, carrying x, C and sigma^2
    x_t^(i)    ~  N(f(x_{t-1}^(k_i)), sigma_{t-1}^{2,(k_i)} diag(s^2))   propagation
    sigma_t^{2,(i)} = ((t-1)/t) sigma_{t-1}^{2,(k_i)} + ||(x_t^(i) - f(x_{t-1}^(k_i))) / s||^2 / (t dim)
                                                               adaptive variance (Table 6; s = 1 there);
                 fixed variance: sigma^2 = kappa / N^(2/dim) for every particle and step
    C_t^(i)    = lam C_{t-1}^(k_i) + dC(x_t^(i) | y_t)          cost update (eq 4)

and the estimate is ``x_t = sum_i pi_t^(i) x_t^(i)`` with ``pi_t^(i) ~ (C_t^(i) - min C_t + delta_C)^-beta``
(``delta_C`` as ``delta_R``, from the costs).  Every particle starts with ``sigma_0^2 = sigma0^2`` (adaptive).

Mapping onto the workbench's predict/update split: the CRPF's selection needs ``y_t``, so ``predict``
only records the motion model (the state becomes *pending*) and ``update`` runs risk, selection,
propagation and cost update in one go.  The estimate of a pending state is the weighted moment of the
noise-free prediction plus the particles' mean propagation variance (``F m``, ``F P F^T + mean_i sigma_i^2
diag(s^2)``; exact for a fixed variance).  A pending item that receives no measurement stays pending; the next
``predict`` moves it blindly (``x <- f(x) + noise``, the variance updated, ``C <- lam C``) before recording the
new motion.  The first ``update`` after ``init`` (nothing pending) only adds the incremental cost of the initial
particles.

Initial particles are uniform in a box around the prior mean with half-widths ``box * sqrt(diag(P0))``
(for the paper-003 prior ``P0 = diag(10^2, 10^2, 2^2, 2^2)``: +-10 m and +-2 m/s, as the brief says).

For a range-bearing model (declared frame and sensor position) a step in which every item moves and has a
measurement runs the fused kernel :func:`workbench_filters.crpf.crpf_step.crpf_step` (Numba on the CPU, else
Taichi); the array code below is its reference in the plugin and gives the same particles up to round-off.

Shapes: particles ``(B, N, n)``, costs and variances ``(B, N)``, step counts ``(B,)``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache, partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, require_finite, single_measurement
from workbench.kernels.counter_normals import draw_key
from workbench.models import MeasurementModel, MotionModel, require_linear
from workbench.params import Param, declared_dataclass, declared_factory, declared_values
from workbench.resampling import normalise_log_weights, systematic_resample
from workbench.specs import BenchmarkSpec, FilterSpec
from workbench.types import Gaussian, InputError, Particles, Scan

from .crpf_step import crpf_step, pmf_offset, propagation_normals

COSTS = ("norm", "arc-length")
VARIANCES = ("adaptive", "fixed")
DELTA_MODES = ("relative", "absolute")
#: "auto": the fused kernel (:mod:`workbench_filters.crpf.crpf_step`, Numba on the CPU, else Taichi) for a
#: range-bearing model; "numpy": always the array code below; "numba"/"taichi": that kernel backend.
BACKENDS = ("auto", "numpy", "numba", "taichi")

#: The paper filters' setting, chosen once on tuning runs by the rule of docs/paper003.md ("The CRPF setting"):
#: the initial propagation standard deviation sigma0 (m and m/s, isotropic) and the relative offset delta.  The rule
#: picked sigma0 = 1 and delta = 0.1 among sigma0 in {0.1, 0.3, 1, 3} x delta in {0.1, 0.3, 1} (the report's
#: "tuning" table recomputes the search and marks its choice beside the setting in use).
PAPER_SIGMA0 = 1.0
PAPER_DELTA = 0.1

PARAMETERS = (
    Param("particles", 100, "particles per run", "int", unit="dimensionless", minimum=1, footprint=40.0),
    Param("lam", 0.95, "forgetting factor of the cost", unit="dimensionless", above=0.0, maximum=1.0),
    Param("q", 2.0, "exponent of the incremental cost ||y - h(x)||^q", unit="dimensionless", minimum=1.0,
          maximum=16.0),
    Param("beta", 2.0, "exponent of the selection PMF (R - min R + delta)^-beta", unit="dimensionless", above=0.0,
          maximum=64.0),
    Param("delta", PAPER_DELTA, "offset of the selection PMF: a multiple of the mean gap of the risks above their "
                                "minimum (delta_mode 'relative') or a cost (delta_mode 'absolute')",
          unit="dimensionless", above=0.0),
    Param("delta_mode", "relative", "how delta is read: relative to the spread of the risks, or absolute", "str",
          choices=DELTA_MODES),
    Param("variance", "adaptive", "propagation variance: Table 6's per-particle running estimate, or fixed "
                                  "sigma^2 = kappa / N^(2/n)", "str", choices=VARIANCES),
    Param("sigma0", PAPER_SIGMA0, "initial propagation standard deviation of every particle (adaptive variance)",
          unit="state", above=0.0),
    Param("kappa", 1.0, "fixed propagation variance sigma^2 = kappa / N^(2/n) (variance 'fixed')", unit="state",
          above=0.0),
    Param("scale", None, "per-component scale of the propagation noise (length n; none: isotropic)", "vector?",
          unit="dimensionless", minimum=0.0, maximum=1e6),
    Param("cost", "arc-length", "incremental cost: the plain norm or the arc-length residual", "str", choices=COSTS),
    Param("box", 1.0, "half-width of the uniform initial box, in prior standard deviations", unit="dimensionless",
          above=0.0, maximum=1e3),
    Param("backend", "auto", "kernel backend of the fused range-bearing step (auto: the policy's choice)", "str",
          choices=BACKENDS),
)


class _CRPFSetting:
    """The methods of :class:`CRPFParams` (its fields are :data:`PARAMETERS`, declared once)."""

    def __post_init__(self) -> None:
        # every value against its declaration (type, range, choices; converted as the factory converts them)
        values = declared_values(PARAMETERS, {f.name: getattr(self, f.name) for f in fields(self)}, "crpf")
        for key, value in values.items():
            object.__setattr__(self, key, value)
        # what no single declaration can say
        if self.scale is not None and self.variance != "fixed" and not all(s > 0 for s in self.scale):
            raise InputError(f"crpf: the adaptive variance needs every scale entry > 0 (it divides by them), got "
                             f"{self.scale}")

    @property
    def adaptive(self) -> bool:
        return self.variance == "adaptive"

    @property
    def relative(self) -> bool:
        return self.delta_mode == "relative"

    def shape(self, dim: int) -> np.ndarray:
        """Per-component scale ``s`` of the propagation noise, ``(n,)`` (ones: isotropic)."""
        if self.scale is not None and len(self.scale) != dim:
            raise InputError(f"crpf: scale has {len(self.scale)} entries but the state has dimension {dim}")
        return np.ones(dim) if self.scale is None else np.asarray(self.scale, dtype=float)

    def initial_variance(self, dim: int) -> float:
        """``sigma_0^2``: ``sigma0^2`` (adaptive) or the fixed ``kappa / N^(2 / dim)``."""
        # fixed: sigma^2 = kappa / N^(2 / dim(x))
        return self.sigma0 ** 2 if self.adaptive else self.kappa / self.particles ** (2.0 / dim)

    def jitter_std(self, dim: int) -> np.ndarray:
        """Per-component propagation standard deviation at the start, ``(n,)``: ``sigma_0 * scale``."""
        return np.sqrt(self.initial_variance(dim)) * self.shape(dim)


CRPFParams = declared_dataclass("CRPFParams", PARAMETERS, __name__, bases=(_CRPFSetting,), doc="""The CRPF's setting,
its fields the declared :data:`PARAMETERS` with their defaults: ``particles`` N, forgetting ``lam`` (0 < lam <= 1),
cost exponent ``q >= 1``, PMF exponent ``beta > 0`` and offset ``delta > 0`` (relative or absolute), the propagation
variance (adaptive from ``sigma0``, or fixed ``kappa / N^(2/n)``) with optional per-component ``scale`` (length n),
the incremental ``cost`` form, the initial ``box`` (multiples of sqrt(diag P0)) and the kernel ``backend``.  Every
value is checked against its declaration when the setting is made.""")


@dataclass(frozen=True)
class CRPFState:
    """Particles, costs and propagation variances; ``pending (B,)`` marks items predicted with ``F`` but not yet
    updated; ``steps (B,)`` counts each item's propagations (the ``t`` of the adaptive variance).

    ``belief`` caches the estimate (weighted moments of the particles, or of their prediction while
    pending), so ``estimate`` is free.  ``selections`` counts resampling (selection) events.
    """

    particles: np.ndarray  # (B, N, n)
    costs: np.ndarray  # (B, N)
    variances: np.ndarray  # (B, N)
    steps: np.ndarray  # (B,) int
    belief: Gaussian
    pending: np.ndarray  # (B,) bool
    F: np.ndarray | None = None  # (n, n) motion of the pending prediction
    selections: int = 0
    blind_moves: int = 0

    #: The batch-first fields; ``F`` is the one motion matrix the batch shares and the counters are the batch's,
    #: kept whole when a tracker takes or joins items (never sliced, whatever the number of items).
    batch_fields = ("particles", "costs", "variances", "steps", "belief", "pending")


def log_pmf(costs: np.ndarray, beta: float, delta: float, relative: bool = False) -> np.ndarray:
    """Unnormalised log PMF ``-beta log(C - min C + delta_C)`` of costs ``(B, N)``.

    ``delta_C`` is ``delta`` or, ``relative``, ``delta`` times the mean gap of the row's finite costs above their
    minimum (:func:`workbench_filters.crpf.crpf_step.pmf_offset`).  Finite costs of any size give finite
    log-weights; an infinite cost gets ``-inf`` (weight zero), and a row whose every cost is infinite (or NaN)
    becomes uniform instead of NaN.
    """
    cmin = np.min(costs, axis=1, keepdims=True)
    ok = np.isfinite(cmin)
    # pi ~ (C - min C + delta_C)^-beta, taken in the log domain
    gap = np.where(ok, costs - np.where(ok, cmin, 0.0), 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        out = -beta * np.log(gap + pmf_offset(costs, delta, relative))
    return np.where(np.isnan(out), -np.inf, out)


def incremental_cost(z: np.ndarray, points: np.ndarray, model: MeasurementModel, params: CRPFParams) -> np.ndarray:
    """``dC = ||z - h(x)||^q`` for ``z (B, m)`` and ``points (B, N, n)`` -> ``(B, N)``.

    ``cost="arc-length"`` scales each angular residual by the measured range (the model's single
    non-angular component): ``dC = ((dr)^2 + (r_meas dtheta)^2)^(q/2)``.
    """
    res = model.residual(z[:, None, :], model.h(points))
    if params.cost == "arc-length":
        plain = ~model.angle_mask
        if plain.sum() != 1:
            raise InputError(f"crpf: the arc-length cost needs exactly one range component; model "
                             f"{model.name!r} has angular={model.angular}")
        rng_meas = np.abs(z[:, np.flatnonzero(plain)[0]])
        res = np.where(model.angle_mask, res * rng_meas[:, None, None], res)
    sq = res[..., 0] * res[..., 0]
    for j in range(1, res.shape[-1]):  # a sum over a short trailing axis, column by column (much faster)
        sq = sq + res[..., j] * res[..., j]
    # dC = ||y - h(x)||^q
    return sq if params.q == 2.0 else sq ** (0.5 * params.q)


def _moments(x: np.ndarray, costs: np.ndarray, params: CRPFParams) -> Gaussian:
    """Weighted mean and covariance with the estimation PMF ``pi ~ (C - min C + delta_C)^-beta``."""
    return Particles(x, normalise_log_weights(log_pmf(costs, params.beta, params.delta, params.relative))).to_gaussian()


def _propagate(parents: np.ndarray, s2: np.ndarray, steps: np.ndarray, e: np.ndarray,
               params: CRPFParams) -> tuple[np.ndarray, np.ndarray]:
    """``x = f_parent + s sigma_parent e`` and the parent's variance updated (Table 6) for step ``t = steps``.

    Shapes: ``parents (B, N, n)`` (the noise-free predictions of the parents), ``s2 (B, N)``, ``steps (B,)``,
    ``e (B, N, n)`` -> ``x (B, N, n)``, ``s2' (B, N)``.
    """
    n = parents.shape[-1]
    dev = e
    dev *= np.sqrt(s2)[..., None]  # in place: e is this step's own array
    x = dev * params.shape(n)
    x += parents
    if not params.adaptive:
        return x, s2
    t = steps.astype(float)[:, None]
    # sigma_t^2 = ((t - 1) / t) sigma_{t-1}^2 + ||(x_t - f(x_{t-1})) / s||^2 / (t dim)
    sq = dev[..., 0] * dev[..., 0]
    for j in range(1, n):
        sq += dev[..., j] * dev[..., j]
    return x, ((t - 1.0) / t) * s2 + sq / (t * n)


def init(prior: Gaussian, rng: np.random.Generator, params: CRPFParams) -> CRPFState:
    """Uniform particles in ``mean +- box * sqrt(diag(cov))``, zero costs, every variance ``sigma_0^2``."""
    B, n = prior.mean.shape
    half = params.box * np.sqrt(np.diagonal(prior.cov, axis1=1, axis2=2))  # (B, n)
    u = rng.uniform(-1.0, 1.0, size=(B, params.particles, n))
    x = prior.mean[:, None, :] + half[:, None, :] * u
    costs = np.zeros((B, params.particles))
    s2 = np.full((B, params.particles), params.initial_variance(n))
    return CRPFState(x, costs, s2, np.zeros(B, dtype=np.int64), _moments(x, costs, params), np.zeros(B, dtype=bool))


def _blind_move(state: CRPFState, rng: np.random.Generator, params: CRPFParams) -> CRPFState:
    """Propagate the pending items that never got a measurement: ``x <- f(x) + noise``, ``C <- lam C``."""
    rows = np.flatnonzero(state.pending)
    x, c, s2, steps = state.particles.copy(), state.costs.copy(), state.variances.copy(), state.steps.copy()
    sub = x[rows]
    steps[rows] += 1
    x[rows], s2[rows] = _propagate(sub @ state.F.T, s2[rows], steps[rows], rng.standard_normal(sub.shape), params)
    c[rows] = params.lam * c[rows]
    return CRPFState(x, c, s2, steps, _moments(x, c, params), np.zeros_like(state.pending), None, state.selections,
                     state.blind_moves + rows.size)


@lru_cache(maxsize=64)
def _shape_squared(params: CRPFParams, n: int) -> np.ndarray:
    """``diag(s^2)`` of the propagation noise's scale ``s`` (:meth:`CRPFParams.shape`), ``(n, n)``, read-only: the
    same for every step of a setting."""
    out = np.diag(params.shape(n) ** 2)
    out.setflags(write=False)
    return out


def _kernel_belief(mean: np.ndarray, cov: np.ndarray) -> Gaussian:
    """The fused kernel's weighted moments (float64 arrays it allocated, of the state's shapes; symmetric positive
    semi-definite by construction) as the belief, once every number is checked finite; a non-finite one goes to
    :meth:`Gaussian.trusted`, which names it."""
    if np.isfinite(mean).all() and np.isfinite(cov).all():
        return Gaussian.kernel_output(mean, cov)
    return Gaussian.trusted(mean, cov)


def predict(state: CRPFState, motion: MotionModel, rng: np.random.Generator, params: CRPFParams,
            who: str = "crpf") -> CRPFState:
    """Record ``F``; the predicted belief is ``N(F m, F P F^T + mean_i sigma_i^2 diag(s^2))``.  A motion model that
    overrides ``f`` is refused naming the filter ``who`` and the model."""
    F = np.asarray(require_linear(motion, who, "'sir' or 'ukf'"), dtype=float)
    if state.pending.any():
        state = _blind_move(state, rng, params)
    n = F.shape[0]
    v = state.variances
    # (B,): the particles' mean propagation variance (np.mean's sum and division, without its Python layers)
    spread = np.add.reduce(v, axis=1) / v.shape[1]
    mean = state.belief.mean @ F.T
    cov = F @ state.belief.cov @ F.T + spread[:, None, None] * _shape_squared(params, n)
    # F P F^T + a non-negative diagonal is symmetric positive semi-definite: no eigenvalue test needed
    return CRPFState(state.particles, state.costs, state.variances, state.steps, Gaussian.trusted(mean, cov),
                     np.ones(state.pending.shape, dtype=bool), F, state.selections, state.blind_moves)


def _fused(model: MeasurementModel, params: CRPFParams) -> bool:
    """Whether the fused kernel applies: a model that declares the range-bearing frame (``h`` = range and
    bearing of ``x, y`` from its declared ``sensor_position``) and a backend other than ``"numpy"``."""
    return (params.backend != "numpy" and model.frame == "range-bearing" and model.sensor_position is not None
            and len(model.sensor_position) == 2)


def update(state: CRPFState, scan: Scan, model: MeasurementModel, rng: np.random.Generator,
           params: CRPFParams) -> CRPFState:
    z, present = single_measurement(scan, "crpf")
    if not present.any():
        return state
    require_finite(z, present, "crpf")
    x, c, s2 = state.particles, state.costs, state.variances
    B, N, n = x.shape
    lam = params.lam
    moving = present & state.pending
    steps = state.steps + moving  # this propagation's t for the moving items
    if moving.all() and _fused(model, params):
        # the same draws in the same order as below: selection offsets, then the key of the propagation normals
        u0 = rng.random((B, 1))
        key = draw_key(rng)
        new_x, costs, new_s2, mean, cov = crpf_step(
            x, c, s2, steps, state.F, z, key, u0, params.shape(n), lam, params.beta, params.delta, params.q,
            params.cost == "arc-length", model.sensor_position, params.adaptive, params.relative,
            backend=params.backend)
        return CRPFState(new_x, costs, new_s2, steps, _kernel_belief(mean, cov), np.zeros(B, dtype=bool), None,
                         state.selections + B, state.blind_moves)
    if moving.any():
        xf = x @ state.F.T  # noise-free prediction f(x_{t-1})
        # R_t = lam C_{t-1} + dC(f(x_{t-1}) | y_t)
        risk = lam * c + incremental_cost(z, xf, model, params)
        idx = systematic_resample(log_pmf(risk, params.beta, params.delta, params.relative), rng)  # (B, N)
        flat = (idx + (np.arange(B) * N)[:, None]).ravel()
        parents = xf.reshape(B * N, n).take(flat, axis=0).reshape(B, N, n)
        c_sel = c.ravel().take(flat).reshape(B, N)
        # x_t ~ N(f(x_{t-1}^(k)), sigma_{t-1}^{2,(k)} diag(s^2)), and sigma_t^2 (Table 6)
        x_new, s2_new = _propagate(parents, s2.ravel().take(flat).reshape(B, N), np.maximum(steps, 1),
                                   propagation_normals(draw_key(rng), B, N, n, backend=params.backend), params)
        keep_x = x_new if moving.all() else np.where(moving[:, None, None], x_new, x)
        keep_c = c_sel if moving.all() else np.where(moving[:, None], c_sel, c)
        keep_s2 = s2_new if moving.all() else np.where(moving[:, None], s2_new, s2)
    else:
        keep_x, keep_c, keep_s2 = x, c, s2
    # C_t = lam C_{t-1} + dC(x_t | y_t); the very first update (nothing pending) starts from C_0
    decay = lam if moving.all() else np.where(moving, lam, 1.0)[:, None]
    costs = decay * keep_c + incremental_cost(z, keep_x, model, params)
    if present.all():
        new_x, new_s2, belief = keep_x, keep_s2, _moments(keep_x, costs, params)
    else:
        costs = keep_where(present, costs, c)
        new_x = keep_where(present, keep_x, x)
        new_s2 = keep_where(present, keep_s2, s2)
        belief = _moments(new_x, costs, params)
        belief = Gaussian.trusted(keep_where(present, belief.mean, state.belief.mean),
                                  keep_where(present, belief.cov, state.belief.cov))
    pending = state.pending & ~present
    return CRPFState(new_x, costs, new_s2, steps, belief, pending, state.F if pending.any() else None,
                     state.selections + int(moving.sum()), state.blind_moves)


def estimate(state: CRPFState) -> Gaussian:
    return state.belief


def diagnostics(state: CRPFState) -> dict:
    return {"selections": state.selections, "blind_moves": state.blind_moves}


@declared_factory(PARAMETERS, "crpf")
def make_crpf(values: dict, *, name: str | None = None) -> FilterSpec:
    """A cost-reference particle filter; the defaults are the paper filters' setting (Table 6's adaptive variance,
    the arc-length cost, a relative delta; sigma0 and delta chosen by the tuning rule of docs/paper003.md).

    Takes the declared :data:`PARAMETERS` (positionally in their order, or by keyword; ``make_crpf(300)`` has 300
    particles) and ``name``; its signature, checks and ``params`` all come from that declaration."""
    params = CRPFParams(**values)
    spread = (f"adaptive sigma^2 from sigma0={params.sigma0:g}" if params.adaptive
              else f"fixed sigma^2=kappa/N^(2/n), kappa={params.kappa:g}")
    label = name or f"crpf-{params.particles}"
    return FilterSpec(
        name=label,
        summary=(f"Cost-reference particle filter, N={params.particles}, {params.cost} cost, lam={params.lam:g}, "
                 f"q={params.q:g}, beta={params.beta:g}, {params.delta_mode} delta={params.delta:g}, {spread}"),
        init=partial(init, params=params),
        predict=partial(predict, params=params, who=label),
        update=partial(update, params=params),
        estimate=estimate,
        # the arc-length cost reads a range and a bearing: it needs a range-bearing sensor
        capabilities=frozenset({"stochastic", "ignores_noise_statistics"}
                               | ({"range_bearing_input"} if params.cost == "arc-length" else set())),
        params={f.name: getattr(params, f.name) for f in fields(params)},
        diagnostics=diagnostics,
        parameters=PARAMETERS,
        build=make_crpf,
    )


#: The paper's three particle counts: the registered filters ``crpf-100``, ``crpf-300`` and ``crpf-500``.
PAPER_FILTERS = (100, 300, 500)


@hookimpl
def workbench_filters():
    return [make_crpf(n) for n in PAPER_FILTERS]


def _bench(quick: bool) -> dict:
    from .bench import bench

    return bench(quick)


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("crpf-step", "the CRPF's fused step kernel per particle: paper 003's configuration "
                                       "against the previous one", _bench)]
