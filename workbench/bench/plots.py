"""Scaling figures of ``workbench bench --plot DIR``: throughput against N, M or B, beside each family's peer and limit.

A benchmark group returns its curves under the key ``"curves"``: a list of JSON-able dicts ::

    {"id": "pf_vs_particles", "title": "...", "x_label": "particles per run N", "x_unit": "",
     "y_label": "throughput", "y_unit": "particle-steps/s", "log_x": True, "log_y": True,
     "series": [{"label": "...", "role": "ours" | "peer" | "limit" | "reference", "x": [...], "y": [...]}, ...]}

:func:`draw_curve` draws one as a matplotlib figure (one line per series; a limit with a single point is drawn as
a horizontal line across the plot); :func:`save_curves` writes ``<group>_<id>.png`` (small, for the docs),
``.svg`` (text kept as text) and ``.csv`` (the data: ``series,role,x,y``).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

__all__ = ["ROLES", "draw_curve", "save_curves", "check_curve"]

#: Line style per series role: ours solid, a peer library dashed, a limit dotted, a reference dash-dotted.
ROLES = {"ours": dict(linestyle="-", marker="o"), "peer": dict(linestyle="--", marker="s"),
         "limit": dict(linestyle=":", marker=None, linewidth=2.0), "reference": dict(linestyle="-.", marker="^")}


def check_curve(curve: dict) -> None:
    """Raise ``ValueError`` naming what is wrong with a curve spec (missing keys, ragged series, unknown role)."""
    for key in ("id", "title", "x_label", "y_label", "series"):
        if key not in curve:
            raise ValueError(f"benchmark curve {curve.get('id', '?')!r} has no {key!r}")
    for s in curve["series"]:
        if s.get("role") not in ROLES:
            raise ValueError(f"curve {curve['id']!r}: series {s.get('label')!r} has role {s.get('role')!r}; "
                             f"expected one of {', '.join(ROLES)}")
        if len(s.get("x", ())) != len(s.get("y", ())) or not len(s.get("x", ())):
            raise ValueError(f"curve {curve['id']!r}: series {s.get('label')!r} needs x and y of one length >= 1")


def _label(name: str, unit: str) -> str:
    return f"{name} ({unit})" if unit else name


def _finite(x, y):
    pts = [(float(a), float(b)) for a, b in zip(x, y)
           if isinstance(a, (int, float)) and isinstance(b, (int, float)) and math.isfinite(a) and math.isfinite(b)]
    return [p[0] for p in pts], [p[1] for p in pts]


def draw_curve(curve: dict):
    """One curve spec as a matplotlib ``Figure`` (Agg): axes labelled with units, one line per series."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    check_curve(curve)
    fig = Figure(figsize=(6.0, 3.8), dpi=90)
    ax = fig.add_subplot()
    xs_all = [float(v) for s in curve["series"] for v in _finite(s["x"], s["y"])[0]]
    lo, hi = (min(xs_all), max(xs_all)) if xs_all else (0.0, 1.0)
    for s in curve["series"]:
        x, y = _finite(s["x"], s["y"])
        style = dict(ROLES[s["role"]])
        if s["role"] == "limit" and len(x) == 1:
            ax.axhline(y[0], label=s["label"], color="black", **{k: v for k, v in style.items() if k != "marker"})
            continue
        ax.plot(x, y, label=s["label"], **style)
    if curve.get("log_x", True):
        ax.set_xscale("log")
    if curve.get("log_y", True):
        ax.set_yscale("log")
    if lo < hi:
        ax.set_xlim(lo / 1.3 if curve.get("log_x", True) else lo, hi * 1.3 if curve.get("log_x", True) else hi)
    ax.set_xlabel(_label(curve["x_label"], curve.get("x_unit", "")))
    ax.set_ylabel(_label(curve["y_label"], curve.get("y_unit", "")))
    ax.set_title(curve["title"], fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    if curve.get("caption"):
        fig.text(0.01, 0.01, curve["caption"], fontsize=6, alpha=0.8)
    fig.tight_layout()
    return fig


def save_curves(results: dict, out_dir) -> list[Path]:
    """Draw every group's ``curves`` of ``results`` (``{group: figures}``) into ``out_dir``: PNG, SVG and CSV per
    curve; returns the PNG paths."""
    import matplotlib

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for group, figures in results.items():
        if not isinstance(figures, dict):
            continue
        for curve in figures.get("curves", []) or []:
            stem = out / f"{group}_{curve['id']}"
            fig = draw_curve(curve)
            with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "workbench"}):
                fig.savefig(stem.with_suffix(".png"), dpi=80)
                fig.savefig(stem.with_suffix(".svg"), metadata={"Date": None})
            with open(stem.with_suffix(".csv"), "w", newline="", encoding="utf-8") as fh:
                w = csv.writer(fh)
                w.writerow(["series", "role", f"x ({curve.get('x_unit', '')})".replace(" ()", ""),
                            f"y ({curve.get('y_unit', '')})".replace(" ()", "")])
                for s in curve["series"]:
                    for x, y in zip(s["x"], s["y"]):
                        w.writerow([s["label"], s["role"], x, y])
            written.append(stem.with_suffix(".png"))
    return written
