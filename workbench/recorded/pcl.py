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
- ``strength_db``: optional candidate strength (dB); NaN when absent;
- ``sigma_range_m`` and ``sigma_range_rate_mps``: optional, together, each candidate's own accuracy (standard
  deviations); they become the candidates' covariances ``Scans.cov = diag(sigma_R^2, sigma_Rdot^2)``.

Metadata lines (comments that start with ``#!``) declare the geometry and the carrier::

    #! carrier_hz: 701e6
    #! transmitter_m: 0, -8400, 420
    #! receiver_m: 0, 0, 60

The carrier converts between Doppler and range-rate (an explicit ``frequency_hz`` argument must agree with it);
:func:`pcl_metadata` reads the three.  A carrier outside :data:`CARRIER_RANGE_HZ` (1 MHz .. 100 GHz) is refused
as a unit slip, with the numbers.

The loader returns :class:`~workbench.types.Scans` with ``z (1, T, M, 2) = [R, Rdot]``, ``doppler`` (Hz),
``snr`` (strength), ``cov`` where the file gives accuracies, and no ``origin`` (recorded data has no truth).  Any
malformed row raises :class:`~workbench.types.InputError` naming the file, the 1-based line and the column.  A
UTF-8 byte-order mark is accepted.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np

from ..sensing.bistatic import doppler_to_range_rate, range_rate_to_doppler, wavelength
from ..textfields import finite_number, read_text
from ..types import InputError, Scans

__all__ = ["COLUMNS", "CARRIER_RANGE_HZ", "check_carrier", "PCLMetadata", "pcl_metadata", "load_pcl_candidates",
           "write_pcl_candidates"]

#: column -> required?  (doppler_hz / range_rate_mps: at least one of the two)
COLUMNS = {"frame": True, "time_s": True, "bistatic_range_m": True, "doppler_hz": False, "range_rate_mps": False,
           "strength_db": False, "sigma_range_m": False, "sigma_range_rate_mps": False}
CANDIDATE_FIELDS = ("bistatic_range_m", "doppler_hz", "range_rate_mps", "strength_db", "sigma_range_m",
                    "sigma_range_rate_mps")
AGREE_MPS = 0.01
#: The carrier assumed when neither the file nor the caller gives one (Hz).
DEFAULT_CARRIER_HZ = 701e6
#: The carriers a passive radar's illuminator can have (Hz): from HF broadcasting (a few MHz) through FM, DAB,
#: DVB-T and mobile networks to satellite TV (about 12 GHz), with a margin; a carrier outside is a unit slip
#: (701 given for 701 MHz is off by 10^6) and is refused.
CARRIER_RANGE_HZ = (1e6, 1e11)


def check_carrier(value: float, where: str) -> float:
    """``value`` (Hz) if it is a plausible illuminator carrier (:data:`CARRIER_RANGE_HZ`), else a named error
    with the numbers and the likely slip."""
    lo, hi = CARRIER_RANGE_HZ
    if lo <= value <= hi:
        return value
    hint = ""
    for factor, unit in ((1e6, "MHz"), (1e3, "kHz"), (1e9, "GHz")):
        if lo <= value * factor <= hi:
            hint = f"; given in {unit}? {value:g} {unit} is {value * factor:g} Hz"
            break
    else:
        for factor, unit in ((1e6, "micro"), (1e3, "milli")):
            if lo <= value / factor <= hi:
                hint = f"; off by a factor {factor:g}? {value / factor:g} Hz would be plausible"
                break
    raise InputError(f"{where}: carrier {value:g} Hz is not a passive-radar illuminator's carrier (expected "
                     f"{lo:g} .. {hi:g} Hz, e.g. 701e6 for a 701 MHz DTV channel){hint}")


@dataclass(frozen=True)
class PCLMetadata:
    """What a candidate file declares about its geometry: the carrier (Hz) and the transmitter's and receiver's
    positions (m), each ``None`` where the file is silent."""

    carrier_hz: float | None = None
    transmitter_m: tuple[float, ...] | None = None
    receiver_m: tuple[float, ...] | None = None


def _read_text(path: Path) -> str:
    return read_text(path, "candidate file")


def _metadata(path: Path, text: str) -> PCLMetadata:
    values: dict = {}
    for i, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped.startswith("#!"):
            continue
        key, sep, raw = stripped[2:].partition(":")
        key = key.strip().lower()
        where = f"{path} line {i}"
        if not sep or key not in ("carrier_hz", "transmitter_m", "receiver_m"):
            raise InputError(f"{where}: a '#!' line declares 'carrier_hz: ...', 'transmitter_m: x, y, z' or "
                             f"'receiver_m: x, y, z', got {stripped!r}")
        if key in values:
            raise InputError(f"{where}: {key} is declared twice")
        numbers = [finite_number(v.strip(), f"{where}, {key}") for v in raw.split(",")]
        if key == "carrier_hz":
            if len(numbers) != 1 or not numbers[0] > 0:
                raise InputError(f"{where}: carrier_hz must be one number > 0, got {raw.strip()!r}")
            values[key] = check_carrier(numbers[0], f"{where}, carrier_hz")
        else:
            if len(numbers) not in (2, 3):
                raise InputError(f"{where}: {key} must be 2 or 3 coordinates, got {raw.strip()!r}")
            values[key] = tuple(numbers)
    return PCLMetadata(**values)


def pcl_metadata(path) -> PCLMetadata:
    """The carrier and geometry a candidate file declares in its ``#!`` lines."""
    path = Path(path)
    return _metadata(path, _read_text(path))


def _where(path, line: int, column: str | None = None) -> str:
    return f"{path} line {line}" + (f", column '{column}'" if column else "")


def _number(raw: str, path, line: int, column: str) -> float:
    return finite_number(raw, _where(path, line, column))


def load_pcl_candidates(path, frequency_hz: float | None = None) -> Scans:
    """Read a candidate CSV (format in the module docstring) into one-run :class:`Scans`.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    frequency_hz : float or None
        Carrier frequency used to convert between Doppler and range-rate; default: the file's ``#! carrier_hz``
        line, else 701 MHz.  Given both, they must agree.

    Shapes
    ------
    z : (1, T, M, 2) with ``[R, Rdot]``; valid, snr, doppler : (1, T, M); times : (T,)
    """
    path = Path(path)
    text = _read_text(path)
    meta = _metadata(path, text)
    if frequency_hz is not None:
        check_carrier(float(frequency_hz), f"load_pcl_candidates({path}): frequency_hz")
    if frequency_hz is not None and meta.carrier_hz is not None and abs(frequency_hz - meta.carrier_hz) > 1e-9 * \
            meta.carrier_hz:
        raise InputError(f"{path}: the file declares carrier_hz {meta.carrier_hz:g}, but {frequency_hz:g} Hz was asked for")
    frequency_hz = frequency_hz or meta.carrier_hz or DEFAULT_CARRIER_HZ
    lam = wavelength(frequency_hz)
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
    accuracy = ("sigma_range_m" in header, "sigma_range_rate_mps" in header)
    if accuracy[0] != accuracy[1]:
        raise InputError(f"{_where(path, head_line)}: give both 'sigma_range_m' and 'sigma_range_rate_mps', or neither")
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
        sig = (np.nan, np.nan)
        if accuracy[0]:
            for c in ("sigma_range_m", "sigma_range_rate_mps"):
                if c not in value or not value[c] > 0:
                    raise InputError(f"{_where(path, line, c)}: each candidate needs its accuracy, a number > 0, got "
                                     f"{fields[col[c]]!r}")
            sig = (value["sigma_range_m"], value["sigma_range_rate_mps"])
        entry["cands"].append((value["bistatic_range_m"], rdot, dop, value.get("strength_db", np.nan)) + sig)
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
    cov = np.broadcast_to(np.eye(2), (1, T, M, 2, 2)).copy() if accuracy[0] else None
    for k in range(T):
        c = np.array(frames[k]["cands"], dtype=float).reshape(-1, 6)
        m = c.shape[0]
        z[0, k, :m] = c[:, :2]
        dop[0, k, :m], snr[0, k, :m] = c[:, 2], c[:, 3]
        valid[0, k, :m] = True
        if cov is not None:
            cov[0, k, :m, 0, 0], cov[0, k, :m, 1, 1] = c[:, 4] ** 2, c[:, 5] ** 2
    return Scans(z, valid, times, snr=snr, doppler=dop, cov=cov)


def write_pcl_candidates(path, scans: Scans, run: int = 0, *, comments: Iterable[str] = (),
                         frequency_hz: float = DEFAULT_CARRIER_HZ, columns: str = "doppler",
                         transmitter_m=None, receiver_m=None) -> Path:
    """Write the valid candidates of one run of ``scans`` (``z = [R, Rdot]``) in the CSV format.

    ``columns``: ``"doppler"`` (``doppler_hz``), ``"range_rate"`` (``range_rate_mps``) or ``"both"``.
    ``comments`` become ``#`` lines at the top (label synthetic data as such); the carrier and, when given, the
    transmitter's and receiver's positions become ``#!`` metadata lines; candidates' covariances (``scans.cov``)
    become the accuracy columns.
    """
    if columns not in ("doppler", "range_rate", "both"):
        raise InputError(f"write_pcl_candidates: columns must be 'doppler', 'range_rate' or 'both', got {columns!r}")
    check_carrier(float(frequency_hz), "write_pcl_candidates: frequency_hz")  # no file the reader would refuse
    lam = wavelength(frequency_hz)
    path = Path(path)
    head = ["frame", "time_s", "bistatic_range_m"]
    head += {"doppler": ["doppler_hz"], "range_rate": ["range_rate_mps"], "both": ["doppler_hz", "range_rate_mps"]}[columns]
    head += ["strength_db"]
    if scans.cov is not None:
        head += ["sigma_range_m", "sigma_range_rate_mps"]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        for c in comments:
            fh.write(f"# {c}\n")
        fh.write(f"#! carrier_hz: {frequency_hz!r}\n")
        for key, pos in (("transmitter_m", transmitter_m), ("receiver_m", receiver_m)):
            if pos is not None:
                fh.write(f"#! {key}: " + ", ".join(repr(float(v)) for v in pos) + "\n")
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
                acc = [] if scans.cov is None else [repr(float(np.sqrt(scans.cov[run, k, j, 0, 0]))),
                                                    repr(float(np.sqrt(scans.cov[run, k, j, 1, 1])))]
                writer.writerow([k, t, f"{r:.3f}"] + vals + [strength] + acc)
    return path
