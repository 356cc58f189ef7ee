"""The motion-model test kit: named checks that a :class:`~workbench.models.MotionModel` is what it says.

A check is ``check(model)``: it raises ``AssertionError`` naming the check, the model and the numbers (measured
and expected), and returns a one-line summary when it passes.  Checks are chosen by what the model declares
(:attr:`~workbench.models.MotionModel.has_jacobian`, :attr:`~workbench.models.MotionModel.linear`, a ``rebuild``
function, ``exact_discretisation``), never by its name.  Use them from pytest
(:func:`workbench.testing.parametrize_with_checks` takes motion models too, ids such as ``cv2d-check_jacobian``)
or without it (:func:`run_motion_checks`).

The states the checks evaluate ``f`` at are drawn at a scale that follows each component's declared unit
(:data:`UNIT_SCALES`: 100 m, 10 m/s, 0.1 rad/s, ...), with the zero state among them (the ``omega -> 0`` limit of
a turn model is where its formulas divide by zero).

``exact_discretisation`` (the class attribute :attr:`workbench.models.MotionModel.exact_discretisation`; ``None``: not declared):

- ``True``: the model is the exact discretisation of a continuous-time linear SDE (e.g. continuous white-noise
  acceleration, Singer), so ``F`` and ``Q`` both compose over two intervals (``check_transition_composes``,
  ``check_noise_composes``).
- ``None`` (undeclared): only ``F`` is held to compose.  The built-in constant-velocity models use *discrete*
  white-noise acceleration (an acceleration held constant over each step, Bar-Shalom's DWNA): their ``Q(T) =
  G G^T sigma^2`` with ``G = [T^2/2, T]`` is not ``F(T2) Q(T1) F(T2)^T + Q(T2)`` for ``T = T1 + T2`` (two
  independent accelerations over the halves are not one over the whole), nor is the random-walk velocity's, so
  the noise identity would fail a correct model and is not applied to them.
- ``False``: a discrete-time model whose ``F`` does not compose either (an Euler step); neither is checked.

Time: a model whose ``f`` takes ``(x, t, dt)`` is held to the binding the time loop uses
(``check_time_arguments``: ``f(x, t, dt) = model.at(t, dt).f(x)``); one written as ``f(x)`` serves the step it
is bound to and is not.
"""

from __future__ import annotations

import inspect

import numpy as np

from ..metrics import chi2_band
from ..models import MotionModel, model_label as _label
from ..rng import generator
from ..units import UNITS
from ._common import Check, Outcomes, chi2_p, fail, normal_p, run_kit

__all__ = ["MOTION_CHECKS", "motion_checks_for", "run_motion_checks", "kit_states", "check_state_layout",
           "check_jacobian", "check_noise_psd", "check_noise_factor", "check_noise_samples",
           "check_transition_composes", "check_noise_composes", "check_time_arguments", "check_batched_f",
           "check_no_mutation", "UNIT_SCALES"]

#: SI dimension -> the scale (in SI) of the kit's test states in a component of that dimension.
UNIT_SCALES = {"length": 100.0, "speed": 10.0, "acceleration": 1.0, "angle": 1.0, "angular_rate": 0.1}
#: Dimensionless state components (a growth model's state) declare one of these units.
DIMENSIONLESS = ("1", "dimensionless")
#: The family-wise false-alarm level of :func:`check_noise_samples`, split evenly (Bonferroni) over its tests.
LEVEL = 1e-3
#: A sample's component along a direction of ``Q`` below the rank threshold may reach this many of that
#: direction's own standard deviations (``sqrt`` of its eigenvalue) before :func:`check_noise_samples` fails it.
NULL_SIGMAS = 8.0
#: Samples of :func:`check_noise_samples`.
SAMPLES = 4000
#: Relative tolerance of the Jacobian against central differences (on the state scales, dimensionless).
JACOBIAN_RTOL = 1e-6
#: Relative tolerances of the exact identities (factor, composition, batching).
IDENTITY_RTOL = 1e-9
#: Eigenvalues of ``Q`` above ``RANK_RTOL`` times its largest count towards its rank; below ``-PSD_RTOL`` times
#: the largest, ``Q`` is not positive semi-definite.
RANK_RTOL = 1e-9
PSD_RTOL = 1e-10


