"""Paper 001's statistics from the task results (the arms' counts pooled over the seed blocks, removal rates,
continuity, RMSE) and its criteria 1-3, judged at the primary values and across the declared unknowns."""

from __future__ import annotations

from dataclasses import replace
from typing import Mapping

import numpy as np

from workbench.criteria import (DeclaredUnknown, Precondition, binomial_interval, bootstrap_interval,
                                criterion_from_counts, criterion_from_runs, judge_across, replication_rate, vectorised)
from workbench.metrics import TrackCounts, continuity, false_track_sums, pooled_rmse, removal_ratio
from workbench.report.engine import component_errors
from workbench.specs import Criterion
from workbench.types import InputError

from .scenario import (ARM_LABELS, FIELDS, GRID_IN_SIM, MIN_FALSE_BEFORE, MIN_RUNS, PROTOCOL_RUNS, TRUE_FRACTION,
                       UNKNOWNS, VARIANTS_IN_SIM, _unknown_key, _unknown_prefix)


def _unknown_rows(results: Mapping, unknown: DeclaredUnknown, value, block: int) -> tuple[Mapping | None, str]:
    """Where the paper rows of one grid value and seed block are: ``(result, prefix)`` (``None`` where missing)."""
    if unknown in GRID_IN_SIM:
        return results.get(f"sim/{block}"), _unknown_prefix(unknown, value)
    return results.get(_unknown_key(unknown, value, block)), ""


def _blocks(results: Mapping) -> list[str]:
    keys = sorted((k for k in results if k.startswith("sim/")), key=lambda k: int(k.split("/")[1]))
    if not keys:
        raise InputError("paper 001: no simulation results (task sim/0 missing)")
    return keys


def _arm_counts(results: Mapping, arm: str, phase: str, blocks: list[str] | None = None) -> TrackCounts | None:
    """An arm's counts pooled over the seed blocks (``None`` if absent)."""
    parts = []
    for key in (blocks if blocks is not None else _blocks(results)):
        res = results[key]
        if arm == "tuned":
            block = key.split("/")[1]
            res, name = results.get("tuning", {}), f"block{block}/tuned/{phase}/"
        else:
            name = f"{arm}/{phase}/"
        if f"{name}confirmed" not in res:
            return None
        parts.append(TrackCounts.from_arrays(res, name))
    return TrackCounts(*(np.concatenate([getattr(c, f) for c in parts]) for f in FIELDS))


def _variant_keys(results: Mapping, variant: str) -> tuple[list[str], str]:
    """The results that hold a remover variant's rows, over the blocks with variant results, and the prefix of its
    rows there (its counts ``{prefix}{arm}/after/``, ``{prefix}first_output_ping``): the ``variants/<block>`` tasks,
    or the ``sim/<block>`` tasks for a variant of :data:`VARIANTS_IN_SIM`."""
    keys = sorted((k for k in results if k.startswith("variants/")), key=lambda k: int(k.split("/")[1]))
    if variant in VARIANTS_IN_SIM:
        return [f"sim/{k.split('/')[1]}" for k in keys], ""
    return keys, f"{variant}/"


def _variant_counts(results: Mapping, variant: str, arm: str) -> tuple[TrackCounts, TrackCounts, list[str], str] | None:
    """Before (the blocks' ``arm``) and after (the variant, tracked by ``arm``) over the blocks with variant
    results; the results that hold the variant's rows and their prefix (:func:`_variant_keys`)."""
    keys, prefix = _variant_keys(results, variant)
    if not keys or any(k not in results for k in keys) or f"{prefix}{arm}/after/confirmed" not in results[keys[0]]:
        return None
    blocks = [f"sim/{k.split('/')[1]}" for k in keys]
    before = _arm_counts(results, arm, "before", blocks)
    after = [TrackCounts.from_arrays(results[k], f"{prefix}{arm}/after/") for k in keys]
    after = TrackCounts(*(np.concatenate([getattr(c, f) for c in after]) for f in FIELDS))
    return before, after, keys, prefix


def _post(results: Mapping, T: int, key: str | None = None) -> np.ndarray:
    res = results[key or _blocks(results)[0]]
    return np.arange(T) >= int(res["first_output_ping"])


def _masked_sq(b: TrackCounts, a: TrackCounts) -> tuple[np.ndarray, np.ndarray]:
    """Squared errors before and after on the (run, ping) pairs held in both (NaN elsewhere)."""
    both = b.held & a.held
    return np.where(both, b.sq_error, np.nan), np.where(both, a.sq_error, np.nan)


