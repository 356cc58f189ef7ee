"""The criterion record: one "reproduced if" check of a paper, judged with its sample size and interval.

Every recipe's ``criteria(results)`` returns a list of :class:`Criterion`.  A verdict is one of

- ``"met"``: the whole 95 % interval of our value lies on the passing side of the threshold, and enough runs
  stand behind it;
- ``"not met"``: the whole interval lies on the failing side;
- ``"inconclusive"``: the interval straddles the threshold, or fewer runs than the criterion needs;
- ``"not attainable"``: the criterion cannot be met by any method on this set-up (the evidence, for example a
  near-optimal reference, is in ``detail``);
- ``"not judgeable"``: a :class:`Precondition` of the criterion fails (the judged rows lose their tracks, the
  reference has not converged...): the numbers cannot speak to the paper's claim, so the criterion is neither met,
  not met nor inconclusive.  The failed preconditions, with their numbers, are in ``preconditions``.

A criterion declares what must hold for it to be judged as a tuple of :class:`Precondition` records.  Where any
fails, the record's verdict *is* ``"not judgeable"`` whatever verdict it was built with (that verdict is kept in
``extra["verdict_if_judged"]``): no construction path can give a *met* (or *not met*) beside a failed
precondition.  :func:`rows_track` and :func:`reference_converged` build the two preconditions the papers use.

A quick report never says *met*: the report engine marks every quick-mode verdict ``indicative``.

The functions below build criteria honestly from per-run data:

- :func:`bootstrap_interval`: a percentile bootstrap interval over runs (paired samples resampled together);
  :func:`vectorised` declares a statistic's form over a batch of resamples, so that the bootstrap evaluates them
  all at once;
- :func:`binomial_interval`: the exact (Clopper-Pearson) interval of a proportion;
- :func:`judge`: the three-way verdict of an interval against a threshold;
- :func:`criterion_from_runs` and :func:`criterion_from_counts`: a :class:`Criterion` with ours, n, the
  interval and the verdict filled in;
- :func:`criterion_equivalent` (with :func:`judge_equivalent` and :func:`equivalence_band`): an "about equal"
  claim judged as equivalence by two one-sided tests (TOST) with a stated margin, read from the 90 % interval, so
  that a tie reads as a tie;
- :func:`replication_rate`: how often the criterion, computed the paper's way on a few runs, holds in
  independent, disjoint batches of runs;
- :func:`rows_track` and :func:`reference_converged`: the preconditions "the judged rows track" (a stated share
  of lost runs at most, per row, with the counts) and "the reference has converged" (the reference at N against
  4N on the same runs, a paired ratio within a stated tolerance, with its interval).

Samples are given with the runs on the first axis.  A *tuple* of arrays is a paired sample: every array
holds the same runs (for example the errors of methods A and C on the same simulated tracks), and a
resample draws the same run indices from each, so a statistic such as ``mean(A) / mean(C)`` keeps the
pairing.  A list is always one sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Callable, Mapping

import numpy as np

__all__ = ["VERDICTS", "NOT_JUDGEABLE", "DIRECTIONS", "Criterion", "Precondition", "bootstrap_interval",
           "binomial_interval", "judge", "criterion_from_runs", "criterion_from_counts", "replication_rate",
           "rows_track", "reference_converged", "equivalence_band", "judge_equivalent", "criterion_equivalent",
           "DeclaredUnknown", "UnknownVerdict",
           "judge_across", "where_it_holds", "Vectorised", "vectorised", "Confirmation", "confirm"]

#: The verdict of a criterion whose precondition fails.
NOT_JUDGEABLE = "not judgeable"

#: The verdicts a criterion may carry.
VERDICTS = ("met", "not met", "inconclusive", "not attainable", NOT_JUDGEABLE)


@dataclass(frozen=True)
class Precondition:
    """What must hold for a criterion to be judged at all, evaluated on our numbers.

    Attributes
    ----------
    name : str
        What must hold, e.g. ``"judged rows track"``.
    holds : bool
        Whether it holds.
    detail : str
        The numbers it was decided on, in words (counts, the ratio and its interval, the stated limit).
    values : dict
        The same numbers, JSON-ready, for a machine reader.
    """

    name: str
    holds: bool
    detail: str = ""
    values: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not str(self.name).strip():
            raise ValueError("a precondition needs a name")
        object.__setattr__(self, "holds", bool(self.holds))
        object.__setattr__(self, "values", _plain(dict(self.values or {})))

    def text(self) -> str:
        """``"NAME holds (DETAIL)"`` or ``"NAME fails (DETAIL)"``."""
        state = "holds" if self.holds else "fails"
        return f"{self.name} {state}" + (f" ({self.detail})" if self.detail else "")

    def to_dict(self) -> dict:
        """``name, holds, detail, values`` (JSON-ready)."""
        return {"name": self.name, "holds": self.holds, "detail": self.detail, "values": _plain(self.values)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Precondition":
        """Rebuild a precondition written by :meth:`to_dict` (unknown keys are ignored)."""
        return cls(str(data["name"]), bool(data["holds"]), str(data.get("detail", "")),
                   dict(data.get("values") or {}))


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
        One of :data:`VERDICTS` (anything else, a bool included, is refused by name).
    detail : str
        How ours was computed, and why the verdict is what it is, in words: the human explanation only.  The
        numbers the verdict was judged on are the record's own fields (``ours, n, interval, level, method,
        threshold, min_n, count, resamples``); :attr:`statistics` puts them into one sentence.
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
    min_n : int or None
        The fewest runs from which the criterion may be decided (below it the verdict is inconclusive).
    method : str or None
        How ``interval`` was computed, e.g. ``"percentile bootstrap, 2000 resamples"``.
    level : float or None
        The confidence level of ``interval``, in (0, 1) (0.95; 0.9 for an equivalence judged by TOST at 5 %);
        ``None`` where the record carries no interval of its own making.
    count : int or None
        For a proportion (:func:`criterion_from_counts`): the runs in which the event happened (ours is
        ``count / n``).
    resamples : int or None
        For a bootstrap interval (:func:`criterion_from_runs`): the number of resamples it was computed from.
    extra : dict
        Further numbers of the recipe's own; ``"verdict_if_judged"`` holds the verdict the numbers gave when a
        precondition fails.
    preconditions : tuple of Precondition
        What must hold for the criterion to be judged.  Where any fails the verdict is ``"not judgeable"``
        (set here, whatever verdict the record was built with); ``"not judgeable"`` without a failed
        precondition is refused.
    across : tuple of UnknownVerdict
        The same criterion judged at each grid value of the recipe's declared unknowns (:class:`DeclaredUnknown`,
        :func:`judge_across`); the verdict above is the one at the primary values.  Empty where the criterion
        does not hinge on an unknown, or the size judges none.
    confirmation : Confirmation or None
        The same criterion judged once more on the confirmation seed (a seed no tuning and no design choice has
        seen) and whether that verdict agrees with this one (:func:`confirm`); ``None`` where the report ran no
        confirmation (a quick report).
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
    min_n: int | None = None
    method: str | None = None
    level: float | None = None
    count: int | None = None
    resamples: int | None = None
    extra: dict = field(default_factory=dict)
    preconditions: tuple[Precondition, ...] = ()
    across: tuple["UnknownVerdict", ...] = ()
    confirmation: "Confirmation | None" = None

    def __post_init__(self) -> None:
        if self.confirmation is not None and not isinstance(self.confirmation, Confirmation):
            object.__setattr__(self, "confirmation", Confirmation.from_dict(self.confirmation))
        object.__setattr__(self, "across", tuple(
            a if isinstance(a, UnknownVerdict) else UnknownVerdict.from_dict(a) for a in (self.across or ())))
        verdict = self.verdict
        if not isinstance(verdict, str) or verdict not in VERDICTS:
            raise ValueError(f"criterion {self.id!r}: the verdict must be one of {VERDICTS} (a string), got "
                             f"{verdict!r} ({type(verdict).__name__})")
        pre = self.preconditions
        if isinstance(pre, (Precondition, Mapping)):
            pre = (pre,)
        pre = tuple(p if isinstance(p, Precondition) else Precondition.from_dict(p) for p in (pre or ()))
        object.__setattr__(self, "preconditions", pre)
        failed = [p.name for p in pre if not p.holds]
        if failed and verdict != NOT_JUDGEABLE:
            # a failed precondition overrides any verdict: the numbers' own verdict is kept, never shown as one
            object.__setattr__(self, "extra", {**self.extra, "verdict_if_judged": verdict})
            verdict = NOT_JUDGEABLE
        elif verdict == NOT_JUDGEABLE and not failed:
            raise ValueError(f"criterion {self.id!r}: the verdict {NOT_JUDGEABLE!r} needs a failed precondition "
                             "naming why")
        object.__setattr__(self, "verdict", verdict)
        if self.interval is not None:
            lo, hi = (float(v) for v in self.interval)
            object.__setattr__(self, "interval", (lo, hi))
        if self.level is not None:
            level = float(self.level)
            if not 0.0 < level < 1.0:
                raise ValueError(f"criterion {self.id!r}: the interval's level must be in (0, 1), got {self.level!r}")
            object.__setattr__(self, "level", level)
        for name in ("count", "resamples"):
            value = getattr(self, name)
            if value is not None:
                if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
                        or not float(value).is_integer() or value < 0:
                    raise ValueError(f"criterion {self.id!r}: {name} must be a whole number >= 0, got {value!r}")
                object.__setattr__(self, name, int(value))

    @property
    def statistics(self) -> str:
        """The numbers the verdict was judged on, in one sentence made from the record's fields (``""`` for a record
        without an interval level, e.g. one built by hand, whose numbers are its columns and its detail).

        A proportion: ``"ours K/N = V, 95 % interval [LO, HI] (exact, Clopper-Pearson); passes if ...; needs
        n >= M"``; a bootstrap: ``"ours V, 95 % interval [LO, HI] (percentile bootstrap over n = N runs, R
        resamples); passes if ...; needs n >= M"`` (``"no interval (...)"`` where none could be computed), followed
        for an equivalence by how it was judged (TOST, margin, level, alpha per side).
        """
        if self.level is None:
            return ""
        pct = 100.0 * self.level
        ours = self.ours if isinstance(self.ours, str) else f"{float(self.ours):.4g}" if self.ours is not None \
            else "n/a"
        interval = self.interval if self.interval is not None and not any(math.isnan(v) for v in self.interval) \
            else None
        if self.count is not None:
            head = f"ours {self.count}/{self.n} = {ours}"
        elif interval is None:
            head = f"ours {ours} from n = {self.n} runs"
        else:
            head = f"ours {ours}"
        if interval is None:
            how = ("no interval (a bootstrap needs 2 runs or more and a finite statistic on every resample)"
                   if self.count is None else "no interval")
        else:
            if self.count is not None:
                source = self.method or "exact"
            elif self.resamples is not None:
                source = f"percentile bootstrap over n = {self.n} runs, {self.resamples} resamples"
            else:
                source = f"{self.method or 'interval'}, n = {self.n}"
            how = f"{pct:g} % interval [{interval[0]:.4g}, {interval[1]:.4g}] ({source})"
        text = f"{head}, {how}" if interval is not None else f"{head}; {how}"
        if self.threshold:
            text += f"; passes if {self.threshold}"
        if self.min_n is not None:
            text += f"; needs n >= {self.min_n}"
        eq = self.extra.get("equivalence")
        if isinstance(eq, Mapping):
            text += (f"; judged as equivalence (TOST, margin {_margin_text(eq['margin'], eq['ratio'])}, {pct:g} % "
                     f"interval, alpha = {float(eq['alpha']):g} per side)")
        return text

    @property
    def met(self) -> bool:
        """True only for a firm ``"met"`` outside quick mode."""
        return self.verdict == "met" and not self.indicative

    @property
    def failed_preconditions(self) -> tuple[Precondition, ...]:
        """The preconditions that fail (empty unless the verdict is ``"not judgeable"``)."""
        return tuple(p for p in self.preconditions if not p.holds)

    @property
    def verdict_if_judged(self) -> str | None:
        """For a criterion that is not judgeable, the verdict its numbers alone would have given."""
        return self.extra.get("verdict_if_judged") if self.verdict == NOT_JUDGEABLE else None

    @property
    def quick_verdict(self) -> str | None:
        """For an indicative criterion, the verdict the quick run's own numbers gave before marking."""
        return self.extra.get("quick_verdict")

    def as_indicative(self) -> "Criterion":
        """The same criterion marked as a quick-mode indication.

        A ``"met"`` becomes ``"inconclusive"``; the other verdicts are kept.  The verdict the quick run's
        numbers gave is kept in ``extra["quick_verdict"]`` (see :attr:`quick_verdict`), so the report can
        say "the quick run would pass".  Marking an indicative criterion again changes nothing.

        Returns
        -------
        Criterion
            A new record with ``indicative=True``.
        """
        if self.indicative:
            return self
        extra = dict(self.extra)
        extra.setdefault("quick_verdict", self.verdict)
        verdict = "inconclusive" if self.verdict == "met" else self.verdict
        return replace(self, verdict=verdict, indicative=True, extra=extra,
                       across=tuple(a.as_indicative() for a in self.across),
                       confirmation=None if self.confirmation is None else self.confirmation.as_indicative())

    def to_dict(self) -> dict:
        """A JSON-ready dict of every field, plus ``met`` (bool) for older readers and ``statistics`` (the sentence
        :attr:`statistics` makes of the fields, for a human reader; :meth:`from_dict` reads the fields).

        Returns
        -------
        dict
            ``id, text, verdict, met, indicative, ours, published, n, interval, threshold, replication, min_n,
            method, level, count, resamples, statistics, detail, extra, preconditions`` (each ``name, holds, detail,
            values``), ``across``
            (each :meth:`UnknownVerdict.to_dict`), ``confirmation`` (:meth:`Confirmation.to_dict` or None); numpy
            scalars become Python numbers, tuples become lists.
        """
        out = {f.name: _plain(getattr(self, f.name)) for f in fields(self)
               if f.name not in ("preconditions", "across", "confirmation")}
        out["preconditions"] = [p.to_dict() for p in self.preconditions]
        out["across"] = [a.to_dict() for a in self.across]
        out["confirmation"] = None if self.confirmation is None else self.confirmation.to_dict()
        out["met"] = bool(self.met)
        out["statistics"] = self.statistics
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Criterion":
        """Rebuild a criterion written by :meth:`to_dict` (unknown keys are ignored).

        Parameters
        ----------
        data : mapping
            The dict, e.g. read back from JSON.

        Returns
        -------
        Criterion
        """
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in data.items() if k in names}
        for key in ("interval", "replication"):
            if kw.get(key) is not None:
                kw[key] = tuple(kw[key])
        if kw.get("extra") is None:
            kw["extra"] = {}
        kw["preconditions"] = tuple(Precondition.from_dict(p) for p in kw.get("preconditions") or ())
        kw["across"] = tuple(UnknownVerdict.from_dict(a) for a in kw.get("across") or ())
        if kw.get("confirmation") is not None:
            kw["confirmation"] = Confirmation.from_dict(kw["confirmation"])
        return cls(**kw)


