"""Paper 000's figures (the paper's Figs 2-13 and Fig. 14, not in the paper): each a data function of the tasks'
results (:mod:`.tasks`) and a drawing function of that data, listed in :data:`FIGURES`."""

from __future__ import annotations

import numpy as np

from workbench.specs import FigureSpec
from workbench.types import InputError

from .methods import METHODS, TRACK_THRESHOLD_DB
from .scenario import PHASES, PUBLISHED
from .tasks import (JUDGED, TABLE_PARTICLES, TABLE_RADIUS, WIDE_RADIUS, average_errors, get_run, label_of,
                    mean_over_runs, per_run_errors, rcs_values, role_of, runs_of, scenario_of, sweep_of, table_runs)


# -- figures ----------------------------------------------------------------------------------------------




def _phase_colours():
    return {"front": "tab:blue", "top": "tab:orange", "side": "tab:green"}


def fig2_data(results):
    return {"truth_km": np.asarray(scenario_of(results)["truth"])[:, :3] / 1e3,
            "phase_start": np.array([a for _, a, _ in PHASES]), "phase_end": np.array([b for _, _, b in PHASES])}


def draw_fig2(data, fig):
    ax = fig.add_subplot(projection="3d")
    p = data["truth_km"]
    for (name, a, b), colour in zip(PHASES, _phase_colours().values()):
        ax.plot(p[a:b + 1, 0], p[a:b + 1, 1], p[a:b + 1, 2], color=colour, lw=2, label=f"{name} (k={a}..{b})")
    ax.scatter([0], [0], [0], color="k", marker="^", s=40, label="radar")
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_zlabel("z (km)")
    ax.legend(loc="upper left", fontsize=8)


def fig3_data(results):
    s = scenario_of(results)
    return {"k": np.arange(np.asarray(s["snr_db"]).shape[1]), "snr_run0_db": np.asarray(s["snr_db"])[0],
            "nominal_snr_db": np.asarray(s["nominal_snr_db"]), "thresholds_db": np.asarray(s["thresholds_db"])}


def draw_fig3(data, fig):
    ax = fig.add_subplot()
    ax.plot(data["k"], data["snr_run0_db"], "r.", ms=3, label="SNR with RCS fluctuation (run 0)")
    ax.plot(data["k"], data["nominal_snr_db"], "k-", lw=1, label="radar equation, nominal RCS")
    for t in data["thresholds_db"]:
        ax.axhline(t, color="grey", lw=0.8, ls="--")
        ax.text(data["k"][-1], t, f" {t:g} dB", va="center", fontsize=7)
    ax.set_xlabel("time index k")
    ax.set_ylabel("SNR (dB)")
    ax.legend(fontsize=8)


def _scatter_points(results, every: int = 10):
    s = scenario_of(results)
    pts = np.asarray(s["points"])
    clutter = pts[:, 5] < 0
    keep = ~clutter | (pts[:, 0] % every == 0)  # every target detection, clutter of every 10th scan
    return pts[keep]


def fig4_data(results):
    pts = _scatter_points(results)
    return {"points_km": pts[:, 1:4] / 1e3, "snr_db": pts[:, 4], "is_target": pts[:, 5] >= 0,
            "truth_km": np.asarray(scenario_of(results)["truth"])[:, :3] / 1e3}


