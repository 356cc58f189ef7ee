"""The Hough clutter remover (paper 001): line recovery, clutter rejection, the theta = 0 / pi seam,
peaks and similarity against independent references, causality and parameter checks."""

from dataclasses import dataclass, field

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from workbench.rng import generator
from workbench.types import CLUTTER, InputError, Scans
from workbench_clutter import hough
from workbench_clutter.hough import (HOUGH, HoughGrid, find_peaks, lines_similar, make_grid, neighbours, remove,
                                     similar_to)

AREA = 250.0


def _scene(start, velocity, pings=12, clutter=20, sigma=1.0, seed=0, pd=1.0):
    """One run: a target on a straight line plus uniform clutter; origin 0 = target."""
    rng = generator(seed, "hough-test")
    k = np.arange(pings)[:, None]
    target = np.asarray(start) + k * np.asarray(velocity) + sigma * rng.standard_normal((pings, 2))
    z = np.concatenate([target[:, None, :], rng.uniform(0, AREA, (pings, clutter, 2))], axis=1)[None]
    valid = np.ones(z.shape[:3], dtype=bool)
    valid[0, :, 0] = rng.random(pings) < pd
    origin = np.concatenate([np.zeros((pings, 1), int), np.full((pings, clutter), CLUTTER)], axis=1)[None]
    return Scans(z, valid, np.arange(pings, dtype=float), origin=origin)


def _fractions(scans, out, first=5):
    o = scans.origin[:, first:]
    v, k = scans.valid[:, first:], out.valid[:, first:]
    return (k & (o == 0)).sum() / (v & (o == 0)).sum(), (k & (o == CLUTTER)).sum() / (v & (o == CLUTTER)).sum()


def _line_distance(lines, rho0, theta0):
    """Distance in (units, degrees) of each (rho, theta) to the true line, modulo (rho, theta) = (-rho, theta + pi)."""
    lines = np.asarray(lines).reshape(-1, 2)
    d_direct = np.abs(lines[:, 0] - rho0) + np.rad2deg(np.abs(lines[:, 1] - theta0))
    d_flip = np.abs(lines[:, 0] + rho0) + np.rad2deg(np.pi - np.abs(lines[:, 1] - theta0))
    return np.minimum(d_direct, d_flip)


def test_recovers_a_noisy_line_and_rejects_clutter():
    scans = _scene((40.0, 60.0), (4.5, 1.5))
    trace = []
    out = remove(scans, trace=trace)
    kept_target, kept_clutter = _fractions(scans, out)
    assert kept_target >= 0.9, kept_target
    assert kept_clutter <= 0.3, kept_clutter
    # the true line: direction (4.5, 1.5), normal angle in [0, pi)
    theta0 = np.mod(np.arctan2(4.5, -1.5), np.pi)
    rho0 = 40.0 * np.cos(theta0) + 60.0 * np.sin(theta0)
    best = [_line_distance(t["similar"], rho0, theta0).min() for t in trace if len(t["similar"])]
    assert len(best) == len(trace) and np.median(best) <= 4.0, best


def test_uniform_clutter_is_mostly_removed():
    rng = generator(3, "clutter-only")
    z = rng.uniform(0, AREA, (4, 15, 31, 2))
    scans = Scans(z, np.ones(z.shape[:3], dtype=bool), np.arange(15.0))
    out = remove(scans)
    kept = out.valid[:, 5:].sum() / scans.valid[:, 5:].sum()
    assert kept < 0.3, kept
    assert not out.valid[:, :5].any()  # warm-up pings give no output


def test_line_across_the_theta_seam_is_kept():
    # a target moving along +y: the normal is theta ~ 0 (rho ~ 120) or theta ~ pi (rho ~ -120)
    scans = _scene((120.0, 20.0), (0.05, 4.5), pings=14, seed=5)
    trace = []
    out = remove(scans, trace=trace)
    kept_target, _ = _fractions(scans, out)
    assert kept_target >= 0.9, kept_target
    near = np.concatenate([t["peaks_a"][np.abs(np.abs(t["peaks_a"][:, 0]) - 120) < 6] for t in trace])
    theta = np.rad2deg(near[:, 1])
    assert (theta < 10).any() and (theta > 170).any(), "the scene must put target peaks on both sides of the seam"


