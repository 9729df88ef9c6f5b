"""Statistics of the discrepancy workflow's decisions (ctrplan.discrepancy.verdict.statistics and .split),
checked against what each claims, by simulation independent of the mechanics: the corrected
comparison of cross-validated models (its size at the workflow's levels, 0.05, 0.01 and
0.01 / 7, where folds share a fitted model or their training data, by exact binomial tests
that fail the uncorrected comparison; its power; the statistic itself), Holm's rule, intervals
over units on serially correlated data, and the split's bookkeeping and buffers. The noise
estimate and test are in test_discrepancy_noise.py."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal, stats

from ctrplan.discrepancy.measured.data import MeasuredData
from ctrplan.choices import BufferReason
from ctrplan.discrepancy.measured.split import BufferChoice, choose_buffer, make_split, near_rows, residual_autocorrelation
from ctrplan.discrepancy.verdict.statistics import (CORRECTED_METHOD, UNCORRECTED_METHOD, cv_comparison, holm, mean_interval,
                                            ratio_interval, shrink_interval)
from ctrplan.discrepancy.fits.fitting import compare
from ctrplan.effects import REGISTRY
from ctrplan.errors import DataFileError
from ctrplan.history import MotionRecord


# --------------------------------------------------------------------------- cross-validated comparison
#: A rejection count fails its size check when the exact one-sided binomial test against the
#: nominal level gives p below this (a test of true size fails it at most once in 1000 runs).
SIZE_CHECK_P = 1e-3
#: The workflow's smallest level: options.significance 0.01, Holm over every registered candidate.
SMALLEST_LEVEL = 0.01 / len(REGISTRY)


def _too_many(count: int, n: int, alpha: float) -> bool:
    """``count`` rejections in ``n`` records are significantly more than ``alpha n`` (exact
    one-sided binomial test at :data:`SIZE_CHECK_P`)."""
    return stats.binomtest(int(count), n, alpha, alternative="greater").pvalue < SIZE_CHECK_P


def _detection_power(n: int, alpha: float, factor: float = 2.0) -> float:
    """Probability that :func:`_too_many` fails a test of true size ``factor * alpha`` with ``n``
    records."""
    k = int(stats.binom.isf(SIZE_CHECK_P, n, alpha))
    while stats.binom.sf(k - 1, n, alpha) >= SIZE_CHECK_P:        # smallest failing count
        k += 1
    return float(stats.binom.sf(k - 1, n, factor * alpha))


def _ar1(rng, reps: int, n: int, phi: float) -> np.ndarray:
    """``reps`` stationary AR(1) records of ``n`` samples, unit variance, shape (reps, n)."""
    w = rng.normal(0.0, np.sqrt(1 - phi ** 2), (reps, n))
    w[:, 0] = rng.normal(0.0, 1.0, reps)
    return signal.lfilter([1.0], [1.0, -phi], w, axis=1)


def _block_folds(blocks: int, per_block: int, n_folds: int = 10) -> np.ndarray:
    """Fold of each of ``blocks * per_block`` samples: time blocks dealt to folds by
    ``GroupKFold``, as the workflow's split deals them, shape (blocks * per_block,)."""
    from sklearn.model_selection import GroupKFold

    units = np.repeat(np.arange(blocks), per_block)
    fold = np.zeros(units.size, int)
    for k, (_, val) in enumerate(GroupKFold(n_folds).split(units, groups=units)):
        fold[val] = k
    return fold


def _standardized(x: np.ndarray) -> np.ndarray:
    """Each row to mean 0, standard deviation 1."""
    x = x - x.mean(axis=1, keepdims=True)
    return x / x.std(axis=1, keepdims=True)


def _slow_regressor(rng, kind: str, reps: int, n: int) -> np.ndarray:
    """A slowly varying regressor, shape (reps, n), standardized: ``"walk"`` a random walk (a
    drifting signature), ``"switch"`` a square wave of random period (100 to 300 samples) with
    jittered switching times (a dead band's signature, switching at the reversals)."""
    if kind == "walk":
        return _standardized(np.cumsum(rng.normal(size=(reps, n)), axis=1))
    t = np.arange(n) / rng.uniform(100, 300, (reps, 1)) + rng.uniform(0, 1, (reps, 1))
    return _standardized(np.sign(np.sin(2 * np.pi * t) + 0.3 * _ar1(rng, reps, n, 0.99)))