def draw_fig4(data, fig):
    ax = fig.add_subplot(projection="3d")
    p, t = data["points_km"], data["is_target"]
    ax.scatter(p[~t, 0], p[~t, 1], p[~t, 2], s=1, c="grey", alpha=0.4, label="clutter (every 10th scan)")
    ax.scatter(p[t, 0], p[t, 1], p[t, 2], s=3, c="r", label="target detections")
    tr = data["truth_km"]
    ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "k-", lw=1.5, label="true path")
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_zlabel("z (km)")
    ax.set_title("all detections >= 3 dB", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")


def fig5_data(results):
    d = fig4_data(results)
    d["thresholds_db"] = np.asarray(scenario_of(results)["thresholds_db"])
    return d


def draw_fig5(data, fig):
    tr = data["truth_km"]
    ax = fig.add_subplot(2, 3, 1, projection="3d")
    ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "g-")
    ax.set_title("(a) true path", fontsize=9)
    p, t, snr = data["points_km"], data["is_target"], data["snr_db"]
    for j, thr in enumerate(data["thresholds_db"]):
        ax = fig.add_subplot(2, 3, j + 2, projection="3d")
        keep = snr >= thr
        c = keep & ~t
        g = keep & t
        ax.scatter(p[c, 0], p[c, 1], p[c, 2], s=1, c="grey", alpha=0.4)
        ax.scatter(p[g, 0], p[g, 1], p[g, 2], s=2, c="r")
        ax.set_title(f"({'bcdef'[j]}) SNR >= {thr:g} dB: {int(g.sum())} target", fontsize=9)
    for ax in fig.axes:
        ax.set_xlim(tr[:, 0].min() - 6, tr[:, 0].max() + 6)
        ax.set_ylim(tr[:, 1].min() - 6, tr[:, 1].max() + 6)
        ax.set_zlim(0, 6)
        ax.set_xlabel("x (km)", fontsize=7)
        ax.set_ylabel("y (km)", fontsize=7)
        ax.set_zlabel("z (km)", fontsize=7)
        ax.tick_params(labelsize=6)


def fig5_counts_data(results):
    s = scenario_of(results)
    return {"k": np.arange(np.asarray(s["count_per_scan"]).shape[1]), "count_per_scan": s["count_per_scan"],
            "thresholds_db": s["thresholds_db"]}


def draw_fig5_counts(data, fig):
    ax = fig.add_subplot()
    for thr, row in zip(data["thresholds_db"], data["count_per_scan"]):
        ax.semilogy(data["k"], np.maximum(row, 1e-2), label=f">= {thr:g} dB")
    ax.set_xlabel("time index k")
    ax.set_ylabel("detections per scan (mean over runs)")
    ax.legend(fontsize=8)


def fig6_data(results):
    s = scenario_of(results)
    pts = np.asarray(s["points"])
    k = 60
    centre = np.asarray(s["truth"])[k, :3]
    at = pts[(pts[:, 0] == k) & (pts[:, 4] >= TRACK_THRESHOLD_DB)]
    d = np.linalg.norm(at[:, 1:4] - centre, axis=1)
    return {"k": np.array(k), "centre_km": centre / 1e3, "points_km": at[:, 1:4] / 1e3, "distance_km": d / 1e3,
            "is_target": at[:, 5] >= 0, "radii_km": np.array([2.5, 1.0])}


def draw_fig6(data, fig):
    ax = fig.add_subplot()
    c, p, d = data["centre_km"], data["points_km"], data["distance_km"]
    from matplotlib.patches import Circle

    for r, ls in zip(data["radii_km"], ("-", "--")):
        ax.add_patch(Circle((c[0], c[1]), r, fill=False, ls=ls, color="b", label=f"R = {r:g} km"))
    inside = d <= data["radii_km"].max()
    ax.scatter(p[~inside, 0], p[~inside, 1], s=6, c="grey", label="outside the gate")
    ax.scatter(p[inside, 0], p[inside, 1], s=10, c="k", label="inside (processed)")
    t = data["is_target"]
    ax.scatter(p[t, 0], p[t, 1], s=40, facecolors="none", edgecolors="r", label="target")
    ax.plot(c[0], c[1], "b+", ms=10, label="predicted position")
    ax.set_aspect("equal")
    ax.set_xlim(c[0] - 5, c[0] + 5)
    ax.set_ylim(c[1] - 5, c[1] + 5)
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_title(f"gate at scan k = {int(data['k'])}, detections >= 5 dB (x-y projection)", fontsize=9)
    ax.legend(fontsize=7)




def fig7_data(results):
    out = {"truth_km": np.asarray(scenario_of(results)["truth"])[:, :3] / 1e3}
    for r in (WIDE_RADIUS, TABLE_RADIUS):
        res = get_run(results, "C", TABLE_PARTICLES, r)
        if res is None:
            raise InputError(f"paper 000 Fig. 7 needs the method-C run with N={TABLE_PARTICLES}, R={r:g} m")
        g = np.asarray(res["gated0"])
        out[f"gated_km_R{r:g}"] = g[:, 1:4] / 1e3
        out[f"gated_target_R{r:g}"] = g[:, 5] >= 0
    return out


