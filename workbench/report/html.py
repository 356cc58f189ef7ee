"""Write the report's pages (``index.html`` and one page per paper) and ``summary.json``.

``index.html`` holds the at-a-glance table (one row per paper: its verdicts counted, the criteria that could not be
judged, the confirmation seed's agreement, a link to its page) and the provenance.  Each paper has its own page,
``paper-NNN.html`` (:func:`page_name`), beside the index: its scoreboard first (each criterion's verdict, ours beside
published as the same statistic, the number of runs, the 95 % interval and the threshold), then its declared
unknowns, what differs from the paper, its figures, tables, published values and time table.  Every page has the same
side navigation (the index, each paper, the parts of the paper being read, the provenance).  Figures are the PNG files
the report wrote (``paperNNN/FIG.png``), linked beside the pages with their width and height, never embedded.  The
anchors of the former one-page report (``index.html#paperNNN-scoreboard``) still work: the index sends them on to the
paper's page.

The markup lives in Jinja2 templates (``workbench/report/templates``, autoescaped); the Python helpers here compute
what goes in the cells.  Published values are shown as readable text or small tables, never as Python reprs; a
table's column is right-aligned when all its values are numbers and left-aligned otherwise.  The pages and the
summary show every paper of the report folder (see :func:`workbench.report.engine.run_report`); each file is
written atomically, the paper pages before the index, and a paper page left from a paper no longer in the folder is
removed.
"""

from __future__ import annotations

import html
import json
import math
import os
import platform
import re
import struct
from dataclasses import replace
from datetime import datetime, timezone
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping
from urllib.parse import quote

import numpy as np
from jinja2 import Environment, FileSystemLoader, StrictUndefined
from markupsafe import Markup

from ..criteria import VERDICTS, where_it_holds
from ..plugins import PluginHost
from .cache import distribution_versions, write_text_atomic
from .tables import _jsonable, paper_time_table

__all__ = ["write_index", "write_summary", "format_value", "human_value", "is_numeric_like", "page_name"]

TEMPLATES = Path(__file__).resolve().parent / "templates"


@lru_cache(maxsize=1)
def _env() -> Environment:
    return Environment(loader=FileSystemLoader(TEMPLATES), autoescape=True, undefined=StrictUndefined,
                       trim_blocks=True, lstrip_blocks=True)


@lru_cache(maxsize=1)
def _assets() -> tuple[Markup, Markup]:
    """The pages' style sheet and navigation script, inlined in every page (the pages work without the script)."""
    return (Markup((TEMPLATES / "style.css").read_text(encoding="utf-8")),
            Markup((TEMPLATES / "nav.js").read_text(encoding="utf-8")))


def _render(template: str, /, **context) -> str:
    return _env().get_template(template).render(**context)


_CLASS = {"met": "v-met", "not met": "v-not-met", "inconclusive": "v-inconclusive",
          "not attainable": "v-not-attainable", "not judgeable": "v-not-judgeable"}
_ORDER = VERDICTS


# -- values --------------------------------------------------------------------------------------------------

def _esc(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _is_scalar(v: Any) -> bool:
    return not isinstance(v, (Mapping, list, tuple, np.ndarray))


def format_value(v: Any) -> str:
    """A number or other scalar as short readable text (not escaped).

    Floats get 4 significant digits (whole numbers up to 10^7 in full), ``None`` reads ``n/a``.
    """
    if isinstance(v, np.generic):
        v = v.item()
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if v == int(v) and abs(v) < 1e7:
            return str(int(v))
        if 1e4 <= abs(v) < 1e7:
            return f"{v:.0f}"
        return f"{v:.4g}"
    return str(v)


def human_value(v: Any, depth: int = 0) -> str:
    """HTML for any published or table value: mappings as ``A 332 · B 291`` or a small nested table,
    sequences joined by commas, numbers formatted by :func:`format_value`; never a Python repr."""
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, Mapping):
        if not v:
            return "n/a"
        if all(_is_scalar(x) for x in v.values()):
            pairs = [f"{k} {format_value(x)}" for k, x in v.items()]
            if len(" · ".join(pairs)) <= 90 or depth > 2:
                return " · ".join(f"<span class='kv'>{_esc(t)}</span>" for t in pairs)
        rows = "".join(f"<tr><th>{_esc(k)}</th><td>{human_value(x, depth + 1)}</td></tr>" for k, x in v.items())
        return f"<table class='nested'>{rows}</table>"
    if isinstance(v, (list, tuple)):
        if not v:
            return "n/a"
        if all(_is_scalar(x) for x in v):
            return _esc(", ".join(format_value(x) for x in v))
        return "<br>".join(human_value(x, depth + 1) for x in v)
    return _esc(format_value(v))


