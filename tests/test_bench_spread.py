"""``workbench bench --repeats R``: every figure read against its spread over R runs, every target judged on the
median, and the machine it ran on.  No benchmark group runs here: ``run_group`` is replaced by a fake that hands
back hand-made runs in order, so the medians below are known by hand."""

import json
import numbers
import os
import platform

import numpy as np
import pytest

from workbench import bench
from workbench.bench.targets import NOT_UNDERSTOOD, collect_targets, format_targets, median_verdict, parse_goal
from workbench.types import InputError


class _Host:
    def __init__(self, *groups):
        self.benchmarks = {g: None for g in groups}


def _fake_runs(monkeypatch, per_group: dict):
    """``run_group`` replaced: each call hands back the next hand-made run of its group; the calls are recorded."""
    calls = []
    queues = {g: list(runs) for g, runs in per_group.items()}

    def run_group(name, quick, timeout=1800, block=(), arch="cpu"):
        calls.append((name, quick, arch))
        return dict(queues[name].pop(0))

    monkeypatch.setattr(bench, "run_group", run_group)
    return calls


def _speed_run(speedup, own_met=None, note="", wall=1.0, curve_y=(1.0, 2.0)):
    return {"speedup": speedup, "target_speedup": ">= 10", "measured_speedup": speedup,
            "met_speedup": bool(speedup >= 10) if own_met is None else own_met, "note_speedup": note,
            "backend": "numba", "group_wall_s": wall,
            "curves": [{"id": "c", "title": "t", "x_label": "N", "y_label": "y",
                        "series": [{"label": "ours", "role": "ours", "x": [1, 10], "y": list(curve_y)}]}]}


def _run(tmp_path, monkeypatch, capsys, runs, repeats, quick=False, group="fake"):
    calls = _fake_runs(monkeypatch, {group: runs})
    path = tmp_path / "bench.json"
    rc = bench.run_bench(_Host(group), quick=quick, json_path=path, repeats=repeats)
    out = capsys.readouterr()
    return rc, json.loads(path.read_text()), out.out, out.err, calls


def _row(text, name):
    return next(line.split() for line in text.splitlines() if line.split()[:2] == ["fake", name])


def test_a_target_is_judged_on_the_median_not_on_the_best_or_worst_run(tmp_path, monkeypatch, capsys):
    # runs 9.9, 10.3, 10.6 against ">= 10": the median 10.3 meets it, the worst (and first) run would not
    runs = [_speed_run(9.9, note="run one"), _speed_run(10.3, note="run two"), _speed_run(10.6, note="run three")]
    rc, data, out, err, calls = _run(tmp_path, monkeypatch, capsys, runs, repeats=3)
    assert rc == 0 and calls == [("fake", False, "cpu")] * 3  # three runs, one process each, one after another
    fake = data["groups"]["fake"]
    assert fake["measured_speedup"] == 10.3 and fake["speedup"] == 10.3 and fake["met_speedup"] is True
    assert fake["note_speedup"] == "run two"  # the note of the run nearest the median
    assert data["spread"]["fake"]["measured_speedup"] == {"min": 9.9, "median": 10.3, "max": 10.6,
                                                        "runs": [9.9, 10.3, 10.6]}
    assert data["spread"]["fake"]["group_wall_s"]["runs"] == [1.0, 1.0, 1.0]
    assert data["repeats"] == 3
    (target,) = data["targets"]
    assert (target["measured"], target["min"], target["max"], target["runs"], target["verdict"]) == (
        10.3, 9.9, 10.6, 3, "met")
    assert _row(out, "speedup") == ["fake", "speedup", ">=", "10", "9.9", "10.3", "10.6", "met"]
    assert "judged on the median of 3 runs" in out
    assert any(line.split()[:2] == ["fake.speedup", "10.3"] and "[9.9 .. 10.6]" in line for line in out.splitlines())
    # curve points are medians point by point; strings common to the runs are kept
    assert fake["curves"][0]["series"][0]["y"] == [1.0, 2.0] and fake["backend"] == "numba"


def test_a_median_below_the_goal_is_not_met_even_when_one_run_met_it(tmp_path, monkeypatch, capsys):
    runs = [_speed_run(10.2), _speed_run(9.5), _speed_run(9.8)]  # the first run met it, the median does not
    rc, data, out, err, _ = _run(tmp_path, monkeypatch, capsys, runs, repeats=3)
    assert rc == 0 and data["groups"]["fake"]["met_speedup"] is False
    assert _row(out, "speedup") == ["fake", "speedup", ">=", "10", "9.5", "9.8", "10.2", "not", "met"]


