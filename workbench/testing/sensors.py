"""The sensor test kit: named checks that a sensor plugin's detections are what its declarations say.

Checks are chosen by the sensor's declared fields (its detection ``frame``, its measurement model's ``frame``,
``truth_to_state``, ``noise_cov``), never by its name.  Each check is ``check(spec)``: it raises
``AssertionError`` naming the check, the statistic and the value expected, and returns a one-line summary
when it passes.  Use them from pytest (:func:`workbench.testing.parametrize_with_checks`, ids such as
``lband-radar-check_centred_on_h``) or without it (:func:`run_checks`, ``workbench check-plugin NAME``).

The test truth (:func:`workbench.testing._common.kit_truth`) is a batch of straight constant-velocity paths in
the state layout the detection frame declares (``[p, v]`` with ``space`` position axes,
:attr:`workbench.frames.Frame.space`: ``[x, y, vx, vy]`` for ``cartesian-2d``, ``range-bearing`` and ``bearing``,
``[x, y, z, vx, vy, vz]`` for ``position-doppler-3d``, ``cartesian-3d`` and ``bistatic-range-rate``; a plugin's
frame declares its own), starting 30 m to 60 km from the model's ``sensor_position`` (the origin when it declares
none), so that every sensor sees some of them.  Nothing assumes a frame has two components, a range or a position:
a one-component angular frame (``bearing``) is checked like any other.  What a sensor must declare for the kit:

- ``frame`` (the detections' frame) and a measurement model with its own ``frame``;
- ``truth_to_state`` when its model's ``h`` takes a state derived from the truth rather than the truth itself;
- ``noise_cov`` when its simulation noise is not its model's ``R``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..frames import FRAMES
from ..params import format_value, when_example
from ..rng import generator
from ..specs import BoundFunction, SensorSpec
from ..types import Scans, Truth
from ._common import Check, Outcome, chi2_p, check_parameters, fail, frame_problems, kit_truth, normal_p, run_kit, \
    scans_equal

__all__ = ["SENSOR_CHECKS", "sensor_checks_for", "run_sensor_checks", "check_centred_on_h",
           "check_same_seed_same_scans", "check_frame_respected", "check_origin_labels", "check_sensor_parameters",
           "check_configured_values", "trial_values", "model_view", "views_differ"]

#: Test paths and scans of the chi-square test: up to RUNS x STEPS target detections.
RUNS, STEPS = 100, 20
#: Fewest target detections the chi-square test accepts.
MIN_DETECTIONS = 200
#: The family-wise false-alarm level of the chi-square check, split evenly (Bonferroni) over its tests.
LEVEL = 1e-3


def _p(p: float) -> str:
    return "p < 1e-300" if p < 1e-300 else f"p = {p:.2g}"


def _model(spec: SensorSpec):
    return spec.measurement_model(**spec.params)


def _truth(spec: SensorSpec, check: str, runs: int, steps: int, seed: int) -> Truth:
    frame = spec.detection_frame()
    try:
        centre = _model(spec).sensor_position
    except Exception:  # noqa: BLE001 - the model's own error is reported by the checks that use it
        centre = None
    try:
        return kit_truth(frame, runs, steps, seed, centre=centre)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"no test truth for the sensor's detection frame {frame!r}: {exc}") from None


def _simulate(spec: SensorSpec, truth: Truth, check: str, seed: int, *key) -> Scans:
    try:
        scans = spec.simulate(truth, generator(seed, "sensor-kit", *key), **spec.params)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"simulate refused the kit's test truth (states {truth.states.shape}, [p, v] for "
                          f"{spec.detection_frame()!r} detections): {type(exc).__name__}: {exc}") from None
    if not isinstance(scans, Scans):
        raise fail(check, f"simulate returned {type(scans).__name__}, not Scans")
    return scans


def _frames_agree(spec: SensorSpec) -> bool:
    """The measurement model describes the detections themselves (its frame is theirs, or undeclared)."""
    try:
        model_frame = _model(spec).frame
        return not model_frame or model_frame == spec.detection_frame()
    except Exception:  # noqa: BLE001 - let the check run and report the error
        return True


def check_centred_on_h(spec: SensorSpec) -> str:
    """The target detections are distributed as ``N(h(x), C)``: ``h`` the sensor's own measurement model applied to
    the truth (through ``truth_to_state`` where declared), ``C`` the declared ``noise_cov`` of each detection or
    else the model's ``R``.

    On up to 2,000 detections of 100 test paths (residuals by ``model.residual``, so angles wrap): per component
    the mean of ``r_j / sqrt(C_jj)`` (normal test) and its mean square (chi-square with N degrees of freedom);
    per pair of components the cross-moment of the whitened residuals ``L^-1 r`` (``C = L L^T``, normal test);
    and the Mahalanobis sum ``sum r^T C^-1 r`` (chi-square with N m degrees of freedom); all two-sided.
    False-alarm level: 1e-3 for the whole check (Bonferroni over its tests).  A 3-sigma bias in one component
    gives a mean score near 3 sqrt(N), beyond 130 standard errors at N = 2,000."""
    name = "check_centred_on_h"
    model = _model(spec)
    frame = spec.detection_frame()
    truth = _truth(spec, name, RUNS, STEPS, seed=1)
    scans = _simulate(spec, truth, name, 1, "centred")
    m = model.dim
    if scans.z.shape[-1] != m:
        raise fail(name, f"detections have dimension {scans.z.shape[-1]}, the measurement model {m}")
    state = truth.states
    if spec.truth_to_state is not None:
        state = np.asarray(spec.truth_to_state(truth.states, **spec.params), dtype=float)
    try:
        expected = np.asarray(model.h(state), dtype=float)
    except Exception as exc:  # noqa: BLE001
        hint = ("; a sensor whose model describes another quantity than the truth state declares "
                "SensorSpec.truth_to_state" if spec.truth_to_state is None else "")
        raise fail(name, f"the measurement model's h does not take the test truth's states ({state.shape[-1]}-"
                         f"dimensional for {frame!r} detections): {type(exc).__name__}: {exc}{hint}") from None
    if expected.shape != state.shape[:2] + (m,):
        raise fail(name, f"h of states {state.shape} has shape {expected.shape}, expected {state.shape[:2] + (m,)}")
    target = scans.valid if scans.origin is None else scans.valid & (scans.origin == 0)
    n = int(target.sum())
    if n < MIN_DETECTIONS:
        raise fail(name, f"only {n} target detections on {truth.batch * truth.steps} test scans (paths 30 m to 60 km "
                         f"from the sensor); the test needs {MIN_DETECTIONS}")
    r = model.residual(scans.z, np.broadcast_to(expected[:, :, None, :], scans.z.shape))[target]
    if spec.noise_cov is None:
        source = "the model's R"
        C = np.broadcast_to(model.R, (n, m, m))
    else:
        source = "the declared noise_cov"
        C = np.broadcast_to(np.asarray(spec.noise_cov(truth, scans, **spec.params), dtype=float),
                            scans.z.shape + (m,))[target]
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        raise fail(name, f"{source} is not positive definite for every target detection; the test needs it "
                         f"to be") from None
    labels = FRAMES[model.frame].components if model.frame in FRAMES else tuple(f"z[{i}]" for i in range(m))
    sd = np.sqrt(np.diagonal(C, axis1=-2, axis2=-1))
    u = r / sd  # each component over its declared standard deviation
    w = np.linalg.solve(L, r[..., None])[..., 0]  # whitened: L^-1 r ~ N(0, I)
    se = 1.0 / math.sqrt(n)
    tests = []  # (p, kind order, message)
    for j in range(m):
        mean = float(u[:, j].mean())
        z = mean / se
        p = float(normal_p(z))
        tests.append((p, 0, f"component {labels[j]!r}: mean residual {mean:+.3f} sigma (expected 0 +- {se:.3f}; "
                            f"z = {z:+.1f}, {_p(p)})"))
    for j in range(m):
        s = float(np.sum(u[:, j] ** 2))
        p = chi2_p(s, n)
        msg = (f"component {labels[j]!r}: mean square residual {s / n:.3f} sigma^2 (expected 1 +- "
               f"{math.sqrt(2.0 / n):.3f}, the spread {source} declares; chi-square({n}) {_p(p)})")
        tests.append((p, 1, msg))
    for j in range(m):
        for k in range(j + 1, m):
            c = float(np.mean(w[:, j] * w[:, k]))
            p = float(normal_p(c / se))
            tests.append((p, 2, f"components {labels[j]!r}, {labels[k]!r}: whitened cross-moment {c:+.3f} "
                                f"(expected 0 +- {se:.3f}, {_p(p)}): the correlation is not what {source} declares"))
    total = float(np.sum(w * w))
    p = chi2_p(total, n * m)
    tests.append((p, 3, f"Mahalanobis sum {total:.0f} (expected {n * m} +- {math.sqrt(2.0 * n * m):.0f}, "
                        f"chi-square({n * m}) {_p(p)})"))
    level = LEVEL / len(tests)
    bad = sorted((t for t in tests if t[0] < level), key=lambda t: (t[1], t[0]))
    if bad:
        hint = ""
        if spec.noise_cov is None and any(t[1] == 1 for t in bad):
            hint = ("; if R deliberately is not the simulation noise (a filters' R, or accuracy that follows each "
                    "detection's SNR), declare the simulation noise as SensorSpec.noise_cov")
        raise fail(name, f"the {n} target detections are not distributed as N(h(truth), {source}) (each test at "
                         f"level {level:.1g}, {LEVEL:g} for the check): " + "; ".join(t[2] for t in bad) + hint)
    worst = max(abs(float(u[:, j].mean())) for j in range(m))
    return (f"{n} target detections: largest |mean residual| {worst:.3f} sigma, mean squares "
            + ", ".join(f"{float(np.mean(u[:, j] ** 2)):.3f}" for j in range(m))
            + f" (expected 1, from {source}); smallest p = {min(t[0] for t in tests):.2g} over {len(tests)} tests "
              f"at level {level:.1g}")


def check_same_seed_same_scans(spec: SensorSpec) -> str:
    """The same seed gives bit-identical scans (every field); a different seed gives different ones."""
    name = "check_same_seed_same_scans"
    truth = _truth(spec, name, 8, 10, seed=2)
    a = _simulate(spec, truth, name, 5, "seed")
    b = _simulate(spec, truth, name, 5, "seed")
    differ = scans_equal(a, b)
    if differ:
        raise fail(name, f"two simulations with the same seed differ in {', '.join(differ)}: the sensor draws "
                         f"from something other than the rng it is given")
    c = _simulate(spec, truth, name, 6, "seed")
    if not scans_equal(a, c):
        raise fail(name, "two simulations with different seeds gave identical scans: the sensor does not draw its "
                         "noise from the rng it is given")
    return "same seed: identical scans; another seed: different scans"


def check_frame_respected(spec: SensorSpec) -> str:
    """The declared detection frame is known (:data:`workbench.frames.FRAMES`: built in or added by a loaded plugin),
    the detections have its dimension and their angular components lie in (-pi, pi]; the scans have the truth's
    batch, steps and times; the measurement model declares a frame whose angular components are the ones it
    wraps."""
    name = "check_frame_respected"
    truth = _truth(spec, name, 20, 10, seed=3)
    scans = _simulate(spec, truth, name, 3, "frame")
    frame = spec.detection_frame()
    problems = frame_problems(frame, scans.z, scans.valid, f"sensor {spec.name!r}")
    if scans.z.shape[:2] != truth.states.shape[:2]:
        problems.append(f"scans have (runs, steps) {scans.z.shape[:2]}, the truth {truth.states.shape[:2]}")
    elif not np.array_equal(scans.times, truth.times):
        problems.append("the scans' times are not the truth's times")
    model = _model(spec)
    if not model.frame:
        problems.append(f"its measurement model {model.name!r} declares no frame")
    elif model.frame not in FRAMES:
        problems.append(f"its measurement model declares the unknown frame {model.frame!r}")
    elif tuple(model.angular) != FRAMES[model.frame].angular:
        problems.append(f"its measurement model wraps the components {model.angular} but its frame "
                        f"{model.frame!r} has angular components {FRAMES[model.frame].angular}")
    if problems:
        raise fail(name, "; ".join(problems))
    view = "" if model.frame == frame else f"; the measurement model is a {model.frame!r} view"
    angles = ", angles in (-pi, pi]" if any(FRAMES[frame].angular) else ""
    return f"{frame!r} detections of dimension {FRAMES[frame].dim}{angles}{view}"


def check_origin_labels(spec: SensorSpec) -> str:
    """Every valid detection of a sensor is the target's: its ``origin`` label is the truth's index, 0."""
    name = "check_origin_labels"
    truth = _truth(spec, name, 20, 10, seed=4)
    scans = _simulate(spec, truth, name, 4, "origin")
    if scans.origin is None:
        raise fail(name, "the scans carry no origin labels; a sensor labels each detection with the index of the "
                         "truth object it comes from (0 for the single target)")
    n = int(scans.valid.sum())
    if n == 0:
        raise fail(name, f"no valid detection on {truth.batch * truth.steps} test scans")
    labels = scans.origin[scans.valid]
    wrong = labels != 0
    if wrong.any():
        found = sorted(set(labels[wrong].tolist()))[:5]
        raise fail(name, f"{int(wrong.sum())} of {n} valid detections are labelled {found}, not 0 (the index of the "
                         f"truth object; clutter comes from clutter generators)")
    return f"{n} valid detections, every one labelled 0 (the truth's index)"


# -- configured values -----------------------------------------------------------------------------------------

#: The truth of the configured-values check: runs x steps, dt seconds apart (0 to 295 s, so parameters of time,
#: such as the times at which a target's aspect changes, are crossed).
EFFECT_RUNS, EFFECT_STEPS, EFFECT_DT = 20, 60, 5.0


def trial_setup(spec, p):
    """For ``check_configured_values``: ``(conds, base, value, values, problem)``: the settings that meet ``p``'s
    :attr:`~workbench.params.Param.when` conditions, the spec configured to them, ``p``'s value there, the other
    values to try (those of :func:`trial_values` its declaration accepts) and a problem line (or ``""``) where the
    conditions themselves are refused."""
    conds = {key: when_example(want) for key, want in p.when}
    try:
        base = spec.configure(**conds) if conds else spec
    except Exception as exc:  # noqa: BLE001
        return conds, None, None, [], f"{p.name!r}: its when conditions {conds} are refused: {exc}"
    value = base.params.get(p.name, p.default)
    values = []
    for v in trial_values(p, value):
        try:
            base.check(**{p.name: v})
        except Exception:  # noqa: BLE001 - not a valid value of this parameter: try another
            continue
        values.append(v)
    return conds, base, value, values, ""


def trial_values(param, value) -> list:
    """Other valid-looking values of ``param`` than its current ``value``, in the order a kit tries them: the
    other choices (or ``not value``); for a number ``value / 2``, ``1.5 value + 1`` and ``value + 100 (|value| + 1)``
    (each moved half-way back towards ``value`` where it passes a declared bound); for an integer ``value + 1`` and
    ``2 value + 1``; for a vector the same element by element; for an optional value ``None`` or a number.  The
    caller still checks each against the declaration (:meth:`workbench.specs.SensorSpec.check`)."""
    if param.type == "bool":
        return [not value] if isinstance(value, bool) else [True, False]
    if param.type == "str":
        return [c for c in (param.choices or ()) if c != value]
    low, high = param.bounds

    def inside(x: float, v: float) -> float:  # half-way from v to the bound x passes
        return (v + high) / 2 if x > high else (v + low) / 2 if x < low else x

    def numbers(v: float) -> list[float]:
        if param.type == "int":
            return [inside(v + 1, v), inside(2 * v + 1, v)]
        return [inside(0.5 * v, v), inside(1.5 * v + 1.0, v), inside(v + 100.0 * (abs(v) + 1.0), v)]

    if value is None:
        if param.type == "vector?":
            n = param.length or (len(param.default) if isinstance(param.default, (tuple, list)) else 0)
            return [tuple(min(max(1.0, low), high) for _ in range(n))] if n else []
        seeds = [param.default] if param.default is not None else []
        return [min(max(float(v), low), high) for v in seeds + [1.0, 10.0]]
    if param.type in ("vector", "vector?"):
        out = [tuple(column) for column in zip(*(numbers(float(v)) for v in value))] if len(value) else []
    else:
        out = numbers(float(value))
        out = [int(round(v)) for v in out] if param.type == "int" else out
    if param.type.endswith("?"):
        out.append(None)
    unique = []
    for v in out:
        if v != (tuple(value) if isinstance(value, list) else value) and v not in unique:
            unique.append(v)
    return unique


def _view(value) -> Any:
    return value if value is None or isinstance(value, str) else np.asarray(value, dtype=float)


def model_view(model, states: np.ndarray) -> dict[str, Any]:
    """Everything a filter can read from a measurement model, evaluated at ``states (..., n)``: its name, frame,
    angular components, ``h``, the Jacobian, ``R``, ``H``, ``std``, ``sensor_position`` and its detection law at fixed
    SNRs, ranges and positions; an evaluation that raises is held as its error text."""
    def call(fn, *args):
        try:
            return _view(fn(*args))
        except Exception as exc:  # noqa: BLE001 - a changed error is a changed model
            return f"{type(exc).__name__}: {exc}"

    x = np.asarray(states, dtype=float)
    view: dict[str, Any] = {"name": model.name, "frame": model.frame, "angular": _view(model.angular),
                            "h": call(model.h, x), "R": _view(model.R), "H": _view(model.H), "std": _view(model.std),
                            "sensor_position": _view(model.sensor_position)}
    if model.jacobian is not None:
        view["jacobian"] = call(model.jacobian, x.reshape(-1, x.shape[-1]))
    d = model.detection
    if d is not None:
        snr, ranges = np.array([3.0, 8.0, 15.0, 25.0]), np.array([500.0, 5e3, 2e4, 6e4])
        view.update(log_pd=call(d.log_pd, snr), position_sigma=call(d.position_sigma, snr, ranges),
                    doppler_sigma=_view(d.doppler_sigma), pfa=_view(d.pfa))
        position = x[..., :3] if x.shape[-1] >= 6 else np.array([[1e3, 2e3, 300.0], [2e4, -1e4, 3e3]])
        for name, args in (("nominal_snr_db", (position,)), ("log_detection", (snr,)),
                           ("log_snr_density", (snr, snr[::-1])), ("clutter_log_snr_density", (snr,))):
            fn = getattr(d, name, None)
            if fn is not None:
                view[name] = call(fn, *args)
    return view


def views_differ(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The entries of two model views that differ (NaN equals NaN)."""
    def same(x, y) -> bool:
        if isinstance(x, np.ndarray) and isinstance(y, np.ndarray):
            return x.shape == y.shape and bool(np.array_equal(x, y, equal_nan=True))
        return type(x) is type(y) and x == y  # names, frames, error texts, None

    return sorted(k for k in a.keys() | b.keys() if k not in a or k not in b or not same(a[k], b[k]))


