"""The criterion record: one "reproduced if" check of a paper, judged with its sample size and interval.

Every recipe's ``criteria(results)`` returns a list of :class:`Criterion`.  A verdict is one of

- ``"met"``: the whole 95 % interval of our value lies on the passing side of the threshold, and enough runs
  stand behind it;
- ``"not met"``: the whole interval lies on the failing side;
- ``"inconclusive"``: the interval straddles the threshold, or fewer runs than the criterion needs;
- ``"not attainable"``: the criterion cannot be met by any method on this set-up (the evidence, for example a
  near-optimal reference, is in ``detail``).

A quick report never says *met*: the report engine marks every quick-mode verdict ``indicative``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

__all__ = ["VERDICTS", "Criterion"]

#: The verdicts a criterion may carry.
VERDICTS = ("met", "not met", "inconclusive", "not attainable")


@dataclass(frozen=True)
class Criterion:
    """One 'reproduced if' criterion of a paper, evaluated on our numbers.

    Attributes
    ----------
    id : str
        Short id, unique within the recipe (``"C4"``, ``"2"``).
    text : str
        The statement, as the brief gives it.
    verdict : str
        One of :data:`VERDICTS`.  For older callers a bool is accepted and read as ``"met"`` / ``"not met"``
        (such a criterion carries no interval; the report says so).
    detail : str
        How ours was computed, and why the verdict is what it is.
    ours : float, str or None
        Our value of the judged statistic.
    published : float, str or None
        The paper's value (or claim) beside ours.
    n : int or None
        The number of independent runs behind ``ours``.
    interval : (float, float) or None
        The 95 % confidence interval of ``ours`` (bootstrap over runs, or exact where it exists).
    threshold : str
        The passing condition in words, e.g. ``"ratio >= 1.3"``.
    indicative : bool
        True in a quick report: the verdict is an indication only (never ``"met"``).
    replication : (int, int) or None
        ``(holds, of)``: in how many independent replications of the paper's own protocol the criterion held.
    """

    id: str
    text: str
    verdict: Any
    detail: str = ""
    ours: float | str | None = None
    published: float | str | None = None
    n: int | None = None
    interval: tuple[float, float] | None = None
    threshold: str = ""
    indicative: bool = False
    replication: tuple[int, int] | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        verdict = self.verdict
        if isinstance(verdict, bool) or type(verdict).__name__ == "bool_":
            verdict = "met" if bool(verdict) else "not met"
        if verdict not in VERDICTS:
            raise ValueError(f"criterion {self.id!r}: verdict must be one of {VERDICTS}, got {verdict!r}")
        object.__setattr__(self, "verdict", verdict)
        if self.interval is not None:
            lo, hi = (float(v) for v in self.interval)
            object.__setattr__(self, "interval", (lo, hi))

    @property
    def met(self) -> bool:
        """True only for a firm ``"met"`` outside quick mode."""
        return self.verdict == "met" and not self.indicative

    def as_indicative(self) -> "Criterion":
        """The same criterion marked as a quick-mode indication: a ``"met"`` becomes ``"inconclusive"``."""
        verdict = "inconclusive" if self.verdict == "met" else self.verdict
        return replace(self, verdict=verdict, indicative=True)
