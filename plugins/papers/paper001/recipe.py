"""Paper 001: Hough-transform clutter removal and CMKF-L multi-target tracking, active sonar, heavy clutter.

Pipeline (brief § 1.1-1.4): the ``active-sonar`` sensor and the ``sonar-poisson`` clutter generator make
Cartesian detections ping by ping; the ``hough`` remover narrows them (or not: "before removal"); the
multi-target tracker :func:`workbench.tracking.run_tracker` runs the chosen filter (``cmkf-l`` by default,
fed the sensor's polar range-bearing view) with M-of-N track management; :mod:`workbench.metrics`
scores confirmed / false tracks, removal rates, continuity and RMSE against the truth.

Rows (*arms*), every one before and after removal on the same detections:

- ``paper`` (primary, judged): the brief's defaults (gate 9.21 with the filter's R, confirm 3 of 5 after
  initiation, delete after 3 misses), the paper's speed-course initial covariance with sigma_v = sigma_c = 1,
  CMKF-L with the paper's R;
- ``paper-mofn``: the paper's M-of-N as it describes it (the two initiation detections count as hits) with R
  matched to the sensor (its stated accuracy): the row with the paper's clutter tracks, drawn in Figs 5, 6, 9
  and 10;
- ``stated`` (principled variant): the same with every detection carrying the sensor's stated accuracy
  (``TrackerConfig.detection_sigma``, read from the sensor's declared model), so CMKF-L's R is that of the
  sensor (the brief's matched-R ablation, done through declared fields);
- ``tuned``: the gate and the deletion rule chosen on tuning runs only, by :data:`TUNING_RULE`;
- ``previous``: the previous settings (global latest-support rule, gate with sigma 2, deletion after 4 misses,
  speed-course prior, initiation detections counted as hits), kept reproducible as an ablation;
- ``min-speed`` (extension, sea-trial surrogate): the paper arm with a minimum-speed test on the tracks.

Runs: ``seeds`` blocks of ``runs`` runs, block ``j`` from seed ``seed + j``; run ``b`` of a block is drawn from
``generator(seed + j, "paper001", scenario, b)`` alone, so every arm, remover variant and size sees the same
detections (quick runs are the first runs of block 0).  Tuning runs come from the stream ``"tuning"``, which
no reported row uses.  The sea trial is not reproducible (data unavailable):
``examples/data/sonar_sea_trial_surrogate.csv`` is a SYNTHETIC SURROGATE written by :func:`write_surrogate`.
Choices where the paper is silent are in :data:`NOTES` and ``docs/paper001.md``.
"""

from __future__ import annotations

from workbench.specs import RecipeSpec

from .figures import FIGURES
from .judging import criteria
from .scenario import DEFAULT_TRACKERS, NOTES, PAPER, PAPER_FILTER, PUBLISHED, SIZES, UNKNOWNS
from .tables import TABLES
from .tasks import tasks

RECIPE = RecipeSpec(
    paper=PAPER,
    title="Hough-transform clutter removal and CMKF-L tracking of an active-sonar target in heavy clutter",
    sizes=SIZES,
    tasks=tasks,
    figures=FIGURES,
    tables=TABLES,
    criteria=criteria,
    default_filters=(PAPER_FILTER,),
    default_trackers=DEFAULT_TRACKERS,
    published=PUBLISHED,
    notes=NOTES,
    unknowns=UNKNOWNS,
)