def _rmse_diff_one(sq_b: np.ndarray, sq_a: np.ndarray) -> float:
    """Pooled RMSE after minus before (pairs held in both); NaN when no pair."""
    return pooled_rmse(sq_a) - pooled_rmse(sq_b)


def _rmse_diff_many(counts: np.ndarray, sq_b: np.ndarray, sq_a: np.ndarray) -> np.ndarray:
    """:func:`_rmse_diff_one` of every resample, from each run's sum and count of finite squared errors weighted by
    the resample counts ``(resamples, runs)`` (no copy of the runs x pings arrays per resample)."""
    rmse = []
    for sq in (sq_a, sq_b):
        sq = sq.reshape(sq.shape[0], -1)
        finite = np.isfinite(sq)
        total = counts @ np.where(finite, sq, 0.0).sum(axis=1)
        held = counts @ finite.sum(axis=1).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            rmse.append(np.where(held > 0, np.sqrt(total / np.maximum(held, 1.0)), np.nan))
    return rmse[0] - rmse[1]


#: The statistic of criterion 3 and the rows table, declared with its batched form for the bootstrap.
_rmse_diff = vectorised(_rmse_diff_one, _rmse_diff_many, given="counts")


def _removal_ratio_many(counts: np.ndarray, sum_before: np.ndarray, sum_after: np.ndarray) -> np.ndarray:
    """:func:`removal_ratio` of every resample: the resampled sums as counts-weighted sums (exact for counts)."""
    den = counts @ np.asarray(sum_before, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, 1.0 - (counts @ np.asarray(sum_after, dtype=float)) / den, np.nan)


#: :func:`removal_ratio` declared with its batched form for the bootstrap.
_removal_ratio = vectorised(removal_ratio, _removal_ratio_many, given="counts")


def summary(before: TrackCounts, after: TrackCounts, post: np.ndarray) -> dict:
    """Removal rates, continuity and RMSE of one before/after pair, per run and pooled.

    The removal rates are held as their paired per-run sums ``(before (B,), after (B,))`` (see
    :func:`workbench.metrics.false_track_sums`): ``rate`` (false tracks, pings in ``post``), ``rate_all`` (all
    pings) and ``rate_total`` (confirmed tracks, pings in ``post``); ``false_before_runs (B,)`` is each run's mean
    number of false tracks per ping before removal over ``post``.
    """
    rate = false_track_sums(before.false, after.false, post)
    cont_b, cont_a = continuity(before.held), continuity(after.held)
    sq_b, sq_a = _masked_sq(before, after)
    return {
        "rate": rate, "rate_all": false_track_sums(before.false, after.false),
        "rate_total": false_track_sums(before.confirmed, after.confirmed, post),
        "false_before_runs": before.false[:, post].mean(axis=1), "false_before_sum": int(rate[0].sum()),
        "cont_before": cont_b, "cont_after": cont_a,
        "held80_before": int(np.sum(cont_b >= TRUE_FRACTION)), "held80_after": int(np.sum(cont_a >= TRUE_FRACTION)),
        "rmse_before": pooled_rmse(sq_b), "rmse_after": pooled_rmse(sq_a), "pairs": int(np.isfinite(sq_a).sum()),
        "sq_before": sq_b, "sq_after": sq_a,
        "false_after": float(after.false[:, post].mean()),
        "runs": int(before.false.shape[0]),
    }


def _rate_text(sums: tuple[np.ndarray, np.ndarray]) -> str:
    """The ratio of sums of a paired per-run sample ``(before, after)`` with its bootstrap interval over runs."""
    value = removal_ratio(*sums)
    if not np.isfinite(value):
        return "n/a (no false track before removal)"
    lo, hi = bootstrap_interval(sums, _removal_ratio)
    if not np.isfinite(lo):
        return f"{100 * value:.1f} %"
    return f"{100 * value:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def _per_ping_text(per_run: np.ndarray) -> str:
    """The mean over runs of per-run values (false tracks per ping) with its bootstrap interval over runs."""
    if per_run.size == 0:
        return "n/a"
    lo, hi = bootstrap_interval(per_run)
    if not np.isfinite(lo):
        return f"{per_run.mean():.2f}"
    return f"{per_run.mean():.2f} [{lo:.2f}, {hi:.2f}]"


