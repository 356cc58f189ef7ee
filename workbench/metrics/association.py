"""How a nearest-neighbour track's choices score against the candidates' origin labels (metrics only).

The tracker never reads ``origin``; these functions do, afterwards, from the track's records
(:class:`~workbench.tracking.NearestNeighbour`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracking.loop import Track
from ..types import InputError, Scans

__all__ = ["AssociationLog", "association_log", "coasted"]


@dataclass(frozen=True)
class AssociationLog:
    """What the NN choices were, scored against the candidates' origin labels.

    Shapes: every field ``(B, T)`` bool; frame 0 (the prior) is never an association.

    - ``target_present``: a valid candidate from the target exists (frames ``k >= 1``)
    - ``correct``: the chosen candidate is the target's
    - ``wrong``: a candidate was chosen and it is not the target's (clutter, or a false alarm)
    - ``coasted``: no update
    - ``jump``: the chosen candidate's first component is more than ``jump_sigma`` sigma from the prediction
    """

    target_present: np.ndarray
    correct: np.ndarray
    wrong: np.ndarray
    coasted: np.ndarray
    jump: np.ndarray

    @property
    def nn_correct_rate(self) -> float:
        """Fraction of the frames with a target candidate in which NN chose it."""
        n = int(self.target_present.sum())
        return float((self.correct & self.target_present).sum() / n) if n else float("nan")

    def events(self, run: int = 0) -> list[tuple[int, str]]:
        """``(frame, kind)`` for every wrong association, jump and coast of one run, in frame order."""
        out = []
        for kind in ("wrong", "jump", "coasted"):
            out += [(int(k), kind) for k in np.flatnonzero(getattr(self, kind)[run])]
        return sorted(out)


def coasted(track: Track) -> np.ndarray:
    """``(B, T)``: frames ``k >= 1`` with no update and no restart (no candidate, or none in the gate)."""
    out = ~track.records["updated"] & ~track.records["restarted"]
    out[:, 0] = False
    return out


def association_log(track: Track, scans: Scans, target: int = 0, jump_sigma: float = 3.0) -> AssociationLog:
    """Score a nearest-neighbour track's choices against ``scans.origin`` (the truth labels).

    A *jump* is a chosen candidate whose first component (e.g. the range) lies more than ``jump_sigma``
    standard deviations ``sqrt(S_00)`` from the predicted one.
    """
    if scans.origin is None:
        raise InputError("association_log needs scans with origin labels")
    rec = track.records
    chosen = rec["chosen"]
    B, T = chosen.shape
    later = np.arange(T) >= 1
    from_target = scans.valid & (scans.origin == target)
    present = from_target.any(axis=2) & later
    idx = np.maximum(chosen, 0)
    chosen_origin = np.take_along_axis(scans.origin, idx[..., None], axis=2)[..., 0] if scans.z.shape[2] else \
        np.full((B, T), -1)
    picked = rec["updated"]
    correct = picked & (chosen_origin == target)
    wrong = picked & (chosen_origin != target)
    sigma = np.sqrt(rec["innovation_cov"][..., 0, 0])
    jump = picked & (np.abs(np.nan_to_num(rec["chosen_z"][..., 0]) - rec["predicted_z"][..., 0]) > jump_sigma * sigma)
    return AssociationLog(present, correct, wrong, coasted(track) & later, jump)
