"""Paper 002: bistatic range / range-rate Kalman tracking of a drone with a DTV passive radar.

Pipeline (detection level, every Monte Carlo run at once)::

    drone truth (ENU) --dtv-pbr--> target candidate [R, Rdot] with P_D
                      --pbr-false-alarms--> zero-Doppler residue + CFAR false alarms (density from the Pfa)
                      --pbr-zero-doppler--> drop |f_D| < 1 bin
                      --NN tracker + filter ("kf" by default) on [R, Rdot]--> track

and the ablation: the same candidates read as a monostatic radial velocity ``v = lambda f_D / 2`` in a
range-velocity model.  The signal level (reference + surveillance samples, ECA, CAF, CA-CFAR) runs two scenes:
the brief's benign one (the paper's row) and a demanding one (ATSC 8-VSB illuminator, direct path +60 dB,
clutter to 17.5 km, reference multipath and its cleaning, a CPI of 0.5 s as at the detection level).  Choices where the paper is silent are in
:data:`.scenario.NOTES` and ``docs/paper002.md``; the criteria, their statistics and the tuning rule are fixed there
before the results.

This module only wires the package's parts into :data:`RECIPE`: :mod:`.scenario` (constants, the declared unknown,
the flights and the detection level's candidates, the notes), :mod:`.methods` (the NN trackers and the ablation's
reading), :mod:`.tuning` (the restart delay's rule), :mod:`.tasks`, :mod:`.judging` (the statistics and the
criteria), :mod:`.tables` and :mod:`.figures`; the signal level is :mod:`.signal` (with :mod:`.atsc` and
:mod:`.fold`).
"""

from __future__ import annotations

from workbench.specs import RecipeSpec

from .figures import FIGURES
from .judging import criteria
from .scenario import FALSE_ALARMS, NOTES, PAPER, PUBLISHED, TUNING_RUNS
from .tables import TABLES
from .tasks import tasks

RECIPE = RecipeSpec(
    paper=PAPER,
    title="Bistatic range / range-rate Kalman filter tracking, DTV passive radar (synthetic substitute)",
    # signal_frames / demanding_frames: the signal-level series, one run each, read by table 2 only (no criterion,
    # no timing: the real-time factor is the benchmark's, timed on the chain alone).  A frame is a whole
    # synthesised CPI (0.8 s of CPU for the benign scene's 2.5 M samples, 1.9 s for the demanding scene's 5 M with
    # 600 taps), so the series are as long as the table's point needs: 20 s of flight (40 frames) shows NN tracking
    # the benign scene's candidates, 10 s (20 frames) that 600 taps find the target frame after frame
    sizes={"quick": {"runs": 500, "frames": 120, "signal_frames": 1, "demanding_frames": 1,
                     "tuning_runs": TUNING_RUNS["quick"]},
           "full": {"runs": 3000, "frames": 120, "signal_frames": 40, "demanding_frames": 20,
                    "tuning_runs": TUNING_RUNS["full"]}},
    tasks=tasks,
    figures=FIGURES,
    tables=TABLES,
    criteria=criteria,
    unknowns=(FALSE_ALARMS,),
    default_filters=("kf",),
    published=PUBLISHED,
    notes=NOTES,
)
