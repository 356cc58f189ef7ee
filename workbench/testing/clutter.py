"""The clutter test kit: named checks that a clutter generator makes what it declares and that a clutter remover
is causal, blind to the origin labels and only narrows the valid mask.

Generators are checked against their declared ``expected_count`` (a Poisson test of the counts), ``region``
(every point inside), ``amplitude_cdf`` (a Kolmogorov-Smirnov test of ``Scans.snr``) and ``frame``; a check whose
declaration is missing does not apply (and says so).  Removers are checked on a scene built in the first of
their declared ``frames`` (``cartesian-2d`` when they declare none): a target on a straight line through
uniform clutter, with SNR and Doppler on every row.  Checks are chosen by these declarations, never by a name.

Each check is ``check(spec)``: it raises ``AssertionError`` naming the check, the statistic and the value
expected, and returns a one-line summary when it passes.  The test truth of a generator is that of the sensor
kit (:func:`workbench.testing._common.kit_truth`) in the generator's frame.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from ..frames import FRAMES
from ..rng import generator
from ..params import format_value
from ..specs import ClutterGeneratorSpec, ClutterRemoverSpec
from ..types import CLUTTER, Scans, Truth
from ._common import Check, Outcome, check_parameters, fail, frame_problems, kit_truth, normal_p, poisson_p, \
    run_kit, scans_equal
from .sensors import _raw, trial_setup

__all__ = ["GENERATOR_CHECKS", "REMOVER_CHECKS", "generator_checks_for", "remover_checks_for",
           "run_generator_checks", "run_remover_checks", "remover_scene", "check_count_poisson",
           "check_inside_region", "check_amplitude_law", "check_all_clutter", "check_causal",
           "check_never_reads_origin", "check_only_narrows", "check_generator_configured_values"]

#: Scans of the count test: RUNS x STEPS = 2,000.
RUNS, STEPS = 40, 50
#: False-alarm level of each statistical check (split evenly, Bonferroni, over the check's tests).
LEVEL = 1e-3
#: The dispersion test uses the scans whose declared mean is at least this (the normal approximation of
#: the Pearson statistic needs it).
DISPERSION_MIN_MEAN = 1.0
#: Most amplitudes the KS test uses (a fixed random subset beyond it).
KS_MAX = 20_000


def _p(p: float) -> str:
    return "p < 1e-300" if p < 1e-300 else f"p = {p:.2g}"


def _truth(spec: ClutterGeneratorSpec, check: str, runs: int, steps: int, seed: int) -> Truth:
    frame = spec.detection_frame()
    try:
        return kit_truth(frame, runs, steps, seed)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"no test truth for the generator's frame {frame!r}: {exc}") from None


def _generate(spec: ClutterGeneratorSpec, truth: Truth, check: str, seed: int, *key) -> Scans:
    try:
        scans = spec.generate(truth, generator(seed, "clutter-kit", *key), **spec.params)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"generate refused the kit's test truth (states {truth.states.shape}): "
                          f"{type(exc).__name__}: {exc}") from None
    if not isinstance(scans, Scans):
        raise fail(check, f"generate returned {type(scans).__name__}, not Scans")
    if scans.z.shape[:2] != truth.states.shape[:2]:
        raise fail(check, f"generate returned scans of (runs, steps) {scans.z.shape[:2]} for a truth of "
                          f"{truth.states.shape[:2]}")
    return scans


def _sample(spec: ClutterGeneratorSpec, check: str, seed: int = 1) -> tuple[Truth, Scans]:
    """The large sample the statistical checks share (2,000 scans)."""
    truth = _truth(spec, check, RUNS, STEPS, seed)
    return truth, _generate(spec, truth, check, seed, "sample")


# -- generators -----------------------------------------------------------------------------------------------


def check_count_poisson(spec: ClutterGeneratorSpec) -> str:
    """The number of clutter points per scan follows the declared ``expected_count``, as a Poisson count.

    Over 2,000 scans (40 test paths x 50 scans): the total count against Poisson(sum of the declared means),
    exact two-sided p-value; and the dispersion, the Pearson statistic ``X = sum (n - mu)^2 / mu`` over the scans
    with ``mu >= 1`` against its Poisson mean ``K`` (scans) and variance ``sum (2 + 1/mu)``, two-sided normal
    test; a scan whose declared mean is 0 must be empty.  False-alarm level 1e-3 for the check (5e-4 per test).
    A generator at twice its declared rate misses the total by ``sqrt(sum mu)`` standard deviations (about 80
    for a mean of 3 per scan)."""
    name = "check_count_poisson"
    truth, scans = _sample(spec, name)
    counts = scans.valid.sum(axis=2)
    mu = np.broadcast_to(np.asarray(spec.expected_count(truth, **spec.params), dtype=float), counts.shape)
    if not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise fail(name, "expected_count returned a negative or non-finite mean")
    level = LEVEL / 2
    problems = []
    zero = (mu == 0) & (counts > 0)
    if zero.any():
        b, k = np.argwhere(zero)[0]
        problems.append(f"{int(zero.sum())} scans whose declared mean is 0 hold clutter (e.g. run {b}, scan {k}: "
                        f"{counts[b, k]} points)")
    total, mean = int(counts.sum()), float(mu.sum())
    p_total = poisson_p(total, mean)
    if p_total < level:
        problems.append(f"{counts.size} scans hold {total} clutter points, {total / max(mean, 1e-300):.3f} times the "
                        f"declared mean count: expected {mean:.1f} +- {math.sqrt(mean):.1f} (Poisson), exact "
                        f"two-sided {_p(p_total)}")
    use = mu >= DISPERSION_MIN_MEAN
    k_scans = int(use.sum())
    disp = ""
    if k_scans >= 100:
        x = float(np.sum((counts[use] - mu[use]) ** 2 / mu[use]))
        var = float(np.sum(2.0 + 1.0 / mu[use]))
        z = (x - k_scans) / math.sqrt(var)
        p_disp = float(normal_p(z))
        disp = f"; dispersion X/K = {x / k_scans:.3f} (expected 1, {_p(p_disp)})"
        if p_disp < level:
            problems.append(f"the counts are {'over' if z > 0 else 'under'}-dispersed for a Poisson count: Pearson "
                            f"statistic X = {x:.0f} over {k_scans} scans with mean >= {DISPERSION_MIN_MEAN:g} "
                            f"(expected {k_scans} +- {math.sqrt(var):.0f}; X/K = {x / k_scans:.3f}, expected 1; "
                            f"z = {z:+.1f}, {_p(p_disp)})")
    if problems:
        raise fail(name, "the counts do not follow the declared expected_count (level "
                         f"{level:g} per test): " + "; ".join(problems))
    return (f"{total} points in {counts.size} scans, declared mean {mean:.1f} (Poisson {_p(p_total)})" + disp)


def _bounds(value, shape) -> np.ndarray:
    """A declared bound ``(B, T, m)``, ``(T, m)`` or ``(m,)`` broadcast to ``(B, T, 1, m)``."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 3:
        a = a[:, :, None, :]
    elif a.ndim == 2:
        a = a[None, :, None, :]
    return np.broadcast_to(a, shape[:2] + (1, shape[-1]))


