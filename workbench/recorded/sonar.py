"""Recorded active-sonar detections: a validated CSV loader and a writer (format: docs/recorded-data.md).

::

    # comment lines start with '#', anywhere in the file
    #! bearing: relative            (metadata: bearings from the bow; default 'true', from the +x axis)
    ping,x,y,level                  (or time instead of ping; range,bearing instead of x,y)
    0,123.4,56.7,9.8

- ``ping``: integer >= 0 (pings numbered from 0; a ping without rows is an empty scan), or ``time``:
  finite number (rows with equal times form one ping).
- ``x, y``: Cartesian position; or ``range >= 0`` and ``bearing`` in **degrees, math convention**
  (counter-clockwise from +x): ``x = sx + range cos(bearing)``, ``y = sy + range sin(bearing)``, with the sensor
  at ``(sx, sy)``: the own ship's position of that ping where the file gives one, else the loader's ``sensor``.
- ``level``: optional, dB (``Scans.snr``).
- ``sigma_x, sigma_y`` (with ``x, y``) or ``sigma_range, sigma_bearing`` (with ``range, bearing``; the bearing's in
  degrees): optional, together, each detection's own accuracy (standard deviations, > 0).  They become
  ``Scans.cov`` in ``(x, y)``: ``diag(sigma_x^2, sigma_y^2)``, or ``J diag(sigma_r^2, sigma_b^2) J^T`` with the
  Jacobian ``J`` of the polar-to-Cartesian conversion at the detection (first order).
- ``own_x, own_y``: optional, together, the own ship's position at the ping; ``heading``: optional, the direction
  of its bow in degrees, math convention.  Every row of a ping gives the same values, and every ping has a row
  (a ping without detections is a row whose detection fields are empty).  With ``#! bearing: relative`` the bearing
  is measured from the bow (``heading`` required): the true bearing is ``heading + bearing``.

:func:`load_sonar_recording` returns the detections as :class:`~workbench.types.Scans` with Cartesian
``z (1, T, M, 2)`` and the own ship's track (:class:`OwnShip`); :func:`load_sonar_csv` returns the scans alone.
Any malformed content raises :class:`~workbench.types.InputError` naming the file, the line and the column
(bearings and headings beyond +-360 degrees and bearing accuracies of 180 degrees or more included).  Values that
are well formed but physically unlikely (an own ship faster than :data:`MAX_OWN_SHIP_SPEED`, a heading far from the
course over ground, bearings that look like radians) give an :class:`ImplausibleValueWarning` with the numbers.
A UTF-8 byte-order mark is accepted.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

import warnings

from ..textfields import ImplausibleValueWarning, finite_number, read_text
from ..types import InputError, Scans

__all__ = ["SONAR_COLUMNS", "OwnShip", "SonarRecording", "load_sonar_recording", "load_sonar_csv",
           "write_sonar_csv"]

#: Every column name the sonar format knows.
SONAR_COLUMNS = ("ping", "time", "x", "y", "range", "bearing", "level", "sigma_x", "sigma_y", "sigma_range",
                 "sigma_bearing", "own_x", "own_y", "heading")
#: The columns that describe a detection (all empty on a row that only records a ping without detections).
DETECTION_COLUMNS = ("x", "y", "range", "bearing", "level", "sigma_x", "sigma_y", "sigma_range", "sigma_bearing")
OWN_SHIP_COLUMNS = ("own_x", "own_y", "heading")
BEARING_REFERENCES = ("true", "relative")
#: A file whose largest ping number makes more than this many times as many pings as it has distinct ping numbers
#: (and more than MAX_EMPTY_PINGS pings) is refused as a probable typo unless ``pings=`` asks for that many.
SPARSE_FACTOR = 100
MAX_EMPTY_PINGS = 1000
#: Bearings and headings are degrees: beyond +-MAX_ANGLE_DEG a value is refused (radians, or a slip).
MAX_ANGLE_DEG = 360.0
#: A bearing accuracy (degrees) must be below this: a wider spread leaves no bearing at all.
MAX_SIGMA_BEARING_DEG = 180.0
#: An own ship faster than this (position units per time unit; m/s for SI files, about 190 knots) is reported
#: with a warning: positions or times in the wrong unit?
MAX_OWN_SHIP_SPEED = 100.0
#: A heading whose median difference from the own ship's course over ground exceeds this (degrees) is reported
#: with a warning: a compass heading where the format wants the mathematical convention?
HEADING_COURSE_LIMIT_DEG = 45.0
#: Slower legs (position units per time unit) say too little about the course to judge a heading.
MIN_COURSE_SPEED = 0.5
#: With at least this many polar detections all within +-2 pi, a warning asks whether the bearings are radians.
RADIAN_SUSPICION_COUNT = 10


@dataclass(frozen=True)
class OwnShip:
    """The own ship's track as a recording gives it, one entry per ping.

    Shapes: ``times (T,)``, ``position (T, 2)``, ``heading_deg (T,)`` (degrees, math convention) or ``None``.
    """

    times: np.ndarray
    position: np.ndarray
    heading_deg: np.ndarray | None = None


@dataclass(frozen=True)
class SonarRecording:
    """A loaded sonar file: its detections in ``(x, y)``, the own ship's track (``None`` where the file gives no
    own-ship columns) and how its bearings are referenced (``"true"`` or ``"relative"``)."""

    scans: Scans
    own_ship: OwnShip | None
    bearing: str = "true"
    key: str = "ping"  #: ``"ping"`` (scan times ``ping * dt``) or ``"time"`` (the file's own times)
    frame: str = "xy"  #: ``"xy"`` or ``"polar"`` (``range, bearing`` rows)


def _where(path: Path, line: int, column: str | None = None) -> str:
    return f"{path} line {line}" + (f", column {column!r}" if column else "")


def _read_text(path: Path) -> str:
    return read_text(path, "sonar file")


def _bearing_reference(path: Path, lines: list[str]) -> str:
    found: tuple[int, str] | None = None
    for i, line in enumerate(lines, 1):
        stripped = line.strip()
        if not stripped.startswith("#!"):
            continue
        key, sep, value = stripped[2:].partition(":")
        key, value = key.strip().lower(), value.strip().lower()
        if not sep or key != "bearing" or value not in BEARING_REFERENCES:
            raise InputError(f"{_where(path, i)}: a '#!' line of a sonar file declares 'bearing: true' or "
                             f"'bearing: relative', got {stripped!r}")
        if found is not None:
            raise InputError(f"{_where(path, i)}: the bearing reference is declared twice (first on line {found[0]})")
        found = (i, value)
    return "true" if found is None else found[1]


def _header(path: Path, lineno: int, line: str, reference: str) -> tuple[list[str], str, str]:
    names = [c.strip().lower() for c in next(csv.reader([line]))]
    for i, name in enumerate(names):
        if name not in SONAR_COLUMNS:
            raise InputError(f"{_where(path, lineno)}: unknown column {name!r} (column {i + 1}); "
                             f"expected names from {', '.join(SONAR_COLUMNS)}")
        if names.count(name) > 1:
            raise InputError(f"{_where(path, lineno)}: column {name!r} appears more than once")
    has = set(names)
    if ("ping" in has) == ("time" in has):
        raise InputError(f"{_where(path, lineno)}: the header needs exactly one of 'ping' or 'time', got {names}")
    cart, polar = {"x", "y"} & has, {"range", "bearing"} & has
    if cart and polar:
        raise InputError(f"{_where(path, lineno)}: give either x,y or range,bearing, not both (got {names})")
    if cart != {"x", "y"} and polar != {"range", "bearing"}:
        raise InputError(f"{_where(path, lineno)}: the header needs both 'x' and 'y', or both 'range' and 'bearing' "
                         f"(got {names})")
    frame = "xy" if cart else "polar"
    pair = ("sigma_x", "sigma_y") if frame == "xy" else ("sigma_range", "sigma_bearing")
    other = ("sigma_range", "sigma_bearing") if frame == "xy" else ("sigma_x", "sigma_y")
    for name in other:
        if name in has:
            raise InputError(f"{_where(path, lineno)}: column {name!r} belongs to "
                             f"{'range,bearing' if frame == 'xy' else 'x,y'} files; the accuracy of "
                             f"{'x,y' if frame == 'xy' else 'range,bearing'} detections is {pair[0]},{pair[1]}")
    for a, b in (pair, ("own_x", "own_y")):
        if (a in has) != (b in has):
            raise InputError(f"{_where(path, lineno)}: give both {a!r} and {b!r}, or neither")
    if "heading" in has and "own_x" not in has:
        raise InputError(f"{_where(path, lineno)}: 'heading' needs the own ship's position 'own_x','own_y' as well")
    if reference == "relative" and (frame != "polar" or "heading" not in has):
        raise InputError(f"{path}: '#! bearing: relative' needs range,bearing detections and a 'heading' column")
    return names, ("ping" if "ping" in has else "time"), frame


def load_sonar_recording(path, dt: float = 1.0, sensor: Sequence[float] = (0.0, 0.0),
                         pings: int | None = None) -> SonarRecording:
    """Load a sonar CSV file (format in the module docstring): the detections and the own ship's track.

    Parameters
    ----------
    path : str or Path
        The file name.
    dt : float
        Time between pings for a ``ping`` column (scan times ``ping * dt``).
    sensor : sequence of float
        Sensor position for ``range, bearing`` rows of a file without own-ship columns.
    pings : int or None
        Number of pings to return (``ping`` files only); default ``max(ping) + 1``.

    Shapes
    ------
    ``scans``: ``z (1, T, M, 2)`` Cartesian, ``valid (1, T, M)``, ``snr (1, T, M)`` (NaN without ``level``),
    ``cov (1, T, M, 2, 2)`` where the file gives accuracies, ``times (T,)``; no ``origin``.  ``own_ship``:
    ``position (T, 2)``, ``heading_deg (T,)``.
    """
    path = Path(path)
    if not dt > 0:
        raise InputError(f"load_sonar_csv: dt must be > 0, got {dt}")
    lines = _read_text(path).splitlines()
    reference = _bearing_reference(path, lines)
    names: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    for lineno, raw in enumerate(lines, start=1):
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        if names is None:
            names, key, frame = _header(path, lineno, raw, reference)
            continue
        fields = [f.strip() for f in next(csv.reader([raw]))]
        if len(fields) != len(names):
            raise InputError(f"{_where(path, lineno)}: expected {len(names)} fields ({','.join(names)}), "
                             f"got {len(fields)}")
        rows.append((lineno, fields))
    if names is None:
        raise InputError(f"{path}: no header line (expected e.g. 'ping,x,y,level')")
    col = {name: i for i, name in enumerate(names)}
    own = "own_x" in col
    accuracy = ("sigma_x" in col) or ("sigma_range" in col)
    if own and tuple(float(s) for s in sensor) != (0.0, 0.0):
        raise InputError(f"{path}: the file gives the own ship's position per ping; sensor= applies to files "
                         f"without it")
    det_cols = [c for c in DETECTION_COLUMNS if c in col]
    when, line_of, pos, level, covs, det_row, bearings = [], [], [], [], [], [], []
    ship: dict[float, tuple[int, tuple[float, ...]]] = {}
    for lineno, fields in rows:
        raw_key = fields[col[key]]
        k = finite_number(raw_key, _where(path, lineno, key))
        if key == "ping" and (k < 0 or k != int(k)):
            raise InputError(f"{_where(path, lineno, 'ping')}: expected an integer >= 0, got {raw_key!r}")
        if own:
            values = tuple(finite_number(fields[col[c]], _where(path, lineno, c)) for c in OWN_SHIP_COLUMNS
                           if c in col)
            if len(values) > 2 and abs(values[2]) > MAX_ANGLE_DEG:
                raise InputError(f"{_where(path, lineno, 'heading')}: a heading in degrees lies within "
                                 f"+-{MAX_ANGLE_DEG:g}, got {fields[col['heading']]!r}")
            first = ship.setdefault(k, (lineno, values))
            if first[1] != values:
                raise InputError(f"{_where(path, lineno)}: the own ship's position or heading of {key} {raw_key} "
                                 f"differs from line {first[0]} (every row of a ping gives the same values)")
        empty = [c for c in det_cols if fields[col[c]] == ""]
        if len(empty) == len(det_cols):
            when.append(k)
            line_of.append(lineno)
            det_row.append(False)
            continue  # a ping without detections
        if empty:
            raise InputError(f"{_where(path, lineno, empty[0])}: empty field in a detection row")
        value = {c: finite_number(fields[col[c]], _where(path, lineno, c)) for c in det_cols}
        for c in ("sigma_x", "sigma_y", "sigma_range", "sigma_bearing"):
            if c in value and not value[c] > 0:
                raise InputError(f"{_where(path, lineno, c)}: an accuracy is a standard deviation > 0, got "
                                 f"{fields[col[c]]!r}")
        if "bearing" in value and abs(value["bearing"]) > MAX_ANGLE_DEG:
            raise InputError(f"{_where(path, lineno, 'bearing')}: a bearing in degrees lies within "
                             f"+-{MAX_ANGLE_DEG:g}, got {fields[col['bearing']]!r}")
        if "sigma_bearing" in value and not value["sigma_bearing"] < MAX_SIGMA_BEARING_DEG:
            raise InputError(f"{_where(path, lineno, 'sigma_bearing')}: a bearing accuracy in degrees must be below "
                             f"{MAX_SIGMA_BEARING_DEG:g} (wider leaves no bearing), got "
                             f"{fields[col['sigma_bearing']]!r}")
        if "bearing" in value:
            bearings.append((lineno, value["bearing"]))
        cov = None
        if frame == "polar":
            if value["range"] < 0:
                raise InputError(f"{_where(path, lineno, 'range')}: expected a range >= 0, got "
                                 f"{fields[col['range']]!r}")
            origin = values[:2] if own else sensor
            b = math.radians(value["bearing"] + (values[2] if reference == "relative" else 0.0))
            r = value["range"]
            # x = sx + r cos(b), y = sy + r sin(b)   (math convention)
            pos.append((origin[0] + r * math.cos(b), origin[1] + r * math.sin(b)))
            if accuracy:
                if r == 0:
                    raise InputError(f"{_where(path, lineno, 'range')}: a detection at range 0 has no x-y accuracy "
                                     f"(its bearing is undefined)")
                # C = J diag(sr^2, sb^2) J^T,  J = [[cos b, -r sin b], [sin b, r cos b]]
                J = np.array([[math.cos(b), -r * math.sin(b)], [math.sin(b), r * math.cos(b)]])
                cov = J @ np.diag([value["sigma_range"] ** 2, math.radians(value["sigma_bearing"]) ** 2]) @ J.T
        else:
            pos.append((value["x"], value["y"]))
            if accuracy:
                cov = np.diag([value["sigma_x"] ** 2, value["sigma_y"] ** 2])
        when.append(k)
        line_of.append(lineno)
        det_row.append(True)
        level.append(value.get("level", np.nan))
        covs.append(cov)
    when_a = np.asarray(when, dtype=float)
    det = np.asarray(det_row, dtype=bool)
    if key == "ping":
        index_all = when_a.astype(np.int64)
        T = int(index_all.max()) + 1 if when_a.size else 0
        distinct = np.unique(index_all).size
        if pings is not None:
            if pings < T:
                raise InputError(f"{path}: holds ping {T - 1} but pings={pings} was asked for")
            T = int(pings)
        elif T > MAX_EMPTY_PINGS and T > SPARSE_FACTOR * distinct:
            line = line_of[int(np.argmax(index_all))]
            raise InputError(f"{_where(path, line, 'ping')}: ping {T - 1} would make {T} pings of which only "
                             f"{distinct} have rows; a typo? (pass pings= to the loader to accept it)")
        times = np.arange(T) * float(dt)
        if own:
            absent = sorted(set(range(T)) - set(index_all.tolist()))
            if absent:
                raise InputError(f"{path}: ping {absent[0]} has no row, so no own-ship position (write "
                                 f"'{absent[0]},,...,<own_x>,<own_y>' for a ping without detections)")
    else:
        if pings is not None:
            raise InputError(f"{path}: pings= applies to files with a 'ping' column only")
        times, index_all = np.unique(when_a, return_inverse=True)
        T = times.size
    index = index_all[det]
    n = int(det.sum())
    counts = np.bincount(index, minlength=T) if n else np.zeros(T, dtype=int)
    M = int(counts.max()) if T and n else 0
    order = np.argsort(index, kind="stable")
    slot = np.arange(n) - np.repeat(np.cumsum(counts) - counts, counts)
    z = np.zeros((1, T, M, 2))
    valid = np.zeros((1, T, M), dtype=bool)
    snr = np.full((1, T, M), np.nan)
    ti = index[order]
    if n:
        z[0, ti, slot] = np.asarray(pos, dtype=float)[order]
        valid[0, ti, slot] = True
        snr[0, ti, slot] = np.asarray(level, dtype=float)[order]
    cov = None
    if accuracy:
        cov = np.broadcast_to(np.eye(2), (1, T, M, 2, 2)).copy()
        if n:
            cov[0, ti, slot] = np.stack(covs)[order]
    own_ship = None
    if own:
        keys = sorted(ship)
        table = np.array([ship[k][1] for k in keys], dtype=float)
        own_ship = OwnShip(times.copy(), table[:, :2].copy(), table[:, 2].copy() if table.shape[1] > 2 else None)
        _check_own_ship(path, own_ship, [ship[k][0] for k in keys])
    _check_bearings(path, bearings)
    return SonarRecording(Scans(z, valid, times, snr=snr, cov=cov), own_ship, reference, key, frame)


def _check_own_ship(path: Path, own: OwnShip, lines: list[int]) -> None:
    """Warnings, with the numbers, for an own ship faster than :data:`MAX_OWN_SHIP_SPEED` or whose heading does not
    follow its course over ground (:data:`HEADING_COURSE_LIMIT_DEG`)."""
    if own.times.size < 2:
        return
    step = np.diff(own.position, axis=0)
    dt = np.diff(own.times)
    speed = np.hypot(step[:, 0], step[:, 1]) / dt
    k = int(np.argmax(speed))
    if speed[k] > MAX_OWN_SHIP_SPEED:
        warnings.warn(f"{path} line {lines[k + 1]}: the own ship moves {np.hypot(*step[k]):.6g} in "
                      f"{dt[k]:.6g} time units (from line {lines[k]}), a speed of {speed[k]:.6g} (over "
                      f"{MAX_OWN_SHIP_SPEED:g} m/s, about 190 knots, for positions in metres and times in seconds): "
                      f"positions or times in another unit?", ImplausibleValueWarning, stacklevel=3)
    if own.heading_deg is None:
        return
    moving = np.flatnonzero(speed >= MIN_COURSE_SPEED)
    if moving.size < 3:
        return
    course = np.degrees(np.arctan2(step[moving, 1], step[moving, 0]))
    h = np.radians(own.heading_deg)
    # the heading over a leg: the circular mean of its two ends
    mean_heading = np.degrees(np.arctan2(np.sin(h[moving]) + np.sin(h[moving + 1]),
                                         np.cos(h[moving]) + np.cos(h[moving + 1])))
    off = np.abs((course - mean_heading + 180.0) % 360.0 - 180.0)
    median = float(np.median(off))
    if median > HEADING_COURSE_LIMIT_DEG:
        i = int(moving[np.argsort(off)[off.size // 2]])
        j = int(np.flatnonzero(moving == i)[0])
        warnings.warn(f"{path}: the own ship's heading differs from its course over ground (own_x, own_y) by a "
                      f"median of {median:.1f} degrees over {moving.size} legs (line {lines[i]}: heading "
                      f"{own.heading_deg[i]:g}, course {course[j]:.1f}); a compass heading? The format wants the "
                      f"mathematical convention (90 - compass heading)", ImplausibleValueWarning, stacklevel=3)


def _check_bearings(path: Path, bearings: list[tuple[int, float]]) -> None:
    """A warning when many bearings all lie within +-2 pi: radians where the format wants degrees?"""
    if len(bearings) < RADIAN_SUSPICION_COUNT:
        return
    largest = max(abs(b) for _, b in bearings)
    if largest <= 2 * math.pi:
        warnings.warn(f"{path}: all {len(bearings)} bearings lie within +-2 pi (largest |bearing| {largest:.4g}, "
                      f"line {max(bearings, key=lambda lb: abs(lb[1]))[0]}): radians? The format wants degrees",
                      ImplausibleValueWarning, stacklevel=3)


def load_sonar_csv(path, dt: float = 1.0, sensor: Sequence[float] = (0.0, 0.0), pings: int | None = None) -> Scans:
    """Load active-sonar detections from a CSV file as one run of :class:`Scans` (the detections of
    :func:`load_sonar_recording`; the parameters are its own).

    Shapes
    ------
    Returns ``z (1, T, M, 2)`` Cartesian, ``valid (1, T, M)``, ``snr (1, T, M)`` (NaN without ``level``),
    ``cov (1, T, M, 2, 2)`` where the file gives accuracies, ``times (T,)``; no ``origin``.
    """
    return load_sonar_recording(path, dt, sensor, pings).scans


def _polar_sigmas(C: np.ndarray, dx: float, dy: float, where: str) -> tuple[float, float]:
    """The range and bearing (degrees) standard deviations of an x-y covariance ``C`` of the polar form."""
    r = math.hypot(dx, dy)
    u = np.array([dx, dy]) / r
    v = np.array([-u[1], u[0]])
    srr, sbb, srb = float(u @ C @ u), float(v @ C @ v), float(u @ C @ v)
    if abs(srb) > 1e-9 * math.sqrt(srr * sbb):
        raise InputError(f"write_sonar_csv: {where}: the covariance is not of the polar form (range and bearing "
                         f"errors correlated); write frame='xy' or give it as J diag(sr^2, sb^2) J^T")
    return math.sqrt(srr), math.degrees(math.sqrt(sbb) / r)


def write_sonar_csv(path, scans: Scans, run: int = 0, frame: str = "xy", comments: Iterable[str] = (),
                    sensor: Sequence[float] = (0.0, 0.0), digits: int = 3, *, key: str = "ping",
                    own_ship: OwnShip | None = None, bearing: str = "true", accuracy: bool = False) -> Path:
    """Write the valid detections of run ``run`` in the sonar CSV format (``frame`` ``"xy"`` or ``"polar"``).

    ``comments`` become ``# ...`` lines at the top.  Levels are written when ``scans.snr`` is set and finite for
    every written detection.  ``key``: ``"ping"`` (ping numbers) or ``"time"`` (the scan times, for irregular
    pings).  ``own_ship`` adds its position (and heading) to every row, and the polar form is then measured from
    it (``bearing="relative"``: from the bow).  ``accuracy`` writes each detection's standard deviations from
    ``scans.cov`` (diagonal in x-y, or of the polar form for ``frame="polar"``).  Pings without detections get a
    row of empty detection fields where the file needs one (own ship, or a ``time`` key).
    """
    if frame not in ("xy", "polar"):
        raise InputError(f"write_sonar_csv: frame must be 'xy' or 'polar', got {frame!r}")
    if key not in ("ping", "time"):
        raise InputError(f"write_sonar_csv: key must be 'ping' or 'time', got {key!r}")
    if bearing not in BEARING_REFERENCES:
        raise InputError(f"write_sonar_csv: bearing must be one of {BEARING_REFERENCES}, got {bearing!r}")
    if bearing == "relative" and (frame != "polar" or own_ship is None or own_ship.heading_deg is None):
        raise InputError("write_sonar_csv: relative bearings need frame='polar' and an own ship with a heading")
    if scans.z.shape[-1] != 2:
        raise InputError(f"write_sonar_csv: needs Cartesian (x, y) detections, got dimension {scans.z.shape[-1]}")
    if not 0 <= run < scans.batch:
        raise InputError(f"write_sonar_csv: run {run} is not in the batch of {scans.batch}")
    if accuracy and scans.cov is None:
        raise InputError("write_sonar_csv: accuracy=True needs the detections' covariances (scans.cov)")
    if own_ship is not None and np.asarray(own_ship.position).shape != (scans.steps, 2):
        raise InputError(f"write_sonar_csv: the own ship needs a position per ping, (T, 2) = ({scans.steps}, 2), "
                         f"got {np.asarray(own_ship.position).shape}")
    path = Path(path)
    with_level = scans.snr is not None and bool(np.all(np.isfinite(scans.snr[run][scans.valid[run]])))
    cols = [key] + (["x", "y"] if frame == "xy" else ["range", "bearing"]) + (["level"] if with_level else [])
    if accuracy:
        cols += ["sigma_x", "sigma_y"] if frame == "xy" else ["sigma_range", "sigma_bearing"]
    heading = None if own_ship is None else own_ship.heading_deg
    if own_ship is not None:
        cols += ["own_x", "own_y"] + ([] if heading is None else ["heading"])
    lines = [f"# {c}" for c in comments]
    if bearing == "relative":
        lines.append("#! bearing: relative")
    lines.append(",".join(cols))
    fmt = f"{{:.{digits}f}}"
    empty_rows = own_ship is not None or key == "time"
    for k in range(scans.steps):
        stamp = str(k) if key == "ping" else repr(float(scans.times[k]))
        ship = [] if own_ship is None else [repr(float(v)) for v in own_ship.position[k]] + \
            ([] if heading is None else [repr(float(heading[k]))])
        origin = sensor if own_ship is None else own_ship.position[k]
        detections = np.flatnonzero(scans.valid[run, k])
        if detections.size == 0 and empty_rows:
            lines.append(",".join([stamp] + [""] * (len(cols) - 1 - len(ship)) + ship))
        for j in detections:
            x, y = scans.z[run, k, j]
            dx, dy = x - origin[0], y - origin[1]
            if frame == "xy":
                a, b = x, y
            else:
                a, b = math.hypot(dx, dy), math.degrees(math.atan2(dy, dx))
                if bearing == "relative":
                    b = (b - float(heading[k]) + 180.0) % 360.0 - 180.0
            fields = [stamp, fmt.format(a), fmt.format(b)]
            if with_level:
                fields.append(fmt.format(scans.snr[run, k, j]))
            if accuracy:
                C = scans.cov[run, k, j]
                if frame == "xy":
                    if abs(C[0, 1]) > 1e-9 * math.sqrt(C[0, 0] * C[1, 1]):
                        raise InputError(f"write_sonar_csv: ping {k}: a detection's covariance is not diagonal in "
                                         f"x, y; the format stores one standard deviation per axis")
                    sig = (math.sqrt(C[0, 0]), math.sqrt(C[1, 1]))
                else:
                    sig = _polar_sigmas(C, dx, dy, f"ping {k}")
                fields += [f"{float(s):.6g}" for s in sig]
            lines.append(",".join(fields + ship))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