def _plain(value: Any) -> Any:
    """``value`` with numpy scalars and arrays, tuples and mappings turned into JSON-ready Python values."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


#: The directions :func:`judge` understands.  ``"within"`` takes ``threshold=(low, high)``.
DIRECTIONS = (">=", ">", "<=", "<", "within")


def _as_runs(samples: Any) -> tuple[tuple[np.ndarray, ...], bool]:
    """Split ``samples`` into arrays with the runs on axis 0; True when it is a paired (tuple) sample."""
    paired = isinstance(samples, tuple) and len(samples) > 0 and all(np.ndim(a) >= 1 for a in samples)
    arrays = tuple(np.asarray(a) for a in samples) if paired else (np.asarray(samples),)
    if arrays[0].ndim == 0:
        raise ValueError("samples must have the runs on a first axis (got a scalar)")
    lengths = {a.shape[0] for a in arrays}
    if len(lengths) != 1:
        raise ValueError(f"paired samples must hold the same number of runs, got lengths {sorted(lengths)}")
    return arrays, paired


def _rng(rng: np.random.Generator | None, seed: int | None) -> np.random.Generator:
    if rng is not None:
        return rng
    return np.random.default_rng(seed)


# Statistics that can be applied to all resamples at once along an axis (a 1-D sample only).
_AXIS_STATISTICS = {np.mean, np.median, np.sum, np.std, np.var, np.min, np.max, np.nanmean, np.nanmedian}

#: The most values one batch of resamples holds (bounds the memory of the resampled copies).
_BATCH_VALUES = 4_000_000
#: What the batched form of a :class:`Vectorised` statistic is given.
_GIVEN = ("resamples", "means", "counts")


class Vectorised:
    """A statistic together with its form over many resamples at once (see :func:`vectorised`).

    Called like the statistic itself (``one``); :func:`bootstrap_interval` and :func:`criterion_from_runs` use
    ``many`` to evaluate a whole batch of resamples in one go.
    """

    __slots__ = ("one", "many", "given")

    def __init__(self, one: Callable[..., float], many: Callable[..., Any], given: str = "resamples"):
        if not callable(one) or not callable(many):
            raise ValueError("a vectorised statistic needs a callable statistic and a callable batched form")
        if given not in _GIVEN:
            raise ValueError(f"a batched form is given one of {_GIVEN}, got {given!r}")
        self.one, self.many, self.given = one, many, given

    def __call__(self, *arrays: Any) -> float:
        return self.one(*arrays)

    @property
    def name(self) -> str:
        return getattr(self.one, "__qualname__", None) or repr(self.one)

    def __repr__(self) -> str:
        return f"vectorised({self.name})"


def vectorised(one: Callable[..., float], many: Callable[..., Any], *, given: str = "resamples") -> Vectorised:
    """Declare a statistic's batched form, so that a bootstrap evaluates all its resamples at once.

    Parameters
    ----------
    one : callable
        The statistic on one sample: ``one(*arrays) -> float``, each array with the runs on axis 0 (as
        :func:`bootstrap_interval` takes it).
    many : callable
        The same statistic on a batch of ``B`` resamples, returning ``(B,)``; what it is given is ``given``'s.  It
        must give, resample by resample, what ``one`` gives (to rounding): :func:`bootstrap_interval` checks it on
        the first resample and refuses, naming the statistic, where it does not.
    given : {"resamples", "means", "counts"}
        ``"resamples"``: ``many(*resampled)``, each array with a leading resample axis,
        ``resampled[i][b] = arrays[i][idx[b]]`` (runs on axis 1): any statistic (medians, spreads...).
        ``"means"``: ``many(*means)``, ``means[i][b]`` the mean over the runs of resample ``b`` of ``arrays[i]``
        (shape ``(B,) + arrays[i].shape[1:]``), from resample counts without copying the runs: for a statistic of
        means over runs.
        ``"counts"``: ``many(W, *arrays)``, the arrays as they are and ``W`` of shape ``(B, runs)``, ``W[b, j]``
        the times run ``j`` is drawn in resample ``b`` (a mean over the resampled runs is ``W @ a / runs``): for
        sums of other kinds (a mean over the finite entries, a count).

    Returns
    -------
    Vectorised
        Called like ``one``.

    Examples
    --------
    >>> ratio = vectorised(lambda a, b: float(a.mean() / b.mean()), lambda a, b: a.mean(axis=1) / b.mean(axis=1))
    >>> ratio(np.array([2.0, 4.0]), np.array([1.0, 2.0]))
    2.0
    """
    return Vectorised(one, many, given)


def _agree(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b or math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)


def _batched_statistics(arrays: tuple[np.ndarray, ...], statistic: Vectorised, idx: np.ndarray) -> np.ndarray:
    """``statistic`` on every resample ``idx[b]`` of ``arrays``, a batch at a time through its batched form."""
    resamples, n = idx.shape
    width = sum(int(np.prod(a.shape[1:], dtype=np.int64)) for a in arrays)
    # copies hold (chunk, n, width) values; counts (chunk, n) and the weighted sums (chunk, width)
    chunk = max(1, _BATCH_VALUES // max(1, n * width if statistic.given == "resamples" else n + width))
    finite = [bool(np.all(np.isfinite(a))) for a in arrays] if statistic.given == "means" else []
    stats = np.empty(resamples)
    for start in range(0, resamples, chunk):
        sel = idx[start:start + chunk]
        if statistic.given == "resamples":
            out = statistic.many(*(a[sel] for a in arrays))
        else:
            rows = sel.shape[0]
            flat = (np.arange(rows)[:, None] * n + sel).ravel()
            counts = np.bincount(flat, minlength=rows * n).reshape(rows, n).astype(float)
            if statistic.given == "counts":
                out = statistic.many(counts, *arrays)
            else:  # a non-finite value counts only where drawn: such an array is resampled by copies
                out = statistic.many(*((counts @ a.reshape(n, -1) / n).reshape((rows,) + a.shape[1:]) if ok
                                       else a[sel].mean(axis=1) for a, ok in zip(arrays, finite)))
        out = np.asarray(out, dtype=float)
        if out.shape != (sel.shape[0],):
            raise ValueError(f"the batched form of the statistic {statistic.name} gave shape {out.shape} for "
                             f"{sel.shape[0]} resamples: it must give one value per resample")
        stats[start:start + sel.shape[0]] = out
    first = float(statistic.one(*(a[idx[0]] for a in arrays)))
    if not _agree(first, float(stats[0])):
        raise ValueError(f"the batched form of the statistic {statistic.name} disagrees with the statistic on the "
                         f"first resample ({stats[0]!r} against {first!r})")
    return stats


def bootstrap_interval(samples: Any, statistic: Callable[..., float] = np.mean, *, level: float = 0.95,
                       resamples: int = 2000, seed: int | None = 0,
                       rng: np.random.Generator | None = None) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of a statistic over independent runs.

    Runs are drawn with replacement ``resamples`` times; the interval is the ``(1 - level) / 2`` and
    ``(1 + level) / 2`` quantiles of the statistic over the resamples.

    Parameters
    ----------
    samples : array_like or tuple of array_like
        One value (or one row) per run, runs on the first axis.  A tuple of arrays is a paired sample:
        each resample takes the same run indices from every array, and ``statistic`` receives the arrays
        as separate arguments, e.g. ``lambda a, c: a.mean() / c.mean()``.
    statistic : callable, default ``np.mean``
        Maps the (resampled) sample(s) to one number.  A statistic declared with its batched form
        (:func:`vectorised`) is evaluated a batch of resamples at a time; any other is called once per resample
        (``np.mean``, ``np.median`` and the like on a 1-D sample are batched as they are).  The resamples are the
        same either way.
    level : float, default 0.95
        Confidence level, in (0, 1).
    resamples : int, default 2000
        Number of bootstrap resamples.
    seed : int or None, default 0
        Seed of the resampling generator (ignored when ``rng`` is given).
    rng : numpy.random.Generator, optional
        The generator to draw resamples from.

    Returns
    -------
    (float, float)
        The interval.  ``(nan, nan)`` when there are fewer than 2 runs (a bootstrap of one run says
        nothing about its spread) or when the statistic is not finite on some resample; :func:`judge`
        reads such an interval as inconclusive.

    Examples
    --------
    >>> lo, hi = bootstrap_interval(np.arange(100.0), seed=1)
    >>> bool(lo < 49.5 < hi)
    True
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if resamples < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    arrays, paired = _as_runs(samples)
    n = arrays[0].shape[0]
    if n < 2:
        return (math.nan, math.nan)
    gen = _rng(rng, seed)
    idx = gen.integers(0, n, size=(resamples, n))
    q = [(1.0 - level) / 2.0, (1.0 + level) / 2.0]
    if isinstance(statistic, Vectorised):
        stats = _batched_statistics(arrays, statistic, idx)
    elif not paired and arrays[0].ndim == 1 and statistic in _AXIS_STATISTICS:
        stats = np.empty(resamples)
        chunk = max(1, 4_000_000 // n)  # bound the memory of the (chunk, n) block of resampled values
        for start in range(0, resamples, chunk):
            stats[start:start + chunk] = statistic(arrays[0][idx[start:start + chunk]], axis=1)
    else:
        stats = np.array([float(statistic(*(a[i] for a in arrays))) for i in idx])
    if not np.all(np.isfinite(stats)):
        return (math.nan, math.nan)
    lo, hi = np.quantile(stats, q)
    return (float(lo), float(hi))


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) confidence interval of a proportion ``k / n``.

    Parameters
    ----------
    k : int
        Number of successes, ``0 <= k <= n``.
    n : int
        Number of independent trials (runs).
    level : float, default 0.95
        Confidence level, in (0, 1).

    Returns
    -------
    (float, float)
        ``(beta.ppf(a/2, k, n-k+1), beta.ppf(1-a/2, k+1, n-k))`` with ``a = 1 - level``; the lower bound is
        0 when ``k = 0`` and the upper bound 1 when ``k = n``.  ``(0, 1)`` when ``n = 0``.

    Examples
    --------
    >>> round(binomial_interval(0, 10)[1], 4)
    0.3085
    """
    from scipy.stats import beta

    k, n = int(k), int(n)
    if n < 0 or not 0 <= k <= max(n, 0):
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if n == 0:
        return (0.0, 1.0)
    alpha = 1.0 - level
    lo = 0.0 if k == 0 else float(beta.ppf(alpha / 2.0, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - alpha / 2.0, k + 1, n - k))
    return (lo, hi)


