"""Recorded passive-radar candidates: per-frame (bistatic range, Doppler or range-rate, strength) lists in CSV.

Format (documented in ``docs/recorded-data.md``, section "Passive radar candidates")::

    # comment lines start with '#', anywhere in the file
    frame,time_s,bistatic_range_m,doppler_hz,strength_db
    0,0.0,445.1,15.30,18.2
    0,0.0,1203.5,-30.10,10.1
    1,0.5,,,                      <- a frame without candidates

- ``frame``: integer >= 0; frames are numbered 0..T-1 and every frame appears on at least one row (a frame
  without candidates on a row whose other candidate fields are empty);
- ``time_s``: the frame's time (s), equal on every row of a frame and increasing from frame to frame;
- ``bistatic_range_m``: excess path ``|p - Tx| + |p - Rx| - |Tx - Rx|`` (m), >= 0;
- ``doppler_hz`` and/or ``range_rate_mps``: at least one; ``Rdot = -lambda f_D`` (positive Doppler =
  approaching); with both, they must agree within 0.01 m/s;
- ``strength_db``: optional candidate strength (dB); NaN when absent.

The loader returns :class:`~workbench.types.Scans` with ``z (1, T, M, 2) = [R, Rdot]``, ``doppler`` (Hz),
``snr`` (strength) and no ``origin`` (recorded data has no truth).  Any malformed row raises
:class:`~workbench.types.InputError` naming the file, the 1-based line and the column.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Iterable

import numpy as np

from ..sensing.bistatic import doppler_to_range_rate, range_rate_to_doppler, wavelength
from .sonar import finite_number
from ..types import InputError, Scans

__all__ = ["COLUMNS", "load_pcl_candidates", "write_pcl_candidates"]

#: column -> required?  (doppler_hz / range_rate_mps: at least one of the two)
COLUMNS = {"frame": True, "time_s": True, "bistatic_range_m": True, "doppler_hz": False, "range_rate_mps": False,
           "strength_db": False}
CANDIDATE_FIELDS = ("bistatic_range_m", "doppler_hz", "range_rate_mps", "strength_db")
AGREE_MPS = 0.01


def _where(path, line: int, column: str | None = None) -> str:
    return f"{path} line {line}" + (f", column '{column}'" if column else "")


def _number(raw: str, path, line: int, column: str) -> float:
    return finite_number(raw, _where(path, line, column))


def load_pcl_candidates(path, frequency_hz: float = 701e6) -> Scans:
    """Read a candidate CSV (format in the module docstring) into one-run :class:`Scans`.

    Parameters
    ----------
    path : the CSV file.
    frequency_hz : carrier frequency used to convert between Doppler and range-rate (default 701 MHz).

    Shapes
    ------
    z : (1, T, M, 2) with ``[R, Rdot]``; valid, snr, doppler : (1, T, M); times : (T,)
    """
    path = Path(path)
    lam = wavelength(frequency_hz)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the candidate file ({exc.strerror or exc})") from None
    rows = [(i + 1, line) for i, line in enumerate(text.splitlines())
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{path}: no header line (expected columns {', '.join(COLUMNS)})")
    head_line, head_text = rows[0]
    header = [h.strip().lower() for h in next(csv.reader([head_text]))]
    for name in header:
        if name not in COLUMNS:
            raise InputError(f"{_where(path, head_line)}: unknown column {name!r} (known: {', '.join(COLUMNS)})")
        if header.count(name) > 1:
            raise InputError(f"{_where(path, head_line)}: column {name!r} appears twice")
    missing = [c for c, req in COLUMNS.items() if req and c not in header]
    if missing:
        raise InputError(f"{_where(path, head_line)}: missing column(s) {missing}")
    if "doppler_hz" not in header and "range_rate_mps" not in header:
        raise InputError(f"{_where(path, head_line)}: need a 'doppler_hz' or a 'range_rate_mps' column")
    col = {name: i for i, name in enumerate(header)}

    frames: dict[int, dict] = {}
    for line, raw_line in rows[1:]:
        fields = [f.strip() for f in next(csv.reader([raw_line]))]
        if len(fields) != len(header):
            raise InputError(f"{_where(path, line)}: expected {len(header)} fields ({', '.join(header)}), "
                             f"got {len(fields)}")
        raw_frame = fields[col["frame"]]
        try:
            frame = int(raw_frame)
        except ValueError:
            raise InputError(f"{_where(path, line, 'frame')}: expected an integer >= 0, got {raw_frame!r}") from None
        if frame < 0:
            raise InputError(f"{_where(path, line, 'frame')}: expected an integer >= 0, got {raw_frame!r}")
        t = _number(fields[col["time_s"]], path, line, "time_s")
        entry = frames.setdefault(frame, {"time": t, "time_line": line, "cands": []})
        if t != entry["time"]:
            raise InputError(f"{_where(path, line, 'time_s')}: frame {frame} has time {entry['time']} on line "
                             f"{entry['time_line']} but {t} here")
        present = [c for c in CANDIDATE_FIELDS if c in col and fields[col[c]] != ""]
        if not present:
            continue  # a frame without candidates
        if fields[col["bistatic_range_m"]] == "":
            raise InputError(f"{_where(path, line, 'bistatic_range_m')}: empty field in a candidate row")
        value = {c: _number(fields[col[c]], path, line, c) for c in present}
        if value["bistatic_range_m"] < 0:
            raise InputError(f"{_where(path, line, 'bistatic_range_m')}: the bistatic range must be >= 0, got "
                             f"{fields[col['bistatic_range_m']]!r}")
        if "doppler_hz" not in value and "range_rate_mps" not in value:
            rate = "doppler_hz" if "doppler_hz" in col else "range_rate_mps"
            raise InputError(f"{_where(path, line, rate)}: empty field in a candidate row")
        if "doppler_hz" in value and "range_rate_mps" in value:
            implied = float(doppler_to_range_rate(value["doppler_hz"], lam))
            if abs(implied - value["range_rate_mps"]) > AGREE_MPS:
                raise InputError(f"{_where(path, line, 'range_rate_mps')}: {value['range_rate_mps']} m/s disagrees with "
                                 f"doppler_hz {value['doppler_hz']} (-lambda f_D = {implied:.4f} m/s at "
                                 f"{frequency_hz / 1e6:g} MHz)")
        rdot = value["range_rate_mps"] if "range_rate_mps" in value else float(doppler_to_range_rate(value["doppler_hz"], lam))
        dop = value["doppler_hz"] if "doppler_hz" in value else float(range_rate_to_doppler(rdot, lam))
        entry["cands"].append((value["bistatic_range_m"], rdot, dop, value.get("strength_db", np.nan)))
    if not frames:
        raise InputError(f"{path}: the file has a header but no rows")
    T = max(frames) + 1
    absent = [k for k in range(T) if k not in frames]
    if absent:
        raise InputError(f"{path}: frame {absent[0]} has no row (frames are numbered 0..{T - 1}; write "
                         f"'{absent[0]},<time_s>,,,' for a frame without candidates)")
    times = np.array([frames[k]["time"] for k in range(T)])
    for k in range(1, T):
        if not times[k] > times[k - 1]:
            raise InputError(f"{_where(path, frames[k]['time_line'], 'time_s')}: frame {k} time {times[k]} is not "
                             f"after frame {k - 1}'s {times[k - 1]}")
    M = max(len(frames[k]["cands"]) for k in range(T))
    z = np.zeros((1, T, M, 2))
    valid = np.zeros((1, T, M), dtype=bool)
    snr = np.full((1, T, M), np.nan)
    dop = np.full((1, T, M), np.nan)
    for k in range(T):
        c = np.array(frames[k]["cands"], dtype=float).reshape(-1, 4)
        m = c.shape[0]
        z[0, k, :m] = c[:, :2]
        dop[0, k, :m], snr[0, k, :m] = c[:, 2], c[:, 3]
        valid[0, k, :m] = True
    return Scans(z, valid, times, snr=snr, doppler=dop)


def write_pcl_candidates(path, scans: Scans, run: int = 0, *, comments: Iterable[str] = (),
                         frequency_hz: float = 701e6, columns: str = "doppler") -> Path:
    """Write the valid candidates of one run of ``scans`` (``z = [R, Rdot]``) in the CSV format.

    ``columns``: ``"doppler"`` (``doppler_hz``), ``"range_rate"`` (``range_rate_mps``) or ``"both"``.
    ``comments`` become ``#`` lines at the top (label synthetic data as such).
    """
    if columns not in ("doppler", "range_rate", "both"):
        raise InputError(f"write_pcl_candidates: columns must be 'doppler', 'range_rate' or 'both', got {columns!r}")
    lam = wavelength(frequency_hz)
    path = Path(path)
    head = ["frame", "time_s", "bistatic_range_m"]
    head += {"doppler": ["doppler_hz"], "range_rate": ["range_rate_mps"], "both": ["doppler_hz", "range_rate_mps"]}[columns]
    head += ["strength_db"]
    with open(path, "w", newline="") as fh:
        for c in comments:
            fh.write(f"# {c}\n")
        writer = csv.writer(fh)
        writer.writerow(head)
        for k in range(scans.steps):
            rows = np.flatnonzero(scans.valid[run, k])
            t = f"{scans.times[k]:.6g}"
            if rows.size == 0:
                writer.writerow([k, t] + [""] * (len(head) - 2))
                continue
            for j in rows:
                r, rdot = scans.z[run, k, j]
                fd = float(range_rate_to_doppler(rdot, lam))
                strength = "" if scans.snr is None or not np.isfinite(scans.snr[run, k, j]) else \
                    f"{scans.snr[run, k, j]:.2f}"
                vals = {"doppler": [f"{fd:.4f}"], "range_rate": [f"{rdot:.4f}"],
                        "both": [f"{fd:.4f}", f"{float(doppler_to_range_rate(round(fd, 4), lam)):.4f}"]}[columns]
                writer.writerow([k, t, f"{r:.3f}"] + vals + [strength])
    return path
