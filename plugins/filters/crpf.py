"""Cost-reference particle filter (CRPF; Míguez, Bugallo & Djurić 2004), batch-first over ``(B, N)``.

The CRPF needs no noise statistics: it never reads ``Q`` or ``R``.  It uses the motion model's ``F``
(the noise-free prediction ``f``), the sensor's ``h`` and the sensor's angle-aware ``residual``.
Particles carry a cost instead of a likelihood weight.  For each measurement ``y_t``::

    dC(x | y)  = || y - h(x) ||^q                         incremental cost (eq 5), bearing wrapped
    R_t^(i)    = lam C_{t-1}^(i) + dC(f(x_{t-1}^(i)) | y_t)  risk (eq 6), noise-free prediction
    pi^(i)    ~  (R_t^(i) - min_k R_t^(k) + delta)^-beta  selection PMF (eq 8), in the log domain
    k_i        ~  systematic(pi)                          select N parents, carrying x and C
    x_t^(i)    ~  N(f(x_{t-1}^(k_i)), sigma^2 diag(s^2))  propagation, sigma^2 = kappa / N^(2/n)
    C_t^(i)    = lam C_{t-1}^(k_i) + dC(x_t^(i) | y_t)     cost update (eq 4)

and the estimate is ``x_t = sum_i pi_t^(i) x_t^(i)`` with ``pi_t^(i) ~ (C_t^(i) - min C_t + delta)^-beta``.

Mapping onto the workbench's predict/update split: the CRPF's selection needs ``y_t``, so ``predict``
only records the motion model (the state becomes *pending*) and ``update`` runs risk, selection,
propagation and cost update in one go.  The estimate of a pending state is the exact weighted moment
of the noise-free prediction plus the propagation variance (``F m``, ``F P F^T + sigma^2 diag(s^2)``).
A pending item that receives no measurement stays pending; the next ``predict`` moves it blindly
(``x <- f(x) + noise``, ``C <- lam C``) before recording the new motion.  The first ``update`` after
``init`` (nothing pending) only adds the incremental cost of the initial particles.

Initial particles are uniform in a box around the prior mean with half-widths ``box * sqrt(diag(P0))``
(for the paper-003 prior ``P0 = diag(10^2, 10^2, 2^2, 2^2)``: +-10 m and +-2 m/s, as the brief says).

Shapes: particles ``(B, N, n)``, costs ``(B, N)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.kernels.counter_normals import draw_key
from workbench.kernels.crpf_step import crpf_step, propagation_normals
from workbench.models import MeasurementModel, MotionModel
from workbench.params import Param
from workbench.resampling import normalise_log_weights, systematic_resample
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Particles, Scan

COSTS = ("norm", "arc-length")
#: "auto": the fused kernel (:mod:`workbench.kernels.crpf_step`, Numba on the CPU, else Taichi) for a
#: range-bearing model; "numpy": always the array code below; "numba"/"taichi": that kernel backend.
BACKENDS = ("auto", "numpy", "numba", "taichi")

PARAMETERS = (
    Param("particles", 100, "particles per run", "int", minimum=1),
    Param("lam", 0.95, "forgetting factor of the cost", above=0.0, maximum=1.0),
    Param("q", 2.0, "exponent of the incremental cost ||y - h(x)||^q", minimum=1.0),
    Param("beta", 2.0, "exponent of the selection PMF (R - min R + delta)^-beta", above=0.0),
    Param("delta", 0.01, "offset of the selection PMF", above=0.0),
    Param("kappa", 1.0, "propagation variance sigma^2 = kappa / N^(2/n)", above=0.0),
    Param("scale", None, "per-component scale of the propagation noise (length n; none: isotropic)", "vector?",
          minimum=0.0),
    Param("cost", "norm", "incremental cost: the plain norm or the arc-length residual", "str", choices=COSTS),
    Param("box", 1.0, "half-width of the uniform initial box, in prior standard deviations", above=0.0),
    Param("backend", "auto", "kernel backend of the fused range-bearing step (auto: the policy's choice)", "str",
          choices=BACKENDS),
)


@dataclass(frozen=True)
class CRPFParams:
    """The CRPF's tuning: ``particles`` N, forgetting ``lam`` (0 < lam <= 1), cost exponent ``q >= 1``,
    PMF exponent ``beta > 0`` and offset ``delta > 0``, jitter ``kappa > 0`` with optional per-component
    ``scale`` (length n), the incremental ``cost`` form and the initial ``box`` (multiples of sqrt(diag P0))."""

    particles: int = 100
    lam: float = 0.95
    q: float = 2.0
    beta: float = 2.0
    delta: float = 0.01
    kappa: float = 1.0
    scale: tuple[float, ...] | None = None
    cost: str = "norm"
    box: float = 1.0
    backend: str = "auto"

    def __post_init__(self) -> None:
        checks = [
            (self.particles >= 1, f"particles must be >= 1, got {self.particles}"),
            (0.0 < self.lam <= 1.0, f"lam (forgetting factor) must be in (0, 1], got {self.lam}"),
            (self.q >= 1.0, f"q must be >= 1, got {self.q}"),
            (self.beta > 0.0, f"beta must be > 0, got {self.beta}"),
            (self.delta > 0.0, f"delta must be > 0, got {self.delta}"),
            (self.kappa > 0.0, f"kappa must be > 0, got {self.kappa}"),
            (self.box > 0.0, f"box must be > 0, got {self.box}"),
            (self.cost in COSTS, f"cost must be one of {COSTS}, got {self.cost!r}"),
            (self.backend in BACKENDS, f"backend must be one of {BACKENDS}, got {self.backend!r}"),
            (self.scale is None or all(s >= 0 for s in self.scale), f"scale entries must be >= 0, got {self.scale}"),
        ]
        for ok, message in checks:
            if not ok:
                raise InputError(f"crpf: {message}")

    def jitter_std(self, dim: int) -> np.ndarray:
        """Per-component propagation standard deviation, ``(n,)``: ``sqrt(kappa / N^(2/n)) * scale``."""
        if self.scale is not None and len(self.scale) != dim:
            raise InputError(f"crpf: scale has {len(self.scale)} entries but the state has dimension {dim}")
        # sigma_t^2 = kappa / N^(2 / dim(x))
        sigma = np.sqrt(self.kappa / self.particles ** (2.0 / dim))
        scale = np.ones(dim) if self.scale is None else np.asarray(self.scale, dtype=float)
        return sigma * scale


@dataclass(frozen=True)
class CRPFState:
    """Particles and costs; ``pending (B,)`` marks items predicted with ``F`` but not yet updated.

    ``belief`` caches the estimate (weighted moments of the particles, or of their prediction while
    pending), so ``estimate`` is free.  ``selections`` counts resampling (selection) events.
    """

    particles: np.ndarray  # (B, N, n)
    costs: np.ndarray  # (B, N)
    belief: Gaussian
    pending: np.ndarray  # (B,) bool
    F: np.ndarray | None = None  # (n, n) motion of the pending prediction
    selections: int = 0
    blind_moves: int = 0


def log_pmf(costs: np.ndarray, beta: float, delta: float) -> np.ndarray:
    """Unnormalised log selection PMF ``-beta log(C - min C + delta)`` of costs ``(B, N)``.

    Finite costs of any size give finite log-weights; an infinite cost gets ``-inf`` (weight zero),
    and a row whose every cost is infinite (or NaN) becomes uniform instead of NaN.
    """
    cmin = np.min(costs, axis=1, keepdims=True)
    ok = np.isfinite(cmin)
    # pi ~ (C - min C + delta)^-beta, taken in the log domain
    gap = np.where(ok, costs - np.where(ok, cmin, 0.0), 0.0)
    with np.errstate(invalid="ignore"):
        out = -beta * np.log(gap + delta)
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
    """Weighted mean and covariance with the estimation PMF ``pi ~ (C - min C + delta)^-beta``."""
    return Particles(x, normalise_log_weights(log_pmf(costs, params.beta, params.delta))).to_gaussian()


def init(prior: Gaussian, rng: np.random.Generator, params: CRPFParams) -> CRPFState:
    """Uniform particles in ``mean +- box * sqrt(diag(cov))``, zero costs."""
    B, n = prior.mean.shape
    half = params.box * np.sqrt(np.diagonal(prior.cov, axis1=1, axis2=2))  # (B, n)
    u = rng.uniform(-1.0, 1.0, size=(B, params.particles, n))
    x = prior.mean[:, None, :] + half[:, None, :] * u
    costs = np.zeros((B, params.particles))
    return CRPFState(x, costs, _moments(x, costs, params), np.zeros(B, dtype=bool))


def _blind_move(state: CRPFState, rng: np.random.Generator, params: CRPFParams) -> CRPFState:
    """Propagate the pending items that never got a measurement: ``x <- f(x) + noise``, ``C <- lam C``."""
    rows = np.flatnonzero(state.pending)
    x = state.particles.copy()
    c = state.costs.copy()
    sub = x[rows]
    std = params.jitter_std(sub.shape[-1])
    x[rows] = sub @ state.F.T + rng.standard_normal(sub.shape) * std
    c[rows] = params.lam * c[rows]
    return CRPFState(x, c, _moments(x, c, params), np.zeros_like(state.pending), None, state.selections,
                     state.blind_moves + rows.size)


def predict(state: CRPFState, motion: MotionModel, rng: np.random.Generator, params: CRPFParams) -> CRPFState:
    """Record ``F``; the predicted belief is ``N(F m, F P F^T + sigma^2 diag(s^2))``."""
    if state.pending.any():
        state = _blind_move(state, rng, params)
    F = np.asarray(motion.F, dtype=float)
    std = params.jitter_std(F.shape[0])
    mean = state.belief.mean @ F.T
    cov = F @ state.belief.cov @ F.T + np.diag(std * std)
    return CRPFState(state.particles, state.costs, Gaussian(mean, cov), np.ones(state.pending.shape, dtype=bool),
                     F, state.selections, state.blind_moves)


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
    if not np.all(np.isfinite(z[present])):
        item = int(np.flatnonzero(present & ~np.all(np.isfinite(z), axis=1))[0])
        raise InputError(f"crpf: the measurement of batch item {item} is not finite (NaN or inf)")
    x, c = state.particles, state.costs
    B, N, n = x.shape
    lam = params.lam
    moving = present & state.pending
    if moving.all() and _fused(model, params):
        # the same draws in the same order as below: selection offsets, then the key of the propagation normals
        u0 = rng.random((B, 1))
        key = draw_key(rng)
        new_x, costs, mean, cov = crpf_step(x, c, state.F, z, key, u0, params.jitter_std(n), lam, params.beta,
                                            params.delta, params.q, params.cost == "arc-length",
                                            model.sensor_position, backend=params.backend)
        return CRPFState(new_x, costs, Gaussian(mean, cov), np.zeros(B, dtype=bool), None,
                         state.selections + B, state.blind_moves)
    if moving.any():
        xf = x @ state.F.T  # noise-free prediction f(x_{t-1})
        # R_t = lam C_{t-1} + dC(f(x_{t-1}) | y_t)
        risk = lam * c + incremental_cost(z, xf, model, params)
        idx = systematic_resample(log_pmf(risk, params.beta, params.delta), rng)  # (B, N)
        flat = (idx + (np.arange(B) * N)[:, None]).ravel()
        parents = xf.reshape(B * N, n).take(flat, axis=0).reshape(B, N, n)
        c_sel = c.ravel().take(flat).reshape(B, N)
        # x_t ~ N(f(x_{t-1}^(k)), sigma^2 diag(s^2))
        x_new = propagation_normals(draw_key(rng), B, N, n)
        x_new *= params.jitter_std(n)
        x_new += parents  # in place: fresh (B, N, n) temporaries are costly
        keep_x = x_new if moving.all() else np.where(moving[:, None, None], x_new, x)
        keep_c = c_sel if moving.all() else np.where(moving[:, None], c_sel, c)
    else:
        keep_x, keep_c = x, c
    # C_t = lam C_{t-1} + dC(x_t | y_t); the very first update (nothing pending) starts from C_0
    decay = lam if moving.all() else np.where(moving, lam, 1.0)[:, None]
    costs = decay * keep_c + incremental_cost(z, keep_x, model, params)
    if present.all():
        new_x, belief = keep_x, _moments(keep_x, costs, params)
    else:
        costs = keep_where(present, costs, c)
        new_x = keep_where(present, keep_x, x)
        belief = _moments(new_x, costs, params)
        belief = Gaussian(keep_where(present, belief.mean, state.belief.mean),
                          keep_where(present, belief.cov, state.belief.cov))
    pending = state.pending & ~present
    return CRPFState(new_x, costs, belief, pending, state.F if pending.any() else None,
                     state.selections + int(moving.sum()), state.blind_moves)


def estimate(state: CRPFState) -> Gaussian:
    return state.belief


def diagnostics(state: CRPFState) -> dict:
    return {"selections": state.selections, "blind_moves": state.blind_moves}


def make_crpf(particles: int = 100, lam: float = 0.95, q: float = 2.0, beta: float = 2.0, delta: float = 0.01,
              kappa: float = 1.0, scale=None, cost: str = "norm", box: float = 1.0,
              name: str | None = None, backend: str = "auto") -> FilterSpec:
    """A cost-reference particle filter; defaults are the brief's (lam 0.95, q 2, beta 2, delta 0.01, kappa 1)."""
    params = CRPFParams(int(particles), float(lam), float(q), float(beta), float(delta), float(kappa),
                        None if scale is None else tuple(float(s) for s in scale), cost, float(box), backend)
    return FilterSpec(
        name=name or f"crpf-{params.particles}",
        summary=(f"Cost-reference particle filter, N={params.particles}, lam={params.lam}, q={params.q}, "
                 f"beta={params.beta}, delta={params.delta}, sigma^2=kappa/N^(2/n) with kappa={params.kappa}"),
        init=partial(init, params=params),
        predict=partial(predict, params=params),
        update=partial(update, params=params),
        estimate=estimate,
        # the arc-length cost reads a range and a bearing: it needs a range-bearing sensor
        capabilities=frozenset({"stochastic", "ignores_noise_statistics"}
                               | ({"range_bearing_input"} if cost == "arc-length" else set())),
        params={"particles": params.particles, "lam": params.lam, "q": params.q, "beta": params.beta,
                "delta": params.delta, "kappa": params.kappa, "scale": params.scale, "cost": params.cost,
                "box": params.box, "backend": params.backend},
        diagnostics=diagnostics,
        parameters=PARAMETERS,
        build=make_crpf,
    )


