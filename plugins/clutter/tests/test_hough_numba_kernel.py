"""The whole-run Numba kernel's own pieces (``hough_numba``): its hand-written sort, gate sweep and counting sort
against NumPy and brute force, and the shape of its compilation (each kernel compiled once, no library sort), which
is what keeps its compile time small in a fresh process.  The kernel's decisions are held to the brute-force
reference of the published algorithm in ``test_hough.py``."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from workbench.kernels.backend import numba_available
from workbench.rng import generator

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba is not installed")


def test_heap_sort_orders_each_ping_by_x():
    from workbench_clutter import hough_numba

    rng = generator(40, "argsort-x")
    # integer x (many ties), real x, a single point and an empty ping, each sorted in place within its rows
    parts = [rng.integers(0, 6, (57, 2)).astype(float), rng.uniform(-1e3, 1e3, (200, 2)), np.array([[3.0, 1.0]]),
             np.zeros((0, 2)), rng.integers(-3, 3, (2, 2)).astype(float)]
    xy = np.concatenate(parts)
    bounds = np.cumsum([0] + [len(p) for p in parts])
    order = np.full(len(xy), -1, dtype=np.int64)
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        hough_numba._argsort_x(xy, int(lo), int(hi), order)
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        got = order[lo:hi]
        assert sorted(got.tolist()) == list(range(lo, hi))  # a permutation of the ping's own rows
        np.testing.assert_array_equal(xy[got, 0], np.sort(xy[lo:hi, 0]))


def test_gate_sweep_equals_brute_force():
    from workbench_clutter import hough_numba

    rng = generator(41, "gate-sweep")
    # integer coordinates: many pairs exactly on the box edge and many equal x
    a = rng.integers(0, 40, (150, 2)).astype(float)
    b = rng.integers(0, 40, (90, 2)).astype(float)
    pts = np.concatenate([a, b])
    order = np.zeros(len(pts), dtype=np.int64)  # only rows len(a) .. are sorted and read
    hough_numba._argsort_x(pts, len(a), len(pts), order)
    xs = pts[order, 0]
    for box in (0.0, 1.0, 3.0, 7.5):
        want = (np.abs(a[:, None, :] - b[None, :, :]) <= box).all(axis=2).any(axis=1)
        got = np.zeros(len(a), dtype=bool)
        hough_numba._has_partner(pts, 0, len(a), xs, order, len(a), len(pts), box, got)
        np.testing.assert_array_equal(got, want)
        assert 0 < want.sum() < len(a) or box == 7.5
    # a point already marked stays marked, and an empty partner set changes nothing
    got = np.ones(len(a), dtype=bool)
    hough_numba._has_partner(pts, 0, len(a), xs, order, len(a), len(a), 1.0, got)
    assert got.all()


def test_support_grid_is_a_stable_sort_by_cell():
    from workbench_clutter import hough_numba

    rng = generator(42, "support-grid")
    W = 5
    reach = np.array([0.0, 16.0, 16.0, 24.0, 32.0])
    pts = rng.uniform(0, 250, (30, 2))
    sizes = [20, 0, 35, 12]  # the gated points of the 4 earlier pings of the group (one has none)
    g_xy = np.round(rng.uniform(0, 250, (sum(sizes), 2)))  # rounded: points on cell edges
    g_sel = np.concatenate([rng.permutation(40)[:n] for n in sizes]).astype(np.int64)
    g_start = np.cumsum([0] + sizes).astype(np.int64)
    g0 = 7
    sup_xy, sup_ring, sup_idx, starts, x0, y0, h, nx, ny = hough_numba._local_inputs(
        pts, 0, len(pts), g_xy, g_sel, g_start, W - 1, g0, reach, W)
    # the reference: the bounding box of every point, the cell side (the smallest reach, doubled while the grid
    # would have over 8 cells per point plus 1024), then each ping's points by a stable argsort of their cells
    every = np.concatenate([pts, g_xy])
    assert (x0, y0) == (every[:, 0].min(), every[:, 1].min())
    side = 16.0 * (1.0 + 2.0 ** -20)
    span = every.max(axis=0) - every.min(axis=0)
    while np.prod(np.floor(span / side) + 1) > 8 * len(every) + 1024:
        side *= 2.0
    assert h == side and (nx, ny) == tuple(int(v) for v in np.floor(span / side) + 1)
    for s in range(W - 1):
        xy, sel = g_xy[g_start[s]:g_start[s + 1]], g_sel[g_start[s]:g_start[s + 1]]
        cell = np.minimum(np.floor((xy - [x0, y0]) / h).astype(np.int64), [nx - 1, ny - 1])
        key = cell[:, 0] * ny + cell[:, 1]
        order = np.argsort(key, kind="stable")
        rows = slice(g_start[s], g_start[s + 1])
        np.testing.assert_array_equal(sup_xy[rows], xy[order])
        np.testing.assert_array_equal(sup_idx[rows], sel[order])
        assert (sup_ring[rows] == (g0 + s) % W).all()
        want = g_start[s] + np.concatenate([[0], np.cumsum(np.bincount(key, minlength=nx * ny))])
        np.testing.assert_array_equal(starts[s], want)


COMPILE_SCRIPT = textwrap.dedent("""
    import json
    import numpy as np
    from numba import types
    from numba.core.event import install_recorder
    from workbench.rng import generator
    from workbench.types import Scans
    from workbench_clutter.hough import remove

    rng = generator(43, "compile-count")
    z = rng.uniform(0, 250, (2, 10, 25, 2))
    z[:, :, 0] = [40.0, 60.0] + np.arange(10)[:, None] * [5.0, 3.0]
    scans = Scans(z, rng.random(z.shape[:3]) < 0.9, np.arange(10, dtype=float))
    with install_recorder("numba:compile") as rec:
        kept = [int(remove(scans, backend="numba", **o).valid.sum())
                for o in ({}, {"support": "latest"}, {"new_measurements": "projected", "support": "any"})]
    out = []
    for _, ev in rec.buffer:
        if ev.is_start:
            d = ev.data["dispatcher"]
            out.append([d.py_func.__module__, d.py_func.__qualname__,
                        any(isinstance(a, types.Literal) for a in ev.data["args"])])
    print(json.dumps({"kept": kept, "compiles": out}))
""")


@pytest.mark.slow
def test_the_run_kernel_compiles_each_function_once_without_library_sorts(tmp_path):
    # a fresh process with an empty cache compiles remove_run and everything it calls: each of the kernel's
    # functions once (a literal integer handed to a kernel would compile it a second time, for Literal[int]), and
    # none of Numba's sort or binary-search routines (several seconds each to compile)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    res = subprocess.run([sys.executable, "-c", COMPILE_SCRIPT], env=env, capture_output=True, text=True,
                         check=True)
    report = json.loads(res.stdout.strip().splitlines()[-1])
    assert all(n > 0 for n in report["kept"])
    ours = [name for module, name, _ in report["compiles"] if module.endswith("hough_numba")]
    assert "remove_run" in ours and "local_keep" in ours and "_rule_keep" in ours
    assert sorted(ours) == sorted(set(ours)), ours
    assert not [c for c in report["compiles"] if c[2]], "a kernel compiled for a literal argument"
    library = [name for module, name, _ in report["compiles"] if not module.endswith("hough_numba")]
    assert not [n for n in library if "sort" in n.lower() or "searchsorted" in n], library
