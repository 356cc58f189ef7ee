"""The ``crpf-step`` benchmark group (the CRPF's fused step per particle, moved here from paper 003's group): the
worst ratio and its target on hand-made timings with hand-computed values, and the real measurement once for its
form."""

import math

import pytest

from workbench_filters.crpf import bench as crpf_bench


@pytest.mark.parametrize("paper_300, ratio_300, worst, met",
                         [(10.0, 1.25, 1.25, False), (9.6, 1.2, 1.2, True), (8.0, 1.0, 1.1, True)])
def test_step_ratios_the_worst_and_the_target(monkeypatch, paper_300, ratio_300, worst, met):
    # ns per particle, previous / paper: N=100 10 / 11 (1.1), N=300 8 / paper_300, N=500 4 / 4.4 (1.1)
    times = {100: {"previous": 10.0, "paper": 11.0}, 300: {"previous": 8.0, "paper": paper_300},
             500: {"previous": 4.0, "paper": 4.4}}
    monkeypatch.setattr(crpf_bench, "_step_times", lambda budget, repeat, seed: times)
    out = crpf_bench.crpf_step_cost(repeat=3, budget=3000)
    assert out["step_ns_per_particle[previous, N=300]"] == 8.0
    assert out["step_ns_per_particle[paper, N=300]"] == paper_300
    assert out["step_ratio_paper_over_previous[N=100]"] == pytest.approx(1.1, rel=1e-15)
    assert out["step_ratio_paper_over_previous[N=300]"] == pytest.approx(ratio_300, rel=1e-15)
    assert out["step_ratio_paper_over_previous[N=500]"] == pytest.approx(1.1, rel=1e-15)
    assert out["measured_crpf_step_ratio"] == pytest.approx(worst, rel=1e-15)
    assert out["met_crpf_step_ratio"] is met  # target <= 1.2, the boundary included
    assert out["target_crpf_step_ratio"] == "<= 1.2"


def test_crpf_step_cost_measures_both_configurations():
    out = crpf_bench.crpf_step_cost(repeat=2, budget=3000)
    for n in crpf_bench.STEP_PARTICLES:
        for config in ("previous", "paper"):
            value = out[f"step_ns_per_particle[{config}, N={n}]"]
            assert math.isfinite(value) and value > 0
    assert isinstance(out["met_crpf_step_ratio"], bool) and out["measured_crpf_step_ratio"] > 0
