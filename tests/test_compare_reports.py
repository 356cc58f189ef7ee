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


def test_a_difference_is_located_the_table_cell_and_the_figure_row(tmp_path):
    def folder(name, median, late):
        (tmp_path / name / "paper000").mkdir(parents=True)
        rows = [["A", "236.0", "0.4"], ["C, 2 m/s kernel", f"{median}", "1.8"]] + [[f"r{i}", "1", "0"] for i in range(8)]
        (tmp_path / name / "summary.json").write_text(json.dumps({"papers": [{"paper": "000", "tables": [
            {"id": "table3", "columns": ["method", "whole: median (m)", "run time (s)"], "rows": rows}]}]}))
        e = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, late]])
        np.savez(tmp_path / name / "paper000" / "fig13.npz", e_error=e, labels=np.array(["A", "C, 2 m/s kernel"]))
        return tmp_path / name

    a = folder("a", 136.9, 4197.91)
    code, text = compare(a, folder("b", 136.6, 4201.74), "--rtol", "1e-6")
    lines = text.splitlines()
    assert code == 1
    at = lines.index("  table table3: DIFFERS (max relative difference 0.0022, 1 timing column(s) skipped)")
    assert lines[at + 1] == "    row 'C, 2 m/s kernel', column 'whole: median (m)': 136.9 against 136.6"
    at = lines.index("  figure fig13: DIFFERS in e_error (max relative difference 0.00091)")
    assert lines[at + 1] == "    e_error[1, 2] (row 'C, 2 m/s kernel'): 4197.91 against 4201.74"
    # many differing cells: the first six listed, the rest counted
    many = folder("c", 136.9, 4197.91)
    summary = json.loads((many / "summary.json").read_text())
    for row in summary["papers"][0]["tables"][0]["rows"]:
        row[1] = "7" if row[0].startswith("r") else row[1]
    (many / "summary.json").write_text(json.dumps(summary))
    code, text = compare(a, many)
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("  table table3: DIFFERS"))
    assert [line.split(",")[0] for line in lines[at + 1:at + 7]] == [f"    row 'r{i}'" for i in range(6)]
    assert lines[at + 7] == "    ... and 2 more cells"
    # agreeing reports list no cells
    code, text = compare(a, folder("d", 136.9, 4197.91))
    assert code == 0 and not any(line.startswith("    ") for line in text.splitlines())
