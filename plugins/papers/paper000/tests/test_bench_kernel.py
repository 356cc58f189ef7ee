"""The kernel-throughput part of paper 000's benchmark group: every backend and precision on the arch the runner
sets (Taichi on the CPU arch here: the code path that ``workbench bench --arch cuda`` takes on a GPU), its targets and
its curves.  Nothing here is timed: the real runs are checked for their form only, and the arithmetic that turns
timings into figures on hand-made timings with hand-computed values."""

import math

import pytest

from workbench.bench.plots import check_curve
from workbench.bench.targets import collect_targets
from workbench.kernels.backend import numba_available, using
from workbench_papers.paper000 import bench


def test_kernel_throughput_rows_cover_every_backend_and_precision_on_the_asked_arch():
    backends = ["taichi"] + (["numba"] if numba_available() else [])
    with using("cpu"):
        rows = bench.kernel_throughput((300, 1000), (5, 20), backends, limit=1e9, repeats=1, numpy_cap=2000)
    assert [(r["N"], r["M"]) for r in rows] == [(300, 5), (300, 20), (1000, 5), (1000, 20)]
    for row in rows:
        for be in backends:
            for key in (f"{be}_pairs_per_s", f"{be}_float32_pairs_per_s", f"{be}_vs_naive",
                        f"{be}_float32_percent_of_limit", f"{be}_float32_over_float64"):
                assert math.isfinite(row[key]) and row[key] > 0, key
    # 2000 pairs at most for the NumPy reference: all 300 particles at M = 5 and 20, 400 and 100 of 1000
    assert [r["numpy_subset_particles"] for r in rows] == [300, 100, 400, 100]


def test_kernel_throughput_arithmetic_on_hand_made_timings(monkeypatch):
    seconds = {"numba": 2e-4, "numba_float32": 1e-4, "taichi": 1e-3, "taichi_float32": 4e-4}
    monkeypatch.setattr(bench, "_interleaved_best", lambda fns, repeats, settle_after=(): {k: seconds[k] for k in fns})
    called = []
    monkeypatch.setattr(bench, "tbd_log_weight_sums_reference", lambda *args: called.append("reference"))
    monkeypatch.setattr(bench, "naive_log_weight_sums", lambda *args: called.append("naive"))

    def best_time(fn, repeats):
        fn()
        return {"reference": 0.01, "naive": 0.1}[called[-1]]

    monkeypatch.setattr(bench, "_best_time", best_time)
    (row,) = bench.kernel_throughput((300,), (5,), ["taichi", "numba"], limit=1e9, repeats=1, numpy_cap=1000)
    # 1500 pairs; the NumPy ones on 1000 // 5 = 200 particles, 1000 pairs: 1e5 pairs/s (reference), 1e4 (naive)
    assert row["numpy_subset_particles"] == 200
    assert row["reference_pairs_per_s"] == pytest.approx(1e5) and row["naive_pairs_per_s"] == pytest.approx(1e4)
    expected = {"numba_pairs_per_s": 7.5e6, "numba_float32_pairs_per_s": 1.5e7, "taichi_pairs_per_s": 1.5e6,
                "taichi_float32_pairs_per_s": 3.75e6, "numba_vs_naive": 750.0, "numba_vs_reference": 75.0,
                "numba_percent_of_limit": 0.75, "numba_float32_percent_of_limit": 1.5, "taichi_vs_naive": 150.0,
                "taichi_float32_vs_reference": 37.5, "numba_float32_over_float64": 2.0,
                "taichi_float32_over_float64": 2.5}
    for key, value in expected.items():
        assert row[key] == pytest.approx(value, rel=1e-12), key


def test_paired_target_rates_arithmetic_on_hand_made_timings(monkeypatch):
    times = {"float64": 0.01, "float32": 0.004, "dgemm": 0.5}
    monkeypatch.setattr(bench, "_interleaved_best", lambda fns, repeats, settle_after=(): {k: times[k] for k in fns})
    paired = bench.paired_target_rates("numpy", repeats=1, size=(500, 8))
    # 4000 pairs in 10 ms and 4 ms; 2 x 1500^3 flops in 0.5 s = 1.35e10 flop/s, at 44 flops a pair 3.068e8 pairs/s
    assert paired["float64_pairs_per_s"] == pytest.approx(4e5) and paired["float32_pairs_per_s"] == pytest.approx(1e6)
    assert paired["dgemm_flops"] == pytest.approx(1.35e10)
    assert paired["limit_pairs_per_s"] == pytest.approx(3.0681818e8, rel=1e-7)


