"""The target table of ``workbench bench``: one line per declared target with its measured value and verdict.

A benchmark group declares a target with three figures that share a name ``X`` (at any depth of its result):

- ``target_X``: the target as text, a comparison and a number with an optional unit: ``"<= 2"``, ``">= 0.5"``,
  ``"< 30 s"``;
- ``measured_X``: the measured value (a number), or a short string saying why there is none
  (``"not installed"``);
- ``met_X``: whether this run met it (a bool), or a short string where it cannot say.  Without it the
  runner judges the measured value against the target itself.

A ``target_X`` that is not text is not a declared target (an older convention's figure) and is left out of the
table.  An optional ``note_X`` (text) is printed under the line: what the figure is measured against, or why a target
is missed.  In quick mode no target is ever "met": the verdict is ``"indicative"`` (small sizes, few
repeats), whatever the group says.

Repeats.  ``workbench bench --repeats R`` runs each group R times; the runner reports each figure's median and
its spread (:func:`workbench.bench.combine_runs`) and judges every target on the MEDIAN of its ``measured_X``
(:func:`median_verdict`): the goal is parsed here (a goal that is not a comparison with a number is refused by
name, :func:`parse_goal`), and a run whose own ``met_X`` said "not met" although its measured value met the goal
(a group whose rule asks more than the goal, e.g. bit-identical results) keeps the target not met.  The table
prints the goal, min / median / max of the measured value over the runs, and the verdict.
"""

from __future__ import annotations

import math
import operator
import re
import statistics
from dataclasses import dataclass

from ..types import InputError

__all__ = ["Target", "collect_targets", "format_targets", "parse_target", "parse_goal", "judge", "median_verdict",
           "NOT_UNDERSTOOD"]

#: The verdict of a target whose goal is not a comparison with a number (refused, never guessed).
NOT_UNDERSTOOD = "target not understood"

_OPS = {"<=": operator.le, ">=": operator.ge, "<": operator.lt, ">": operator.gt, "==": operator.eq}
_TARGET = re.compile(r"^\s*(<=|>=|<|>|==)\s*([-+0-9.eE]+)\s*(.*?)\s*$")


@dataclass(frozen=True)
class Target:
    """One row of the target table."""

    group: str
    name: str
    target: str
    measured: object
    verdict: str
    note: str = ""
    #: the smallest and largest measured value over the runs (``None`` where there is no numeric spread) and
    #: how many runs the measured value (the median) is taken over
    min: object = None
    max: object = None
    runs: int = 1


def parse_target(text: str) -> tuple[str, float, str] | None:
    """``"<= 2 s"`` -> ``("<=", 2.0, "s")``; ``None`` for text that is not a comparison with a number."""
    m = _TARGET.match(str(text))
    if not m:
        return None
    try:
        return m.group(1), float(m.group(2)), m.group(3)
    except ValueError:
        return None


def parse_goal(text, name: str) -> tuple[str, float, str]:
    """:func:`parse_target`, refusing a goal it does not understand with an :class:`~workbench.types.InputError`
    that names the target (``name``, e.g. ``"core.pf_over_floor_N100000"``)."""
    parsed = parse_target(text) if isinstance(text, str) else None
    if parsed is None:
        raise InputError(f"benchmark target {name}: goal {text!r} is not a comparison with a number "
                         f"(expected e.g. '>= 10', '<= 0.5' or '< 30 s'); it cannot be judged")
    return parsed


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def median_verdict(name: str, goal, measured_runs: list, met_runs: list) -> tuple[bool, str]:
    """The verdict of target ``name`` over several runs: whether the MEDIAN of the numeric ``measured_runs``
    meets ``goal``, and a remark (empty, or why a run keeps it not met).

    ``met_runs`` are the group's own ``met_X`` of each run (``None`` where it declares none): a run that said
    ``False`` although its own measured value met the goal applied a further condition of the group (e.g.
    bit-identical results); then the target is not met whatever the median.  An unparseable goal raises
    :class:`~workbench.types.InputError` naming the target; a measured value that is not a finite number in
    every run raises ``ValueError`` (there is no median to judge)."""
    op, value, _ = parse_goal(goal, name)
    if not measured_runs or not all(_is_number(m) for m in measured_runs):
        raise ValueError(f"benchmark target {name}: measured values {measured_runs!r} are not all finite numbers")
    median = statistics.median(measured_runs)
    for k, (m, own) in enumerate(zip(measured_runs, met_runs), start=1):
        if own is False and _OPS[op](m, value):
            return False, (f"run {k} of {len(measured_runs)}: the group's own rule said not met although "
                           f"{m:.4g} meets the goal {goal!r}")
    return bool(_OPS[op](median, value)), ""


