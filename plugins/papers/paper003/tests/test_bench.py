"""Paper 003's benchmark group: the Monte Carlo figures it prints add up."""

from workbench_papers.paper003 import bench as bench_paper003
from workbench_papers.paper003 import recipe


def test_paper003_monte_carlo_figures_add_up():
    out = bench_paper003.monte_carlo_wall_time("quick")
    assert out["mc_runs_per_level"] == recipe.SIZES["quick"]["runs"] and out["mc_filters"] == len(recipe.DEFAULT_FILTERS)
    per_filter = [out[f"mc_filter_s[{name}]"] for name in recipe.DEFAULT_FILTERS]
    assert all(s > 0 for s in per_filter) and sum(per_filter) <= out["mc_wall_s"]
    assert out["mc_crpf_backend"] in ("numba", "taichi")
    assert "mc_target_met" not in out  # the target is about the full size only
