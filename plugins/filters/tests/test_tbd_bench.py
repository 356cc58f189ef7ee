"""The ``tbd-weights`` benchmark group (the tbd-pf filter's weight kernel, moved here from paper 000's group): every
backend and precision on the arch the runner sets (Taichi on the CPU arch here: the code path that ``workbench bench
--arch cuda`` takes on a GPU), its limits, targets and curves.  Nothing here is timed: the real runs are checked for
their form only, the arithmetic that turns timings into figures on hand-made timings with hand-computed values, the
peak loop's work against its closed form, and the count of multiplies per pair against a count by hand."""

import math

import numpy as np
import pytest

from workbench.bench.plots import check_curve
from workbench.bench.targets import collect_targets
from workbench.kernels.backend import numba_available, using
from workbench_filters.tbd import bench

LIMITS = {"float64": 1e9, "float32": 2e9}


def test_kernel_throughput_rows_cover_every_backend_and_precision_on_the_asked_arch():
    backends = ["taichi"] + (["numba"] if numba_available() else [])
    with using("cpu"):
        rows = bench.kernel_throughput((300, 1000), (5, 20), backends, limits={"float64": 1e12, "float32": 1e12},
                                       repeats=1, numpy_cap=2000)
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
    monkeypatch.setattr(bench, "_interleaved_best", lambda fns, repeats: {k: seconds[k] for k in fns})
    called = []
    monkeypatch.setattr(bench, "tbd_log_weight_sums_reference", lambda *args: called.append("reference"))
    monkeypatch.setattr(bench, "naive_log_weight_sums", lambda *args: called.append("naive"))

    def best_time(fn, repeats):
        fn()
        return {"reference": 0.01, "naive": 0.1}[called[-1]]

    monkeypatch.setattr(bench, "_best_time", best_time)
    (row,) = bench.kernel_throughput((300,), (5,), ["taichi", "numba"], limits=LIMITS, repeats=1, numpy_cap=1000)
    # 1500 pairs; the NumPy ones on 1000 // 5 = 200 particles, 1000 pairs: 1e5 pairs/s (reference), 1e4 (naive)
    assert row["numpy_subset_particles"] == 200
    assert row["reference_pairs_per_s"] == pytest.approx(1e5) and row["naive_pairs_per_s"] == pytest.approx(1e4)
    # float64 against 1e9 pairs/s, float32 against 2e9
    expected = {"numba_pairs_per_s": 7.5e6, "numba_float32_pairs_per_s": 1.5e7, "taichi_pairs_per_s": 1.5e6,
                "taichi_float32_pairs_per_s": 3.75e6, "numba_vs_naive": 750.0, "numba_vs_reference": 75.0,
                "numba_percent_of_limit": 0.75, "numba_float32_percent_of_limit": 0.75, "taichi_vs_naive": 150.0,
                "taichi_float32_percent_of_limit": 0.1875, "taichi_float32_vs_reference": 37.5,
                "numba_float32_over_float64": 2.0, "taichi_float32_over_float64": 2.5}
    for key, value in expected.items():
        assert row[key] == pytest.approx(value, rel=1e-12), key


def test_a_share_above_the_limit_reads_limit_invalid_never_a_number_above_100():
    assert bench.share_of_limit(0.5e9, 1e9) == pytest.approx(50.0)
    assert bench.share_of_limit(1e9, 1e9) == pytest.approx(100.0)
    assert bench.share_of_limit(1.01e9, 1e9) == "limit invalid"
    row = {"N": 100_000, "M": 1_000, "numba_pairs_per_s": 1.0e9, "numba_vs_naive": 100.0}
    paired = {"rounds": 3, "float64_pairs_per_s": 1.0e9, "float32_pairs_per_s": 2.6e9, "float64_multiplies_per_pair": 18,
              "float32_multiplies_per_pair": 14, "float64_limit_pairs_per_s": 0.9e9, "float32_limit_pairs_per_s": 4e9}
    figures = bench.kernel_targets([row], "numba", paired)
    assert figures["measured_float64_percent_of_limit"] == "limit invalid"
    assert figures["met_float64_percent_of_limit"] == "limit invalid"
    assert figures["measured_float32_percent_of_limit"] == pytest.approx(65.0)  # 2.6e9 of 4e9
    verdicts = {t.name: t.verdict for t in collect_targets({"tbd-weights": {"kernel_targets": figures}}, quick=False)}
    assert verdicts["kernel_targets.float64_percent_of_limit"] == "limit invalid"
    assert verdicts["kernel_targets.float32_percent_of_limit"] == "met"
    with using("cpu"):
        rows = bench.kernel_throughput((300,), (5,), ["taichi"], limits={"float64": 1.0, "float32": 1.0}, repeats=1,
                                       numpy_cap=100)
    assert rows[0]["taichi_percent_of_limit"] == rows[0]["taichi_float32_percent_of_limit"] == "limit invalid"


