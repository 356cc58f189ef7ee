"""The growth-model benchmark (issue 23, first "done when"): the documented block of docs/motion-models.md runs
as written (Gordon, Salmond & Smith's growth model sampled with ``wb.sample_motion``, the quadratic measurement,
the built-in ``sir`` through ``wb.run``), and its RMSE agrees, within Monte Carlo error, with a bootstrap particle
filter written out plainly here (the same N and the same runs, its own random stream).

Tolerance: both filters run on the same 200 truths, so the per-run RMSEs are paired; the two filters' random
streams are independent, so the differences ``d_r = RMSE_sir,r - RMSE_plain,r`` are independent over runs with
mean zero when the filters are the same algorithm.  The test asks ``|mean d| <= 4 sd(d) / sqrt(R)`` (a false
alarm probability of about 6e-5, the seeds being fixed).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import workbench as wb

ROOT = Path(__file__).parents[1]


def _doc_block() -> str:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "motion-models.md").read_text(encoding="utf-8"),
                        flags=re.S)
    assert len(blocks) == 1, "docs/motion-models.md holds one Python block, the benchmark"
    return blocks[0]


def _plain_bootstrap(z: np.ndarray, particles: int, prior_var: float, rng: np.random.Generator) -> np.ndarray:
    """A bootstrap particle filter for the growth model, written out: ``z (R, T)`` -> the estimates ``(R, T)``.

    Particles from the prior; at each step after the first, ``x <- x/2 + 25 x/(1 + x^2) + 8 cos(1.2 k) + v`` with
    ``k`` the scan's time (1, 2, ...) and ``v ~ N(0, 10)``; weights ``N(z; x^2/20, 1)``; systematic resampling at
    every scan; the estimate the mean of the resampled particles (as ``sir`` with ``threshold > 1`` reports)."""
    R, T = z.shape
    x = rng.normal(0.0, math.sqrt(prior_var), (R, particles))
    out = np.empty((R, T))
    for k in range(T):
        if k > 0:
            x = 0.5 * x + 25.0 * x / (1.0 + x * x) + 8.0 * math.cos(1.2 * k) + rng.normal(0.0, math.sqrt(10.0),
                                                                                         x.shape)
        logw = -0.5 * (z[:, k : k + 1] - x * x / 20.0) ** 2
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        cdf = np.cumsum(w / w.sum(axis=1, keepdims=True), axis=1)
        cdf[:, -1] = 1.0
        u = (rng.random((R, 1)) + np.arange(particles)) / particles
        # one search for all runs: run r's CDF and offsets shifted by r
        shift = np.arange(R)[:, None]
        flat = np.searchsorted((cdf + shift).ravel(), (u + shift).ravel(), side="right").reshape(R, particles)
        x = x.ravel()[np.minimum(flat, (shift + 1) * particles - 1)]
        out[:, k] = x.mean(axis=1)
    return out


@pytest.mark.slow  # about 3 s: 200 runs x 50 steps x 500 particles, twice
def test_the_documented_growth_benchmark_runs_and_sir_agrees_with_a_plain_bootstrap_filter(capsys):
    ns: dict = {}
    exec(compile(_doc_block(), "docs/motion-models.md", "exec"), ns)  # noqa: S102 - the documented code itself
    printed = capsys.readouterr().out
    truth, scans, track, rmse = ns["truth"], ns["scans"], ns["track"], ns["rmse"]
    runs, steps, particles = ns["runs"], ns["steps"], ns["particles"]
    assert f"sir, N = {particles}: mean RMSE {rmse.mean():.2f}" in printed
    assert track.mean.shape == (runs, steps, 1) and scans.times.tolist() == list(range(steps))

    z = scans.z[:, :, 0, 0]
    plain = _plain_bootstrap(z, particles, 5.0, wb.generator(23, "test-growth", "plain-bootstrap"))
    rmse_plain = np.sqrt(np.mean((plain - truth.states[..., 0]) ** 2, axis=1))
    d = rmse - rmse_plain
    se = d.std(ddof=1) / math.sqrt(runs)
    assert abs(d.mean()) <= 4.0 * se, (rmse.mean(), rmse_plain.mean(), d.mean(), se)
    # the pairing is informative (the runs differ far more than the filters do), and the benchmark is the
    # growth model's: a bootstrap filter of 500 particles is far better than ignoring the data (the truth's
    # spread) yet, the sign being unobserved, not exact
    assert se < 0.25 * rmse.std(ddof=1)
    assert 1.0 < rmse.mean() < 0.7 * truth.states[..., 0].std()
