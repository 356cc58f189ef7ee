"""The Hough clutter remover (paper 001): both implementations (NumPy, Numba) against the brute-force reference of
the published algorithm (``hough_reference.py``), the pieces against independent references, and the behaviour
(line recovery, clutter rejection, the target kept after a miss, causality, blindness to ``origin``)."""

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from workbench.kernels.backend import numba_available
from workbench.rng import generator
from workbench.types import CLUTTER, InputError, Scans
from workbench_clutter import hough
from workbench_clutter.hough import HOUGH, find_peaks, lines_similar, make_grid, neighbours, remove, similar_to

sys.path.insert(0, str(Path(__file__).parent))
from hough_reference import reference_remove_run  # noqa: E402

AREA = 250.0
BACKENDS = ["numpy"] + (["numba"] if numba_available() else [])


def _reference(scans, **options):
    """The reference's keep mask and output positions for every run."""
    runs = [reference_remove_run(scans.z[b], scans.valid[b], **options) for b in range(scans.batch)]
    return np.stack([r[0] for r in runs]), np.stack([r[1] for r in runs])


def _assert_equal_to_reference(scans, backend, **options):
    keep, z = _reference(scans, **options)
    out = remove(scans, backend=backend, **options)
    np.testing.assert_array_equal(out.valid, keep)
    np.testing.assert_array_equal(np.where(keep[..., None], out.z, 0.0), np.where(keep[..., None], z, 0.0))
    return keep


def _random_scene(seed, runs=2, pings=11, clutter=20, seam=False, area=AREA, pd=0.85):
    """Targets on straight legs (random heading and speed, or along +y: normal at theta ~ 0 / pi) plus uniform
    clutter; detections missing with probability 1 - pd."""
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
    return Scans(z, rng.random(z.shape[:3]) < pd, np.arange(pings, dtype=float))


# -- the fast remover decides exactly as the brute-force reference -------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed, seam, options", [
    (0, False, {}),
    (1, True, {}),
    (2, False, {"support": "latest"}),
    (3, True, {"support": "any"}),
    (4, False, {"vel_gate": None}),
    (5, True, {"require_chain": True}),
    (6, False, {"new_measurements": "projected"}),
    (7, True, {"window": 3, "shift": 3, "v_min": 2}),
    (8, False, {"d_rho": 2.0, "d_theta_deg": 2.0, "eps": 5.0, "v_min": 2, "vel_gate": 1.0}),
    (9, False, {"window": 7, "v_min": 4, "support_reach": 30.0, "warmup": "keep"}),
    (10, True, {"sim_theta_deg": 200.0, "new_measurements": "projected", "support": "latest"}),
])
def test_remover_equals_the_brute_force_reference(backend, seed, seam, options):
    scans = _random_scene(seed, seam=seam)
    keep = _assert_equal_to_reference(scans, backend, **options)
    assert 0 < keep.sum() < scans.valid.sum()


@pytest.mark.parametrize("backend", BACKENDS)
def test_reference_agreement_on_the_k_d_tree_path(backend, monkeypatch):
    # a limit of 0 forces every pair search onto the k-d tree (nearest first, in rounds)
    monkeypatch.setattr(hough, "CELL_PAIRS_PER_POINT", 0)
    for seed, options in ((11, {}), (12, {"support": "latest"}), (13, {"require_chain": True})):
        _assert_equal_to_reference(_random_scene(seed, seam=seed == 12), backend, **options)


@pytest.mark.parametrize("backend", BACKENDS)
def test_points_exactly_on_the_tolerances(backend):
    # integer coordinates on a line along +x (theta = 90 deg, rho = y): supports exactly at the reach
    # (16 units for gaps 1-2, 24 for gap 3), a point exactly eps = 4 off the line, gate boxes exactly 8 wide
    pings = 8
    z = np.zeros((1, pings, 6, 2))
    valid = np.zeros((1, pings, 6), dtype=bool)
    x = np.array([0.0, 8.0, 16.0, 24.0, 32.0, 40.0, 48.0, 56.0]) + 40.0
    z[0, :, 0] = np.column_stack([x, np.full(pings, 100.0)])
    valid[0, :, 0] = True
    valid[0, 5, 0] = False  # a miss: ping 6's support is 16 away (gap 2)
    z[0, 6:, 1] = [[x[6] - 16.0, 104.0], [x[7] + 24.0, 96.0]]  # exactly at reach; 4 off the line
    z[0, :, 2] = np.column_stack([x + 8.0, np.full(pings, 108.0)])  # a parallel line exactly 8 away
    valid[0, :, 1:3] = True
    valid[0, :6, 1] = False
    rng = generator(14, "edges")
    z[0, :, 3:] = rng.integers(0, 250, (pings, 3, 2)).astype(float)
    valid[0, :, 3:] = True
    scans = Scans(z, valid, np.arange(pings, dtype=float))
    for options in ({}, {"support": "latest"}, {"vel_gate": None}, {"eps": 4.0, "sim_rho": 0.0}):
        keep = _assert_equal_to_reference(scans, backend, **options)
    assert keep[0, 6, 0] and keep[0, 7, 0]  # the target after the miss