def test_two_runs_judge_the_mean_of_the_middle_pair(tmp_path, monkeypatch, capsys):
    rc, data, out, _, _ = _run(tmp_path, monkeypatch, capsys, [_speed_run(9.0), _speed_run(11.5)], repeats=2)
    assert data["groups"]["fake"]["measured_speedup"] == 10.25 and data["groups"]["fake"]["met_speedup"] is True


def test_a_group_rule_stricter_than_its_goal_keeps_the_target_not_met(tmp_path, monkeypatch, capsys):
    # like the Dask group: met only with bit-identical results; run 2 measured 12 (>= 10) but said not met
    runs = [_speed_run(11.0), _speed_run(12.0, own_met=False), _speed_run(11.5)]
    rc, data, out, err, _ = _run(tmp_path, monkeypatch, capsys, runs, repeats=3)
    fake = data["groups"]["fake"]
    assert fake["measured_speedup"] == 11.5 and fake["met_speedup"] is False
    assert "run 2 of 3" in fake["note_speedup"] and _row(out, "speedup")[-2:] == ["not", "met"]


def test_one_run_keeps_the_groups_own_verdict_and_quick_stays_indicative(tmp_path, monkeypatch, capsys):
    rc, data, out, _, calls = _run(tmp_path, monkeypatch, capsys, [_speed_run(9.9)], repeats=None, quick=True)
    assert len(calls) == 1 and data["repeats"] == 1  # --quick: one run by default
    assert data["groups"]["fake"]["met_speedup"] is False and data["targets"][0]["verdict"] == "indicative"
    assert _row(out, "speedup") == ["fake", "speedup", ">=", "10", "9.9", "9.9", "9.9", "indicative"]


def test_full_size_runs_three_times_by_default(tmp_path, monkeypatch, capsys):
    rc, data, _, _, calls = _run(tmp_path, monkeypatch, capsys, [_speed_run(v) for v in (12, 13, 14)],
                                 repeats=None)
    assert len(calls) == 3 and data["repeats"] == 3 and data["groups"]["fake"]["measured_speedup"] == 13


def test_figures_that_differ_in_kind_over_the_runs_are_shown_not_hidden(tmp_path, monkeypatch, capsys):
    runs = [_speed_run(11.0), _speed_run(12.0), _speed_run(13.0)]
    runs[1]["backend"] = "numpy"
    runs[2]["measured_speedup"] = "timed out"
    rc, data, out, _, _ = _run(tmp_path, monkeypatch, capsys, runs, repeats=3)
    fake, spread = data["groups"]["fake"], data["spread"]["fake"]
    assert fake["backend"] == "numba" and spread["backend"] == {"runs": ["numba", "numpy", "numba"]}
    assert spread["measured_speedup"] == {"runs": [11.0, 12.0, "timed out"]}
    assert "differs over the runs" in out
    # no median of a figure that is not a number in every run; the runs' own verdicts agree, so it is kept
    assert fake["met_speedup"] is True


def test_a_failed_run_fails_its_group_and_names_the_run(tmp_path, monkeypatch, capsys):
    runs = [_speed_run(11.0), {"error": "benchmark group 'fake' failed: boom"}, _speed_run(12.0)]
    rc, data, out, err, calls = _run(tmp_path, monkeypatch, capsys, runs, repeats=3)
    assert rc == 1 and len(calls) == 2  # the third run is not started
    assert data["groups"]["fake"] == {"error": "benchmark group 'fake' failed: boom (run 2 of 3)"}


def test_an_unparseable_goal_is_refused_by_name(tmp_path, monkeypatch, capsys):
    with pytest.raises(InputError, match=r"benchmark target core\.x: goal 'about 10' is not a comparison"):
        parse_goal("about 10", "core.x")
    with pytest.raises(InputError, match="core.x"):
        median_verdict("core.x", "fast enough", [1.0, 2.0, 3.0], [True, True, True])
    runs = [_speed_run(v) for v in (11.0, 12.0, 13.0)]
    for r in runs:
        r["target_speedup"] = "about 10"
    rc, data, out, err, _ = _run(tmp_path, monkeypatch, capsys, runs, repeats=3)
    assert rc == 1
    assert "workbench: error: benchmark target fake.speedup: goal 'about 10' is not a comparison" in err
    assert data["groups"]["fake"]["met_speedup"] == NOT_UNDERSTOOD and data["targets"][0]["verdict"] == NOT_UNDERSTOOD
    # the table refuses it whatever the group's own met_X says, in quick mode too
    rows = collect_targets({"g": {"target_a": "roughly 2", "measured_a": 1.0, "met_a": True}}, quick=True)
    assert rows[0].verdict == NOT_UNDERSTOOD and NOT_UNDERSTOOD in format_targets(rows, quick=True)


