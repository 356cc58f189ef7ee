"""Report engine: outputs, figure data, caching and resuming after an interruption."""

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fixtures import demo_distribution_env

from workbench.report.cache import load_arrays
from workbench.report.engine import resolve_filters, run_report
from workbench.plugins import UnknownComponent
from workbench.types import InputError



def test_report_writes_index_figures_data_and_tables(tmp_path, demo_host, monkeypatch):
    monkeypatch.delenv("WORKBENCH_REPORT_FORMATS", raising=False)  # the default formats: PNG and SVG
    report = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False, command="workbench report")
    paper = report.papers[0]
    assert not paper.errors
    index = (tmp_path / "index.html").read_text()
    page = _page(tmp_path)
    # the index: the at-a-glance table linking the paper's page, and the provenance
    for section in ("At a glance", "Provenance", "seed", "package numpy", "workbench report",
                    "<a href='paper-demo.html'>demo</a>"):
        assert section in index
    # the paper's page: scoreboard first, then what differs, figures, tables, published values
    order = ["Paper demo", "Scoreboard: reproduced if", "What differs from the paper and why", "A fixture.",
             "id='paperdemo-fig-fig1'", "id='paperdemo-table-table1'", "Published values and claims"]
    assert [page.index(x) for x in order] == sorted(page.index(x) for x in order)
    assert "Provenance" in page and "href='index.html#provenance'" in page  # the shared navigation
    # figures are the files beside the pages, with their size; nothing embedded
    assert "base64" not in index + page
    assert "<img src='paperdemo/fig1.png' alt='fig1: MSE vs time' width='704' height='528'>" in page
    for ext in ("png", "svg", "npz", "csv"):
        assert (tmp_path / "paperdemo" / f"fig1.{ext}").stat().st_size > 0
    data = load_arrays(tmp_path / "paperdemo" / "fig1.npz")
    assert data["mse"].shape == (2, 15) and list(data["filters"]) == ["ekf", "kf"]
    # KF and EKF are the same filter on a linear model: identical curves behind the figure.
    np.testing.assert_allclose(data["mse"][0], data["mse"][1], rtol=1e-9)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["papers"][0]["tables"][0]["columns"][2].startswith("published")
    assert "<a href='paperdemo/fig1.svg'>SVG</a>" in page  # linked beside the PNG