_NUMERIC = re.compile(r"^[-+\u2212]?(\d[\d,]*(\.\d*)?|\.\d+)(e[-+]?\d+)?\s*(%|x|/\s*\d+|\u00b1\s*\S+)?$", re.I)


def is_numeric_like(v: Any) -> bool:
    """True for numbers and for text that reads as one (``"12.5"``, ``"3/20"``, ``"61.0 %"``, ``"nan"``)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    if isinstance(v, str):
        s = v.strip()
        return bool(_NUMERIC.match(s)) or s.lower() in ("nan", "inf", "-inf", "n/a")
    return False


def _blank(v: Any) -> bool:
    """No value: ``None``, empty text, or a dash standing for 'not applicable'."""
    return v is None or (isinstance(v, str) and v.strip() in ("", "-", "\u2013", "\u2014"))


def _numeric_columns(rows, ncols: int) -> list[bool]:
    """Per column: True when every non-blank value is numeric-like (and at least one is a real number)."""
    out = []
    for j in range(ncols):
        vals = [r[j] for r in rows if j < len(r) and not _blank(r[j])]
        real = [v for v in vals if not (isinstance(v, str) and v.strip().lower() == "n/a")]
        out.append(bool(real) and all(is_numeric_like(v) for v in vals))
    return out


class _Span(str):
    """HTML for a cell that spans ``n`` columns (the cells it covers are skipped)."""

    def __new__(cls, text: str, n: int):
        obj = super().__new__(cls, text)
        obj.n = n
        return obj


def _table(columns, rows, *, cls: str = "", row_classes=None, html_cells=None, numeric=None) -> Markup:
    """A table (rendered by ``templates/table.html``); ``html_cells[i][j]`` (when given and not None) is used as is
    instead of ``rows[i][j]``.

    A :class:`_Span` html cell spans its number of columns.
    """
    numeric = numeric if numeric is not None else _numeric_columns(rows, len(columns))
    num = lambda j: j < len(numeric) and bool(numeric[j])  # noqa: E731
    head = [(str(c), num(j)) for j, c in enumerate(columns)]
    body = []
    for i, row in enumerate(rows):
        cells, skip = [], 0
        for j, v in enumerate(row):
            if skip:
                skip -= 1
                continue
            given = html_cells[i][j] if html_cells is not None else None
            if isinstance(given, _Span):
                cells.append((Markup(str(given)), False, given.n))
                skip = given.n - 1
                continue
            cells.append((Markup(given if given is not None else human_value(v)), num(j), 0))
        body.append((row_classes[i] if row_classes else "", cells))
    if len(columns) >= 9:
        cls = f"{cls} dense".strip()
    return _env().get_template("table.html").module.table(head, body, cls)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "-", str(text)).strip("-") or "x"


def _anchor(paper, kind: str = "", item: str = "") -> str:
    base = f"paper{_slug(paper)}"
    return "-".join(x for x in (base, kind, _slug(item) if item else "") if x)


def _badge(verdict: str) -> str:
    return f"<span class='badge {_CLASS.get(verdict, '')}'>{_esc(verdict)}</span>"


def _png_size(data: bytes) -> tuple[int, int] | None:
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24:
        return struct.unpack(">II", data[16:24])
    return None


def _rel(path, out: Path) -> str:
    """``path`` as a link from a page in ``out`` (relative, forward slashes, URL-quoted)."""
    path, out = Path(path), Path(out)
    try:
        rel = path.relative_to(out).as_posix()
    except ValueError:
        try:
            rel = Path(os.path.relpath(path.resolve(), out.resolve())).as_posix()
        except ValueError:  # e.g. another drive: no relative link can be written
            return path.resolve().as_uri()
    return quote(rel)


def page_name(paper) -> str:
    """The file name of a paper's page in the report folder, e.g. ``paper-003.html``."""
    return f"paper-{_slug(paper)}.html"