def test_taichi_peak_rate_runs_on_the_cpu_arch():
    with using("cpu"):
        out = bench.taichi_peak_flops(repeats=1, elements=1 << 12, rounds=20)
    assert math.isfinite(out["peak_flops"]) and out["peak_flops"] > 0


def _row(f64=1.0e9, f32=2.6e9, naive=1e7):
    return {"N": 100_000, "M": 1_000, "numba_pairs_per_s": f64, "numba_float32_pairs_per_s": f32,
            "numba_percent_of_limit": 100 * f64 / 1.8e9, "numba_vs_naive": f64 / naive,
            "numba_float32_over_float64": f32 / f64}


def test_kernel_targets_are_declared_in_the_runner_convention():
    figures = bench.kernel_targets([_row()], "numba")
    rows = {t.name: t for t in collect_targets({"paper000": {"kernel_targets": figures}}, quick=False)}
    assert set(rows) == {"kernel_targets.float64_percent_of_limit", "kernel_targets.float32_over_float64",
                         "kernel_targets.float64_vs_naive"}
    assert rows["kernel_targets.float64_percent_of_limit"].target == ">= 50"
    assert rows["kernel_targets.float64_percent_of_limit"].verdict == "met"  # 1.0e9 of 1.8e9: 56 %
    assert rows["kernel_targets.float32_over_float64"].verdict == "met"
    slow = {t.name: t.verdict for t in collect_targets(
        {"paper000": {"kernel_targets": bench.kernel_targets([_row(f64=0.8e9, f32=1.6e9)], "numba")}}, quick=False)}
    assert slow["kernel_targets.float64_percent_of_limit"] == "not met"
    assert slow["kernel_targets.float32_over_float64"] == "not met"  # 2.0 < 2.5
    assert bench.kernel_targets([_row()], "taichi") == {}  # no figures for that backend: no target claimed


def test_kernel_curves_draw_each_backend_and_precision_beside_the_peers_and_the_limit():
    rows = [dict(_row(), N=n, M=m, taichi_pairs_per_s=1e8, taichi_float32_pairs_per_s=2e8,
                 reference_pairs_per_s=3e6, naive_pairs_per_s=1e7)
            for n in (1_000, 100_000) for m in (10, 1_000)]
    figs = bench.kernel_curves(rows, ["taichi", "numba"], limit=2e9)
    assert [f["id"] for f in figs] == ["kernel_vs_N", "kernel_vs_M"]
    for fig in figs:
        check_curve(fig)
        roles = [s["role"] for s in fig["series"]]
        assert roles.count("ours") == 4 and roles.count("peer") == 1 and roles.count("limit") == 1
        assert next(s for s in fig["series"] if s["role"] == "limit")["y"] == [2e9]
    assert figs[0]["series"][0]["x"] == [1_000, 100_000]  # against N at M = 1000
    assert figs[1]["series"][0]["x"] == [10, 1_000]  # against M at N = 10^5


def test_the_targets_case_is_timed_in_turn_with_the_peak_rate():
    backend = "numba" if numba_available() else "taichi"
    with using("cpu"):
        paired = bench.paired_target_rates(backend, repeats=1, size=(500, 8))
    assert (paired["N"], paired["M"], paired["backend"]) == (500, 8, backend)
    for key in ("float64_pairs_per_s", "float32_pairs_per_s", "dgemm_flops", "limit_pairs_per_s"):
        assert math.isfinite(paired[key]) and paired[key] > 0
    # the targets take the paired figures where given
    row = dict(_row(), N=100_000, M=1_000)
    fixed = dict(paired, float64_pairs_per_s=1.0e9, float32_pairs_per_s=2.4e9, limit_pairs_per_s=2.5e9)
    figures = bench.kernel_targets([row], "numba", fixed)
    assert figures["measured_float64_percent_of_limit"] == pytest.approx(40.0)
    assert figures["measured_float32_over_float64"] == pytest.approx(2.4)
    assert not figures["met_float64_percent_of_limit"] and not figures["met_float32_over_float64"]
    assert "timed in turn" in figures["note_float64_percent_of_limit"]
