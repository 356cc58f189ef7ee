"""Track files: a documented CSV of estimated tracks, one row per track per time (``docs/recorded-data.md``).

::

    # workbench track file
    # format: workbench-tracks 1
    # state: x [m], y [m], vx [m/s], vy [m/s]
    # covariance: upper triangle
    # runs: 2
    # steps: 50
    # note: any free text (the writer's ``notes``)
    run,track,step,time,status,updated,x,y,vx,vy,cov_x_x,cov_x_y,cov_x_vx,...,cov_vy_vy
    0,0,0,0.0,confirmed,1,101.25,-3.5,...

- ``run``: the Monte Carlo run (0 for a recorded file); ``track``: the track's id, unique within its run;
  ``step``: the scan index; ``time``: the scan's time in seconds.
- ``status``: ``tentative`` or ``confirmed`` (a single-target filter's track is ``confirmed`` at every step).
- ``updated``: ``1`` when the track was updated with a detection at this step, ``0`` when it coasted, empty when
  the writer did not know.
- the state components, named and with units in the ``state`` line; then, when the ``covariance`` line says
  ``upper triangle``, the covariance's upper triangle row by row, ``cov_a_b = Cov(a, b)`` (unit: unit of ``a``
  times unit of ``b``); ``covariance: none`` and no such columns when the writer had none.
- ``existence``, last, only where the header has the line ``# existence: column``: the track's probability of
  existence (JIPDA) or its Gaussian component's weight (GM-PHD, which may exceed 1), a finite number >= 0.
  Without the line (or with ``# existence: none``) there is no such column.

Numbers are written with Python's ``repr`` (the shortest text that reads back to the same double), so a file reads
back exactly.  The file is written and read with the standard :mod:`csv` module; :func:`read_tracks` refuses a
malformed file with a :class:`~workbench.types.InputError` naming the file, the line and the column, and checks
content as well as structure: one time per step, times that increase with the step, variances >= 0 and
positive semi-definite covariances (:func:`covariance_problems`; the writers refuse what it would refuse).

Writers: :func:`write_track_log` (a multi-target :class:`~workbench.tracking.TrackLog`), :func:`write_track` (a
single-target :class:`~workbench.tracking.Track`, mean and covariance per run and step) and :func:`write_tracks`
(a :class:`TrackFile`, what :func:`read_tracks` returns).
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from .models import MotionModel
from .tracking.loop import Track
from .tracking.multi import CONFIRMED, TENTATIVE, TrackLog
from .textfields import finite_number, read_text
from .types import InputError

__all__ = ["FORMAT", "VERSION", "PSD_TOLERANCE", "covariance_problems", "TrackFile", "state_layout", "write_tracks",
           "write_track_log", "write_track", "read_tracks"]

#: The format's name, on the ``format`` line of every track file.
FORMAT = "workbench-tracks"
#: The format version this module writes and reads.
VERSION = 1
#: The columns before the state components.
LEADING = ("run", "track", "step", "time", "status", "updated")
STATUS = {TENTATIVE: "tentative", CONFIRMED: "confirmed"}
_STATUS_CODE = {v: k for k, v in STATUS.items()}
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_COMPONENT = re.compile(r"^([A-Za-z][A-Za-z0-9_]*) \[([^\[\],]*)\]$")
#: A covariance is accepted as positive semi-definite when its correlation form (``D^-1/2 C D^-1/2``, ``D`` its
#: diagonal) has no eigenvalue below ``-PSD_TOLERANCE``: round-off of a filter's arithmetic passes, a sign error or
#: a correlation beyond +-1 does not.
PSD_TOLERANCE = 1e-8


def covariance_problems(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For covariances ``cov (R, n, n)`` (symmetric): ``(negative_variance (R,) bool, not_psd (R,) bool)``.

    ``not_psd`` is judged on the correlation form, so states whose components have very different scales (metres
    and metres per second) are held to the same relative tolerance :data:`PSD_TOLERANCE`.
    """
    cov = np.asarray(cov, dtype=float)
    R = cov.shape[0]
    if R == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
    var = np.diagonal(cov, axis1=1, axis2=2)
    negative = np.any(var < 0, axis=1)
    scale = np.sqrt(np.where(var > 0, var, 1.0))
    corr = cov / (scale[:, :, None] * scale[:, None, :])
    corr = 0.5 * (corr + np.swapaxes(corr, 1, 2))
    not_psd = np.linalg.eigvalsh(corr)[:, 0] < -PSD_TOLERANCE
    return negative, not_psd & ~negative


