"""Helpers filter authors share, and :func:`run_filter`, the direct-association form of the time loop."""

from __future__ import annotations

from typing import Callable

import numpy as np

from .models import MeasurementModel, MotionModel
from .specs import FilterSpec
from .types import Gaussian, InputError, Scan, Scans

__all__ = ["run_filter", "single_measurement", "require_finite", "keep_where"]


def single_measurement(scan: Scan, who: str = "this filter") -> tuple[np.ndarray, np.ndarray]:
    """The one measurement per batch item of a scan: ``z (B, m)`` and ``present (B,)``.

    Raises :class:`~workbench.types.InputError` when an item holds more than one valid row: a
    single-measurement filter needs an association or pseudo-measurement step before it.
    """
    if scan.z.shape[1] == 1:  # the common case (one row per item): no counting needed
        # present contiguous whatever the scan's layout (a scan cut from a (B, T, M) array has strided columns): a
        # compiled kernel taking it then has one signature, not a second compilation for strided masks
        return scan.z[:, 0], np.ascontiguousarray(scan.valid[:, 0])
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


def require_finite(z: np.ndarray, present: np.ndarray, who: str) -> None:
    """Refuse, naming ``who`` and the first batch item, a present measurement ``z (B, m)`` holding NaN or inf."""
    if not np.all(np.isfinite(z[present])):
        item = int(np.flatnonzero(present & ~np.all(np.isfinite(z), axis=1))[0])
        raise InputError(f"{who}: the measurement of batch item {item} is not finite (NaN or inf)")


def keep_where(present: np.ndarray, updated: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """``updated`` where ``present`` (B,), else ``previous``: an empty scan leaves the state as predicted."""
    shape = (present.shape[0],) + (1,) * (updated.ndim - 1)
    return np.where(present.reshape(shape), updated, previous)


def run_filter(spec: FilterSpec, prior: Gaussian, motion: MotionModel, model: MeasurementModel, scans: Scans,
               rng: np.random.Generator, *, progress: Callable[[float], None] | None = None,
               predict_first: bool = False):
    """Run ``spec`` over ``scans``: update with scan 0 from ``prior`` (or predict first with ``predict_first``),
    then predict/update for each later scan.  :func:`workbench.tracking.run` with the direct association.

    ``origin`` labels are stripped before the filter sees a scan.  Returns a :class:`~workbench.tracking.Track`.
    """
    from .tracking import Direct, run

    return run(spec, scans, motion, model, association=Direct(), prior=prior, rng=rng, predict_first=predict_first,
               progress=progress)