def _reference_max3(score, n_rho):
    """3 x 3 maximum with the seam: pad theta with the far column flipped in rho (independent of neighbours())."""
    padded = np.concatenate([score[::-1, -1:], score, score[::-1, :1]], axis=1)
    return ndimage.maximum_filter(padded, size=3, mode="constant", cval=-1.0)[:, 1:-1]


def test_find_peaks_equals_a_grid_maximum_filter():
    grid = make_grid(1.0, 10.0, 6.0)  # 18 columns, small grid
    rng = generator(4, "peaks")
    for _ in range(20):
        support = rng.integers(0, 6, grid.shape).astype(np.int16)
        votes = support + rng.integers(0, 3, grid.shape)
        rows, cols = find_peaks(support, votes, 3, grid)
        score = support + votes / (votes.max() + 1.0)
        ref = (support >= 3) & (score >= _reference_max3(score, grid.n_rho))
        got = np.zeros(grid.shape, dtype=bool)
        got[rows, cols] = True
        assert np.array_equal(got, ref)


def test_neighbours_cross_the_seam_with_rho_negated():
    grid = make_grid(1.0, 1.0, 10.0)
    row = grid.off + 7  # rho = +7 in column 0 (theta = 0)
    nb = neighbours(np.array([row]), np.array([0]), grid)[0]
    r, c = np.divmod(nb[nb >= 0], grid.n_theta)
    rho = r - grid.off
    # column -1 is theta = 179 deg with rho negated: rho in {-6, -7, -8}
    assert set(rho[c == grid.n_theta - 1]) == {-6, -7, -8}
    assert set(rho[c == 1]) == {6, 7, 8}


def test_similar_to_matches_the_closed_form():
    grid = make_grid(1.0, 1.0, 60.0)
    rng = generator(6, "similar")
    ra, ca = rng.integers(0, grid.n_rho, 40), rng.integers(0, grid.n_theta, 40)
    rb, cb = rng.integers(0, grid.n_rho, 400), rng.integers(0, grid.n_theta, 400)
    # put some b cells right across the seam from a cells
    rb[:40], cb[:40] = grid.n_rho - 1 - ra, (grid.n_theta - 1 - ca % 3)
    got = similar_to(rb, cb, ra, ca, grid, 3, 3)
    rho, theta = grid.rho, grid.theta
    ref = lines_similar(rho[ra], theta[ca], rho[rb], theta[cb], 3.0, np.deg2rad(3.0) + 1e-9).any(axis=0)
    assert np.array_equal(got, ref)
    assert got[:40].any()


def test_lines_similar_identifies_the_seam_equivalence():
    # (rho, theta) and (-rho, theta + pi) are the same line
    assert lines_similar([50.0], [np.deg2rad(1.0)], [-51.0], [np.deg2rad(178.0)], 3.0, np.deg2rad(3.0))[0, 0]
    assert not lines_similar([50.0], [np.deg2rad(1.0)], [51.0], [np.deg2rad(178.0)], 3.0, np.deg2rad(3.0))[0, 0]


def test_causal_and_blind_to_origin():
    scans = _scene((40.0, 60.0), (4.5, 1.5), pings=12, seed=8)
    full = remove(scans).valid
    short = Scans(scans.z[:, :9], scans.valid[:, :9], scans.times[:9], origin=scans.origin[:, :9])
    assert np.array_equal(remove(short).valid, full[:, :9])
    scrambled = Scans(scans.z, scans.valid, scans.times, origin=np.zeros_like(scans.origin))
    assert np.array_equal(remove(scrambled).valid, full)
    assert not np.any(full & ~scans.valid)


def test_warmup_keep_and_parameter_errors():
    scans = _scene((40.0, 60.0), (4.5, 1.5), pings=8)
    out = remove(scans, warmup="keep")
    assert np.array_equal(out.valid[:, :5], scans.valid[:, :5])
    with pytest.raises(InputError, match="window"):
        remove(scans, window=1)
    with pytest.raises(InputError, match="d_theta"):
        remove(scans, d_theta_deg=7.0)
    with pytest.raises(InputError, match="warmup"):
        remove(scans, warmup="maybe")
    with pytest.raises(InputError, match="support"):
        remove(scans, support="nearest")
    assert HOUGH.name == "hough" and HOUGH.params["window"] == 5