def _scales(model) -> np.ndarray:
    """One scale per state component from its declared unit (1 where the unit is unknown or undeclared)."""
    n = model.dim
    units = tuple(model.state_units)
    out = np.ones(n)
    if len(units) == n:
        for i, unit in enumerate(units):
            if unit in UNITS:
                dim, factor = UNITS[unit]
                out[i] = UNIT_SCALES.get(dim, 1.0) / factor
    return out


def _rate_components(model) -> np.ndarray:
    units = tuple(model.state_units)
    if len(units) != model.dim:
        return np.zeros(model.dim, bool)
    return np.array([u in UNITS and UNITS[u][0] == "angular_rate" for u in units])


def kit_states(model, count: int, seed: int, *key) -> np.ndarray:
    """``count`` test states ``(count, n)`` drawn at the unit scales (:data:`UNIT_SCALES`), the first the zero
    state and, where the state has angular-rate components, the second with those rates exactly zero."""
    rng = generator(seed, "motion-kit", *key)
    x = rng.standard_normal((count, model.dim)) * _scales(model)
    x[0] = 0.0
    if count > 1:
        x[1, _rate_components(model)] = 0.0
    return x


def _f(model, x, check: str) -> np.ndarray:
    try:
        out = model.f(x)
    except Exception as exc:  # noqa: BLE001 - the model's own error is the finding
        raise fail(check, f"{_label(model)}: f raised {type(exc).__name__} on states of shape {np.shape(x)}: "
                          f"{exc}") from None
    out = np.asarray(out, dtype=float)
    if out.shape != np.shape(x):
        raise fail(check, f"{_label(model)}: f maps states of shape {np.shape(x)} to shape {out.shape}; it must "
                          f"keep the shape (..., n)")
    _finite(model, x, out, "f", check)
    return out


def _finite(model, x, out, what: str, check: str) -> None:
    """A non-finite value from a finite state, named with the state (e.g. a turn that divides by omega = 0)."""
    bad = ~np.isfinite(out)
    if bad.any():
        rows = bad.reshape(bad.shape[: np.ndim(x) - 1] + (-1,)).any(axis=-1)
        at = tuple(int(v) for v in np.argwhere(rows)[0]) if rows.ndim else ()
        state = np.asarray(x)[at] if at else np.asarray(x)
        raise fail(check, f"{_label(model)}: {what} returns a non-finite value at the state "
                          f"{np.array2string(state, precision=4)} ({int(rows.sum()) if rows.ndim else 1} of "
                          f"{max(1, int(np.prod(rows.shape)))} states); a limit (e.g. omega -> 0) not handled?")


def _jac(model, x, check: str) -> np.ndarray:
    try:
        out = model.jacobian(x)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"{_label(model)}: jacobian raised {type(exc).__name__} on states of shape "
                          f"{np.shape(x)}: {exc}") from None
    out = np.asarray(out, dtype=float)
    want = np.shape(x) + (model.dim,)
    if out.shape != want:
        raise fail(check, f"{_label(model)}: jacobian maps states of shape {np.shape(x)} to shape {out.shape}, "
                          f"expected {want}")
    _finite(model, x, out, "jacobian", check)
    return out


def _sym_q(model) -> np.ndarray:
    Q = np.asarray(model.Q, dtype=float)
    return (Q + Q.T) / 2.0


# -- the checks -----------------------------------------------------------------------------------------------


