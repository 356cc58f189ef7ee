"""The ``report`` benchmark group measures its child's peak memory: checked on a child of known size."""

import pytest

from workbench_papers import report_bench

FAKE = ("import sys, numpy as np; a = np.ones(300 * 2**20 // 8); a += 1; "
        "print('paper 900: fake, 0.1 s'); print('paper 901: fake, 0.1 s'); sys.exit(int(a[0]) - 2)")


def test_peak_memory_is_the_childs_and_the_target_is_declared(monkeypatch):
    import numpy as np

    # the calling process's own memory (a 900 MiB ballast here, the test session's in CI) must not count: a child
    # forked from a big process inherits that process's peak in getrusage
    ballast = np.ones(900 * 2**20 // 8)
    ballast += 1
    monkeypatch.setattr(report_bench, "_MAIN", FAKE)
    out = report_bench.bench(quick=True)
    del ballast
    # the child held a 300 MiB array: its peak is at least that, and far below the target
    assert 300 / 1024 <= out["measured_report_peak_memory_gib"] < 0.75
    assert out["target_report_peak_memory_gib"] == "<= 1.5" and out["met_report_peak_memory_gib"] is True
    assert out["papers"] == "paper 900, paper 901" and out["size"] == "quick"


def test_a_failing_report_fails_the_group(monkeypatch):
    monkeypatch.setattr(report_bench, "_MAIN", "import sys; print('boom', file=sys.stderr); sys.exit(3)")
    with pytest.raises(RuntimeError, match="exit 3.*boom"):
        report_bench.bench(quick=True)


def test_the_full_size_declares_the_main_job_s_wall_target_and_judges_it(monkeypatch):
    monkeypatch.setattr(report_bench, "_MAIN", "import time; time.sleep(0.2); print('paper 900: fake, 0.1 s')")
    quick = report_bench.bench(quick=True)
    assert "target_report_wall_s" not in quick and "target_report_wall_limit_s" not in quick  # a smoke run: none
    monkeypatch.setattr(report_bench, "WALL_TARGET_S", 0.1)  # a child that sleeps 0.2 s misses a 0.1 s target
    monkeypatch.setattr(report_bench, "WALL_LIMIT_S", 3600.0)  # and meets a one-hour limit
    full = report_bench.bench(quick=False)
    assert full["target_report_wall_s"] == "<= 0.1" and full["measured_report_wall_s"] >= 0.2
    assert full["met_report_wall_s"] is False
    assert full["target_report_wall_limit_s"] == "<= 3600" and full["met_report_wall_limit_s"] is True
    monkeypatch.setattr(report_bench, "WALL_TARGET_S", 3600.0)
    monkeypatch.setattr(report_bench, "WALL_LIMIT_S", 0.1)
    full = report_bench.bench(quick=False)
    assert full["met_report_wall_s"] is True and full["met_report_wall_limit_s"] is False