def _ref_remove(scans, **kw):
    p = {**HOUGH.params, **kw}
    valid = scans.valid
    extent = float(np.max(np.linalg.norm(scans.z[valid], axis=-1))) if valid.any() else 1.0
    grid = make_grid(p["d_rho"], p["d_theta_deg"], extent)
    args = {k: p[k] for k in ("window", "shift", "v_max", "dt", "gate_gap", "v_min", "sim_rho", "sim_theta_deg",
                              "eps", "support_reach", "support", "warmup")}
    return np.stack([_ref_remove_run(scans.z[b], valid[b], grid, **args) for b in range(scans.batch)])


def _random_scene(seed, runs=3, pings=13, clutter=40, seam=False, area=AREA):
    """Targets on straight legs (random heading and speed, or along +y: normal at theta ~ 0 / pi) plus
    uniform clutter, 10 % of detections missing."""
    rng = generator(seed, "hough-equal")
    z = rng.uniform(0, area, (runs, pings, clutter + 1, 2))
    k = np.arange(pings)[:, None]
    for b in range(runs):
        if seam:
            start, velocity = np.array([0.5 * area, 0.1 * area]), np.array([rng.normal(0, 0.05), 4.5])
        else:
            heading, speed = rng.uniform(0, 2 * np.pi), rng.uniform(1.0, 7.0)
            start, velocity = rng.uniform(0.2 * area, 0.8 * area, 2), speed * np.array([np.cos(heading), np.sin(heading)])
        z[b, :, 0] = start + k * velocity + rng.standard_normal((pings, 2))
    return Scans(z, rng.random(z.shape[:3]) < 0.9, np.arange(pings, dtype=float))


@pytest.mark.parametrize("seed, seam, options", [
    (0, False, {}),
    (1, True, {}),
    (2, False, {"support": "any"}),
    (3, True, {"window": 3, "shift": 3}),
    (4, False, {"support_reach": "gap", "warmup": "keep"}),
    (5, True, {"d_rho": 2.0, "d_theta_deg": 2.0, "eps": 5.0, "v_min": 2}),
    (6, False, {"window": 11, "v_min": 4, "sim_theta_deg": 200.0}),  # 10 support slots: two bit words
])
def test_fast_remover_decides_exactly_as_the_dense_reference(seed, seam, options):
    scans = _random_scene(seed, seam=seam)
    got = remove(scans, **options).valid
    assert np.array_equal(got, _ref_remove(scans, **options))
    assert got.any()


def test_fast_remover_equals_the_reference_in_dense_clutter():
    # 2,000 detections per ping on the paper's area: most cells voted by most pings, ~10^4 peaks
    scans = _random_scene(7, runs=1, pings=8, clutter=2000)
    assert np.array_equal(remove(scans).valid, _ref_remove(scans))


def test_fast_remover_equals_the_reference_on_a_sonar_scenario():
    # the installed active-sonar sensor and sonar clutter at their defaults, a target crossing the area
    from workbench.plugins import load_host
    from workbench.trajectory import Leg, piecewise_trajectory
    from workbench.types import Truth

    host = load_host()
    one = piecewise_trajectory((100.0, 100.0), (4.0, 2.0), (Leg("straight", 19.0),), 1.0)
    truth = Truth(np.repeat(one.states, 4, axis=0), one.times)
    rng = generator(11, "hough-sonar-scenario")
    scans = host.sensor("active-sonar").simulate(truth, rng).merge(
        host.clutter_generator("sonar-poisson").generate(truth, rng))
    got = remove(scans).valid
    assert np.array_equal(got, _ref_remove(scans))
    assert got.any() and (got.sum() < scans.valid.sum())