def _share_text(k: int, n: int) -> str:
    if n == 0:
        return "n/a"
    lo, hi = binomial_interval(k, n)
    return f"{100 * k / n:.0f} % ({k}/{n}) [{100 * lo:.0f}, {100 * hi:.0f}]"


def _f(x, digits=2) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _kept_text(res: Mapping, prefix: str, name: str) -> str:
    n, k = res.get(f"{prefix}{name}_n"), res.get(f"{prefix}{name}_kept")
    if n is None or int(np.sum(n)) == 0:
        return "n/a"
    return f"{100 * np.sum(k) / np.sum(n):.1f} % (n={int(np.sum(n))})"


def _pooled_stats(results: Mapping, keys: list[str], prefix: str) -> dict:
    out: dict = {}
    for key in keys:
        for name, value in results[key].items():
            if name.startswith(prefix):
                out[name] = np.concatenate([out[name], np.atleast_1d(value)]) if name in out else np.atleast_1d(value)
    return out


def _arms_in(results: Mapping, tuned: bool = True) -> list[str]:
    """The arms with rows in every seed block (an arm whose filter raised in any block is left out here and
    marked FAILED by :func:`_failed_rows`): the paper's own arms (the tuned one only with ``tuned``), then any
    added ``filter:`` arm."""
    arms = [a for a in ARM_LABELS if (tuned or a != "tuned") and _arm_counts(results, a, "after") is not None]
    added = {k.split("/")[0] for key in _blocks(results) for k in results[key]
             if k.startswith("filter:") and k.endswith("/after/confirmed")}
    arms += sorted(a for a in added if _arm_counts(results, a, "after") is not None)
    return arms


def _failed_arms(results: Mapping) -> dict[str, str]:
    """``{arm: "RuntimeError: ..."}`` of the arms whose filter raised in a simulation block (their rows are left
    out; the report names the failure in the paper's errors too)."""
    failed: dict[str, str] = {}
    for key in (k for k in results if k.startswith("sim/")):
        for arm, message in component_errors(results[key]):
            failed.setdefault(arm, f"{key}: {message}")
    return failed


def _failed_rows(results: Mapping, width: int, lead: tuple = ()) -> list[tuple]:
    """One marked row per failed arm: ``lead``, the arm, ``FAILED: <error>``, blanks up to ``width`` columns."""
    return [(*lead, arm, f"FAILED, no rows: {msg}", *([""] * (width - len(lead) - 2)))
            for arm, msg in sorted(_failed_arms(results).items())]


