"""Paper 002's figures: the layout, the range-Doppler trajectory, the benign scene's CAF, the ablation's NIS and the
demanding scene's CAF (each ``data(results)`` and ``draw(data, fig)``)."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from workbench import plot as wbplot
from workbench.models import range_rate_model
from workbench.specs import FigureSpec
from workbench.types import InputError, Truth

from .judging import detection_results, stated_sigma
from .methods import on_target
from .scenario import FRAME_DT, SECTOR_CENTRE_DEG, SECTOR_DEG, SECTOR_RANGES, SIGMA_A, VARIANTS

# -- figures ---------------------------------------------------------------------------------------------


def _first(results) -> tuple[str, Mapping[str, np.ndarray]]:
    found = detection_results(results)
    if not found:
        raise InputError("paper 002: the results hold no detection task")
    return found[0]


def fig_geometry_data(results) -> dict[str, np.ndarray]:
    _, res = _first(results)
    return {"tx": res["tx"], "rx": res["rx"], "path": res["run0/xyz"],
            "sector": np.array([SECTOR_CENTRE_DEG, SECTOR_DEG, SECTOR_RANGES[1] * 1.3])}


def draw_geometry(data, fig) -> None:
    tx, rx, path = data["tx"], data["rx"], data["path"]
    centre, width, reach = data["sector"]
    ref_dir = np.degrees(np.arctan2(tx[1] - rx[1], tx[0] - rx[0]))
    for i, (title, lim) in enumerate((("layout (local ENU)", None), ("surveillance area", reach * 1.15))):
        ax = fig.add_subplot(1, 2, i + 1)
        ax.plot([tx[0], rx[0]], [tx[1], rx[1]], color="0.5", lw=1, label="baseline")
        ax.plot(*tx[:2], "^", color="tab:red", ms=9, label="Tx (DTV, 701 MHz)")
        ax.plot(*rx[:2], "s", color="tab:blue", ms=7, label="Rx")
        angles = np.radians(np.linspace(centre - width / 2, centre + width / 2, 40))
        wedge = np.vstack([rx[:2], rx[:2] + reach * np.c_[np.cos(angles), np.sin(angles)], rx[:2]])
        ax.fill(wedge[:, 0], wedge[:, 1], color="tab:green", alpha=0.15, label="surveillance sector")
        arrow = 0.25 * (reach if lim else np.hypot(*(tx[:2] - rx[:2])))
        ax.annotate("", xy=rx[:2] + arrow * np.array([np.cos(np.radians(centre)), np.sin(np.radians(centre))]),
                    xytext=rx[:2], arrowprops={"arrowstyle": "->", "color": "tab:green"})
        ax.annotate("", xy=rx[:2] + arrow * np.array([np.cos(np.radians(ref_dir)), np.sin(np.radians(ref_dir))]),
                    xytext=rx[:2], arrowprops={"arrowstyle": "->", "color": "tab:red"})
        ax.plot(path[:, 0], path[:, 1], color="k", lw=1.2, label="drone path (run 0)")
        ax.plot(path[0, 0], path[0, 1], "o", color="k", ms=4)
        if lim:
            ax.set_xlim(-0.3 * lim, lim)
            ax.set_ylim(-0.65 * lim, 0.65 * lim)
        ax.set_aspect("equal", adjustable="box" if lim else "datalim")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_title(title + ("\narrows: reference antenna (red, to Tx), surveillance (green)" if i == 0 else ""),
                     fontsize=8)
        if i == 0:
            ax.legend(fontsize=6, loc="center left")


def fig_trajectory_data(results) -> dict[str, np.ndarray]:
    filt, res = _first(results)
    out = {"filter": np.array([filt]), "truth": res["truth_rr"][0], "times": res["times"],
           "candidates": res["run0/cand_z"], "wavelength": res["wavelength"]}
    for g in ("nogate", "gate"):
        out[f"{g}/chosen"] = res[f"rr-{g}/chosen"][0]
        out[f"{g}/est"] = res[f"rr-{g}/est"][0]
        out[f"{g}/pred"] = res[f"rr-{g}/pred"]
    return out


#: The [R, Rdot] state the figures draw: its declared names and units label the axes (workbench.plot).
_RR_MOTION = range_rate_model(FRAME_DT, SIGMA_A)
#: The measurement dimension of both models' NIS ([R, Rdot] and [R, v]): the chi-square's degrees of freedom.
_NIS_DOF = 2


def _truth_rr(data) -> Truth:
    """Run 0's [R, Rdot] truth as a one-run ``Truth`` over the frame times, for ``workbench.plot``."""
    return Truth(np.asarray(data["truth"], dtype=float)[None], np.asarray(data["times"], dtype=float))