@pytest.mark.parametrize("scale, offset", [(1.0, 0.0), (1.0, -500.0), (0.25, 1e6), (3.0, 0.0)])
def test_cell_pairs_hold_every_pair_within_reach(scale, offset):
    # integer coordinates put many pairs exactly on the box edge |dx| = r
    rng = generator(21, "cell-pairs", scale, offset)
    for r in (8.0, 16.0, 5.0):
        a = offset + scale * rng.integers(0, 120, (300, 2)).astype(float)
        b = offset + scale * rng.integers(0, 120, (500, 2)).astype(float)
        b[:50] = a[:50] + scale * r * rng.choice([-1.0, 0.0, 1.0], (50, 2))  # on the edge
        rr = scale * r
        i, j = hough._cell_pairs(a, b, rr, 10 ** 9)
        got = set(zip(i.tolist(), j.tolist()))
        assert len(got) == i.size  # no pair twice
        cheb = np.abs(a[:, None, :] - b[None, :, :]).max(axis=2)
        want = set(zip(*np.nonzero(cheb <= rr)))
        assert want <= got and len(want) > 50
    assert hough._cell_pairs(a, b, rr, 10) is None  # over the limit: the caller uses the k-d tree


def test_box_gate_equals_the_k_d_tree_gate():
    rng = generator(22, "box-gate")
    for trial in range(6):
        pts = [rng.integers(0, 200 + 200 * trial, (150 + 40 * trial, 2)).astype(float) for _ in range(5)]
        if trial % 2:
            pts = [p + rng.uniform(-0.5, 0.5, p.shape) for p in pts]
        grid = make_grid(1.0, 1.0, 1000.0)
        fast = hough._RunCache(pts=pts, grid=grid, slots=[None] * 5, count_dtype=np.uint16,
                               ring=np.empty((5, 400, grid.n_theta), np.int32), ring_ping=[-1] * 5)
        ref = _RunCache(pts=pts, grid=grid, slots=[None] * 5)
        got, want = hough._gate(fast, range(5), 8.0, 1.0, 2), _gate(ref, range(5), 8.0, 1.0, 2)
        assert all(np.array_equal(got[p], want[p]) for p in range(5))
        assert 0 < sum(m.sum() for m in got.values()) < sum(len(p) for p in pts)


def test_rho_index_in_blocks_equals_one_pass():
    rng = generator(23, "rho-index")
    pts = rng.uniform(-3000, 3000, (1300, 2))
    for d_rho, d_theta in ((1.0, 1.0), (0.7, 2.0), (2.0, 0.5)):
        grid = make_grid(d_rho, d_theta, 4300.0)
        want = _ref_rho_index(grid, pts)
        for block in (1, 7, 512, 5000):
            assert np.array_equal(grid.rho_index(pts, block=block), want)


def test_window_tables_or_the_rows_of_each_window():
    rng = generator(24, "window-tables")
    e = 3
    bits = (rng.random((2, 5, 40)) < 0.1).astype(np.uint8) * rng.integers(1, 256, (2, 5, 40)).astype(np.uint8)
    bits[:, :, :e] = bits[:, :, -e:] = 0  # the padding rows
    out = hough._window_tables(bits, e, np.full((2, 5, 2 * e + 2, 40), 77, dtype=np.uint8))
    for a in range(2 * e + 2):
        for r in range(40):
            stop = min(r + 2 * e + 1 - a, 40)
            want = np.bitwise_or.reduce(bits[:, :, r:stop], axis=2) if stop > r else np.zeros((2, 5), np.uint8)
            assert np.array_equal(out[:, :, a, r], want)


@pytest.mark.parametrize("seed, pings, options", [
    (30, 9, {}),
    (31, 13, {"window": 11, "v_min": 4}),  # 10 support slots: two bit words
    (32, 9, {"support": "any", "support_reach": "gap", "d_rho": 2.0, "eps": 5.0}),
])
def test_cell_pairs_and_k_d_tree_paths_decide_alike(seed, pings, options, monkeypatch):
    # 600 detections per ping on [0, 1000]^2 (about the paper's density): the default takes
    # neighbouring-cell pairs; a limit of 0 forces every gate and every inverse step onto the k-d tree
    # (rounds of nearest supports)
    scans = _random_scene(seed, runs=1, pings=pings, clutter=600, area=1000.0)
    cells = remove(scans, **options).valid
    monkeypatch.setattr(hough, "CELL_PAIRS_PER_POINT", 0)
    trees = remove(scans, **options).valid
    assert np.array_equal(cells, trees)
    assert np.array_equal(cells, _ref_remove(scans, **options))
    assert 0 < cells.sum() < scans.valid[:, 5:].sum()

