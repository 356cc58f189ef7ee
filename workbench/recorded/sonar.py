"""Recorded active-sonar detections: a validated CSV loader and a writer (format: docs/recorded-data.md).

::

    # comment lines start with '#'
    ping,x,y,level                  (or time instead of ping; range,bearing instead of x,y)
    0,123.4,56.7,9.8

- ``ping``: integer >= 0 (pings numbered from 0; a ping without rows is an empty scan), or ``time``:
  finite number (rows with equal times form one ping).
- ``x, y``: Cartesian position; or ``range >= 0`` and ``bearing`` in **degrees, math convention**
  (counter-clockwise from +x): ``x = sx + range cos(bearing)``, ``y = sy + range sin(bearing)``.
- ``level``: optional, dB (``Scans.snr``).

:func:`load_sonar_csv` returns :class:`~workbench.types.Scans` with Cartesian ``z (1, T, M, 2)``; any
malformed content raises :class:`~workbench.types.InputError` naming the file, the line and the column.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..types import InputError, Scans

__all__ = ["SONAR_COLUMNS", "load_sonar_csv", "write_sonar_csv"]

#: Every column name the sonar format knows.
SONAR_COLUMNS = ("ping", "time", "x", "y", "range", "bearing", "level")


def _header(path: Path, lineno: int, line: str) -> tuple[list[str], str, str]:
    names = [c.strip().lower() for c in line.split(",")]
    for i, name in enumerate(names):
        if name not in SONAR_COLUMNS:
            raise InputError(f"{path} line {lineno}: unknown column {name!r} (column {i + 1}); "
                             f"expected names from {', '.join(SONAR_COLUMNS)}")
        if names.count(name) > 1:
            raise InputError(f"{path} line {lineno}: column {name!r} appears more than once")
    has = set(names)
    if ("ping" in has) == ("time" in has):
        raise InputError(f"{path} line {lineno}: the header needs exactly one of 'ping' or 'time', got {names}")
    cart, polar = {"x", "y"} & has, {"range", "bearing"} & has
    if cart and polar:
        raise InputError(f"{path} line {lineno}: give either x,y or range,bearing, not both (got {names})")
    if cart != {"x", "y"} and polar != {"range", "bearing"}:
        raise InputError(f"{path} line {lineno}: the header needs both 'x' and 'y', or both 'range' and 'bearing' "
                         f"(got {names})")
    return names, ("ping" if "ping" in has else "time"), ("xy" if cart else "polar")


def finite_number(text: str, where: str) -> float:
    """Parse one CSV field as a finite float; ``where`` (file, line, column) goes into the error."""
    text = text.strip()
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: expected a finite number, got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {text!r}")
    return value


def _number(path: Path, lineno: int, column: str, text: str) -> float:
    return finite_number(text, f"{path} line {lineno}, column {column!r}")


def load_sonar_csv(path, dt: float = 1.0, sensor: Sequence[float] = (0.0, 0.0), pings: int | None = None) -> Scans:
    """Load active-sonar detections from a CSV file as one run of :class:`Scans`.

    Parameters
    ----------
    path : file name.
    dt : time between pings for a ``ping`` column (scan times ``ping * dt``).
    sensor : sensor position for ``range, bearing`` rows.
    pings : number of pings to return (``ping`` files only); default ``max(ping) + 1``.

    Shapes
    ------
    Returns ``z (1, T, M, 2)`` Cartesian, ``valid (1, T, M)``, ``snr (1, T, M)`` (NaN without ``level``),
    ``times (T,)``; no ``origin``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if not dt > 0:
        raise InputError(f"load_sonar_csv: dt must be > 0, got {dt}")
    names: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    with path.open("r", encoding="utf-8") as fh:
        for lineno, raw in enumerate(fh, start=1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            if names is None:
                names, key, frame = _header(path, lineno, line)
                continue
            fields = line.split(",")
            if len(fields) != len(names):
                raise InputError(f"{path} line {lineno}: expected {len(names)} fields ({','.join(names)}), "
                                 f"got {len(fields)}")
            rows.append((lineno, fields))
    if names is None:
        raise InputError(f"{path}: no header line (expected e.g. 'ping,x,y,level')")
    col = {name: i for i, name in enumerate(names)}
    n = len(rows)
    when = np.empty(n)
    pos = np.empty((n, 2))
    level = np.full(n, np.nan)
    for r, (lineno, fields) in enumerate(rows):
        value = {name: _number(path, lineno, name, fields[i]) for name, i in col.items()}
        if key == "ping":
            p = value["ping"]
            if p < 0 or p != int(p):
                raise InputError(f"{path} line {lineno}, column 'ping': expected an integer >= 0, "
                                 f"got {fields[col['ping']].strip()!r}")
        if frame == "polar":
            if value["range"] < 0:
                raise InputError(f"{path} line {lineno}, column 'range': expected a range >= 0, "
                                 f"got {fields[col['range']].strip()!r}")
            b = math.radians(value["bearing"])
            # x = sx + r cos(b), y = sy + r sin(b)   (math convention)
            pos[r] = (sensor[0] + value["range"] * math.cos(b), sensor[1] + value["range"] * math.sin(b))
        else:
            pos[r] = (value["x"], value["y"])
        when[r] = value[key]
        if "level" in value:
            level[r] = value["level"]
    if key == "ping":
        index = when.astype(np.int64)
        T = int(index.max()) + 1 if n else 0
        if pings is not None:
            if pings < T:
                raise InputError(f"{path}: holds ping {T - 1} but pings={pings} was asked for")
            T = int(pings)
        times = np.arange(T) * float(dt)
    else:
        if pings is not None:
            raise InputError(f"{path}: pings= applies to files with a 'ping' column only")
        times, index = np.unique(when, return_inverse=True)
        T = times.size
    counts = np.bincount(index, minlength=T) if n else np.zeros(T, dtype=int)
    M = int(counts.max()) if T else 0
    order = np.argsort(index, kind="stable")
    slot = np.arange(n) - np.repeat(np.cumsum(counts) - counts, counts)
    z = np.zeros((1, T, M, 2))
    valid = np.zeros((1, T, M), dtype=bool)
    snr = np.full((1, T, M), np.nan)
    ti, si = index[order], slot
    z[0, ti, si] = pos[order]
    valid[0, ti, si] = True
    snr[0, ti, si] = level[order]
    return Scans(z, valid, times, snr=snr)


def write_sonar_csv(path, scans: Scans, run: int = 0, frame: str = "xy", comments: Iterable[str] = (),
                    sensor: Sequence[float] = (0.0, 0.0), digits: int = 3) -> Path:
    """Write the valid detections of run ``run`` in the sonar CSV format (``frame`` ``"xy"`` or ``"polar"``).

    ``comments`` become ``# ...`` lines at the top.  Levels are written when ``scans.snr`` is set and
    finite for every written detection.
    """
    if frame not in ("xy", "polar"):
        raise InputError(f"write_sonar_csv: frame must be 'xy' or 'polar', got {frame!r}")
    if scans.z.shape[-1] != 2:
        raise InputError(f"write_sonar_csv: needs Cartesian (x, y) detections, got dimension {scans.z.shape[-1]}")
    if not 0 <= run < scans.batch:
        raise InputError(f"write_sonar_csv: run {run} is not in the batch of {scans.batch}")
    path = Path(path)
    with_level = scans.snr is not None and bool(np.all(np.isfinite(scans.snr[run][scans.valid[run]])))
    cols = ["ping"] + (["x", "y"] if frame == "xy" else ["range", "bearing"]) + (["level"] if with_level else [])
    lines = [f"# {c}" for c in comments] + [",".join(cols)]
    fmt = f"{{:.{digits}f}}"
    for k in range(scans.steps):
        for j in np.flatnonzero(scans.valid[run, k]):
            x, y = scans.z[run, k, j]
            if frame == "xy":
                a, b = x, y
            else:
                dx, dy = x - sensor[0], y - sensor[1]
                a, b = math.hypot(dx, dy), math.degrees(math.atan2(dy, dx))
            fields = [str(k), fmt.format(a), fmt.format(b)]
            if with_level:
                fields.append(fmt.format(scans.snr[run, k, j]))
            lines.append(",".join(fields))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
