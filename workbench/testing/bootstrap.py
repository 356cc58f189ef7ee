"""Test helpers for batched bootstrap statistics (:func:`workbench.criteria.vectorised`).

A recipe that declares a batched form of a statistic holds its criteria to the per-resample computation: patch
``workbench.criteria._batched_statistics`` with :func:`loop_statistics` (one call of the plain statistic per
resample, as the bootstrap computed before batching) and compare the two records with :func:`same_numbers`.
"""

from __future__ import annotations

import numpy as np
import pytest

__all__ = ["loop_statistics", "same_numbers"]


def loop_statistics(arrays, statistic, idx):
    """The bootstrap's statistics one call per resample (the reference for a batched form): ``statistic.one``
    applied to each resample ``i`` of ``idx`` of the arrays."""
    return np.array([float(statistic.one(*(a[i] for a in arrays))) for i in idx])


def same_numbers(fast, slow, where: str = "criterion") -> None:
    """Every number of two ``to_dict()`` records agrees to 1e-12 relative (NaN with NaN); everything else is
    equal.  ``where`` names the place of a difference in the assertion."""
    if isinstance(fast, dict):
        assert fast.keys() == slow.keys(), where
        for key in fast:
            same_numbers(fast[key], slow[key], f"{where}.{key}")
    elif isinstance(fast, list):
        assert len(fast) == len(slow), where
        for i, (a, b) in enumerate(zip(fast, slow)):
            same_numbers(a, b, f"{where}[{i}]")
    elif isinstance(fast, float) and not isinstance(slow, bool):
        assert fast == pytest.approx(slow, rel=1e-12, abs=0.0, nan_ok=True), where
    else:
        assert fast == slow, where