def _raw(fn):
    """The plugin's own function behind a spec's bound function."""
    return fn.raw if isinstance(fn, BoundFunction) else fn


def _configured_problems(configured: SensorSpec, truth: Truth, states, seed: int):
    """``(model view, scans, problems)``: the view of ``configured.measurement_model()`` at ``states``, its
    ``simulate(truth, rng)`` and where ``configured`` called without parameters is not its plugin's functions
    called with its ``params``."""
    out = []
    params = dict(configured.params)
    bound = model_view(configured.measurement_model(), states)
    raw = model_view(_raw(configured.measurement_model)(**params), states)
    if views_differ(bound, raw):
        out.append(f"measurement_model() differs from the plugin's measurement_model(**params) in "
                   f"{', '.join(views_differ(bound, raw))}")
    a = configured.simulate(truth, generator(seed, "sensor-kit", "configured"))
    b = _raw(configured.simulate)(truth, generator(seed, "sensor-kit", "configured"), **params)
    if scans_equal(a, b):
        out.append(f"simulate(truth, rng) differs from the plugin's simulate(truth, rng, **params) in "
                   f"{', '.join(scans_equal(a, b))}")
    if configured.truth_to_state is not None and not np.array_equal(
            np.asarray(configured.truth_to_state(truth.states)),
            np.asarray(_raw(configured.truth_to_state)(truth.states, **params))):
        out.append("truth_to_state(states) differs from the plugin's truth_to_state(states, **params)")
    if configured.noise_cov is not None and not np.array_equal(
            np.asarray(configured.noise_cov(truth, a)), np.asarray(_raw(configured.noise_cov)(truth, a, **params)),
            equal_nan=True):
        out.append("noise_cov(truth, scans) differs from the plugin's noise_cov(truth, scans, **params)")
    return bound, a, out