def _check_direction(threshold: Any, direction: str) -> None:
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    if direction == "within":
        if np.ndim(threshold) != 1 or len(threshold) != 2 or not threshold[0] <= threshold[1]:
            raise ValueError(f"direction 'within' needs threshold=(low, high) with low <= high, got {threshold!r}")
    elif np.ndim(threshold) != 0:
        raise ValueError(f"direction {direction!r} needs one number as threshold, got {threshold!r}")


def judge(interval: tuple[float, float] | None, threshold: float | tuple[float, float], direction: str,
          n: int | None = None, min_n: int | None = None) -> str:
    """The three-way verdict of a confidence interval against a threshold.

    Parameters
    ----------
    interval : (float, float) or None
        The confidence interval ``(lo, hi)`` of our value.
    threshold : float or (float, float)
        The passing boundary; for ``direction="within"``, the passing range ``(low, high)``.
    direction : {">=", ">", "<=", "<", "within"}
        The passing side: ``value >= threshold`` etc., or ``low <= value <= high``.
    n, min_n : int, optional
        The number of runs behind the interval and the number the criterion needs.

    Returns
    -------
    str
        ``"met"`` when the whole interval lies on the passing side, ``"not met"`` when the whole interval
        lies on the failing side, ``"inconclusive"`` when it straddles the boundary, when ``n < min_n``,
        or when the interval is missing or not a number.

    Examples
    --------
    >>> judge((1.4, 1.6), 1.3, ">=")
    'met'
    >>> judge((1.2, 1.6), 1.3, ">=")
    'inconclusive'
    >>> judge((1.4, 1.6), 1.3, ">=", n=5, min_n=20)
    'inconclusive'
    """
    _check_direction(threshold, direction)
    if min_n is not None and (n is None or n < min_n):
        return "inconclusive"
    if interval is None:
        return "inconclusive"
    lo, hi = (float(v) for v in interval)
    if math.isnan(lo) or math.isnan(hi):
        return "inconclusive"
    if lo > hi:
        raise ValueError(f"interval must be (lo, hi) with lo <= hi, got {interval!r}")
    if direction == "within":
        a, b = (float(v) for v in threshold)
        if a <= lo and hi <= b:
            return "met"
        if hi < a or lo > b:
            return "not met"
        return "inconclusive"
    t = float(threshold)
    passing = {">=": lo >= t, ">": lo > t, "<=": hi <= t, "<": hi < t}[direction]
    failing = {">=": hi < t, ">": hi <= t, "<=": lo > t, "<": lo >= t}[direction]
    if passing:
        return "met"
    if failing:
        return "not met"
    return "inconclusive"


