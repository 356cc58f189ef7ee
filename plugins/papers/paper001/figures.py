"""Paper 001's figures: the data behind each (from the task results) and its drawing, collected in
:data:`FIGURES`."""

from __future__ import annotations

import numpy as np

from workbench.metrics import TrackCounts
from workbench.specs import FigureSpec

from .judging import _arm_counts, _blocks
from .scenario import FIG_ARM, GOSPA_C, HOUGH, PAPER_TRACKER, PINGS, _warm
from .tables import _tracker_blocks, comparison_rows, comparison_series


def _fig3_data(results):
    d = results["hough-demo"]
    return {"points": d["points"], "point_ping": d["point_ping"], "point_target": d["point_target"],
            "line": _demo_line(d), "true_line": d["true_line"]}


def _demo_line(d) -> np.ndarray:
    """The similar line closest to the true line, ``(rho, theta)`` (NaNs if none)."""
    sim = np.asarray(d["similar"]).reshape(-1, 2)
    if sim.shape[0] == 0:
        return np.array([np.nan, np.nan])
    rho0, th0 = d["true_line"]
    dth = np.abs(sim[:, 1] - th0)
    flip = dth > np.pi / 2
    dr = np.where(flip, np.abs(sim[:, 0] + rho0), np.abs(sim[:, 0] - rho0))
    dth = np.where(flip, np.pi - dth, dth)
    return sim[np.argmin(dr + np.rad2deg(dth))]


def _draw_line(ax, rho, theta, **kw):
    # points on x cos(theta) + y sin(theta) = rho
    c, s = np.cos(theta), np.sin(theta)
    foot = np.array([rho * c, rho * s])
    t = np.linspace(-200, 200, 2)
    ax.plot(foot[0] - t * s, foot[1] + t * c, **kw)


def _fig3_draw(data, fig):
    ax = fig.add_subplot(1, 1, 1)
    pts, tgt = data["points"], data["point_target"].astype(bool)
    ax.scatter(pts[~tgt, 0], pts[~tgt, 1], s=12, c="0.6", label="clutter")
    ax.scatter(pts[tgt, 0], pts[tgt, 1], s=30, c="C3", label="target (5 pings)")
    rho, theta = data["line"]
    if np.isfinite(rho):
        _draw_line(ax, rho, theta, color="C0", lw=1.2, label=f"line rho={rho:.0f}, theta={np.rad2deg(theta):.0f} deg")
        ax.plot([0, rho * np.cos(theta)], [0, rho * np.sin(theta)], "C0--", lw=0.8)
        ax.annotate("rho", (0.5 * rho * np.cos(theta), 0.5 * rho * np.sin(theta)), color="C0")
    ax.set(xlim=(0, 250), ylim=(0, 250), xlabel="x (units)", ylabel="y (units)", aspect="equal",
           title="Fig 3: x-y space; rho = x cos(theta) + y sin(theta)")
    ax.legend(fontsize=7, loc="upper left")


def _fig4_data(results):
    d = results["hough-demo"]
    theta = d["theta_axis"]
    pts = d["points"]
    # eq 1 for every point: its sinusoid rho(theta)
    sinus = pts[:, :1] * np.cos(theta) + pts[:, 1:2] * np.sin(theta)
    peak = _demo_line(d)
    ra = np.asarray(d["rho_axis"])
    centre = peak[0] if np.isfinite(peak[0]) else 0.0
    rows = np.flatnonzero(np.abs(ra - centre) <= 80.0)  # the accumulator around the peak
    lo, hi = rows.min(), rows.max() + 1
    return {"theta_deg": np.rad2deg(theta), "sinusoids": sinus, "point_target": d["point_target"],
            "rho_axis": ra[lo:hi], "support": d["support"][lo:hi], "peak": peak}


