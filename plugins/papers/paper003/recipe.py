"""Paper 003: EKF, UKF, CDKF, SR-UKF, SR-CDKF and the cost-reference particle filter, range-bearing, unknown noise.

The recipe only wires the package's modules together: the scenario and the declared unknown delta
(:mod:`.scenario`), the tasks (:mod:`.tasks`), the figures (:mod:`.figures`), the tables (:mod:`.tables`) and the
criteria (:mod:`.judging`).
"""

from __future__ import annotations

from workbench.specs import RecipeSpec

from . import judging
from .figures import FIGURES
from .scenario import DELTA, NOTES, PAPER, PUBLISHED
from .tables import TABLES
from .tasks import DEFAULT_FILTERS, SIZES, tasks

RECIPE = RecipeSpec(
    paper=PAPER,
    title="EKF, UKF, CDKF, SR-UKF, SR-CDKF and the cost-reference particle filter under unknown noise",
    sizes=SIZES,
    tasks=tasks,
    figures=FIGURES,
    tables=TABLES,
    criteria=judging.criteria,
    default_filters=DEFAULT_FILTERS,
    published=PUBLISHED,
    notes=NOTES,
    unknowns=(DELTA,),
)