def check_inside_region(spec: ClutterGeneratorSpec) -> str:
    """Every clutter point lies inside the declared ``region`` (inclusive bounds of each component, per run and
    scan), over the 2,000 scans of the count check.  Exact: no statistics, no tolerance beyond 1e-9 of the
    region's size."""
    name = "check_inside_region"
    truth, scans = _sample(spec, name)
    low, high = spec.region(truth, **spec.params)
    shape = scans.z.shape
    try:
        low, high = _bounds(low, shape), _bounds(high, shape)
    except ValueError as exc:
        raise fail(name, f"the declared region does not fit detections of shape {shape}: {exc}") from None
    tol = 1e-9 * np.maximum(np.abs(high - low), 1.0)
    outside = ((scans.z < low - tol) | (scans.z > high + tol)) & scans.valid[..., None]
    n = int(scans.valid.sum())
    if outside.any():
        labels = FRAMES[spec.detection_frame()].components if spec.detection_frame() in FRAMES else None
        rows = outside.any(axis=-1)
        b, k, j, i = np.argwhere(outside)[0]
        comp = labels[i] if labels else f"z[{i}]"
        raise fail(name, f"{int(rows.sum())} of {n} clutter points lie outside the declared region (expected 0); "
                         f"e.g. run {b}, scan {k}, row {j}: {comp} = {scans.z[b, k, j, i]:.6g} not in "
                         f"[{low[b, k, 0, i]:.6g}, {high[b, k, 0, i]:.6g}]")
    return f"all {n} clutter points inside the declared region"