def _docs_page(paper: str) -> Path | None:
    """The repository's ``docs/paperNNN.md`` for ``paper``, when this checkout has it."""
    page = Path(__file__).resolve().parents[2] / "docs" / f"paper{paper}.md"
    return page if page.is_file() else None


def _tally(criteria) -> dict[str, int]:
    counts = {v: 0 for v in _ORDER}
    for c in criteria:
        counts[c.verdict] = counts.get(c.verdict, 0) + 1
    return counts


# -- sections ------------------------------------------------------------------------------------------------

def published_number(v: Any) -> float | int | None:
    """The published value of the statistic a criterion judges, when the record gives one: a number.

    :class:`workbench.criteria.Criterion` declares ``published`` as the paper's value beside ours, so a number there
    is the same statistic as ``ours``, in its units.  Anything else (text such as ``"78 %"`` or a claim in words,
    a mapping of the paper's raw numbers) is not a value of that statistic: :func:`paper_claim` gives it its own
    column.  Nothing is converted or inferred from the text.
    """
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return v


def paper_claim(v: Any) -> Any:
    """The paper's own numbers or claim behind a criterion, when ``published`` is not a number (else ``None``)."""
    if published_number(v) is not None or _blank(v):
        return None
    if isinstance(v, (Mapping, list, tuple, np.ndarray)) and len(v) == 0:
        return None
    return v


def _scoreboard(p) -> Markup:
    crit = list(p.criteria)
    if not crit:
        return Markup("<p class='meta'>This recipe declares no criteria.</p>")
    with_rep = any(c.replication is not None for c in crit)
    with_conf = any(c.confirmation is not None for c in crit)
    with_claim = any(paper_claim(c.published) is not None for c in crit)
    # ours and published: the same statistic; the paper's numbers of another quantity (or its words) apart
    columns = ["id", "criterion", "verdict", "ours", "published", "n", "95 % interval", "threshold"]
    if with_claim:
        columns.append("the paper's own numbers or claim")
    if with_rep:
        columns.append("paper's protocol, replicated")
    if with_conf:
        columns.append("confirmation")
    rows, cells, classes = [], [], []
    for c in crit:
        interval = None
        if c.interval is not None and not any(math.isnan(v) for v in c.interval):
            interval = f"[{format_value(c.interval[0])}, {format_value(c.interval[1])}]"
        verdict = _badge(c.verdict)
        failed = c.failed_preconditions
        if failed:
            verdict += f"<div class='would'>failed: {_esc(', '.join(p.name for p in failed))}</div>"
            if c.verdict_if_judged:
                verdict += f"<div class='would'>numbers alone: {_esc(c.verdict_if_judged)}</div>"
        if c.indicative:
            verdict += "<br><span class='ind'>indicative (quick run)</span>"
            if c.quick_verdict == "met":
                verdict += "<div class='would'>quick-run numbers pass</div>"
        # the record's fields fill the columns (n and the runs needed, the interval and its method, the threshold);
        # its detail is the explanation in words
        method, min_n = c.method, c.min_n
        statement = _esc(c.text) + (f"<div class='detail'>{_esc(c.detail)}</div>" if c.detail else "")
        statement += "".join(
            f"<div class='pre {'ok' if p.holds else 'fail'}'>precondition {'holds' if p.holds else 'fails'}: "
            f"{_esc(p.name)}{f' ({_esc(p.detail)})' if p.detail else ''}</div>"
            for p in c.preconditions)
        row = [c.id, c.text, c.verdict, c.ours, published_number(c.published), c.n, interval, c.threshold or None]
        n_cell = None
        if min_n is not None and c.n is not None:
            n_cell = f"{_esc(format_value(c.n))}<div class='detail'>needs &ge; {_esc(min_n)}</div>"
        interval_cell = _esc(interval) if interval else "n/a"
        if method and interval:
            interval_cell += f"<div class='detail'>{_esc(method)}</div>"
        cell = [None, statement, verdict, None, None, n_cell, interval_cell,
                _esc(c.threshold) if c.threshold else "n/a"]
        if with_claim:
            row.append(paper_claim(c.published))
            cell.append(None)
        if with_rep:
            row.append(None if c.replication is None else f"{c.replication[0]}/{c.replication[1]}")
            cell.append("n/a" if c.replication is None else
                        f"holds in {c.replication[0]} of {c.replication[1]}")
        if with_conf:
            text, html = _confirmation_cell(c.confirmation)
            row.append(text)
            cell.append(html)
        if all(x is None for x in row[3:]) and not c.threshold:  # a pass/fail check without statistics
            cell[3] = _Span("n/a: a pass/fail check with no sample size, interval or threshold recorded; "
                            "its numbers are in the detail", len(row) - 3)
        rows.append(row)
        cells.append(cell)
        classes.append("row-" + _CLASS.get(c.verdict, "")[2:])
    numeric = _numeric_columns(rows, len(columns))
    for j, name in enumerate(columns):
        if name in ("id", "criterion", "verdict", "the paper's own numbers or claim", "paper's protocol, replicated",
                    "confirmation"):
            numeric[j] = False
        elif name == "95 % interval":
            numeric[j] = True  # the interval reads as numbers
        elif name == "published":
            numeric[j] = True  # numbers only (or n/a)
    return _table(columns, rows, cls="scoreboard", row_classes=classes, html_cells=cells, numeric=numeric)