def _threshold_text(threshold: Any, direction: str) -> str:
    if direction == "within":
        return f"within [{threshold[0]:g}, {threshold[1]:g}]"
    return f"{direction} {float(threshold):g}"


def criterion_from_runs(id: str, text: str, samples: Any, statistic: Callable[..., float],
                        threshold: float | tuple[float, float], direction: str, *, min_n: int,
                        published: Any = None, detail: str = "", level: float = 0.95,
                        resamples: int = 2000, seed: int | None = 0, threshold_text: str | None = None,
                        replication: tuple[int, int] | None = None,
                        preconditions: tuple[Precondition, ...] = ()) -> Criterion:
    """A :class:`Criterion` judged from per-run data: ours, n, a bootstrap interval and the verdict.

    Parameters
    ----------
    id, text : str
        The criterion's id and statement.
    samples : array_like or tuple of array_like
        Per-run values, runs on the first axis (a tuple is a paired sample; see :func:`bootstrap_interval`).
    statistic : callable
        The judged statistic, e.g. ``np.mean`` or ``lambda a, c: a.mean() / c.mean()``.
    threshold, direction
        The passing condition (see :func:`judge`).
    min_n : int
        The fewest runs from which the criterion may be decided; with fewer the verdict is inconclusive.
    published : optional
        The paper's value, shown beside ours.
    detail : str
        The human explanation (how ours was computed, what stands behind it), kept as it is.  The numbers are the
        record's fields (``ours, n, interval, level, resamples, method, threshold, min_n``), not words in
        ``detail``: :attr:`Criterion.statistics` makes the sentence of them.
    level, resamples, seed
        Passed to :func:`bootstrap_interval`.
    threshold_text : str, optional
        The passing condition in words (default e.g. ``">= 1.3"``).
    replication : (int, int), optional
        ``(holds, of)`` from :func:`replication_rate`.
    preconditions : tuple of Precondition
        What must hold for the criterion to be judged (e.g. :func:`rows_track`); where any fails the verdict is
        ``"not judgeable"``.

    Returns
    -------
    Criterion
    """
    _check_direction(threshold, direction)
    arrays, _ = _as_runs(samples)
    n = int(arrays[0].shape[0])
    ours = float(statistic(*arrays)) if n else math.nan
    interval = bootstrap_interval(samples, statistic, level=level, resamples=resamples, seed=seed)
    verdict = judge(interval, threshold, direction, n=n, min_n=min_n)
    thr = threshold_text or _threshold_text(threshold, direction)
    no_interval = math.isnan(interval[0])
    return Criterion(id, text, verdict, _explanation(detail), ours=ours, published=published, n=n,
                     interval=interval, threshold=thr, replication=replication, min_n=min_n,
                     method=None if no_interval else f"percentile bootstrap, {resamples} resamples", level=level,
                     resamples=resamples, preconditions=tuple(preconditions))