def check_amplitude_law(spec: ClutterGeneratorSpec) -> str:
    """The clutter amplitudes (``Scans.snr``) follow the declared ``amplitude_cdf``: a one-sample
    Kolmogorov-Smirnov test (``scipy.stats.kstest``) of up to 20,000 amplitudes of the count check's scans,
    two-sided, false-alarm level 1e-3."""
    name = "check_amplitude_law"
    truth, scans = _sample(spec, name)
    if scans.snr is None:
        raise fail(name, "the scans carry no amplitudes (Scans.snr) to compare with the declared amplitude_cdf")
    x = scans.snr[scans.valid]
    if x.size < 50:
        raise fail(name, f"only {x.size} clutter points in {scans.valid.shape[0] * scans.valid.shape[1]} scans; "
                         f"the test needs 50")
    if not np.all(np.isfinite(x)):
        raise fail(name, f"{int((~np.isfinite(x)).sum())} valid clutter points have no finite amplitude")
    if x.size > KS_MAX:
        x = generator(0, "clutter-kit", "ks-subset").choice(x, KS_MAX, replace=False)
    params = dict(spec.params)
    cdf = lambda s: np.asarray(spec.amplitude_cdf(s, **params), dtype=float)  # noqa: E731
    result = stats.kstest(x, cdf)
    median = float(np.median(x))
    if result.pvalue < LEVEL:
        raise fail(name, f"the amplitudes of {x.size} clutter points do not follow the declared amplitude_cdf: "
                         f"Kolmogorov-Smirnov D = {result.statistic:.4f} (expected below "
                         f"{stats.kstwo.isf(LEVEL, x.size):.4f} at level {LEVEL:g}), {_p(result.pvalue)}; the "
                         f"declared cdf at the sample median {median:.4g} is {float(cdf(median)):.3f} (expected 0.5)")
    return f"{x.size} amplitudes: KS D = {result.statistic:.4f}, {_p(result.pvalue)}"


def check_all_clutter(spec: ClutterGeneratorSpec) -> str:
    """Every valid row a clutter generator makes is labelled ``CLUTTER`` (origin -1)."""
    name = "check_all_clutter"
    truth = _truth(spec, name, 8, 10, seed=2)
    scans = _generate(spec, truth, name, 2, "labels")
    if scans.origin is None:
        raise fail(name, "the scans carry no origin labels; every clutter row is labelled CLUTTER (-1)")
    labels = scans.origin[scans.valid]
    wrong = labels != CLUTTER
    if wrong.any():
        raise fail(name, f"{int(wrong.sum())} of {labels.size} valid rows are labelled "
                         f"{sorted(set(labels[wrong].tolist()))[:5]}, not CLUTTER ({CLUTTER})")
    return f"{labels.size} valid rows, every one labelled CLUTTER"


def check_generator_same_seed(spec: ClutterGeneratorSpec) -> str:
    """The same seed gives bit-identical scans (every field); a different seed gives different ones."""
    name = "check_same_seed_same_scans"
    truth = _truth(spec, name, 8, 10, seed=3)
    a = _generate(spec, truth, name, 5, "seed")
    b = _generate(spec, truth, name, 5, "seed")
    differ = scans_equal(a, b)
    if differ:
        raise fail(name, f"two runs with the same seed differ in {', '.join(differ)}: the generator draws from "
                         f"something other than the rng it is given")
    if not scans_equal(a, _generate(spec, truth, name, 6, "seed")):
        raise fail(name, "two runs with different seeds gave identical scans: the generator does not draw from the "
                         "rng it is given")
    return "same seed: identical scans; another seed: different scans"