def _confirmation_cell(record) -> tuple[str | None, str]:
    """The scoreboard's confirmation cell: whether the verdict on the confirmation seed agrees, with that verdict,
    ours and the interval there (text, html)."""
    if record is None:
        return None, "n/a: not run"
    if record.verdict is None:
        return record.text(), f"<div class='would'>no verdict on seed {_esc(record.seed)}</div>" \
                              f"<div class='detail'>{_esc(record.detail)}</div>"
    head = "agrees" if record.agrees else "DIFFERS"
    # the verdict in words, not as a badge: the scoreboard's badges are the reported seed's verdicts
    cell = f"<b>{head}</b> (seed {_esc(record.seed)}): <i>{_esc(record.verdict)}</i>"
    if record.failed:
        cell += f"<div class='would'>failed: {_esc(', '.join(record.failed))}</div>"
    cell += _numbers_line(record)
    return record.text(), cell


def _numbers_line(record) -> str:
    """A verdict record's value, interval and n as one detail line (empty where it has none)."""
    nums = []
    if isinstance(record.ours, (int, float)) and not isinstance(record.ours, bool):
        nums.append(format_value(record.ours))
    if record.interval is not None and not any(math.isnan(v) for v in record.interval):
        nums.append(f"[{format_value(record.interval[0])}, {format_value(record.interval[1])}]")
    if record.n is not None:
        nums.append(f"n = {format_value(record.n)}")
    return f"<div class='detail'>{_esc(' '.join(nums))}</div>" if nums else ""


def _confirmation_summary(p) -> tuple[str, str]:
    """The at-a-glance cell: how many verdicts the confirmation seed agrees with, and which differ (text, html)."""
    records = [(c.id, c.confirmation) for c in p.criteria if c.confirmation is not None]
    if not records:
        why = "off (quick run)" if p.size != "full" else "not run"
        return why, _esc(why)
    seed = records[0][1].seed
    judged = [(i, r) for i, r in records if r.verdict is not None]
    agree = sum(1 for _, r in judged if r.agrees)
    text = f"seed {seed}: {agree} of {len(records)} agree"
    differ = [f"{i}: {r.primary} -> {r.verdict}" for i, r in judged if not r.agrees]
    none = [str(i) for i, r in records if r.verdict is None]
    if differ:
        text += "; differ: " + ", ".join(differ)
    if none:
        text += "; no verdict: " + ", ".join(none)
    return text, _esc(text)