def draw_fig7(data, fig):
    tr = data["truth_km"]
    for j, r in enumerate((2500, 1000)):
        ax = fig.add_subplot(1, 2, j + 1, projection="3d")
        g, t = data[f"gated_km_R{r}"], data[f"gated_target_R{r}"]
        ax.scatter(g[~t, 0], g[~t, 1], g[~t, 2], s=1, c="grey", label=f"clutter ({int((~t).sum())})")
        ax.scatter(g[t, 0], g[t, 1], g[t, 2], s=2, c="r", label=f"target ({int(t.sum())})")
        ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "g-", lw=1)
        ax.set_title(f"({'ab'[j]}) gated detections, R = {r / 1e3:g} km, 5 dB", fontsize=9)
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
        ax.set_zlabel("z (km)")
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=6)


def _paths_data(results, particles: int):
    out = {"truth_km": np.asarray(scenario_of(results)["truth"])[:, :3] / 1e3}
    for r in (WIDE_RADIUS, TABLE_RADIUS):
        res = get_run(results, "C", particles, r)
        if res is None:
            raise InputError(f"paper 000 needs the method-C run with N={particles}, R={r:g} m")
        out[f"estimate_km_R{r:g}"] = np.asarray(res["path0"]) / 1e3
        out[f"lost_R{r:g}"] = np.asarray(res["lost"])
    return out


def _draw_paths(data, fig, particles: int):
    tr = data["truth_km"]
    for j, r in enumerate((2500, 1000)):
        ax = fig.add_subplot(1, 2, j + 1, projection="3d")
        est = data[f"estimate_km_R{r}"]
        ax.plot(tr[:, 0], tr[:, 1], tr[:, 2], "g-", lw=2, label="true path")
        ax.plot(est[:, 0], est[:, 1], est[:, 2], "b-", lw=1, label="estimate (run 0)")
        lost = data[f"lost_R{r}"]
        ax.set_title(f"({'ab'[j]}) R = {r / 1e3:g} km, N = {particles}; lost {int(lost.sum())}/{lost.size}",
                     fontsize=9)
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
        ax.set_zlabel("z (km)")
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=6)


def fig10_data(results):
    out = {}
    for r in (WIDE_RADIUS, TABLE_RADIUS):
        res = get_run(results, "C", TABLE_PARTICLES, r)
        if res is None:
            raise InputError(f"paper 000 Fig. 10 needs the method-C run with N={TABLE_PARTICLES}, R={r:g} m")
        out[f"m_error_R{r:g}"] = mean_over_runs(res["m_error"])
        out[f"e_error_R{r:g}"] = np.asarray(res["error"]).mean(axis=0)
    out["k"] = np.arange(out["e_error_R1000"].size)
    return out


def draw_fig10(data, fig):
    ax = fig.add_subplot()
    for r, ls in ((2500, "-"), (1000, "--")):
        ax.semilogy(data["k"], data[f"m_error_R{r}"], ls, color="grey", label=f"M_error, R = {r / 1e3:g} km")
        ax.semilogy(data["k"], data[f"e_error_R{r}"], ls, color="b", label=f"E_error, R = {r / 1e3:g} km")
    ax.set_xlabel("time index k")
    ax.set_ylabel("error (m), mean over runs")
    ax.set_title(f"measurement vs estimation error, method C, N = {TABLE_PARTICLES}, 5 dB", fontsize=9)
    ax.legend(fontsize=8)


def fig11_data(results):
    rows = sorted((n, res) for (m, n, r), res in runs_of(results).items() if m == "C" and r == TABLE_RADIUS)
    if not rows:
        raise InputError("paper 000 Fig. 11 has no particle-count sweep")
    return {"particles": np.array([n for n, _ in rows]),
            "e_error": np.stack([np.asarray(res["error"]).mean(axis=0) for _, res in rows])}


