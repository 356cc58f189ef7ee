"""The ``workbench bench`` runner: the target table, the arch a group runs on, and the scaling figures (drawn from
small synthetic results; nothing here is timed)."""

import csv
import json
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from workbench.bench import flatten, print_results
from workbench.bench.plots import ROLES, check_curve, draw_curve, save_curves
from workbench.bench.targets import collect_targets, format_targets, judge, parse_target


def _results():
    return {
        "core": {"pf": 3.0, "target_pf_over_floor": "<= 2", "measured_pf_over_floor": 1.5,
                 "met_pf_over_floor": True, "note_pf_over_floor": "floor of the draws",
                 "target_speedup": ">= 10", "measured_speedup": 7.25, "met_speedup": False,
                 "target_peer": ">= 10", "measured_peer": "not installed", "met_peer": "not installed",
                 "target_legacy": 30.0},
        "paper000": {"kernel_targets": {"target_f32_over_f64": ">= 2.5", "measured_f32_over_f64": 2.7},
                     "scenario": {"target_s": "< 30 s", "measured_s": 31.5}},
        "broken": {"error": "benchmark group 'broken' failed: boom"},
    }


def test_parse_and_judge_targets():
    assert parse_target("<= 2") == ("<=", 2.0, "")
    assert parse_target(">= 2.5e-1 pairs/s") == (">=", 0.25, "pairs/s")
    assert parse_target("< 30 s") == ("<", 30.0, "s")
    assert parse_target("fast") is None and parse_target("") is None
    assert judge("<= 2", 1.999) == "met" and judge("<= 2", 2.001) == "not met"
    assert judge(">= 10", 10.0) == "met" and judge("> 10", 10.0) == "not met"
    assert judge("<= 2", "not installed") == "not installed"
    assert judge("<= 2", float("nan")) == "not measured" and judge("<= 2", True) == "not measured"
    assert judge("about 2", 1.0) == "target not understood"


def test_target_rows_one_per_declared_target_with_verdicts():
    rows = collect_targets(_results(), quick=False)
    by = {(r.group, r.name): r for r in rows}
    assert set(by) == {("core", "pf_over_floor"), ("core", "speedup"), ("core", "peer"),
                       ("paper000", "kernel_targets.f32_over_f64"), ("paper000", "scenario.s")}
    assert by["core", "pf_over_floor"].verdict == "met" and by["core", "pf_over_floor"].note == "floor of the draws"
    assert by["core", "speedup"].verdict == "not met"  # the group's own met_ wins
    assert by["core", "peer"].verdict == "not installed" and by["core", "peer"].measured == "not installed"
    # without met_ the runner judges the measured value against the target itself
    assert by["paper000", "kernel_targets.f32_over_f64"].verdict == "met"
    assert by["paper000", "scenario.s"].verdict == "not met" and by["paper000", "scenario.s"].target == "< 30 s"


def test_quick_mode_never_says_met():
    rows = collect_targets(_results(), quick=True)
    assert rows and {r.verdict for r in rows} == {"indicative"}
    text = format_targets(rows, quick=True)
    assert "indicative" in text and " met" not in text.replace("never 'met'", "")


def test_target_table_format_one_line_per_target():
    rows = collect_targets(_results(), quick=False)
    lines = format_targets(rows, quick=False).splitlines()
    assert lines[0] == "targets" and lines[1].split() == ["group", "target", "goal", "min", "median", "max", "verdict"]
    body = [line for line in lines[2:] if not line.lstrip().startswith("note:")]
    assert len(body) == len(rows)
    speed = next(line for line in body if line.split()[1] == "speedup")
    assert speed.split()[2:] == [">=", "10", "-", "7.25", "-", "not", "met"]  # no spread given: min and max "-"
    assert any(line.strip() == "note: floor of the draws" for line in lines)
    assert format_targets([], quick=False) == "targets: none declared"


def test_printed_results_keep_curves_out_of_the_figures():
    res = {"core": {"x": 1.0, "curves": [_curve()], "target_a": "<= 1", "measured_a": 0.5}}
    rows = dict(flatten("core", res["core"]))
    assert rows["core.curves"].startswith("1 scaling figure") and "core.curves[0].id" not in rows
    lines = []
    print_results(res, quick=False, out=lines.append)
    assert "\n".join(lines).splitlines()[-1].split() == ["core", "a", "<=", "1", "-", "0.5", "-", "met"]


def _curve(**extra):
    curve = {"id": "pf_vs_particles", "title": "PF", "x_label": "particles N", "x_unit": "", "y_label": "throughput",
             "y_unit": "particle-steps/s",
             "series": [{"label": "ours", "role": "ours", "x": [1e3, 1e4, 1e5], "y": [2e6, 8e6, 9e6]},
                        {"label": "Stone Soup", "role": "peer", "x": [1e3, 1e5], "y": [1e6, 1.5e6]},
                        {"label": "floor", "role": "limit", "x": [1e3, 1e4, 1e5], "y": [3e7, 4e7, 4e7]},
                        {"label": "peak / 44", "role": "limit", "x": [1e3], "y": [5e7]}]}
    curve.update(extra)
    return curve