def draw_trajectory(data, fig) -> None:
    lam = float(data["wavelength"])
    cands = data["candidates"].reshape(-1, 2)
    for i, (g, title) in enumerate((("nogate", "no gate (paper)"), ("gate", "gate d2 <= 9.21"))):
        ax = fig.add_subplot(1, 2, i + 1)
        ax.plot(cands[:, 0], cands[:, 1], ".", color="0.8", ms=2, label="all candidates", gid="candidates")
        wbplot.truth(ax, _truth_rr(data), motion=_RR_MOTION, color="0.55")
        ax.plot(*data[f"{g}/chosen"].T, ":", color="k", marker=".", ms=3, lw=0.8, label="selected (NN) measurements",
                gid="selected")
        wbplot.estimate(ax, data[f"{g}/est"][None], motion=_RR_MOTION, color="tab:red", label="KF estimate",
                        linewidth=1.3)
        wbplot.estimate(ax, data[f"{g}/pred"][None], motion=_RR_MOTION, color="purple", linestyle=":",
                        label="one-step prediction", linewidth=1.3)
        span = data["truth"]
        ax.set_xlim(max(span[:, 0].min() - 150, -50), span[:, 0].max() + 150)
        ax.set_ylim(span[:, 1].min() - 4, span[:, 1].max() + 4)
        ax.set_xlabel(f"bistatic range {wbplot.state_label(_RR_MOTION, 0)}")
        ax.set_ylabel(f"bistatic range-rate {wbplot.state_label(_RR_MOTION, 1)}")
        sec = ax.secondary_yaxis("right", functions=(lambda r: -r / lam, lambda f: -f * lam))
        sec.set_ylabel("Doppler f_D = -Rdot / lambda (Hz)")
        ax.set_title(f"{data['filter'][0]}, run 0, {title}", fontsize=9)
        if i == 0:
            ax.legend(fontsize=6, loc="best")


def draw_time(data, fig) -> None:
    t = data["times"]
    labels = (("bistatic range", 0), ("range-rate", 1))
    for i, (label, c) in enumerate(labels):
        ax = fig.add_subplot(2, 1, i + 1)
        wbplot.truth(ax, _truth_rr(data), dims=c, motion=_RR_MOTION, color="0.6")
        ax.plot(t, data["nogate/chosen"][:, c], ".", color="k", ms=3, label="selected measurement (no gate)",
                gid="selected")
        wbplot.estimate(ax, data["nogate/est"][None], dims=c, times=t, motion=_RR_MOTION, color="tab:red",
                        label="KF, no gate")
        wbplot.estimate(ax, data["gate/est"][None], dims=c, times=t, motion=_RR_MOTION, color="tab:blue",
                        linestyle="--", label="KF, gate")
        lo, hi = data["truth"][:, c].min(), data["truth"][:, c].max()
        pad = 0.5 * (hi - lo) + (50 if c == 0 else 2)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(f"{label} {wbplot.state_label(_RR_MOTION, c)}")
        if i == 1:
            ax.set_xlabel("time (s)")
        else:
            ax.set_xlabel("")
            ax.legend(fontsize=6, ncol=2)


