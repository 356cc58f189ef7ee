"""Write the report's ``index.html`` (self-contained: figures embedded) and ``summary.json``."""

from __future__ import annotations

import base64
import html
import json
import platform
from datetime import datetime, timezone
from typing import Any

from ..plugins import PluginHost
from .cache import distribution_versions

__all__ = ["write_index", "write_summary"]

_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:.6em 0 1.4em;font-size:.9em}
th,td{border:1px solid #bbb;padding:.25em .6em;text-align:right}
th{background:#eee} td:first-child,th:first-child{text-align:left}
.met{background:#d9f2d9}.unmet{background:#f8d7d7}.err{color:#a00}
figure{margin:1em 0 2em} figcaption{font-size:.9em;color:#444}
code,pre{background:#f4f4f4;padding:.1em .3em}
details{margin:.5em 0}
"""


def _esc(x: Any) -> str:
    if isinstance(x, float):
        return html.escape(f"{x:.4g}")
    return html.escape(str(x))


def _table(columns, rows, classes=None) -> str:
    head = "".join(f"<th>{_esc(c)}</th>" for c in columns)
    body = []
    for i, row in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{_esc(v)}</td>" for v in row) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _provenance(report, host: PluginHost) -> list[tuple[str, str]]:
    versions = distribution_versions()
    rows = [
        ("command", report.command or "(library call)"),
        ("seed", str(report.seed)),
        ("size", report.size),
        ("wall time", f"{report.seconds:.1f} s"),
        ("finished", datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")),
        ("python", platform.python_version()),
        ("machine", f"{platform.machine()} {platform.system()}"),
    ]
    rows += [(f"package {k}", v) for k, v in versions.items()]
    rows += [(f"plugin {p.name}", f"{p.distribution} {p.version} ({p.status})") for p in host.plugins]
    return rows


def write_index(report, host: PluginHost) -> None:
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>workbench report</title>"
             f"<style>{_STYLE}</style></head><body>",
             "<h1>workbench report</h1>",
             "<p>Each paper: our figures and tables regenerated from saved raw numbers, the paper's "
             "published values beside ours, and the brief's 'reproduced if' criteria evaluated on our "
             "numbers.</p>",
             "<h2>Contents</h2><ul>"]
    for p in report.papers:
        parts.append(f"<li><a href='#paper{p.paper}'>Paper {p.paper}: {_esc(p.title)}</a></li>")
    parts.append("<li><a href='#provenance'>Provenance</a></li></ul>")
    for p in report.papers:
        parts.append(f"<h2 id='paper{p.paper}'>Paper {p.paper}: {_esc(p.title)}</h2>")
        parts.append(f"<p>Size: <b>{_esc(p.size)}</b>; filters: {_esc(', '.join(p.filters) or '-')}; "
                     f"time: {p.seconds:.1f} s.</p>")
        for err in p.errors:
            parts.append(f"<p class='err'>Not done: {_esc(err)}</p>")
        if p.criteria:
            parts.append("<h3>Reproduced if</h3>")
            parts.append(_table(["criterion", "statement", "met", "ours"],
                                [(c.id, c.text, "met" if c.met else "NOT met", c.detail) for c in p.criteria],
                                ["met" if c.met else "unmet" for c in p.criteria]))
        for t in p.tables:
            parts.append(f"<h3>{_esc(t['id'])}: {_esc(t['caption'])}</h3>")
            parts.append(_table(t["columns"], t["rows"]))
            parts.append(f"<p><a href='{t['csv'].relative_to(report.out)}'>CSV</a></p>")
        for f in p.figures:
            png = base64.b64encode(f["png"].read_bytes()).decode()
            rel = lambda x: x.relative_to(report.out)  # noqa: E731
            parts.append(f"<figure id='paper{p.paper}-{f['id']}'><img alt='{_esc(f['id'])}' "
                         f"src='data:image/png;base64,{png}' style='max-width:100%'>"
                         f"<figcaption><b>{_esc(f['id'])}</b>: {_esc(f['caption'])} "
                         f"[<a href='{rel(f['svg'])}'>SVG</a>, <a href='{rel(f['data'])}'>data NPZ</a>, "
                         f"<a href='{rel(f['data']).with_suffix('.csv')}'>data CSV</a>]</figcaption></figure>")
        if p.published:
            parts.append("<h3>Published values and claims</h3>")
            parts.append(_table(["item", "published"], [(k, v) for k, v in p.published.items()]))
        if p.notes:
            parts.append(f"<details><summary>Choices made where the paper is silent</summary>"
                         f"<pre style='white-space:pre-wrap'>{_esc(p.notes)}</pre></details>")
        parts.append("<details><summary>Tasks</summary>" + _table(
            ["task", "seconds", "from cache", "error"],
            [(t["key"], t["seconds"], "yes" if t["cached"] else "no", t["error"]) for t in p.tasks]) + "</details>")
    parts.append("<h2 id='provenance'>Provenance</h2>")
    parts.append(_table(["what", "value"], _provenance(report, host)))
    parts.append("</body></html>")
    (report.out / "index.html").write_text("\n".join(parts), encoding="utf-8")


def write_summary(report, host: PluginHost) -> None:
    summary = {
        "command": report.command,
        "seed": report.seed,
        "size": report.size,
        "seconds": report.seconds,
        "versions": distribution_versions(),
        "plugins": [{"name": p.name, "distribution": p.distribution, "version": p.version, "status": p.status,
                     "error": p.error} for p in host.plugins],
        "papers": [{
            "paper": p.paper, "title": p.title, "filters": list(p.filters), "seconds": p.seconds,
            "errors": p.errors,
            "criteria": [{"id": c.id, "text": c.text, "met": bool(c.met), "detail": c.detail} for c in p.criteria],
            "tables": [{"id": t["id"], "columns": t["columns"], "rows": t["rows"]} for t in p.tables],
            "figures": [f["id"] for f in p.figures],
            "tasks": [{k: v for k, v in t.items() if k != "traceback"} for t in p.tasks],
        } for p in report.papers],
    }
    (report.out / "summary.json").write_text(json.dumps(summary, indent=2, default=str), encoding="utf-8")
