"""Statistics of the discrepancy workflow's decisions (ctrplan.discrepancy.statistics and .split),
checked against what each claims, by simulation independent of the mechanics: the corrected
comparison of cross-validated models (size where folds share a fitted model, power, the
statistic itself), Holm's rule, intervals over units on serially correlated data, and the
split's bookkeeping and buffers. The noise estimate and test are in test_discrepancy_noise.py."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from ctrplan.discrepancy.data import MeasuredData
from ctrplan.discrepancy.split import choose_buffer, make_split, near_rows, residual_autocorrelation
from ctrplan.discrepancy.statistics import cv_comparison, holm, mean_interval, ratio_interval, shrink_interval
from ctrplan.errors import DataFileError
from ctrplan.history import MotionRecord


def _binomial_upper(rate: float, n: int, z: float = 4.0) -> float:
    """A rejection count's upper limit at ``z`` standard deviations (a test that fails only when
    the rate is really off)."""
    return rate + z * np.sqrt(rate * (1 - rate) / n)


# --------------------------------------------------------------------------- cross-validated comparison
def _fold_errors(rng, n_folds=10, units_per_fold=4, per_unit=10, fit_scatter=0.6, shift=0.0, phi=0.8):
    """Out-of-fold errors of two models with equal expected error (plus ``shift`` in favour of
    b) on a motion of ``n_folds x units_per_fold`` blocks: serially correlated noise shared by
    both, and per fold one fitted offset per model (the fit of a fold errs the same way at
    every sample it validates). Returns (err_a, err_b, fold, units)."""
    n_units = n_folds * units_per_fold
    k = n_units * per_unit
    eps = np.zeros(k)
    w = rng.normal(0, np.sqrt(1 - phi ** 2), k)
    for i in range(1, k):
        eps[i] = phi * eps[i - 1] + w[i]
    units = np.repeat(np.arange(n_units), per_unit)
    fold = units % n_folds                              # blocks dealt round-robin, as GroupKFold does
    off_a = rng.normal(0, fit_scatter, n_folds)[fold]
    off_b = rng.normal(0, fit_scatter, n_folds)[fold]
    err_a = np.abs(eps + off_a + 1.5)
    err_b = np.abs(eps + off_b + 1.5) - shift
    return err_a, err_b, fold, units


def test_fold_comparison_holds_its_size_where_a_test_over_units_does_not():
    """Two models with the same expected error, each fold validated by one fitted model whose
    error is shared by all its samples: the t test clustered by fold rejects "b is better" in at
    most its stated 5 % of 500 seeds (plus binomial slack), where a t test over units (treating
    the units of one fold as independent) rejects far more often. Catches a comparison that
    treats samples or units validated by one fit as independent observations."""
    rng = np.random.default_rng(20031)
    reps, alpha = 500, 0.05
    corrected = naive = 0
    for _ in range(reps):
        a, b, fold, units = _fold_errors(rng)
        out = cv_comparison(a, b, fold)
        corrected += out.p_value < alpha
        d = np.array([np.mean((a - b)[units == u]) for u in np.unique(units)])
        naive += stats.t.sf(d.mean() / (d.std(ddof=1) / np.sqrt(d.size)), d.size - 1) < alpha
    assert corrected / reps <= _binomial_upper(alpha, reps), corrected
    assert naive / reps > 2 * alpha, naive


def test_fold_comparison_finds_a_real_improvement_and_its_interval_covers_it():
    """b better by 0.4 everywhere (the noise as above, fitted offsets scattering by 0.1 between
    folds): p < 0.01 in nearly every seed, and the 95 % interval of the difference covers the
    true 0.4 in at least 90 % of seeds.
    Catches a test made safe by never rejecting, a one-sided test pointing the wrong way, and an
    interval of the wrong width."""
    rng = np.random.default_rng(777)
    hits = covered = 0
    reps = 300
    for _ in range(reps):
        a, b, fold, _ = _fold_errors(rng, shift=0.4, fit_scatter=0.1)
        out = cv_comparison(a, b, fold)
        hits += out.p_value < 0.01 and out.p_worse > 0.99
        lo, hi = out.ci
        covered += lo <= 0.4 <= hi
    assert hits / reps >= 0.95, hits
    assert covered / reps >= 0.9, covered


def test_fold_comparison_is_the_clustered_t_statistic_of_log_ratios():
    """Four folds of 10 samples, model a's fold means 2, 4, 6, 12 against b's 1: log ratios ln 2,
    ln 4, ln 6, ln 12, their mean over their standard error, t with 3 degrees of freedom; the
    mean difference 5 with its t-interval over the folds."""
    a = np.repeat([2.0, 4.0, 6.0, 12.0], 10)
    fold = np.repeat(np.arange(4), 10)
    out = cv_comparison(a, np.ones(40), fold)
    logs = np.log([2.0, 4.0, 6.0, 12.0])
    se = np.std(logs, ddof=1) / 2.0
    assert out.ratio == pytest.approx(np.exp(logs.mean()))
    assert out.reduction == pytest.approx(1 - np.exp(-logs.mean()))
    assert out.se == pytest.approx(se)
    assert out.p_value == pytest.approx(stats.t.sf(logs.mean() / se, 3))
    assert out.mean_difference == pytest.approx(5.0)
    assert out.ci[1] - 5.0 == pytest.approx(stats.t.ppf(0.975, 3) * np.std([1, 3, 5, 11], ddof=1) / 2.0)
    assert out.dof == 3 and out.positive_folds == 4


def test_fold_comparison_holds_its_size_when_the_folds_share_their_training_data():
    """Two least-squares models as good as each other (each misses one of two equally strong,
    slowly varying regressors of the truth), fitted without each of 10 folds of a serially
    correlated record, so that the folds' fitted coefficients are correlated through the
    training data they share: "b is better" is rejected at 5 % in at most 5 % of 300 seeds (plus
    binomial slack), and so is "a is better". Catches a comparison whose level depends on folds
    being fitted on independent data."""
    from sklearn.model_selection import GroupKFold

    rng = np.random.default_rng(4242)
    reps, alpha = 300, 0.05
    hits = {"b": 0, "a": 0}
    n, blocks = 1000, 40
    units = np.arange(n) // (n // blocks)
    for _ in range(reps):
        x = np.cumsum(rng.normal(size=(n, 2)), axis=0)
        x = (x - x.mean(axis=0)) / x.std(axis=0)
        e = np.zeros(n)
        w = rng.normal(0, 0.6, n)
        for i in range(1, n):
            e[i] = 0.8 * e[i - 1] + w[i]
        y = x[:, 0] + x[:, 1] + e
        fold = np.zeros(n, int)
        for k, (_, val) in enumerate(GroupKFold(10).split(x, groups=units)):
            fold[val] = k
        err = np.zeros((2, n))
        for k in range(10):
            train, val = fold != k, fold == k
            for m in (0, 1):
                X = np.column_stack([np.ones(n), x[:, m]])
                coef = np.linalg.lstsq(X[train], y[train], rcond=None)[0]
                err[m, val] = np.abs(y[val] - X[val] @ coef)
        out = cv_comparison(err[0], err[1], fold)
        hits["b"] += out.p_value < alpha
        hits["a"] += out.p_worse < alpha
    for side, count in hits.items():
        assert count / reps <= _binomial_upper(alpha, reps), (side, count)


def test_holm_steps_down_and_stops_at_the_first_failure():
    p = {"a": 0.001, "b": 0.012, "c": 0.02, "d": 0.04}
    # a: 0.001 <= 0.05/4; b: 0.012 <= 0.05/3; c: 0.02 <= 0.05/2; d: 0.04 <= 0.05 -> all
    assert holm(p, 0.05) == {"a": True, "b": True, "c": True, "d": True}
    # at 0.04: a <= 0.01 yes; b 0.012 <= 0.0133 yes; c 0.02 <= 0.02 yes; d 0.04 <= 0.04 yes
    assert all(holm(p, 0.04).values())
    # at 0.03: b 0.012 > 0.01 -> b and everything after it fail, even d (0.04 > 0.03 anyway)
    assert holm(p, 0.03) == {"a": True, "b": False, "c": False, "d": False}


# --------------------------------------------------------------------------- intervals over units
def test_mean_and_shrink_intervals_over_units_cover_on_serially_correlated_errors():
    """AR(1) errors (phi = 0.9) in 10 test blocks of 30 samples: the t-interval of the mean over
    units covers the true mean in about 95 % of 400 seeds (at least 88 %), where one over samples
    would cover far less; the paired interval of the shrink 1 - mean(after) / mean(before) covers
    the true 30 % as often. Catches intervals over samples and a shrink interval that ignores the
    pairing."""
    rng = np.random.default_rng(55102)
    units = np.repeat(np.arange(10), 30)
    covered = shrunk = naive = 0
    reps = 400
    for _ in range(reps):
        e = np.zeros(300)
        w = rng.normal(0, 1, 300)
        for i in range(1, 300):
            e[i] = 0.9 * e[i - 1] + w[i]
        before = 5.0 + e
        after = 0.7 * before + 0.3 * rng.normal(0, 1, 300)
        m = mean_interval(before, units)
        covered += m.ci[0] <= 5.0 <= m.ci[1]
        s = shrink_interval(before, after, units)
        shrunk += s.ci[0] <= 0.3 <= s.ci[1]
        half = 1.96 * before.std() / np.sqrt(before.size)
        naive += abs(before.mean() - 5.0) <= half
    assert 0.88 <= covered / reps <= 0.99, covered
    assert 0.88 <= shrunk / reps <= 0.99, shrunk
    assert naive / reps < 0.7           # the data really is serially correlated


def test_ratio_interval_of_known_unit_sums():
    """Three units: sums (2, 4, 9), counts (1, 2, 3): R = 15 / 6 = 2.5; z = (-0.5, -1, 1.5),
    se = sqrt(3 var(z)) / 6, t with 2 degrees of freedom."""
    out = ratio_interval(np.array([2.0, 4.0, 9.0]), np.array([1.0, 2.0, 3.0]))
    se = np.sqrt(3 * np.var([-0.5, -1.0, 1.5], ddof=1)) / 6
    assert out.value == pytest.approx(2.5) and out.se == pytest.approx(se)
    assert out.ci[1] - out.value == pytest.approx(stats.t.ppf(0.975, 2) * se)


# --------------------------------------------------------------------------- split
def _data(k, config_id=None, sequence=None):
    """Toy data of ``k`` samples (only the bookkeeping the split reads is meaningful)."""
    z = np.zeros((k, 2))
    config_id = np.arange(k) if config_id is None else np.asarray(config_id)
    sequence = np.zeros(k, int) if sequence is None else np.asarray(sequence)
    return MeasuredData(alpha=z, beta=z, tip=np.zeros((k, 3)), tangent=None, eta=np.zeros((k, 1), int),
                        translation_last=np.zeros((k, 1), bool), sequence=sequence, config_id=config_id,
                        subset=None, time=None, file="toy.csv", frame="robot",
                        record=MotionRecord(z, z, sequence=sequence), rows=np.arange(k),
                        given_eta=np.zeros((k, 1), int))


@pytest.mark.parametrize("k, blocks, block_len", [(300, 30, 10), (500, 50, 10), (1307, 49, 27), (5000, 50, 100)])
def test_time_block_split_follows_the_record_length_and_never_cuts_a_block(k, blocks, block_len):
    """A continuous motion of k samples: blocks of at least 10 samples, 50 at most (the last one
    shorter); at least 8 test
    units spread over the motion (not one end); 10 folds at most, each with at least 2 development
    units; every development block validated in exactly one fold, no test sample in a fold.
    Catches a test split too small for intervals over units and a split that cuts a block."""
    s = make_split(_data(k), test_fraction=0.2, seed=31)
    assert s.unit_kind == "time block" and np.unique(s.units).size == blocks and s.block_samples == block_len
    assert np.all(np.diff(s.units) >= 0)                      # contiguous, in time order
    assert np.all(s.fold[s.test_rows] == -1) and np.all(s.fold[~s.test_rows] >= 0)
    for u in np.unique(s.units):
        assert np.unique(s.fold[s.units == u]).size == 1      # a block is never cut
    test_units = np.unique(s.units[s.test_rows])
    assert test_units.size >= 8 and np.ptp(test_units) >= 0.7 * blocks  # spread over the motion
    assert s.n_folds == min(10, (blocks - test_units.size) // 2)
    assert min(np.unique(s.units[s.fold == kf]).size for kf in range(s.n_folds)) >= 2
    for kf in range(s.n_folds):
        assert not np.any(s.calibration_rows(kf) & s.validation_rows(kf))
        assert np.all(s.calibration_rows(kf) | s.validation_rows(kf) | s.test_rows)


def test_buffer_keeps_fits_away_from_the_blocks_they_are_judged_on():
    """With a buffer of 3 samples, no calibration row of fold k lies within 3 samples of a row
    validated in fold k or of a test row, and every development row further away is kept.
    Catches buffers on one side only, across motions, or around the wrong blocks."""
    s = make_split(_data(500), seed=3).with_buffer(3, "test")
    data = s.data
    idx = np.arange(500)
    for kf in range(s.n_folds):
        cal = s.calibration_rows(kf)
        judged = np.flatnonzero(s.validation_rows(kf) | s.test_rows)
        dist = np.min(np.abs(idx[:, None] - judged[None, :]), axis=1)
        assert not np.any(cal & (dist <= 3))
        assert np.all(cal[(dist > 3) & s.dev_rows & (s.fold != kf)])
    # two motions: a buffer never reaches into the other motion
    two = _data(40, sequence=np.repeat([0, 1], 20))
    mask = np.zeros(40, bool)
    mask[19] = True
    np.testing.assert_array_equal(np.flatnonzero(near_rows(two, mask, 2)), [17, 18, 19])


@pytest.mark.parametrize("phi, expected", [(0.0, 0), (0.5, 3), (0.8, 10)])
def test_buffer_follows_the_residuals_autocorrelation(phi, expected):
    """AR(1) residuals: the buffer is the last lag before the autocorrelation falls to 0.1
    (phi^h <= 0.1 at h = 1, 4, 11 for phi = 0, 0.5, 0.8), within one sample; half a block at
    most. Catches a buffer that ignores the serial correlation or is not capped."""
    rng = np.random.default_rng(4)
    k = 20000
    r = np.zeros((k, 3))
    w = rng.normal(size=(k, 3))
    for i in range(1, k):
        r[i] = phi * r[i - 1] + np.sqrt(1 - phi ** 2) * w[i]
    acf = residual_autocorrelation(r, _data(k), 12)
    assert acf[1] == pytest.approx(phi, abs=0.03)
    h, _ = choose_buffer(r, _data(k), 40)
    assert abs(h - expected) <= 1
    capped, why = choose_buffer(r, _data(k), 12)
    assert capped == min(h, 6) and (capped < h) == ("half a block" in why)
    assert choose_buffer(r, _data(k), None)[0] == 0


def test_grid_protocol_split_keeps_each_configuration_group_whole():
    """The paper's protocol: four approaches per configuration. A configuration's rows share a
    unit, so none is split between the test split and a fold, or between folds."""
    config = np.repeat(np.arange(60), 4)
    s = make_split(_data(240, config_id=config, sequence=np.arange(240)), seed=5)
    assert s.unit_kind == "configuration group"
    for c in range(60):
        rows = config == c
        assert np.unique(s.fold[rows]).size == 1


def test_too_few_units_for_the_split_is_refused_naming_the_file():
    with pytest.raises(DataFileError, match="toy.csv.*too few"):
        make_split(_data(100))