def check_generator_frame(spec: ClutterGeneratorSpec) -> str:
    """The declared frame is one of :data:`workbench.frames.FRAMES`, the points have its dimension and their
    angular components lie in (-pi, pi]; the scans have the truth's times."""
    name = "check_frame_respected"
    truth = _truth(spec, name, 8, 10, seed=4)
    scans = _generate(spec, truth, name, 4, "frame")
    problems = frame_problems(spec.detection_frame(), scans.z, scans.valid, f"clutter generator {spec.name!r}")
    if not np.array_equal(scans.times, truth.times):
        problems.append("the scans' times are not the truth's times")
    if problems:
        raise fail(name, "; ".join(problems))
    return f"{spec.detection_frame()!r} points of dimension {scans.z.shape[-1]}"


#: The truth of the configured-values check: runs x steps, dt seconds apart.
EFFECT_RUNS, EFFECT_STEPS, EFFECT_DT = 4, 30, 5.0


def _declared_problems(configured: ClutterGeneratorSpec, truth: Truth, seed: int) -> tuple[Scans, list[str]]:
    """The configured generator's scans, and where it called without parameters is not its plugin's functions
    called with its ``params``."""
    params = dict(configured.params)
    out = []
    a = configured.generate(truth, generator(seed, "clutter-kit", "configured"))
    b = _raw(configured.generate)(truth, generator(seed, "clutter-kit", "configured"), **params)
    if scans_equal(a, b):
        out.append(f"generate(truth, rng) differs from the plugin's generate(truth, rng, **params) in "
                   f"{', '.join(scans_equal(a, b))}")
    snr = np.linspace(-10.0, 40.0, 11)
    for field, args in (("expected_count", (truth,)), ("region", (truth,)), ("amplitude_cdf", (snr,))):
        fn = getattr(configured, field)
        if fn is not None and not _same_output(fn(*args), _raw(fn)(*args, **params)):
            out.append(f"{field}() differs from the plugin's {field}(..., **params)")
    return a, out


def _same_output(x, y) -> bool:
    if isinstance(x, tuple) and isinstance(y, tuple):
        return len(x) == len(y) and all(_same_output(u, v) for u, v in zip(x, y))
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return x.shape == y.shape and bool(np.array_equal(x, y, equal_nan=True))


def check_generator_configured_values(spec: ClutterGeneratorSpec) -> str:
    """Every declared parameter, configured (``spec.configure(name=value)``) to another valid value, changes the
    clutter the generator makes (the same seed, 4 test paths of 30 scans 5 s apart), and the configured generator
    called without parameters (``generate(truth, rng)``, ``expected_count``, ``region``, ``amplitude_cdf``) equals its
    plugin's own functions called with the configured ``params``.

    A parameter with :attr:`~workbench.params.Param.when` conditions (the settings in which it has an effect, e.g. a
    site's detection probability when there are sites) is tried with them met.  The values tried are those of
    :func:`workbench.testing.sensors.trial_values` that pass the declaration; the check passes a parameter at the
    first one that changes the clutter.  A parameter with no other valid value is not tried."""
    name = "check_configured_values"
    declared = spec.declared
    problems, tried, untried = [], [], []
    seed = 9
    for p in declared:
        conds, base, value, values, problem = trial_setup(spec, p)
        if problem:
            problems.append(problem)
            continue
        if not values:
            untried.append(p.name)
            continue
        try:
            truth = kit_truth(base.detection_frame(), EFFECT_RUNS, EFFECT_STEPS, seed, dt=EFFECT_DT)
            before = base.generate(truth, generator(seed, "clutter-kit", "configured"))
        except Exception as exc:  # noqa: BLE001
            problems.append(f"{p.name!r}: no test truth or clutter with {conds or 'its values'}: "
                            f"{type(exc).__name__}: {exc}")
            continue
        found, notes = None, []
        for v in values:
            try:
                configured = base.configure(**{p.name: v})
                after, wrong = _declared_problems(configured, truth, seed)
            except Exception as exc:  # noqa: BLE001
                notes.append(f"{format_value(v)}: {type(exc).__name__}: {exc}")
                continue
            changed = scans_equal(before, after)
            if configured.detection_frame() != base.detection_frame():
                changed.append("frame")
            if changed or wrong:
                found = (v, changed, wrong)
                break
            notes.append(f"{format_value(v)} changed nothing")
        where = f" (with {', '.join(f'{k} = {format_value(w)}' for k, w in conds.items())})" if conds else ""
        if found is None:
            problems.append(f"{p.name!r}{where} changed nothing in the clutter when configured from "
                            f"{format_value(value)} to: " + "; ".join(notes))
            continue
        v, changed, wrong = found
        if wrong:
            problems.append(f"{p.name!r} = {format_value(v)}{where}: the configured generator called without "
                            f"parameters is not its plugin's functions called with the configured params: "
                            + "; ".join(wrong))
            continue
        tried.append(f"{p.name} -> {', '.join(changed)}")
    if problems:
        raise fail(name, f"{len(problems)} of {len(declared)} parameters are not honoured when configured: "
                   + "; ".join(problems) + "; a parameter that has an effect only in some settings declares them "
                                           "with Param.when")
    skipped = f"; not tried (no other valid value): {', '.join(untried)}" if untried else ""
    return f"{len(tried)} parameters configured, each changed the clutter: " + "; ".join(tried) + skipped