def _fig4_draw(data, fig):
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    th = data["theta_deg"]
    tgt = data["point_target"].astype(bool)
    for curve, is_t in zip(data["sinusoids"], tgt):
        ax1.plot(th, curve, color="C3" if is_t else "0.7", lw=1.2 if is_t else 0.6)
    rho, theta = data["peak"]
    for ax in (ax1, ax2):
        if np.isfinite(rho):
            ax.plot(np.rad2deg(theta), rho, "o", mfc="none", mec="C0", ms=12, mew=1.5)
    ax1.set(xlabel="theta (deg)", ylabel="rho (units)", title="sinusoids (target red, clutter grey)")
    ra = data["rho_axis"]
    im = ax2.imshow(data["support"], aspect="auto", origin="lower", cmap="viridis",
                    extent=(th[0], th[-1] + (th[1] - th[0]), ra[0], ra[-1]))
    fig.colorbar(im, ax=ax2, label="distinct pings voting (group B)")
    ax2.set(xlabel="theta (deg)", ylabel="rho (units)", title="accumulator; circle = similar peak")
    fig.suptitle("Fig 4: Hough parameter space", fontsize=10)


def _xy_data(task: str, phase: str):
    def data(results):
        d = results[task]
        p = f"fig/{phase}/"
        out = {k: d[p + k] for k in ("det_xy", "det_ping", "det_target", "det_kept", "trk_ping", "trk_id", "trk_xy",
                                     "trk_true", "truth_xy")}
        out["removed"] = np.array(phase == "after")
        return out
    return data


def _xy_draw(title: str):
    def draw(data, fig):
        ax = fig.add_subplot(1, 1, 1)
        xy, kept = data["det_xy"], data["det_kept"].astype(bool)
        if (~kept).any():
            ax.scatter(xy[~kept, 0], xy[~kept, 1], s=3, c="0.85", label="removed detections")
        ax.scatter(xy[kept, 0], xy[kept, 1], s=4, c="0.35", label="detections (all pings)")
        txy, true = data["trk_xy"], data["trk_true"].astype(bool)
        ax.scatter(txy[~true, 0], txy[~true, 1], s=22, facecolors="none", edgecolors="C0", lw=0.8,
                   label="confirmed false tracks")
        ax.scatter(txy[true, 0], txy[true, 1], s=30, facecolors="none", edgecolors="C3", lw=1.2,
                   label="confirmed target track")
        ax.plot(data["truth_xy"][:, 0], data["truth_xy"][:, 1], "k-", lw=0.8, label="truth")
        ax.set(xlim=(0, 250), ylim=(0, 250), xlabel="x (units)", ylabel="y (units)", aspect="equal", title=title)
        ax.legend(fontsize=7, loc="upper left")
    return draw


def _count_data(source: str, phase: str):
    def data(results):
        if source == "sim":
            blocks = _blocks(results)[:1]
            c = _arm_counts(results, FIG_ARM, phase, blocks)
            others = {arm: _arm_counts(results, arm, phase, blocks) for arm in ("paper", "stated", "previous")}
        else:
            c, others = TrackCounts.from_arrays(results[source], f"paper/{phase}/"), {}
        out = {"ping": np.arange(1, c.confirmed.shape[1] + 1), "run0": c.confirmed[0],
               "run0_false": c.false[0], "mean": c.confirmed.mean(axis=0),
               "q10": np.quantile(c.confirmed, 0.1, axis=0), "q90": np.quantile(c.confirmed, 0.9, axis=0),
               "false_mean": c.false.mean(axis=0), "runs": np.array(c.confirmed.shape[0])}
        for arm, counts in others.items():
            if counts is not None:
                out[f"{arm}_mean"] = counts.confirmed.mean(axis=0)
        return out
    return data


def _count_draw(title: str):
    def draw(data, fig):
        ax = fig.add_subplot(1, 1, 1)
        ax.bar(data["ping"], data["run0"], color="0.75", label="run 0: confirmed tracks")
        ax.bar(data["ping"], data["run0_false"], color="C0", width=0.4, label="run 0: false tracks")
        runs = int(data["runs"])
        if runs > 1:
            ax.fill_between(data["ping"], data["q10"], data["q90"], color="C3", alpha=0.15, step="mid",
                            label=f"10-90 % of {runs} runs")
            ax.plot(data["ping"], data["mean"], "C3.-", lw=1, label=f"mean over {runs} runs (drawn row)")
        for arm, style, label in (("paper", "C4-.", "mean, paper rows (judged)"),
                                  ("stated", "C2--", "mean, R from the stated accuracy"),
                                  ("previous", "C1:", "mean, previous settings")):
            if f"{arm}_mean" in data:
                ax.plot(data["ping"], data[f"{arm}_mean"], style, lw=1, label=label)
        ax.set(xlabel="ping", ylabel="confirmed tracks (count)", title=title, xticks=data["ping"])
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
    return draw