def check_state_layout(model) -> str:
    """``F``, ``Q`` square ``(n, n)``, ``Q_sqrt`` ``(n, r)``, all finite; ``dt > 0``; ``state_names`` (distinct)
    and ``state_units`` (units of :data:`workbench.units.UNITS`, or ``"1"`` for a dimensionless component)
    declared, one per state component."""
    name = "check_state_layout"
    problems = []
    Q = np.asarray(model.Q, dtype=float)
    if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
        raise fail(name, f"{_label(model)}: Q must be square, got shape {Q.shape}")
    n = Q.shape[0]
    for field in ("F", "Q", "Q_sqrt"):
        a = np.asarray(getattr(model, field), dtype=float)
        if a.ndim != 2 or a.shape[0] != n or (field != "Q_sqrt" and a.shape[1] != n):
            problems.append(f"{field} has shape {a.shape}, expected ({n}, {n})" if field != "Q_sqrt"
                            else f"Q_sqrt has shape {a.shape}, expected ({n}, r)")
        elif not np.all(np.isfinite(a)):
            problems.append(f"{field} holds a non-finite value")
    if not (np.isfinite(model.dt) and model.dt > 0):
        problems.append(f"dt is {model.dt}, expected a finite step > 0")
    names, units = tuple(model.state_names or ()), tuple(model.state_units or ())
    if len(names) != n:
        problems.append(f"state_names declares {len(names)} names {names} for a state of dimension {n}")
    elif len(set(names)) != n or not all(isinstance(s, str) and s for s in names):
        problems.append(f"state_names {names} are not {n} distinct non-empty strings")
    if len(units) != n:
        problems.append(f"state_units declares {len(units)} units {units} for a state of dimension {n}")
    else:
        unknown = [u for u in units if u not in UNITS and u not in DIMENSIONLESS]
        if unknown:
            problems.append(f"state_units {unknown} are not units of workbench.units.UNITS (e.g. m, m/s, rad, "
                            f"rad/s; '1' for a dimensionless component)")
    if problems:
        raise fail(name, f"{_label(model)}: " + "; ".join(problems))
    return f"n = {n}: {', '.join(f'{a} [{u}]' for a, u in zip(names, units))}; dt = {model.dt:g} s"


def check_jacobian(model) -> str:
    """``jacobian(x)`` equals the central differences of ``f`` at 6 test states (the zero state among them), to
    ``1e-6`` relative on the state scales (entry ``(i, j)`` weighted by ``scale_j / scale_i``)."""
    name = "check_jacobian"
    x = kit_states(model, 6, 0, "jacobian")
    s = _scales(model)
    J = _jac(model, x.copy(), name)
    h = 1e-5 * s
    cols = []
    for j in range(model.dim):
        step = np.zeros(model.dim)
        step[j] = h[j]
        cols.append((_f(model, x + step, name) - _f(model, x - step, name)) / (2.0 * h[j]))
    fd = np.stack(cols, axis=-1)  # (K, n, n): d f_i / d x_j
    weight = s[None, :] / s[:, None]
    err = np.abs(J - fd) * weight
    size = max(1.0, float(np.max(np.abs(fd) * weight)))
    worst = np.unravel_index(int(np.nanargmax(np.where(np.isfinite(err), err, np.inf))), err.shape)
    rel = float(err[worst]) / size if np.isfinite(err[worst]) else float("inf")
    if not rel <= JACOBIAN_RTOL:
        k, i, j = (int(v) for v in worst)
        ratio = J[worst] / fd[worst] if fd[worst] != 0 else float("nan")
        names = tuple(model.state_names or ())
        wrt = f"d {names[i]} / d {names[j]}" if len(names) == model.dim else f"d f_{i} / d x_{j}"
        raise fail(name, f"{_label(model)}: jacobian differs from the central differences of f: at state "
                         f"{np.array2string(x[k], precision=4)} entry ({i}, {j}) ({wrt}) is {J[worst]:.8g}, the "
                         f"differences give {fd[worst]:.8g} (ratio {ratio:.6g}); scaled error {rel:.3g} > "
                         f"{JACOBIAN_RTOL:g}")
    return f"6 states: largest scaled difference from central differences {rel:.2g} (<= {JACOBIAN_RTOL:g})"