def _parameters(spec) -> str:
    """Every declared default passes its own declaration, and so does the current value; a NaN, a quantity in a
    wrong unit, a string outside the choices and an undeclared key are each refused by ``spec.configure`` with
    an ``InputError`` that names the parameter."""
    return check_parameters(spec, "check_parameters")


GENERATOR_CHECKS: tuple[Check, ...] = (
    Check("check_count_poisson", check_count_poisson.__doc__, lambda s: s.expected_count is not None,
          check_count_poisson, "a declared expected_count"),
    Check("check_inside_region", check_inside_region.__doc__, lambda s: s.region is not None, check_inside_region,
          "a declared region"),
    Check("check_amplitude_law", check_amplitude_law.__doc__, lambda s: s.amplitude_cdf is not None,
          check_amplitude_law, "a declared amplitude_cdf"),
    Check("check_all_clutter", check_all_clutter.__doc__, lambda s: True, check_all_clutter),
    Check("check_same_seed_same_scans", check_generator_same_seed.__doc__, lambda s: True, check_generator_same_seed),
    Check("check_frame_respected", check_generator_frame.__doc__, lambda s: True, check_generator_frame),
    Check("check_parameters", _parameters.__doc__, lambda s: True, _parameters),
    Check("check_configured_values", check_generator_configured_values.__doc__, lambda s: bool(s.declared),
          check_generator_configured_values, "declared parameters"),
)


# -- removers -------------------------------------------------------------------------------------------------

#: The remover scene: a box of this side (non-angular components), the target's step per scan, the mean clutter
#: count per scan (at most MAX_CLUTTER rows), scans and runs.
BOX, TARGET_STEP, CLUTTER_RATE, MAX_CLUTTER, SCENE_STEPS, SCENE_RUNS = 250.0, 4.0, 20.0, 45, 16, 3