def _out_of_fold_errors(x: np.ndarray, y: np.ndarray, fold: np.ndarray) -> np.ndarray:
    """``|y - x beta_(-f)|`` at every sample of fold f, ``beta_(-f)`` the least-squares fit on the
    other folds (all folds and records at once, from the per-fold normal equations).

    Parameters
    ----------
    x : ndarray, shape (R, K, P)
    y : ndarray, shape (R, K)
    fold : ndarray of int, shape (K,)

    Returns
    -------
    ndarray, shape (R, K)
    """
    gram = np.einsum("rkp,rkq->rpq", x, x)
    moment = np.einsum("rkp,rk->rp", x, y)
    beta = np.empty((x.shape[0], fold.max() + 1, x.shape[2]))
    for f in range(fold.max() + 1):
        val = fold == f
        g = gram - np.einsum("rkp,rkq->rpq", x[:, val], x[:, val])
        m = moment - np.einsum("rkp,rk->rp", x[:, val], y[:, val])
        beta[:, f] = np.linalg.solve(g, m[..., None])[..., 0]
    return np.abs(y - np.einsum("rkp,rkp->rk", x, beta[:, fold]))


def _shared_fit_records(rng, reps: int, null: str, *, phi: float, kind: str, blocks: int = 40, per_block: int = 25,
                        effect: float = 0.0, batch: int = 1000, n_folds: int = 10, drift: float = 0.0):
    """Out-of-fold errors of two least-squares models on ``reps`` serially correlated records of
    ``blocks`` time blocks of ``per_block`` samples, ``n_folds`` folds, each fold's models fitted on
    the other folds (so the folds' fitted coefficients are correlated through the data they share).
    ``drift`` > 0 adds to the truth a slow unmodelled discrepancy neither model has: AR(1) of unit
    variance at phi = ``drift``.

    ``null="nested"``: truth ``y = x1 + effect z + e``, a the baseline ``[1, x1]``, b the
    candidate ``[1, x1, z]`` with one extra, slowly varying regressor ``z`` (``kind``);
    ``effect = 0`` is the null "b is not better". ``null="non-nested"``: truth
    ``y = x0 + x1 + e``, a ``[1, x0]`` and b ``[1, x1]``, both regressors of ``kind``: two models
    equally good. ``e`` is AR(1) of unit variance at ``phi``; ``x1`` in the nested case a random
    walk.

    Returns
    -------
    err_a, err_b : ndarray, shape (reps, blocks * per_block)
    fold : ndarray of int, shape (blocks * per_block,)
    """
    fold = _block_folds(blocks, per_block, n_folds)
    n = fold.size
    err_a, err_b = [], []
    for start in range(0, reps, batch):
        r = min(batch, reps - start)
        e = _ar1(rng, r, n, phi) + (_ar1(rng, r, n, drift) if drift > 0 else 0.0)
        one = np.ones((r, n))
        if null == "nested":
            x1 = _slow_regressor(rng, "walk", r, n)
            z = _slow_regressor(rng, kind, r, n)
            y = x1 + effect * z + e
            a, b = np.stack([one, x1], -1), np.stack([one, x1, z], -1)
        else:
            x0, x1 = _slow_regressor(rng, kind, r, n), _slow_regressor(rng, kind, r, n)
            y = x0 + x1 + e
            a, b = np.stack([one, x0], -1), np.stack([one, x1], -1)
        err_a.append(_out_of_fold_errors(a, y, fold))
        err_b.append(_out_of_fold_errors(b, y, fold))
    return np.concatenate(err_a), np.concatenate(err_b), fold


def _rejections(err_a, err_b, fold, levels, *, corrected: bool | None = None) -> dict:
    """The workflow's own comparison (:func:`ctrplan.discrepancy.fits.fitting.compare`, the test
    that names an effect) of every record, or :func:`cv_comparison` with ``corrected`` when it is
    given: ``{"b": counts, "a": counts}``, the number of records where "b is better" (``p_value``)
    and "a is better" (``p_worse``) is rejected at each of ``levels``, shape (len(levels),)."""
    split = SimpleNamespace(fold=np.asarray(fold), dev_rows=slice(None))
    run = ((lambda ea, eb: compare(split, ea, eb)) if corrected is None else
           (lambda ea, eb: cv_comparison(ea, eb, fold, corrected=corrected)))
    p = np.array([[c.p_value, c.p_worse] for c in (run(ea, eb) for ea, eb in zip(err_a, err_b))])
    levels = np.asarray(levels)[:, None]
    return {"b": np.sum(p[:, 0] < levels, axis=1), "a": np.sum(p[:, 1] < levels, axis=1)}