def check_configured_values(spec: SensorSpec) -> str:
    """Every declared parameter, configured (``spec.configure(name=value)``) to another valid value, changes what the
    sensor publishes or simulates as its declared role says, and the configured sensor called without parameters
    (``measurement_model()``, ``simulate(truth, rng)``, ``truth_to_state``, ``noise_cov``) equals its plugin's own
    functions called with the configured ``params``.

    Roles (:attr:`workbench.params.Param.affects`): a ``"simulation"`` parameter must change the simulated
    detections (the same seed, 20 test paths of 60 scans 5 s apart); a ``"noise"`` one the published model's ``R``; a
    ``"model"`` one something a filter reads from the model (``h``, the Jacobian, ``R``, frame, sensor position,
    detection law).  A parameter with :attr:`~workbench.params.Param.when` conditions is tried with them met.  The
    values tried are :func:`trial_values` that pass the declaration; the check passes a parameter at the first one
    that has an effect.  A parameter with no other valid value (a single choice, a free string) is not tried."""
    name = "check_configured_values"
    declared = spec.declared
    roles = bool(spec.parameters)  # inferred declarations carry no role: any effect will do
    problems, tried, untried = [], [], []
    seed = 8
    for p in declared:
        conds, base, value, values, problem = trial_setup(spec, p)
        if problem:
            problems.append(problem)
            continue
        if not values:
            untried.append(p.name)
            continue
        try:
            truth = kit_truth(base.detection_frame(), EFFECT_RUNS, EFFECT_STEPS, seed,
                              centre=base.measurement_model().sensor_position, dt=EFFECT_DT)
            states = truth.states[:4, ::10]
            if base.truth_to_state is not None:
                states = np.asarray(base.truth_to_state(states), dtype=float)
            before_model = model_view(base.measurement_model(), states)
            before_scans = base.simulate(truth, generator(seed, "sensor-kit", "configured"))
        except Exception as exc:  # noqa: BLE001
            problems.append(f"{p.name!r}: no test truth, model or detections of the sensor with "
                            f"{conds or 'its values'}: {type(exc).__name__}: {exc}")
            continue
        role = p.affects if roles else "any"
        found, notes = None, []
        for v in values:
            try:
                configured = base.configure(**{p.name: v})
                view, simulated, wrong = _configured_problems(configured, truth, states, seed)
                if configured.detection_frame() != base.detection_frame():
                    found = (v, [f"detection frame {configured.detection_frame()!r}"], wrong)
                    break
                model = views_differ(before_model, view)
                scans = scans_equal(before_scans, simulated)
            except Exception as exc:  # noqa: BLE001
                notes.append(f"{format_value(v)}: {type(exc).__name__}: {exc}")
                continue
            effect = (scans if role == "simulation" else ["R"] if role == "noise" and "R" in model else
                      [] if role == "noise" else model if role == "model" else model + scans)
            if effect or wrong:
                found = (v, effect, wrong)
                break
            seen = ([f"the model's {', '.join(model)}"] if model else []) + (
                [f"the simulated {', '.join(scans)}"] if scans else [])
            notes.append(f"{format_value(v)} changed " + (" and ".join(seen) or "nothing"))
        where = f" (with {', '.join(f'{k} = {format_value(w)}' for k, w in conds.items())})" if conds else ""
        if found is None:
            what = {"simulation": "the simulated detections", "noise": "the published model's R",
                    "model": "the published measurement model", "any": "the model or the detections"}[role]
            problems.append(f"{p.name!r}{where}, declared affects={p.affects!r}, changed nothing in {what} when "
                            f"configured from {format_value(value)} to: " + "; ".join(notes))
            continue
        v, effect, wrong = found
        if wrong:
            problems.append(f"{p.name!r} = {format_value(v)}{where}: the configured sensor called without "
                            f"parameters is not its plugin's functions called with the configured params: "
                            + "; ".join(wrong))
            continue
        tried.append(f"{p.name} -> {', '.join(effect)}")
    if problems:
        hint = ("; a parameter that shapes only the simulated detections declares affects='simulation', one that "
                "reaches the model only in some settings declares them with Param.when")
        raise fail(name, f"{len(problems)} of {len(declared)} parameters are not honoured when configured: "
                   + "; ".join(problems) + hint)
    skipped = f"; not tried (no other valid value): {', '.join(untried)}" if untried else ""
    return f"{len(tried)} parameters configured, each changed what it declares: " + "; ".join(tried) + skipped