@pytest.mark.parametrize("backend", BACKENDS)
def test_lines_across_the_seam(backend):
    # targets moving along +-y: the line's normal is theta ~ 0 or ~ pi (rho of either sign)
    rng = generator(15, "seam")
    pings = 11
    z = rng.uniform(0, AREA, (2, pings, 12, 2))
    k = np.arange(pings)
    z[0, :, 0] = np.column_stack([120.0 + 0.02 * k, 20.0 + 4.5 * k])
    z[1, :, 0] = np.column_stack([60.0 - 0.02 * k, 230.0 - 4.5 * k])
    scans = Scans(z, np.ones(z.shape[:3], dtype=bool), np.arange(pings, dtype=float))
    keep = _assert_equal_to_reference(scans, backend)
    assert keep[:, 5:, 0].all()


def test_backends_decide_alike_in_dense_clutter():
    if not numba_available():
        pytest.skip("numba is not installed: one backend only")
    # ~600 and 2,000 detections per ping: the reference is too slow here, the two implementations are compared
    for seed, clutter, area in ((16, 600, 1000.0), (17, 2000, AREA)):
        scans = _random_scene(seed, runs=1, pings=8, clutter=clutter, area=area)
        for options in ({}, {"require_chain": True}):
            a = remove(scans, backend="numba", **options).valid
            b = remove(scans, backend="numpy", **options).valid
            np.testing.assert_array_equal(a, b)
            assert a.any()


# -- behaviour -----------------------------------------------------------------------------------------------


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
    o = scans.origin[:, 5:]
    kept_target = (out.valid[:, 5:] & (o == 0)).sum() / (scans.valid[:, 5:] & (o == 0)).sum()
    kept_clutter = (out.valid[:, 5:] & (o == CLUTTER)).sum() / (scans.valid[:, 5:] & (o == CLUTTER)).sum()
    assert kept_target >= 0.9 and kept_clutter <= 0.4, (kept_target, kept_clutter)
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
    assert out.valid[:, 5:].sum() / scans.valid[:, 5:].sum() < 0.6
    assert not out.valid[:, :5].any()  # warm-up pings give no output


def test_the_target_is_kept_after_a_miss_where_the_global_rule_loses_it():
    # the target misses ping 7; clutter moving far ahead on its line at pings 5-7 (gated by its own steps) is
    # the line's latest support anywhere at ping 7 (the previous rule): the target at ping 8 is not within 16 of
    # it and is lost; the local rule keeps it through its own detection at ping 6
    pings = 10
    k = np.arange(pings)
    z = np.zeros((1, pings, 3, 2))
    z[0, :, 0] = np.column_stack([40.0 + 4.0 * k, 60.0 + 2.0 * k])
    z[0, :, 1] = np.column_stack([40.0 + 4.0 * (k + 20), 60.0 + 2.0 * (k + 20)])  # the far clutter on the line
    z[0, :, 2] = generator(18, "far").uniform(0, AREA, (pings, 2))
    valid = np.ones((1, pings, 3), dtype=bool)
    valid[0, 7, 0] = False
    valid[0, :5, 1] = False
    valid[0, 8:, 1] = False
    scans = Scans(z, valid, np.arange(pings, dtype=float))
    for backend in BACKENDS:
        assert remove(scans, backend=backend).valid[0, 8, 0]
    assert not remove(scans, support="latest").valid[0, 8, 0]
    assert _reference(scans)[0][0, 8, 0] and not _reference(scans, support="latest")[0][0, 8, 0]