#: The paper's three particle counts.
PAPER_FILTERS = (100, 300, 500)

#: Per-component jitter shapes of the sweep (brief § 3.3: "a per-component scale vector, since position
#: and velocity have different units"), for the state [x, y, vx, vy] and T = 1 s.  "dwna" is the
#: acceleration-driven shape G = [T^2/2, T^2/2, T, T]; "iso" is the brief's literal sigma^2 I_4.  (The sweep
#: in docs/paper003.md also ran position-only jitter (1, 1, 0, 0): its velocities collapse to one value, the
#: particle covariance becomes singular, and it tracked worst; it is not registered.)
JITTER_SHAPES = {
    "iso": None,
    "vel0.1": (1.0, 1.0, 0.1, 0.1),
    "dwna": (0.5, 0.5, 1.0, 1.0),
}

#: The default of the paper filters, chosen from the plain-norm sweep (kappa in {0.1, 1, 10} x the shapes
#: above, CRPF-100, 300 runs per level, seed 0) by one rule for every level: the smallest geometric mean
#: over L1-L3 of the time-averaged MSE (docs/paper003.md).  The brief's literal default (kappa = 1,
#: isotropic) is the ablation "crpf-100-iso".
PAPER_SHAPE = "dwna"
PAPER_KAPPA = 1.0