def fig_caf_data(results) -> dict[str, np.ndarray]:
    sig = results["signal"]
    keys = ("caf_db", "caf_raw_db", "range_m", "doppler_hz", "det_range", "det_doppler", "det_strength",
            "true_range", "true_doppler", "wavelength")
    return {k: sig[k] for k in keys}


def draw_caf(data, fig) -> None:
    r, f = data["range_m"], data["doppler_hz"]
    lam = float(data["wavelength"])
    for i, (key, title) in enumerate((("caf_raw_db", "before ECA"), ("caf_db", "after ECA, with CA-CFAR detections"))):
        ax = fig.add_subplot(1, 2, i + 1)
        dr, df = r[1] - r[0], f[1] - f[0]
        im = ax.imshow(data[key].T, origin="lower", aspect="auto", cmap="viridis", vmin=-5, vmax=45,
                       extent=(r[0] - dr / 2, r[-1] + dr / 2, f[0] - df / 2, f[-1] + df / 2), interpolation="nearest")
        if i == 1:
            ax.plot(data["det_range"], data["det_doppler"], "o", mfc="none", mec="w", ms=8, label="CFAR candidates")
            ax.plot(data["true_range"], data["true_doppler"], "x", color="tab:red", ms=7, label="true target")
            ax.legend(fontsize=6, loc="lower right")
            fig.colorbar(im, ax=ax, label="|chi|^2 (dB over noise)")
        ax.set_xlabel("bistatic range (m)")
        ax.set_ylabel("Doppler (Hz)")
        sec = ax.secondary_yaxis("right", functions=(lambda x: -x * lam, lambda v: -v / lam))
        sec.set_ylabel("range-rate (m/s)" if i == 1 else "")
        ax.set_title(title, fontsize=9)


def fig_nis_data(results) -> dict[str, np.ndarray]:
    _, res = _first(results)
    edges = np.linspace(0.0, 20.0, 41)
    out = {"edges": edges}
    sigma = stated_sigma(res)
    for v in VARIANTS:
        white = np.asarray(res[f"{v}/white"], dtype=float)
        # on-target updates: the target's candidate exists and the chosen one is within 3 sigma of the truth
        good = np.asarray(res[f"{v}/target_present"], bool) & on_target(res[f"{v}/chosen"], res["truth_rr"], sigma)
        nis = np.sum(white ** 2, axis=-1)[good & np.isfinite(white[..., 0])]
        out[f"{v}/density"] = np.histogram(np.minimum(nis, edges[-1] - 1e-9), edges, density=True)[0]
        out[f"{v}/samples"] = np.array(nis.size)
    return out


def draw_nis(data, fig) -> None:
    for i, g in enumerate(("nogate", "gate")):
        ax = fig.add_subplot(1, 2, i + 1)
        wbplot.nis_density(ax, data[f"rr-{g}/density"], data["edges"], _NIS_DOF, label="range / range-rate",
                           color="tab:red")
        wbplot.nis_density(ax, data[f"rv-{g}/density"], data["edges"], _NIS_DOF, label="monostatic velocity",
                           color="tab:orange", linestyle="--", reference=False)
        ax.set_xlabel(f"NIS ({_NIS_DOF} dof; on-target updates; last bin: >= {data['edges'][-2]:g})")
        ax.set_title("no gate (paper)" if g == "nogate" else "gate d2 <= 9.21", fontsize=9)
        ax.legend(fontsize=6)


def fig_demanding_data(results) -> dict[str, np.ndarray]:
    dem = results["signal-demanding"]
    keys = ("caf_raw_db", "caf_edge_db", "caf_full_db", "range_m", "doppler_hz", "wavelength", "true_range",
            "true_doppler", "taps", "edge/det_range", "edge/det_doppler", "full/det_range", "full/det_doppler",
            "detected", "clutter_max")
    return {k: dem[k] for k in keys}