def _fold_errors(rng, n_folds=10, units_per_fold=4, per_unit=10, fit_scatter=0.6, shift=0.0, phi=0.8):
    """Out-of-fold errors of two models with equal expected error (plus ``shift`` in favour of
    b) on a motion of ``n_folds x units_per_fold`` blocks: serially correlated noise shared by
    both, and per fold one fitted offset per model, independent between folds (the fit of a fold
    errs the same way at every sample it validates). Returns (err_a, err_b, fold, units)."""
    n_units = n_folds * units_per_fold
    k = n_units * per_unit
    eps = _ar1(rng, 1, k, phi)[0]
    units = np.repeat(np.arange(n_units), per_unit)
    fold = units % n_folds                              # blocks dealt round-robin, as GroupKFold does
    off_a = rng.normal(0, fit_scatter, n_folds)[fold]
    off_b = rng.normal(0, fit_scatter, n_folds)[fold]
    err_a = np.abs(eps + off_a + 1.5)
    err_b = np.abs(eps + off_b + 1.5) - shift
    return err_a, err_b, fold, units


def test_size_checks_detect_twice_the_nominal_rate():
    """The record counts of the size checks below detect a true rejection rate of twice the
    nominal level with power > 0.9 (3000 records at 0.05 and 0.01, 24000 at 0.01 over the
    registry's candidates), while a test of nominal size fails them once in 1000 runs. Catches
    size checks too small to fail."""
    assert _detection_power(3000, 0.05) > 0.9 and _detection_power(3000, 0.01) > 0.9
    assert _detection_power(24000, SMALLEST_LEVEL) > 0.9
    assert _detection_power(3000, SMALLEST_LEVEL) < 0.5          # why the smallest level needs more


def test_fold_comparison_holds_its_size_where_a_test_over_units_does_not():
    """Two models with the same expected error, each fold validated by one fitted model whose
    error is shared by all its samples: the test clustered by fold rejects "b is better" at 5 %
    in 600 seeds no more often than the exact binomial test allows (power 0.94 against 10 %),
    where a t test over units (treating the units of one fold as independent) rejects far more
    often. Catches a comparison that treats samples or units validated by one fit as
    independent observations."""
    rng = np.random.default_rng(20031)
    reps, alpha = 600, 0.05
    clustered = naive = 0
    for _ in range(reps):
        a, b, fold, units = _fold_errors(rng)
        clustered += cv_comparison(a, b, fold).p_value < alpha
        d = np.array([np.mean((a - b)[units == u]) for u in np.unique(units)])
        naive += stats.t.sf(d.mean() / (d.std(ddof=1) / np.sqrt(d.size)), d.size - 1) < alpha
    assert not _too_many(clustered, reps, alpha), clustered
    assert _too_many(naive, reps, alpha), naive


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


def test_fold_comparison_finds_a_real_extra_effect_when_the_folds_share_their_training_data():
    """A candidate with one extra, dead-band-like regressor whose true coefficient is 1.2 (the
    noise's standard deviation 1, AR(1) at phi = 0.8), fitted without each of 10 folds: the
    corrected test finds it at the workflow's smallest level (0.01 over the registry's
    candidates) in at least 80 % of 300 records, and never finds the baseline better. Catches a correction that inflates the
    variance so much that a real effect is no longer named."""
    rng = np.random.default_rng(8123)
    a, b, fold = _shared_fit_records(rng, 300, "nested", phi=0.8, kind="switch", effect=1.2)
    hits = _rejections(a, b, fold, [SMALLEST_LEVEL])
    assert hits["b"][0] / 300 >= 0.8, hits
    assert hits["a"][0] == 0, hits


def _check_size(rng, reps: int, levels, null: str, kind: str, **records) -> None:
    """Null records with shared-training folds (AR(1) phi 0.9; ``records`` passed on to
    :func:`_shared_fit_records`): the workflow's comparison's rejections at each level pass the
    exact binomial test against it (both sides for the non-nested null), and in the non-nested
    null the uncorrected comparison fails it at every level."""
    a, b, fold = _shared_fit_records(rng, reps, null, phi=0.9, kind=kind, **records)
    sides = ("b", "a") if null == "non-nested" else ("b",)
    hits = _rejections(a, b, fold, levels)
    for side in sides:
        for alpha, count in zip(levels, hits[side]):
            assert not _too_many(count, reps, alpha), (side, alpha, count)
    if null == "non-nested":
        plain = _rejections(a, b, fold, levels, corrected=False)
        for side in sides:
            assert all(_too_many(count, reps, alpha) for alpha, count in zip(levels, plain[side])), (side, plain)


