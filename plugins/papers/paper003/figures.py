"""Paper 003's figures: the example runs (Figs 2-3), the MSE curves per level (Figs 4-6, 8) and the processing
times (Fig 7), each as data from the saved results and a drawing (:data:`FIGURES`)."""

from __future__ import annotations

import numpy as np

from workbench import plot as wbplot
from workbench.models import random_walk_velocity
from workbench.specs import FigureSpec
from workbench.types import Truth

from .reading import REFERENCE, filters_in, mc, timing, timing_arrays
from .scenario import DT, LEVELS, NOMINAL, case_name
from .tasks import PREVIOUS


def _example_table(results, case, names):
    """Per example run: lost flags ``(F, E)`` and time-averaged errors ``(F, E)`` on ``case``."""
    lost = np.array([mc(results, case, n)["lost"][: len(mc(results, case, n)["est_xy"])] for n in names])
    err = np.array([mc(results, case, n)["run_mse"][: len(mc(results, case, n)["est_xy"])] for n in names])
    return lost, err


def _example_data(results, case, run, names, why) -> dict:
    scen = results[f"scenario/{case}"]
    z = scen["z"][run]
    return {
        "level": np.array(case), "run": np.array(run), "why": np.array(why),
        "filters": np.array(names, dtype=str),
        "truth_xy": scen["truth_xy"][run],
        "meas_xy": np.stack([z[:, 0] * np.cos(z[:, 1]), z[:, 0] * np.sin(z[:, 1])], axis=-1),
        "est_xy": np.stack([mc(results, case, n)["est_xy"][run] for n in names]),
        "lost": np.array([bool(mc(results, case, n)["lost"][run]) for n in names]),
        "lost_threshold_m": np.array(float(scen["lost_threshold"][run])),
    }


def fig2_data(results) -> dict:
    """A run where every filter tracks: the example run (L1, then L2) with the smallest worst-filter error
    among runs where no filter is lost (or the fewest filters lost)."""
    names = filters_in(results)
    best = None
    for level in ("L1", "L2"):
        lost, err = _example_table(results, level, names)
        score = lost.sum(axis=0) * 1e12 + err.max(axis=0)
        run = int(np.argmin(score))
        cand = (float(score[run]), level, run)
        if best is None or cand[0] < best[0]:
            best = cand
    _, level, run = best
    return _example_data(results, level, run, names, "all filters track (smallest worst-filter error)")


def fig3_data(results) -> dict:
    """A run where a filter loses the target: EKF lost while another filter tracks (L2, L3, L1), else
    any filter lost while another tracks, else the run with the largest spread of final errors."""
    names = filters_in(results)
    fallback = None
    for level in ("L2", "L3", "L1"):
        lost, err = _example_table(results, level, names)
        some_track = ~lost.all(axis=0)
        if "ekf" in names:
            ekf_lost = lost[names.index("ekf")] & some_track
            if ekf_lost.any():
                tracking = (~lost).sum(axis=0)
                score = np.where(ekf_lost, tracking * 1e12 + np.minimum(err[names.index("ekf")], 1e11), -np.inf)
                run = int(np.argmax(score))
                return _example_data(results, level, run, names, "EKF loses the target")
        any_lost = lost.any(axis=0) & some_track
        if any_lost.any() and fallback is None:
            spread = np.where(any_lost, err.max(axis=0) / np.maximum(err.min(axis=0), 1e-12), -np.inf)
            run = int(np.argmax(spread))
            who = ", ".join(n for n, flag in zip(names, lost[:, run]) if flag)
            fallback = (level, run, f"{who} lose(s) the target")
    if fallback is None:
        lost, err = _example_table(results, "L3", names)
        run = int(np.argmax(err.max(axis=0) / np.maximum(err.min(axis=0), 1e-12)))
        fallback = ("L3", run, "no example run with a lost track: largest spread of errors")
    level, run, why = fallback
    return _example_data(results, level, run, names, why)