def remover_scene(frame: str, seed: int, runs: int = SCENE_RUNS, steps: int = SCENE_STEPS) -> Scans:
    """A scene for a remover in ``frame``: per run, a target moving on a straight line (``TARGET_STEP`` per scan
    through the box ``[0, BOX]`` of each non-angular component; angles in (-pi, pi]) with noise 1, detected with
    probability 0.9, plus ``Poisson(CLUTTER_RATE)`` uniform clutter points per scan; every row has an SNR (target
    15 dB, clutter 10 log10 of an exponential power of mean 10) and a Doppler (target 5 to 20 Hz in magnitude,
    clutter uniform in +-10 Hz); ``origin`` 0 for the target, ``CLUTTER`` otherwise.

    Shapes: ``z (runs, steps, 1 + MAX_CLUTTER, m)``; row 0 is the target's.
    """
    f = FRAMES[frame]
    m = f.dim
    ang = np.asarray(f.angular)
    lo = np.where(ang, -math.pi, 0.0)
    span = np.where(ang, 2 * math.pi, BOX)
    rng = generator(seed, "remover-scene", frame, runs, steps)
    start = lo + span * (0.25 + 0.5 * rng.random((runs, m)))
    direction = rng.standard_normal((runs, m))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    step = np.where(ang, 0.02, TARGET_STEP) * direction
    k = np.arange(steps, dtype=float)
    target = start[:, None, :] + k[None, :, None] * step[:, None, :] + np.where(ang, 0.005, 1.0) * rng.standard_normal(
        (runs, steps, m))
    counts = np.minimum(rng.poisson(CLUTTER_RATE, (runs, steps)), MAX_CLUTTER)
    clutter = lo + span * rng.random((runs, steps, MAX_CLUTTER, m))
    z = np.concatenate([target[:, :, None, :], clutter], axis=2)
    z = np.where(ang, (z + math.pi) % (2 * math.pi) - math.pi, z)
    valid = np.concatenate([(rng.random((runs, steps)) < 0.9)[..., None],
                            np.arange(MAX_CLUTTER) < counts[..., None]], axis=2)
    snr = np.concatenate([np.full((runs, steps, 1), 15.0),
                          10 * np.log10(rng.exponential(10.0, (runs, steps, MAX_CLUTTER)))], axis=2)
    sign = np.where(rng.random((runs, 1, 1)) < 0.5, -1.0, 1.0)
    doppler = np.concatenate([np.broadcast_to(sign * rng.uniform(5, 20, (runs, 1, 1)), (runs, steps, 1)),
                              rng.uniform(-10, 10, (runs, steps, MAX_CLUTTER))], axis=2)
    origin = np.concatenate([np.zeros((runs, steps, 1), int), np.full((runs, steps, MAX_CLUTTER), CLUTTER)], axis=2)
    return Scans(z, valid, k, snr=snr, doppler=doppler, origin=origin)


def _scene(spec: ClutterRemoverSpec, seed: int = 1) -> Scans:
    return remover_scene(spec.frames[0] if spec.frames else "cartesian-2d", seed)


def _remove(spec: ClutterRemoverSpec, scans: Scans, check: str) -> Scans:
    try:
        out = spec.remove(scans, **spec.params)
    except Exception as exc:  # noqa: BLE001
        raise fail(check, f"remove refused the kit's scene (z {scans.z.shape}): {type(exc).__name__}: {exc}") from None
    if not isinstance(out, Scans) or out.valid.shape != scans.valid.shape:
        shape = getattr(getattr(out, "valid", None), "shape", None)
        raise fail(check, f"remove returned {type(out).__name__} with valid of shape {shape}, expected Scans with "
                          f"valid {scans.valid.shape}")
    return out


def _splice(early: Scans, late: Scans, k: int) -> Scans:
    """Scans ``0..k`` of ``early`` followed by scans ``k+1..`` of ``late`` (same shapes)."""
    def cat(a, b):
        return np.concatenate([a[:, :k + 1], b[:, k + 1:]], axis=1)

    return Scans(cat(early.z, late.z), cat(early.valid, late.valid), early.times, snr=cat(early.snr, late.snr),
                 doppler=cat(early.doppler, late.doppler), origin=cat(early.origin, late.origin))


