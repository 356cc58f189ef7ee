"""Paper 001's tables (removal rates, rows, seed blocks, per ping, remover variants, tuning, surrogate, timing,
GOSPA and the trackers compared), collected in :data:`TABLES`."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from workbench.criteria import bootstrap_interval
from workbench.metrics import TrackCounts, continuity, false_track_sums, removal_rate_pooled_per_ping
from workbench.report.engine import component_errors
from workbench.specs import Table, TableSpec

from .judging import (_arm_counts, _arms_in, _blocks, _f, _failed_rows, _kept_text, _per_ping_text, _pooled_stats,
                      _post, _rate_text, _rmse_diff, _share_text, _variant_counts, summary)
from .scenario import (ARM_LABELS, FIELDS, MIN_SPEED, PAPER_TRACKER, PUBLISHED, TRUE_FRACTION, TUNING_CANDIDATES,
                       TUNING_RULE, TUNING_STREAM, VARIANT_LABELS, VARIANTS)
from .tasks import _tracker_prefix


def _tuned_label(results: Mapping) -> str:
    t = results.get("tuning")
    if t is None:
        return ARM_LABELS["tuned"]
    cand = TUNING_CANDIDATES[int(t["tuning/chosen"])]
    gate = "filter's R" if cand["gate_sigma"] is None else f"sigma {cand['gate_sigma']:g}"
    return f"tuned (tuning runs only): gate with {gate}, delete after {cand['delete_misses']} misses"


def _removal_table(results) -> Table:
    rows = []
    blocks = _blocks(results)
    T = results[blocks[0]]["paper/before/false"].shape[1]
    post = _post(results, T)
    for arm in _arms_in(results):
        s = summary(_arm_counts(results, arm, "before"), _arm_counts(results, arm, "after"), post)
        label = _tuned_label(results) if arm == "tuned" else ARM_LABELS.get(arm, f"{arm}, brief's defaults")
        rows.append(("simulation", label, f"{100 * PUBLISHED['removal_rate_simulation']:.0f} %", _rate_text(s["rate"]),
                     _rate_text(s["rate_all"]), _rate_text(s["rate_total"]), _per_ping_text(s["false_before_runs"]),
                     _f(s["false_after"], 2), s["false_before_sum"], s["runs"]))
    rows += _failed_rows(results, 10, ("simulation",))
    for task, label in (("surrogate", "sea-trial surrogate, Monte Carlo (SYNTHETIC)"),
                        ("file", "sea-trial surrogate file, one run (SYNTHETIC)")):
        if task not in results:
            continue
        res = results[task]
        post_s = np.arange(T) >= int(res["first_output_ping"])
        b = TrackCounts.from_arrays(res, "paper/before/")
        for arm, arm_label in (("paper", ARM_LABELS["paper"]),
                               ("min-speed", f"EXTENSION: paper + minimum-speed test ({MIN_SPEED:g} units/ping)")):
            s = summary(b, TrackCounts.from_arrays(res, f"{arm}/after/"), post_s)
            rows.append((label, arm_label, f"{100 * PUBLISHED['removal_rate_sea_trial']:.0f} %", _rate_text(s["rate"]),
                         _rate_text(s["rate_all"]), _rate_text(s["rate_total"]), _per_ping_text(s["false_before_runs"]),
                         _f(s["false_after"], 2), s["false_before_sum"], s["runs"]))
    return Table(("case", "row", "published removal rate",
                  "ours: 1 - sum F_after / sum F_before (false tracks, runs x pings 6-20) [95 % CI]",
                  "ours incl. warm-up pings", "ours, total tracks", "false tracks/ping before (pings 6-20) [95 % CI]",
                  "false tracks/ping after", "false tracks before, summed", "runs"), tuple(rows))


def _per_ping_table(results) -> Table:
    b, a = _arm_counts(results, "paper", "before"), _arm_counts(results, "paper", "after")
    r = removal_rate_pooled_per_ping(b.false, a.false)
    none_before = b.false == 0
    rows = []
    for k in range(b.false.shape[1]):
        n = int(np.sum(b.false[:, k] > 0))
        rows.append((k + 1, _f(b.false[:, k].mean()), _f(a.false[:, k].mean()),
                     "n/a" if not np.isfinite(r[k]) else f"{100 * r[k]:.1f} %", n,
                     int(np.sum(a.false[:, k][none_before[:, k]]))))
    post = _post(results, b.false.shape[1])
    s = summary(b, a, post)
    rows.append(("pings 6-20", _per_ping_text(s["false_before_runs"]), _f(a.false[:, post].mean()),
                 _rate_text(s["rate"]), int(np.sum(b.false[:, post] > 0)),
                 int(np.sum(a.false[:, post][none_before[:, post]]))))
    return Table(("ping", "false tracks before (mean per run)", "false tracks after (mean per run)",
                  "removal rate 1 - sum F_after / sum F_before over the runs",
                  "runs with a false track before (last row: run-pings)",
                  "false tracks after removal in runs with none before at that ping (they lower the rate)"), tuple(rows))


def _rows_table(results) -> Table:
    """Every arm: removal rate, criterion 2's share and criterion 3's RMSE, with intervals."""
    blocks = _blocks(results)
    T = results[blocks[0]]["paper/before/false"].shape[1]
    post = _post(results, T)
    rows = []
    for arm in _arms_in(results):
        s = summary(_arm_counts(results, arm, "before"), _arm_counts(results, arm, "after"), post)
        diff_ci = bootstrap_interval((s["sq_before"], s["sq_after"]), _rmse_diff)
        label = _tuned_label(results) if arm == "tuned" else ARM_LABELS.get(arm, arm)
        rows.append((label, _rate_text(s["rate"]), _per_ping_text(s["false_before_runs"]),
                     _share_text(s["held80_before"], s["runs"]),
                     _share_text(s["held80_after"], s["runs"]),
                     f"{_f(s['rmse_before'])} / {_f(s['rmse_after'])}",
                     f"{_f(s['rmse_after'] - s['rmse_before'])} [{_f(diff_ci[0])}, {_f(diff_ci[1])}]",
                     s["pairs"], s["runs"]))
    rows += _failed_rows(results, 9)
    return Table(("row", "removal rate, ratio of sums [95 % CI] (criterion 1)",
                  "false tracks/ping before removal [95 % CI]", "runs holding the target >= 80 %, before [CI]",
                  "after removal [CI] (criterion 2)", "RMSE before / after (paired pings)",
                  "RMSE after - before [CI] (criterion 3)", "paired pings", "runs"), tuple(rows))


def _gospa_stats(results: Mapping, arm: str, phase: str) -> dict | None:
    """Per-run means over the pings after the warm-up of GOSPA and its terms, pooled over the seed blocks."""
    blocks = _blocks(results)
    if any(f"{arm}/{phase}/gospa" not in results[key] for key in blocks):  # the arm failed in some block
        return None
    out = {}
    for term in ("gospa", "gospa_loc", "gospa_missed", "gospa_false"):
        runs = []
        for key in blocks:
            values = np.asarray(results[key][f"{arm}/{phase}/{term}"], dtype=float)
            post = _post(results, values.shape[1], key)
            runs.append(values[:, post].mean(axis=1))
        out[term] = np.concatenate(runs)
    return out


def _gospa_table(results) -> Table:
    """GOSPA (c = 10, p = 2) of every arm before and after removal: the distance (mean over runs and pings after the
    warm-up, 95 % bootstrap interval over runs) and its terms (localisation, missed, false; in units^2)."""
    rows = []
    for arm in _arms_in(results):
        label = _tuned_label(results) if arm == "tuned" else ARM_LABELS.get(arm, arm)
        for phase in ("before", "after"):
            g = _gospa_stats(results, arm, phase)
            if g is None:
                continue
            lo, hi = bootstrap_interval(g["gospa"])
            rows.append((label, phase, f"{_f(g['gospa'].mean())} [{_f(lo)}, {_f(hi)}]", _f(g["gospa_loc"].mean()),
                         _f(g["gospa_missed"].mean()), _f(g["gospa_false"].mean()), g["gospa"].size))
    return Table(("row", "removal", "GOSPA [95 % CI]", "localisation", "missed", "false", "runs"), tuple(rows))


def _tracker_blocks(results: Mapping) -> list[str]:
    return sorted((k for k in results if k.startswith("trackers/")), key=lambda k: int(k.split("/")[1]))


def tracker_order(results: Mapping) -> list[str]:
    """The trackers compared, in ``RecipeOptions.trackers`` order (empty when the report compares none)."""
    keys = _tracker_blocks(results)
    return [str(t) for t in np.atleast_1d(results[keys[0]]["order"])] if keys else []


def comparison_rows(results: Mapping) -> list[tuple[str, str, str, tuple[str, str]]]:
    """``(reference, label, kind, source)`` of every row of the tracker comparison: the paper's ``"mofn"`` gives
    two rows read from the simulation blocks' arms (``("arm", "paper")``: the judged rows; ``("arm", "stated")``:
    the same M-of-N with the extension rows' R), any other reference one EXTENSION row from the ``trackers/``
    blocks (``("tracker", reference)``)."""
    rows = []
    for ref in tracker_order(results):
        if ref == PAPER_TRACKER:
            rows.append((ref, "M-of-N, " + ARM_LABELS["paper"], "paper's method (judged rows)", ("arm", "paper")))
            rows.append((ref, "M-of-N, " + ARM_LABELS["stated"] + ": the extension rows' R", "paper's method, "
                         "principled R (not judged)", ("arm", "stated")))
        else:
            rows.append((ref, f"{ref}, Kalman filter with R from the sensor's stated accuracy (sigma 2.0)",
                         "EXTENSION (not in the paper)", ("tracker", ref)))
    return rows


def comparison_series(results: Mapping, source: tuple[str, str], phase: str) -> tuple[TrackCounts, np.ndarray] | None:
    """A comparison row's counts and GOSPA ``(B, T)`` at ``phase``, pooled over the seed blocks (``None`` where the
    row failed in a block or is absent)."""
    kind, name = source
    keys, prefix = ((_blocks(results), f"{name}/{phase}/") if kind == "arm"
                    else (_tracker_blocks(results), _tracker_prefix(name, phase)))
    if not keys or any(f"{prefix}gospa" not in results[k] or f"{prefix}confirmed" not in results[k] for k in keys):
        return None
    parts = [TrackCounts.from_arrays(results[k], prefix) for k in keys]
    counts = TrackCounts(*(np.concatenate([getattr(c, f) for c in parts]) for f in FIELDS))
    return counts, np.concatenate([np.asarray(results[k][f"{prefix}gospa"], dtype=float) for k in keys])


def _tracker_post(results: Mapping, T: int) -> np.ndarray:
    """The pings after the Hough warm-up (the paper rows' and the extension rows' warm-up are the same)."""
    keys = [k for k in results if k.startswith("sim/")] or _tracker_blocks(results)
    return np.arange(T) >= int(results[keys[0]]["first_output_ping"])


def _failed_trackers(results: Mapping) -> dict[str, str]:
    failed: dict[str, str] = {}
    for key in _tracker_blocks(results):
        for what, message in component_errors(results[key]):
            if what.startswith("tracker:"):
                failed.setdefault(what[len("tracker:"):], f"{key}: {message}")
    return failed


def _mean_text(per_run: np.ndarray, scale: float = 1.0, digits: int = 2, unit: str = "") -> str:
    """The mean over runs of per-run values with its 95 % bootstrap interval over runs."""
    if per_run.size == 0:
        return "n/a"
    lo, hi = bootstrap_interval(per_run) if per_run.size > 1 else (np.nan, np.nan)
    mean = f"{scale * per_run.mean():.{digits}f}{unit}"
    return mean if not np.isfinite(lo) else f"{mean} [{scale * lo:.{digits}f}, {scale * hi:.{digits}f}]"


def tracker_stats(counts: TrackCounts, gospa: np.ndarray, post: np.ndarray) -> dict:
    """Per run over the pings in ``post``: mean GOSPA, false tracks per ping and the share of pings at which a
    confirmed true track holds the target; and each run's continuity (criterion 2's statistic)."""
    return {"gospa": gospa[:, post].mean(axis=1), "false": counts.false[:, post].mean(axis=1),
            "held": counts.held[:, post].mean(axis=1), "continuity": continuity(counts.held)}


def _trackers_table(results) -> Table:
    """Every tracker compared, before and after removal on the same runs: GOSPA, false tracks per ping, the share of
    pings the target is held (each a mean over runs of per-run means over the pings after the warm-up, 95 %
    bootstrap interval over runs), runs holding the target >= 80 % (exact binomial interval) and the removal rate
    (ratio of sums, paired bootstrap)."""
    rows = []
    for ref, label, kind, source in comparison_rows(results):
        got = {phase: comparison_series(results, source, phase) for phase in ("before", "after")}
        if got["before"] is None or got["after"] is None:
            continue
        post = _tracker_post(results, got["before"][1].shape[1])
        for phase in ("before", "after"):
            counts, gospa = got[phase]
            st = tracker_stats(counts, gospa, post)
            rate = ("-" if phase == "before" else
                    _rate_text(false_track_sums(got["before"][0].false, counts.false, post)))
            rows.append((ref, label, kind, phase, _mean_text(st["gospa"]), _mean_text(st["false"]),
                         _mean_text(st["held"], 100.0, 1, " %"),
                         _share_text(int(np.sum(st["continuity"] >= TRUE_FRACTION)), st["continuity"].size), rate,
                         st["gospa"].size))
    rows += [(ref, f"FAILED, no rows: {msg}", "EXTENSION (not in the paper)", *([""] * 7))
             for ref, msg in sorted(_failed_trackers(results).items())]
    return Table(("tracker", "row", "kind", "removal", "GOSPA (c = 10, p = 2) per ping [95 % CI]",
                  "false tracks/ping [95 % CI]", "share of pings the target is held [95 % CI]",
                  "runs holding the target >= 80 % of the pings after initiation [CI]",
                  "removal rate, ratio of sums [95 % CI]", "runs"), tuple(rows))


def _seed_table(results) -> Table:
    """Criterion 2 (paper rows) seed block by seed block."""
    rows = []
    for key in _blocks(results):
        a = TrackCounts.from_arrays(results[key], "paper/after/")
        k = int(np.sum(continuity(a.held) >= TRUE_FRACTION))
        rows.append((key.split("/")[1], _share_text(k, a.held.shape[0])))
    return Table(("seed block (seed = report seed + block)", "runs holding the target >= 80 % after removal [CI]"),
                 tuple(rows))


def _variant_table(results) -> Table:
    rows = []
    for name in VARIANTS:
        got = {arm: _variant_counts(results, name, arm) for arm in ("paper", "stated")}
        if got["paper"] is None or got["stated"] is None:
            continue
        keys, prefix = got["paper"][2], got["paper"][3]
        post = np.arange(got["paper"][0].false.shape[1]) >= int(results[keys[0]][f"{prefix}first_output_ping"])
        s = {arm: summary(got[arm][0], got[arm][1], post) for arm in got}
        st = _pooled_stats(results, keys, f"rem/{name}/")
        rows.append((VARIANT_LABELS[name], _kept_text(st, f"rem/{name}/", "hit"),
                     _kept_text(st, f"rem/{name}/", "miss"), _kept_text(st, f"rem/{name}/", "clutter"),
                     _rate_text(s["paper"]["rate"]), _share_text(s["paper"]["held80_after"], s["paper"]["runs"]),
                     _rate_text(s["stated"]["rate"]), _share_text(s["stated"]["held80_after"], s["stated"]["runs"]),
                     s["paper"]["runs"]))
    return Table(("remover", "target kept, detected at k-1", "target kept after a miss at k-1", "clutter kept",
                  "paper rows: removal rate (ratio of sums) [CI]", "paper rows: runs holding the target >= 80 % [CI]",
                  "R from stated accuracy: removal rate (ratio of sums) [CI]",
                  "R from stated accuracy: runs holding >= 80 % [CI]",
                  "runs"), tuple(rows))


def _tuning_table(results) -> Table:
    t = results.get("tuning")
    if t is None:
        return Table(("candidate",), ())
    n = int(t["tuning/runs"])
    chosen = int(t["tuning/chosen"])
    rows = []
    for i, cand in enumerate(TUNING_CANDIDATES):
        gate = "filter's R" if cand["gate_sigma"] is None else f"sigma {cand['gate_sigma']:g}"
        rows.append((gate, cand["delete_misses"], _share_text(int(t["tuning/held"][i]), n),
                     "chosen" if i == chosen else ""))
    rows.append(("rule: " + TUNING_RULE, "", f"tuning runs: stream '{TUNING_STREAM}', runs 0..{n - 1} (never "
                 "reported)", ""))
    return Table(("gate computed with", "delete after misses", "tuning runs holding the target >= 80 % [CI]",
                  "chosen"), tuple(rows))


def _surrogate_table(results) -> Table:
    rows = []
    for task in ("surrogate", "file"):
        if task not in results:
            continue
        res = results[task]
        T = res["paper/before/false"].shape[1]
        post = np.arange(T) >= int(res["first_output_ping"])
        b = TrackCounts.from_arrays(res, "paper/before/")
        for arm in ("paper", "min-speed"):
            for phase in ("before", "after"):
                c = TrackCounts.from_arrays(res, f"{arm}/{phase}/")
                cont = continuity(c.held)
                rate = _rate_text(summary(b, c, post)["rate"]) if (arm, phase) != ("paper", "before") else "-"
                rows.append((f"{task} (SYNTHETIC)", arm if arm == "paper" else "EXTENSION: min-speed test",
                             phase, _f(c.false[:, post].mean(), 2), rate,
                             _share_text(int(np.sum(cont >= TRUE_FRACTION)), cont.size)))
        if "rem/main/site_n" in res:
            rows.append((f"{task} (SYNTHETIC)", "remover", "after",
                         "persistent-site detections kept " + _kept_text(res, "rem/main/", "site"),
                         "uniform clutter kept " + _kept_text(res, "rem/main/", "clutter"),
                         "target kept " + _kept_text(res, "rem/main/", "hit")))
    return Table(("case", "row", "removal", "false tracks/ping (pings 6-20)", "removal rate (ratio of sums) vs paper before",
                  "runs holding the target >= 80 % [CI]"), tuple(rows))


def _timing_table(results) -> Table:
    t = results.get("timing")
    if t is None:
        return Table(("stage",), ())
    how = (f"one run of the paper's scenario ({_f(float(t['detections_per_ping']), 1)} detections per ping), warmed "
           f"up (one untimed call first), median of {int(t['repeats'])} timed calls / 20 pings")
    rows = tuple((name, f"{1e3 * float(t[f'{name}_cpu_s']):.2f}", f"{1e3 * float(t[f'{name}_wall_s']):.2f}", how)
                 for name in ("remover", "tracker_before", "tracker_after"))
    return Table(("stage", "ms per ping (process CPU)", "ms per ping (wall)", "how timed"), rows)


TABLES = (
    TableSpec("removal-rate", "False-track removal rate: published (20-ping average) beside ours (ratio of sums over "
              "the runs and pings 6-20, 95 % paired bootstrap interval over runs), with the false tracks per ping "
              "before removal it is judged on (mean over runs and pings 6-20, bootstrap interval over runs) and their "
              "sum, every row. Sea-trial rows are a SYNTHETIC SURROGATE.", _removal_table),
    TableSpec("rows", "Every row before and after removal: removal rate (criterion 1) beside the false tracks per ping "
              "before removal, criterion 2 (share of runs holding the "
              "target >= 80 % of the pings after initiation, exact binomial interval) and criterion 3 (paired "
              "RMSE, bootstrap interval over runs).", _rows_table),
    TableSpec("seed-blocks", "Criterion 2 of the paper rows on each seed block separately.", _seed_table),
    TableSpec("removal-per-ping", "Simulation, paper rows: false tracks per ping before/after removal and the "
              "removal rate at each ping as a ratio of sums over the runs (pings 1-5 are the Hough warm-up: no "
              "detections after removal).", _per_ping_table),
    TableSpec("remover-variants", "Remover variants (support rule, new measurements, angle bins, grouping), each "
              "with the paper's tracker; target detections kept after a miss at the previous ping.", _variant_table),
    TableSpec("tuning", "The tuned row's search: candidates, their score on the tuning runs and the rule (fixed "
              "in docs/paper001.md before the search).", _tuning_table),
    TableSpec("surrogate", "Sea-trial SYNTHETIC SURROGATE: paper rows and the minimum-speed extension against "
              "its stationary clutter.", _surrogate_table),
    TableSpec("timing", "Per-ping time of the remover and the tracker, paper scenario, warmed up.", _timing_table),
    TableSpec("gospa", "GOSPA (alpha 2, c = 10, p = 2) of the confirmed tracks beside the paper's counts, every row "
              "before and after removal, over the pings after the Hough warm-up.", _gospa_table),
    TableSpec("trackers", "The trackers compared (--trackers; default M-of-N, GNN, JIPDA, GM-PHD), before and after "
              "Hough removal on the same runs: the paper's M-of-N rows and the EXTENSION rows (not in the paper: the "
              "Kalman filter with R from the sensor's stated accuracy, each tracker's scenario settings in "
              "docs/paper001.md). GOSPA, false tracks and the share of pings held are per-run means over pings 6-20 "
              "with 95 % bootstrap intervals over runs; runs holding >= 80 % with exact binomial intervals.",
              _trackers_table),
)