def _replication(samples, holds) -> tuple[int, int] | None:
    n = np.asarray(samples[0] if isinstance(samples, tuple) else samples).shape[0]
    if n < 2 * PROTOCOL_RUNS:
        return None
    return replication_rate(samples, PROTOCOL_RUNS, holds, replications=n // PROTOCOL_RUNS)


def _c1_holds(sum_before, sum_after) -> bool:
    r = removal_ratio(sum_before, sum_after)
    return bool(np.isfinite(r) and 0.60 <= r <= 0.95)


def c1_criterion(before_false: np.ndarray, after_false: np.ndarray, post: np.ndarray, prefix: str = "",
                 suffix: str = "", min_false: int = MIN_FALSE_BEFORE) -> Criterion:
    """Criterion 1 from the false-track counts ``(B, T)`` before and after removal and the judged pings ``post``.

    Ours: the ratio of sums ``1 - sum F_after / sum F_before`` over the runs and the pings in ``post``; its 95 %
    interval a percentile bootstrap over runs (each run's two sums resampled together), judged within
    [0.60, 0.95] from at least ``MIN_RUNS["1"]`` runs.  Beside it: the false tracks per ping before removal (mean
    over runs and pings, bootstrap interval over runs) and their sum.  The population precondition: with fewer
    than ``min_false`` false tracks before removal summed over the runs and pings, the verdict is not judgeable
    (never met, never not met), the reason in the detail and ``extra["precondition"]``.
    """
    sums = false_track_sums(before_false, after_false, post)
    judged = np.flatnonzero(post) + 1
    pings = f"pings {judged[0]}-{judged[-1]}" if judged.size else "no pings"
    per_run = np.asarray(before_false, dtype=float)[:, np.asarray(post, dtype=bool)].mean(axis=1)
    total = int(sums[0].sum())
    held = total >= min_false
    lo, hi = bootstrap_interval(per_run) if per_run.size > 1 else (np.nan, np.nan)
    interval = f" [{lo:.3g}, {hi:.3g}]" if np.isfinite(lo) else ""
    mean = float(per_run.mean()) if per_run.size else float("nan")
    population = (f"false tracks per ping before removal {mean:.3g}{interval} (mean over {per_run.size} runs x "
                  f"{pings}, bootstrap over runs); {total} false tracks before removal summed, "
                  f"{int(sums[1].sum())} after")
    pre = (f"population precondition: >= {min_false} false tracks before removal summed over the runs "
           f"({'holds' if held else 'FAILS'}: {total})")
    text = (prefix + f"; rate = 1 - sum F_after / sum F_before over the runs and {pings}; " + population + "; " + pre
            + suffix)
    name = "false tracks before removal, summed"
    # a failed precondition makes the verdict "not judgeable"
    population_holds = Precondition(name, held, f"{total} summed over {per_run.size} runs x {pings}; needs >= "
                                    f"{min_false}", {"needs": min_false, "has": total})
    crit = criterion_from_runs(
        "1", "mean false-track removal rate in simulation is in 60-95 % (paper 78 %)", sums, _removal_ratio,
        (0.60, 0.95), "within", min_n=MIN_RUNS["1"], published="78 %", detail=text,
        threshold_text="removal rate (ratio of sums) within [0.60, 0.95]",
        replication=_replication(sums, _c1_holds), preconditions=(population_holds,))
    extra = dict(crit.extra, false_per_ping_before=mean if np.isfinite(mean) else None,
                 false_per_ping_before_interval=(float(lo), float(hi)) if np.isfinite(lo) else None,
                 precondition={"name": name, "needs": min_false, "has": total, "holds": held})
    if held:
        return replace(crit, extra=extra)
    reason = (f"; NOT JUDGEABLE: {total} false tracks before removal summed over the runs, fewer than the "
              f"{min_false} the rate needs (verdict {crit.verdict_if_judged!r} from the interval alone set aside)")
    return replace(crit, detail=crit.detail + reason, extra=extra)


def _c2_holds(cont) -> bool:
    return bool(np.mean(cont >= TRUE_FRACTION) >= 0.90)


def _c3_holds(sq_b, sq_a) -> bool:
    d = _rmse_diff(sq_b, sq_a)
    return bool(np.isfinite(d) and d <= 0.0)


def _others(results, post, what: str) -> str:
    """The same statistic on the extra rows of the simulation blocks, for the detail text (the tuned row is in the
    rows table: the criteria never read the tuning task, so the confirmation seed does not rerun it)."""
    parts = []
    for arm in _arms_in(results, tuned=False):
        if arm == "paper":
            continue
        s = summary(_arm_counts(results, arm, "before"), _arm_counts(results, arm, "after"), post)
        label = {"stated": "R from stated accuracy", "previous": "previous settings",
                 "paper-mofn": "paper's M-of-N (initiation counted) with matched R",
                 "two-point": "two-point initial covariance"}.get(arm, arm)
        if what == "rate":
            parts.append(f"{label} {_rate_text(s['rate'])}")
        elif what == "held":
            parts.append(f"{label} {_share_text(s['held80_after'], s['runs'])}")
        else:
            parts.append(f"{label} {_f(s['rmse_after'] - s['rmse_before'])}")
    return "; other rows (not judged): " + ", ".join(parts) if parts else ""


def remover_cap(stats: Mapping) -> dict:
    """What the remover costs criterion 2: the target's detections at the pings after the warm-up that it drops,
    split by whether the target was detected at the previous ping (``miss``: it was not), pooled over the runs.

    ``stats``: the ``rem/main/`` arrays (``miss_n, miss_kept, hit_n, hit_kept`` per run).  Returns
    ``{"miss_n", "miss_dropped", "hit_n", "hit_dropped"}`` (counts)."""
    out = {}
    for name in ("miss", "hit"):
        n = int(np.sum(stats.get(f"rem/main/{name}_n", 0)))
        out[f"{name}_n"] = n
        out[f"{name}_dropped"] = n - int(np.sum(stats.get(f"rem/main/{name}_kept", 0)))
    return out


def _cap_text(results, s: Mapping) -> str:
    """Criterion 2's cap in words, with numbers: the target detections the remover drops after a missed ping and
    otherwise, and the runs holding the target before against after removal."""
    cap = remover_cap(_pooled_stats(results, _blocks(results), "rem/main/"))
    pct = lambda k, n: f"{100 * k / n:.1f} % ({k} of {n})" if n else "n/a (none)"  # noqa: E731
    lost = s["held80_before"] - s["held80_after"]
    return (f"; the cap on it: the remover drops {pct(cap['miss_dropped'], cap['miss_n'])} of the target's "
            f"detections at a ping after a missed ping and {pct(cap['hit_dropped'], cap['hit_n'])} after a "
            f"detected one (pings after the warm-up); runs holding the target >= 80 % go from "
            f"{s['held80_before']} of {s['runs']} before removal to {s['held80_after']} after ({lost:+d} "
            f"runs lost to the remover: {100 * lost / max(s['runs'], 1):.1f} points)")


def _judge(b: TrackCounts, a: TrackCounts, post: np.ndarray, label: str, others: tuple = ("", "", ""),
           cap: str = "") -> list[Criterion]:
    """Criteria 1-3 of one row from its counts before and after removal (``label`` names the row and runs)."""
    s = summary(b, a, post)
    out = [c1_criterion(b.false, a.false, post, label, others[0])]
    cont = s["cont_after"]
    out.append(criterion_from_counts(
        "2", "after removal the target holds a confirmed track for >= 80 % of the pings after initiation in >= 90 % "
             "of runs", s["held80_after"], s["runs"], 0.90, ">=", min_n=MIN_RUNS["2"], published=">= 90 % of runs",
        detail=f"{label}; before removal {_share_text(s['held80_before'], s['runs'])}" + cap + others[1],
        threshold_text="share of runs >= 0.90", replication=_replication(cont, _c2_holds)))
    sq = (s["sq_before"], s["sq_after"])
    out.append(criterion_from_runs(
        "3", "target-track RMSE after removal <= RMSE before", sq, _rmse_diff, 0.0, "<=", min_n=MIN_RUNS["3"],
        published="after <= before",
        detail=f"{label}; RMSE after minus before on the {s['pairs']} (run, ping) pairs "
               f"held in both ({_f(s['rmse_after'])} vs {_f(s['rmse_before'])})" + others[2],
        threshold_text="RMSE after - RMSE before <= 0", replication=_replication(sq, _c3_holds)))
    return out


def _unknown_counts(results: Mapping, unknown: DeclaredUnknown, value, phase: str) -> TrackCounts | None:
    """The paper rows at one grid value, pooled over the seed blocks (None where a block's task is missing)."""
    parts = []
    for block in range(len(_blocks(results))):
        res, prefix = _unknown_rows(results, unknown, value, block)
        if res is None or f"{prefix}paper/{phase}/confirmed" not in res:
            return None
        parts.append(TrackCounts.from_arrays(res, f"{prefix}paper/{phase}/"))
    return TrackCounts(*(np.concatenate([getattr(c, f) for c in parts]) for f in FIELDS))


def _across_unknowns(results: Mapping, judged: list[Criterion], b: TrackCounts, post: np.ndarray) -> list[Criterion]:
    """``judged`` (the paper rows' criteria at the primary values) with their verdicts at every grid value of
    :data:`UNKNOWNS` (``Criterion.across``); an unknown whose grid tasks are missing is left out."""
    out = list(judged)
    for unknown in UNKNOWNS:
        at: dict = {}
        for value in unknown.grid:
            if value == unknown.primary:
                at[value] = judged
                continue
            bv, av = _unknown_counts(results, unknown, value, "before"), _unknown_counts(results, unknown, value,
                                                                                          "after")
            if bv is None or av is None:
                at = {}
                break
            at[value] = _judge(bv, av, post, unknown.label(value))
        if not at:
            continue
        note = f"paper rows, the same {b.false.shape[0]} runs (the same target detections) at every value"
        out = [replace(c, across=c.across + judge_across(unknown, {v: at[v][i] for v in unknown.grid},
                                                         {v: note for v in unknown.grid}))
               for i, c in enumerate(out)]
    return out


def criteria(results) -> list[Criterion]:
    blocks = _blocks(results)
    b, a = _arm_counts(results, "paper", "before"), _arm_counts(results, "paper", "after")
    post = _post(results, b.false.shape[1])
    s = summary(b, a, post)
    label = f"paper rows, {len(blocks)} seed block(s) of {b.false.shape[0] // len(blocks)} runs"
    others = tuple(_others(results, post, what) for what in ("rate", "held", "rmse"))
    judged = _judge(b, a, post, label, others, _cap_text(results, s))
    return _across_unknowns(results, judged, b, post)
