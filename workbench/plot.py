"""Figures of the workbench's own records, on Matplotlib.

Every function takes a Matplotlib ``Axes`` (or ``None``: a new figure's axes, through ``pyplot``), draws one
kind of record and returns the ``Axes``.  Axis labels carry units: a state component's from the motion model's
declared ``state_names`` and ``state_units`` (pass ``motion=``), a detection's from its measurement frame
(``workbench.frames.FRAMES``), time in seconds where the scan times are given.  Where nothing declares a
unit the label says so (``"state component 2"``); nothing is guessed from an array's length.

- ``truth``: one line per object of a run (a ``Truth`` or a ``MultiTruth``), a filled circle at its start;
- ``detections``: a run's detections, clutter and target detections told apart by ``Scans.origin``; positions
  through the frame's ``to_position`` where the frame gives one;
- ``tracks``: a ``TrackLog``'s tracks of a run, one line per track identity, a triangle at its start and a
  hollow square at its end;
- ``estimate``: a single-target filter's mean over time (a ``Track``), a hollow circle at its start, optional
  covariance ellipses;
- ``ellipses``: ``n_sigma`` covariance ellipses of the 2x2 position block at chosen steps;
- ``nees``, ``nis``: the mean over runs per step with the two-sided chi-square band of a run-average;
- ``nis_density``: a histogram density of NIS values (computed by the caller) against the chi-square density;
- ``rmse``: position RMSE over runs per step; ``error_over_time``: an error measure per step that the caller
  computed (one method's MSE or RMSE curve); ``gospa``: GOSPA per scan; ``track_counts``: confirmed tracks per
  scan;
- ``log_axis``: a logarithmic axis with plain tick labels (``20``, not ``2x10^1``).

Every artist a function draws carries a ``gid`` naming what it is (``"truth:object 0"``,
``"track-start:gnn:3"``, ``"band-upper:NIS"``), so a caller (or a test) finds it again with
``[a for a in ax.lines if a.get_gid() == ...]``.  Matplotlib is imported inside the functions:
``import workbench`` does not load it.

Example::

    import workbench as wb
    ax = wb.plot.truth(None, truth, motion=cv)
    wb.plot.detections(ax, scans, model=model)
    wb.plot.estimate(ax, track, motion=cv, ellipse_steps=[0, 10, 20])
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .types import CLUTTER, InputError

__all__ = ["truth", "detections", "tracks", "estimate", "ellipses", "nees", "nis", "nis_density", "rmse",
           "error_over_time", "gospa", "track_counts", "log_axis", "plain_number", "state_label",
           "ellipse_vertices", "chi2_band", "LINESTYLES"]

#: The line styles given to the 1st, 2nd, ... filter or tracker drawn on one Axes (with colours ``C0``,
#: ``C1``, ...), so that one never hides another.
LINESTYLES = ("-", "--", "-.", ":")


def _axes(ax, who: str):
    from matplotlib.axes import Axes

    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots()
        return ax
    if not isinstance(ax, Axes):
        raise InputError(f"plot.{who}: ax must be a Matplotlib Axes or None, got {type(ax).__name__}")
    return ax


def _next_color(ax) -> str:
    """The Axes' next colour of its property cycle (as a plain ``ax.plot`` would take it)."""
    probe, = ax.plot([], [])
    color = probe.get_color()
    probe.remove()
    return color


def _run(who: str, run: int, batch: int) -> int:
    if isinstance(run, bool) or not isinstance(run, (int, np.integer)) or not 0 <= run < batch:
        raise InputError(f"plot.{who}: run must be an integer in [0, {batch}), got {run!r}")
    return int(run)


def _dims(who: str, dims, n: int) -> tuple[int, ...]:
    """``dims`` as one component (drawn over time) or two (drawn in the plane), each in ``[0, n)``."""
    out = (dims,) if isinstance(dims, (int, np.integer)) and not isinstance(dims, bool) else tuple(dims)
    if len(out) not in (1, 2) or not all(isinstance(d, (int, np.integer)) and not isinstance(d, bool) and
                                         0 <= d < n for d in out):
        raise InputError(f"plot.{who}: dims must be one state component (drawn over time) or two (drawn in the "
                         f"plane), each in [0, {n}), got {dims!r}")
    return tuple(int(d) for d in out)


