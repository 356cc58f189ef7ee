"""Drive a filter over a scan series, and helpers filter authors share."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from .models import MeasurementModel, MotionModel
from .specs import FilterSpec
from .types import Gaussian, InputError, Scan, Scans

__all__ = ["Estimates", "run_filter", "single_measurement", "keep_where"]


@dataclass(frozen=True)
class Estimates:
    """A filter's output over a scan series.

    Shapes
    ------
    mean, predicted_mean : (B, T, n)
    cov : (B, T, n, n)
    """

    filter: str
    mean: np.ndarray
    cov: np.ndarray
    predicted_mean: np.ndarray
    diagnostics: Mapping[str, float]


def single_measurement(scan: Scan, who: str = "this filter") -> tuple[np.ndarray, np.ndarray]:
    """The one measurement per batch item of a scan: ``z (B, m)`` and ``present (B,)``.

    Raises :class:`~workbench.types.InputError` when an item holds more than one valid row: a
    single-measurement filter needs an association or pseudo-measurement step before it.
    """
    counts = scan.counts
    if np.any(counts > 1):
        item = int(np.argmax(counts > 1))
        raise InputError(f"{who} takes at most one measurement per scan, but batch item {item} has "
                         f"{int(counts[item])}; put gating/association or a pseudo-measurement step first")
    present = counts == 1
    if scan.z.shape[1] == 0:
        return np.zeros((scan.batch, scan.z.shape[2])), present
    first = np.argmax(scan.valid, axis=1)
    return scan.z[np.arange(scan.batch), first], present


def keep_where(present: np.ndarray, updated: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """``updated`` where ``present`` (B,), else ``previous``: an empty scan leaves the state as predicted."""
    shape = (present.shape[0],) + (1,) * (updated.ndim - 1)
    return np.where(present.reshape(shape), updated, previous)


def run_filter(spec: FilterSpec, prior: Gaussian, motion: MotionModel, model: MeasurementModel, scans: Scans,
               rng: np.random.Generator, *, progress: Callable[[float], None] | None = None) -> Estimates:
    """Run ``spec`` over ``scans``: update with scan 0 from ``prior``, then predict/update for each later scan.

    ``origin`` labels are stripped before the filter sees a scan.
    """
    if prior.batch != scans.batch:
        raise InputError(f"prior has batch {prior.batch} but the scans have batch {scans.batch}")
    T = scans.steps
    B, n = prior.mean.shape
    mean = np.empty((B, T, n))
    cov = np.empty((B, T, n, n))
    pred = np.empty((B, T, n))
    state = spec.init(prior, rng)
    for k in range(T):
        if k > 0:
            state = spec.predict(state, motion, rng)
        pred[:, k] = spec.estimate(state).mean
        state = spec.update(state, scans.scan(k).for_filter(), model, rng)
        est = spec.estimate(state)
        mean[:, k] = est.mean
        cov[:, k] = est.cov
        if progress is not None:
            progress((k + 1) / T)
    diag = dict(spec.diagnostics(state)) if spec.diagnostics is not None else {}
    return Estimates(spec.name, mean, cov, pred, diag)
