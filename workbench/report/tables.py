"""The report's plain-data helpers, shared by the engine and the pages: the time tables and JSON-ready values.

- :func:`task_time_table`: the time table of a paper's task entries (:data:`TASK_STATUSES`);
- :func:`paper_time_table`: that table with the paper's wall seconds and the seconds outside the tasks, from a
  :class:`~workbench.report.engine.PaperOutcome` (read by attribute; this module imports neither the engine nor
  the pages, so that both import it);
- :func:`_jsonable`: a value as plain JSON data.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

__all__ = ["TASK_STATUSES", "task_time_table", "paper_time_table"]


#: How a task of the time table got its result: run now, read from the cache (0 s), reused on the confirmation seed
#: from the reported seed (a task declared ``seeded=False``: 0 s), or failed (its seconds were spent all the same).
TASK_STATUSES = ("computed", "cached", "reused", "failed")


def _task_status(entry: Mapping) -> str:
    if entry.get("error"):
        return "failed"
    if entry.get("reused"):
        return "reused"
    return "cached" if entry.get("cached") else "computed"


def _shares(seconds: Sequence[float]) -> list[float]:
    """Percent shares of ``seconds`` in hundredths of a percent, by largest remainder: they sum to exactly 100 %
    (in hundredths) when any second was spent, and every one is 0 when none was."""
    total = float(sum(seconds))
    if not total > 0.0:
        return [0.0 for _ in seconds]
    exact = [10_000.0 * s / total for s in seconds]
    parts = [int(np.floor(e)) for e in exact]
    for i in sorted(range(len(exact)), key=lambda i: (parts[i] - exact[i], i))[:10_000 - sum(parts)]:
        parts[i] += 1
    return [p / 100.0 for p in parts]


def task_time_table(entries: Iterable[Mapping]) -> dict:
    """The time table of a report's task entries (``PaperOutcome.tasks``: ``key, seconds, cached, error`` and, where
    recorded, ``runs`` and ``reused``).

    Returns ``{"computed_seconds", "counts", "rows"}``: ``rows`` holds one ``{task, runs, seconds, share_percent,
    status}`` per entry, the largest first (ties in the entries' order); ``status`` is one of
    :data:`TASK_STATUSES`.  A cached or reused task counts 0 s; the shares are of the seconds the tasks spent (the
    computed and the failed ones), in hundredths of a percent, and sum to exactly 100 % (all 0 where every task was
    cached).
    """
    entries = list(entries)
    statuses = [_task_status(e) for e in entries]
    seconds = [0.0 if st in ("cached", "reused") else max(float(e.get("seconds") or 0.0), 0.0)
               for e, st in zip(entries, statuses)]
    shares = _shares(seconds)
    rows = [{"task": str(e.get("key")),
             "runs": None if e.get("runs") is None else int(e["runs"]),
             "seconds": s, "share_percent": sh, "status": st}
            for e, st, s, sh in zip(entries, statuses, seconds, shares)]
    order = sorted(range(len(rows)), key=lambda i: (-rows[i]["seconds"], i))
    return {"computed_seconds": float(sum(seconds)),
            "counts": {st: statuses.count(st) for st in TASK_STATUSES},
            "rows": [rows[i] for i in order]}


def paper_time_table(outcome) -> dict:
    """A paper's time table (:func:`task_time_table` of its tasks) with the paper's wall seconds and the seconds
    spent outside the tasks: ``other_seconds`` by stage (figures and tables, criteria) and ``items``, each figure
    and table with its seconds and their parts (``{what, seconds, parts}``, the largest first)."""
    table = task_time_table(outcome.tasks)
    table["paper_seconds"] = float(outcome.seconds)
    table["other_seconds"] = {k: float(v) for k, v in outcome.stage_seconds.items()}
    items = [{"what": str(k), "seconds": float(sum(parts.values())), "parts": {p: float(v) for p, v in parts.items()}}
             for k, parts in outcome.item_seconds.items()]
    table["items"] = sorted(items, key=lambda item: -item["seconds"])
    return table


def _jsonable(value, strict: bool = False):
    """``value`` as plain JSON data (numpy scalars and arrays, tuples, paths converted; others as str).

    With ``strict``, non-finite floats become ``None`` (standard JSON has no NaN or infinity).
    """
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v, strict) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v, strict) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist(), strict)
    if isinstance(value, np.generic):
        return _jsonable(value.item(), strict)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and strict and not np.isfinite(value):
        return None
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return str(value)