def _verdict_at(record) -> str:
    """One grid value's verdict cell: the badge, the failed preconditions, ours and the interval."""
    cell = _badge(record.verdict)
    if record.failed:
        cell += f"<div class='would'>failed: {_esc(', '.join(record.failed))}</div>"
    if record.indicative and record.quick_verdict == "met":
        cell += "<div class='would'>quick-run numbers pass</div>"
    cell += _numbers_line(record)
    if record.detail:
        cell += f"<div class='detail'>{_esc(record.detail)}</div>"
    return cell


def _unknowns(p) -> Markup:
    """The declared unknowns of a paper (name, unit, primary, grid, why) and, per criterion that hinges on one,
    its verdict at the primary values beside its verdict at every grid value and where it holds."""
    unknowns = list(getattr(p, "unknowns", None) or ())
    if not unknowns:
        return Markup("")
    declared = _table(["unknown", "unit", "primary", "grid", "why (and where the primary came from)"],
                      [(u.name, u.unit or "-", format_value(u.primary), ", ".join(format_value(v) for v in u.grid),
                        u.why) for u in unknowns],
                      numeric=[False, False, True, False, False])
    blocks = []
    for u in unknowns:
        crit = [c for c in p.criteria if any(a.unknown == u.name for a in c.across)]
        if not crit:
            blocks.append({"name": u.name, "table": None})
            continue
        columns = ["id", "verdict at the primary values",
                   *(f"{u.name} = {format_value(v)}" + (" (primary)" if v == u.primary else "") for v in u.grid),
                   f"where it holds across {u.name}"]
        notes = {a.detail for c in crit for a in c.across if a.unknown == u.name}
        shared = notes.pop() if len(notes) == 1 else None  # one note for every cell: said once, under the table
        rows, cells = [], []
        for c in crit:
            at = {a.value: a for a in c.across if a.unknown == u.name}
            if shared is not None:
                at = {v: replace(a, detail="") for v, a in at.items()}
            line = where_it_holds(c.across, u.name)
            rows.append([c.id, c.verdict, *(at[v].verdict if v in at else None for v in u.grid), line])
            cells.append([None, _badge(c.verdict), *(_verdict_at(at[v]) if v in at else "n/a: not judged"
                                                     for v in u.grid), f"<b>{_esc(line)}</b>"])
        blocks.append({"name": u.name, "unit": u.unit or "no unit", "shared": shared,
                       "table": _table(columns, rows, cls="scoreboard", html_cells=cells,
                                       numeric=[False] * len(columns))})
    return Markup(_render("unknowns.html", anchor=_anchor(p.paper, "unknowns"), declared=declared, blocks=blocks))


def _not_judgeable_cell(criteria) -> tuple[str | None, str]:
    """The at-a-glance cell of a paper's criteria that are not judgeable: per failed precondition, the criteria ids
    (text, html); ``(None, "n/a")`` when every criterion could be judged."""
    by_name: dict[str, list[str]] = {}
    for c in criteria:
        for p in c.failed_preconditions:
            by_name.setdefault(p.name, []).append(str(c.id))
    if not by_name:
        return None, "n/a"
    text = "; ".join(f"{name}: {', '.join(ids)}" for name, ids in by_name.items())
    return text, "<br>".join(f"<b>{_esc(name)}</b> fails for {_esc(', '.join(ids))}" for name, ids in by_name.items())


def _nav_tally(criteria) -> str:
    counts = _tally(criteria)
    parts = [f"<span class='pill {_CLASS[v]}'>{n} {_esc(v)}</span>" for v, n in counts.items() if n]
    if parts and any(c.indicative for c in criteria):
        parts.append("<span class='pill ind'>indicative</span>")
    return "".join(parts) if parts else "<span class='pill'>no criteria</span>"


