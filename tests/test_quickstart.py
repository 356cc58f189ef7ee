"""The documented Python quick start runs as written: docs/quickstart.md and the README's quick start, code block
by code block, and what they compute is checked here against the truth they simulate."""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).parents[1]


def _blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), flags=re.S)


def test_quickstart_page_runs_and_tracks(capsys):
    blocks = _blocks(ROOT / "docs" / "quickstart.md")
    assert len(blocks) >= 4
    ns: dict = {}
    for code in blocks:
        exec(compile(code, "docs/quickstart.md", "exec"), ns)  # noqa: S102 - the documented code itself
    out = capsys.readouterr().out
    # batched UKF: the error is a few metres (range noise 1 m, bearing 0.1 rad at ~100 m), far below the prior's
    rmse = float(re.search(r"RMSE over 500 runs: ([0-9.]+) m", out).group(1))
    assert 0.5 < rmse < 15.0
    assert ns["track"].mean.shape == (500, 100, 4) and ns["track"].cov.shape == (500, 100, 4, 4)
    assert ns["pf"].name == "sir(particles=2000)" and ns["track_pf"].mean.shape == (20, 100, 4)
    # one track, step by step, ends near its truth
    assert np.linalg.norm(ns["estimates"][-1][:2] - ns["truth"].states[0, -1, :2]) < 30.0
    # the multi-target tracker confirms the sonar target
    assert ns["log"].confirmed_counts()[0].max() >= 1


def test_readme_quick_start_runs():
    blocks = _blocks(ROOT / "README.md")
    assert blocks, "README.md has a Python quick start"
    ns: dict = {}
    for code in blocks:
        exec(compile(code, "README.md", "exec"), ns)  # noqa: S102
    assert "track" in ns and np.all(np.isfinite(ns["track"].mean))