def test_projection_moves_kept_points_onto_their_line():
    # a target on a straight line with noise across it; every kept detection is moved along the normal of the
    # nearest similar line onto that line (the accumulator cell's (rho, theta))
    scans = _scene((40.0, 100.0), (4.0, 2.0), pings=10, clutter=5, sigma=1.0, seed=19)
    trace = []
    out = remove(scans, new_measurements="projected", trace=trace)
    moved = 0
    for t in trace:
        k = int(t["ping"])
        lines = t["similar"]
        for m in t["kept"]:
            x, y = scans.z[0, k, m]
            d = x * np.cos(lines[:, 1]) + y * np.sin(lines[:, 1]) - lines[:, 0]
            rho, theta = lines[np.argmin(np.abs(d))]
            nx, ny = out.z[0, k, m]
            assert abs(nx * np.cos(theta) + ny * np.sin(theta) - rho) < 1e-9  # on the line
            shift = np.array([nx - x, ny - y])
            assert abs(shift @ [-np.sin(theta), np.cos(theta)]) < 1e-9  # along its normal
            moved += np.hypot(*shift) > 0
    assert moved >= 3
    plain = remove(scans)  # the default never moves a detection
    np.testing.assert_array_equal(plain.z[plain.valid], scans.z[plain.valid])


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
    for bad, match in (({"window": 1}, "window"), ({"d_theta_deg": 7.0}, "d_theta"), ({"warmup": "maybe"}, "warmup"),
                       ({"support": "nearest"}, "support"), ({"new_measurements": "moved"}, "new_measurements"),
                       ({"support_reach": "gap"}, "support_reach"), ({"backend": "fortran"}, "backend"),
                       ({"require_chain": True, "support": "any"}, "require_chain"), ({"sigma_pos": 0.0}, "sigma_pos")):
        with pytest.raises(InputError, match=match):
            remove(scans, **bad)
    assert set(HOUGH.params) == {p.name for p in HOUGH.parameters}


# -- pieces against independent references --------------------------------------------------------------------


def _reference_max3(score):
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
        ref = (support >= 3) & (score >= _reference_max3(score))
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
    assert np.array_equal(got, ref) and got[:40].any()


def test_lines_similar_identifies_the_seam_equivalence():
    # (rho, theta) and (-rho, theta + pi) are the same line
    assert lines_similar([50.0], [np.deg2rad(1.0)], [-51.0], [np.deg2rad(178.0)], 3.0, np.deg2rad(3.0))[0, 0]
    assert not lines_similar([50.0], [np.deg2rad(1.0)], [51.0], [np.deg2rad(178.0)], 3.0, np.deg2rad(3.0))[0, 0]


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


def test_rho_index_in_blocks_equals_one_pass():
    rng = generator(23, "rho-index")
    pts = rng.uniform(-3000, 3000, (1300, 2))
    for d_rho, d_theta in ((1.0, 1.0), (0.7, 2.0), (2.0, 0.5)):
        grid = make_grid(d_rho, d_theta, 4300.0)
        th = grid.theta
        want = (np.rint((pts[:, :1] * np.cos(th) + pts[:, 1:2] * np.sin(th)) / d_rho) + grid.off).astype(np.int32)
        for block in (1, 7, 512, 5000):
            assert np.array_equal(grid.rho_index(pts, block=block), want)


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
def test_trailing_zero_table_of_the_kernel():
    from workbench_clutter.hough_numba import CTZ, DE_BRUIJN

    # the table against the position of the only set bit, with NumPy's wrapping 64-bit product
    with np.errstate(over="ignore"):
        for i in range(64):
            low = np.uint64(1) << np.uint64(i)
            assert CTZ[int((low * DE_BRUIJN) >> np.uint64(58))] == i == int(low).bit_length() - 1


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
def test_compiled_helpers_equal_their_numpy_twins():
    from workbench_clutter import hough_numba

    rng = generator(24, "twins")
    # vote rows: the same operations in the same order as HoughGrid.rho_index, ties (x + 0.5) included
    for d_rho, d_theta in ((1.0, 1.0), (0.7, 2.0), (2.0, 0.5)):
        grid = make_grid(d_rho, d_theta, 6000.0)
        pts = np.concatenate([rng.uniform(-4000, 4000, (3000, 2)), rng.integers(-300, 300, (2000, 2)) + 0.5,
                              rng.integers(-300, 300, (2000, 2)).astype(float)])
        want = grid.rho_index(pts)
        got = hough_numba.rho_rows(pts, np.cos(grid.theta), np.sin(grid.theta), grid.d_rho, grid.off,
                                   np.empty_like(want))
        np.testing.assert_array_equal(got, want)
    # votes added and taken away, against np.add.at / np.subtract.at; the group sums against numpy
    grid = make_grid(1.0, 1.0, 400.0)
    rows = grid.rho_index(rng.uniform(0, 250, (500, 2)))
    which = np.flatnonzero(rng.random(500) < 0.6)
    counts = np.zeros(grid.n_rho * grid.n_theta, dtype=np.uint16)
    hough_numba.add_votes(counts, rows, which, grid.n_theta, True)
    want = np.zeros_like(counts)
    np.add.at(want, (rows[which] * grid.n_theta + np.arange(grid.n_theta)).ravel(), 1)
    np.testing.assert_array_equal(counts, want)
    hough_numba.add_votes(counts, rows, which[:100], grid.n_theta, False)
    np.subtract.at(want, (rows[which[:100]] * grid.n_theta + np.arange(grid.n_theta)).ravel(), 1)
    np.testing.assert_array_equal(counts, want)
    n_pings, votes = np.zeros(counts.size, np.uint8), np.zeros(counts.size, np.uint32)
    hough_numba.accumulate(n_pings, votes, counts)
    hough_numba.accumulate(n_pings, votes, counts)
    np.testing.assert_array_equal(n_pings, 2 * (counts > 0))
    np.testing.assert_array_equal(votes, 2 * counts.astype(np.uint32))