def _explanation(detail: Any) -> str:
    """A constructor's ``detail``: the human explanation as given, refused by name where it is not text."""
    if not isinstance(detail, str):
        raise ValueError(f"detail is the explanation in words (a str), got {type(detail).__name__}: {detail!r}")
    return detail


def criterion_from_counts(id: str, text: str, k: int, n: int, threshold: float | tuple[float, float],
                          direction: str, *, min_n: int, published: Any = None, detail: str = "",
                          level: float = 0.95, threshold_text: str | None = None,
                          replication: tuple[int, int] | None = None,
                          preconditions: tuple[Precondition, ...] = ()) -> Criterion:
    """A :class:`Criterion` on a proportion ``k / n`` of runs, with the exact binomial interval.

    Parameters
    ----------
    id, text : str
        The criterion's id and statement.
    k, n : int
        Runs in which the event happened, and runs in all.
    threshold, direction, min_n, published, level, threshold_text, replication, preconditions
        As in :func:`criterion_from_runs` (the threshold is a proportion in [0, 1]).
    detail : str
        The human explanation, kept as it is; the numbers are the record's fields (``count`` = ``k``, ``n``,
        ``ours``, ``interval``, ``level``, ``method``, ``threshold``, ``min_n``; :attr:`Criterion.statistics`).

    Returns
    -------
    Criterion
    """
    _check_direction(threshold, direction)
    interval = binomial_interval(k, n, level)
    ours = k / n if n else math.nan
    verdict = judge(interval, threshold, direction, n=n, min_n=min_n)
    thr = threshold_text or _threshold_text(threshold, direction)
    return Criterion(id, text, verdict, _explanation(detail), ours=ours, published=published, n=int(n),
                     interval=interval, threshold=thr, replication=replication, min_n=min_n,
                     method="exact, Clopper-Pearson", level=level, count=int(k), preconditions=tuple(preconditions))


# -- equivalence (two one-sided tests) ------------------------------------------------------------------------

def equivalence_band(margin: float, *, ratio: bool = False) -> tuple[float, float]:
    """The equivalence range of a stated margin: ``[-margin, +margin]`` for a difference, ``[1/(1+m), 1+m]`` for a
    ratio (symmetric on the log scale: "within 5 %" either way).

    Examples
    --------
    >>> equivalence_band(0.5)
    (-0.5, 0.5)
    >>> tuple(round(v, 4) for v in equivalence_band(0.05, ratio=True))
    (0.9524, 1.05)
    """
    m = float(margin)
    if not (math.isfinite(m) and m > 0.0):
        raise ValueError(f"an equivalence margin must be a finite number > 0, got {margin!r}")
    return (1.0 / (1.0 + m), 1.0 + m) if ratio else (-m, m)


def _margin_text(margin: float, ratio: bool) -> str:
    return f"{100 * float(margin):g} %" if ratio else f"{float(margin):g}"


def judge_equivalent(interval: tuple[float, float] | None, margin: float, *, ratio: bool = False,
                     n: int | None = None, min_n: int | None = None) -> str:
    """The equivalence verdict (two one-sided tests) of a ``1 - 2 alpha`` interval against a stated margin.

    TOST at level alpha rejects both "difference <= -margin" and "difference >= +margin" exactly when the
    ``1 - 2 alpha`` interval (90 % for alpha = 0.05) lies inside the equivalence band; this is :func:`judge` with
    ``direction="within"`` on :func:`equivalence_band`.

    Returns
    -------
    str
        ``"met"`` (equivalent: the whole interval inside the band), ``"not met"`` (the whole interval outside it: a
        difference of at least the margin shown), else ``"inconclusive"`` (also when ``n < min_n``).

    Examples
    --------
    >>> judge_equivalent((-0.1, 0.2), 0.5), judge_equivalent((0.6, 0.9), 0.5), judge_equivalent((0.1, 0.7), 0.5)
    ('met', 'not met', 'inconclusive')
    """
    return judge(interval, equivalence_band(margin, ratio=ratio), "within", n=n, min_n=min_n)


def criterion_equivalent(id: str, text: str, samples: Any, statistic: Callable[..., float], margin: float, *,
                         ratio: bool = False, alpha: float = 0.05, min_n: int, published: Any = None,
                         detail: str = "", resamples: int = 2000, seed: int | None = 0,
                         threshold_text: str | None = None, replication: tuple[int, int] | None = None,
                         preconditions: tuple[Precondition, ...] = ()) -> Criterion:
    """A :class:`Criterion` for an "about equal" claim, judged as equivalence by two one-sided tests (TOST).

    The statistic is a per-run difference (equivalent to 0) or ratio (equivalent to 1) with a stated ``margin``.
    The two one-sided tests at level ``alpha`` are read from the percentile bootstrap interval at level
    ``1 - 2 alpha`` (90 % for alpha = 0.05) of :func:`criterion_from_runs` with ``direction="within"`` on
    :func:`equivalence_band`: *met* (equivalent, a tie) when the whole interval lies inside the band, *not met*
    when the whole interval lies outside it (a difference of at least the margin shown), else *inconclusive*.

    Parameters
    ----------
    id, text, samples, statistic, min_n, published, resamples, seed, threshold_text, replication, preconditions
        As in :func:`criterion_from_runs`.
    margin : float
        The stated margin: ``|difference| <= margin``, or for ``ratio=True`` the relative margin ``m`` of the band
        ``[1/(1+m), 1+m]``.  State it (and why) before looking at the result.
    ratio : bool, default False
        Whether the statistic is a ratio (equivalent to 1) rather than a difference (equivalent to 0).
    alpha : float, default 0.05
        The level of each one-sided test, in (0, 0.5); the interval's level is ``1 - 2 alpha``.
    detail : str
        The human explanation, kept as it is; the numbers are the record's fields and ``extra["equivalence"]``
        (:attr:`Criterion.statistics` says how it was judged).

    Returns
    -------
    Criterion
        ``method`` says ``"equivalence (TOST, margin ..., 90 % interval); percentile bootstrap, N resamples"``;
        ``extra`` holds ``equivalence: {margin, ratio, alpha, band}``.

    Examples
    --------
    >>> x = np.random.default_rng(0).normal(0.0, 0.1, 200)
    >>> c = criterion_equivalent("E", "about equal", x, np.mean, 0.1, min_n=20, resamples=500)
    >>> c.verdict, c.method.split(";")[0]
    ('met', 'equivalence (TOST, margin 0.1, 90 % interval)')
    """
    if not 0.0 < float(alpha) < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha!r}")
    band = equivalence_band(margin, ratio=ratio)
    level = 1.0 - 2.0 * float(alpha)
    mtext = _margin_text(margin, ratio)
    thr = threshold_text or (f"{100 * level:g} % interval within [{band[0]:.4g}, {band[1]:.4g}] (equivalent, "
                             f"margin {mtext})")
    c = criterion_from_runs(id, text, samples, statistic, band, "within", min_n=min_n, published=published,
                            detail=detail, level=level,
                            resamples=resamples, seed=seed,
                            threshold_text=thr, replication=replication, preconditions=preconditions)
    method = f"equivalence (TOST, margin {mtext}, {100 * level:g} % interval)" + (f"; {c.method}" if c.method else "")
    extra = {**c.extra, "equivalence": {"margin": float(margin), "ratio": bool(ratio), "alpha": float(alpha),
                                        "band": list(band)}}
    return replace(c, method=method, extra=extra)