def test_draw_curve_has_units_one_line_per_series_and_the_limit():
    fig = draw_curve(_curve())
    ax = fig.axes[0]
    assert ax.get_xlabel() == "particles N" and ax.get_ylabel() == "throughput (particle-steps/s)"
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    lines = {line.get_label(): line for line in ax.get_lines()}
    assert set(lines) == {"ours", "Stone Soup", "floor", "peak / 44"}
    assert list(lines["ours"].get_ydata()) == [2e6, 8e6, 9e6]
    assert lines["floor"].get_linestyle() == ":" and lines["Stone Soup"].get_linestyle() == "--"
    # a one-point limit spans the plot as a horizontal line at its value
    assert list(lines["peak / 44"].get_ydata()) == [5e7, 5e7]
    assert {t.get_text() for t in ax.get_legend().get_texts()} == set(lines)


def test_bad_curves_are_refused_with_their_name():
    with pytest.raises(ValueError, match="no 'series'"):
        check_curve({"id": "a", "title": "t", "x_label": "x", "y_label": "y"})
    bad = _curve()
    bad["series"][0]["role"] = "mine"
    with pytest.raises(ValueError, match="role 'mine'"):
        check_curve(bad)
    ragged = _curve()
    ragged["series"][1]["y"] = [1.0]
    with pytest.raises(ValueError, match="Stone Soup"):
        check_curve(ragged)
    assert set(ROLES) == {"ours", "peer", "limit", "reference"}


def test_save_curves_writes_png_svg_and_csv(tmp_path):
    res = {"core": {"curves": [_curve(), _curve(id="ukf_vs_batch", x_label="runs B", y_unit="run-steps/s")]},
           "other": {"error": "failed"}}
    pngs = save_curves(res, tmp_path)
    assert sorted(p.name for p in pngs) == ["core_pf_vs_particles.png", "core_ukf_vs_batch.png"]
    for png in pngs:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size < 150_000
        svg = ET.parse(png.with_suffix(".svg")).getroot()
        texts = " ".join(t.text or "" for t in svg.iter("{http://www.w3.org/2000/svg}text"))
        assert "throughput" in texts and ("particle-steps/s" in texts or "run-steps/s" in texts)
    with open(tmp_path / "core_pf_vs_particles.csv", newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0] == ["series", "role", "x", "y (particle-steps/s)"]
    assert len(table) == 1 + 3 + 2 + 3 + 1 and ["Stone Soup", "peer", "100000.0", "1500000.0"] in table


def test_bench_replots_a_saved_json_and_checks_its_options(tmp_path):
    saved = tmp_path / "bench.json"
    saved.write_text(json.dumps({"quick": True, "groups": {"core": {"curves": [_curve()]}}}))
    code = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"
    run = lambda *a: subprocess.run([sys.executable, "-c", code, "bench", *a], capture_output=True, text=True,  # noqa: E731
                                    timeout=120, cwd=tmp_path)
    proc = run("--from", str(saved), "--plot", str(tmp_path / "figs"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "figs" / "core_pf_vs_particles.svg").is_file()
    proc = run("--from", str(saved))
    assert proc.returncode == 2 and "--plot" in proc.stderr
    proc = run("--from", str(tmp_path / "missing.json"), "--plot", "x")
    assert proc.returncode == 2 and "no such file" in proc.stderr


def test_the_group_process_runs_its_kernels_on_the_asked_arch(monkeypatch, capsys):
    # child_main sets the kernel arch for the group's run (the policy's current_arch inside it) and records it
    from workbench import bench
    from workbench.kernels import backend
    from workbench.specs import BenchmarkSpec

    seen = {}

    def run(quick):
        seen["arch"], seen["auto"] = backend.current_arch(), backend.resolve("auto")
        return {"x": 1.0}

    class Host:
        def benchmark(self, group):
            return BenchmarkSpec(group, "fake", run)

    monkeypatch.setattr("workbench.plugins.load_host", lambda block=(): Host())
    bench.child_main("fake", True, (), "cuda")
    assert seen == {"arch": "cuda", "auto": "taichi"} and backend.current_arch() == "cpu"
    out = json.loads(capsys.readouterr().out.strip().split("@@BENCH@@")[1])
    assert out["kernel_arch"] == "cuda" and out["x"] == 1.0 and out["peak_rss_mib"] > 0


def test_bench_refuses_a_gpu_arch_that_is_not_here(tmp_path):
    from workbench.kernels.runtime import taichi_available_arches

    if "cuda" in taichi_available_arches():
        pytest.skip("a CUDA GPU is available here")
    code = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", code, "bench", "--arch", "cuda", "--only", "core"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2 and "GPU figures are not available" in proc.stderr


def test_a_group_process_peak_memory_is_its_own_not_its_callers():
    # a child started from a big process: getrusage would report the caller's peak; own_peak_kib the child's
    ballast = np.ones(800 * 2**20 // 8)
    ballast += 1
    code = "from workbench.bench import own_peak_kib; print(own_peak_kib())"
    kib = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    del ballast
    assert 0 < kib < 500 * 1024
