"""Paper 003: EKF, UKF, CDKF, their square-root forms and the cost-reference particle filter under unknown noise.

The paper's own plugin package: its scenario (:mod:`.scenario`: constants, the two readings of the bearing unit,
data streams, the lost rule, the declared unknown delta, the published claims and notes), tasks (:mod:`.tasks`),
figures (:mod:`.figures`), tables (:mod:`.tables`), "reproduced if" criteria (:mod:`.judging`), the recipe that
only wires them (:mod:`.recipe`), its benchmarks (:mod:`.bench`) and its tests (``tests/``).
It registers through the ``workbench`` entry-point group exactly as a third-party package would, and reaches the
sensors, clutter models and filters it compares only through the plugin host.  Choices where the paper is silent
are in ``docs/paper003.md``.
"""

from workbench import hookimpl
from workbench.specs import BenchmarkSpec

from . import bench, bench_dask
from .recipe import RECIPE


@hookimpl
def workbench_report_recipes():
    return [RECIPE]


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("paper003", "paper 003: the full Monte Carlo with the reference PF and the UKF against FilterPy "
                                      "(the CRPF step per particle is the crpf-step group)", bench.bench),
            BenchmarkSpec("dask", "paper 003: the full Monte Carlo in-process against a 2-worker local Dask cluster",
                          bench_dask.bench)]