#: The filters' motion model (the nominal level's): its declared state names and units label the example figures.
_FIGURE_MOTION = random_walk_velocity(2, DT, LEVELS[NOMINAL][2])


def _draw_example(data, fig) -> None:
    ax = fig.add_subplot()
    ax.plot(data["meas_xy"][:, 0], data["meas_xy"][:, 1], ".", color="0.7", ms=3, label="measurements",
            gid="measurements")
    truth_xy = np.asarray(data["truth_xy"], dtype=float)
    wbplot.truth(ax, Truth(truth_xy[None], np.arange(truth_xy.shape[0]) * DT), motion=_FIGURE_MOTION, color="k")
    for i, (name, xy, lost) in enumerate(zip(data["filters"], data["est_xy"], data["lost"])):
        wbplot.estimate(ax, np.asarray(xy, dtype=float)[None], motion=_FIGURE_MOTION, color=f"C{i % 10}",
                        linestyle=wbplot.LINESTYLES[i % len(wbplot.LINESTYLES)], linewidth=1.0,
                        label=f"{name}{' (lost)' if lost else ''}")
    ax.plot([0], [0], "k^", ms=8, label="sensor", gid="sensor")
    ax.set_title(f"{data['level']} run {int(data['run'])}: {data['why']} "
                 f"(lost beyond {float(data['lost_threshold_m']):.3g} m)", fontsize=9)
    truth = data["truth_xy"]
    span = np.ptp(np.concatenate([truth, [[0.0, 0.0]]]), axis=0).max()
    centre = truth.mean(axis=0)
    ax.set_xlim(centre[0] - span, centre[0] + span)
    ax.set_ylim(centre[1] - span, centre[1] + span)
    ax.set_aspect("equal", adjustable="box")
    ax.legend(fontsize=7, ncol=2)


def _curves(results, case) -> tuple[list[str], np.ndarray, list[str]]:
    """Row labels, MSE curves ``(rows, T)`` and row kinds (filter / ablation / reference) of a case."""
    reading = "deg" if case.startswith("deg-") else "rad"
    names = filters_in(results, reading)
    labels, curves, kinds = [], [], []
    for n in names:
        labels.append(n)
        curves.append(mc(results, case, n)["mse_t"])
        kinds.append("filter")
    for key, spec, kind in ((f"ablation/{case}", PREVIOUS, "ablation"), (f"reference/{case}", REFERENCE, "reference")):
        if key in results:
            labels.append(spec["label"] + (f", first {int(results[key]['runs'])} runs" if kind == "reference" else ""))
            curves.append(results[key]["mse_t"])
            kinds.append(kind)
    return labels, np.stack(curves), kinds


def mse_data(level: str, reading: str = "rad"):
    case = case_name(reading, level)

    def data(results) -> dict:
        labels, curves, kinds = _curves(results, case)
        return {"level": np.array(case), "reading": np.array(reading), "filters": np.array(labels, dtype=str),
                "kind": np.array(kinds, dtype=str), "time": np.arange(curves.shape[1]) * DT, "mse_t": curves}
    return data


def _plot_curves(ax, data, title) -> None:
    for name, kind, curve in zip(data["filters"], data["kind"], data["mse_t"]):
        name = str(name)
        styles = {"reference": dict(color="k", ls="--", lw=1.8), "ablation": dict(color="tab:olive", ls=":", lw=1.8)}
        style = styles.get(str(kind), dict(lw=1.2, ls="--" if name.startswith("sr-") else "-"))
        wbplot.error_over_time(ax, curve, times=data["time"], quantity="position MSE", unit="m$^2$", label=name,
                               color=style.get("color"), linestyle=style["ls"], linewidth=style["lw"])
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)


def _draw_mse(data, fig) -> None:
    ax = fig.add_subplot()
    _plot_curves(ax, data, f"{data['level']}: mismatched noise statistics (nominal L2 Q, R); reference given the "
                           f"true noise")
    ax.legend(fontsize=6.5, ncol=2)