# --- reference: the dense implementation before the incremental rewrite (kept verbatim, renamed) ------
# Every ping re-votes the W pings of group B with a full-grid bincount, gates with k-d tree queries,
# filters the float score with scipy.ndimage and counts line cells with dense cumulative sums.  The fast
# remover must give exactly its decisions.


def _ref_rho_index(grid, points):
    th = grid.theta
    rho = points[:, :1] * np.cos(th) + points[:, 1:2] * np.sin(th)
    return (np.rint(rho / grid.d_rho) + grid.off).astype(np.int32)


def _seam_pad(grid_values: np.ndarray, width: int) -> np.ndarray:
    """Pad the ``theta`` axis by ``width`` columns on each side across the ``theta = 0 / pi`` seam:
    column ``-c`` is column ``n_theta - c`` with ``rho`` negated (rows flipped), column ``n_theta + c``
    is column ``c`` flipped.  ``(n_rho, n_theta) -> (n_rho, n_theta + 2 width)``."""
    if width == 0:
        return grid_values
    left = grid_values[::-1, grid_values.shape[1] - width:]
    right = grid_values[::-1, :width]
    return np.concatenate([left, grid_values, right], axis=1)


def _ref_find_peaks(support: np.ndarray, votes: np.ndarray, v_min: int, grid: HoughGrid) -> tuple[np.ndarray, np.ndarray]:
    """Peaks ``(rows, cols)``: cells with ``support >= v_min`` that are maxima of
    ``score = support + votes / (max votes + 1)`` over their 3 x 3 neighbourhood (seam-aware, ties kept).

    Dense grid filter: two separable 3-point maximum filters over the seam-padded score (cells outside
    the ``rho`` range count as ``-1``), so the cost is a few passes over the grid however many cells
    qualify (dense clutter).  Equal to comparing each cell with :func:`neighbours` (tested).
    """
    scale = 1.0 / (votes.max() + 1.0) if votes.size else 1.0
    # score = support + votes / (max votes + 1)
    score = support.astype(np.float64) + votes * scale
    m = ndimage.maximum_filter1d(_seam_pad(score, 1), size=3, axis=0, mode="constant", cval=-1.0)
    m = ndimage.maximum_filter1d(m, size=3, axis=1, mode="constant", cval=-1.0)[:, 1:-1]
    return np.nonzero((support >= v_min) & (score >= m))



def _ref_similar_to(rows_b, cols_b, rows_a, cols_a, grid: HoughGrid, half_rho: int, half_theta: int) -> np.ndarray:
    """Which cells ``b`` lie within ``half_rho`` rows and ``half_theta`` columns of some cell ``a``, modulo
    ``(rho, theta) == (-rho, theta + pi)``; ``(len(b),)`` bool.

    Dense: the ``a`` cells are marked on the grid, padded across the seam, dilated by a
    ``(2 half_rho + 1) x (2 half_theta + 1)`` maximum filter and read at the ``b`` cells.
    """
    out = np.zeros(len(rows_b), dtype=bool)
    if len(rows_a) == 0 or len(rows_b) == 0:
        return out
    mark = np.zeros(grid.shape, dtype=np.uint8)
    mark[rows_a, cols_a] = 1
    ht = min(int(half_theta), grid.n_theta)
    near = ndimage.maximum_filter(_seam_pad(mark, ht), size=(2 * int(half_rho) + 1, 2 * ht + 1), mode="constant",
                                  cval=0)
    return near[rows_b, np.asarray(cols_b) + ht] > 0



