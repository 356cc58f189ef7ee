"""Counter-based standard normals: the normals of row ``b`` of stream ``key`` are a pure function of ``(key, b)``.

The formulas and the NumPy twin are in :mod:`.counter_normals_numpy`; the compiled twin is
:mod:`.counter_normals_numba` (the same numbers bit for bit).  :func:`counter_normals` takes the compiled one
where the backend policy (:mod:`.backend`) has Numba.
"""

from __future__ import annotations

import numpy as np

from .backend import numba_available
from .counter_normals_numpy import counter_normals_numpy, draw_key, log_poly, sincos_poly

__all__ = ["counter_normals", "counter_normals_numpy", "draw_key", "log_poly", "sincos_poly"]


def counter_normals(key: int, rows: int, count: int) -> np.ndarray:
    """``count`` standard normals for each of ``rows`` rows of stream ``key``: ``(rows, count)``.

    Computed by the Numba twin when Numba is installed (about 2 ns a number, on every core), else by
    :func:`counter_normals_numpy` (about 120 ns); the two give the same numbers bit for bit (tested).
    """
    if not numba_available():
        return counter_normals_numpy(key, rows, count)
    from .counter_normals_numba import fill_rows

    out = np.empty((int(rows), int(count)))
    if out.size:
        fill_rows(np.uint64(key), out)
    return out