def test_multiplies_per_pair_are_read_from_the_kernels():
    # counted by hand from tbd_weights_numba.py (two pairs per iteration, counted once): float64: the log-weight's
    # five multiply-adds, 13 in Estrin's degree-11 polynomial of 2^f (f^2, f^4, six pairs c f + c', three by f^2,
    # two by f^4), one scaling by 2^n, one rescaling of the sum (s * e + 1) -> 20; float32: three squares, a_m times
    # their sum, beta2 * dv * dv (2), 8 in Estrin's degree-6 polynomial (f^2, f^4, s0 f^2, three c f, one by f^2,
    # one by f^4), one scaling, one rescaling -> 16
    assert bench.multiplies_per_pair("float64") == 20
    assert bench.multiplies_per_pair("float32") == 16


def test_the_count_follows_a_changed_kernel_and_refuses_one_it_cannot_read():
    source = (
        "def helper(x):\n    return x * 2.0 * x\n\n"
        "def kernel(a, b, out):\n"
        "    for t in range(2):\n"
        "        y = a[0] * 3.0\n"
        "        for m in range(3):\n"
        "            w = b[m] * 4.0\n"
        "            for j in range(4):\n"
        "                out[j] += a[j] * w + helper(a[j])\n"
        "        for j in range(4):\n"
        "            out[j] = out[j] * 0.5\n")
    assert bench.multiplies_per_pair("float64", source) == 3  # a[j] * w, and helper's two
    assert bench.multiplies_per_pair("float64", source.replace("+ helper(a[j])", "+ helper(a[j]) * a[j]")) == 4
    # two pairs per iteration: the call sites of the pair function divide the loop's count
    two = ("def log2_weight(a, j):\n    return a[j] * 3.0\n\n"
           "def kernel(a, out):\n"
           "    for t in range(2):\n"
           "        for m in range(3):\n"
           "            for j in range(2):\n"
           "                out[j] = log2_weight(a, j) * 2.0\n"
           "                out[j + 2] = log2_weight(a, j + 2) * 2.0\n")
    assert bench.multiplies_per_pair("float64", two) == 2
    with pytest.raises(ValueError, match="2 pairs per iteration"):
        bench.multiplies_per_pair("float64", two.replace("log2_weight(a, j + 2) * 2.0", "log2_weight(a, j + 2)"))
    with pytest.raises(ValueError, match="expected one loop over particles"):
        bench.multiplies_per_pair("float64", "def kernel(a):\n    for t in range(2):\n        a[t] = a[t] * 2\n")


@pytest.mark.skipif(not numba_available(), reason="the peak loop is a Numba kernel")
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_the_peak_loop_does_the_multiply_adds_it_counts(precision):
    # eight multiply-adds per element and round: after r rounds each accumulator is the affine recursion
    # v <- m v + c applied 8 r times, v_n = m^n (v_0 - c / (1 - m)) + c / (1 - m)
    run, fmas = bench._fma_runner(precision, threads=2, lanes=16, rounds=3)
    assert fmas == 2 * bench.PEAK_ACCUMULATORS * 16 * 8 * 3
    run()
    loop = bench._peak_kernel()
    dtype = np.dtype(precision).type
    acc = np.ones((2, bench.PEAK_ACCUMULATORS, 16), dtype)
    m, c = 0.999999, 1e-7
    loop(acc, dtype(m), dtype(c), 3)
    fixed = c / (1.0 - m)
    expected = m ** 24 * (1.0 - fixed) + fixed
    np.testing.assert_allclose(acc, expected, rtol=1e-12 if precision == "float64" else 1e-5)
    assert bench.fma_peak(precision, repeats=1, threads=1) > 0


def test_paired_target_rates_arithmetic_on_hand_made_timings(monkeypatch):
    times = {"float64": 0.01, "float32": 0.004, "peak_float64": 0.5, "peak_float32": 0.25}
    monkeypatch.setattr(bench, "_interleaved_best", lambda fns, repeats: {k: times[k] for k in fns})
    monkeypatch.setattr(bench, "_fma_runner", lambda precision: (lambda: None, 1e9))
    paired = bench.paired_target_rates("numpy", repeats=1, size=(500, 8), peak_repeats=2)
    # 4000 pairs in 10 ms and 4 ms; the peak loop: 1e9 multiply-adds in 0.5 s and 0.25 s -> 2e9 and 4e9 per second,
    # over 20 and 16 multiplies per pair -> 1e8 and 2.5e8 pairs/s
    assert paired["float64_pairs_per_s"] == pytest.approx(4e5) and paired["float32_pairs_per_s"] == pytest.approx(1e6)
    assert paired["float64_fma_per_s"] == pytest.approx(2e9) and paired["float32_fma_per_s"] == pytest.approx(4e9)
    assert paired["float64_limit_pairs_per_s"] == pytest.approx(1e8, rel=1e-7)
    assert paired["float32_limit_pairs_per_s"] == pytest.approx(2.5e8, rel=1e-7)


