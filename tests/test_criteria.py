"""The criterion record and the statistics that build it: verdicts from hand-made run data, exact binomial
intervals against known values, bootstrap coverage, disjoint replications; a bool verdict refused."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import binom, ttest_1samp

from workbench.criteria import (
    VERDICTS,
    Criterion,
    Precondition,
    binomial_interval,
    bootstrap_interval,
    criterion_equivalent,
    criterion_from_counts,
    criterion_from_runs,
    equivalence_band,
    judge,
    judge_equivalent,
    reference_converged,
    replication_rate,
    rows_track,
    vectorised,
)


# -- the record: verdict words only, and quick-mode marking --------------------------------------------------

def test_a_verdict_is_one_of_the_words_and_a_bool_is_refused_by_name():
    yes = Criterion("1", "mean MSE below 100", "met", "worst 3.2")
    no = Criterion("2", "ordering C < B < A", "not met", "B < C")
    assert (yes.verdict, yes.met, yes.detail) == ("met", True, "worst 3.2")
    assert (no.verdict, no.met) == ("not met", False)
    assert yes.n is None and yes.interval is None and not yes.indicative and yes.statistics == ""
    for bad in (True, np.bool_(False), 1, None, "passed"):
        with pytest.raises(ValueError, match=r"criterion '3': the verdict must be one of .*\(a string\)"):
            Criterion("3", "x", bad)
    with pytest.raises(ValueError, match="criterion '4': the verdict must be one of .* got True \\(bool\\)"):
        Criterion("4", "x", True)


def test_as_indicative_never_leaves_met_and_remembers_the_quick_verdict():
    met = Criterion("1", "x", "met", interval=(1.4, 1.6), n=4).as_indicative()
    assert (met.verdict, met.met, met.indicative, met.quick_verdict) == ("inconclusive", False, True, "met")
    assert met.interval == (1.4, 1.6) and met.n == 4
    not_met = Criterion("2", "x", "not met").as_indicative()
    assert (not_met.verdict, not_met.quick_verdict, not_met.met) == ("not met", "not met", False)
    assert met.as_indicative() == met  # marking twice keeps the first quick verdict
    assert Criterion("3", "x", "not attainable").as_indicative().verdict == "not attainable"


def test_to_dict_is_json_ready_and_round_trips():
    c = Criterion("C2", "ratio", "inconclusive", "d", ours=np.float64(1.31), published={"A": 332.0}, n=np.int64(20),
                  interval=(np.float64(1.1), 1.5), threshold=">= 1.3", replication=(41, 50)).as_indicative()
    d = json.loads(json.dumps(c.to_dict()))
    assert d["verdict"] == "inconclusive" and d["met"] is False and d["indicative"] is True
    assert d["interval"] == [1.1, 1.5] and d["n"] == 20 and d["published"] == {"A": 332.0}
    assert d["extra"] == {"quick_verdict": "inconclusive"}
    back = Criterion.from_dict(d)
    assert back == c and isinstance(back.interval, tuple) and back.replication == (41, 50)


def test_the_numbers_travel_as_fields_through_json_and_the_sentence_is_made_from_them():
    runs = criterion_from_runs("R", "mean >= 1", np.linspace(0.5, 2.5, 40), np.mean, 1.0, ">=", min_n=20,
                               resamples=500, detail="forty runs")
    counts = criterion_from_counts("K", "share >= 0.5", 30, 40, 0.5, ">=", min_n=20, detail="thirty of forty")
    for c in (runs, counts):
        d = json.loads(json.dumps(c.to_dict()))
        assert d["statistics"] == c.statistics and d["detail"] == c.detail
        back = Criterion.from_dict(d)  # "statistics" is derived, not read back
        assert back == c and back.statistics == c.statistics
    assert (runs.level, runs.resamples, runs.count) == (0.95, 500, None)
    assert (counts.level, counts.resamples, counts.count) == (0.95, None, 30)
    # the sentence follows the fields, not a copy of words: another threshold reads in it
    assert replace(runs, threshold=">= 0.9").statistics.endswith("passes if >= 0.9; needs n >= 20")
    # a summary.json written before the fields existed (its sentence inside the detail, a "statistics" string)
    old = {"id": "2", "text": "t", "verdict": "met", "detail": "d; ours 1.5, ...", "statistics": "ours 1.5, ...",
           "n": 30, "interval": [1.4, 1.6], "min_n": 20, "method": "percentile bootstrap, 2000 resamples"}
    read = Criterion.from_dict(old)
    assert (read.verdict, read.detail, read.level, read.statistics) == ("met", "d; ours 1.5, ...", None, "")
    for bad in ({"level": 95}, {"count": 2.5}, {"resamples": -1}, {"count": True}, {"resamples": "2000"}):
        with pytest.raises(ValueError, match="criterion 'X': "):
            Criterion("X", "x", "met", **bad)


# -- judge ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("interval, threshold, direction, verdict", [
    ((1.4, 1.6), 1.3, ">=", "met"),
    ((1.3, 1.6), 1.3, ">=", "met"),           # the boundary passes ">="
    ((1.3, 1.6), 1.3, ">", "inconclusive"),   # ... but not ">"
    ((1.0, 1.2), 1.3, ">=", "not met"),
    ((1.2, 1.4), 1.3, ">=", "inconclusive"),  # straddles
    ((0.05, 0.09), 0.1, "<", "met"),
    ((0.1, 0.2), 0.1, "<", "not met"),
    ((0.1, 0.2), 0.1, "<=", "inconclusive"),
    ((0.08, 0.12), 0.1, "<=", "inconclusive"),
    ((0.70, 0.85), (0.60, 0.95), "within", "met"),
    ((0.20, 0.50), (0.60, 0.95), "within", "not met"),
    ((0.96, 0.99), (0.60, 0.95), "within", "not met"),
    ((0.50, 0.70), (0.60, 0.95), "within", "inconclusive"),
    ((math.nan, math.nan), 1.0, ">=", "inconclusive"),
    (None, 1.0, ">=", "inconclusive"),
])
def test_judge_reads_the_whole_interval(interval, threshold, direction, verdict):
    assert judge(interval, threshold, direction) == verdict


def test_judge_is_inconclusive_below_min_n_even_for_a_clear_interval():
    assert judge((5.0, 6.0), 1.0, ">=", n=19, min_n=20) == "inconclusive"
    assert judge((5.0, 6.0), 1.0, ">=", n=20, min_n=20) == "met"
    assert judge((5.0, 6.0), 1.0, ">=", n=None, min_n=20) == "inconclusive"
    with pytest.raises(ValueError, match="direction"):
        judge((1.0, 2.0), 1.0, "=>")
    with pytest.raises(ValueError, match="low, high"):
        judge((1.0, 2.0), 1.0, "within")


# -- exact binomial interval ------------------------------------------------------------------------------

@pytest.mark.parametrize("k, n, lo, hi", [
    (0, 10, 0.0, 0.3085),     # upper = 1 - 0.025**(1/10)
    (10, 10, 0.6915, 1.0),    # lower = 0.025**(1/10)
    (1, 10, 0.0025, 0.4450),
    (5, 10, 0.1871, 0.8129),
])
def test_binomial_interval_matches_known_clopper_pearson_values(k, n, lo, hi):
    got = binomial_interval(k, n)
    assert got == pytest.approx((lo, hi), abs=1e-4)


def test_binomial_interval_closed_form_at_zero_and_exact_coverage():
    for n in (1, 7, 20, 50):
        assert binomial_interval(0, n, 0.9)[1] == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-10)
    # Clopper-Pearson is conservative: for every p the exact probability of covering it is >= the level.
    n = 20
    bounds = [binomial_interval(k, n) for k in range(n + 1)]
    for p in np.linspace(0.01, 0.99, 99):
        cover = sum(binom.pmf(k, n, p) for k, (lo, hi) in enumerate(bounds) if lo <= p <= hi)
        assert cover >= 0.95 - 1e-12, p
    assert binomial_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError):
        binomial_interval(11, 10)


# -- bootstrap --------------------------------------------------------------------------------------------

def _coverage(level, datasets=200, n=40, mean=5.0, sd=2.0):
    rng = np.random.default_rng(20240612)
    hits = 0
    for i in range(datasets):
        lo, hi = bootstrap_interval(rng.normal(mean, sd, n), np.mean, level=level, resamples=1000, seed=i)
        hits += lo <= mean <= hi
    return hits / datasets


@pytest.mark.parametrize("level", [0.95, 0.5])
def test_bootstrap_interval_covers_a_known_mean_at_about_its_level(level):
    coverage = _coverage(level)
    # 3 binomial standard deviations over 200 datasets, plus 0.02 for the percentile method's known
    # small under-coverage at n = 40.
    tol = 3 * math.sqrt(level * (1 - level) / 200) + 0.02
    assert abs(coverage - level) <= tol, coverage


def test_bootstrap_interval_of_a_mean_matches_the_normal_interval_for_many_runs():
    x = np.random.default_rng(7).normal(10.0, 3.0, 2000)
    lo, hi = bootstrap_interval(x, seed=1)
    half = 1.959964 * x.std(ddof=1) / math.sqrt(x.size)
    assert (hi - lo) / 2 == pytest.approx(half, rel=0.1)
    assert (lo + hi) / 2 == pytest.approx(x.mean(), abs=0.2 * half)


def test_bootstrap_resamples_paired_samples_with_the_same_runs():
    c = np.random.default_rng(3).exponential(100.0, 30)
    a = 2.0 * c  # A is exactly twice C run by run: every paired resample gives a ratio of exactly 2

    def ratio(a_, c_):
        assert np.allclose(a_, 2.0 * c_)  # the same run indices were drawn for both
        return a_.mean() / c_.mean()

    assert bootstrap_interval((a, c), ratio, seed=0) == pytest.approx((2.0, 2.0))
    # the same data resampled independently would not be so sure: the pairing is what narrows it
    rng = np.random.default_rng(0)
    independent = [a[rng.integers(0, 30, 30)].mean() / c[rng.integers(0, 30, 30)].mean() for _ in range(2000)]
    assert np.quantile(independent, 0.975) - np.quantile(independent, 0.025) > 0.5


def test_bootstrap_is_seeded_handles_rows_and_refuses_to_guess_from_one_run():
    x = np.random.default_rng(1).normal(size=25)
    assert bootstrap_interval(x, seed=4) == bootstrap_interval(x, seed=4)
    assert bootstrap_interval(x, seed=4) != bootstrap_interval(x, seed=5)
    assert bootstrap_interval(x, rng=np.random.default_rng(4)) == bootstrap_interval(x, seed=4)
    # the fast (vectorised) path and the per-resample path agree
    assert bootstrap_interval(x, np.median, seed=2) == pytest.approx(
        bootstrap_interval(x, lambda v: float(np.median(v)), seed=2))
    rows = np.tile(x[:, None], (1, 3))  # (runs, time): resampled by run
    assert bootstrap_interval(rows, lambda e: e.mean(), seed=4) == pytest.approx(bootstrap_interval(x, seed=4))
    assert all(math.isnan(v) for v in bootstrap_interval([1.0], seed=0))
    assert all(math.isnan(v) for v in bootstrap_interval(x, lambda v: np.nan, seed=0))


def _loop_interval(samples, statistic, *, level=0.95, resamples=2000, seed=0):
    """The bootstrap as it was before batching, kept as the reference: one call of the statistic per resample."""
    arrays = tuple(np.asarray(a) for a in samples) if isinstance(samples, tuple) else (np.asarray(samples),)
    idx = np.random.default_rng(seed).integers(0, arrays[0].shape[0], size=(resamples, arrays[0].shape[0]))
    stats = np.array([float(statistic(*(a[i] for a in arrays))) for i in idx])
    if not np.all(np.isfinite(stats)):
        return (math.nan, math.nan)
    lo, hi = np.quantile(stats, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return (float(lo), float(hi))


def _batched_statistics_cases():
    rng = np.random.default_rng(11)
    runs, steps = 57, 40
    a, c = rng.exponential(3.0, runs), rng.exponential(2.0, runs)
    err = rng.gamma(2.0, 1.0, (runs, steps))
    meas = rng.gamma(2.2, 1.0, (runs, steps))
    meas[rng.random((runs, steps)) < 0.1] = np.nan  # scans without a gated detection
    levels = tuple(rng.gamma(2.0, s, (runs, 3)) for s in (1.0, 1.5, 2.0))

    def below(e, m):
        with np.errstate(invalid="ignore"):
            mm = np.nanmean(m, axis=0)
        return float(np.mean(e.mean(axis=0) < mm))

    def below_many(e, m):
        with np.errstate(invalid="ignore"):
            mm = np.nanmean(m, axis=1)
        return np.mean(e.mean(axis=1) < mm, axis=1)

    def below_counts(w, e, m):  # w: (resamples, runs) counts; nanmean as weighted sums
        finite = np.isfinite(m)
        with np.errstate(invalid="ignore"):
            mm = (w @ np.where(finite, m, 0.0)) / (w @ finite)
        return np.mean((w @ e) / e.shape[0] < mm, axis=1)

    def worst_level(*lv):
        return float(max(max(m[1] / m[0], m[2] / m[1]) for m in (x.mean(axis=0) for x in lv)))

    def worst_level_many(*lv):
        return np.max(np.stack([np.maximum(m[:, 1] / m[:, 0], m[:, 2] / m[:, 1])
                                for m in (x.mean(axis=1) for x in lv)], axis=1), axis=1)

    return {
        "paired ratio of means": ((a, c), vectorised(lambda x, y: float(x.mean() / y.mean()),
                                                      lambda x, y: x.mean(axis=1) / y.mean(axis=1))),
        "share of scans below (runs x steps, NaN)": ((err, meas), vectorised(below, below_many)),
        "max over levels of column ratios": (levels, vectorised(worst_level, worst_level_many)),
        "ratio of column medians": (levels[0], vectorised(
            lambda x: float(np.median(x, axis=0)[2] / np.median(x, axis=0)[0]),
            lambda x: np.median(x, axis=1)[:, 2] / np.median(x, axis=1)[:, 0])),
        "standard deviation": (a, vectorised(lambda x: float(x.std(ddof=1)), lambda x: x.std(axis=1, ddof=1))),
        "share of scans below, from resample counts": ((err, meas), vectorised(below, below_counts, given="counts")),
        "max over levels of column ratios, from the means": (levels, vectorised(
            worst_level, lambda *m: np.max(np.stack([np.maximum(x[:, 1] / x[:, 0], x[:, 2] / x[:, 1]) for x in m],
                                                    axis=1), axis=1), given="means")),
        "paired ratio of means, from the means": ((a, c), vectorised(lambda x, y: float(x.mean() / y.mean()),
                                                                      lambda x, y: x / y, given="means")),
    }


@pytest.mark.parametrize("case", list(_batched_statistics_cases()))
@pytest.mark.parametrize("level", [0.95, 0.9])
def test_a_vectorised_statistic_gives_the_per_resample_loops_interval(case, level):
    samples, stat = _batched_statistics_cases()[case]
    fast = bootstrap_interval(samples, stat, level=level, resamples=700, seed=3)
    slow = _loop_interval(samples, stat.one, level=level, resamples=700, seed=3)
    assert np.all(np.isfinite(slow)) and slow[0] < slow[1]
    assert fast == pytest.approx(slow, rel=1e-12, abs=0.0)
    # criterion_from_runs takes the same path: its ours is the plain statistic's
    c = criterion_from_runs("x", "x", samples, stat, 0.0, ">", min_n=2, level=level, resamples=700, seed=3)
    assert c.interval == pytest.approx(slow, rel=1e-12, abs=0.0)
    assert c.ours == stat.one(*(samples if isinstance(samples, tuple) else (samples,)))


def test_a_batched_form_that_disagrees_or_gives_the_wrong_shape_is_refused_by_name():
    x = np.random.default_rng(2).normal(size=30)

    def spread(v):
        return float(v.max() - v.min())

    with pytest.raises(ValueError, match="batched form of the statistic .*spread disagrees"):
        bootstrap_interval(x, vectorised(spread, lambda v: v.std(axis=1)), resamples=50)
    with pytest.raises(ValueError, match="spread gave shape \\(50, 30\\) for 50 resamples"):
        bootstrap_interval(x, vectorised(spread, lambda v: v - v.min()), resamples=50)
    with pytest.raises(ValueError, match="given one of"):
        vectorised(spread, np.mean, given="runs")
    # means from counts take a non-finite run only where a resample draws it, as the per-resample loop does (a
    # weighted sum would make 0 x inf a NaN for every resample): the same intervals, a number or not
    y = x.copy()
    y[4] = np.inf
    ratio = vectorised(lambda u, v: float(u.mean() / v.mean()), lambda u, v: u / v, given="means")
    fast, slow = (bootstrap_interval((x, y), ratio, resamples=200), _loop_interval((x, y), ratio.one, resamples=200))
    assert np.all(np.isfinite(slow)) and fast == pytest.approx(slow, rel=1e-12)  # x / inf = 0 where drawn
    fast, slow = (bootstrap_interval((y, x), ratio, resamples=200), _loop_interval((y, x), ratio.one, resamples=200))
    assert all(math.isnan(v) for v in fast + slow)


# -- criteria from hand-made run data ---------------------------------------------------------------------

def test_criterion_from_runs_met_not_met_and_inconclusive():
    wiggle = np.tile([-0.01, 0.01], 15)  # 30 runs
    met = criterion_from_runs("2", "A/C >= 1.3", 1.5 + wiggle, np.mean, 1.3, ">=", min_n=20, published=1.9)
    assert (met.verdict, met.n, met.published, met.threshold) == ("met", 30, 1.9, ">= 1.3")
    assert met.ours == pytest.approx(1.5) and 1.49 <= met.interval[0] <= met.interval[1] <= 1.51
    # the numbers are the record's fields; the detail is left to the caller's words (none given here)
    assert (met.min_n, met.level, met.resamples, met.count, met.detail) == (20, 0.95, 2000, None, "")
    lo, hi = met.interval
    assert met.statistics == (f"ours {met.ours:.4g}, 95 % interval [{lo:.4g}, {hi:.4g}] (percentile bootstrap over "
                              "n = 30 runs, 2000 resamples); passes if >= 1.3; needs n >= 20")

    not_met = criterion_from_runs("2", "A/C >= 1.3", 1.0 + wiggle, np.mean, 1.3, ">=", min_n=20)
    assert not_met.verdict == "not met" and not not_met.met

    straddle = criterion_from_runs("2", "A/C >= 1.3", np.linspace(1.0, 1.6, 30), np.mean, 1.3, ">=", min_n=20)
    assert straddle.ours == pytest.approx(1.3)
    assert straddle.interval[0] < 1.3 < straddle.interval[1] and straddle.verdict == "inconclusive"

    too_few = criterion_from_runs("2", "A/C >= 1.3", [2.0, 2.1, 1.9, 2.0, 2.0], np.mean, 1.3, ">=", min_n=20)
    assert too_few.interval[0] > 1.3 and too_few.n == 5 and too_few.verdict == "inconclusive"


def test_criterion_from_runs_on_a_paired_ratio_within_a_range():
    c = np.random.default_rng(11).exponential(200.0, 40)
    crit = criterion_from_runs("R", "A/C in 1.3..2.5", (1.8 * c, c), lambda a, c_: a.mean() / c_.mean(),
                               (1.3, 2.5), "within", min_n=20, detail="A and C on the same {40} runs")
    # the explanation is kept as given (braces and all: it is not a format); the numbers are fields
    assert crit.verdict == "met" and crit.ours == pytest.approx(1.8) and crit.detail == "A and C on the same {40} runs"
    assert crit.interval == pytest.approx((1.8, 1.8)) and crit.n == 40
    with pytest.raises(ValueError, match="detail is the explanation in words \\(a str\\), got int"):
        criterion_from_runs("R", "x", c, np.mean, 1.0, ">=", min_n=20, detail=3)
    assert crit.threshold == "within [1.3, 2.5]"


def test_criterion_from_counts_uses_the_exact_interval():
    zero = criterion_from_counts("L", "lost runs <= 50 %", 0, 10, 0.5, "<=", min_n=10)
    assert zero.verdict == "met" and zero.interval == pytest.approx((0.0, 0.3085), abs=1e-4) and zero.ours == 0.0
    some = criterion_from_counts("L", "lost runs <= 50 %", 3, 10, 0.5, "<=", min_n=10)
    assert some.verdict == "inconclusive" and (some.count, some.n, some.level, some.detail) == (3, 10, 0.95, "")
    lo, hi = binomial_interval(3, 10)
    assert some.statistics == (f"ours 3/10 = 0.3, 95 % interval [{lo:.4g}, {hi:.4g}] (exact, Clopper-Pearson); "
                               "passes if <= 0.5; needs n >= 10")
    many = criterion_from_counts("L", "lost runs <= 50 %", 9, 10, 0.5, "<=", min_n=10)
    assert many.verdict == "not met"
    assert criterion_from_counts("L", "x", 0, 5, 0.5, "<=", min_n=10).verdict == "inconclusive"


# -- replication of the paper's protocol ------------------------------------------------------------------

def test_replication_rate_uses_disjoint_batches_of_the_protocol_size():
    runs = np.arange(100)
    seen = []

    def record(batch):
        seen.append(np.asarray(batch))
        return True

    assert replication_rate(runs, 20, record, replications=3, seed=1) == (3, 3)
    assert [len(b) for b in seen] == [20, 20, 20]
    assert len(np.unique(np.concatenate(seen))) == 60  # no run used twice
    seen.clear()
    assert replication_rate(runs, 20, record, replications=50, seed=1) == (5, 5)  # only 5 batches fit
    assert sorted(np.concatenate(seen).tolist()) == list(range(100))
    assert replication_rate(runs, 200, record, replications=5) == (0, 0)


def test_replication_rate_counts_how_often_the_criterion_holds():
    runs = np.arange(100)
    # run 0 is in exactly one of the five disjoint batches, whatever the shuffle
    for seed in range(5):
        assert replication_rate(runs, 20, lambda b: 0 in b, replications=5, seed=seed) == (1, 5)
    # paired arrays are cut by the same run indices
    assert replication_rate((runs, 2 * runs), 10, lambda a, b: np.array_equal(b, 2 * a), 10, seed=3) == (10, 10)
    # a criterion that holds on a batch's mean: 20-run batches of N(0.3, 1) beat 0 often but not always
    x = np.random.default_rng(5).normal(0.3, 1.0, 1000)
    holds, of = replication_rate(x, 20, lambda b: b.mean() > 0, replications=50, seed=0)
    assert of == 50 and 30 <= holds <= 50  # P(mean of 20 > 0) = Phi(0.3 * sqrt(20)) = 0.91
    assert replication_rate(x, 20, lambda b: b.mean() > 0, replications=50, seed=0) == (holds, of)


# -- preconditions: "not judgeable" ------------------------------------------------------------------------

def test_a_failed_precondition_makes_every_verdict_not_judgeable():
    fails = Precondition("judged rows track", False, "lost runs A 20/20 (100 %)")
    holds = Precondition("reference converged", True, "1.001 [0.99, 1.01]")
    assert "not judgeable" in VERDICTS
    for verdict in ("met", "not met", "inconclusive", "not attainable"):
        c = Criterion("1", "x", verdict, preconditions=(holds, fails))
        assert c.verdict == "not judgeable" and not c.met
        assert c.failed_preconditions == (fails,)
        assert c.verdict_if_judged == verdict
    # all preconditions hold: the verdict stands
    assert Criterion("1", "x", "met", preconditions=(holds,)).verdict == "met"
    # no path back to "met" while a precondition fails: a replaced verdict is overridden again
    from dataclasses import replace

    c = Criterion("1", "x", "met", preconditions=(fails,))
    again = replace(c, verdict="not attainable")
    assert again.verdict == "not judgeable" and again.verdict_if_judged == "not attainable"
    # quick mode keeps it; summary.json round-trips it, preconditions and numbers included
    assert c.as_indicative().verdict == "not judgeable"
    d = json.loads(json.dumps(c.to_dict()))
    assert d["verdict"] == "not judgeable" and d["met"] is False
    assert d["preconditions"] == [{"name": "judged rows track", "holds": False, "detail": "lost runs A 20/20 (100 %)",
                                   "values": {}}]
    assert Criterion.from_dict(d) == c
    # "not judgeable" must name a failed precondition
    with pytest.raises(ValueError, match="needs a failed precondition"):
        Criterion("1", "x", "not judgeable")
    with pytest.raises(ValueError, match="needs a failed precondition"):
        Criterion("1", "x", "not judgeable", preconditions=(holds,))


def test_rows_track_counts_the_lost_runs_of_each_row():
    lost = {"A": np.ones(20, dtype=bool), "B": np.r_[np.ones(2, bool), np.zeros(18, bool)],
            "C": np.zeros(20, dtype=bool)}
    p = rows_track(lost, 0.10)
    assert not p.holds and p.name == "judged rows track"
    assert p.values["rows"] == {"A": {"lost": 20, "runs": 20, "share": 1.0}, "B": {"lost": 2, "runs": 20, "share": 0.1},
                                "C": {"lost": 0, "runs": 20, "share": 0.0}}
    assert p.values["above"] == ["A"] and p.values["max_share"] == 0.1  # B at exactly the share is allowed
    assert p.detail == ("lost runs A 20/20 (100 %), B 2/20 (10 %), C 0/20 (0 %); each judged row may lose at most "
                        "10 % of its runs; above it: A")
    assert rows_track({"B": lost["B"], "C": lost["C"]}, 0.10).holds
    assert not rows_track({"B": lost["B"]}, 0.05).holds
    assert not rows_track({"A": np.zeros(0, dtype=bool)}, 0.5).holds  # a row with no runs does not track
    assert rows_track({"A": [0, 1, 0, 0]}, 0.25).values["rows"]["A"]["lost"] == 1  # 0/1 flags read as bools
    with pytest.raises(ValueError, match="max_share"):
        rows_track(lost, 1.5)
    with pytest.raises(ValueError, match="one bool per run"):
        rows_track({"A": np.zeros((2, 3), dtype=bool)}, 0.5)


def test_reference_converged_is_a_paired_ratio_within_the_tolerance():
    from scipy.stats import bootstrap

    rng = np.random.default_rng(3)
    at_4n = rng.lognormal(3.0, 0.4, 100)
    # 4N particles lower every run's error by the same 8 %: every resample's ratio is 1.08 exactly
    p = reference_converged(1.08 * at_4n, at_4n, particles=5000, tolerance=0.05, min_n=100)
    assert not p.holds and p.values["ratio"] == pytest.approx(1.08)
    assert p.values["interval"] == pytest.approx([1.08, 1.08]) and p.values["particles_4n"] == 20000
    assert p.values["band"] == [0.95, 1.05] and p.values["n"] == 100
    assert p.detail.startswith("mean error of the reference at N = 5000 / at 4N = 20000 on the same 100 runs: 1.08")
    # a 1 % change with a 1 % run-to-run scatter: converged
    near = at_4n * 1.01 * rng.lognormal(0.0, 0.01, 100)
    p = reference_converged(near, at_4n, particles=5000, tolerance=0.05, min_n=100, seed=1)
    assert p.holds
    # the interval is the paired percentile bootstrap of mean(N) / mean(4N): scipy's agrees to its resampling noise
    ref = bootstrap((near, at_4n), lambda a, b, axis=-1: a.mean(axis=axis) / b.mean(axis=axis), paired=True,
                    method="percentile", n_resamples=20000, random_state=np.random.default_rng(0)).confidence_interval
    assert p.values["interval"] == pytest.approx([ref.low, ref.high], abs=2e-3)
    # too few runs: convergence is not shown, however close the two are
    few = reference_converged(near[:20], at_4n[:20], particles=5000, tolerance=0.05, min_n=100)
    assert not few.holds and "needs n >= 100" in few.detail
    # runs differing one by one with equal means: a wide interval, not shown to converge
    wide = reference_converged(at_4n[::-1], at_4n, particles=100, tolerance=0.05)
    assert wide.values["ratio"] == pytest.approx(1.0) and wide.values["interval"][1] > 1.05 and not wide.holds
    with pytest.raises(ValueError, match="same runs"):
        reference_converged(at_4n[:10], at_4n, particles=5000, tolerance=0.05)
    with pytest.raises(ValueError, match="tolerance"):
        reference_converged(at_4n, at_4n, particles=5000, tolerance=0.0)


def test_a_criterion_fed_diverged_rows_or_an_unconverged_reference_is_not_judgeable():
    rng = np.random.default_rng(5)
    # A/C >= 1.3 from A's diverged runs (tens of km) against C's tracked ones (about 100 m): the numbers say "met"
    a = rng.uniform(30e3, 45e3, 100)
    c = rng.uniform(80.0, 120.0, 100)
    lost = {"A": a > 3e3, "C": c > 3e3}
    crit = criterion_from_runs("2", "A/C >= 1.3", (a, c), lambda x, y: x.mean() / y.mean(), 1.3, ">=", min_n=20,
                               preconditions=(rows_track(lost, 0.10),))
    assert crit.verdict == "not judgeable" and crit.verdict_if_judged == "met" and crit.interval[0] > 1.3
    assert "A 100/100 (100 %)" in crit.failed_preconditions[0].detail
    # "not attainable" resting on a reference that 4N particles improve by 8 %
    ref = rng.lognormal(3.0, 0.3, 100)
    unconverged = reference_converged(ref, ref / 1.08, particles=5000, tolerance=0.05, min_n=100)
    crit = criterion_from_counts("4", "beats the reference", 10, 100, 0.5, ">=", min_n=20,
                                 preconditions=(unconverged,))
    assert crit.verdict == "not judgeable" and crit.verdict_if_judged == "not met"
    assert Criterion("4", "x", "not attainable", preconditions=(unconverged,)).verdict == "not judgeable"
    # both preconditions holding leave the verdict as the numbers give it
    ok = criterion_from_runs("2", "A/C >= 1.3", (a, c), lambda x, y: x.mean() / y.mean(), 1.3, ">=", min_n=20,
                             preconditions=(rows_track({"A": c > 3e3, "C": c > 3e3}, 0.10),))
    assert ok.verdict == "met" and ok.met


# -- equivalence: two one-sided tests (TOST) with a stated margin -----------------------------------------------

def _normal(n, mu, sd=1.0, seed=7):
    """A normal sample of exactly mean ``mu`` and standard deviation ``sd`` (ddof = 1)."""
    z = np.random.default_rng(seed).normal(size=n)
    return mu + sd * (z - z.mean()) / z.std(ddof=1)


def test_equivalence_band_of_a_difference_and_of_a_ratio():
    assert equivalence_band(0.3) == (-0.3, 0.3)
    lo, hi = equivalence_band(0.05, ratio=True)
    assert lo == pytest.approx(0.952380952, rel=1e-8) and hi == pytest.approx(1.05, rel=1e-12)  # 1/1.05, 1.05
    assert judge_equivalent((0.96, 1.04), 0.05, ratio=True) == "met"
    assert judge_equivalent((0.94, 0.949), 0.05, ratio=True) == "not met"  # wholly below 1/1.05
    assert judge_equivalent((0.94, 0.96), 0.05, ratio=True) == "inconclusive"
    assert judge_equivalent((-0.1, 0.1), 0.3, n=5, min_n=20) == "inconclusive"
    for bad in (0.0, -0.1, math.inf, math.nan):
        with pytest.raises(ValueError, match="margin"):
            equivalence_band(bad)


def test_tost_on_hand_made_samples_tie_difference_and_wide():
    m = 0.3
    tie = criterion_equivalent("E", "about equal", _normal(200, 0.0, 0.2), np.mean, m, min_n=20)
    assert tie.verdict == "met" and -m < tie.interval[0] < tie.interval[1] < m
    for mu in (2 * m, -2 * m):  # a difference of twice the margin, either side
        far = criterion_equivalent("E", "about equal", _normal(200, mu, 0.2), np.mean, m, min_n=20)
        assert far.verdict == "not met", mu
    wide = criterion_equivalent("E", "about equal", _normal(200, 0.0, 8.0), np.mean, m, min_n=20)
    assert wide.verdict == "inconclusive" and wide.interval[0] < -m and wide.interval[1] > m
    assert criterion_equivalent("E", "x", _normal(10, 0.0, 0.2), np.mean, m, min_n=20).verdict == "inconclusive"
    # the record states the method, the margin and the 90 % level
    assert tie.method.startswith("equivalence (TOST, margin 0.3, 90 % interval)")
    assert tie.level == pytest.approx(0.9) and tie.detail == ""
    assert tie.statistics.startswith(f"ours {tie.ours:.4g}, 90 % interval [{tie.interval[0]:.4g}, ")
    assert tie.statistics.endswith("; judged as equivalence (TOST, margin 0.3, 90 % interval, alpha = 0.05 per side)")
    assert tie.extra["equivalence"] == {"margin": 0.3, "ratio": False, "alpha": 0.05, "band": [-0.3, 0.3]}
    back = Criterion.from_dict(json.loads(json.dumps(tie.to_dict())))
    assert back.verdict == "met" and back.method == tie.method


def test_tost_on_a_paired_ratio_reads_a_tie_as_a_tie():
    rng = np.random.default_rng(11)
    a = rng.lognormal(3.0, 0.3, 1000)
    tie = criterion_equivalent("C2", "about equal", (a, a * 1.002 * rng.lognormal(0.0, 0.01, 1000)),
                               lambda x, y: y.mean() / x.mean(), 0.05, ratio=True, min_n=100)
    assert tie.verdict == "met" and 1.0 < tie.interval[0] < tie.interval[1] < 1.01
    assert "margin 5 %" in tie.method and "within [0.9524, 1.05]" in tie.threshold
    for f in (1.12, 1 / 1.12):  # 12 % apart, either way: a difference of at least the margin
        c = criterion_equivalent("C2", "about equal", (a, a * f), lambda x, y: y.mean() / x.mean(), 0.05,
                                 ratio=True, min_n=100)
        assert c.verdict == "not met", f


def test_tost_uses_the_90_percent_interval_of_the_same_bootstrap():
    x = _normal(200, 0.1, 1.0)
    c = criterion_equivalent("E", "x", x, np.mean, 0.3, min_n=20, resamples=3000, seed=4)
    # the same resamples drawn here, and their 5th and 95th percentiles taken by numpy
    idx = np.random.default_rng(4).integers(0, 200, size=(3000, 200))
    means = x[idx].mean(axis=1)
    assert c.interval == pytest.approx(tuple(np.percentile(means, [5.0, 95.0])), rel=1e-12, abs=1e-12)
    assert c.interval[0] > np.percentile(means, 2.5) and c.interval[1] < np.percentile(means, 97.5)


@pytest.mark.parametrize("mu", [-0.6, -0.428, -0.25, -0.172, 0.0, 0.1, 0.172, 0.25, 0.428, 0.6])
def test_tost_agrees_with_the_t_based_two_one_sided_tests_on_a_normal_sample(mu):
    """The bootstrap TOST's verdict against scipy's one-sided t-tests at alpha = 0.05 on a normal sample of 200.

    mu = +-0.172 and +-0.428 sit where the one-sided p-value is about 0.036: between 0.025 and 0.05, so a verdict
    read from the 95 % interval (each side at 0.025) would be inconclusive there."""
    m, x = 0.3, _normal(200, mu, 1.0)
    p_equiv = max(ttest_1samp(x, -m, alternative="greater").pvalue, ttest_1samp(x, m, alternative="less").pvalue)
    p_diff = min(ttest_1samp(x, m, alternative="greater").pvalue, ttest_1samp(x, -m, alternative="less").pvalue)
    assert all(abs(p - 0.05) > 0.01 for p in (p_equiv, p_diff))  # no case at the boundary itself
    if abs(mu) in (0.172, 0.428):  # the cases that tell 90 % from 95 %: one one-sided p in (0.025, 0.05)
        assert 0.025 < (p_equiv if abs(mu) < 0.3 else p_diff) < 0.05
    expected = "met" if p_equiv < 0.05 else "not met" if p_diff < 0.05 else "inconclusive"
    assert criterion_equivalent("E", "x", x, np.mean, m, min_n=20, seed=3).verdict == expected


# -- declared unknowns: verdicts across a grid (issue 24, item 2) ---------------------------------------------

def _at(verdict, failed=None):
    from workbench.criteria import Criterion, Precondition

    pre = (Precondition(failed, False, "numbers"),) if failed else ()
    return Criterion("C", "claim", verdict, n=100, ours=1.0, interval=(0.9, 1.1), preconditions=pre)


def test_where_it_holds_reads_every_verdict_pattern_from_hand_made_records():
    from workbench.criteria import Criterion, DeclaredUnknown, judge_across, where_it_holds

    u = DeclaredUnknown("delta", "", 0.1, (0.1, 0.3, 1.0), "withheld by the paper; the tuning rule's pick")

    def line(*verdicts, failed=None):
        records = {v: _at(x, failed if x == "not judgeable" else None) for v, x in zip(u.grid, verdicts)}
        return where_it_holds(Criterion("C", "claim", "met", across=judge_across(u, records)))

    assert line("met", "met", "met") == "holds everywhere"
    assert line("not met", "not met", "not met") == "holds nowhere"
    assert line("not met", "inconclusive", "met") == \
        "holds for delta in {1}; not met at {0.1}; inconclusive at {0.3}"
    assert line("met", "met", "not met") == "holds for delta in {0.1, 0.3}; not met at {1}"
    assert line("met", "not judgeable", "met", failed="reference converged") == \
        "holds for delta in {0.1, 1}; not judgeable at {0.3} (reference converged failed)"
    assert line("not judgeable", "not judgeable", "not judgeable", failed="judged rows track") == \
        "not judgeable at every value of delta (judged rows track failed)"
    assert line("not attainable", "not met", "not met") == "holds nowhere; not met at {0.3, 1}; not attainable at {0.1}"
    assert line("inconclusive", "inconclusive", "inconclusive") == \
        "shown to hold at no value; inconclusive at {0.1, 0.3, 1}"
    assert line("not met", "inconclusive", "not met") == \
        "shown to hold at no value; not met at {0.1, 1}; inconclusive at {0.3}"
    assert where_it_holds(()) == ""


def test_verdicts_across_an_unknown_round_trip_and_never_say_met_in_a_quick_report():
    from workbench.criteria import Criterion, DeclaredUnknown, UnknownVerdict, judge_across, where_it_holds

    u = DeclaredUnknown("rate", "per scan", 50, (50, 100), "brief's value and the paper's")
    assert u.primary == 50.0 and u.grid == (50.0, 100.0) and u.label(100) == "rate = 100 per scan"
    across = judge_across(u, {50: _at("met"), 100: _at("not judgeable", "reference converged")},
                          {50: "first 10 runs", 100: "first 10 runs"})
    assert [(a.value, a.verdict, a.failed) for a in across] == [(50.0, "met", ()),
                                                                (100.0, "not judgeable", ("reference converged",))]
    c = Criterion("C", "claim", "met", across=across)
    assert Criterion.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    assert DeclaredUnknown.from_dict(json.loads(json.dumps(u.to_dict()))) == u
    quick = c.as_indicative()
    assert [a.verdict for a in quick.across] == ["inconclusive", "not judgeable"]
    assert quick.across[0].quick_verdict == "met" and quick.across[0].indicative
    assert where_it_holds(quick) == ("shown to hold at no value; inconclusive at {50}; not judgeable at {100} "
                                     "(reference converged failed) "
                                     "(indicative: the quick numbers alone pass at {50})")
    # a grid value left out, or one outside the grid, is refused rather than read as "holds nowhere"
    with pytest.raises(ValueError, match="no verdict at the grid values"):
        judge_across(u, {50: _at("met")})
    with pytest.raises(ValueError, match="not grid values"):
        judge_across(u, {50: _at("met"), 100: _at("met"), 7: _at("met")})
    # a not-judgeable record needs the failed precondition, and only it
    with pytest.raises(ValueError, match="exactly when a precondition failed"):
        UnknownVerdict("rate", 50, "not judgeable")
    with pytest.raises(ValueError, match="not in its grid"):
        DeclaredUnknown("rate", "", 10, (50, 100), "why")
    with pytest.raises(ValueError, match="say why"):
        DeclaredUnknown("rate", "", 50, (50, 100), " ")
    with pytest.raises(ValueError, match="repeats"):
        DeclaredUnknown("rate", "", 50, (50, 50.0), "why")