def check_noise_psd(model) -> str:
    """``Q`` symmetric (to ``1e-10`` of its largest entry) and positive semi-definite: its smallest eigenvalue
    at least ``-1e-10`` times its largest."""
    name = "check_noise_psd"
    Q = np.asarray(model.Q, dtype=float)
    scale = float(np.max(np.abs(Q))) if Q.size else 0.0
    asym = float(np.max(np.abs(Q - Q.T))) if Q.size else 0.0
    if asym > PSD_RTOL * scale:
        i, j = np.unravel_index(int(np.argmax(np.abs(Q - Q.T))), Q.shape)
        raise fail(name, f"{_label(model)}: Q is not symmetric: Q[{i}, {j}] = {Q[i, j]:.8g} but Q[{j}, {i}] = "
                         f"{Q[j, i]:.8g} (difference {asym:.3g}, tolerance {PSD_RTOL * scale:.3g})")
    eig = np.linalg.eigvalsh(_sym_q(model))
    top = max(float(eig[-1]), 0.0)
    if eig[0] < -PSD_RTOL * top or (top == 0.0 and eig[0] < 0.0):
        raise fail(name, f"{_label(model)}: Q is not positive semi-definite: eigenvalues "
                         f"{np.array2string(eig, precision=4)}, the smallest {eig[0]:.6g} < -{PSD_RTOL:g} x the "
                         f"largest ({top:.6g})")
    rank = int(np.sum(eig > RANK_RTOL * top)) if top > 0 else 0
    return f"Q symmetric, eigenvalues {eig[0]:.3g} .. {top:.3g}, rank {rank} of {model.dim}"


def check_noise_factor(model) -> str:
    """``Q_sqrt Q_sqrt^T`` equals ``Q`` (to ``1e-9`` of ``Q``'s largest entry)."""
    name = "check_noise_factor"
    Q = np.asarray(model.Q, dtype=float)
    L = np.asarray(model.Q_sqrt, dtype=float)
    if L.ndim != 2 or L.shape[0] != Q.shape[0]:
        raise fail(name, f"{_label(model)}: Q_sqrt has shape {L.shape}, expected ({Q.shape[0]}, r)")
    LL = L @ L.T
    scale = float(np.max(np.abs(Q))) if Q.size else 0.0
    diff = np.abs(LL - Q)
    worst = float(np.max(diff)) if diff.size else 0.0
    tol = IDENTITY_RTOL * scale + 1e-300
    if not worst <= tol:
        i, j = np.unravel_index(int(np.argmax(diff)), diff.shape)
        raise fail(name, f"{_label(model)}: Q_sqrt Q_sqrt^T is not Q: entry ({i}, {j}) is {LL[i, j]:.8g}, Q has "
                         f"{Q[i, j]:.8g} (largest difference {worst:.3g}, tolerance {tol:.3g}); Q_sqrt must be a "
                         f"factor of Q itself, e.g. its Cholesky factor")
    return f"Q_sqrt Q_sqrt^T = Q to {worst / scale if scale else 0.0:.2g} relative"


