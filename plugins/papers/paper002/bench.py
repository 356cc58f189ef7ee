"""Speed of the paper-002 signal level: the cross-ambiguity function of one frame, computed and searched.

``bench(quick)`` times, on one 0.25 s CPI of 10 MHz complex baseband (2.5 M samples), 0-3 km bistatic
range (102 bins) and +-50 m/s (61 Doppler bins):

- ``caf_s``: the batches-algorithm CAF (:func:`workbench.pcl.caf_batches`);
- ``cfar_s``: the 2-D CA-CFAR search and candidate extraction (:func:`workbench.pcl.cfar_candidates`);
- ``realtime_factor = frame duration / (caf_s + cfar_s)`` (> 1: faster than the data arrive);

and, for information, ECA (``eca_s``), the signal synthesis (``synthesis_s``) and the quick report's
whole signal-level task (``signal_task_s``: synthesis, two CAFs, ECA and CFAR of one frame).
Timings are medians over ``repeats`` runs after a warm-up (:func:`workbench.bench.median_time`).  Run ``python -m workbench.bench_paper002 [--full]``.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from workbench.bench import median_time
from .signal import PCLConfig, SignalScene, caf_batches, cfar_candidates, eca, frame_signals
from workbench.rng import generator

__all__ = ["bench"]


def bench(quick: bool = True) -> dict:
    """Time one frame's CAF + CFAR (see the module docstring); returns the numbers as a dict."""
    repeats = 3 if quick else 10
    config, scene = PCLConfig(), SignalScene()
    t0 = time.perf_counter()
    ref, surv = frame_signals(np.array([[600.0, -8.0]]), generator(0, "bench002"), config, scene)
    synth_s = time.perf_counter() - t0
    clean, _ = eca(surv, ref, config.eca_taps)
    caf = caf_batches(clean, ref, config)
    cands, _ = cfar_candidates(caf, config)
    eca_s = median_time(lambda: eca(surv, ref, config.eca_taps), repeats, warmup=0)
    caf_s = median_time(lambda: caf_batches(clean, ref, config), repeats)
    cfar_s = median_time(lambda: cfar_candidates(caf, config), repeats)
    result = {
        "frame_s": config.samples / config.sample_rate,
        "samples": config.samples,
        "range_bins": config.lags,
        "doppler_bins": 2 * config.doppler_half + 1,
        "caf_s": caf_s,
        "cfar_s": cfar_s,
        "eca_s": eca_s,
        "synthesis_s": synth_s,
        "candidates": int(len(cands.range_m)),
        "cpu_count": os.cpu_count() or 1,
        "repeats": repeats,
    }
    result["realtime_factor"] = result["frame_s"] / (caf_s + cfar_s)
    try:  # the quick report's signal-level task, end to end
        from workbench.plugins import load_host
        from . import recipe as paper002
        from workbench.specs import TaskContext

        host = load_host()
        params = {"frames": int(paper002.RECIPE.sizes["quick"]["signal_frames"]), "filter": "kf"}
        t0 = time.perf_counter()
        paper002._signal_task(TaskContext(params=params, seed=0, host=host))
        result["signal_task_s"] = time.perf_counter() - t0
    except Exception as exc:  # noqa: BLE001 - the CAF timing stands on its own
        result["signal_task_error"] = f"{type(exc).__name__}: {exc}"
    print(f"paper 002 CAF + CFAR of one frame ({config.samples} samples, {result['range_bins']} x "
          f"{result['doppler_bins']} cells): {1e3 * (caf_s + cfar_s):.1f} ms -> real-time factor "
          f"{result['realtime_factor']:.2f} on {result['cpu_count']} cores")
    return result


if __name__ == "__main__":  # pragma: no cover
    out = bench(quick="--full" not in sys.argv)
    for key, value in out.items():
        print(f"{key:>16}: {value}")
