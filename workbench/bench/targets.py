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
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass

__all__ = ["Target", "collect_targets", "format_targets", "parse_target", "judge"]

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


def parse_target(text: str) -> tuple[str, float, str] | None:
    """``"<= 2 s"`` -> ``("<=", 2.0, "s")``; ``None`` for text that is not a comparison with a number."""
    m = _TARGET.match(str(text))
    if not m:
        return None
    try:
        return m.group(1), float(m.group(2)), m.group(3)
    except ValueError:
        return None


def judge(target: str, measured) -> str:
    """``"met"`` / ``"not met"`` for a numeric ``measured`` against ``target``; else why it cannot say."""
    parsed = parse_target(target)
    if parsed is None:
        return "target not understood"
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


def collect_targets(results: dict, quick: bool) -> list[Target]:
    """Every declared target of every group in ``results`` (``{group: figures}``), in the groups' order."""
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
            if quick:
                verdict = "indicative"
            elif isinstance(met, bool):
                verdict = "met" if met else "not met"
            elif met is not None:
                verdict = str(met)
            else:
                verdict = judge(str(target), measured)
            rows.append(Target(group, at + name, str(target), measured, verdict, str(note or "")))
    return rows


def _value(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def format_targets(rows: list[Target], quick: bool) -> str:
    """The table: one line per target (group, name, target, measured, verdict), notes indented below."""
    if not rows:
        return "targets: none declared"
    head = ("group", "target", "goal", "measured", "verdict")
    cells = [(r.group, r.name, r.target, _value(r.measured), r.verdict) for r in rows]
    width = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(head)]
    title = "targets" + (" (quick sizes: indicative only, never 'met')" if quick else "")
    lines = [title, "  ".join(h.ljust(w) for h, w in zip(head, width)).rstrip()]
    for r, c in zip(rows, cells):
        lines.append("  ".join(v.ljust(w) for v, w in zip(c, width)).rstrip())
        if r.note:
            lines.append(" " * (width[0] + 2) + "note: " + r.note)
    return "\n".join(lines)
