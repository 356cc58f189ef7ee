"""The Hough clutter remover (paper 001): line recovery, clutter rejection, the theta = 0 / pi seam,
peaks and similarity against independent references, causality and parameter checks."""

import numpy as np
import pytest
from scipy import ndimage

from workbench.rng import generator
from workbench.types import CLUTTER, InputError, Scans
from workbench_clutter.hough import (HOUGH, find_peaks, lines_similar, make_grid, neighbours, remove,
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