@dataclass
class _RunCache:
    """Per-run memo of what earlier pings already computed (mutable, private to one ``remove`` call)."""

    pts: list
    grid: HoughGrid
    slots: list
    row_cache: dict = field(default_factory=dict)
    trees: dict = field(default_factory=dict)
    partner: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    peaks: dict = field(default_factory=dict)

    def rows(self, p: int) -> np.ndarray:
        """The vote rows of ping ``p`` in every column, ``(n_p, n_theta)`` (computed once)."""
        if p not in self.row_cache:
            self.row_cache[p] = _ref_rho_index(self.grid, self.pts[p])
        return self.row_cache[p]

    def tree(self, p: int) -> cKDTree:
        if p not in self.trees:
            self.trees[p] = cKDTree(self.pts[p])
        return self.trees[p]


def _has_partner(cache: _RunCache, p: int, q: int, box: float) -> np.ndarray:
    """Points of ping ``p`` with a point of ping ``q`` in the box ``|dx|, |dy| <= box``."""
    key = (p, q)
    if key not in cache.partner:
        if len(cache.pts[p]) == 0 or len(cache.pts[q]) == 0:
            cache.partner[key] = np.zeros(len(cache.pts[p]), dtype=bool)
        else:
            bound = np.nextafter(box, np.inf)
            d, _ = cache.tree(q).query(cache.pts[p], k=1, p=np.inf, distance_upper_bound=bound)
            cache.partner[key] = np.isfinite(d)
    return cache.partner[key]


def _gate(cache: _RunCache, group: range, v_max: float, dt: float, gap: int) -> dict:
    # the remover's loop over ping pairs, with the reference k-d tree partner test
    return hough._gate(cache, group, v_max, dt, gap, has_partner=_has_partner)


def _counts(cache: _RunCache, grid: HoughGrid, p: int, mask: np.ndarray) -> np.ndarray:
    key = (p, mask.tobytes())
    if key not in cache.counts:
        rows = cache.rows(p)[mask]
        flat = (rows * grid.n_theta + np.arange(grid.n_theta)).ravel()
        cache.counts[key] = np.bincount(flat, minlength=grid.n_rho * grid.n_theta).reshape(grid.shape)
    return cache.counts[key]


def _pairs_supported(rz: np.ndarray, rs: np.ndarray, slot: np.ndarray, cum: np.ndarray, cols: np.ndarray,
                     e: int) -> np.ndarray:
    """For pairs (detection, support): is there a similar line within ``e`` rows of both in one of the
    columns ``cols``, counted in the support's map ``cum[slot]``?

    ``rz, rs (P, len(cols))`` rows, ``slot (P,)``, ``cum (S, n_rho + 1, J)`` the cumulative count of
    qualifying line cells down each of the ``J`` line columns (``cols`` index into those).
    """
    n_rho, J = cum.shape[1] - 1, cum.shape[2]
    lo = np.maximum(np.maximum(rz, rs) - e, 0)
    hi = np.minimum(np.minimum(rz, rs) + e, n_rho - 1)
    ok = hi >= lo
    hi = np.where(ok, hi, lo)
    base = slot[:, None] * (n_rho + 1)
    flat = cum.reshape(-1, J)
    # line cells in rows lo..hi of each column: cum[hi + 1] - cum[lo]
    n = flat[base + hi + 1, cols] - flat[base + lo, cols]
    return np.any(ok & (n > 0), axis=1)


def _check_pairs(zi: np.ndarray, si: np.ndarray, rz_all: np.ndarray, sup_rows, cum_slot: np.ndarray, cum: np.ndarray,
                 e: int, chunk: int = 16) -> np.ndarray:
    """:func:`_pairs_supported` for pairs (detection ``zi``, support ``si``), a few columns at a time: a
    pair is dropped from later columns as soon as one column supports it (dense clutter settles fast)."""
    J = cum.shape[2]
    ok = np.zeros(zi.size, dtype=bool)
    todo = np.arange(zi.size)
    for start in range(0, J, chunk):
        if todo.size == 0:
            break
        cols = np.arange(start, min(start + chunk, J))
        rs = sup_rows(si[todo], cols)
        hit = _pairs_supported(rz_all[zi[todo][:, None], cols[None, :]], rs, cum_slot[si[todo]], cum, cols, e)
        ok[todo[hit]] = True
        todo = todo[~hit]
    return ok


