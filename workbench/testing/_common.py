"""What the test kits share: the check record, the runner, the kits' test truth, the parameter check and the
exact tail probabilities the statistical checks use.

Every kit is a tuple of :class:`Check`; a check is a plain function ``check(spec)`` that raises
``AssertionError`` with a readable message (naming the check, the statistic and the value expected) and may
return a one-line summary of what it measured, which :func:`run_kit` shows for a passed check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Sequence as SequenceABC
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np
from scipy import stats

from ..frames import FRAMES, frame as frame_of
from ..params import check_value
from ..rng import generator
from ..types import InputError, Truth

__all__ = ["Check", "Outcome", "Outcomes", "run_kit", "iter_kit", "kit_truth", "check_parameters", "normal_p", "chi2_p", "poisson_p",
           "fail", "SPACE_DIMS", "scans_equal", "frame_problems"]


@dataclass(frozen=True)
class Check:
    """One named check of a kit.

    ``applies(spec)`` says, from the component's declared capabilities and fields (never its name), whether the
    check applies; ``requires`` says in words what it needs, for the message of a check that does not apply.
    """

    name: str
    description: str
    applies: Callable[[Any], bool]
    run: Callable[[Any], Any]
    requires: str = ""

    def __call__(self, spec) -> Any:
        return self.run(spec)


@dataclass(frozen=True)
class Outcome:
    check: str
    status: str  # passed, failed, skipped, xfailed, xpassed
    message: str = ""


def _exit_message(spec, exc: SystemExit) -> str:
    """What a check that ended in ``sys.exit()`` records: the call, where it was made (file, line, function and
    module of the innermost frame) and the component."""
    call = "sys.exit()" if exc.code is None else f"sys.exit({exc.code!r})"
    where, tb = "", exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    if tb is not None:
        code = tb.tb_frame.f_code
        module = tb.tb_frame.f_globals.get("__name__", "?")
        where = f" at {Path(code.co_filename).name}:{tb.tb_lineno} (in {code.co_name}, module {module})"
    kind = getattr(spec, "kind", "component")
    return (f"{kind} {getattr(spec, 'name', '?')!r} called {call}{where}; a plugin must raise an exception, never "
            f"end the process: the check is recorded as failed and the kit goes on")


def iter_kit(spec, checks: Sequence[Check]) -> Iterator[Outcome]:
    """Every check of ``checks`` on ``spec`` without pytest, each outcome as soon as its check finishes:
    ``passed`` (with the check's summary, if it returns one), ``failed`` (with its message), ``skipped`` (does not
    apply, and why), ``xfailed`` / ``xpassed`` for a check the component declares among its ``expected_failures``.
    A component that calls ``sys.exit()`` inside a check fails that check (the message names the call, where it was
    made and the component) and the kit goes on with the next."""
    expected_failures = getattr(spec, "expected_failures", {}) or {}
    for check in checks:
        if not check.applies(spec):
            why = f"does not apply: needs {check.requires}" if check.requires else \
                "does not apply to the declared capabilities"
            yield Outcome(check.name, "skipped", why)
            continue
        expected = expected_failures.get(check.name)
        try:
            summary = check.run(spec)
        except SystemExit as exc:  # a plugin ending the process ends only its check
            yield Outcome(check.name, "xfailed" if expected else "failed", _exit_message(spec, exc))
            continue
        except Exception as exc:  # noqa: BLE001 - a check's failure is its outcome
            msg = str(exc) if isinstance(exc, AssertionError) else f"{type(exc).__name__}: {exc}"
            yield Outcome(check.name, "xfailed" if expected else "failed", msg)
            continue
        if expected:
            yield Outcome(check.name, "xpassed", f"expected to fail ({expected}) but passed")
        else:
            yield Outcome(check.name, "passed", summary if isinstance(summary, str) else "")


class Outcomes(SequenceABC):
    """The outcomes of a kit run, each computed when it is first read: a caller that iterates (``workbench
    check-plugin`` prints a line per outcome) sees every outcome as soon as its check finishes, while indexing,
    ``len()`` and a second iteration see one list (the checks run once).  Compares equal to a list of the same
    outcomes."""

    def __init__(self, outcomes: Iterable[Outcome]):
        self._source: Iterator[Outcome] | None = iter(outcomes)
        self._done: list[Outcome] = []

    def _fill(self, upto: int | None = None) -> None:
        while self._source is not None and (upto is None or len(self._done) <= upto):
            try:
                self._done.append(next(self._source))
            except StopIteration:
                self._source = None

    def __iter__(self) -> Iterator[Outcome]:
        i = 0
        while True:
            self._fill(i)
            if i >= len(self._done):
                return
            yield self._done[i]
            i += 1

    def __len__(self) -> int:
        self._fill()
        return len(self._done)

    def __getitem__(self, index):
        if isinstance(index, slice) or index < 0:
            self._fill()
        else:
            self._fill(index)
        return self._done[index]

    def __eq__(self, other) -> bool:
        if isinstance(other, (Outcomes, list, tuple)):
            return list(self) == list(other)
        return NotImplemented

    def __repr__(self) -> str:
        return f"Outcomes({list(self)!r})"


def run_kit(spec, checks: Sequence[Check]) -> Outcomes:
    """Every check of ``checks`` on ``spec`` without pytest (:func:`iter_kit`): a sequence of outcomes filled as it
    is read, so a caller that iterates sees each outcome as soon as its check finishes."""
    return Outcomes(iter_kit(spec, checks))


def fail(check: str, message: str) -> AssertionError:
    """The error a check raises: its name, then what it measured and what it expected."""
    return AssertionError(f"{check}: {message}")


# -- exact tail probabilities -----------------------------------------------------------------------------


def normal_p(z) -> np.ndarray:
    """Two-sided p-value of standard normal scores ``z``: ``2 (1 - Phi(|z|))``."""
    return 2.0 * stats.norm.sf(np.abs(np.asarray(z, dtype=float)))


def chi2_p(statistic: float, dof: float) -> float:
    """Two-sided p-value of a chi-square statistic with ``dof`` degrees of freedom: ``2 min(F, 1 - F)``."""
    return float(min(1.0, 2.0 * min(stats.chi2.cdf(statistic, dof), stats.chi2.sf(statistic, dof))))


def poisson_p(count: int, mean: float) -> float:
    """Exact two-sided p-value of a Poisson ``count`` with mean ``mean``: ``2 min(P(N <= n), P(N >= n))``."""
    if mean <= 0:
        return 1.0 if count == 0 else 0.0
    return float(min(1.0, 2.0 * min(stats.poisson.cdf(count, mean), stats.poisson.sf(count - 1, mean))))


# -- the kits' test truth -----------------------------------------------------------------------------------

#: Position dimensions of the kits' test truth for detections in each built-in measurement frame: the state is
#: ``[p (d), v (d)]``, positions first (``range-rate``: a range and its rate, ``d = 1``).  Each frame declares its
#: own (:attr:`workbench.frames.Frame.space`); :func:`kit_truth` reads that, so plugin frames have test truths too.
SPACE_DIMS = {name: f.space for name, f in FRAMES.items()}

#: The start distances of the test paths: log-uniform between these (m).
DISTANCES = (30.0, 60e3)
#: Their speeds: log-uniform between these (m/s).
SPEEDS = (2.0, 40.0)


def kit_truth(frame: str, batch: int, steps: int, seed: int, centre=None, dt: float = 1.0) -> Truth:
    """Straight constant-velocity test paths in the state layout a ``frame`` sensor takes.

    Run ``b`` starts at a distance from ``centre`` (default the origin) drawn log-uniformly in
    :data:`DISTANCES`, in a random direction (3-D: at an altitude of 2 % to 30 % of its horizontal distance),
    and moves at a speed drawn log-uniformly in :data:`SPEEDS` in a random direction, so a batch covers
    near and far targets, slow and fast ones, at every bearing.  ``dt`` seconds between steps.

    Shapes: ``states (batch, steps, 2 d)`` with ``d`` the frame's declared ``space`` (its position axes: built in
    or added by a plugin), ``times (steps,)``.
    """
    try:
        d = frame_of(frame).space
    except InputError as exc:
        raise InputError(f"the test kits have no test truth for detections in the frame {frame!r}: {exc}") from None
    rng = generator(seed, "kit-truth", frame, batch, steps)
    dist = np.exp(rng.uniform(np.log(DISTANCES[0]), np.log(DISTANCES[1]), batch))
    if d == 1:
        p = dist[:, None]
    else:
        u = rng.standard_normal((batch, 2))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        p = dist[:, None] * u
        if d == 3:
            p = np.concatenate([p, (dist * rng.uniform(0.02, 0.3, batch))[:, None]], axis=1)
    if centre is not None:
        p = p + np.asarray(centre, dtype=float)[:d]
    speed = np.exp(rng.uniform(np.log(SPEEDS[0]), np.log(SPEEDS[1]), batch))
    v = rng.standard_normal((batch, d))
    v *= (speed / np.linalg.norm(v, axis=1))[:, None]
    t = dt * np.arange(steps, dtype=float)
    # p_k = p_0 + v t_k,  v constant
    pos = p[:, None, :] + v[:, None, :] * t[None, :, None]
    return Truth(np.concatenate([pos, np.broadcast_to(v[:, None, :], pos.shape)], axis=-1), t)


# -- shared checks --------------------------------------------------------------------------------------------


def _bad_values(param) -> list[tuple[str, Any]]:
    """``(what, value)`` pairs a declaration must refuse: a NaN, a quantity of another unit, a non-choice."""
    out: list[tuple[str, Any]] = []
    if param.type in ("float", "float?", "int"):
        out.append(("NaN", float("nan")))
    elif param.type in ("vector", "vector?"):
        n = param.length or (len(param.default) if isinstance(param.default, (tuple, list)) and param.default else 1)
        out.append(("a vector holding NaN", (float("nan"),) * n))
    if param.unit is not None and param.type != "int":
        wrong = "1 m" if param.unit != "length" else "1 s"
        value: Any = wrong
        if param.type in ("vector", "vector?"):
            n = param.length or (len(param.default) if isinstance(param.default, (tuple, list)) and param.default
                                 else 1)
            value = (wrong,) * n
        out.append((f"a value in the wrong unit ({wrong!r} for a {param.unit})", value))
    if param.type == "str" and param.choices:
        out.append(("a value outside its choices", "__not-a-choice__"))
    if param.type == "bool":
        out.append(("a non-boolean", "yes"))
    return out


def check_parameters(spec, name: str = "check_parameters") -> str:
    """Every declared default passes its own declaration, and so does the current value; a NaN, a quantity in a
    wrong unit, a string outside the choices and an undeclared key are each refused by ``spec.configure`` with
    an ``InputError`` that names the parameter."""
    problems = []
    declared = spec.declared
    for p in declared:
        for label, value in (("default", p.default), ("current value", spec.params.get(p.name, p.default))):
            try:
                check_value(p, value, f"{spec.kind} {spec.name!r}: {p.name}")
            except InputError as exc:
                problems.append(f"the {label} of {p.name!r} ({value!r}) fails its own declaration: {exc}")
        for what, value in _bad_values(p):
            try:
                spec.configure(**{p.name: value})
            except InputError as exc:
                if p.name not in str(exc):
                    problems.append(f"{what} for {p.name!r} is refused, but the message does not name the "
                                    f"parameter: {exc}")
            except Exception as exc:  # noqa: BLE001 - the wrong kind of error is the finding
                problems.append(f"{what} for {p.name!r} raised {type(exc).__name__} ({exc}), not an InputError")
            else:
                problems.append(f"{what} for {p.name!r} was accepted ({value!r})")
    try:
        spec.configure(__kit_undeclared__=1.0)
    except InputError as exc:
        if "__kit_undeclared__" not in str(exc):
            problems.append(f"an undeclared parameter is refused without naming it: {exc}")
    except Exception as exc:  # noqa: BLE001
        problems.append(f"an undeclared parameter raised {type(exc).__name__} ({exc}), not an InputError")
    else:
        problems.append("an undeclared parameter was accepted")
    if problems:
        raise fail(name, f"{len(problems)} problem(s) with the declared parameters: " + "; ".join(problems))
    return f"{len(declared)} declared parameters: defaults valid; NaN, wrong units and undeclared keys refused by name"


def frame_problems(frame_name: str, z: np.ndarray, valid: np.ndarray, who: str) -> list[str]:
    """What is wrong with detections ``z (..., m)`` (valid rows ``valid (...)``) said to be in ``frame_name``: an
    unknown frame, a dimension other than the frame's, angular components outside (-pi, pi]."""
    if not frame_name:
        return [f"{who} declares no measurement frame (frames: {', '.join(FRAMES)})"]
    if frame_name not in FRAMES:
        return [f"{who} declares the frame {frame_name!r}, which is not one of {', '.join(FRAMES)}"]
    frame = FRAMES[frame_name]
    if z.shape[-1] != frame.dim:
        return [f"{who} makes detections of dimension {z.shape[-1]}, but its frame {frame_name!r} has {frame.dim} "
                f"components {frame.components}"]
    out = []
    rows = z[valid]
    for i, (component, angular) in enumerate(zip(frame.components, frame.angular)):
        if not angular or not rows.size:
            continue
        bad = ~((rows[:, i] > -math.pi) & (rows[:, i] <= math.pi))
        if bad.any():
            out.append(f"{int(bad.sum())} of {len(rows)} {component} values lie outside (-pi, pi] (e.g. "
                       f"{rows[bad, i][0]:.6g}); angular components are wrapped")
    return out


def scans_equal(a, b) -> list[str]:
    """The fields in which two :class:`~workbench.types.Scans` differ (NaN equals NaN)."""
    out = []
    for key in ("z", "valid", "times", "snr", "doppler", "origin", "cov", "clutter_density"):
        x, y = getattr(a, key), getattr(b, key)
        if x is None and y is None:
            continue
        if x is None or y is None or x.shape != y.shape or not np.array_equal(
                x, y, equal_nan=bool(np.issubdtype(np.asarray(x).dtype, np.floating))):
            out.append(key)
    return out