@dataclass(frozen=True)
class TrackFile:
    """The content of a track file: one row per track per step.

    Shapes
    ------
    run, track, step, status, updated : (R,) integers (``status``: :data:`~workbench.tracking.TENTATIVE` or
        :data:`~workbench.tracking.CONFIRMED`; ``updated``: 1, 0, or -1 where unknown)
    time : (R,) seconds
    mean : (R, n)
    cov : (R, n, n) or None
    existence : (R,) or None, each track's probability of existence or PHD weight (finite, >= 0)

    ``names`` and ``units`` name the ``n`` state components; ``runs`` and ``steps`` are the extent of the scan
    series the tracks came from (a step may hold no track); ``notes`` are free comment lines.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    runs: int
    steps: int
    run: np.ndarray
    track: np.ndarray
    step: np.ndarray
    time: np.ndarray
    status: np.ndarray
    updated: np.ndarray
    mean: np.ndarray
    cov: np.ndarray | None = None
    notes: tuple[str, ...] = field(default=())
    version: int = VERSION
    existence: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.names)
        if len(self.units) != n:
            raise InputError(f"TrackFile: {n} state names but {len(self.units)} units")
        for name in self.names:
            if not _NAME.match(name):
                raise InputError(f"TrackFile: state name {name!r} must be a letter followed by letters, digits or _")
        if len(set(self.names)) != n:
            raise InputError(f"TrackFile: state names repeat: {self.names}")
        for unit in self.units:
            if any(ch in unit for ch in "[],\n"):
                raise InputError(f"TrackFile: unit {unit!r} may not hold '[', ']', ',' or a line break")
        ints = {key: np.asarray(getattr(self, key), dtype=np.int64) for key in ("run", "track", "step", "status",
                                                                                 "updated")}
        R = ints["run"].shape[0]
        mean = np.asarray(self.mean, dtype=float).reshape(R, n) if R else np.zeros((0, n))
        time = np.asarray(self.time, dtype=float)
        for key, arr in (*ints.items(), ("time", time)):
            if arr.shape != (R,):
                raise InputError(f"TrackFile.{key} must have shape ({R},), got {arr.shape}")
        if R and (ints["run"].min() < 0 or ints["run"].max() >= self.runs):
            raise InputError(f"TrackFile: run numbers must lie in 0..{self.runs - 1}")
        if R and (ints["step"].min() < 0 or ints["step"].max() >= self.steps):
            raise InputError(f"TrackFile: steps must lie in 0..{self.steps - 1}")
        if R and ints["track"].min() < 0:
            raise InputError("TrackFile: track ids must be >= 0")
        if not np.all(np.isin(ints["status"], list(STATUS))):
            raise InputError(f"TrackFile: status must be {TENTATIVE} (tentative) or {CONFIRMED} (confirmed)")
        if not np.all(np.isin(ints["updated"], (-1, 0, 1))):
            raise InputError("TrackFile: updated must be 1, 0 or -1 (unknown)")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(time))):
            raise InputError("TrackFile: the states and times must be finite")
        cov = None
        if self.cov is not None:
            cov = np.asarray(self.cov, dtype=float)
            if cov.shape != (R, n, n):
                raise InputError(f"TrackFile.cov must have shape ({R}, {n}, {n}), got {cov.shape}")
            if not np.all(np.isfinite(cov)):
                raise InputError("TrackFile: the covariances must be finite")
        existence = None
        if self.existence is not None:
            existence = np.asarray(self.existence, dtype=float)
            if existence.shape != (R,):
                raise InputError(f"TrackFile.existence must have shape ({R},), one per row, got {existence.shape}")
            if not np.all(np.isfinite(existence)) or np.any(existence < 0):
                raise InputError("TrackFile: the existence values must be finite numbers >= 0")
        for key, arr in ints.items():
            object.__setattr__(self, key, arr)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "existence", existence)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "units", tuple(self.units))
        object.__setattr__(self, "notes", tuple(self.notes))

    @property
    def rows(self) -> int:
        return int(self.run.shape[0])

    def to_track_log(self) -> TrackLog:
        """The rows as a :class:`~workbench.tracking.TrackLog` (ordered by run, then step; ``updated`` becomes
        ``hit``, which must be known on every row), with the covariances and existence values where the file has
        them."""
        if np.any(self.updated < 0):
            raise InputError("a TrackLog needs to know whether every track was updated; the file leaves it open")
        order = np.lexsort((self.step, self.run))
        return TrackLog(self.run[order], self.step[order], self.track[order], self.status[order].astype(np.int8),
                        self.updated[order] == 1, self.mean[order], self.runs, self.steps,
                        None if self.cov is None else self.cov[order],
                        None if self.existence is None else self.existence[order])

    def single_target(self) -> tuple[np.ndarray, np.ndarray | None]:
        """One track per run at every step (a single-target filter's output): ``mean (B, T, n)`` and ``cov
        (B, T, n, n)`` (None without covariances)."""
        B, T, n = self.runs, self.steps, len(self.names)
        cell = self.run * T + self.step
        if self.rows != B * T or np.unique(cell).size != B * T:
            raise InputError(f"a single-target file has exactly one row per run and step ({B} x {T}); this one has "
                             f"{self.rows} rows")
        mean = np.empty((B * T, n))
        mean[cell] = self.mean
        cov = None
        if self.cov is not None:
            cov = np.empty((B * T, n, n))
            cov[cell] = self.cov
            cov = cov.reshape(B, T, n, n)
        return mean.reshape(B, T, n), cov


def state_layout(n: int, motion: MotionModel | None = None, names: Sequence[str] | None = None,
                 units: Sequence[str] | None = None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The names and units of ``n`` state components.

    Given ``names`` (and ``units``) win.  Otherwise the motion model's declared ``state_names`` and ``state_units``,
    or its layout (positions, then velocities, :mod:`workbench.models`): ``x, y[, z]`` in m and ``vx, vy[, vz]`` in
    m/s; without a motion model (or for a layout of more than three positions) ``s0, s1, ...`` with no unit.
    """
    if names is None:
        if motion is not None and motion.dim != n:
            raise InputError(f"the motion model {motion.name!r} has {motion.dim} state components, the tracks {n}")
        d = n // 2
        if motion is not None and len(motion.state_names) == n:
            names = motion.state_names
            units = (motion.state_units if len(motion.state_units) == n else ("",) * n) if units is None else units
        elif motion is not None and n == 2 * d and 1 <= d <= 3:
            names = ("x", "y", "z")[:d] + ("vx", "vy", "vz")[:d]
            units = ("m",) * d + ("m/s",) * d if units is None else units
        else:
            names = tuple(f"s{i}" for i in range(n))
    names = tuple(str(v) for v in names)
    units = ("",) * n if units is None else tuple(str(u) for u in units)
    if len(names) != n or len(units) != n:
        raise InputError(f"need {n} state names and units, got {len(names)} names and {len(units)} units")
    return names, units


def _cov_names(names: Sequence[str]) -> list[str]:
    n = len(names)
    return [f"cov_{names[i]}_{names[j]}" for i in range(n) for j in range(i, n)]


def _float(value: float) -> str:
    return repr(float(value))


def write_tracks(path, tracks: TrackFile) -> Path:
    """Write a :class:`TrackFile` (rows in the order given).  Returns the path."""
    path = Path(path)
    n = len(tracks.names)
    iu = np.triu_indices(n)
    header = ["# workbench track file", f"# format: {FORMAT} {tracks.version}",
              "# state: " + ", ".join(f"{a} [{u}]" for a, u in zip(tracks.names, tracks.units)),
              f"# covariance: {'none' if tracks.cov is None else 'upper triangle'}",
              *([] if tracks.existence is None else ["# existence: column"]),
              f"# runs: {tracks.runs}", f"# steps: {tracks.steps}"]
    header += [f"# note: {line}" for note in tracks.notes for line in str(note).splitlines() or [""]]
    columns = list(LEADING) + list(tracks.names) + ([] if tracks.cov is None else _cov_names(tracks.names))
    columns += [] if tracks.existence is None else ["existence"]
    if tracks.cov is not None:  # a file the reader would refuse is not written
        negative, not_psd = covariance_problems(tracks.cov)
        if negative.any() or not_psd.any():
            r = int(np.flatnonzero(negative | not_psd)[0])
            what = "has a negative variance" if negative[r] else "is not positive semi-definite"
            raise InputError(f"{path}: the covariance of track {int(tracks.track[r])} (run {int(tracks.run[r])}, step "
                             f"{int(tracks.step[r])}) {what} (smallest eigenvalue "
                             f"{float(np.linalg.eigvalsh(tracks.cov[r])[0]):.6g}); not written")
    with path.open("w", newline="", encoding="utf-8") as fh:
        fh.write("\n".join(header) + "\n")
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(columns)
        for r in range(tracks.rows):
            upd = int(tracks.updated[r])
            row = [str(int(tracks.run[r])), str(int(tracks.track[r])), str(int(tracks.step[r])),
                   _float(tracks.time[r]), STATUS[int(tracks.status[r])], "" if upd < 0 else str(upd)]
            row += [_float(v) for v in tracks.mean[r]]
            if tracks.cov is not None:
                row += [_float(v) for v in tracks.cov[r][iu]]
            if tracks.existence is not None:
                row.append(_float(tracks.existence[r]))
            writer.writerow(row)
    return path


def _times(times, steps: int) -> np.ndarray:
    times = np.asarray(times, dtype=float)
    if times.shape != (steps,):
        raise InputError(f"times must have shape ({steps},), one per step, got {times.shape}")
    if not np.all(np.isfinite(times)):
        raise InputError("times must be finite")
    return times


def write_track_log(path, log: TrackLog, times, *, motion: MotionModel | None = None,
                    names: Sequence[str] | None = None, units: Sequence[str] | None = None, cov=None,
                    existence=None, notes: Iterable[str] = ()) -> Path:
    """Write every track of a multi-target :class:`~workbench.tracking.TrackLog` (tentative and confirmed).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    log : TrackLog
        The tracker's log, rows ``(R,)``.
    times : array (T,)
        The time of each step (scan) in seconds, ``T = log.pings``.
    motion : MotionModel, optional
        The tracker's motion model, for the names and units of the state (:func:`state_layout`).
    names, units : sequence of str, optional
        The state components' names and units, overriding the motion model's layout.
    cov : array (R, n, n), optional
        Each row's state covariance; by default the log's own (``TrackLog.cov``, where the tracker keeps it).
    existence : array (R,), optional
        Each row's probability of existence (or PHD weight); by default the log's own (``TrackLog.existence``,
        where the tracker has one): the ``existence`` column.
    notes : sequence of str, optional
        Free text lines for the header.
    """
    n = log.mean.shape[1] if log.mean.ndim == 2 else 0
    names, units = state_layout(n, motion, names, units)
    times = _times(times, log.pings)
    if cov is None:
        cov = log.cov
    if existence is None:
        existence = log.existence
    return write_tracks(path, TrackFile(names, units, log.runs, log.pings, log.run, log.track_id, log.ping,
                                        times[log.ping], log.status, np.asarray(log.hit, dtype=np.int64), log.mean,
                                        cov, tuple(notes), existence=existence))


def write_track(path, track: Track, times, *, motion: MotionModel | None = None, names: Sequence[str] | None = None,
                units: Sequence[str] | None = None, updated=None, notes: Iterable[str] = ()) -> Path:
    """Write a single-target filter's :class:`~workbench.tracking.Track`: one row (track 0, ``confirmed``) per run
    and step, with its mean and covariance.

    ``updated (B, T)`` says at which steps each run's track was updated with a detection; by default the track's
    own ``updated`` record where its association role keeps one (nearest neighbour), else unknown.  ``times``,
    ``motion``, ``names``, ``units``, ``notes`` as :func:`write_track_log` takes them.
    """
    mean = np.asarray(track.mean, dtype=float)
    B, T, n = mean.shape
    names, units = state_layout(n, motion, names, units)
    times = _times(times, T)
    if updated is None:
        updated = track.records.get("updated") if track.records else None
    upd = np.full((B, T), -1, dtype=np.int64) if updated is None else np.asarray(updated, dtype=bool).astype(np.int64)
    if upd.shape != (B, T):
        raise InputError(f"updated must have shape ({B}, {T}), got {upd.shape}")
    run, step = np.divmod(np.arange(B * T), T)
    return write_tracks(path, TrackFile(names, units, B, T, run, np.zeros(B * T, dtype=np.int64), step, times[step],
                                        np.full(B * T, CONFIRMED), upd.reshape(-1), mean.reshape(B * T, n),
                                        np.asarray(track.cov, dtype=float).reshape(B * T, n, n), tuple(notes)))


# -- reading --------------------------------------------------------------------------------------------


def _header_block(path: Path, lines: list[str]) -> tuple[dict[str, tuple[int, str]], list[str], int]:
    """The ``# key: value`` lines before the column header, the notes, and the header's line index."""
    keys: dict[str, tuple[int, str]] = {}
    notes: list[str] = []
    for i, line in enumerate(lines):
        text = line.rstrip("\r\n")
        if not text.strip():
            continue
        if not text.startswith("#"):
            return keys, notes, i
        body = text[1:].strip()
        key, sep, value = body.partition(":")
        key = key.strip().lower()
        if sep and key == "note":
            notes.append(value[1:] if value.startswith(" ") else value)
        elif sep and key in ("format", "state", "covariance", "existence", "runs", "steps"):
            if key in keys:
                raise InputError(f"{path} line {i + 1}: the header gives '{key}' twice")
            keys[key] = (i + 1, value.strip())
    raise InputError(f"{path}: no column header (the file holds comment lines only)")


def _count(path: Path, keys, key: str) -> int:
    if key not in keys:
        raise InputError(f"{path}: the header has no '# {key}: ...' line")
    line, text = keys[key]
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"{path} line {line}: '{key}' must be an integer >= 0, got {text!r}") from None
    if value < 0:
        raise InputError(f"{path} line {line}: '{key}' must be an integer >= 0, got {text!r}")
    return value


