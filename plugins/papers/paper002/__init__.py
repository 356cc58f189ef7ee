"""Paper 002: Bistatic range / range-rate tracking with a DTV passive radar.

The paper's own plugin package: its scenario constants, tasks, figures, tables and "reproduced if" criteria
(:mod:`.recipe`), the science only this paper uses, its benchmarks (:mod:`.bench`) and its tests (``tests/``).
It registers through the ``workbench`` entry-point group exactly as a third-party package would, and reaches the
sensors, clutter models and filters it compares only through the plugin host.  Choices where the paper is silent
are in ``docs/paper002.md``.
"""

from workbench import hookimpl
from workbench.specs import BenchmarkSpec

from . import bench
from .recipe import RECIPE


@hookimpl
def workbench_report_recipes():
    return [RECIPE]


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("paper002", "paper 002: one frame of the signal chain (ECA + CAF + CFAR) end to end, stage by "
                          "stage, and its real-time factor (target >= 2 in the demanding scene)", bench.bench)]
