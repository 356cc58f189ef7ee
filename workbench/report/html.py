"""Write the report's ``index.html`` (self-contained: figures embedded) and ``summary.json``.

The page has a fixed side navigation (each paper, and under it its scoreboard, tables and figures, then
the provenance) and, per paper, a scoreboard first: each criterion's verdict, ours beside published, the
number of runs, the 95 % interval and the threshold.  Published values are shown as readable text or small
tables, never as Python reprs; a table's column is right-aligned when all its values are numbers and
left-aligned otherwise.  Both files show every paper of the report folder (see
:func:`workbench.report.engine.run_report`) and are written atomically.
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
import platform
import re
import struct
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..criteria import VERDICTS, where_it_holds
from ..plugins import PluginHost
from .cache import distribution_versions, write_text_atomic

__all__ = ["write_index", "write_summary", "format_value", "human_value", "is_numeric_like"]

_STYLE = """
:root{--nav:16.5rem;--ink:#1d2329;--muted:#5b6570;--line:#d5dae0;--head:#eef1f4;--link:#1a4f8b}
*{box-sizing:border-box}
html{scroll-padding-top:.8rem}
body{margin:0;font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:var(--ink);
  line-height:1.45;background:#fff}
a{color:var(--link)}
nav#nav{position:fixed;top:0;left:0;bottom:0;width:var(--nav);overflow-y:auto;background:#f4f6f8;
  border-right:1px solid var(--line);padding:1rem .7rem 2rem;font-size:.84rem}
nav#nav .brand{font-weight:700;font-size:1rem;margin:0 .3rem .6rem}
nav#nav .brand a{color:var(--ink);text-decoration:none}
nav#nav ul{list-style:none;margin:0;padding:0}
nav#nav li{margin:0}
nav#nav a{display:block;padding:.12rem .35rem;border-radius:4px;text-decoration:none;white-space:nowrap;
  overflow:hidden;text-overflow:ellipsis}
nav#nav a:hover{background:#e1e7ee}
nav#nav a.here{background:#dbe5f1;color:#0b2f57;font-weight:600}
nav#nav .paper>a{font-weight:650;margin-top:.55rem;color:var(--ink)}
nav#nav .paper>a small{font-weight:400;color:var(--muted)}
nav#nav .sub{padding-left:.7rem;border-left:2px solid var(--line);margin:.1rem 0 .2rem .45rem}
nav#nav .group{color:var(--muted);font-size:.74rem;text-transform:uppercase;letter-spacing:.04em;
  padding:.3rem .35rem 0}
nav#nav .tally{display:block;padding:0 .35rem .15rem}
.pill{display:inline-block;border-radius:3px;padding:0 .3rem;margin:0 .2rem .1rem 0;font-size:.7rem;
  font-weight:600;white-space:nowrap;border:1px solid transparent}