def read_tracks(path) -> TrackFile:
    """Read a track file written by :func:`write_tracks` (or by hand, in the documented format).

    The header block must give the ``format`` (``workbench-tracks 1``), the ``state`` components with their
    units, the ``covariance`` (``upper triangle`` or ``none``), ``runs`` and ``steps``, and may give ``existence``
    (``column`` or ``none``; none without the line); the column header must be exactly the columns these imply.
    Any other problem (a wrong field count, a value that is not a number, a non-finite number, an unknown status,
    a run or step out of range, a track listed twice at one step, one step with two times, times that do not
    increase with the step, a negative variance or existence or a covariance that is not positive semi-definite)
    raises :class:`~workbench.types.InputError` naming the file and the line (and the
    column where one field is at fault).
    """
    path = Path(path)
    lines = read_text(path, "track file").splitlines(keepends=True)
    keys, notes, head = _header_block(path, lines)
    if "format" not in keys:
        raise InputError(f"{path}: not a workbench track file (no '# format: {FORMAT} {VERSION}' line)")
    line, fmt = keys["format"]
    parts = fmt.split()
    if len(parts) != 2 or parts[0] != FORMAT or not parts[1].isdigit():
        raise InputError(f"{path} line {line}: expected '# format: {FORMAT} {VERSION}', got {fmt!r}")
    if int(parts[1]) != VERSION:
        raise InputError(f"{path} line {line}: format version {parts[1]} is not supported (this reader reads "
                         f"version {VERSION})")
    if "state" not in keys:
        raise InputError(f"{path}: the header has no '# state: name [unit], ...' line")
    line, state = keys["state"]
    names, units = [], []
    for item in (s.strip() for s in state.split(",")):
        match = _COMPONENT.match(item)
        if not match:
            raise InputError(f"{path} line {line}: a state component must read 'name [unit]', got {item!r}")
        names.append(match.group(1))
        units.append(match.group(2))
    if "covariance" not in keys or keys["covariance"][1] not in ("upper triangle", "none"):
        where = f"line {keys['covariance'][0]}" if "covariance" in keys else "the header"
        raise InputError(f"{path} {where}: expected '# covariance: upper triangle' or '# covariance: none'")
    with_cov = keys["covariance"][1] == "upper triangle"
    if "existence" in keys and keys["existence"][1] not in ("column", "none"):
        raise InputError(f"{path} line {keys['existence'][0]}: expected '# existence: column' or '# existence: none', "
                         f"got {keys['existence'][1]!r}")
    with_existence = "existence" in keys and keys["existence"][1] == "column"
    runs, steps = _count(path, keys, "runs"), _count(path, keys, "steps")
    n = len(names)
    expected = list(LEADING) + names + (_cov_names(names) if with_cov else [])
    expected += ["existence"] if with_existence else []
    reader = csv.reader(lines[head:])
    columns = [c.strip() for c in next(reader)]
    if columns != expected:
        missing = [c for c in expected if c not in columns]
        extra = [c for c in columns if c not in expected]
        detail = (f"missing {missing}" if missing else "") + ("; " if missing and extra else "") + \
                 (f"unexpected {extra}" if extra else "") or "the columns are out of order"
        raise InputError(f"{path} line {head + 1}: the column header does not match the state line ({detail}); "
                         f"expected {','.join(expected)}")
    iu = np.triu_indices(n)
    rows: dict[str, list] = {k: [] for k in ("run", "track", "step", "time", "status", "updated", "mean", "cov",
                                             "existence")}
    seen: dict[tuple[int, int, int], int] = {}
    step_time: dict[int, tuple[float, int]] = {}  # step -> (its time, the first line that gave it)
    lines_of: list[int] = []
    for fields in reader:
        lineno = head + reader.line_num
        if not fields or (len(fields) == 1 and not fields[0].strip()):
            continue
        if fields[0].lstrip().startswith("#"):
            continue
        if len(fields) != len(expected):
            raise InputError(f"{path} line {lineno}: expected {len(expected)} fields, got {len(fields)}")
        where = lambda col: f"{path} line {lineno}, column {col!r}"  # noqa: E731
        run, track, step = (_integer(fields[i], where(LEADING[i])) for i in range(3))
        if run >= runs:
            raise InputError(f"{where('run')}: run {run} is not below the header's runs ({runs})")
        if step >= steps:
            raise InputError(f"{where('step')}: step {step} is not below the header's steps ({steps})")
        key = (run, step, track)
        if key in seen:
            raise InputError(f"{where('track')}: track {track} of run {run} appears twice at step {step} (lines "
                             f"{seen[key]} and {lineno})")
        seen[key] = lineno
        status = fields[4].strip()
        if status not in _STATUS_CODE:
            raise InputError(f"{where('status')}: expected tentative or confirmed, got {status!r}")
        upd = fields[5].strip()
        if upd not in ("", "0", "1"):
            raise InputError(f"{where('updated')}: expected 1, 0 or an empty field, got {upd!r}")
        rows["run"].append(run)
        rows["track"].append(track)
        rows["step"].append(step)
        t = finite_number(fields[3], where("time"))
        first = step_time.setdefault(step, (t, lineno))
        if t != first[0]:
            raise InputError(f"{where('time')}: step {step} has time {first[0]!r} on line {first[1]} but {t!r} here "
                             f"(track {track}, run {run}); a step is one scan, at one time")
        lines_of.append(lineno)
        rows["time"].append(t)
        rows["status"].append(_STATUS_CODE[status])
        rows["updated"].append(int(upd) if upd else -1)
        rows["mean"].append([finite_number(fields[6 + i], where(names[i])) for i in range(n)])
        if with_cov:
            tri = [finite_number(fields[6 + n + k], where(expected[6 + n + k])) for k in range(len(iu[0]))]
            c = np.zeros((n, n))
            c[iu] = tri
            c.T[iu] = tri
            for i in range(n):
                if c[i, i] < 0:
                    col = f"cov_{names[i]}_{names[i]}"
                    raise InputError(f"{where(col)}: {float(c[i, i])!r} is the variance of {names[i]} of track "
                                     f"{track} (run {run}, step {step}) and must be >= 0")
            rows["cov"].append(c)
        if with_existence:
            e = finite_number(fields[-1], where("existence"))
            if e < 0:
                raise InputError(f"{where('existence')}: {e!r} is the existence of track {track} (run {run}, step "
                                 f"{step}) and must be >= 0")
            rows["existence"].append(e)
    R = len(rows["run"])
    ordered = sorted(step_time)
    for a, b in zip(ordered, ordered[1:]):
        if not step_time[b][0] > step_time[a][0]:
            raise InputError(f"{path} line {step_time[b][1]}, column 'time': step {b} has time {step_time[b][0]!r}, "
                             f"not after step {a}'s {step_time[a][0]!r} (line {step_time[a][1]}); the times of a track "
                             f"file increase with the step")
    if with_cov and R:
        _, not_psd = covariance_problems(np.array(rows["cov"]))
        if not_psd.any():
            r = int(np.flatnonzero(not_psd)[0])
            low = float(np.linalg.eigvalsh(rows["cov"][r])[0])
            raise InputError(f"{path} line {lines_of[r]}: the covariance of track {rows['track'][r]} (run "
                             f"{rows['run'][r]}, step {rows['step'][r]}) is not positive semi-definite (smallest "
                             f"eigenvalue {low:.6g}; a correlation beyond +-1?)")
    return TrackFile(tuple(names), tuple(units), runs, steps, np.array(rows["run"], dtype=np.int64),
                     np.array(rows["track"], dtype=np.int64), np.array(rows["step"], dtype=np.int64),
                     np.array(rows["time"], dtype=float), np.array(rows["status"], dtype=np.int64),
                     np.array(rows["updated"], dtype=np.int64), np.array(rows["mean"], dtype=float).reshape(R, n),
                     np.array(rows["cov"]).reshape(R, n, n) if with_cov else None, tuple(notes), VERSION,
                     np.array(rows["existence"], dtype=float) if with_existence else None)


def _integer(text: str, where: str) -> int:
    text = text.strip()
    if not re.fullmatch(r"\d+", text):
        raise InputError(f"{where}: expected an integer >= 0, got {text!r}")
    return int(text)