SUR = "[SYNTHETIC SURROGATE, not sea-trial data] "


FIGURES = (
    FigureSpec("fig3", "A line in x-y space and its normal form (rho, theta); demo scene of 5 pings.",
               _fig3_data, _fig3_draw, size=(6.0, 6.0)),
    FigureSpec("fig4", "Hough space: sinusoids of the target points meet at one (rho, theta); clutter does not.",
               _fig4_data, _fig4_draw, size=(11.0, 4.5)),
    FigureSpec("fig5", "Simulation, run 0, before clutter removal: detections of 20 pings and confirmed tracks of the "
               "row 'M-of-N as the paper describes it (initiation detections counted), R matched to the sensor', the "
               "row with the paper's clutter tracks (the judged paper rows have few).", _xy_data("sim/0", "before"),
               _xy_draw("Fig 5: simulation, before removal (paper's M-of-N, matched R)"), size=(6.4, 6.4)),
    FigureSpec("fig6", "Simulation, run 0, after Hough clutter removal (removed detections light grey); the same row "
               "as Fig 5 (M-of-N as the paper describes it, initiation detections counted, R matched to the sensor).",
               _xy_data("sim/0", "after"), _xy_draw("Fig 6: simulation, after removal (paper's M-of-N, matched R)"),
               size=(6.4, 6.4)),
    FigureSpec("fig7", SUR + "Sea-trial surrogate file, before clutter removal.",
               _xy_data("file", "before"), _xy_draw("Fig 7: SURROGATE (synthetic), before removal"), size=(6.4, 6.4)),
    FigureSpec("fig8", SUR + "Sea-trial surrogate file, after clutter removal.",
               _xy_data("file", "after"), _xy_draw("Fig 8: SURROGATE (synthetic), after removal"), size=(6.4, 6.4)),
    FigureSpec("fig9", "Confirmed tracks per ping, simulation, before removal, row 'M-of-N as the paper describes it "
               "(initiation detections counted), R matched to the sensor' (run 0 bars; mean and 10-90 % band over the first seed "
               "block; the judged paper rows' and the other rows' means for comparison).", _count_data("sim", "before"),
               _count_draw("Fig 9: simulation, before removal (paper's M-of-N, matched R)")),
    FigureSpec("fig10", "Confirmed tracks per ping, simulation, after removal, the same row as Fig 9 (pings 1-5 are the "
               "warm-up).", _count_data("sim", "after"),
               _count_draw("Fig 10: simulation, after removal (paper's M-of-N, matched R)")),
    FigureSpec("fig11", SUR + "Confirmed tracks per ping, surrogate file, before removal.",
               _count_data("file", "before"), _count_draw("Fig 11: SURROGATE (synthetic), before removal")),
    FigureSpec("fig12", SUR + "Confirmed tracks per ping, surrogate file, after removal.",
               _count_data("file", "after"), _count_draw("Fig 12: SURROGATE (synthetic), after removal")),
)


def _gospa_data(results):
    """GOSPA per ping (mean over runs) of the paper rows before and after removal, with its false-track term."""
    blocks = _blocks(results)
    out = {}
    for phase in ("before", "after"):
        stack = np.concatenate([np.asarray(results[k][f"paper/{phase}/gospa"], dtype=float) for k in blocks])
        false = np.concatenate([np.asarray(results[k][f"paper/{phase}/gospa_false"], dtype=float) for k in blocks])
        out[f"gospa_{phase}"] = stack.mean(axis=0)
        out[f"false_{phase}"] = np.sqrt(np.maximum(false.mean(axis=0), 0.0))
    out["ping"] = np.arange(out["gospa_before"].size)
    out["first_output_ping"] = np.array(int(results[blocks[0]]["first_output_ping"]))
    out["c"] = np.array(GOSPA_C)
    return out