def _differs(p, out: Path) -> Markup:
    """The paper's "what differs" part: the recipe's notes and a link to the repository's docs page, when there."""
    context = {"anchor": _anchor(p.paper, "differs"), "notes": (p.notes or "").strip(), "link": None, "path": None,
               "name": None}
    page = _docs_page(p.paper)
    if page is not None:
        context["name"] = page.name
        try:
            context["link"] = quote(os.path.relpath(page, Path(out).resolve()).replace(os.sep, "/"))
        except ValueError:  # e.g. another drive: no relative link can be written
            context["path"] = str(page)
    return Markup(_render("differs.html", **context))


def _figure(p, f, out: Path) -> dict:
    """A figure of the paper's page: its PNG file linked beside the page (with its width and height), the caption and
    links to the SVG and the data behind it."""
    links = []
    for label, key in (("SVG", "svg"), ("data NPZ", "data")):
        if f.get(key) is not None:
            links.append((label, _rel(f[key], out)))
    if f.get("data") is not None:
        links.append(("data CSV", _rel(Path(f["data"]).with_suffix(".csv"), out)))
    fig = {"anchor": _anchor(p.paper, "fig", f["id"]), "name": f["id"], "caption": f["caption"], "links": links,
           "src": None, "width": None, "height": None, "error": None}
    try:
        with open(f["png"], "rb") as fh:
            size = _png_size(fh.read(24))
    except (OSError, TypeError) as exc:
        fig["error"] = f"{type(exc).__name__}: {f['png']}"
        return fig
    fig["src"] = _rel(f["png"], out)
    if size:
        fig["width"], fig["height"] = size
    return fig


def _paper_page(p, out: Path, nav: dict) -> str:
    """The paper's page: scoreboard first, then unknowns, what differs, figures, tables, published values and the
    time table."""
    tables = [{"anchor": _anchor(p.paper, "table", t["id"]), "name": t["id"], "caption": t["caption"],
               "html": _table(t["columns"], t["rows"]),
               "csv": _rel(t["csv"], out) if t.get("csv") is not None else None} for t in p.tables]
    published = None
    if p.published:
        items = list(p.published.items())
        numeric = [False, _numeric_columns([[v] for _, v in items], 1)[0]]
        published = _table(["item", "published"], items, numeric=numeric)
    style, script = _assets()
    return _render("paper.html", style=style, script=script, nav=nav, p=p, anchor=_anchor(p.paper),
                   filters=", ".join(p.filters) or "-", seconds=f"{p.seconds:.1f}",
                   indicative=any(c.indicative for c in p.criteria), criteria=bool(p.criteria),
                   claims=any(paper_claim(c.published) is not None for c in p.criteria),
                   scoreboard=_scoreboard(p), unknowns=_unknowns(p), differs=_differs(p, out),
                   figures=[_figure(p, f, out) for f in p.figures], tables=tables, published=published,
                   tasks=_time_table(p))


def _time_table(p) -> Markup:
    """The paper's time table, collapsed: each task (reported seed, unknowns' grid points, confirmation seed) with
    its runs, seconds, share of the paper's task compute and whether it was computed, cached, reused or failed."""
    table = paper_time_table(p)
    counts = table["counts"]
    errors = {str(t.get("key")): t.get("error", "") for t in p.tasks}
    done = ", ".join(f"{n} {st}" for st, n in counts.items() if n) or "no task"
    other = "; ".join(f"{k} {v:.1f} s" for k, v in table["other_seconds"].items())
    head = (f"Time per task: {len(table['rows'])} tasks ({done}), {table['computed_seconds']:.1f} s of task compute"
            f"{'; outside the tasks: ' + other if other else ''}")
    rows = [(r["task"], "-" if r["runs"] is None else r["runs"], round(r["seconds"], 2),
             f"{r['share_percent']:.2f} %", r["status"], errors.get(r["task"], "")) for r in table["rows"]]
    tasks = _table(["task", "runs", "seconds", "share of the paper's compute", "status", "error"], rows,
                   numeric=[False, True, True, True, False, False])
    items = (_table(["figure or table (outside the tasks)", "seconds", "parts"],
                    [(i["what"], round(i["seconds"], 2),
                      ", ".join(f"{k} {v:.2f} s" for k, v in i["parts"].items())) for i in table["items"]],
                    numeric=[False, True, False]) if table["items"] else "")
    return Markup(_render("tasks.html", anchor=_anchor(p.paper, "tasks"), head=head, tasks=tasks, items=items))