def check_noise_samples(model) -> str:
    """Samples ``f(x) + Q_sqrt e`` (``e ~ N(0, I)``, 4,000 of them at test states, fixed seed) are distributed
    as ``N(f(x), Q)``: the residual from a second call of ``f`` lies in the range of ``Q`` (no component along
    its null space); whitened on that range (the pseudo-inverse, ``dof = rank Q``), the mean squared
    Mahalanobis distance, each component's mean and mean square and each pair's cross moment are inside their
    two-sided bands (``scipy.stats.chi2`` for the squares, the normal for the means and cross moments).
    False-alarm level 1e-3 for the check, split evenly over its tests."""
    name = "check_noise_samples"
    x = kit_states(model, SAMPLES, 0, "samples", "states")
    L = np.asarray(model.Q_sqrt, dtype=float)
    e = generator(0, "motion-kit", "samples", "noise").standard_normal((SAMPLES, L.shape[1]))
    fx = _f(model, x.copy(), name)  # copies: a model that writes into its input fails check_no_mutation
    sample = fx + e @ L.T
    r = sample - _f(model, x.copy(), name)
    eig, U = np.linalg.eigh(_sym_q(model))
    top = max(float(eig[-1]), 0.0)
    if eig[0] < -PSD_RTOL * top or (top == 0.0 and eig[0] < 0.0):
        raise fail(name, f"{_label(model)}: no Gaussian has this Q: its smallest eigenvalue is {eig[0]:.6g} < 0 "
                         f"(see check_noise_psd)")
    keep = eig > RANK_RTOL * top if top > 0 else np.zeros(eig.shape, bool)
    rank = int(keep.sum())
    null = r @ U[:, ~keep]
    # a direction counted as null may still hold a tiny variance (an exactly discretised model over a short step:
    # Q's eigenvalues span T^5 .. T), which its samples may show up to NULL_SIGMAS of its own standard deviation
    tol = (1e-6 * np.sqrt(top) + 1e-12 * max(1.0, float(np.max(np.abs(fx))))
           + NULL_SIGMAS * np.sqrt(np.clip(eig[~keep], 0.0, None)))
    if null.size and np.any(np.max(np.abs(null), axis=0) > tol):
        worst = int(np.argmax(np.max(np.abs(null), axis=0) - tol))
        raise fail(name, f"{_label(model)}: the samples f(x) + Q_sqrt e leave the range of Q (rank {rank} of "
                         f"{model.dim}): a component along Q's null space of "
                         f"{float(np.max(np.abs(null[:, worst]))):.3g} (tolerance {float(tol[worst]):.3g}); Q_sqrt "
                         f"puts noise where Q has none, or f is not deterministic")
    if rank == 0:
        return "Q = 0: every sample equals f(x)"
    w = (r @ U[:, keep]) / np.sqrt(eig[keep])  # (N, rank), N(0, I) when the samples follow Q
    N = SAMPLES
    tests: list[tuple[str, float]] = []
    maha = float(np.sum(w * w))
    tests.append((f"mean squared Mahalanobis distance {maha / N:.4f} (expected {rank}, chi-square({N * rank}) / "
                  f"{N})", chi2_p(maha, N * rank)))
    for i in range(rank):
        ss = float(np.sum(w[:, i] ** 2))
        tests.append((f"whitened component {i}: mean square {ss / N:.4f} (expected 1)", chi2_p(ss, N)))
        m = float(np.mean(w[:, i]))
        tests.append((f"whitened component {i}: mean {m:.4f} (expected 0, sd {1 / np.sqrt(N):.4f})",
                      float(normal_p(m * np.sqrt(N)))))
        for j in range(i + 1, rank):
            c = float(np.mean(w[:, i] * w[:, j]))
            tests.append((f"whitened components {i}, {j}: cross moment {c:.4f} (expected 0, sd "
                          f"{1 / np.sqrt(N):.4f})", float(normal_p(c * np.sqrt(N)))))
    level = LEVEL / len(tests)
    bad = [(what, p) for what, p in tests if p < level]
    if bad:
        lo, hi = chi2_band(rank, N, 1 - LEVEL)
        raise fail(name, f"{_label(model)}: {N} samples f(x) + Q_sqrt e are not distributed as N(f(x), Q) "
                         f"(rank {rank}, band of the mean squared distance [{lo:.4f}, {hi:.4f}] at level "
                         f"{LEVEL:g}): " + "; ".join(f"{what}, p = {p:.2g} < {level:.2g}" for what, p in bad))
    return (f"{N} samples, rank {rank}: mean squared Mahalanobis distance {maha / N:.4f} (expected {rank}); "
            f"{len(tests)} tests, smallest p = {min(p for _, p in tests):.2g}")


#: The pairs of intervals the composition checks use, in units of the model's own step.
INTERVALS = ((0.37, 1.9), (1.0, 1.0), (2.5, 0.6))


def _interval(model, dt: float, check: str):
    try:
        out = model.for_interval(dt)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"{_label(model)}: for_interval({dt:g}) raised {type(exc).__name__}: {exc}") from None
    if np.asarray(out.F).shape != np.asarray(model.F).shape or not np.isclose(out.dt, dt, rtol=1e-12):
        raise fail(check, f"{_label(model)}: for_interval({dt:g}) gave a model of step {out.dt:g} s and F "
                          f"{np.asarray(out.F).shape}, expected step {dt:g} s and F {np.asarray(model.F).shape}")
    return out


