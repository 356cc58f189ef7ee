"""scripts/compare_reports.py: numbers of the papers both reports have; a paper only one has is coverage."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "compare_reports.py"


def report(folder: Path, papers: dict[str, float], extra: str = "") -> Path:
    """A report folder reduced to what the script reads: per paper one table and one figure scaled by ``value``
    (and, where ``extra`` names one, a second table and figure of that id)."""
    summary = {"papers": []}
    for paper, value in papers.items():
        (folder / f"paper{paper}").mkdir(parents=True)
        tables = [{"id": t, "columns": ["row", "RMSE (m)"], "rows": [["a", f"{value:.12g}"]]}
                  for t in ("t1", extra) if t]
        summary["papers"].append({"paper": paper, "tables": tables})
        for name in ("fig1", extra):
            if name:
                np.savez(folder / f"paper{paper}" / f"{name}.npz", y=np.array([1.0, 2.0]) * value)
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def compare(a: Path, b: Path, *extra: str):
    out = subprocess.run([sys.executable, str(SCRIPT), str(a), str(b), *extra], capture_output=True, text=True,
                         timeout=60)
    return out.returncode, out.stdout


def test_a_report_with_fewer_papers_is_a_coverage_difference_not_a_number_difference(tmp_path):
    full = report(tmp_path / "full", {"000": 1.0, "001": 2.0})
    part = report(tmp_path / "part", {"001": 2.0})
    code, text = compare(full, part)
    assert code == 0, text
    assert "SOME NUMBERS DIFFER" not in text
    assert "only in the first report (not compared): paper 000" in text
    assert "the reports cover different papers" in text
    code, text = compare(full, part, "--same-papers")
    assert code == 1 and "only in the first report" in text


def test_numbers_that_differ_in_a_shared_paper_still_fail(tmp_path):
    a = report(tmp_path / "a", {"000": 1.0, "001": 2.0})
    code, text = compare(a, report(tmp_path / "b", {"001": 2.5}))
    assert code == 1 and "SOME NUMBERS DIFFER (in the 1 paper(s) both reports have)" in text
    code, text = compare(a, report(tmp_path / "c", {"000": 1.0, "001": 2.0}))
    assert code == 0 and text.strip().endswith("all numbers agree")
    code, text = compare(a, report(tmp_path / "d", {"002": 1.0}))
    assert code == 1 and "nothing compared" in text


def test_a_table_or_figure_only_one_report_has_in_a_shared_paper_is_named(tmp_path):
    a = report(tmp_path / "a", {"001": 2.0})
    b = report(tmp_path / "b", {"001": 2.0}, extra="more")
    for first, second, where in ((a, b, "first"), (b, a, "second")):
        code, text = compare(first, second)
        assert code == 1 and "SOME NUMBERS DIFFER (in the 1 paper(s) both reports have)" in text, text
        assert f"table more: missing in the {where} report" in text
        assert f"figure more: missing in the {where} report" in text
        assert "table t1: identical" in text and "figure fig1: identical" in text