def test_figure_formats_are_honoured_or_refused_by_name(tmp_path, demo_host, monkeypatch, capsys):
    from workbench.cli import main

    # PNG only (the test suite's setting): no SVG written, none linked, a stale one from an earlier report removed
    monkeypatch.delenv("WORKBENCH_REPORT_FORMATS", raising=False)
    run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False, formats=("png", "svg"))
    assert (tmp_path / "paperdemo" / "fig1.svg").is_file()
    monkeypatch.setenv("WORKBENCH_REPORT_FORMATS", "png")
    report = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    assert [f["svg"] for f in report.papers[0].figures] == [None] * len(report.papers[0].figures)
    assert (tmp_path / "paperdemo" / "fig1.png").stat().st_size > 0
    assert not (tmp_path / "paperdemo" / "fig1.svg").exists()
    page = _page(tmp_path)
    assert "src='paperdemo/fig1.png'" in page and "fig1.svg" not in page
    # an explicit argument wins over the environment
    run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False, formats="png,svg")
    assert (tmp_path / "paperdemo" / "fig1.svg").is_file()
    # refused by name, before any paper runs: through the API and in one line from the CLI
    with pytest.raises(InputError, match="png is needed"):
        run_report(demo_host, tmp_path / "x", papers=["demo"], progress=False, formats=("svg",))
    with pytest.raises(InputError, match="figure formats are png and svg .*got 'pdf'"):
        run_report(demo_host, tmp_path / "x", papers=["demo"], progress=False, formats="png,pdf")
    with pytest.raises(InputError, match="named twice"):
        run_report(demo_host, tmp_path / "x", papers=["demo"], progress=False, formats=["png", "png"])
    monkeypatch.setenv("WORKBENCH_REPORT_FORMATS", "jpeg")
    assert main(["report", "--quick", "--paper", "000", "--out", str(tmp_path / "y"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["workbench: error: WORKBENCH_REPORT_FORMATS='jpeg': figure formats are png and svg "
                   "(comma-separated), got 'jpeg'"]
    assert not (tmp_path / "y" / "paper000").exists()


def _page(folder, paper="demo"):
    """The text of a paper's page in a report folder."""
    return (folder / f"paper-{paper}.html").read_text()


def _criteria_by_id(summary, paper="demo"):
    entry = next(p for p in summary["papers"] if p["paper"] == paper)
    return {c["id"]: c for c in entry["criteria"]}


def test_quick_report_declares_nothing_met_and_shows_n_interval_and_verdict(tmp_path, demo_host):
    run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    crit = _criteria_by_id(json.loads((tmp_path / "summary.json").read_text()))
    keys = {"id", "statement", "ours", "published", "n", "interval", "threshold", "verdict", "indicative", "met",
            "detail", "replication"}
    assert all(keys <= set(c) for c in crit.values())
    assert all(c["indicative"] and c["met"] is False and c["verdict"] != "met" for c in crit.values())
    # criterion 1 is an old-style bool criterion: no n, no interval; its quick numbers pass (worst MSE < 100)
    assert crit["1"]["n"] is None and crit["1"]["interval"] is None and crit["1"]["verdict"] == "inconclusive"
    assert crit["1"]["extra"]["quick_verdict"] == "met" and crit["1"]["detail"].startswith("worst ")
    # criterion 2: the KF's per-run mean squared error, 20 quick runs, bootstrap interval around ours
    two = crit["2"]
    lo, hi = two["interval"]
    assert two["n"] == 20 and lo < two["ours"] < hi and two["threshold"] == "<= 10" and two["published"] == 4.0
    assert hi <= 10 and two["verdict"] == "inconclusive" and two["extra"]["quick_verdict"] == "met"
    # criterion 3: a paired ratio, exactly 1 on a linear model; replicated in 4 disjoint 5-run batches
    assert crit["3"]["ours"] == pytest.approx(1.0) and crit["3"]["interval"] == pytest.approx([1.0, 1.0])
    assert crit["3"]["replication"] == [4, 4] and crit["3"]["published"] == {"KF": 4.0, "EKF": 4.0}

    index = _page(tmp_path)
    board = index[index.index("id='paperdemo-scoreboard'"):index.index("id='paperdemo-differs'")]
    assert board.count("indicative (quick run)") == 3 and board.count("quick-run numbers pass") == 3
    assert ">met</span>" not in board and board.count(">inconclusive</span>") == 3
    assert f"[{lo:.4g}, {hi:.4g}]" in board and "holds in 4 of 4" in board
    # ours and published: the same statistic. Criterion 2 publishes a mean MSE beside our mean MSE; criterion 3
    # judges a ratio, while the paper gives per-filter MSEs: no published ratio, its numbers in their own column
    head = re.findall(r"<th[^>]*>([^<]*)</th>", board.split("</thead>")[0])
    assert head[3:6] == ["ours", "published", "n"] and head[8] == "the paper&#39;s own numbers or claim"
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in re.findall(r"<tr class='[^']*'>(.*?)</tr>", board)]
    rows = {c[0]: c for c in cells}
    assert rows["2"][3:5] == [f"{two['ours']:.4g}", "4"] and rows["2"][8] == "n/a"
    assert rows["3"][3:5] == ["1", "n/a"]
    assert rows["3"][8] == "<span class='kv'>KF 4</span> · <span class='kv'>EKF 4</span>"
    assert "{'KF'" not in index and "KF&#x27;" not in index and "KF&#39;" not in index  # never a dict repr
    published = index[index.index("id='paperdemo-published'"):]
    assert "<td>kf, ekf</td>" in published  # a tuple, joined readably


def test_scoreboard_shows_the_records_numbers_in_its_columns_and_its_detail_as_words(tmp_path, demo_host):
    from workbench.criteria import Criterion, criterion_from_counts, criterion_from_runs

    runs = criterion_from_runs("a", "mean below 2", np.linspace(0.0, 2.0, 50), np.mean, 2.0, "<=", min_n=30,
                               detail="paired runs")
    counts = criterion_from_counts("b", "share", 45, 50, 0.8, ">=", min_n=40, detail="Runs 3 and 7 lost.")
    # the record declares what the scoreboard shows in its columns: no sentence is parsed, none is cut
    assert (counts.min_n, counts.method, counts.count, counts.detail) == (40, "exact, Clopper-Pearson", 45,
                                                                         "Runs 3 and 7 lost.")
    assert (runs.min_n, runs.method, runs.resamples, runs.detail) == (30, "percentile bootstrap, 2000 resamples",
                                                                      2000, "paired runs")
    # without an interval the record says so in its sentence instead of printing [nan, nan]
    one = criterion_from_runs("d", "one run", np.array([1.0]), np.mean, 2.0, "<=", min_n=30, detail="one run only")
    assert one.method is None and one.detail == "one run only"
    assert one.statistics.startswith("ours 1 from n = 1 runs; no interval") and "nan" not in one.statistics
    # read back from summary.json, the record still declares them
    back = Criterion.from_dict(json.loads(json.dumps(runs.to_dict())))
    assert back == runs and back.statistics == runs.statistics
    # the demo paper's full report: the interval column names its method, the n column the runs needed, and the
    # criterion column shows the explanation only
    run_report(demo_host, tmp_path, papers=["demo"], size="full", seed=3, progress=False)
    index = _page(tmp_path)
    board = index[index.index("id='paperdemo-scoreboard'"):index.index("id='paperdemo-differs'")]
    crit = _criteria_by_id(json.loads((tmp_path / "summary.json").read_text()))
    assert "passes if" in crit["2"]["statistics"] and "passes if" not in crit["2"]["detail"]
    assert "passes if" not in board and "percentile bootstrap, 2000 resamples" in board and "needs &ge;" in board
    assert crit["2"]["level"] == 0.95 and crit["2"]["resamples"] == 2000 and crit["2"]["min_n"] == 10


def test_full_report_gives_firm_verdicts(tmp_path, demo_host):
    run_report(demo_host, tmp_path, papers=["demo"], size="full", seed=3, progress=False)
    crit = _criteria_by_id(json.loads((tmp_path / "summary.json").read_text()))
    assert {k: (c["verdict"], c["met"], c["indicative"]) for k, c in crit.items()} == {
        "1": ("met", True, False), "2": ("met", True, False), "3": ("met", True, False)}
    assert crit["2"]["n"] == 100
    index = _page(tmp_path)
    assert "indicative (quick run)" not in index and index.count(">met</span>") >= 3


def test_paper_into_an_existing_folder_keeps_the_other_papers(tmp_path, capsys):
    from dataclasses import replace

    from fixtures import demo_plugin
    from workbench import hookimpl
    from workbench.plugins import load_host

    other = replace(demo_plugin.RECIPE, paper="other", title="Another paper", notes="Other notes.")

    class OtherPaper:
        @hookimpl
        def workbench_report_recipes(self):
            return [other]

    demo_host = load_host(extra_plugins=[("demo", demo_plugin), ("other", OtherPaper())])
    run_report(demo_host, tmp_path, papers=["other"], seed=5, progress=False, command="workbench report --paper other")
    (tmp_path / "paperbroken").mkdir()
    (tmp_path / "paperbroken" / "outcome.json").write_text("{not json")
    (tmp_path / "paper-broken.html").write_text("a page of an earlier report")  # its paper is no longer shown
    (tmp_path / "paper-notes.txt").write_text("not a page")
    report = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    # a damaged saved outcome is skipped with one warning line; the report goes on
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "paperbroken" in ln]
    assert len(lines) == 1 and "JSONDecodeError" in lines[0] and report.warnings == [lines[0].split("warning: ", 1)[1]]
    assert [p.paper for p in report.papers] == ["demo"] and [p.paper for p in report.saved] == ["other"]

    summary = json.loads((tmp_path / "summary.json").read_text())
    papers = {p["paper"]: p for p in summary["papers"]}
    assert set(papers) == {"demo", "other"}
    assert (papers["demo"]["from_saved"], papers["other"]["from_saved"]) == (False, True)
    assert (papers["demo"]["seed"], papers["other"]["seed"]) == (3, 5)
    assert papers["other"]["figures"] == ["fig1"] and papers["other"]["tables"][0]["rows"][0][0] == "ekf"
    assert _criteria_by_id(summary, "other")["2"]["n"] == 20
    index = (tmp_path / "index.html").read_text()
    pages = {p: _page(tmp_path, p) for p in ("demo", "other")}
    for paper, page in pages.items():
        # each paper's page: its anchors, linked in its navigation; the other paper's page linked from every page
        for anchor in (f"paper{paper}", f"paper{paper}-scoreboard", f"paper{paper}-fig-fig1",
                       f"paper{paper}-table-table1"):
            assert f"id='{anchor}'" in page and f"href='#{anchor}'" in page
        assert f"href='paper-{paper}.html'" in index and f"href='paper-{paper}.html'" in pages[{"demo": "other",
                                                                                             "other": "demo"}[paper]]
    section = pages["other"][pages["other"].index("<section id='paperother'>"):]
    section = section[:section.index("</section>")]
    assert "Another paper" in section and "Other notes." in section and "workbench report --paper other" in section
    assert section.count("<img src='paperother/fig1.png'") == 1
    assert "paperbroken" in index and "skipped the saved outcome" in index
    assert "Paper broken" not in index and not (tmp_path / "paper-broken.html").exists()
    assert (tmp_path / "paper-notes.txt").read_text() == "not a page"

    # and re-running the other paper now keeps demo (its fresh outcome was saved in turn)
    again = run_report(demo_host, tmp_path, papers=["other"], seed=5, progress=False)
    assert [p.paper for p in again.saved] == ["demo"] and again.saved[0].seed == 3
    assert {p["paper"] for p in json.loads((tmp_path / "summary.json").read_text())["papers"]} == {"demo", "other"}


def test_saved_outcome_round_trips(tmp_path, demo_host):
    from workbench.report.engine import load_outcome

    report = run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    fresh = report.papers[0]
    back = load_outcome(tmp_path / "paperdemo" / "outcome.json", tmp_path)
    assert back.saved and not fresh.saved
    assert back.criteria == fresh.criteria
    assert [(t["id"], t["columns"], t["rows"]) for t in back.tables] == \
        [(t["id"], list(t["columns"]), [list(r) for r in t["rows"]]) for t in fresh.tables]
    assert [f["png"] for f in back.figures] == [f["png"] for f in fresh.figures]
    assert back.published == {"mean MSE": 4.0, "per filter": {"KF": 4.0, "EKF": 4.0}, "filters": ["kf", "ekf"]}
    assert (back.seed, back.size, back.filters, back.notes) == (3, "quick", ("kf", "ekf"), "A fixture.")
    assert [t["key"] for t in back.tasks] == ["mse-kf", "mse-ekf"]


def test_index_and_summary_are_written_atomically(tmp_path, demo_host, monkeypatch):
    import workbench.report.cache as cache

    run_report(demo_host, tmp_path, papers=["demo"], seed=3, progress=False)
    before = (tmp_path / "index.html").read_text()
    page_before = _page(tmp_path)

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(cache.os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        run_report(demo_host, tmp_path, papers=["demo"], seed=4, progress=False)
    assert (tmp_path / "index.html").read_text() == before  # the old pages, whole
    assert _page(tmp_path) == page_before
    assert json.loads((tmp_path / "paperdemo" / "outcome.json").read_text())["seed"] == 3
    assert not [p for p in tmp_path.rglob("*.tmp")]  # no temporary file left behind


def test_published_values_and_alignment_are_readable():
    import re

    from workbench.report.html import _table, format_value, human_value, is_numeric_like

    text = lambda h: re.sub(r"<[^>]+>", "", h)  # noqa: E731
    assert text(human_value({"A": 332.0, "B": 291.0, "C": 221.0})) == "A 332 · B 291 · C 221"
    assert text(human_value((0.5, 1, "x"))) == "0.5, 1, x"
    nested = human_value({"L1": {"ekf": 1.7964, "ukf": 1.78}, "note": "see text"})
    assert nested.startswith("<table class='nested'>") and "ekf 1.796" in text(nested) and "note" in nested
    assert [format_value(v) for v in (None, 3, 2.0, 0.000123456, 12345.6, float("nan"), True)] == \
        ["n/a", "3", "2", "0.0001235", "12346", "nan", "yes"]
    assert all(map(is_numeric_like, [1, 2.5, "3/20", "61.0 %", "1.2e+04", "nan", "-0.5"]))
    assert not any(map(is_numeric_like, ["ekf", "(A) ekf-nis", "L1", True, "holds in 4 of 4"]))
    html = _table(["method", "ours (m)", "lost runs", "note"],
                  [("ekf", 268.3, "0/2", "fine"), ("ukf", 311.1, "-", "slow 2x")])
    head = re.findall(r"<th( class='num')?>([^<]*)</th>", html)
    assert [(name, bool(num)) for num, name in head] == [
        ("method", False), ("ours (m)", True), ("lost runs", True), ("note", False)]
    assert "<td>ekf</td><td class='num'>268.3</td><td class='num'>0/2</td><td>fine</td>" in html


def test_second_run_reuses_cache_and_a_changed_filter_set_recomputes_only_the_new_task(tmp_path, demo_host):
    run_report(demo_host, tmp_path, papers=["demo"], progress=False)
    again = run_report(demo_host, tmp_path, papers=["demo"], progress=False)
    assert all(t["cached"] for t in again.papers[0].tasks)
    more = run_report(demo_host, tmp_path, papers=["demo"], filters="+sir", progress=False)
    status = {t["key"]: t["cached"] for t in more.papers[0].tasks}
    assert status == {"mse-kf": True, "mse-ekf": True, "mse-sir": False}
    other_seed = run_report(demo_host, tmp_path, papers=["demo"], seed=9, progress=False)
    assert not any(t["cached"] for t in other_seed.papers[0].tasks)


def test_resolve_filters(demo_host):
    assert resolve_filters(("kf", "ekf"), None, demo_host) == ("kf", "ekf")
    assert resolve_filters(("kf", "ekf"), "+sir,-ekf", demo_host) == ("kf", "sir")
    assert resolve_filters(("kf", "ekf"), "sir", demo_host) == ("sir",)
    with pytest.raises(UnknownComponent, match="no filter named 'nope'"):
        resolve_filters(("kf",), "+nope", demo_host)
    # configured filters: the commas inside the parentheses do not split, and the label names the values
    got = resolve_filters(("kf", "ekf"), "+sir(particles=300, threshold=0.25),~ekf", demo_host)
    assert got == ("kf", "sir(particles=300, threshold=0.25)")
    assert demo_host.filter(got[1]).params == {"particles": 300, "threshold": 0.25, "backend": "auto"}
    with pytest.raises(InputError, match="leaves no filter"):
        resolve_filters(("kf",), "-kf", demo_host)  # removing the last filter is an error, not undone
    with pytest.raises(InputError, match="cannot remove 'ukf'"):
        resolve_filters(("kf", "ekf"), "-ukf", demo_host)
    with pytest.raises(InputError, match="particles: must be >= 1"):
        resolve_filters(("kf",), "+sir(particles=0)", demo_host)


def test_failed_task_is_reported_and_the_rest_kept(tmp_path, demo_host):
    from fixtures import demo_plugin

    def boom(ctx):
        raise RuntimeError("solver exploded")

    recipe = demo_plugin.RECIPE
    from dataclasses import replace
    from workbench.report.engine import run_recipe

    broken = replace(recipe, tasks=lambda o: [*demo_plugin._tasks(o)[:1], demo_plugin.Task("bad", {}, boom)])
    outcome = run_recipe(broken, demo_host, tmp_path, progress=False)
    assert any("task 'bad' failed: RuntimeError: solver exploded" in e for e in outcome.errors)
    assert (tmp_path / "cache" / "paperdemo").exists()
    assert [t["key"] for t in outcome.tasks if not t["error"]] == ["mse-kf"]


def test_interrupted_report_resumes_and_loses_nothing(tmp_path):
    env = demo_distribution_env(tmp_path)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "workbench.cli", "report", "--quick", "--paper", "demo", "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, env=dict(env, WORKBENCH_TEST_SLOW_TASK="ekf"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    cache_dir = out / "cache" / "paperdemo"
    # the ekf task blocks until killed: wait for the kf task's entry (or for the process to end, which fails)
    hang_guard = time.monotonic() + 600  # only against a hang: no outcome depends on how long it took
    while proc.poll() is None and not list(cache_dir.glob("mse-kf-*.npz")) and time.monotonic() < hang_guard:
        time.sleep(0.1)
    assert proc.poll() is None, f"the report ended before it could be interrupted: {proc.stderr.read()}"
    proc.kill()
    proc.wait()
    assert list(cache_dir.glob("mse-kf-*.npz")) and not list(cache_dir.glob("mse-ekf-*.npz"))
    assert not (out / "index.html").exists()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    tasks = {t["key"]: t["cached"] for t in json.loads((out / "summary.json").read_text())["papers"][0]["tasks"]}
    assert tasks == {"mse-kf": True, "mse-ekf": False}
    assert (out / "index.html").exists()


def test_what_differs_links_the_papers_docs_page_when_the_repository_has_it(tmp_path):
    from workbench.report.engine import PaperOutcome
    from workbench.report.html import _differs

    docs = Path(__file__).resolve().parents[1] / "docs" / "paper000.md"
    assert docs.is_file()
    out = tmp_path / "deep" / "report"
    block = _differs(PaperOutcome("000", "t", "quick", (), "Gate chosen on tuning seeds.", {}), out)
    assert "What differs from the paper and why" in block and "Gate chosen on tuning seeds." in block
    href = block.split("<a href='", 1)[1].split("'", 1)[0]
    assert not href.startswith("/") and (out / href).resolve() == docs.resolve()
    none = _differs(PaperOutcome("demo", "t", "quick", (), "", {}), out)
    assert "<a href" not in none and "records no choices" in none


def test_summary_is_strict_json_and_a_one_run_criterion_has_no_interval(tmp_path, demo_host):
    from dataclasses import replace

    from fixtures import demo_plugin
    from workbench.criteria import criterion_from_runs
    from workbench.report.engine import ReportOutcome, run_recipe
    from workbench.report.html import write_index, write_summary

    def criteria(results):
        return [criterion_from_runs("x", "from one run", [2.0], np.mean, 1.0, ">=", min_n=1)]

    recipe = replace(demo_plugin.RECIPE, criteria=criteria)
    paper = run_recipe(recipe, demo_host, tmp_path, size="full", progress=False)
    report = ReportOutcome(tmp_path, [paper], 0.0, "", 0, "full")
    write_summary(report, demo_host)
    write_index(report, demo_host)

    def no_constants(name):
        raise ValueError(f"non-standard JSON constant {name}")

    summary = json.loads((tmp_path / "summary.json").read_text(), parse_constant=no_constants)
    (crit,) = summary["papers"][0]["criteria"]
    assert crit["interval"] == [None, None] and crit["n"] == 1 and crit["ours"] == 2.0
    assert crit["verdict"] == "inconclusive" and crit["indicative"] is False  # a full run, still undecided
    index = _page(tmp_path)
    board = index.split("id='paperdemo-scoreboard'")[1].split("id='paperdemo-differs'")[0]
    assert ">inconclusive</span>" in board and "nan" not in board


def test_a_recipe_whose_figure_and_table_share_an_id_is_refused():
    from workbench.specs import FigureSpec, RecipeSpec, Table, TableSpec

    fig = FigureSpec("gospa", "a figure", lambda results: {}, lambda data, fig: None)
    table = TableSpec("gospa", "a table", lambda results: Table(("a",), ()))
    with pytest.raises(ValueError, match="'gospa' is already a figure id"):
        RecipeSpec("x", "t", {"quick": {}}, lambda options: [], figures=(fig,), tables=(table,))
    RecipeSpec("x", "t", {"quick": {}}, lambda options: [], figures=(fig,),
               tables=(TableSpec("gospa-table", "a table", table.make),))


def test_scoreboard_and_at_a_glance_show_not_judgeable_with_the_failed_precondition(tmp_path, demo_host):
    from dataclasses import replace

    from fixtures import demo_plugin
    from workbench.criteria import criterion_from_runs, rows_track
    from workbench.report.engine import ReportOutcome, run_recipe
    from workbench.report.html import write_index, write_summary

    def criteria(results):
        a, c = np.full(20, 39e3), np.linspace(90.0, 110.0, 20)
        track = rows_track({"A": a > 3e3, "C": c > 3e3}, 0.1)
        return [criterion_from_runs("1", "A/C >= 1.3", (a, c), lambda x, y: x.mean() / y.mean(), 1.3, ">=",
                                    min_n=20, preconditions=(track,)),
                criterion_from_runs("2", "C below 200 m", c, np.mean, 200.0, "<", min_n=20,
                                    preconditions=(rows_track({"C": c > 3e3}, 0.1),))]

    paper = run_recipe(replace(demo_plugin.RECIPE, criteria=criteria), demo_host, tmp_path, size="full",
                       progress=False)
    report = ReportOutcome(tmp_path, [paper], 0.0, "", 0, "full")
    write_summary(report, demo_host)
    write_index(report, demo_host)
    crit = _criteria_by_id(json.loads((tmp_path / "summary.json").read_text()))
    assert crit["1"]["verdict"] == "not judgeable" and crit["1"]["met"] is False
    assert crit["1"]["extra"]["verdict_if_judged"] == "met"
    (pre,) = crit["1"]["preconditions"]
    assert pre["name"] == "judged rows track" and pre["holds"] is False
    assert pre["values"]["rows"]["A"] == {"lost": 20, "runs": 20, "share": 1.0}
    assert crit["2"]["verdict"] == "met" and crit["2"]["preconditions"][0]["holds"] is True
    index = (tmp_path / "index.html").read_text()
    page = _page(tmp_path)
    board = page.split("id='paperdemo-scoreboard'")[1].split("id='paperdemo-differs'")[0]
    assert board.count(">not judgeable</span>") == 1 and board.count(">met</span>") == 1
    assert "row-not-judgeable" in board and "failed: judged rows track" in board and "numbers alone: met" in board
    assert "precondition fails: judged rows track (lost runs A 20/20 (100 %), C 0/20 (0 %)" in board
    assert "precondition holds: judged rows track (lost runs C 0/20 (0 %)" in board
    glance = index.split("id='overview'")[1].split("id='provenance'")[0]
    assert "<th class='num'>not judgeable</th>" in glance and "not judgeable: failed precondition" in glance
    assert "<span class='badge v-not-judgeable'>1</span>" in glance
    assert "<b>judged rows track</b> fails for 1" in glance
    for text in (index, page):  # the shared navigation counts the verdicts on every page
        nav = text.split("<nav")[1].split("</nav>")[0]
        assert "1 not judgeable" in nav


def test_declared_unknowns_and_the_verdicts_across_them_are_rendered(tmp_path, demo_host):
    from dataclasses import replace

    from fixtures import demo_plugin
    from workbench.criteria import DeclaredUnknown, criterion_from_runs, judge_across
    from workbench.report.engine import ReportOutcome, load_outcome, run_recipe
    from workbench.report.html import write_index, write_summary

    unknown = DeclaredUnknown("gain", "dimensionless", 1.0, (0.5, 1.0, 2.0),
                              "the paper gives no value; 1 is the brief's")
    c = np.linspace(90.0, 110.0, 20)

    def judged(scale):
        return criterion_from_runs("1", "C below 150", scale * c, np.mean, 150.0, "<", min_n=20)

    def criteria(results):
        main = judged(1.0)
        return [replace(main, across=judge_across(unknown, {g: judged(g) for g in unknown.grid})),
                criterion_from_runs("2", "C below 500", c, np.mean, 500.0, "<", min_n=20)]

    paper = run_recipe(replace(demo_plugin.RECIPE, criteria=criteria, unknowns=(unknown,)), demo_host, tmp_path,
                       size="full", progress=False)
    assert paper.unknowns == [unknown]
    back = load_outcome(tmp_path / "paperdemo" / "outcome.json", tmp_path)
    assert back.unknowns == [unknown] and back.criteria[0].across == paper.criteria[0].across
    report = ReportOutcome(tmp_path, [paper], 0.0, "", 0, "full")
    write_summary(report, demo_host)
    write_index(report, demo_host)
    summary = json.loads((tmp_path / "summary.json").read_text())
    entry = next(p for p in summary["papers"] if p["paper"] == "demo")
    assert entry["unknowns"] == [unknown.to_dict()]
    crit = _criteria_by_id(summary)
    assert [a["verdict"] for a in crit["1"]["across"]] == ["met", "met", "not met"]  # 50, 100, 200 against 150
    assert crit["1"]["where_it_holds"] == {"gain": "holds for gain in {0.5, 1}; not met at {2}"}
    assert crit["2"]["across"] == [] and crit["2"]["where_it_holds"] == {}
    index = _page(tmp_path)
    section = index.split("id='paperdemo-unknowns'")[1].split("id='paperdemo-differs'")[0]
    assert "the paper gives no value; 1 is the brief&#x27;s" in section and "0.5, 1, 2" in section
    assert "gain = 1 (primary)" in section and "holds for gain in {0.5, 1}; not met at {2}" in section
    assert section.count(">met</span>") == 3 and section.count(">not met</span>") == 1  # primary + two grid values
    assert ">2</td>" not in section  # criterion 2 does not hinge on the unknown: no row


def test_pages_escape_what_they_show_and_link_each_paper(tmp_path, demo_host):
    from workbench.report.engine import PaperOutcome, ReportOutcome
    from workbench.report.html import write_index

    title = "<script>alert(1)</script> & 'q'"
    papers = [PaperOutcome("x1", title, "quick", (), "notes <i>", {"claim": "<b>"}),
              PaperOutcome("x2", "second", "quick", (), "", {})]
    write_index(ReportOutcome(tmp_path, papers, 0.0, "cmd <x>", 1, "quick"), demo_host)
    index = (tmp_path / "index.html").read_text()
    pages = {p: (tmp_path / f"paper-{p}.html").read_text() for p in ("x1", "x2")}
    escaped = "&lt;script&gt;alert(1)&lt;/script&gt; &amp; &#39;q&#39;"
    for text in (index, *pages.values()):
        assert "<script>alert" not in text and escaped in text  # in the navigation of every page
        assert "href='paper-x1.html'" in text or "href='#paperx1'" in text
    assert "notes &lt;i&gt;" in pages["x1"] and "<td>&lt;b&gt;</td>" in pages["x1"] and "cmd &lt;x&gt;" in index
    # each page's navigation: the other paper's page, the index's parts; its own parts in-page
    assert "href='paper-x2.html'" in pages["x1"] and "href='#paperx1-scoreboard'" in pages["x1"]
    assert "href='index.html#overview'" in pages["x2"] and "href='#paperx1-scoreboard'" not in pages["x2"]
    assert sorted(p.name for p in tmp_path.glob("*.html")) == ["index.html", "paper-x1.html", "paper-x2.html"]