def _compose(model, check: str, what: str):
    worst = 0.0
    for a, b in INTERVALS:
        t1, t2 = a * model.dt, b * model.dt
        m1, m2, m12 = _interval(model, t1, check), _interval(model, t2, check), _interval(model, t1 + t2, check)
        F1, F2 = np.asarray(m1.F, float), np.asarray(m2.F, float)
        if what == "F":
            got, want = np.asarray(m12.F, float), F2 @ F1
            formula = "F(dt1 + dt2) = F(dt2) F(dt1)"
        else:
            got, want = np.asarray(m12.Q, float), F2 @ np.asarray(m1.Q, float) @ F2.T + np.asarray(m2.Q, float)
            formula = "Q(dt1 + dt2) = F(dt2) Q(dt1) F(dt2)^T + Q(dt2)"
        scale = max(float(np.max(np.abs(want))), 1e-300)
        diff = np.abs(got - want)
        rel = float(np.max(diff)) / scale
        if not rel <= IDENTITY_RTOL:
            i, j = np.unravel_index(int(np.argmax(diff)), diff.shape)
            raise fail(check, f"{_label(model)}: {formula} fails for dt1 = {t1:g} s, dt2 = {t2:g} s: entry "
                              f"({i}, {j}) is {got[i, j]:.8g} from for_interval({t1 + t2:g}), {want[i, j]:.8g} "
                              f"composed (relative difference {rel:.3g} > {IDENTITY_RTOL:g})")
        worst = max(worst, rel)
    return worst


def check_transition_composes(model) -> str:
    """For a linear model that rebuilds for other intervals: ``F(dt1 + dt2) = F(dt2) F(dt1)`` for three pairs of
    intervals (to ``1e-9`` relative).  Catches a ``rebuild`` that ignores the step or a hard-coded 1 s."""
    worst = _compose(model, "check_transition_composes", "F")
    return f"F composes over {len(INTERVALS)} pairs of intervals (largest relative difference {worst:.2g})"


def check_noise_composes(model) -> str:
    """For a linear model that declares ``exact_discretisation = True``: ``Q(dt1 + dt2) = F(dt2) Q(dt1)
    F(dt2)^T + Q(dt2)`` for three pairs of intervals (to ``1e-9`` relative), as an exactly discretised
    continuous-time model satisfies."""
    worst = _compose(model, "check_noise_composes", "Q")
    return f"Q composes over {len(INTERVALS)} pairs of intervals (largest relative difference {worst:.2g})"


def check_batched_f(model) -> str:
    """``f`` on a batch ``(B, S, n)`` (and the ``jacobian`` where the model has one) equals ``f`` on each state
    ``(n,)`` alone and on the flattened ``(B S, n)`` (to ``1e-9`` relative), and ``f`` called twice gives the
    same result."""
    name = "check_batched_f"
    B, S = 3, 5
    x = kit_states(model, B * S, 0, "batch").reshape(B, S, model.dim)
    # copies: a model that writes into its input fails check_no_mutation, not this check
    whole = _f(model, x.copy(), name)
    flat = _f(model, x.reshape(B * S, model.dim).copy(), name).reshape(x.shape)
    items = np.stack([_f(model, x[b, s].copy(), name) for b in range(B) for s in range(S)]).reshape(x.shape)
    again = _f(model, x.copy(), name)
    scale = max(1.0, float(np.max(np.abs(items))))
    tol = IDENTITY_RTOL * scale

    def worst(a, b):  # NaN equals NaN here: a NaN on its own is the finding
        both = np.isnan(a) & np.isnan(b)
        d = np.where(both, 0.0, np.abs(a - b))
        d = np.where(np.isnan(d), np.inf, d)
        return (float(np.max(d)), np.unravel_index(int(np.argmax(d)), d.shape)) if d.size else (0.0, ())

    for got, label in ((whole, f"f on the batch ({B}, {S}, {model.dim})"),
                       (flat, f"f on the flattened batch ({B * S}, {model.dim})")):
        err, at = worst(got, items)
        if not err <= tol:
            at = tuple(int(v) for v in at)
            raise fail(name, f"{_label(model)}: {label} differs from f on each state alone: at item {at[:-1]}, "
                             f"component {at[-1]}, {got[at]:.8g} against {items[at]:.8g} (difference {err:.3g}); "
                             f"f must be vectorised over any leading axes (..., n)")
    err, at = worst(again, whole)
    if not err <= tol:
        at = tuple(int(v) for v in at)
        raise fail(name, f"{_label(model)}: f called twice on the same batch differs by {err:.3g} (at {at}); f "
                         f"must be deterministic (the kit adds the noise)")
    summary = f"f on ({B}, {S}, {model.dim}) equals f item by item"
    if model.has_jacobian:
        J = _jac(model, x.copy(), name)
        Ji = np.stack([_jac(model, x[b, s].copy(), name) for b in range(B) for s in range(S)]).reshape(J.shape)
        err, at = worst(J, Ji)
        if not err <= IDENTITY_RTOL * max(1.0, float(np.max(np.abs(Ji)))):
            at = tuple(int(v) for v in at)
            raise fail(name, f"{_label(model)}: jacobian on the batch ({B}, {S}, {model.dim}) differs from the "
                             f"jacobian of each state alone: entry {at}, {J[at]:.8g} against {Ji[at]:.8g}")
        summary += ", and so does its jacobian"
    return summary