def draw_fig11(data, fig):
    ax = fig.add_subplot()
    k = np.arange(data["e_error"].shape[1])
    for n, row in zip(data["particles"], data["e_error"]):
        ax.semilogy(k, row, lw=1, label=f"N = {n}")
    ax.set_xlabel("time index k")
    ax.set_ylabel("E_error (m), mean over runs")
    ax.set_title(f"estimation error per particle count, method C, R = {TABLE_RADIUS / 1e3:g} km", fontsize=9)
    ax.legend(fontsize=7, ncol=2)


def fig12_data(results):
    ns, per_run = sweep_of(results)
    if not ns.size:
        raise InputError("paper 000 Fig. 12 has no particle-count sweep")
    return {"particles": ns, "e_avg_mean": np.array([x.mean() for x in per_run]),
            "e_avg_median": np.array([np.median(x) for x in per_run]),
            "e_avg_std": np.array([x.std(ddof=1) if x.size > 1 else 0.0 for x in per_run]),
            "runs": np.array(per_run[0].size)}


def draw_fig12(data, fig):
    ax = fig.add_subplot()
    n, m, s = data["particles"], data["e_avg_mean"], data["e_avg_std"]
    ax.plot(n, m, "bo-", label=f"mean over {int(data['runs'])} runs (lost runs included)")
    ax.plot(n, data["e_avg_median"], "k^--", label="median over runs")
    ax.fill_between(n, np.maximum(m - s, 0.0), m + s, color="b", alpha=0.15, label="mean +- 1 std (clipped at 0)")
    ax.set_yscale("log")
    ax.set_xlabel("number of particles N")
    ax.set_ylabel("E_error,avg over k = 1..K (m)")
    ax.legend(fontsize=8)


def fig13_data(results):
    runs = table_runs(results)
    if not runs:
        raise InputError("paper 000 Fig. 13 has no method runs")
    keys = list(runs)
    return {"methods": np.array(keys), "labels": np.array([label_of(k) for k in keys]),
            "roles": np.array([role_of(k) for k in keys]),
            "e_error": np.stack([np.asarray(runs[k]["error"]).mean(axis=0) for k in keys])}


def draw_fig13(data, fig):
    ax = fig.add_subplot()
    k = np.arange(data["e_error"].shape[1])
    styles = {"A": "-", "B": "-", "C": "-", "ours": "--", "ablation": ":", "extra": "-."}
    for label, role, row in zip(data["labels"], data["roles"], data["e_error"]):
        ax.semilogy(k, row, styles.get(str(role), "-"), lw=1.2 if role in JUDGED else 1.0, label=str(label))
    ax.set_xlabel("time index k")
    ax.set_ylabel("E_error (m), mean over runs")
    ax.set_title(f"estimation error per method, N = {TABLE_PARTICLES}, R = {TABLE_RADIUS / 1e3:g} km", fontsize=9)
    ax.legend(fontsize=7)


def fig14_data(results):
    values = rcs_values(results)
    if not values:
        raise InputError("paper 000 Fig. 14 has no method runs")
    keys = [m.key for m in METHODS if m.role in (*JUDGED, "ours") and all(m.key in table_runs(results, r)
                                                                           for r in values)]
    mean = np.array([[average_errors(table_runs(results, r)[k])[1] for r in values] for k in keys])
    median = np.array([[float(np.median(per_run_errors(table_runs(results, r)[k])[1])) for r in values]
                       for k in keys])
    lost = np.array([[int(np.sum(table_runs(results, r)[k]["lost"])) for r in values] for k in keys])
    return {"rcs_dbsm": np.array(values), "methods": np.array(keys), "labels": np.array([label_of(k) for k in keys]),
            "whole_mean": mean, "whole_median": median, "lost": lost}