@pytest.mark.parametrize("null, kind", [("non-nested", "switch"), ("nested", "switch"), ("nested", "walk")])
def test_fold_comparison_holds_its_size_when_the_folds_share_their_training_data(null, kind):
    """Nulls of the workflow, each fold's least-squares models fitted on the other nine folds of a
    serially correlated record (AR(1), phi = 0.9, 40 blocks of 25 samples), so that the folds'
    fitted coefficients are correlated through the training data they share: two non-nested
    models equally good (both sides tested), or a candidate with one extra slowly varying
    regressor of true coefficient 0 against its baseline ("candidate better" tested). In 3000
    records the rejections at 0.05 and at 0.01 pass the exact binomial test against the level
    (which detects twice the level with power > 0.9; the workflow's smallest level is checked in
    the slow test below). In the non-nested case the uncorrected test fails the same check.
    Catches a comparison whose level depends on folds being fitted on independent data (a
    variance of s^2 / F), a one-sided test pointing the wrong way (the nested candidate is
    worse out of fold), and a simulation too easy to tell the two apart."""
    rng = np.random.default_rng({"non-nested": 4242, "nested": 4343}[null] + len(kind))
    reps, levels = 3000, (0.05, 0.01)
    _check_size(rng, reps, levels, null, kind)


def test_the_test_that_names_holds_its_size_beside_a_slow_unmodelled_discrepancy():
    """A candidate with one extra random-walk regressor of true coefficient 0 against its
    baseline, while a slow discrepancy that neither models (AR(1), phi = 0.995, unit variance, as
    a real robot's or a misspecified file's) rides on the noise: in 3000 records the workflow's
    own comparison (``fitting.compare``, the Holm gate of the verdict) passes the exact binomial
    test at 0.05 and 0.01, and the uncorrected comparison fails it at 0.01 (rate about 0.04).
    Catches the gate going back to the uncorrected test for a model against one it contains,
    which names a useless parameter about four times as often as its level says."""
    rng = np.random.default_rng(6161)
    reps, levels = 3000, (0.05, 0.01)
    a, b, fold = _shared_fit_records(rng, reps, "nested", phi=0.9, kind="walk", drift=0.995)
    hits = _rejections(a, b, fold, levels)
    assert not any(_too_many(c, reps, alpha) for alpha, c in zip(levels, hits["b"])), hits
    plain = _rejections(a, b, fold, levels, corrected=False)
    assert _too_many(plain["b"][1], reps, 0.01), plain


@pytest.mark.parametrize("null, kind", [("non-nested", "switch"), ("nested", "walk")])
def test_fold_comparison_holds_its_size_with_five_folds(null, kind):
    """The workflow's lengthened splits often end with 5 folds (t with 4 degrees of freedom, each
    fold's fit on four fifths of the data): the size check of the test above at 0.05 and 0.01
    with 5 folds of 40 blocks. Catches a comparison whose level holds only with 10 folds (a
    correction or degrees of freedom tied to that count)."""
    rng = np.random.default_rng({"non-nested": 7171, "nested": 7272}[null])
    _check_size(rng, 3000, (0.05, 0.01), null, kind, n_folds=5)


def test_ten_folds_of_shorter_blocks_find_a_real_effect_far_more_often_at_the_same_size():
    """The split's lengthening keeps its folds (``split.lengthen_blocks``): 400 samples in 20 blocks
    of 20 dealt to 10 folds, against the 10 blocks of 40 in 5 folds that the longer blocks left.
    With 10 folds the nulls hold their level at 0.05 and 0.01 (3000 records each: a useless extra
    random walk beside a slow unmodelled discrepancy, phi 0.995, and two equally good non-nested
    models, noise phi 0.9), and a real square-wave effect as large as the noise (phi 0.6) is
    found at the workflow's smallest level (0.01 / 8) in more than twice as many records as with
    5 folds. Catches a split rule that trades folds for buffer (the power lost) and a 10-fold
    comparison that holds its power by exceeding its size."""
    levels = (0.05, 0.01)
    short = dict(blocks=20, per_block=20, n_folds=10)
    for null, kind, seed, extra in (("nested", "walk", 8181, dict(drift=0.995)), ("non-nested", "switch", 8282, {})):
        a, b, fold = _shared_fit_records(np.random.default_rng(seed), 3000, null, phi=0.9, kind=kind, **short, **extra)
        hits = _rejections(a, b, fold, levels)
        for side in (("b", "a") if null == "non-nested" else ("b",)):
            assert not any(_too_many(c, 3000, alpha) for alpha, c in zip(levels, hits[side])), (null, side, hits)
    found = {}
    for name, shape in (("ten", short), ("five", dict(blocks=10, per_block=40, n_folds=5))):
        a, b, fold = _shared_fit_records(np.random.default_rng(8383), 1000, "nested", phi=0.6, kind="switch",
                                         effect=1.0, **shape)
        found[name] = int(_rejections(a, b, fold, (SMALLEST_LEVEL,))["b"][0])
    assert found["ten"] > 2 * found["five"] and found["ten"] >= 200, found