def check_no_mutation(model) -> str:
    """``f`` and ``jacobian`` leave their input unchanged (bit for bit) and accept a read-only one, and leave the
    model's ``F``, ``Q`` and ``Q_sqrt`` unchanged."""
    name = "check_no_mutation"
    x = kit_states(model, 8, 0, "mutation").reshape(2, 4, model.dim)
    before = {k: np.array(getattr(model, k), dtype=float, copy=True) for k in ("F", "Q", "Q_sqrt")}
    methods = [("f", model.f)] + ([("jacobian", model.jacobian)] if model.has_jacobian else [])
    for label, fn in methods:
        work = x.copy()
        try:
            fn(work)
        except Exception as exc:  # noqa: BLE001
            raise fail(name, f"{_label(model)}: {label} raised {type(exc).__name__} on states of shape "
                             f"{work.shape}: {exc}") from None
        if not np.array_equal(work, x):
            changed = np.argwhere(work != x)
            at = tuple(int(v) for v in changed[0])
            raise fail(name, f"{_label(model)}: {label} wrote into its input: {len(changed)} of {x.size} values "
                             f"changed (e.g. at {at}: {x[at]:.8g} became {work[at]:.8g}); return a new array")
        frozen = x.copy()
        frozen.setflags(write=False)
        try:
            fn(frozen)
        except Exception as exc:  # noqa: BLE001
            raise fail(name, f"{_label(model)}: {label} fails on a read-only input ({type(exc).__name__}: "
                             f"{exc}); it must not write into its input") from None
    for k, arr in before.items():
        if not np.array_equal(np.asarray(getattr(model, k), dtype=float), arr):
            raise fail(name, f"{_label(model)}: calling {', '.join(m for m, _ in methods)} changed the model's {k}")
    return f"{', '.join(m for m, _ in methods)} leave their input and the model unchanged"


#: The (start time, interval) pairs of :func:`check_time_arguments`, in units of the model's own step (the
#: intervals other than 1 only for a model that rebuilds).
TIMES = ((0.0, 1.0), (3.7, 1.0), (-2.5, 1.0), (11.0, 1.9), (0.4, 0.3))


def _takes_time(model) -> bool:
    """Whether ``model.f`` takes the time and the interval (``f(x, t, dt)``), as the protocol writes it."""
    try:
        params = inspect.signature(model.f).parameters
    except (TypeError, ValueError):
        return False
    return "t" in params and "dt" in params