def draw_demanding(data, fig) -> None:
    r, f = data["range_m"], data["doppler_hz"]
    lam = float(data["wavelength"])
    taps = data["taps"]
    reach = float(data["clutter_max"]) / 1e3
    panels = (("caf_raw_db", None, "no ECA"), ("caf_edge_db", "edge", f"ECA {taps[2]} taps (the map, 0-3 km)"),
              ("caf_full_db", "full", f"ECA {taps[3]} taps (past the clutter's {reach:g} km)"))
    dr, df = r[1] - r[0], f[1] - f[0]
    for i, (key, det, title) in enumerate(panels):
        ax = fig.add_subplot(1, 3, i + 1)
        img = data[key]
        floor = float(np.median(img[:, np.abs(f) > df]))  # this panel's floor over the full-tap floor
        im = ax.imshow(img.T, origin="lower", aspect="auto", cmap="viridis", vmin=floor - 5, vmax=floor + 50,
                       extent=(r[0] - dr / 2, r[-1] + dr / 2, f[0] - df / 2, f[-1] + df / 2), interpolation="nearest")
        if det is not None:
            ax.plot(data[f"{det}/det_range"], data[f"{det}/det_doppler"], "o", mfc="none", mec="w", ms=8,
                    label="CFAR candidates")
            found = bool(data["detected"][i])
            title += f"; target {'detected' if found else 'lost'}"
        title += f"\nnoise floor {floor:+.0f} dB (colour scale: floor -5 to +50 dB)"
        ax.plot(data["true_range"], data["true_doppler"], "x", color="tab:red", ms=7, label="true target")
        ax.set_xlabel("bistatic range (m)")
        ax.set_ylabel("Doppler (Hz)")
        sec = ax.secondary_yaxis("right", functions=(lambda x: -x * lam, lambda v: -v / lam))
        sec.set_ylabel("range-rate (m/s)")
        ax.set_title(title, fontsize=7)
        fig.colorbar(im, ax=ax, pad=0.18, label=f"|chi|^2 (dB over the {taps[3]}-tap noise floor)")
        if i == 2:
            ax.legend(fontsize=6, loc="lower right")


FIGURES = (
        FigureSpec("fig1", "Experiment layout (local ENU): Tx, Rx, baseline, reference and surveillance antenna "
                   "directions, surveillance sector and the drone path of run 0.", fig_geometry_data, draw_geometry,
                   size=(10.0, 4.6)),
        FigureSpec("fig2", "Range-Doppler trajectory of run 0 (x: bistatic range in m; y: range-rate in m/s, right "
                   "axis Doppler in Hz): selected NN measurements black dotted, KF estimates red, one-step "
                   "predictions purple dotted; grey: all candidates and truth.", fig_trajectory_data,
                   draw_trajectory, size=(10.0, 4.6)),
        FigureSpec("fig2b", "Bistatic range R(t) and range-rate Rdot(t) of run 0 against truth (grey).",
                   fig_trajectory_data, draw_time, size=(7.0, 5.5)),
        FigureSpec("fig3", "Benign scene (the paper's row): cross-ambiguity map of one signal-level frame "
                   "(|chi|^2 in dB over the noise floor) before and after ECA, with the CA-CFAR candidates "
                   "(zero-Doppler bin excluded) and the true target.", fig_caf_data, draw_caf, size=(10.0, 4.2)),
        FigureSpec("fig4", "Ablation: NIS histograms of the range / range-rate model and of the monostatic "
                   "range-velocity model on on-target updates, against the chi-square(2) density.",
                   fig_nis_data, draw_nis, size=(9.0, 3.8)),
        FigureSpec("fig5", "Demanding scene (ATSC 8-VSB, direct path +60 dB, clutter to 17.5 km, reference multipath "
                   "cleaned, CPI 0.5 s): one frame without ECA, with taps over the map's 0-3 km (102: the clutter "
                   "beyond the map buries the target) and with 600 taps (0-18 km: the target is back), with the "
                   "CA-CFAR candidates and the true target.",
                   fig_demanding_data, draw_demanding, size=(15.0, 4.4)),
)