def test_sparse_peaks_and_similar_cells_equal_the_grid_filters():
    """Few candidate cells take the neighbourhood look-up instead of the pass over the grid: held to the same
    references as the dense filters (the maximum filter with the seam, the closed-form similarity)."""
    grid = make_grid(1.0, 1.0, 60.0)  # 180 columns
    rng = generator(9, "sparse-peaks")
    for _ in range(10):
        support = np.zeros(grid.shape, dtype=np.int16)
        votes = np.zeros(grid.shape, dtype=np.int32)
        cells = rng.integers(0, support.size, 150)
        support.ravel()[cells] = rng.integers(1, 6, cells.size)
        votes.ravel()[cells] = support.ravel()[cells] + rng.integers(0, 3, cells.size)
        # clusters across the seam and at the rho edges
        for r, c in ((5, 0), (grid.n_rho - 1, 179), (0, 1), (grid.n_rho - 6, 179)):
            support[r, c], votes[r, c] = 4, 7
        support[grid.n_rho - 1 - 5, 179], votes[grid.n_rho - 1 - 5, 179] = 4, 8  # beats (5, 0) across the seam
        assert 36 * np.count_nonzero(support >= 3) <= support.size  # the sparse path
        rows, cols = find_peaks(support, votes, 3, grid)
        score = support + votes / (votes.max() + 1.0)
        ref = (support >= 3) & (score >= _reference_max3(score))
        got = np.zeros(grid.shape, dtype=bool)
        got[rows, cols] = True
        assert np.array_equal(got, ref) and not got[5, 0] and got[grid.n_rho - 6, 179]
    ra, ca = rng.integers(0, grid.n_rho, 40), rng.integers(0, grid.n_theta, 40)
    rb, cb = rng.integers(0, grid.n_rho, 20), rng.integers(0, grid.n_theta, 20)
    ca[:10] = np.arange(10) % 3  # a in columns 0 .. 2, b in column 179 with rho negated: across the seam
    rb[:10], cb[:10] = grid.n_rho - 1 - ra[:10], grid.n_theta - 1
    ra[10:14], ca[10:14] = rng.integers(5, grid.n_rho - 5, 4), rng.integers(5, grid.n_theta - 5, 4)
    rb[10:14], cb[10:14] = ra[10:14] + 3, ca[10:14] - 3  # exactly on the tolerances
    got = similar_to(rb, cb, ra, ca, grid, 3, 3)
    rho, theta = grid.rho, grid.theta
    ref = lines_similar(rho[ra], theta[ca], rho[rb], theta[cb], 3.0, np.deg2rad(3.0) + 1e-9).any(axis=0)
    assert 4 * rb.size * 49 <= grid.n_rho * grid.n_theta  # the sparse path
    assert np.array_equal(got, ref) and got[:14].all()