def test_interleaved_timing_takes_a_callable_s_own_time_where_it_gives_one():
    calls = []
    best = bench._interleaved_best({"plain": lambda: calls.append("plain"),
                                    "own": lambda: calls.append("own") or 123.0}, repeats=3)
    assert calls == ["plain", "own"] * 4  # one warm-up call each, then three rounds in turn
    assert best["own"] == 123.0 and 0 <= best["plain"] < 1.0


def test_taichi_peak_rate_runs_on_the_cpu_arch():
    with using("cpu"):
        for precision in ("float64", "float32"):
            peak = bench.taichi_fma_peak(precision, repeats=1, elements=1 << 12, rounds=20)
            assert math.isfinite(peak) and peak > 0


def _row(f64=1.0e9, f32=2.6e9, naive=1e7):
    return {"N": 100_000, "M": 1_000, "numba_pairs_per_s": f64, "numba_float32_pairs_per_s": f32,
            "numba_percent_of_limit": 100 * f64 / 1.6e9, "numba_float32_percent_of_limit": 100 * f32 / 4e9,
            "numba_vs_naive": f64 / naive, "numba_float32_over_float64": f32 / f64}


def test_kernel_targets_are_declared_in_the_runner_convention():
    figures = bench.kernel_targets([_row()], "numba")
    rows = {t.name: t for t in collect_targets({"tbd-weights": {"kernel_targets": figures}}, quick=False)}
    assert set(rows) == {"kernel_targets.float64_percent_of_limit", "kernel_targets.float32_percent_of_limit",
                         "kernel_targets.float32_over_float64", "kernel_targets.float64_vs_naive"}
    assert rows["kernel_targets.float64_percent_of_limit"].target == ">= 60"
    assert rows["kernel_targets.float64_percent_of_limit"].verdict == "met"  # 1.0e9 of 1.6e9: 62.5 %
    assert rows["kernel_targets.float32_percent_of_limit"].verdict == "met"  # 2.6e9 of 4e9: 65 %
    assert rows["kernel_targets.float32_over_float64"].verdict == "met"
    slow = {t.name: t.verdict for t in collect_targets(
        {"tbd-weights": {"kernel_targets": bench.kernel_targets([_row(f64=0.8e9, f32=1.6e9)], "numba")}},
        quick=False)}
    assert slow["kernel_targets.float64_percent_of_limit"] == "not met"  # 50 %
    assert slow["kernel_targets.float32_percent_of_limit"] == "not met"  # 40 %
    assert slow["kernel_targets.float32_over_float64"] == "not met"  # 2.0 < 2.5
    assert bench.kernel_targets([_row()], "taichi") == {}  # no figures for that backend: no target claimed


def test_kernel_curves_draw_each_backend_and_precision_beside_the_peers_and_the_limits():
    rows = [dict(_row(), N=n, M=m, taichi_pairs_per_s=1e8, taichi_float32_pairs_per_s=2e8,
                 reference_pairs_per_s=3e6, naive_pairs_per_s=1e7)
            for n in (1_000, 100_000) for m in (10, 1_000)]
    figs = bench.kernel_curves(rows, ["taichi", "numba"], limits={"float64": 2e9, "float32": 5e9})
    assert [f["id"] for f in figs] == ["kernel_vs_N", "kernel_vs_M"]
    for fig in figs:
        check_curve(fig)
        roles = [s["role"] for s in fig["series"]]
        assert roles.count("ours") == 4 and roles.count("peer") == 1 and roles.count("limit") == 2
        assert [s["y"] for s in fig["series"] if s["role"] == "limit"] == [[2e9], [5e9]]
    assert figs[0]["series"][0]["x"] == [1_000, 100_000]  # against N at M = 1000
    assert figs[1]["series"][0]["x"] == [10, 1_000]  # against M at N = 10^5


def test_the_targets_case_is_timed_in_turn_with_the_peak_loops():
    backend = "numba" if numba_available() else "taichi"
    if not numba_available():
        pytest.skip("the peak loop is a Numba kernel")
    with using("cpu"):
        paired = bench.paired_target_rates(backend, repeats=1, size=(500, 8), peak_repeats=1)
    assert (paired["N"], paired["M"], paired["backend"]) == (500, 8, backend)
    for pr in ("float64", "float32"):
        for key in (f"{pr}_pairs_per_s", f"{pr}_fma_per_s", f"{pr}_limit_pairs_per_s"):
            assert math.isfinite(paired[key]) and paired[key] > 0
    # the targets take the paired figures where given
    fixed = dict(paired, float64_pairs_per_s=1.0e9, float32_pairs_per_s=2.4e9, float64_limit_pairs_per_s=2.5e9,
                 float32_limit_pairs_per_s=3e9)
    figures = bench.kernel_targets([_row()], "numba", fixed)
    assert figures["measured_float64_percent_of_limit"] == pytest.approx(40.0)
    assert figures["measured_float32_percent_of_limit"] == pytest.approx(80.0)
    assert figures["measured_float32_over_float64"] == pytest.approx(2.4)
    assert not figures["met_float64_percent_of_limit"] and figures["met_float32_percent_of_limit"]
    assert "timed in turn" in figures["note_float64_percent_of_limit"]
