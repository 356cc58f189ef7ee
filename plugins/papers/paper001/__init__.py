"""Paper 001: Hough-transform clutter removal and CMKF-L multi-target tracking (active sonar).

The paper's own plugin package: its scenario constants, declared unknowns and simulation (:mod:`.scenario`), tasks
(:mod:`.tasks`), figures (:mod:`.figures`), tables (:mod:`.tables`) and "reproduced if" criteria (:mod:`.judging`),
wired into the report recipe by :mod:`.recipe`; its benchmarks (:mod:`.bench`) and its tests (``tests/``).
It registers through the ``workbench`` entry-point group exactly as a third-party package would, and reaches the
sensors, clutter models and filters it compares only through the plugin host.  Choices where the paper is silent
are in ``docs/paper001.md``.
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
    return [BenchmarkSpec("paper001", "paper 001: one ping of 10^4 detections through the Hough remover and the tracker "
                                      "(wide area; saturated), and the quick report's compute", bench.bench)]