def check_time_arguments(model) -> str:
    """For a model whose ``f`` takes ``(x, t, dt)``: ``f(x, t, dt)`` equals ``model.at(t, dt).f(x)`` (the model
    bound to that step, as the time loop hands it to filters), and so does the ``jacobian``, at five
    ``(t, dt)`` pairs (intervals other than the model's own only where it rebuilds), to ``1e-9`` relative; and
    ``f(x)`` equals ``f(x, model.t, model.dt)``.  Catches an ``f`` that ignores its arguments or the bound time."""
    name = "check_time_arguments"
    x = kit_states(model, 6, 0, "time")
    pairs = [(a * model.dt, b * model.dt) for a, b in TIMES if b == 1.0 or _rebuilds(model)]
    worst = 0.0

    def compare(got, want, what):
        nonlocal worst
        got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
        scale = max(1.0, float(np.max(np.abs(want))))
        diff = np.abs(got - want)
        err = float(np.max(diff)) / scale if diff.size else 0.0
        if not err <= IDENTITY_RTOL:
            at = tuple(int(v) for v in np.unravel_index(int(np.argmax(diff)), diff.shape))
            raise fail(name, f"{_label(model)}: {what}: at {at}, {got[at]:.8g} against {want[at]:.8g} (relative "
                             f"difference {err:.3g} > {IDENTITY_RTOL:g})")
        worst = max(worst, err)

    compare(_f(model, x.copy(), name), _call(model.f, x, model.t, model.dt, name, model, "f"),
            f"f(x) differs from f(x, t={model.t:g}, dt={model.dt:g}) (its bound time and step)")
    for t, dt in pairs:
        try:
            bound = model.at(t, dt)
        except Exception as exc:  # noqa: BLE001
            raise fail(name, f"{_label(model)}: at({t:g}, {dt:g}) raised {type(exc).__name__}: {exc}") from None
        if not (bound.t == t and np.isclose(bound.dt, dt, rtol=1e-12)):
            raise fail(name, f"{_label(model)}: at({t:g}, {dt:g}) gave a model bound to t = {bound.t:g}, dt = "
                             f"{bound.dt:g}")
        compare(_call(model.f, x, t, dt, name, model, "f"), _f(bound, x.copy(), name),
                f"f(x, t={t:g}, dt={dt:g}) differs from at({t:g}, {dt:g}).f(x)")
        if model.has_jacobian:
            compare(_call(model.jacobian, x, t, dt, name, model, "jacobian"), _jac(bound, x.copy(), name),
                    f"jacobian(x, t={t:g}, dt={dt:g}) differs from at({t:g}, {dt:g}).jacobian(x)")
    return (f"f{' and jacobian' if model.has_jacobian else ''} with (t, dt) equal the bound model's at "
            f"{len(pairs)} steps (largest relative difference {worst:.2g})")


def _call(fn, x, t, dt, check, model, what):
    try:
        return fn(x.copy(), t, dt)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"{_label(model)}: {what}(x, t={t:g}, dt={dt:g}) raised {type(exc).__name__}: "
                          f"{exc}") from None


def _rebuilds(model) -> bool:
    return model.rebuild is not None


MOTION_CHECKS: tuple[Check, ...] = (
    Check("check_state_layout", check_state_layout.__doc__, lambda m: True, check_state_layout),
    Check("check_jacobian", check_jacobian.__doc__, lambda m: bool(m.has_jacobian), check_jacobian,
          "a jacobian (a linear model's F, or the model's own jacobian method)"),
    Check("check_noise_psd", check_noise_psd.__doc__, lambda m: True, check_noise_psd),
    Check("check_noise_factor", check_noise_factor.__doc__, lambda m: True, check_noise_factor),
    Check("check_noise_samples", check_noise_samples.__doc__, lambda m: True, check_noise_samples),
    Check("check_transition_composes", check_transition_composes.__doc__,
          lambda m: bool(m.linear) and _rebuilds(m) and m.exact_discretisation is not False,
          check_transition_composes,
          "a linear model with a rebuild function, not declaring exact_discretisation = False"),
    Check("check_noise_composes", check_noise_composes.__doc__,
          lambda m: bool(m.linear) and _rebuilds(m) and m.exact_discretisation is True,
          check_noise_composes,
          "a linear model with a rebuild function that declares exact_discretisation = True (the built-in "
          "DWNA constant-velocity and random-walk models are discretised with an acceleration held over each "
          "step, whose Q does not compose over two intervals)"),
    Check("check_time_arguments", check_time_arguments.__doc__, _takes_time, check_time_arguments,
          "a model whose f takes the time and the interval, f(x, t, dt) (one written as f(x) serves the step it "
          "is bound to)"),
    Check("check_batched_f", check_batched_f.__doc__, lambda m: True, check_batched_f),
    Check("check_no_mutation", check_no_mutation.__doc__, lambda m: True, check_no_mutation),
)


def motion_checks_for(model: MotionModel) -> list[Check]:
    """The motion-model checks that apply to ``model`` given its declarations."""
    return [c for c in MOTION_CHECKS if c.applies(model)]


def run_motion_checks(model: MotionModel) -> Outcomes:
    """Every motion-model check on ``model`` without pytest (``passed``, ``failed``, ``skipped`` with why)."""
    return run_kit(model, MOTION_CHECKS)