def replication_rate(samples: Any, protocol_runs: int, holds_fn: Callable[..., bool], replications: int = 50,
                     seed: int | None = 0) -> tuple[int, int]:
    """How often a criterion, computed the paper's way on ``protocol_runs`` runs, holds on independent batches.

    The runs are shuffled (seeded) and cut into disjoint batches of ``protocol_runs`` runs; no run serves
    two batches.  With fewer than ``protocol_runs * replications`` runs, as many whole batches as fit are
    used (the rest of the runs are left out).

    Parameters
    ----------
    samples : array_like or tuple of array_like
        Per-run values, runs on the first axis; a tuple is paired and its arrays are cut by the same
        run indices.
    protocol_runs : int
        The paper's number of runs per evaluation (e.g. 20).
    holds_fn : callable
        ``holds_fn(*batch) -> bool``: the criterion computed the paper's way (no interval) on one batch.
    replications : int, default 50
        The number of batches wanted.
    seed : int or None, default 0
        Seed of the shuffle.

    Returns
    -------
    (int, int)
        ``(holds, of)``: batches on which the criterion held, batches evaluated.  ``(0, 0)`` when not one
        batch fits.
    """
    if protocol_runs < 1 or replications < 1:
        raise ValueError(f"protocol_runs and replications must be >= 1, got {protocol_runs}, {replications}")
    arrays, _ = _as_runs(samples)
    n = arrays[0].shape[0]
    batches = min(replications, n // protocol_runs)
    order = np.random.default_rng(seed).permutation(n)
    holds = 0
    for b in range(batches):
        idx = order[b * protocol_runs:(b + 1) * protocol_runs]
        holds += bool(holds_fn(*(a[idx] for a in arrays)))
    return (holds, batches)


# -- preconditions ------------------------------------------------------------------------------------------

def rows_track(lost: Mapping[str, Any], max_share: float, *, name: str = "judged rows track") -> Precondition:
    """The precondition "the judged rows track": each row loses at most ``max_share`` of its runs.

    Parameters
    ----------
    lost : mapping
        Row label -> per-run lost flags (bool array, one per run) of the runs the criterion judges.
    max_share : float
        The largest share of lost runs, in [0, 1], a row may have and still be judged.
    name : str
        The precondition's name.

    Returns
    -------
    Precondition
        Holds when every row has at least one run and ``lost / runs <= max_share``; ``detail`` gives every row's
        count (``"A 20/20 (100 %)"``), the limit and the rows above it; ``values`` holds ``max_share``, per row
        ``lost, runs, share`` and the list ``above``.

    Examples
    --------
    >>> p = rows_track({"A": [True, True, False, True], "C": [False] * 4}, 0.5)
    >>> p.holds, p.values["rows"]["A"]["lost"], p.values["above"]
    (False, 3, ['A'])
    """
    if not 0.0 <= float(max_share) <= 1.0:
        raise ValueError(f"max_share must be in [0, 1], got {max_share!r}")
    if not lost:
        raise ValueError("rows_track needs at least one row's lost flags")
    rows: dict[str, dict] = {}
    for label, flags in lost.items():
        f = np.asarray(flags)
        if f.ndim != 1 or not (f.dtype == bool or np.isin(f, (0, 1)).all()):
            raise ValueError(f"row {label!r}: lost flags must be one bool per run, got shape {f.shape}, "
                             f"dtype {f.dtype}")
        k, n = int(np.count_nonzero(f)), int(f.size)
        rows[str(label)] = {"lost": k, "runs": n, "share": k / n if n else math.nan}
    above = [label for label, r in rows.items() if not (r["runs"] > 0 and r["share"] <= max_share)]
    counts = ", ".join(f"{label} {r['lost']}/{r['runs']}"
                       + (f" ({100 * r['share']:.0f} %)" if r["runs"] else " (no runs)") for label, r in rows.items())
    detail = f"lost runs {counts}; each judged row may lose at most {100 * float(max_share):g} % of its runs"
    if above:
        detail += f"; above it: {', '.join(above)}"
    return Precondition(name, not above, detail, {"max_share": float(max_share), "rows": rows, "above": above})


def _mean_ratio_one(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(a) / np.mean(b))


_mean_ratio = vectorised(_mean_ratio_one, lambda a, b: a / b, given="means")


def reference_converged(at_n: Any, at_4n: Any, *, particles: int, tolerance: float, min_n: int | None = None,
                        level: float = 0.95, resamples: int = 2000, seed: int | None = 0,
                        what: str = "mean error", name: str = "reference converged") -> Precondition:
    """The precondition "the reference has converged": the reference at N against 4N on the same runs.

    The statistic is the paired ratio ``mean(at_n) / mean(at_4n)`` of a per-run error (for example each run's
    time-averaged MSE), with a paired percentile bootstrap interval (:func:`bootstrap_interval`).  The reference
    has converged when the whole interval lies within ``[1 - tolerance, 1 + tolerance]``: four times the
    particles changes its error by less than the tolerance.

    Parameters
    ----------
    at_n, at_4n : array_like
        Per-run errors of the reference with ``particles`` and with ``4 * particles``, on the same runs (the same
        truths and measurements) in the same order.
    particles : int
        N, the reference's particle count.
    tolerance : float
        The largest relative change of the error from N to 4N, in (0, 1).
    min_n : int, optional
        The fewest runs from which convergence may be shown; with fewer it is not shown (the precondition fails).
    level, resamples, seed
        Passed to :func:`bootstrap_interval`.
    what : str
        The per-run error's name, for the detail (e.g. ``"MSE"``).
    name : str
        The precondition's name.

    Returns
    -------
    Precondition
        ``values``: ``particles, particles_4n, n, ratio, interval, tolerance, band, min_n``.

    Examples
    --------
    >>> p = reference_converged([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0], particles=100, tolerance=0.05)
    >>> p.holds, p.values["ratio"]
    (True, 1.0)
    """
    if not 0.0 < float(tolerance) < 1.0:
        raise ValueError(f"tolerance must be in (0, 1), got {tolerance!r}")
    a, b = np.asarray(at_n, dtype=float), np.asarray(at_4n, dtype=float)
    if a.ndim != 1 or a.shape != b.shape:
        raise ValueError(f"the reference at N and at 4N need one error per run on the same runs, got shapes "
                         f"{a.shape} and {b.shape}")
    n = int(a.size)
    ratio = _mean_ratio(a, b) if n else math.nan
    interval = bootstrap_interval((a, b), _mean_ratio, level=level, resamples=resamples, seed=seed)
    band = (1.0 - float(tolerance), 1.0 + float(tolerance))
    enough = min_n is None or n >= min_n
    holds = enough and judge(interval, band, "within") == "met"
    detail = (f"{what} of the reference at N = {particles} / at 4N = {4 * particles} on the same {n} runs: "
              f"{ratio:.4g}, {100 * level:g} % interval [{interval[0]:.4g}, {interval[1]:.4g}] (paired percentile "
              f"bootstrap, {resamples} resamples); converged if the interval lies within "
              f"[{band[0]:g}, {band[1]:g}]")
    if not enough:
        detail += f"; needs n >= {min_n}"
    return Precondition(name, holds, detail, {"particles": int(particles), "particles_4n": 4 * int(particles),
                                              "n": n, "ratio": ratio, "interval": list(interval),
                                              "tolerance": float(tolerance), "band": list(band), "min_n": min_n})


# -- declared unknowns: the values a paper withholds, judged across a grid ---------------------------------------

def _value_text(value: Any) -> str:
    """A grid value in words: ``0.1``, ``1e-4``, ``"rad"``."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, float, np.integer, np.floating)):
        return f"{float(value):g}"
    return str(value)


def _grid_value(value: Any) -> float | str:
    """A grid value as stored: a finite float, or a non-empty string (a named choice)."""
    if isinstance(value, str):
        if not value.strip():
            raise ValueError("a grid value may not be an empty string")
        return value
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"a grid value must be a number or a name, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"a grid value must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class DeclaredUnknown:
    """A value the paper withholds that the reproduction had to choose, declared with the grid it is judged on.

    A recipe declares its unknowns (``RecipeSpec.unknowns``); its criteria that hinge on one are judged at every
    grid value (:func:`judge_across`) and the report shows, per criterion, where it holds
    (:func:`where_it_holds`) beside the verdict at the primary value.

    Attributes
    ----------
    name : str
        The value's name as the report writes it, e.g. ``"delta"``.
    unit : str
        Its unit or scale in words (``""`` for a pure number).
    primary : float or str
        The value the primary verdicts use (the pre-registered choice).
    grid : tuple of float or str
        The values every criterion that hinges on it is judged at; the primary is one of them.
    why : str
        Why the paper withholds it, where the primary came from, and what the grid spans.
    """

    name: str
    unit: str
    primary: Any
    grid: tuple
    why: str

    def __post_init__(self) -> None:
        if not str(self.name).strip():
            raise ValueError("a declared unknown needs a name")
        grid = tuple(_grid_value(v) for v in (self.grid or ()))
        if not grid:
            raise ValueError(f"declared unknown {self.name!r}: the grid is empty")
        if len(set(grid)) != len(grid):
            raise ValueError(f"declared unknown {self.name!r}: the grid repeats a value: {grid}")
        primary = _grid_value(self.primary)
        if primary not in grid:
            raise ValueError(f"declared unknown {self.name!r}: the primary value {_value_text(primary)} is not in "
                             f"its grid {[_value_text(v) for v in grid]}")
        if not str(self.why).strip():
            raise ValueError(f"declared unknown {self.name!r}: say why the paper withholds it and where the primary "
                             "came from")
        object.__setattr__(self, "grid", grid)
        object.__setattr__(self, "primary", primary)

    def label(self, value: Any) -> str:
        """``"delta = 0.1"`` (with the unit where there is one)."""
        return f"{self.name} = {_value_text(value)}" + (f" {self.unit}" if self.unit else "")

    def to_dict(self) -> dict:
        """``name, unit, primary, grid, why`` (JSON-ready)."""
        return {"name": self.name, "unit": self.unit, "primary": self.primary, "grid": list(self.grid),
                "why": self.why}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "DeclaredUnknown":
        """Rebuild a declared unknown written by :meth:`to_dict`."""
        return cls(str(data["name"]), str(data.get("unit", "")), data["primary"], tuple(data["grid"]),
                   str(data["why"]))


def _verdict_record(cls, data: Mapping[str, Any]):
    """A verdict record (:class:`UnknownVerdict`, :class:`Confirmation`) from its ``to_dict``: unknown keys ignored,
    the interval and the failed preconditions back to tuples."""
    names = {f.name for f in fields(cls)}
    kw = {k: v for k, v in data.items() if k in names}
    if kw.get("interval") is not None:
        kw["interval"] = tuple(kw["interval"])
    kw["failed"] = tuple(kw.get("failed") or ())
    return cls(**kw)

@dataclass(frozen=True)
class UnknownVerdict:
    """A criterion's verdict at one grid value of a declared unknown (a row of ``Criterion.across``).

    Attributes
    ----------
    unknown : str
        The declared unknown's name.
    value : float or str
        The grid value.
    verdict : str
        One of :data:`VERDICTS`, as the criterion judged at that value gave it.
    ours, n, interval
        The criterion's statistic, runs and interval at that value.
    failed : tuple of str
        The names of the preconditions that failed there (non-empty exactly when the verdict is not judgeable).
    detail : str
        A short note of the recipe's (e.g. the runs it was judged on).
    indicative : bool
        True in a quick report (the verdict is never ``"met"`` then).
    quick_verdict : str or None
        For an indicative record, the verdict the quick numbers gave before marking.
    """

    unknown: str
    value: Any
    verdict: str
    ours: Any = None
    n: int | None = None
    interval: tuple[float, float] | None = None
    failed: tuple[str, ...] = ()
    detail: str = ""
    indicative: bool = False
    quick_verdict: str | None = None

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"unknown {self.unknown!r} = {self.value!r}: verdict must be one of {VERDICTS}, got "
                             f"{self.verdict!r}")
        object.__setattr__(self, "value", _grid_value(self.value))
        object.__setattr__(self, "failed", tuple(str(f) for f in (self.failed or ())))
        if (self.verdict == NOT_JUDGEABLE) != bool(self.failed):
            raise ValueError(f"unknown {self.unknown!r} = {self.value!r}: a verdict is not judgeable exactly when a "
                             "precondition failed")
        if self.interval is not None:
            object.__setattr__(self, "interval", tuple(float(v) for v in self.interval))

    @classmethod
    def of(cls, unknown: str, value: Any, criterion: Criterion, detail: str = "") -> "UnknownVerdict":
        """The record of ``criterion`` (the criterion judged at ``unknown = value``)."""
        return cls(unknown, value, criterion.verdict, criterion.ours, criterion.n, criterion.interval,
                   tuple(p.name for p in criterion.failed_preconditions), detail, criterion.indicative,
                   criterion.quick_verdict)

    def as_indicative(self) -> "UnknownVerdict":
        """Marked as a quick-mode indication: ``"met"`` becomes ``"inconclusive"``, the quick verdict is kept."""
        if self.indicative:
            return self
        return replace(self, verdict="inconclusive" if self.verdict == "met" else self.verdict, indicative=True,
                       quick_verdict=self.verdict)

    def to_dict(self) -> dict:
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "UnknownVerdict":
        return _verdict_record(cls, data)


def judge_across(unknown: DeclaredUnknown, judged: Mapping[Any, Criterion],
                 notes: Mapping[Any, str] | None = None) -> tuple[UnknownVerdict, ...]:
    """A criterion's verdicts across ``unknown``'s grid, in grid order.

    Parameters
    ----------
    unknown : DeclaredUnknown
    judged : mapping
        Grid value -> the criterion judged with the unknown at that value.  Every grid value must be present
        (a grid value left out would read as "holds nowhere" there): a missing one raises.
    notes : mapping, optional
        Grid value -> a short note (e.g. the runs it was judged on).

    Returns
    -------
    tuple of UnknownVerdict
        For ``Criterion.across``.
    """
    keyed = {_grid_value(k): v for k, v in judged.items()}
    notes = {_grid_value(k): v for k, v in (notes or {}).items()}
    missing = [v for v in unknown.grid if v not in keyed]
    if missing:
        raise ValueError(f"{unknown.name}: no verdict at the grid values {[_value_text(v) for v in missing]}")
    extra = [k for k in keyed if k not in unknown.grid]
    if extra:
        raise ValueError(f"{unknown.name}: {[_value_text(v) for v in extra]} are not grid values "
                         f"{[_value_text(v) for v in unknown.grid]}")
    return tuple(UnknownVerdict.of(unknown.name, v, keyed[v], notes.get(v, "")) for v in unknown.grid)


def _set_text(values) -> str:
    return "{" + ", ".join(_value_text(v) for v in values) + "}"


def where_it_holds(across: Any, unknown: str | None = None) -> str:
    """Where a criterion holds across one declared unknown's grid, in one line.

    ``"holds everywhere"`` (met at every grid value), ``"holds nowhere"`` (not met, or not attainable, at every
    one), ``"holds for delta in {0.3, 1}"`` (met at some), ``"shown to hold at no value"`` (met at none, but not
    shown to fail at every one), followed by what it is elsewhere (``"not met at {0.1}"``, ``"inconclusive at
    {...}"``, ``"not attainable at {...}"``, ``"not judgeable at {...} (reference converged failed)"``).  Where no
    grid value could be judged the line is ``"not judgeable at every value ..."``.  For indicative (quick)
    records the line adds where the quick numbers alone would pass.

    Parameters
    ----------
    across : Criterion or sequence of UnknownVerdict
    unknown : str, optional
        Which unknown (default: the only one in ``across``; several raise).

    Returns
    -------
    str
        ``""`` where there are no records.
    """
    records = list(across.across if isinstance(across, Criterion) else across)
    if not records:
        return ""
    names = list(dict.fromkeys(r.unknown for r in records))
    if unknown is None:
        if len(names) > 1:
            raise ValueError(f"several unknowns {names}: name the one to describe")
        unknown = names[0]
    records = [r for r in records if r.unknown == unknown]
    if not records:
        return ""
    by: dict[str, list] = {}
    for r in records:
        by.setdefault(r.verdict, []).append(r.value)
    judged = [r for r in records if r.verdict != NOT_JUDGEABLE]
    met = by.get("met", [])
    failing = by.get("not met", []) + by.get("not attainable", [])
    if not judged:
        head = f"not judgeable at every value of {unknown}"
    elif len(met) == len(records):
        head = "holds everywhere"
    elif len(failing) == len(records):
        head = "holds nowhere"
    elif not met:
        head = "shown to hold at no value"
    else:
        head = f"holds for {unknown} in {_set_text(met)}"
    rest = []
    for verdict in ("not met", "inconclusive", "not attainable"):
        if by.get(verdict) and not (len(by[verdict]) == len(records) and verdict == "not met"):
            rest.append(f"{verdict} at {_set_text(by[verdict])}")
    nj = [r for r in records if r.verdict == NOT_JUDGEABLE]
    if nj and judged:
        why = sorted({f for r in nj for f in r.failed})
        rest.append(f"not judgeable at {_set_text([r.value for r in nj])} ({', '.join(why)} failed)")
    elif nj:
        head += f" ({', '.join(sorted({f for r in nj for f in r.failed}))} failed)"
    line = head + (f"; {'; '.join(rest)}" if rest else "")
    quick = [r.value for r in records if r.indicative and r.quick_verdict == "met"]
    if quick:
        line += f" (indicative: the quick numbers alone pass at {_set_text(quick)})"
    return line



# -- the confirmation seed: every criterion judged once more on a seed nothing was tuned on -------------------

@dataclass(frozen=True)
class Confirmation:
    """A criterion judged once more on the confirmation seed, beside its verdict on the reported seed.

    The report engine reruns the tasks a recipe's criteria read with the confirmation seed (a seed that no tuning
    and no design choice has seen) and judges the criteria again, unchanged (:func:`confirm` pairs them by id).

    Attributes
    ----------
    seed : int
        The confirmation seed.
    verdict : str or None
        The criterion's verdict on that seed (one of :data:`VERDICTS`), or ``None`` where it could not be judged
        there (a task failed, or the criteria did not return this id): ``detail`` says why.
    primary : str
        The verdict on the reported seed it is compared with.
    ours, n, interval
        The criterion's statistic, runs and interval on the confirmation seed.
    failed : tuple of str
        The preconditions that failed on the confirmation seed.
    detail : str
        Why there is no verdict, or a note.
    indicative : bool
        True in a quick report (the verdict is then never ``"met"``).
    """

    seed: int
    verdict: str | None
    primary: str
    ours: Any = None
    n: int | None = None
    interval: tuple[float, float] | None = None
    failed: tuple[str, ...] = ()
    detail: str = ""
    indicative: bool = False

    def __post_init__(self) -> None:
        for name in ("verdict", "primary"):
            value = getattr(self, name)
            if not (value in VERDICTS or (name == "verdict" and value is None)):
                raise ValueError(f"confirmation on seed {self.seed}: {name} must be one of {VERDICTS}, got {value!r}")
        if self.verdict is None and not str(self.detail).strip():
            raise ValueError(f"confirmation on seed {self.seed}: without a verdict, the detail must say why")
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "failed", tuple(str(f) for f in (self.failed or ())))
        if self.interval is not None:
            object.__setattr__(self, "interval", tuple(float(v) for v in self.interval))

    @property
    def agrees(self) -> bool | None:
        """Whether the confirmation seed gives the same verdict as the reported seed (``None``: no verdict)."""
        return None if self.verdict is None else self.verdict == self.primary

    def text(self) -> str:
        """``"agrees (met)"``, ``"differs: inconclusive (reported: met)"`` or ``"no verdict: WHY"``."""
        if self.verdict is None:
            return f"no verdict: {self.detail}"
        if self.agrees:
            return f"agrees ({self.verdict})"
        return f"differs: {self.verdict} (reported seed: {self.primary})"

    def as_indicative(self) -> "Confirmation":
        """Marked as a quick-mode indication: ``"met"`` becomes ``"inconclusive"`` on both sides."""
        if self.indicative:
            return self
        mark = lambda v: "inconclusive" if v == "met" else v  # noqa: E731
        return replace(self, verdict=mark(self.verdict), primary=mark(self.primary), indicative=True)

    def to_dict(self) -> dict:
        """Every field, JSON-ready, plus ``agrees``."""
        out = {f.name: _plain(getattr(self, f.name)) for f in fields(self)}
        out["agrees"] = self.agrees
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Confirmation":
        return _verdict_record(cls, data)


def confirm(reported: Any, again: Any, seed: int, missing: str = "") -> list[Criterion]:
    """The criteria judged on the reported seed, each with its :class:`Confirmation` from ``again``.

    Parameters
    ----------
    reported : sequence of Criterion
        The criteria as judged on the reported seed (their verdicts are the report's).
    again : sequence of Criterion or None
        The same recipe's criteria judged, unchanged, on results of the confirmation seed; paired with
        ``reported`` by id.  ``None`` where they could not be judged there (``missing`` says why).
    seed : int
        The confirmation seed.
    missing : str
        Why a criterion has no verdict on the confirmation seed (for ``again=None``, or an id it lacks).

    Returns
    -------
    list of Criterion
        ``reported`` in order, each with ``confirmation`` set; their own verdicts are unchanged.
    """
    by_id = {c.id: c for c in (again or ())}
    out = []
    for c in reported:
        other = by_id.get(c.id)
        if other is None:
            why = missing or f"the criteria judged on seed {seed} have no criterion {c.id!r}"
            record = Confirmation(seed, None, c.verdict, detail=why)
        else:
            record = Confirmation(seed, other.verdict, c.verdict, other.ours, other.n, other.interval,
                                  tuple(p.name for p in other.failed_preconditions))
        out.append(replace(c, confirmation=record))
    return out