def test_bench_refuses_zero_repeats_in_one_line(tmp_path, capsys):
    from workbench.cli import main

    assert main(["bench", "--repeats", "0", "--json", str(tmp_path / "b.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["workbench: error: bench --repeats: expected a whole number >= 1, got 0"]
    with pytest.raises(InputError, match="--repeats"):
        bench.run_bench(_Host("fake"), quick=False, json_path=tmp_path / "b.json", repeats=0)


def test_the_machine_is_in_the_header_and_the_json(tmp_path, monkeypatch, capsys):
    runs = [_speed_run(v) for v in (11.0, 12.0)]
    rc, data, out, _, _ = _run(tmp_path, monkeypatch, capsys, runs, repeats=2)
    m = data["machine"]
    assert isinstance(m["cpu_model"], str) and m["cpu_model"]
    assert isinstance(m["usable_cores"], int) and isinstance(m["logical_cores"], int)
    assert 1 <= m["usable_cores"] <= m["logical_cores"]
    if hasattr(os, "sched_getaffinity"):
        assert m["usable_cores"] == len(os.sched_getaffinity(0))
    assert m["python"] == platform.python_version() and m["numpy"] == np.__version__
    assert isinstance(m["numba"], str) and m["numba"]
    load = m["load_avg"]["fake"]
    if hasattr(os, "getloadavg"):
        for when in ("before", "after"):
            assert len(load[when]) == 3 and all(isinstance(v, numbers.Real) and v >= 0 for v in load[when])
    header = out.splitlines()[:3]
    assert header[0].startswith(f"machine: {m['cpu_model']}")
    assert f"{m['usable_cores']} usable of {m['logical_cores']} cores" in header[0]
    assert m["cpu"] == bench.cpu_identity()
    if m["cpu"]:  # Linux: the family and model and the widest vector extension, in the header
        assert bench.cpu_identity_text(m) in header[0] and m["cpu"]["vector_isa"] in header[0]
    assert f"NumPy {np.__version__}" in header[0] and header[1].startswith("repeats: 2 run(s) per group")
    assert header[2].startswith("load average (1 min) before -> after each group's runs: fake ")


_INTEL = """processor	: 0
vendor_id	: GenuineIntel
cpu family	: 6
model		: 143
model name	: Intel(R) Xeon(R) Platinum 8480+
stepping	: 8
flags		: fpu sse sse2 sse4_2 avx avx2 fma avx512f avx512dq

processor	: 1
vendor_id	: GenuineIntel
cpu family	: 6
model		: 1
flags		: fpu sse
"""

_ZEN1 = """processor	: 0
vendor_id	: AuthenticAMD
cpu family	: 23
model		: 1
model name	: AMD EPYC
stepping	: 2
flags		: fpu sse sse2 ssse3 sse4_1 sse4_2 avx f16c avx2 fma bmi2
"""

_ARM = """processor	: 0
BogoMIPS	: 243.75
Features	: fp asimd evtstrm aes pmull sha1 sha2 crc32 atomics fphp asimdhp sve
CPU implementer	: 0x41
CPU architecture: 8
CPU variant	: 0x1
CPU part	: 0xd40
"""


@pytest.mark.parametrize("text, expected, shown", [
    (_INTEL, {"vendor": "GenuineIntel", "family": "6", "model": "143", "stepping": "8", "vector_isa": "AVX-512"},
     "GenuineIntel family 6 model 143 stepping 8, AVX-512"),
    (_ZEN1, {"vendor": "AuthenticAMD", "family": "23", "model": "1", "stepping": "2", "vector_isa": "AVX2"},
     "AuthenticAMD family 23 model 1 stepping 2, AVX2"),
    (_ARM, {"vendor": "0x41", "family": "8", "model": "0xd40", "stepping": "0x1", "vector_isa": "SVE"},
     "0x41 family 8 model 0xd40 stepping 0x1, SVE"),
    ("processor\t: 0\nflags\t\t: fpu\n", {"vector_isa": "unknown"}, "unknown"),
    ("", {}, ""),
])
def test_cpu_identity_tells_cpus_of_one_model_name_apart(text, expected, shown):
    """The first processor's vendor, family, model, stepping and widest vector extension (the "model name" alone,
    "AMD EPYC", covers a Zen 1 with AVX2 and a Zen 4 with AVX-512), and the header's text of them."""
    ident = bench.cpu_identity(text)
    assert ident == expected
    assert bench.cpu_identity_text({"cpu": ident}) == shown
