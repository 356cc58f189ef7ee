#!/usr/bin/env python3
"""Compare the numbers of two report folders (``workbench report --out A`` and ``--out B``), timings aside.

For every paper in both folders: every table of ``summary.json`` cell by cell, and every figure's data
(``paperNNN/FIG.npz``) array by array; a table or figure of a shared paper that only one report has is a difference.  Numbers must agree to ``--rtol`` (default 1e-9 relative, 1e-12 absolute);
strings exactly.  Columns and arrays that hold measured times (their name mentions seconds, time, "(s)", "(ms)",
"us", "speed" or ends in "_s") are skipped, as are the criteria and cells holding a verdict word (the verdict format
is the report's; the numbers behind it come from the same tables and figures), and text cells that quote measured
times.

Only the papers in both folders are compared: a paper that only one report has is listed as such, which is a
difference of coverage, not of numbers (``--same-papers`` makes it one).

Exit status 0 when everything compared agrees, 1 otherwise; one line per table and figure either way, and under a
table that differs, its first differing cells (row, column, both values).

    python scripts/compare_reports.py before/ after/ [--rtol 1e-9]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

TIMING = re.compile(r"(second|time|\(s\)|\(ms\)|\bms\b|\bus\b|µs|speed|wall|cpu|per run|_s$|_s_)", re.IGNORECASE)
#: The differing cells of a table that are listed (row, column, both values), the rest counted.
MAX_CELLS = 6
#: Cells that hold a criterion's verdict word rather than a number (the verdict format is the report's, not a result).
VERDICT_WORDS = {"met", "not met", "NOT met", "inconclusive", "not attainable", "not judgeable", "indicative"}


def _close(a, b, rtol: float) -> tuple[bool, float]:
    """Whether two cells/arrays agree, and the largest relative difference of their numbers."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return False, float("inf")
    if a.dtype.kind in "fciub" and b.dtype.kind in "fciub":
        a, b = a.astype(float), b.astype(float)
        same_nan = np.isnan(a) == np.isnan(b)
        ok = np.isclose(a, b, rtol=rtol, atol=1e-12, equal_nan=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            # relative to the larger of the two (0 against 2.5 is a difference of 1, not of 2.5e300)
            scale = np.maximum(np.maximum(np.abs(a), np.abs(b)), 1e-300)
            rel = np.where(np.isfinite(a) & np.isfinite(b), np.abs(a - b) / scale, 0.0)
        return bool(np.all(ok & same_nan)), float(np.max(rel, initial=0.0))
    return bool(np.array_equal(a.astype(str), b.astype(str))), 0.0


def _cell(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)


def compare_tables(pa: dict, pb: dict, rtol: float, out: list[str]) -> bool:
    good = True
    tb = {t["id"]: t for t in pb["tables"]}
    for t in pa["tables"]:
        other = tb.get(t["id"])
        if other is None:
            out.append(f"  table {t['id']}: missing in the second report")
            good = False
            continue
        keep = [i for i, c in enumerate(t["columns"]) if not TIMING.search(str(c))]
        if t["columns"] != other["columns"] or len(t["rows"]) != len(other["rows"]):
            out.append(f"  table {t['id']}: different columns or row count")
            good = False
            continue
        worst, ok, cells = 0.0, True, []
        for ra, rb in zip(t["rows"], other["rows"]):
            for i in keep:
                a, b = _cell(ra[i]), _cell(rb[i])
                if isinstance(a, float) and isinstance(b, float):
                    same, rel = _close(a, b, rtol)
                elif str(ra[i]).split(" (")[0] in VERDICT_WORDS or str(rb[i]).split(" (")[0] in VERDICT_WORDS:
                    same, rel = True, 0.0  # a verdict word: how the report words it, not a number
                elif TIMING.search(str(ra[i])) and TIMING.search(str(rb[i])):
                    same, rel = True, 0.0  # a text quoting measured times
                else:
                    same, rel = str(ra[i]) == str(rb[i]), 0.0
                if not same:
                    cells.append(f"    row {str(ra[0])[:60]!r}, column {t['columns'][i]!r}: {ra[i]} against {rb[i]}")
                ok &= same
                worst = max(worst, rel)
        skipped = len(t["columns"]) - len(keep)
        out.append(f"  table {t['id']}: {'identical' if worst == 0 and ok else ('agrees' if ok else 'DIFFERS')}"
                   f" (max relative difference {worst:.2g}{f', {skipped} timing column(s) skipped' if skipped else ''})")
        out.extend(cells[:MAX_CELLS] + ([f"    ... and {len(cells) - MAX_CELLS} more cells"]
                                        if len(cells) > MAX_CELLS else []))
        good &= ok
    ids = {t["id"] for t in pa["tables"]}
    for t in pb["tables"]:
        if t["id"] not in ids:
            out.append(f"  table {t['id']}: missing in the first report")
            good = False
    return good


def _largest_difference(name: str, a, b, labels) -> str | None:
    """Where two numeric arrays of a figure differ most: the index, both values and, where the figure's
    ``labels`` name the rows of its first axis, that row's label."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype.kind not in "fciub" or b.dtype.kind not in "fciub" or a.size == 0:
        return None
    with np.errstate(invalid="ignore"):
        gap = np.where(np.isfinite(a) & np.isfinite(b), np.abs(a.astype(float) - b.astype(float)), 0.0)
    if not np.any(gap):
        return None
    at = np.unravel_index(int(np.argmax(gap)), a.shape)
    row = ""
    if labels is not None and a.ndim >= 1 and np.ndim(labels) == 1 and len(labels) == a.shape[0]:
        row = f" (row {str(labels[at[0]])[:60]!r})"
    index = ", ".join(str(int(i)) for i in at)
    return f"    {name}[{index}]{row}: {a[at]:.6g} against {b[at]:.6g}"


def compare_figures(da: Path, db: Path, rtol: float, out: list[str]) -> bool:
    good = True
    for fa in sorted(da.glob("*.npz")):
        fb = db / fa.name
        if not fb.exists():
            out.append(f"  figure {fa.stem}: missing in the second report")
            good = False
            continue
        with np.load(fa, allow_pickle=False) as xa, np.load(fb, allow_pickle=False) as xb:
            names = [n for n in xa.files if not TIMING.search(n)]
            worst, ok, bad, where = 0.0, set(xa.files) == set(xb.files), [], []
            for n in names:
                if n not in xb.files:
                    ok, bad = False, bad + [n]
                    continue
                same, rel = _close(xa[n], xb[n], rtol)
                if not same:
                    bad.append(n)
                    where.append(_largest_difference(n, xa[n], xb[n], xa["labels"] if "labels" in xa.files else None))
                ok &= same
                worst = max(worst, rel)
        status = "identical" if ok and worst == 0 else ("agrees" if ok else "DIFFERS in " + ", ".join(bad[:6]))
        out.append(f"  figure {fa.stem}: {status} (max relative difference {worst:.2g})")
        out.extend(w for w in where[:MAX_CELLS] if w)
        good &= ok
    for fb in sorted(db.glob("*.npz")):
        if not (da / fb.name).exists():
            out.append(f"  figure {fb.stem}: missing in the first report")
            good = False
    return good


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("first", type=Path)
    parser.add_argument("second", type=Path)
    parser.add_argument("--rtol", type=float, default=1e-9)
    parser.add_argument("--same-papers", action="store_true",
                        help="a paper that only one of the two reports has is a difference (default: listed only)")
    args = parser.parse_args(argv)
    sa = json.loads((args.first / "summary.json").read_text())
    sb = json.loads((args.second / "summary.json").read_text())
    papers_b = {p["paper"]: p for p in sb["papers"]}
    only_first = [p["paper"] for p in sa["papers"] if p["paper"] not in papers_b]
    only_second = sorted(set(papers_b) - {p["paper"] for p in sa["papers"]})
    good, compared = True, 0
    for pa in sa["papers"]:
        pb = papers_b.get(pa["paper"])
        if pb is None:
            continue
        compared += 1
        print(f"paper {pa['paper']}:")
        out: list[str] = []
        ok = compare_tables(pa, pb, args.rtol, out)
        ok &= compare_figures(args.first / f"paper{pa['paper']}", args.second / f"paper{pa['paper']}", args.rtol, out)
        print("\n".join(out))
        good &= ok
    for where, papers in (("first", only_first), ("second", only_second)):
        if papers:
            print(f"only in the {where} report (not compared): paper " + ", ".join(map(str, papers)))
    covered = not (only_first or only_second)
    if compared == 0:
        print("no paper is in both reports: nothing compared")
        return 1
    if not good:
        print(f"SOME NUMBERS DIFFER (in the {compared} paper(s) both reports have)")
    elif covered:
        print("all numbers agree")
    else:
        print(f"all numbers agree in the {compared} paper(s) both reports have; the reports cover different papers")
    return 0 if good and (covered or not args.same_papers) else 1


if __name__ == "__main__":
    sys.exit(main())