def deg_data(results) -> dict:
    out = {}
    for level in LEVELS:
        d = mse_data(level, "deg")(results)
        out.update({f"{level}:{k}": v for k, v in d.items() if k in ("filters", "kind", "mse_t")})
        out["time"] = d["time"]
    return out


def _draw_deg(data, fig) -> None:
    axes = fig.subplots(1, 3)
    for ax, level in zip(axes, LEVELS):
        sub = {"filters": data[f"{level}:filters"], "kind": data[f"{level}:kind"], "mse_t": data[f"{level}:mse_t"],
               "time": data["time"]}
        st, sr, sa = LEVELS[level]
        _plot_curves(ax, sub, f"{level}: sigma_theta {st:g} deg, sigma_r {sr:g} m, sigma_a {sa:g}")
    axes[0].legend(fontsize=6, ncol=1)


def fig7_data(results) -> dict:
    names = filters_in(results)
    times = np.array([timing(results, n) for n in names])
    arrays = [timing_arrays(results, n) or {} for n in names]
    runs = np.array([len(a.get("per_run_s", ())) for a in arrays])
    reps = np.array([len(a.get("batched_per_run_s", ())) for a in arrays])
    return {"filters": np.array(names, dtype=str), "unbatched_s_per_run": times[:, 0],
            "batched_s_per_run": times[:, 1], "timing_runs": runs, "batched_repeats": reps}


def _draw_time(data, fig) -> None:
    ax = fig.add_subplot()
    x = np.arange(len(data["filters"]))
    ax.bar(x - 0.2, data["unbatched_s_per_run"] * 1e3, 0.4, label="un-batched (B = 1), median of the timed runs")
    ax.bar(x + 0.2, data["batched_s_per_run"] * 1e3, 0.4, label="batched (all runs in one call), median of repeats",
           hatch="//")
    wbplot.log_axis(ax, "y")
    ax.set_xticks(x, [str(n) for n in data["filters"]], rotation=30, ha="right")
    ax.set_ylabel("wall time per run of 100 steps (ms)")
    ax.set_title("warmed-up code (each filter ran once before the clock)", fontsize=9)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8)


FIGURES = (
    FigureSpec("fig2", "A run where every filter tracks: truth, estimates, measurements converted to x-y.",
               fig2_data, _draw_example, size=(6.4, 6.0)),
    FigureSpec("fig3", "A run where a filter loses the target under the lost rule (an EKF loss where one occurs "
                       "among the example runs, else any filter's); where no example run has a lost track the "
                       "title says so and shows the run with the largest spread of errors.",
               fig3_data, _draw_example, size=(6.4, 6.0)),
    FigureSpec("fig4", "Position MSE vs time at L1 (sigma_theta 0.01 rad, sigma_r 0.1, sigma_a 0.01), mismatched; "
                       "the reference PF given the true noise, and the previous CRPF (ablation).",
               mse_data("L1"), _draw_mse),
    FigureSpec("fig5", "Position MSE vs time at L2 (sigma_theta 0.1 rad, sigma_r 1, sigma_a 0.1), matched = "
                       "mismatched; the reference PF and the previous CRPF (ablation).",
               mse_data("L2"), _draw_mse),
    FigureSpec("fig6", "Position MSE vs time at L3 (sigma_theta 1 rad, sigma_r 10, sigma_a 1), mismatched; "
                       "the reference PF given the true noise, and the previous CRPF (ablation).",
               mse_data("L3"), _draw_mse),
    FigureSpec("fig7", "Processing time per run per filter on warmed-up code: un-batched (B = 1) and batched.",
               fig7_data, _draw_time),
    FigureSpec("fig8", "Degrees reading of the bearing noise: position MSE vs time at L1, L2, L3, mismatched, with "
                       "the reference PF and the previous CRPF (ablation).", deg_data, _draw_deg, size=(13.0, 4.4)),
)