def _nav(papers, here=None) -> dict:
    """The side navigation of a page: the index's parts, every paper (with its verdicts counted) and, for the paper
    whose page it is (``here``), each part of that page as an in-page link."""
    on_index = here is None
    home = "#top" if on_index else "index.html"
    entries = []
    for p in papers:
        current = here is not None and p.paper == here.paper
        page = "" if current else page_name(p.paper)
        items = []
        if current:
            items.append({"href": f"{page}#{_anchor(p.paper, 'scoreboard')}", "text": "Scoreboard"})
            if getattr(p, "unknowns", None):
                items.append({"href": f"{page}#{_anchor(p.paper, 'unknowns')}", "text": "Declared unknowns"})
            items.append({"href": f"{page}#{_anchor(p.paper, 'differs')}", "text": "What differs"})
            if p.figures:
                items.append({"group": "Figures"})
                items += [{"href": f"{page}#{_anchor(p.paper, 'fig', f['id'])}", "title": f["caption"],
                           "text": f["id"]} for f in p.figures]
            if p.tables:
                items.append({"group": "Tables"})
                items += [{"href": f"{page}#{_anchor(p.paper, 'table', t['id'])}", "title": t["caption"],
                           "text": t["id"]} for t in p.tables]
            if p.published:
                items.append({"href": f"{page}#{_anchor(p.paper, 'published')}", "text": "Published values"})
            items.append({"href": f"{page}#{_anchor(p.paper, 'tasks')}", "text": "Time per task"})
        items = [{"group": None, "title": None, "href": None, "text": None, **x} for x in items]
        entries.append({"paper": p.paper, "title": p.title, "current": current, "parts": items,
                        "href": f"#{_anchor(p.paper)}" if current else page_name(p.paper),
                        "tally": Markup(_nav_tally(p.criteria))})
    return {"home": home, "overview": "#overview" if on_index else "index.html#overview",
            "provenance": "#provenance" if on_index else "index.html#provenance", "papers": entries}


def _overview(papers) -> Markup:
    rows, cells = [], []
    for p in papers:
        counts = _tally(p.criteria)
        why, why_html = _not_judgeable_cell(p.criteria)
        conf, conf_html = _confirmation_summary(p)
        # the failed preconditions and the confirmation seed's agreement share one text column (the table must fit
        # the page's content column beside the navigation)
        rows.append([p.paper, p.title, p.size, *(counts[v] for v in _ORDER), f"{why or 'n/a'}; confirmation seed: {conf}",
                     len(p.errors)])
        cells.append([f"<a href='{_esc(page_name(p.paper))}'>{_esc(p.paper)}</a>",
                      f"<a href='{_esc(page_name(p.paper))}#{_anchor(p.paper, 'scoreboard')}'>{_esc(p.title)}</a>",
                      None,
                      *(f"<span class='badge {_CLASS[v]}'>{counts[v]}</span>" if counts[v] else "0" for v in _ORDER),
                      f"{why_html}<div class='detail'>confirmation seed: {conf_html}</div>", None])
    columns = ["paper", "title", "size", *_ORDER, "not judgeable: failed precondition; confirmation seed",
               "problems"]
    numeric = [False, False, False, *(True for _ in _ORDER), False, True]
    return _table(columns, rows, html_cells=cells, numeric=numeric)