def _inverse(cache: _RunCache, grid: HoughGrid, k: int, group_b: range, kept: dict, counts: dict,
             sim_rows: np.ndarray, sim_cols: np.ndarray, eps: float, reach: np.ndarray, support: str) -> np.ndarray:
    """Keep mask over the valid detections of ping ``k`` (step 6).

    ``sim_rows, sim_cols``: the similar line cells.  ``reach (len(earlier pings),)``: the distance allowed
    to a support of each earlier ping of B.  Only the columns holding a similar line are looked at.
    """
    n_k = len(cache.pts[k])
    keep = np.zeros(n_k, dtype=bool)
    earlier = [p for p in group_b if p < k]
    if n_k == 0 or sim_rows.size == 0 or not earlier:
        return keep
    e = int(np.floor(eps / grid.d_rho + 1e-9))
    cols, col_of = np.unique(sim_cols, return_inverse=True)
    J = cols.size
    similar = np.zeros((grid.n_rho, J), dtype=bool)
    similar[sim_rows, col_of] = True
    n_slots = len(earlier)
    if support == "latest":
        # latest earlier ping of B with a gated point within e rows of each line cell
        latest = np.full((grid.n_rho, J), -1, dtype=np.int16)
        for slot, p in enumerate(earlier):
            latest[counts[p][:, cols] > 0] = slot
        latest = ndimage.maximum_filter1d(latest, size=2 * e + 1, axis=0, mode="constant", cval=-1)
        cum = np.zeros((n_slots, grid.n_rho + 1, J), dtype=np.int32)
        for slot in range(n_slots):
            np.cumsum(similar & (latest == slot), axis=0, out=cum[slot, 1:])
    else:  # "any": every earlier support of the line counts; one map serves all slots
        cum = np.zeros((1, grid.n_rho + 1, J), dtype=np.int32)
        np.cumsum(similar, axis=0, out=cum[0, 1:])
    # candidates: detections of ping k within e rows of some similar line at all
    near_line = ndimage.maximum_filter1d(similar.view(np.uint8), size=2 * e + 1, axis=0, mode="constant", cval=0) > 0
    rz_all = cache.rows(k)[:, cols]
    cand = np.flatnonzero(near_line[rz_all, np.arange(J)].any(axis=1))
    sup_pts = [cache.pts[p][kept[p]] for p in earlier]
    sup_xy = np.concatenate(sup_pts, axis=0)
    if cand.size == 0 or sup_xy.shape[0] == 0:
        return keep
    sup_ping = np.concatenate([np.full(len(sp), p, dtype=np.intp) for p, sp in zip(earlier, sup_pts)])
    sup_index = np.concatenate([np.flatnonzero(kept[p]) for p in earlier])
    sup_slot = np.concatenate([np.full(len(sp), i, dtype=np.intp) for i, sp in enumerate(sup_pts)])
    sup_reach = reach[sup_slot]
    cum_slot = sup_slot if support == "latest" else np.zeros_like(sup_slot)
    ping_rows = {p: cache.rows(p)[:, cols] for p in earlier}

    def sup_rows(idx: np.ndarray, sub: np.ndarray) -> np.ndarray:
        out = np.empty((idx.size, sub.size), dtype=np.intp)
        for p in earlier:
            m = sup_ping[idx] == p
            if m.any():
                out[m] = ping_rows[p][sup_index[idx[m]][:, None], sub[None, :]]
        return out

    tree = cKDTree(sup_xy)
    todo = cand
    done_k = 0
    S = sup_xy.shape[0]
    for k_nn in (1, 4, 32, S):  # rounds of nearest supports; most detections settle in the first
        k_nn = min(k_nn, S)
        if todo.size == 0 or k_nn <= done_k:
            break
        d, idx = tree.query(cache.pts[k][todo], k=k_nn, distance_upper_bound=np.nextafter(reach.max(), np.inf))
        d = d.reshape(todo.size, -1)[:, done_k:]
        idx = idx.reshape(todo.size, -1)[:, done_k:]
        found = np.isfinite(d)
        i_loc, col = np.nonzero(found)
        s_idx = idx[i_loc, col]
        close = d[i_loc, col] <= sup_reach[s_idx]
        i_loc, s_idx = i_loc[close], s_idx[close]
        hit = np.zeros(todo.size, dtype=bool)
        ok = _check_pairs(todo[i_loc], s_idx, rz_all, sup_rows, cum_slot, cum, e)
        hit[i_loc[ok]] = True
        keep[todo[hit]] = True
        # a detection whose every support within reach has been checked is finished
        exhausted = ~found[:, -1]
        todo = todo[~hit & ~exhausted]
        done_k = k_nn
    return keep