def ablation_name(shape: str, kappa: float, cost: str = "norm") -> str:
    """``crpf-100[-arc][-shape][-k<kappa>]``; the paper default's shape and kappa are left out of the name."""
    return ("crpf-100" + ("-arc" if cost == "arc-length" else "") + ("" if shape == PAPER_SHAPE else f"-{shape}")
            + ("" if kappa == PAPER_KAPPA else f"-k{kappa:g}"))


#: Ablations of CRPF-100: the jitter sweep with the paper's plain norm, and the arc-length cost
#: (isotropic and dwna shapes), kappa in {0.1, 1, 10}.  (name, shape, kappa, cost)
ABLATIONS = tuple(
    (ablation_name(shape, kappa, cost), shape, kappa, cost)
    for cost, shapes in (("norm", tuple(JITTER_SHAPES)), ("arc-length", ("iso", "dwna")))
    for shape in shapes for kappa in (0.1, 1.0, 10.0)
)


@hookimpl
def workbench_filters():
    paper = [make_crpf(n, kappa=PAPER_KAPPA, scale=JITTER_SHAPES[PAPER_SHAPE]) for n in PAPER_FILTERS]
    return paper + [make_crpf(100, kappa=k, scale=JITTER_SHAPES[shape], cost=cost, name=name)
                    for name, shape, k, cost in ABLATIONS if name != "crpf-100"]