def state_label(motion, i: int) -> str:
    """``"x (m)"`` from the motion model's declared ``state_names`` and ``state_units``, else
    ``"state component i"``."""
    if motion is not None:
        names, units = tuple(motion.state_names), tuple(motion.state_units)
        if len(names) == motion.dim and i < len(names):
            return f"{names[i]} ({units[i]})" if len(units) == motion.dim else names[i]
    return f"state component {i}"


def _time_axis(who: str, times, steps: int):
    if times is None:
        return np.arange(steps), "scan"
    times = np.asarray(times, dtype=float)
    if times.shape != (steps,):
        raise InputError(f"plot.{who}: times must have shape ({steps},), one per step, got {times.shape}")
    return times, "time (s)"


def _set_labels(ax, xlabel: str, ylabel: str) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)


def _xy(points: np.ndarray, dims: tuple[int, ...], x_time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if len(dims) == 2:
        return points[:, dims[0]], points[:, dims[1]]
    return x_time, points[:, dims[0]]


def truth(ax, truth, run: int = 0, dims=(0, 1), motion=None, color: str = "k", label: str = "truth"):
    """Draw the true path of every object of run ``run``: one line per object (over the scans it is alive), a
    filled circle at its first state.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    truth : Truth or MultiTruth
        ``states (B, T, n)``, or ``(B, T, K, n)`` with its ``alive`` mask (each object's line spans its live
        scans; its ``labels`` name the lines' ``gid``: ``"truth:<label>"``, ``"truth-start:<label>"``).
    run : int
    dims : int or (int, int)
        Two state components: drawn in the plane; one: drawn over time (the truth's ``times``).
    motion : MotionModel or None
        Its ``state_names`` and ``state_units`` label the axes.
    """
    from .truth import MultiTruth
    from .types import Truth

    ax = _axes(ax, "truth")
    if isinstance(truth, MultiTruth):
        states, alive, names = truth.states, truth.alive, truth.labels
    elif isinstance(truth, Truth):
        states, alive = truth.states[:, :, None, :], np.ones(truth.states.shape[:2] + (1,), dtype=bool)
        names = ("truth",)
    else:
        raise InputError(f"plot.truth: truth must be a Truth or a MultiTruth, got {type(truth).__name__}")
    b = _run("truth", run, states.shape[0])
    d = _dims("truth", dims, states.shape[-1])
    first = True
    for k in range(states.shape[2]):
        live = np.flatnonzero(alive[b, :, k])
        if live.size == 0:
            continue
        x, y = _xy(states[b, live, k], d, truth.times[live])
        ax.plot(x, y, "-", color=color, lw=1.3, label=label if first else "_nolegend_", gid=f"truth:{names[k]}")
        ax.plot(x[:1], y[:1], "o", color=color, ms=5, label="_nolegend_", gid=f"truth-start:{names[k]}")
        if isinstance(truth, MultiTruth):
            ax.annotate(names[k], (x[0], y[0]), textcoords="offset points", xytext=(4, 4), fontsize=7,
                        color=color)
        first = False
    if len(d) == 2:
        _set_labels(ax, state_label(motion, d[0]), state_label(motion, d[1]))
    else:
        _set_labels(ax, "time (s)", state_label(motion, d[0]))
    return ax


def _frame(who: str, frame, model):
    from .frames import FRAMES, Frame

    if isinstance(frame, Frame):
        return frame
    name = frame if frame is not None else (getattr(model, "frame", "") or None)
    if name is None:
        return None
    if not isinstance(name, str) or name not in FRAMES:
        raise InputError(f"plot.{who}: unknown measurement frame {name!r} (known: {', '.join(FRAMES)})")
    return FRAMES[name]


def detections(ax, scans, run: int = 0, model=None, frame=None, sensor=None, component: int | None = None):
    """Draw the detections of run ``run``; clutter (``origin == CLUTTER``) as light grey dots, target detections
    as dark crosses, and all as grey dots where the scans carry no ``origin`` (recorded data).

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    scans : Scans
    run : int
    model : MeasurementModel or None
        Declares the frame (``model.frame``) and the sensor's position (``model.sensor_position``) when ``frame``
        is not given.
    frame : str or Frame or None
        The detections' measurement frame; by default the model's.
    sensor : sequence of float or None
        Where the detections were measured from; by default the model's ``sensor_position`` when the model
        describes measurements of this frame, else the origin.
    component : int or None
        ``None``: positions in the plane, through the frame's ``to_position`` (refused where the frame gives no
        position or declares none); an integer: that measurement component over time.
    """
    ax = _axes(ax, "detections")
    fr = _frame("detections", frame, model)
    b = _run("detections", run, scans.batch)
    valid = scans.valid[b]
    z = scans.z[b][valid]
    t = np.broadcast_to(scans.times[:, None], valid.shape)[valid]
    if component is None:
        if fr is None or fr.position is None or fr.space < 2:
            why = "declares no frame" if fr is None else f"frame {fr.name!r} gives no position in the plane"
            raise InputError(f"plot.detections: the detections {why}; draw one measurement component over time "
                             f"(component=0)")
        if sensor is None and model is not None and getattr(model, "frame", "") == fr.name:
            sensor = model.sensor_position
        xy = fr.to_position(z, sensor)
        x, y = xy[:, 0], xy[:, 1]
        unit = next((u for u in fr.units if u in ("m", "km")), "m")
        xlabel, ylabel = f"x ({unit})", f"y ({unit})"
    else:
        m = scans.z.shape[-1]
        if isinstance(component, bool) or not isinstance(component, (int, np.integer)) or not 0 <= component < m:
            raise InputError(f"plot.detections: component must be None or an integer in [0, {m}), got "
                             f"{component!r}")
        x, y = t, z[:, component]
        xlabel = "time (s)"
        ylabel = fr.labels()[component] if fr is not None else f"measurement component {component} (no frame " \
                                                               f"declared)"
    if scans.origin is None:
        groups = [("detections", np.ones(x.shape, dtype=bool), dict(marker=".", color="0.5", ms=3))]
    else:
        clutter = scans.origin[b][valid] == CLUTTER
        groups = [("clutter", clutter, dict(marker=".", color="0.72", ms=3)),
                  ("target detections", ~clutter, dict(marker="x", color="0.3", ms=3.5, mew=0.8))]
    for name, keep, style in groups:
        if keep.any():
            ax.plot(x[keep], y[keep], ls="none", label=name, gid=f"detections:{name}", **style)
    _set_labels(ax, xlabel, ylabel)
    return ax


def tracks(ax, log, run: int = 0, confirmed_only: bool = True, dims=(0, 1), motion=None, times=None,
           color: str | None = None, linestyle: str = "-", label: str = "tracks", linewidth: float = 1.1):
    """Draw a tracker's tracks of run ``run``: one line per track identity through its states in ping order, a
    triangle at its first state and a hollow square at its last.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    log : TrackLog
    run : int
    confirmed_only : bool
        Only the rows where a track is confirmed (a track never confirmed draws nothing).
    dims : int or (int, int)
        Two state components: drawn in the plane; one: drawn over the pings (``times[ping]`` where ``times``
        is given).
    motion : MotionModel or None
        Labels the axes.
    color, linestyle, label : str
        One colour (and line style, width ``linewidth``) for all of this log's tracks (default: the Axes' next colour); the legend shows ``label``
        once.  Artists' ``gid``: ``"track:<label>:<id>"``, ``"track-start:..."``, ``"track-end:..."``.
    """
    from .tracking.records import CONFIRMED, TrackLog

    ax = _axes(ax, "tracks")
    if not isinstance(log, TrackLog):
        raise InputError(f"plot.tracks: log must be a TrackLog, got {type(log).__name__}")
    b = _run("tracks", run, log.runs)
    d = _dims("tracks", dims, log.mean.shape[-1])
    x_time, xlabel = _time_axis("tracks", times, log.pings)
    rows = log.run == b
    if confirmed_only:
        rows = rows & (log.status == CONFIRMED)
    color = color or _next_color(ax)
    ids = np.unique(log.track_id[rows])
    for i, tid in enumerate(ids):
        r = np.flatnonzero(rows & (log.track_id == tid))
        r = r[np.argsort(log.ping[r], kind="stable")]
        x, y = _xy(log.mean[r], d, x_time[log.ping[r]])
        ax.plot(x, y, linestyle, color=color, lw=linewidth, label=label if i == 0 else "_nolegend_",
                gid=f"track:{label}:{tid}")
        ax.plot(x[:1], y[:1], "^", color=color, ms=5, label="_nolegend_", gid=f"track-start:{label}:{tid}")
        ax.plot(x[-1:], y[-1:], "s", color=color, mfc="none", ms=5, label="_nolegend_",
                gid=f"track-end:{label}:{tid}")
    if len(d) == 2:
        _set_labels(ax, state_label(motion, d[0]), state_label(motion, d[1]))
    else:
        _set_labels(ax, xlabel, state_label(motion, d[0]))
    return ax


def _mean_cov(who: str, track) -> tuple[np.ndarray, np.ndarray | None]:
    if isinstance(track, (np.ndarray, list, tuple)):
        mean, cov = track, None
    else:
        mean, cov = getattr(track, "mean", track), getattr(track, "cov", None)
    mean = np.asarray(mean, dtype=float)
    if mean.ndim != 3:
        raise InputError(f"plot.{who}: the estimate's mean must have shape (B, T, n) (a Track, or an array), got "
                         f"{mean.shape}")
    if cov is not None:
        cov = np.asarray(cov, dtype=float)
        if cov.shape != mean.shape + mean.shape[-1:]:
            raise InputError(f"plot.{who}: the estimate's cov must have shape {mean.shape + mean.shape[-1:]}, got "
                             f"{cov.shape}")
    return mean, cov


def estimate(ax, track, run: int = 0, dims=(0, 1), motion=None, times=None, color: str | None = None,
             linestyle: str = "-", label: str | None = None, ellipse_steps: Sequence[int] = (),
             n_sigma: float = 2.0, linewidth: float = 1.2):
    """Draw a single-target filter's mean of run ``run`` over time, a hollow circle at its first step, and its
    covariance ellipses at ``ellipse_steps`` (see ``ellipses``).

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    track : Track or array
        ``mean (B, T, n)`` (and ``cov (B, T, n, n)`` for ellipses): a ``workbench.tracking.Track`` or
        the mean array itself.
    run : int
    dims : int or (int, int)
        Two state components: drawn in the plane; one: drawn over time (``times``, else the step index).
    motion : MotionModel or None
        Labels the axes.
    color, linestyle : str
        Default colour: the Axes' next one (``linewidth``: the line's width in points).
    label : str or None
        Default: the track's ``filter`` name.  Artists' ``gid``: ``"estimate:<label>"``,
        ``"estimate-start:<label>"``.
    ellipse_steps : sequence of int
    n_sigma : float
    """
    ax = _axes(ax, "estimate")
    mean, cov = _mean_cov("estimate", track)
    b = _run("estimate", run, mean.shape[0])
    d = _dims("estimate", dims, mean.shape[-1])
    x_time, xlabel = _time_axis("estimate", times, mean.shape[1])
    label = label or getattr(track, "filter", None) or "estimate"
    color = color or _next_color(ax)
    x, y = _xy(mean[b], d, x_time)
    ax.plot(x, y, linestyle, color=color, lw=linewidth, label=label, gid=f"estimate:{label}")
    ax.plot(x[:1], y[:1], "o", color=color, mfc="none", ms=7, mew=1.2, label="_nolegend_",
            gid=f"estimate-start:{label}")
    if len(ellipse_steps):
        if cov is None:
            raise InputError("plot.estimate: ellipse_steps need the estimate's covariances (a Track, not a mean "
                             "array)")
        if len(d) != 2:
            raise InputError("plot.estimate: ellipses are drawn in the plane: dims must name two components")
        ellipses(ax, mean[b], cov[b], steps=ellipse_steps, n_sigma=n_sigma, dims=d, color=color)
    if len(d) == 2:
        _set_labels(ax, state_label(motion, d[0]), state_label(motion, d[1]))
    else:
        _set_labels(ax, xlabel, state_label(motion, d[0]))
    return ax


def ellipse_vertices(center: np.ndarray, cov2: np.ndarray, n_sigma: float = 2.0, points: int = 72) -> np.ndarray:
    """``(points, 2)`` vertices of the ellipse ``(v - c)^T P^-1 (v - c) = n_sigma^2``: ``c + n_sigma V
    sqrt(L) [cos t, sin t]`` from the eigen-decomposition ``P = V L V^T`` of the 2x2 block."""
    w, V = np.linalg.eigh(cov2)
    t = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    unit = np.stack([np.cos(t), np.sin(t)])
    return center + (n_sigma * (V * np.sqrt(np.clip(w, 0.0, None))) @ unit).T


def ellipses(ax, mean, cov, steps=None, n_sigma: float = 2.0, dims=(0, 1), color: str | None = None,
             points: int = 72):
    """Draw the ``n_sigma`` ellipse of the 2x2 block ``dims`` of each covariance at ``steps``: the points ``v``
    with ``(v - m)^T P^-1 (v - m) = n_sigma^2`` (from the block's eigen-decomposition), as unfilled polygons with
    ``gid`` ``"ellipse:<step>"``.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    mean : array (T, n) or (n,)
    cov : array (T, n, n) or (n, n)
    steps : sequence of int or None
        The steps to draw (``None``: every step).
    n_sigma : float
    dims : (int, int)
    """
    from matplotlib.patches import Polygon

    ax = _axes(ax, "ellipses")
    mean, cov = np.asarray(mean, dtype=float), np.asarray(cov, dtype=float)
    if mean.ndim == 1:
        mean, cov = mean[None], cov[None] if cov.ndim == 2 else cov
    if mean.ndim != 2 or cov.shape != mean.shape + mean.shape[-1:]:
        raise InputError(f"plot.ellipses: need mean (T, n) and cov (T, n, n), got {mean.shape} and {cov.shape}")
    d = _dims("ellipses", dims, mean.shape[-1])
    if len(d) != 2:
        raise InputError("plot.ellipses: dims must name two state components")
    if not (np.isfinite(n_sigma) and n_sigma > 0):
        raise InputError(f"plot.ellipses: n_sigma must be > 0, got {n_sigma}")
    T = mean.shape[0]
    steps = range(T) if steps is None else steps
    color = color or _next_color(ax)
    block = np.ix_(d, d)
    for k in steps:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not -T <= k < T:
            raise InputError(f"plot.ellipses: steps must be integers in [0, {T}), got {k!r}")
        P = cov[k][block]
        if not np.all(np.isfinite(P)) or np.linalg.eigvalsh(P)[0] < -1e-9 * max(1.0, np.abs(P).max()):
            raise InputError(f"plot.ellipses: the position covariance at step {int(k)} is not finite positive "
                             f"semi-definite")
        v = ellipse_vertices(mean[k, list(d)], P, n_sigma, points)
        ax.add_patch(Polygon(v, closed=True, fill=False, edgecolor=color, lw=0.8, gid=f"ellipse:{int(k)}"))
    ax.autoscale_view()
    return ax


def chi2_band(dof: int, count, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """The two-sided ``confidence`` interval of the average of ``count`` independent chi-square(``dof``) values:
    ``chi2.ppf((1 -+ confidence) / 2, dof count) / count`` (NaN where ``count`` is 0)."""
    from scipy.stats import chi2

    count = np.asarray(count, dtype=float)
    n = np.where(count > 0, count, np.nan)
    tail = (1.0 - confidence) / 2.0
    return chi2.ppf(tail, dof * n) / n, chi2.ppf(1.0 - tail, dof * n) / n


def _consistency(who, ax, values, dof, runs, times, confidence, label, color, log):
    ax = _axes(ax, who)
    values = np.asarray(values, dtype=float)
    if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 1:
        raise InputError(f"plot.{who}: dof must be a positive integer (the state or measurement dimension), got "
                         f"{dof!r}")
    if not 0 < confidence < 1:
        raise InputError(f"plot.{who}: confidence must lie in (0, 1), got {confidence}")
    if values.ndim == 2:
        if runs is not None and runs != values.shape[0]:
            raise InputError(f"plot.{who}: values of shape {values.shape} hold {values.shape[0]} runs, but "
                             f"runs={runs}")
        count = np.isfinite(values).sum(axis=0)
        total = np.where(np.isfinite(values), values, 0.0).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        runs = values.shape[0]
    elif values.ndim == 1:
        if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 1:
            raise InputError(f"plot.{who}: values of shape {values.shape} are means over runs: say over how many "
                             f"(runs=), or give the per-run values (B, T)")
        mean = values
        count = np.where(np.isfinite(values), runs, 0)
    else:
        raise InputError(f"plot.{who}: values must be (B, T) per run or (T,) means over runs, got {values.shape}")
    x, xlabel = _time_axis(who, times, mean.shape[0])
    lo, hi = chi2_band(int(dof), count, confidence)
    color = color or _next_color(ax)
    ax.plot(x, mean, "-", marker=".", ms=3, color=color, lw=1.2, label=f"{label} (mean over {runs} run{'s' * (runs != 1)})",
            gid=f"{who}:{label}")
    pct = f"{100 * confidence:g} %"
    ax.fill_between(x, lo, hi, color=color, alpha=0.12, lw=0, gid=f"band:{label}")
    ax.plot(x, lo, "--", color=color, lw=0.8, label=f"{pct} band of the mean", gid=f"band-lower:{label}")
    ax.plot(x, hi, "--", color=color, lw=0.8, label="_nolegend_", gid=f"band-upper:{label}")
    ax.axhline(dof, color="0.5", lw=0.6, ls=":", gid="expected")
    _set_labels(ax, xlabel, f"{who.upper()} (dimensionless; {int(dof)} dof)")
    if log:
        log_axis(ax, "y")
    return ax


def nees(ax, values, dof: int, runs: int | None = None, times=None, confidence: float = 0.95,
         label: str = "NEES", color: str | None = None, log: bool = False):
    """Draw the NEES per step, averaged over runs, with the two-sided ``confidence`` chi-square band of a
    run-average (``chi2_band``: ``chi2.ppf(q, dof N) / N`` for ``N`` runs) and the expected value ``dof``.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    values : array (B, T) or (T,)
        Per-run NEES (``workbench.metrics.nees``; NaN entries are left out of the mean and the band's ``N``
        at that step), or means over ``runs`` runs.
    dof : int
        The state dimension the NEES is over.
    runs : int or None
        Needed for ``(T,)`` means; must agree with ``B`` for ``(B, T)``.
    times : array (T,) or None
        Default: the step index.
    log : bool
        A logarithmic y axis (plain tick labels).
    """
    return _consistency("nees", ax, values, dof, runs, times, confidence, label, color, log)


def nis(ax, values, dof: int | None = None, runs: int | None = None, times=None, confidence: float = 0.95,
        label: str = "NIS", color: str | None = None, log: bool = False):
    """Draw the NIS per step, averaged over the runs updated at that step, with its chi-square band (as
    ``nees``).

    ``values``: ``(B, T)`` per run (NaN where a run had no update), ``(T,)`` means over ``runs`` runs, or an
    ``workbench.kalman_core.Innovations`` record over scans (``run(..., innovations=True)``), whose
    ``nis`` where ``present`` is drawn and whose measurement dimension is the default ``dof``.
    """
    if hasattr(values, "nis") and hasattr(values, "present"):
        nis_values = np.asarray(values.nis, dtype=float)
        values_m = np.asarray(values.y).shape[-1]
        dof = values_m if dof is None else dof
        values = np.where(np.asarray(values.present, dtype=bool), nis_values, np.nan)
    if dof is None:
        raise InputError("plot.nis: dof (the measurement dimension) is needed with an array of NIS values")
    return _consistency("nis", ax, values, dof, runs, times, confidence, label, color, log)


def nis_density(ax, density, edges, dof: int, label: str = "NIS", color: str | None = None, linestyle: str = "-",
                reference: bool = True, log: bool = True):
    """Draw a histogram density of NIS values (computed by the caller, e.g. ``numpy.histogram(...,
    density=True)``) as steps at the bin centres, and the chi-square(``dof``) density ``scipy.stats.chi2.pdf`` at
    the same centres: the distribution a consistent filter's NIS follows.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    density : array (K,)
        The histogram's density per bin (finite, >= 0).
    edges : array (K + 1,)
        The bins' edges, increasing.
    dof : int
        The measurement dimension (the chi-square's degrees of freedom).
    label : str
        The legend entry and ``gid`` (``"nis-density:<label>"``); the reference is ``"chi2-density:<dof>"``.
    reference : bool
        Draw the chi-square density (leave it out for a second histogram on the same Axes).
    log : bool
        A logarithmic y axis with plain tick labels (default).
    """
    from scipy.stats import chi2

    ax = _axes(ax, "nis_density")
    density, edges = np.asarray(density, dtype=float), np.asarray(edges, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0):
        raise InputError(f"plot.nis_density: edges must be finite and increasing, shape (K + 1,) with K >= 1, got "
                         f"shape {edges.shape}")
    if density.shape != (edges.size - 1,):
        raise InputError(f"plot.nis_density: density must have one value per bin, shape ({edges.size - 1},), got "
                         f"{density.shape}")
    if not np.all(np.isfinite(density)) or np.any(density < 0):
        raise InputError("plot.nis_density: density must be finite and >= 0")
    if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 1:
        raise InputError(f"plot.nis_density: dof must be a positive integer (the measurement dimension), got "
                         f"{dof!r}")
    mid = 0.5 * (edges[1:] + edges[:-1])
    color = color or _next_color(ax)
    ax.step(mid, density, where="mid", ls=linestyle, color=color, lw=1.2, label=label, gid=f"nis-density:{label}")
    if reference:
        ax.plot(mid, chi2.pdf(mid, int(dof)), "-", color="k", lw=0.8, label=f"chi-square, {int(dof)} dof",
                gid=f"chi2-density:{int(dof)}")
    _set_labels(ax, f"NIS (dimensionless; {int(dof)} dof)", "probability density")
    if log:
        log_axis(ax, "y")
    return ax


def error_over_time(ax, values, times=None, quantity: str = "position RMSE", unit: str | None = None,
                    label: str = "estimate", color: str | None = None, linestyle: str = "-",
                    linewidth: float = 1.2, log: bool = True):
    """Draw an error measure per step that the caller computed (one curve per call: a method's position MSE
    averaged over runs, say), where ``rmse`` would need the truth and the estimates themselves.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    values : array (T,)
        The measure per step (>= 0; NaN or inf leaves a gap).
    times : array (T,) or None
        Default: the step index.
    quantity, unit : str
        The y label, ``"<quantity> (<unit>)"`` (``"unit not declared"`` without a unit).
    label : str
        The legend entry and ``gid`` (``"error:<label>"``).
    log : bool
        A logarithmic y axis with plain tick labels (default).
    """
    ax = _axes(ax, "error_over_time")
    values = np.asarray(values, dtype=float)
    if values.ndim != 1:
        raise InputError(f"plot.error_over_time: values must be one curve (T,) per call, got {values.shape}")
    if np.any(values < 0):
        raise InputError("plot.error_over_time: values must be >= 0 (an error measure; NaN or inf, a diverged "
                         "run's, leaves a gap)")
    x, xlabel = _time_axis("error_over_time", times, values.shape[0])
    color = color or _next_color(ax)
    ax.plot(x, values, linestyle, color=color, lw=linewidth, label=label, gid=f"error:{label}")
    _set_labels(ax, xlabel, f"{quantity} ({unit if unit else 'unit not declared'})")
    if log:
        log_axis(ax, "y")
    return ax


def rmse(ax, truth, estimate, position_dims: int | None = None, motion=None, times=None, label: str | None = None,
         color: str | None = None, linestyle: str = "-", log: bool = True, linewidth: float = 1.2):
    """Draw the position RMSE over runs per step, ``sqrt(mean_b |p_true - p_est|^2)``.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
    truth : Truth or array (B, T, n)
    estimate : Track or array (B, T, n)
    position_dims : int or None
        How many leading state components are the position; by default the motion model's
        ``workbench.models.MotionModel.position_dims`` (one of the two must be given).
    motion : MotionModel or None
        Declares the position components and their unit.
    times : array (T,) or None
        Default: the truth's ``times`` (a ``workbench.types.Truth``), else the step index.
    log : bool
        A logarithmic y axis with plain tick labels (default).
    """
    from .metrics import position_sq_error

    ax = _axes(ax, "rmse")
    states = np.asarray(getattr(truth, "states", truth), dtype=float)
    mean, _ = _mean_cov("rmse", estimate)
    if states.ndim != 3 or states.shape[:2] != mean.shape[:2]:
        raise InputError(f"plot.rmse: truth states (B, T, n) and the estimate's mean must share (B, T), got "
                         f"{states.shape} and {mean.shape}")
    if position_dims is None:
        if motion is None:
            raise InputError("plot.rmse: say which components are the position: motion= (its state_units) or "
                             "position_dims=")
        position_dims = motion.position_dims
    if not 1 <= position_dims <= min(states.shape[-1], mean.shape[-1]):
        raise InputError(f"plot.rmse: position_dims must lie in [1, {min(states.shape[-1], mean.shape[-1])}], got "
                         f"{position_dims}")
    if times is None and hasattr(truth, "times"):
        times = truth.times
    x, xlabel = _time_axis("rmse", times, states.shape[1])
    r = np.sqrt(position_sq_error(states, mean, position_dims).mean(axis=0))
    label = label or getattr(estimate, "filter", None) or "estimate"
    color = color or _next_color(ax)
    ax.plot(x, r, linestyle, color=color, lw=linewidth, label=label, gid=f"rmse:{label}")
    units = tuple(motion.state_units) if motion is not None else ()
    unit = f" ({units[0]})" if motion is not None and len(units) == motion.dim else " (unit not declared)"
    _set_labels(ax, xlabel, f"position RMSE{unit}")
    if log:
        log_axis(ax, "y")
    return ax


def gospa(ax, per_scan, times=None, cutoff: float | None = None, order: float | None = None,
          unit: str | None = None, label: str = "GOSPA", color: str | None = None, linestyle: str = "-",
          linewidth: float = 1.2):
    """Draw GOSPA per scan: the mean over runs of ``per_scan (B, T)`` (``workbench.metrics.ospa.gospa``'s
    ``distance``), or ``(T,)`` as given.

    ``cutoff``, ``order`` and ``unit`` (the positions' unit, e.g. the motion model's ``state_units[0]``) go into
    the y label; ``label`` into the legend (``gid`` ``"gospa:<label>"``).
    """
    ax = _axes(ax, "gospa")
    values = np.asarray(per_scan, dtype=float)
    if values.ndim == 2:
        runs = values.shape[0]
        values = values.mean(axis=0)
    elif values.ndim == 1:
        runs = None
    else:
        raise InputError(f"plot.gospa: per_scan must be (B, T) or (T,), got {values.shape}")
    x, xlabel = _time_axis("gospa", times, values.shape[0])
    color = color or _next_color(ax)
    ax.plot(x, values, linestyle, color=color, lw=linewidth, label=label, gid=f"gospa:{label}")
    u = unit if unit else "unit not declared"
    params = "".join([f"; c = {cutoff:g}{' ' + unit if unit else ''}" if cutoff is not None else "",
                      f", p = {order:g}" if order is not None else ""])
    mean = f", mean over {runs} runs" if runs is not None else ""
    _set_labels(ax, xlabel, f"GOSPA ({u}{params}{mean})")
    return ax


def track_counts(ax, log, run: int | None = None, times=None, label: str = "confirmed tracks",
                 color: str | None = None, linestyle: str = "-"):
    """Draw the number of confirmed tracks per scan of run ``run`` (``None``: the mean over runs) as steps."""
    from .tracking.records import TrackLog

    ax = _axes(ax, "track_counts")
    if not isinstance(log, TrackLog):
        raise InputError(f"plot.track_counts: log must be a TrackLog, got {type(log).__name__}")
    counts = log.confirmed_counts()
    if run is None:
        values = counts.mean(axis=0)
        what = f"mean over {log.runs} runs" if log.runs != 1 else "its one run"
    else:
        values, what = counts[_run("track_counts", run, log.runs)], f"run {run}"
    x, xlabel = _time_axis("track_counts", times, log.pings)
    color = color or _next_color(ax)
    ax.step(x, values, where="mid", ls=linestyle, color=color, lw=1.2, label=label, gid=f"track_counts:{label}")
    _set_labels(ax, xlabel, f"confirmed tracks per scan ({what})")
    return ax


def plain_number(x: float) -> str:
    """``x`` as a plain decimal (``20``, ``0.6``, ``1000000``), never ``2x10^1`` or ``6e-01``."""
    return np.format_float_positional(float(x), precision=6, unique=True, trim="-")


def log_axis(ax, axis: str = "y"):
    """Make ``axis`` (``"x"`` or ``"y"``) logarithmic with plain tick labels (``20``, ``0.6``) instead of
    Matplotlib's ``2x10^1``: every decade labelled, and the minor ticks 2 to 9 where the axis spans at most one
    decade, 2 and 5 where it spans up to three."""
    from matplotlib.ticker import FuncFormatter

    if axis not in ("x", "y"):
        raise InputError(f"plot.log_axis: axis must be 'x' or 'y', got {axis!r}")
    getattr(ax, f"set_{axis}scale")("log")
    target = ax.yaxis if axis == "y" else ax.xaxis

    def minor(x: float, pos=None) -> str:
        lo, hi = sorted(target.get_view_interval())
        decades = np.log10(hi / lo) if lo > 0 and hi > 0 else np.inf
        mantissa = round(x / 10.0 ** np.floor(np.log10(x) + 1e-9)) if x > 0 else 0
        shown = decades <= 1.0 or (decades <= 3.0 and mantissa in (2, 5))
        return plain_number(x) if shown else ""

    target.set_major_formatter(FuncFormatter(lambda x, pos=None: plain_number(x)))
    target.set_minor_formatter(FuncFormatter(minor))
    return ax