def _provenance(report, host: PluginHost) -> list[tuple[str, str]]:
    versions = distribution_versions()
    rows = [
        ("command", report.command or "(library call)"),
        ("seed", str(report.seed)),
        ("confirmation seed", ", ".join(sorted({str(p.confirmation_seed) for p in report.papers
                                                if getattr(p, "confirmation_seed", None) is not None}))
         or "none (quick run: the confirmation seed runs with --full)"),
        ("size", report.size),
        ("wall time", f"{report.seconds:.1f} s"),
        ("finished", datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")),
        ("python", platform.python_version()),
        ("machine", f"{platform.machine()} {platform.system()}"),
    ]
    for p in getattr(report, "saved", []):
        rows.append((f"paper {p.paper}", f"kept from an earlier run: {p.command or '(library call)'}, size {p.size}, "
                                         f"seed {p.seed}, finished {p.finished or 'unknown'}"))
    rows += [(f"package {k}", v) for k, v in versions.items()]
    rows += [(f"plugin {p.name}", f"{p.distribution} {p.version} ({p.status})") for p in host.plugins]
    return rows


def _papers(report) -> list:
    return list(getattr(report, "all_papers", report.papers))


_PAGE = re.compile(r"^paper-[A-Za-z0-9_-]+\.html$")


def write_index(report, host: PluginHost) -> None:
    """Write the report's pages (atomically): one page per paper of the report folder (:func:`page_name`), then
    ``report.out/index.html``; a paper page of a paper no longer in the folder is removed."""
    papers = _papers(report)
    out = Path(report.out)
    written = set()
    for p in papers:
        name = page_name(p.paper)
        write_text_atomic(out / name, _paper_page(p, out, _nav(papers, here=p)))
        written.add(name)
    style, script = _assets()
    write_text_atomic(out / "index.html", _render(
        "index.html", style=style, script=script, nav=_nav(papers),
        warnings=list(getattr(report, "warnings", [])),
        quick=any(c.indicative for p in papers for c in p.criteria), overview=_overview(papers),
        provenance=_table(["what", "value"], _provenance(report, host), numeric=[False, False]),
        pages={_anchor(p.paper): page_name(p.paper) for p in papers}))
    for stale in out.glob("paper-*.html"):
        if _PAGE.match(stale.name) and stale.name not in written:
            stale.unlink(missing_ok=True)


def _criterion_summary(c) -> dict:
    d = c.to_dict()
    d["statement"] = c.text
    names = list(dict.fromkeys(a.unknown for a in c.across))
    d["where_it_holds"] = {name: where_it_holds(c.across, name) for name in names}
    return d


def write_summary(report, host: PluginHost) -> None:
    """Write ``report.out/summary.json`` (atomically): every paper's criteria, tables, figures and tasks.

    Each paper carries ``task_times`` (:func:`workbench.report.tables.paper_time_table`: every task's runs,
    seconds, share of the paper's task compute and status).  Each criterion carries ``id, statement (and text),
    ours, published, n, interval, threshold, verdict, indicative, met`` (bool, for older readers), ``replication``,
    the rest of its numbers as fields (``min_n, method, level, count, resamples``), ``statistics`` (the sentence
    :attr:`~workbench.criteria.Criterion.statistics` makes of them), ``detail`` (the explanation in words), ``extra``
    and ``preconditions`` (each ``name, holds, detail, values``); a paper kept from an earlier run into the folder has
    ``from_saved: true``.
    """
    summary = {
        "command": report.command,
        "seed": report.seed,
        "size": report.size,
        "seconds": report.seconds,
        "versions": distribution_versions(),
        "warnings": list(getattr(report, "warnings", [])),
        "plugins": [{"name": p.name, "distribution": p.distribution, "version": p.version, "status": p.status,
                     "error": p.error} for p in host.plugins],
        "papers": [{
            "paper": p.paper, "title": p.title, "size": p.size, "seed": p.seed, "filters": list(p.filters),
            "seconds": p.seconds, "finished": p.finished, "from_saved": bool(p.saved), "errors": p.errors,
            "criteria": [_criterion_summary(c) for c in p.criteria],
            "unknowns": [u.to_dict() for u in getattr(p, "unknowns", None) or ()],
            "tables": [{"id": t["id"], "columns": t["columns"], "rows": t["rows"]} for t in p.tables],
            "figures": [f["id"] for f in p.figures],
            "published": p.published,
            "tasks": [{k: v for k, v in t.items() if k != "traceback"} for t in p.tasks],
            "task_times": paper_time_table(p),
        } for p in _papers(report)],
    }
    # strict JSON: NaN and infinities become null, so any JSON reader takes the file
    write_text_atomic(Path(report.out) / "summary.json",
                      json.dumps(_jsonable(summary, strict=True), indent=2, allow_nan=False))