def draw_fig14(data, fig):
    ax = fig.add_subplot()
    x = data["rcs_dbsm"]
    for j, label in enumerate(data["labels"]):
        line, = ax.semilogy(x, data["whole_mean"][j], "o-", label=f"{label}: mean")
        ax.semilogy(x, data["whole_median"][j], "^--", color=line.get_color(), alpha=0.7)
    for value, ref in ((PUBLISHED["table3_whole_m"][m], m) for m in JUDGED):
        ax.axhline(value, color="grey", lw=0.6, ls=":")
        # A (236 m) and B (214 m) lie close: A's label above its line, B's below
        ax.text(x.max(), value, f" paper {ref}", fontsize=7, va={"A": "bottom", "B": "top"}.get(ref, "center"))
    ax.set_xlabel("reference (front-aspect) RCS (dBsm)")
    ax.set_ylabel("whole-track E_error,avg (m): mean (o), median (^)")
    ax.set_title("sensitivity to the withheld reference RCS, N = 600, R = 1 km", fontsize=9)
    ax.legend(fontsize=7)


FIGURES = (
    FigureSpec("fig2", "True 3-D path, radar at the origin; front / top / side aspect phases.", fig2_data,
               draw_fig2),
    FigureSpec("fig3", "Target SNR along the path (red: with 2 dB RCS fluctuation, run 0; black: nominal) and "
               "the thresholds 12/9/7/5/3 dB.", fig3_data, draw_fig3, size=(7.0, 4.2)),
    FigureSpec("fig4", "Scenario with radar clutter: all detections >= 3 dB of run 0 (clutter of every 10th "
               "scan) and the true path.", fig4_data, draw_fig4),
    FigureSpec("fig5", "(a) true path; (b)-(f) detections kept at the thresholds 12, 9, 7, 5 and 3 dB (run 0, "
               "clutter of every 10th scan).", fig5_data, draw_fig5, size=(10.0, 6.5)),
    FigureSpec("fig5_counts", "Detections per scan passing each threshold (target + clutter, mean over runs).",
               fig5_counts_data, draw_fig5_counts, size=(7.0, 4.2)),
    FigureSpec("fig6", "Gating: detections >= 5 dB of one scan around the predicted position, R = 2.5 and 1 km.",
               fig6_data, draw_fig6, size=(6.0, 6.0)),
    FigureSpec("fig7", "Detections >= 5 dB inside the gate, accumulated over k (run 0 of the N = 600 method-C "
               "runs), (a) R = 2.5 km, (b) R = 1 km.", fig7_data, draw_fig7, size=(10.0, 4.8)),
    FigureSpec("fig8", "True (green) vs estimated (blue) path, method C, N = 100, (a) R = 2.5 km, (b) R = 1 km.",
               lambda r: _paths_data(r, 100), lambda d, f: _draw_paths(d, f, 100), size=(10.0, 4.8)),
    FigureSpec("fig9", "True (green) vs estimated (blue) path, method C, N = 600, (a) R = 2.5 km, (b) R = 1 km.",
               lambda r: _paths_data(r, 600), lambda d, f: _draw_paths(d, f, 600), size=(10.0, 4.8)),
    FigureSpec("fig10", "Measurement error M_error(k) (eq 19, gated detections) vs estimation error E_error(k) "
               "(eq 20), method C, N = 600, R = 2.5 and 1 km.", fig10_data, draw_fig10, size=(7.0, 4.2)),
    FigureSpec("fig11", "E_error(k) per particle count N (method C, R = 1 km, mean over runs).", fig11_data,
               draw_fig11, size=(7.0, 4.2)),
    FigureSpec("fig12", "Average estimation error E_error,avg (eq 21) vs N: mean over runs (lost runs "
               "included) +- 1 std, and the median.", fig12_data, draw_fig12, size=(6.0, 4.2)),
    FigureSpec("fig13", "E_error(k) per method: the paper's A and B (fixed R), C, our A and B (dashed) and the "
               "ablations of C (dotted); N = 600, R = 1 km, mean over runs.", fig13_data, draw_fig13,
               size=(8.0, 4.8)),
    FigureSpec("fig14", "Not in the paper: whole-track error of A, B, C and our A, B against the withheld "
               "reference RCS (mean and median over runs; the paper's Table 3 as dotted lines).", fig14_data,
               draw_fig14, size=(7.0, 4.2)),
)