main{margin-left:var(--nav);padding:1.4rem 2rem 4rem;max-width:calc(var(--nav) + 72rem)}
h1{font-size:1.7rem;margin:.2rem 0 .4rem}
h2{font-size:1.35rem;margin:2.6rem 0 .3rem;padding-top:.6rem;border-top:3px solid var(--ink)}
h3{font-size:1.08rem;margin:1.6rem 0 .4rem}
.meta{color:var(--muted);font-size:.9rem;margin:.2rem 0 .8rem}
.callout{border-left:4px solid #c99a06;background:#fff8e1;padding:.5rem .8rem;margin:.8rem 0;font-size:.92rem}
.callout.bad{border-color:#b42318;background:#fdecea}
.err{color:#a00}
.tablewrap{max-width:100%;overflow-x:auto}
table{border-collapse:collapse;margin:.4rem 0 1rem;font-size:.86rem;max-width:100%}
th,td{border:1px solid var(--line);padding:.28rem .55rem;text-align:left;vertical-align:top;
  overflow-wrap:break-word}
.kv{white-space:nowrap}
th{background:var(--head);font-weight:600}
th.num,td.num{text-align:right;font-variant-numeric:tabular-nums}
td.num{white-space:nowrap;overflow-wrap:normal}
table.dense{font-size:.78rem}
table.dense th,table.dense td{padding:.2rem .35rem}
table.nested{margin:0;font-size:1em}
table.nested th,table.nested td{padding:.1rem .4rem;border-color:#e3e6ea}
table.nested th{background:#f6f7f9;font-weight:500}
table.scoreboard{width:100%}
table.scoreboard td.statement{min-width:14rem}
table.scoreboard td.na{color:var(--muted);font-size:.8rem;font-style:italic}
table.scoreboard .detail{color:var(--muted);font-size:.82rem;margin-top:.15rem}
table.scoreboard td.num .detail{white-space:normal;text-align:right}
.badge{display:inline-block;border-radius:999px;padding:.05rem .55rem;font-weight:650;font-size:.8rem;
  white-space:nowrap;border:1px solid transparent}
.v-met{background:#dcf2e1;color:#17612b;border-color:#8fcf9f}
.v-not-met{background:#fbe1e0;color:#9b1c1c;border-color:#eba7a3}
.v-inconclusive{background:#fff1c9;color:#6e4e00;border-color:#e9cf79}
.v-not-attainable{background:#e7e8ee;color:#464a5c;border-color:#c3c6d2}
.v-not-judgeable{background:#f3e6f5;color:#6a2a73;border-color:#cfa6d6}
tr.row-met>td:first-child{box-shadow:inset 4px 0 #2e8b4a}
tr.row-not-met>td:first-child{box-shadow:inset 4px 0 #c0392b}
tr.row-inconclusive>td:first-child{box-shadow:inset 4px 0 #d4a20a}
tr.row-not-attainable>td:first-child{box-shadow:inset 4px 0 #7c8196}
tr.row-not-judgeable>td:first-child{box-shadow:inset 4px 0 #8e44ad}
table.scoreboard .pre{font-size:.8rem;margin-top:.2rem}
table.scoreboard .pre.fail{color:#6a2a73;font-weight:600}
table.scoreboard .pre.ok{color:var(--muted)}
.ind{display:inline-block;margin-top:.2rem;font-size:.74rem;color:#6e4e00;border:1px dashed #d4a20a;
  border-radius:4px;padding:0 .3rem;white-space:nowrap}
.would{font-size:.76rem;color:var(--muted);margin-top:.15rem}
.tally .badge{margin-right:.25rem}
.notes{white-space:pre-wrap;font-family:ui-monospace,SFMono-Regular,Menlo,monospace;font-size:.8rem;
  background:#f7f8fa;border:1px solid var(--line);border-radius:4px;padding:.6rem .8rem;margin:.3rem 0 .6rem;
  max-height:28rem;overflow-y:auto}
figure{margin:1rem 0 2rem}
figure img{max-width:100%;height:auto;display:block;border:1px solid #eceff2}
figcaption{font-size:.88rem;color:#3b4450;margin-top:.3rem}
code{background:#f1f3f5;padding:.05em .3em;border-radius:3px}
details{margin:.5rem 0}
summary{cursor:pointer;color:var(--link)}
@media (max-width:1200px){
  :root{--nav:13rem}
  main{padding:1.2rem 1.2rem 3rem}
  .ind{white-space:normal}
}
@media (max-width:900px){
  nav#nav{position:static;width:auto;border-right:0;border-bottom:1px solid var(--line)}
  main{margin-left:0;padding:1rem}
}
"""

# Highlights, in the side navigation, the part of the page being read (the page works without it).
_SCRIPT = """
(() => {
  const nav = document.getElementById('nav');
  const targets = [...nav.querySelectorAll('a[href^="#"]')]
    .map(a => [a, document.getElementById(a.getAttribute('href').slice(1))]).filter(([a, el]) => el && el.id !== 'top');
  let pending = false;
  const update = () => {
    pending = false;
    // the last part whose top has reached the top of the window (any part in view at the very bottom)
    const bottom = innerHeight + scrollY >= document.documentElement.scrollHeight - 2;
    const line = bottom ? innerHeight - 40 : 100;
    let here = null;
    for (const [a, el] of targets) if (el.getBoundingClientRect().top <= line) here = a;
    nav.querySelectorAll('a.here').forEach(x => { if (x !== here) x.classList.remove('here'); });
    if (!here || here.classList.contains('here')) return;
    here.classList.add('here');
    if (here.offsetTop < nav.scrollTop || here.offsetTop > nav.scrollTop + nav.clientHeight - 30)
      nav.scrollTop = here.offsetTop - nav.clientHeight / 3;
  };
  const onScroll = () => { if (!pending) { pending = true; requestAnimationFrame(update); } };
  addEventListener('scroll', onScroll, {passive: true});
  update();
})();
"""

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


def _table(columns, rows, *, cls: str = "", row_classes=None, html_cells=None, numeric=None) -> str:
    """A table; ``html_cells[i][j]`` (when given and not None) is used as is instead of ``rows[i][j]``.

    A :class:`_Span` html cell spans its number of columns.
    """
    numeric = numeric if numeric is not None else _numeric_columns(rows, len(columns))
    num = lambda j: " class='num'" if j < len(numeric) and numeric[j] else ""  # noqa: E731
    head = "".join(f"<th{num(j)}>{_esc(c)}</th>" for j, c in enumerate(columns))
    body = []
    for i, row in enumerate(rows):
        rcls = f" class='{row_classes[i]}'" if row_classes else ""
        cells, skip = [], 0
        for j, v in enumerate(row):
            if skip:
                skip -= 1
                continue
            given = html_cells[i][j] if html_cells is not None else None
            if isinstance(given, _Span):
                cells.append(f"<td colspan='{given.n}' class='na'>{given}</td>")
                skip = given.n - 1
                continue
            cells.append(f"<td{num(j)}>{given if given is not None else human_value(v)}</td>")
        body.append(f"<tr{rcls}>{''.join(cells)}</tr>")
    if len(columns) >= 9:
        cls = f"{cls} dense".strip()
    c = f" class='{cls}'" if cls else ""
    return (f"<div class='tablewrap'><table{c}><thead><tr>{head}</tr></thead>"
            f"<tbody>{''.join(body)}</tbody></table></div>")


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
    try:
        return Path(path).relative_to(out).as_posix()
    except ValueError:
        return str(path)


def _docs_page(paper: str) -> Path | None:
    """The repository's ``docs/paperNNN.md`` for ``paper``, when this checkout has it."""
    page = Path(__file__).resolve().parents[2] / "docs" / f"paper{paper}.md"
    return page if page.is_file() else None


def _tally(criteria) -> dict[str, int]:
    counts = {v: 0 for v in _ORDER}
    for c in criteria:
        counts[c.verdict] = counts.get(c.verdict, 0) + 1
    return counts


def scoreboard_detail(c) -> tuple[str, str | None, int | None]:
    """A criterion's detail for the scoreboard: ``(explanation, how the interval was computed, runs needed)``.

    The scoreboard has columns for the numbers of the statistics sentence a criterion declares
    (``Criterion.statistics``: ours, the interval and its method, the passing condition, the runs needed), so that
    sentence is taken out of the detail (with a full stop right after it); ``method`` and ``min_n`` are the
    record's own fields.  A detail that does not contain the sentence (or a record without one) comes back whole;
    ``summary.json`` keeps every detail whole.
    """
    detail = c.detail or ""
    if not c.statistics or c.statistics not in detail:
        return detail, c.method, c.min_n
    before, _, after = detail.partition(c.statistics)
    after = after[1:] if after.startswith(".") else after
    text = (before.rstrip(" ;") + (" " if before.strip() and after.strip() else "") + after.lstrip(" ;")).strip()
    return text, c.method, c.min_n


# -- sections ------------------------------------------------------------------------------------------------

def _scoreboard(p) -> str:
    crit = list(p.criteria)
    if not crit:
        return "<p class='meta'>This recipe declares no criteria.</p>"
    with_rep = any(c.replication is not None for c in crit)
    with_conf = any(c.confirmation is not None for c in crit)
    columns = ["id", "criterion", "verdict", "ours", "published", "n", "95 % interval", "threshold"]
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
        explanation, method, min_n = scoreboard_detail(c)
        statement = _esc(c.text) + (f"<div class='detail'>{_esc(explanation)}</div>" if explanation else "")
        statement += "".join(
            f"<div class='pre {'ok' if p.holds else 'fail'}'>precondition {'holds' if p.holds else 'fails'}: "
            f"{_esc(p.name)}{f' ({_esc(p.detail)})' if p.detail else ''}</div>"
            for p in c.preconditions)
        row = [c.id, c.text, c.verdict, c.ours, c.published, c.n, interval, c.threshold or None]
        n_cell = None
        if min_n is not None and c.n is not None:
            n_cell = f"{_esc(format_value(c.n))}<div class='detail'>needs &ge; {_esc(min_n)}</div>"
        interval_cell = _esc(interval) if interval else "n/a"
        if method and interval:
            interval_cell += f"<div class='detail'>{_esc(method)}</div>"
        cell = [None, statement, verdict, None, None, n_cell, interval_cell,
                _esc(c.threshold) if c.threshold else "n/a"]
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
    numeric[0] = numeric[1] = numeric[2] = False
    numeric[6] = True  # the interval reads as numbers
    if with_rep:
        numeric[8] = False
    if with_conf:
        numeric[-1] = False
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


def _unknowns(p) -> str:
    """The declared unknowns of a paper (name, unit, primary, grid, why) and, per criterion that hinges on one,
    its verdict at the primary values beside its verdict at every grid value and where it holds."""
    unknowns = list(getattr(p, "unknowns", None) or ())
    if not unknowns:
        return ""
    parts = [f"<h3 id='{_anchor(p.paper, 'unknowns')}'>Declared unknowns: values the paper withholds</h3>",
             "<p class='meta'>Values the paper does not give, which this reproduction had to choose. The scoreboard's "
             "verdicts use the primary value; the criteria that hinge on an unknown are judged again at every grid "
             "value below.</p>"]
    parts.append(_table(["unknown", "unit", "primary", "grid", "why (and where the primary came from)"],
                        [(u.name, u.unit or "-", format_value(u.primary), ", ".join(format_value(v) for v in u.grid),
                          u.why) for u in unknowns],
                        numeric=[False, False, True, False, False]))
    for u in unknowns:
        crit = [c for c in p.criteria if any(a.unknown == u.name for a in c.across)]
        if not crit:
            parts.append(f"<p class='meta'>No criterion of this report was judged across {_esc(u.name)}.</p>")
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
        parts.append(f"<p class='meta'>Verdicts across {_esc(u.name)} ({_esc(u.unit or 'no unit')})"
                     + (f": {_esc(shared)}" if shared else "") + ".</p>")
        parts.append(_table(columns, rows, cls="scoreboard", html_cells=cells,
                            numeric=[False] * len(columns)))
    return "".join(parts)


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


def _differs(p, out: Path) -> str:
    parts = [f"<h3 id='{_anchor(p.paper, 'differs')}'>What differs from the paper and why</h3>"]
    if p.notes:
        parts.append("<p class='meta'>The choices this reproduction made where the paper is silent or where our "
                     "set-up differs from the paper's:</p>")
        parts.append(f"<div class='notes'>{_esc(p.notes.strip())}</div>")
    else:
        parts.append("<p class='meta'>The recipe records no choices of its own.</p>")
    page = _docs_page(p.paper)
    if page is not None:
        try:
            link = os.path.relpath(page, Path(out).resolve()).replace(os.sep, "/")
            parts.append(f"<p>The full discussion: <a href='{_esc(link)}'>docs/{_esc(page.name)}</a>.</p>")
        except ValueError:  # e.g. another drive: no relative link can be written
            parts.append(f"<p>The full discussion: <code>{_esc(page)}</code>.</p>")
    return "".join(parts)


def _figure(p, f, out: Path) -> str:
    fid = _anchor(p.paper, "fig", f["id"])
    links = []
    for label, key in (("SVG", "svg"), ("data NPZ", "data")):
        if f.get(key) is not None:
            links.append(f"<a href='{_esc(_rel(f[key], out))}'>{label}</a>")
    if f.get("data") is not None:
        links.append(f"<a href='{_esc(_rel(Path(f['data']).with_suffix('.csv'), out))}'>data CSV</a>")
    caption = (f"<figcaption><b>{_esc(f['id'])}</b>: {_esc(f['caption'])} "
               f"[{', '.join(links)}]</figcaption>")
    try:
        data = Path(f["png"]).read_bytes()
    except (OSError, TypeError) as exc:
        return (f"<figure id='{fid}'><p class='err'>Figure image missing ({_esc(type(exc).__name__)}: "
                f"{_esc(f['png'])}).</p>{caption}</figure>")
    size = _png_size(data)
    dims = f" width='{size[0]}' height='{size[1]}'" if size else ""
    png = base64.b64encode(data).decode()
    return (f"<figure id='{fid}'><img alt='{_esc(f['id'])}: {_esc(f['caption'])}'{dims} "
            f"src='data:image/png;base64,{png}'>{caption}</figure>")


def _paper_section(p, out: Path) -> str:
    parts = [f"<section id='{_anchor(p.paper)}'>",
             f"<h2>Paper {_esc(p.paper)}: {_esc(p.title)}</h2>"]
    meta = [f"size <b>{_esc(p.size)}</b>"]
    if p.seed is not None:
        meta.append(f"seed {_esc(p.seed)}")
    meta.append(f"filters {_esc(', '.join(p.filters) or '-')}")
    meta.append(f"{p.seconds:.1f} s")
    if p.finished:
        meta.append(f"finished {_esc(p.finished)}")
    parts.append(f"<p class='meta'>{' · '.join(meta)}</p>")
    if p.saved:
        parts.append("<p class='callout'>Kept from an earlier run into this folder (not re-run this time)"
                     + (f": <code>{_esc(p.command)}</code>" if p.command else "") + ".</p>")
    for err in p.errors:
        parts.append(f"<p class='err'>Not done: {_esc(err)}</p>")
    parts.append(f"<h3 id='{_anchor(p.paper, 'scoreboard')}'>Scoreboard: reproduced if</h3>")
    if any(c.indicative for c in p.criteria):
        parts.append("<p class='callout'>Quick run: every verdict below is an <b>indication</b> from a small "
                     "sample. None is declared <i>met</i>; run <code>workbench report --full</code> to decide.</p>")
    parts.append(_scoreboard(p))
    parts.append(_unknowns(p))
    parts.append(_differs(p, out))
    for t in p.tables:
        parts.append(f"<h3 id='{_anchor(p.paper, 'table', t['id'])}'>{_esc(t['id'])}: {_esc(t['caption'])}</h3>")
        parts.append(_table(t["columns"], t["rows"]))
        if t.get("csv") is not None:
            parts.append(f"<p class='meta'><a href='{_esc(_rel(t['csv'], out))}'>CSV</a></p>")
    if p.figures:
        parts.append(f"<h3 id='{_anchor(p.paper, 'figures')}'>Figures</h3>")
    for f in p.figures:
        parts.append(_figure(p, f, out))
    if p.published:
        parts.append(f"<h3 id='{_anchor(p.paper, 'published')}'>Published values and claims</h3>")
        items = list(p.published.items())
        numeric = [False, _numeric_columns([[v] for _, v in items], 1)[0]]
        parts.append(_table(["item", "published"], items, numeric=numeric))
    parts.append(_time_table(p))
    parts.append("</section>")
    return "\n".join(parts)


def _time_table(p) -> str:
    """The paper's time table, collapsed: each task (reported seed, unknowns' grid points, confirmation seed) with
    its runs, seconds, share of the paper's task compute and whether it was computed, cached, reused or failed."""
    from .engine import paper_time_table

    table = paper_time_table(p)
    counts = table["counts"]
    errors = {str(t.get("key")): t.get("error", "") for t in p.tasks}
    done = ", ".join(f"{n} {st}" for st, n in counts.items() if n) or "no task"
    other = "; ".join(f"{k} {v:.1f} s" for k, v in table["other_seconds"].items())
    head = (f"Time per task: {len(table['rows'])} tasks ({done}), {table['computed_seconds']:.1f} s of task compute"
            f"{'; outside the tasks: ' + other if other else ''}")
    rows = [(r["task"], "-" if r["runs"] is None else r["runs"], round(r["seconds"], 2),
             f"{r['share_percent']:.2f} %", r["status"], errors.get(r["task"], "")) for r in table["rows"]]
    return (f"<details id='{_anchor(p.paper, 'tasks')}'><summary>{_esc(head)}</summary>"
            "<p class='meta'>Share: of the seconds the paper's tasks spent (a cached task, or one the confirmation "
            "seed reuses because it does not depend on the seed, counts 0 s); the shares sum to 100 %.</p>"
            + _table(["task", "runs", "seconds", "share of the paper's compute", "status", "error"], rows,
                     numeric=[False, True, True, True, False, False])
            + (_table(["figure or table (outside the tasks)", "seconds", "parts"],
                      [(i["what"], round(i["seconds"], 2),
                        ", ".join(f"{k} {v:.2f} s" for k, v in i["parts"].items())) for i in table["items"]],
                      numeric=[False, True, False]) if table["items"] else "")
            + "</details>")


def _nav(papers) -> str:
    items = ["<nav id='nav' aria-label='Contents'><div class='brand'><a href='#top'>workbench report</a></div><ul>"]
    items.append("<li><a href='#overview'>At a glance</a></li>")
    for p in papers:
        sub = [f"<li><a href='#{_anchor(p.paper, 'scoreboard')}'>Scoreboard</a>"
               f"<span class='tally'>{_nav_tally(p.criteria)}</span></li>",
               f"<li><a href='#{_anchor(p.paper, 'differs')}'>What differs</a></li>"]
        if p.tables:
            sub.append("<li class='group'>Tables</li>")
            sub += [f"<li><a href='#{_anchor(p.paper, 'table', t['id'])}' title='{_esc(t['caption'])}'>"
                    f"{_esc(t['id'])}</a></li>" for t in p.tables]
        if p.figures:
            sub.append("<li class='group'>Figures</li>")
            sub += [f"<li><a href='#{_anchor(p.paper, 'fig', f['id'])}' title='{_esc(f['caption'])}'>"
                    f"{_esc(f['id'])}</a></li>" for f in p.figures]
        if p.published:
            sub.append(f"<li><a href='#{_anchor(p.paper, 'published')}'>Published values</a></li>")
        items.append(f"<li class='paper'><a href='#{_anchor(p.paper)}' title='{_esc(p.title)}'>Paper "
                     f"{_esc(p.paper)} <small>{_esc(p.title)}</small></a><ul class='sub'>{''.join(sub)}</ul></li>")
    items.append("<li class='paper'><a href='#provenance'>Provenance</a></li></ul></nav>")
    return "".join(items)


def _overview(papers) -> str:
    rows, cells = [], []
    for p in papers:
        counts = _tally(p.criteria)
        why, why_html = _not_judgeable_cell(p.criteria)
        conf, conf_html = _confirmation_summary(p)
        # the failed preconditions and the confirmation seed's agreement share one text column (the table must fit
        # the page's content column beside the navigation)
        rows.append([p.paper, p.title, p.size, *(counts[v] for v in _ORDER), f"{why or 'n/a'}; confirmation seed: {conf}",
                     len(p.errors)])
        cells.append([f"<a href='#{_anchor(p.paper)}'>{_esc(p.paper)}</a>", None, None,
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


def write_index(report, host: PluginHost) -> None:
    """Write ``report.out/index.html`` (atomically) for every paper of the report folder."""
    papers = _papers(report)
    out = Path(report.out)
    parts = ["<!doctype html><html lang='en'><head><meta charset='utf-8'>"
             "<meta name='viewport' content='width=device-width, initial-scale=1'><title>workbench report</title>"
             f"<style>{_STYLE}</style></head><body>",
             _nav(papers),
             "<main id='top'>",
             "<h1>workbench report</h1>",
             "<p>Each paper: a scoreboard of the brief's 'reproduced if' criteria judged on our numbers (the "
             "number of runs, the 95 % interval and a verdict among <i>met</i>, <i>not met</i>, "
             "<i>inconclusive</i>, <i>not attainable</i> and <i>not judgeable</i>, the last where a precondition "
             "of the criterion fails, named with its numbers), what differs from the paper, then our tables and "
             "figures regenerated from saved raw numbers with the published values beside ours.</p>"]
    for line in getattr(report, "warnings", []):
        parts.append(f"<p class='callout bad'>{_esc(line)}</p>")
    if any(c.indicative for p in papers for c in p.criteria):
        parts.append("<p class='callout'><b>Quick run:</b> the verdicts are indicative only and none is declared "
                     "<i>met</i>; <code>workbench report --full</code> gives firm verdicts.</p>")
    parts.append("<h2 id='overview'>At a glance</h2>")
    parts.append(_overview(papers))
    for p in papers:
        parts.append(_paper_section(p, out))
    parts.append("<h2 id='provenance'>Provenance</h2>")
    parts.append(_table(["what", "value"], _provenance(report, host), numeric=[False, False]))
    parts.append(f"</main><script>{_SCRIPT}</script></body></html>")
    write_text_atomic(out / "index.html", "\n".join(parts))


def _criterion_summary(c) -> dict:
    d = c.to_dict()
    d["statement"] = c.text
    names = list(dict.fromkeys(a.unknown for a in c.across))
    d["where_it_holds"] = {name: where_it_holds(c.across, name) for name in names}
    return d


def write_summary(report, host: PluginHost) -> None:
    """Write ``report.out/summary.json`` (atomically): every paper's criteria, tables, figures and tasks.

    Each paper carries ``task_times`` (:func:`workbench.report.engine.paper_time_table`: every task's runs,
    seconds, share of the paper's task compute and status).  Each criterion carries ``id, statement (and text),
    ours, published, n, interval, threshold, verdict, indicative, met`` (bool, for older readers), ``replication``, ``detail``, ``extra`` and ``preconditions``
    (each ``name, holds, detail, values``); a paper kept from an earlier run into the folder has
    ``from_saved: true``.
    """
    from .engine import _jsonable, paper_time_table

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
