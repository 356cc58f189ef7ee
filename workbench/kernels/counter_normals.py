"""Counter-based standard normals: the normals of row ``b`` of stream ``key`` are a pure function of ``(key, b)``.

The formulas (a float32 Box-Muller of one SplitMix64 word per pair) and the NumPy twin are in
:mod:`.counter_normals_numpy`; the compiled twin is
:mod:`.counter_normals_numba` (the same numbers bit for bit).  :func:`counter_normals` takes the compiled one
where the backend policy (:func:`.backend.runs_numba`) picks Numba on the CPU (the normals are always made on the
host, whatever arch a kernel that uses them runs on), and notes which ran in :data:`RECORD`.
"""

from __future__ import annotations

import numpy as np

from .backend import BackendRecord, runs_numba
from .counter_normals_numpy import counter_normals_numpy, draw_key, log_poly, sincos_poly

__all__ = ["counter_normals", "counter_normals_numpy", "draw_key", "log_poly", "sincos_poly", "RECORD"]

#: Which code this thread's :func:`counter_normals` calls ran (``"numba"`` or ``"numpy"``), for tests.
RECORD = BackendRecord()


def counter_normals(key: int, rows: int, count: int, backend: str = "auto") -> np.ndarray:
    """``count`` standard normals for each of ``rows`` rows of stream ``key``: ``(rows, count)``.

    Computed on the host by the Numba twin where the backend policy picks Numba on the CPU for ``backend``
    (``"auto"``: Numba installed and ``WORKBENCH_BACKEND`` not set to another backend; about 3.6 ns a number on one
    thread of a Zen-1 EPYC core, rows on every core), else by :func:`counter_normals_numpy` (about 60 ns there;
    ``"numpy"`` and ``"taichi"``, which has no version here, run it); the two give the same numbers bit for bit
    (tested).  The numbers are float32 values (a float32 Box-Muller, the generator of
    :mod:`.counter_normals_numpy`'s docstring), stored as float64: ``(rows, count)`` float64.
    """
    if not runs_numba(backend, "cpu"):
        RECORD.note("numpy")
        return counter_normals_numpy(key, rows, count)
    from .counter_normals_numba import fill_rows

    out = np.empty((int(rows), int(count)))
    if out.size:
        fill_rows(np.uint64(key), out)
    RECORD.note("numba")
    return out