@pytest.mark.slow
@pytest.mark.parametrize("null, kind", [("non-nested", "switch"), ("non-nested", "walk"), ("nested", "switch"),
                                        ("nested", "walk")])
def test_fold_comparison_holds_its_size_at_the_workflows_smallest_level(null, kind):
    """As the test above at the levels 0.05, 0.01 and 0.01 / 8 (the smallest Holm level of the
    workflow: significance 0.01 over the registry's candidates), with 24000 records (twice the
    smallest level detected with power 0.93). In the non-nested case the uncorrected test fails
    the same check at every level. Catches a test whose level holds at 5 % but not in the far
    tail the workflow decides in (a t with too many degrees of freedom, a variance that is too
    small)."""
    rng = np.random.default_rng({"non-nested": 5151, "nested": 5252}[null] + len(kind))
    reps, levels = 24000, (0.05, 0.01, SMALLEST_LEVEL)
    _check_size(rng, reps, levels, null, kind)


def test_fold_comparison_is_the_corrected_t_statistic_of_log_ratios():
    """Four folds of 10 samples, model a's fold means 2, 4, 6, 12 against b's 1: log ratios ln 2,
    ln 4, ln 6, ln 12; their mean over its standard error s sqrt(1/4 + 10/30) (the Nadeau-Bengio
    term n_validation / n_training = 1/3), t with 3 degrees of freedom; the mean difference 5
    with its t-interval of the same variance; without the correction s / 2. A fifth fold of NaN
    errors is left out, and a NaN sample in fold 0 leaves it 9 samples (term the mean of
    9/30, 10/29, 10/29, 10/29). Catches a wrong variance factor, training counts that include
    non-finite samples, and a method label that does not say which test was done."""
    a = np.repeat([2.0, 4.0, 6.0, 12.0], 10)
    fold = np.repeat(np.arange(4), 10)
    logs = np.log([2.0, 4.0, 6.0, 12.0])
    for corrected, factor in ((True, 1 / 4 + 1 / 3), (False, 1 / 4)):
        out = cv_comparison(np.append(a, [np.nan] * 3), np.ones(43), np.append(fold, [4] * 3), corrected=corrected)
        se = np.std(logs, ddof=1) * np.sqrt(factor)
        assert out.ratio == pytest.approx(np.exp(logs.mean()))
        assert out.reduction == pytest.approx(1 - np.exp(-logs.mean()))
        assert out.se == pytest.approx(se)
        assert out.t == pytest.approx(logs.mean() / se)
        assert out.p_value == pytest.approx(stats.t.sf(logs.mean() / se, 3))
        assert out.p_worse == pytest.approx(stats.t.cdf(logs.mean() / se, 3))
        assert out.ratio_ci[1] == pytest.approx(np.exp(logs.mean() + stats.t.ppf(0.975, 3) * se))
        assert out.mean_difference == pytest.approx(5.0)
        half = stats.t.ppf(0.975, 3) * np.std([1, 3, 5, 11], ddof=1) * np.sqrt(factor)
        assert out.ci[1] - 5.0 == pytest.approx(half)
        assert out.dof == 3 and out.positive_folds == 4 and out.n_folds == 4 and out.n_samples == 40
        assert out.validation_to_training == pytest.approx(factor - 1 / 4)
        assert out.as_dict()["validation_to_training"] == out.validation_to_training
    assert out.method == UNCORRECTED_METHOD and "not corrected" in out.method
    assert cv_comparison(a, np.ones(40), fold).method == CORRECTED_METHOD and "Nadeau-Bengio" in CORRECTED_METHOD
    a[0] = np.nan
    out = cv_comparison(a, np.ones(40), fold)
    assert out.n_samples == 39
    assert out.validation_to_training == pytest.approx(np.mean([9 / 30, 10 / 29, 10 / 29, 10 / 29]))


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
    s = make_split(_data(500), seed=3).with_buffer(BufferChoice(3, BufferReason.AUTOCORRELATION_FALLS))
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
    h = choose_buffer(r, _data(k), 40).samples
    assert abs(h - expected) <= 1
    capped = choose_buffer(r, _data(k), 12)
    assert capped.samples == min(h, 6) and (capped.samples < h) == (capped.reason == BufferReason.HALF_A_BLOCK)
    assert choose_buffer(r, _data(k), None).samples == 0


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