def check_causal(spec: ClutterRemoverSpec) -> str:
    """The decision for scan ``k`` uses scans ``<= k`` only: at three cuts ``k``, replacing scans ``k+1..`` by
    other ones, or dropping them, leaves the kept rows of scans ``0..k`` unchanged."""
    name = "check_causal"
    scans = _scene(spec)
    other = _scene(spec, seed=2)
    out = _remove(spec, scans, name).valid
    problems = []
    for k in (SCENE_STEPS // 4, SCENE_STEPS // 2, 3 * SCENE_STEPS // 4):
        for how, changed in (("replaced", _splice(scans, other, k)), ("dropped", scans.head(k + 1))):
            got = _remove(spec, changed, name).valid[:, :k + 1]
            diff = got != out[:, :k + 1]
            if diff.any():
                b, t, j = np.argwhere(diff)[0]
                problems.append(f"with scans {k + 1}.. {how}, {int(diff.sum())} decisions for scans 0..{k} changed "
                                f"(e.g. run {b}, scan {t}, row {j}: {'kept' if out[b, t, j] else 'dropped'} before, "
                                f"{'kept' if got[b, t, j] else 'dropped'} after)")
    if problems:
        raise fail(name, "the remover looks ahead (a causal remover decides scan k from scans <= k): "
                         + "; ".join(problems))
    kept = int(out.sum())
    return (f"decisions for scans 0..k unchanged when later scans change or are dropped (3 cuts; {kept} of "
            f"{int(scans.valid.sum())} rows kept)")


def check_never_reads_origin(spec: ClutterRemoverSpec) -> str:
    """The output is the same with the ``origin`` labels removed or scrambled (the labels are for metrics only)."""
    name = "check_never_reads_origin"
    scans = _scene(spec)
    out = _remove(spec, scans, name)
    rng = generator(0, "clutter-kit", "scramble")
    scrambled = rng.permuted(scans.origin, axis=2)
    scrambled = np.where(rng.random(scrambled.shape) < 0.3, rng.integers(-1, 3, scrambled.shape), scrambled)
    problems = []
    for how, origin in (("removed", None), ("scrambled", scrambled)):
        changed = Scans(scans.z, scans.valid, scans.times, snr=scans.snr, doppler=scans.doppler, origin=origin)
        got = _remove(spec, changed, name)
        both = out.valid & got.valid
        differ = ["valid"] if not np.array_equal(out.valid, got.valid) else []
        differ += [f for f in scans_equal(out.with_valid(both), got.with_valid(both)) if f not in ("origin", "valid")]
        if differ:
            n = int((out.valid != got.valid).sum())
            problems.append(f"with the origin labels {how}, the output differs in {', '.join(differ)}"
                            + (f" ({n} decisions changed)" if n else ""))
    if problems:
        raise fail(name, "the remover reads the origin labels, which only metrics may read: " + "; ".join(problems))
    return "same output with the origin labels removed or scrambled"


def check_only_narrows(spec: ClutterRemoverSpec) -> str:
    """The remover only narrows the valid mask: no invalid row becomes valid, and the detections themselves
    (``z``, ``snr``, ``doppler``, ``times``) are unchanged."""
    name = "check_only_narrows"
    scans = _scene(spec)
    out = _remove(spec, scans, name)
    problems = []
    widened = out.valid & ~scans.valid
    if widened.any():
        b, k, j = np.argwhere(widened)[0]
        problems.append(f"{int(widened.sum())} invalid rows became valid (e.g. run {b}, scan {k}, row {j})")
    changed = [f for f in scans_equal(scans.with_valid(out.valid & scans.valid), out)
               if f not in ("valid", "origin")]
    if changed:
        problems.append(f"the remover changed {', '.join(changed)} (it may only narrow valid)")
    if problems:
        raise fail(name, "; ".join(problems))
    return f"{int(out.valid.sum())} of {int(scans.valid.sum())} rows kept, no row widened or moved"


REMOVER_CHECKS: tuple[Check, ...] = (
    Check("check_causal", check_causal.__doc__, lambda s: True, check_causal),
    Check("check_never_reads_origin", check_never_reads_origin.__doc__, lambda s: True, check_never_reads_origin),
    Check("check_only_narrows", check_only_narrows.__doc__, lambda s: True, check_only_narrows),
    Check("check_parameters", _parameters.__doc__, lambda s: True, _parameters),
)


def generator_checks_for(spec: ClutterGeneratorSpec) -> list[Check]:
    """The generator checks that apply to ``spec`` given its declarations."""
    return [c for c in GENERATOR_CHECKS if c.applies(spec)]


def remover_checks_for(spec: ClutterRemoverSpec) -> list[Check]:
    """The remover checks that apply to ``spec`` (all of them)."""
    return [c for c in REMOVER_CHECKS if c.applies(spec)]


def run_generator_checks(spec: ClutterGeneratorSpec) -> list[Outcome]:
    """Every generator check on ``spec`` without pytest."""
    return run_kit(spec, GENERATOR_CHECKS)


def run_remover_checks(spec: ClutterRemoverSpec) -> list[Outcome]:
    """Every remover check on ``spec`` without pytest."""
    return run_kit(spec, REMOVER_CHECKS)