def check_sensor_parameters(spec: SensorSpec) -> str:
    """Every declared default passes its own declaration, and so does the current value; a NaN, a quantity in a
    wrong unit, a string outside the choices and an undeclared key are each refused by ``spec.configure`` with
    an ``InputError`` that names the parameter."""
    return check_parameters(spec, "check_parameters")


SENSOR_CHECKS: tuple[Check, ...] = (
    Check("check_centred_on_h", check_centred_on_h.__doc__, _frames_agree, check_centred_on_h,
          "a measurement model in the frame of the detections (this one's model is a view in another frame)"),
    Check("check_same_seed_same_scans", check_same_seed_same_scans.__doc__, lambda s: True,
          check_same_seed_same_scans),
    Check("check_frame_respected", check_frame_respected.__doc__, lambda s: True, check_frame_respected),
    Check("check_origin_labels", check_origin_labels.__doc__, lambda s: True, check_origin_labels),
    Check("check_parameters", check_sensor_parameters.__doc__, lambda s: True, check_sensor_parameters),
    Check("check_configured_values", check_configured_values.__doc__, lambda s: bool(s.declared),
          check_configured_values, "declared parameters"),
)


def sensor_checks_for(spec: SensorSpec) -> list[Check]:
    """The sensor checks that apply to ``spec`` given its declarations."""
    return [c for c in SENSOR_CHECKS if c.applies(spec)]


def run_sensor_checks(spec: SensorSpec) -> list[Outcome]:
    """Every sensor check on ``spec`` without pytest."""
    return run_kit(spec, SENSOR_CHECKS)