def _ref_remove_run(z: np.ndarray, valid: np.ndarray, grid: HoughGrid, window: int = 5, shift: int = 1,
                     v_max: float = 8.0, dt: float = 1.0, gate_gap: int = 2, v_min: int = 3, sim_rho: float = 3.0,
                     sim_theta_deg: float = 3.0, eps: float = 4.0, support_reach=None,
                     support: str = "latest", warmup: str = "drop", trace: list | None = None,
                     run: int = 0) -> np.ndarray:
    """The keep mask of one run, ``z (T, M, 2)``, ``valid (T, M)`` -> ``(T, M)`` bool."""
    if support not in ("latest", "any"):
        raise InputError(f"hough: support must be 'latest' or 'any', got {support!r}")
    T = z.shape[0]
    sr = int(np.floor(sim_rho / grid.d_rho + 1e-9))
    st = int(np.floor(np.deg2rad(sim_theta_deg) / grid.d_theta + 1e-9))
    slots = [np.flatnonzero(valid[k]) for k in range(T)]
    pts = [z[k][s] for k, s in enumerate(slots)]
    cache = _RunCache(pts=pts, grid=grid, slots=slots)
    out = np.zeros(valid.shape, dtype=bool)
    first_output = window - 1 + shift
    gaps = np.arange(window - 1, 0, -1)  # k - p for the earlier pings of B, oldest first
    if support_reach is None:  # two pings at the largest speed
        reach = np.full(gaps.shape, 2.0 * v_max * dt)
    elif support_reach == "gap":  # the largest travel since that ping, at least two pings
        reach = v_max * dt * np.maximum(gaps, 2).astype(float)
    else:
        reach = np.full(gaps.shape, float(support_reach))
    for k in range(T):
        if k < first_output and warmup == "keep":
            out[k] = valid[k]
        if k < window - 1:
            continue
        group_b = range(k - window + 1, k + 1)
        kept = _gate(cache, group_b, v_max, dt, gate_gap)
        counts = {p: _counts(cache, grid, p, kept[p]) for p in group_b}
        n_pings = sum((counts[p] > 0).astype(np.int16) for p in group_b)
        votes = sum(counts[p] for p in group_b)
        cache.peaks[k] = _ref_find_peaks(n_pings, votes, v_min, grid)
        for old in [q for q in cache.peaks if q < k - shift]:
            del cache.peaks[old]
        if k < first_output:
            continue
        ra, ca = cache.peaks[k - shift]
        rb, cb = cache.peaks[k]
        now = counts[k][rb, cb] > 0  # a B peak needs a vote from ping k
        rb, cb = rb[now], cb[now]
        sim = _ref_similar_to(rb, cb, ra, ca, grid, sr, st)
        keep = _inverse(cache, grid, k, group_b, kept, counts, rb[sim], cb[sim], eps, reach, support)
        out[k, slots[k][keep]] = True
        # memo entries later pings can no longer use
        for p in [p for p in cache.trees if p < k - window]:
            del cache.trees[p]
        for p in [p for p in cache.row_cache if p <= k - window]:
            del cache.row_cache[p]
        cache.counts = {key: v for key, v in cache.counts.items() if key[0] > k - window}
        cache.partner = {key: v for key, v in cache.partner.items() if min(key) > k - window}
        if trace is not None:
            rho, theta = grid.rho, grid.theta
            trace.append({
                "run": np.array(run), "ping": np.array(k), "rho": rho, "theta": theta,
                "support_b": n_pings.astype(np.int8),
                "peaks_a": np.stack([rho[ra], theta[ca]], axis=1), "peaks_b": np.stack([rho[rb], theta[cb]], axis=1),
                "similar": np.stack([rho[rb[sim]], theta[cb[sim]]], axis=1),
                "kept": slots[k][keep],
            })
    return out
