"""Paper 003's benchmark group: the Monte Carlo figures it prints add up, and the step-cost figures are measured."""

from workbench_papers.paper003 import bench as bench_paper003
from workbench_papers.paper003 import recipe

SMALL = {**recipe.SIZES["quick"], "runs": 8, "chunk": 4, "reference_runs": 2, "steps": 20}


def test_paper003_monte_carlo_figures_add_up():
    out = bench_paper003.monte_carlo_wall_time("quick", values=SMALL)
    assert out["mc_runs_per_level"] == 8 and out["mc_filters"] == len(recipe.DEFAULT_FILTERS)
    assert out["mc_reference_runs_per_level"] == 2
    rows = list(recipe.DEFAULT_FILTERS) + [recipe.PREVIOUS["label"], recipe.REFERENCE["label"]]
    per_row = [out[f"mc_filter_s[{name}]"] for name in rows]
    assert all(s > 0 for s in per_row) and sum(per_row) <= out["mc_wall_s"]
    assert out["mc_crpf_backend"] in ("numba", "taichi")
    assert out["mc_load_average_1min_before"] >= 0
    assert "target_mc_wall_s" not in out  # the target is about the full size only


def test_crpf_step_cost_figures():
    out = bench_paper003.crpf_step_cost(repeat=2, budget=3000)
    for n in recipe.CRPF_PARTICLES:
        prev, paper = out[f"step_ns_per_particle[previous, N={n}]"], out[f"step_ns_per_particle[paper, N={n}]"]
        assert prev > 0 and paper > 0
        assert out[f"step_ratio_paper_over_previous[N={n}]"] == paper / prev
    worst = max(out[f"step_ratio_paper_over_previous[N={n}]"] for n in recipe.CRPF_PARTICLES)
    assert out["measured_crpf_step_ratio"] == worst
    assert out["met_crpf_step_ratio"] == (worst <= bench_paper003.STEP_TARGET_RATIO)
    assert out["target_crpf_step_ratio"] == f"<= {bench_paper003.STEP_TARGET_RATIO:g}"
