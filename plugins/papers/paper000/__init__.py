"""Paper 000: Radar particle filter for track-before-detect (L-band, low SNR, heavy clutter).

The paper's own plugin package: its scenario and declared unknowns (:mod:`.scenario`), tasks (:mod:`.tasks`),
figures (:mod:`.figures`), tables (:mod:`.tables`) and "reproduced if" criteria (:mod:`.judging`), wired into the
recipe by :mod:`.recipe`; the science only this paper uses (:mod:`.methods`, :mod:`.pipeline`, :mod:`.tuning`), its
benchmarks (:mod:`.bench`) and its tests (``tests/``).
It registers through the ``workbench`` entry-point group exactly as a third-party package would, and reaches the
sensors, clutter models and filters it compares only through the plugin host.  Choices where the paper is silent
are in ``docs/paper000.md``.
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
    return [BenchmarkSpec("paper000", "paper 000: the 300-scan method-C scenario, one update's memory and the full "
                                      "report's compute time (the weight kernel is the tbd-weights group)", bench.bench)]