def _gospa_draw(data, fig):
    ax = fig.add_subplot()
    ax.plot(data["ping"], data["gospa_before"], "o-", color="tab:red", label="GOSPA before removal")
    ax.plot(data["ping"], data["gospa_after"], "s-", color="tab:blue", label="GOSPA after removal")
    ax.plot(data["ping"], data["false_before"], ":", color="tab:red", label="its false-track part (root), before")
    ax.plot(data["ping"], data["false_after"], ":", color="tab:blue", label="its false-track part (root), after")
    ax.axvline(float(data["first_output_ping"]) - 0.5, color="0.6", lw=0.8)
    ax.axhline(float(data["c"]) / np.sqrt(2.0), color="0.3", ls="--", lw=0.8, label="one missed target (c / sqrt 2)")
    ax.set_xlabel("ping")
    ax.set_ylabel("GOSPA (c = 10, p = 2), position units")
    ax.legend(fontsize=7)


FIGURES = FIGURES + (
    FigureSpec("gospa-per-ping", "GOSPA of the confirmed tracks per ping (mean over runs), paper rows, before and after Hough "
               "removal; the dotted lines are its false-track part (the line marks the end of the warm-up).",
               _gospa_data, _gospa_draw),
)


def _trackers_gospa_data(results):
    """GOSPA per ping (mean over runs) of every comparison row, before and after removal: ``rows`` (the row
    labels: the reference, ``mofn`` twice as ``mofn (paper rows)`` and ``mofn (stated R)``), ``gospa_before`` and
    ``gospa_after`` ``(rows, T)``."""
    names, before, after = [], [], []
    T = None
    for ref, _, _, source in comparison_rows(results):
        b, a = comparison_series(results, source, "before"), comparison_series(results, source, "after")
        if b is None or a is None:
            continue
        names.append(ref if source[0] == "tracker" else f"{ref} ({'paper rows' if source[1] == 'paper' else 'stated R'})")
        before.append(b[1].mean(axis=0))
        after.append(a[1].mean(axis=0))
        T = b[1].shape[1]
    if T is None:
        T = np.asarray(results[_blocks(results)[0]]["paper/before/gospa"]).shape[1] if any(
            k.startswith("sim/") for k in results) else PINGS
    keys = [k for k in results if k.startswith("sim/")] or _tracker_blocks(results)
    first = int(results[keys[0]]["first_output_ping"]) if keys else _warm(HOUGH)
    return {"rows": np.array(names, dtype=str), "ping": np.arange(T),
            "gospa_before": np.array(before, dtype=float).reshape(len(names), T),
            "gospa_after": np.array(after, dtype=float).reshape(len(names), T),
            "first_output_ping": np.array(first), "c": np.array(GOSPA_C)}


def _trackers_gospa_draw(data, fig):
    axes = fig.subplots(1, 2, sharey=True)
    for ax, phase in zip(axes, ("before", "after")):
        for i, name in enumerate(data["rows"]):
            paper = str(name).startswith(PAPER_TRACKER + " (")
            ax.plot(data["ping"], data[f"gospa_{phase}"][i], "o-" if paper else ".--", color=f"C{i % 10}", lw=1.2 if
                    paper else 0.9, label=str(name) + ("" if paper else " (extension)"))
        ax.axvline(float(data["first_output_ping"]) - 0.5, color="0.6", lw=0.8)
        ax.axhline(float(data["c"]) / np.sqrt(2.0), color="0.3", ls=":", lw=0.8, label="one missed target (c / sqrt 2)")
        ax.set(xlabel="ping", title=f"{phase} Hough removal")
    axes[0].set_ylabel("GOSPA (c = 10, p = 2), position units")
    axes[0].legend(fontsize=7)


FIGURES = FIGURES + (
    FigureSpec("gospa-trackers", "GOSPA of the confirmed tracks per ping (mean over runs) of every tracker compared, "
               "before (left) and after (right) Hough removal on the same runs: the paper's M-of-N rows (solid) and "
               "the EXTENSION rows (dashed: trackers the paper does not have, each with the Kalman filter and R from "
               "the sensor's stated accuracy); the grey line marks the end of the warm-up.",
               _trackers_gospa_data, _trackers_gospa_draw, size=(11.0, 4.5)),
)