def judge(target: str, measured) -> str:
    """``"met"`` / ``"not met"`` for a numeric ``measured`` against ``target``; else why it cannot say."""
    parsed = parse_target(target)
    if parsed is None:
        return NOT_UNDERSTOOD
    if isinstance(measured, bool) or not isinstance(measured, (int, float)) or not math.isfinite(measured):
        return str(measured) if isinstance(measured, str) else "not measured"
    op, value, _ = parsed
    return "met" if _OPS[op](measured, value) else "not met"


def _leaves(prefix: str, value, out: dict) -> dict:
    if isinstance(value, dict):
        for k, v in value.items():
            _leaves(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        for i, v in enumerate(value):
            _leaves(f"{prefix}[{i}]", v, out)
    else:
        out[prefix] = value
    return out


def collect_targets(results: dict, quick: bool, spread: dict | None = None) -> list[Target]:
    """Every declared target of every group in ``results`` (``{group: figures}``), in the groups' order.

    ``spread`` (``{group: {dotted figure name: {"min", "median", "max", "runs"}}}``, from
    :func:`workbench.bench.combine_runs`) gives each row the min and max of its measured value over the runs; the
    measured value of ``results`` is then the median, and the group's ``met_X`` there was judged on it.  A goal
    that is not a comparison with a number gets the verdict :data:`NOT_UNDERSTOOD`, in quick mode too."""
    spread = spread or {}
    rows = []
    for group, figures in results.items():
        if not isinstance(figures, dict):
            continue
        leaves = _leaves("", figures, {})
        for key, target in leaves.items():
            head, _, leaf = key.rpartition(".")
            if not leaf.startswith("target_") or not isinstance(target, str):
                continue  # a number named target_* is a figure of an older convention, not a declared target
            name = leaf[len("target_"):]
            at = (head + ".") if head else ""
            measured = leaves.get(f"{at}measured_{name}", "not measured")
            met = leaves.get(f"{at}met_{name}")
            note = leaves.get(f"{at}note_{name}", "")
            sp = (spread.get(group) or {}).get(f"{at}measured_{name}") or {}
            if parse_target(target) is None:
                verdict = NOT_UNDERSTOOD
            elif quick:
                verdict = "indicative"
            elif isinstance(met, bool):
                verdict = "met" if met else "not met"
            elif met is not None:
                verdict = str(met)
            else:
                verdict = judge(str(target), measured)
            rows.append(Target(group, at + name, str(target), measured, verdict, str(note or ""),
                               sp.get("min"), sp.get("max"), len(sp.get("runs", ())) or 1))
    return rows


def _value(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def format_targets(rows: list[Target], quick: bool) -> str:
    """The table: one line per target (group, name, goal, min / median / max of the measured value over the runs,
    verdict), notes indented below.  Where the measured value is not a number (or has no spread) min and max
    read ``-``."""
    if not rows:
        return "targets: none declared"
    head = ("group", "target", "goal", "min", "median", "max", "verdict")
    cells = [(r.group, r.name, r.target, "-" if r.min is None else _value(r.min), _value(r.measured),
              "-" if r.max is None else _value(r.max), r.verdict) for r in rows]
    width = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(head)]
    runs = max(r.runs for r in rows)
    title = "targets" + (f" (judged on the median of {runs} runs)" if runs > 1 else "") + (
        " (quick sizes: indicative only, never 'met')" if quick else "")
    lines = [title, "  ".join(h.ljust(w) for h, w in zip(head, width)).rstrip()]
    for r, c in zip(rows, cells):
        lines.append("  ".join(v.ljust(w) for v, w in zip(c, width)).rstrip())
        if r.note:
            lines.append(" " * (width[0] + 2) + "note: " + r.note)
    return "\n".join(lines)
