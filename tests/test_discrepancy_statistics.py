"""Statistics of the discrepancy workflow's decisions (ctrplan.discrepancy.statistics and .split),
checked against what each claims, by simulation independent of the mechanics: the noise test's
false-alarm rate with fitted parameters, the sign-flip test's size and power, Holm's rule, the
block bootstrap's coverage on serially correlated data, and the split's bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from ctrplan.discrepancy.data import MeasuredData
from ctrplan.discrepancy.split import make_split
from ctrplan.discrepancy.statistics import block_bootstrap, holm, noise_test, paired_improvement
from ctrplan.errors import DataFileError
from ctrplan.history import MotionRecord


def _binomial_upper(rate: float, n: int, z: float = 4.0) -> float:
    """A rejection count's upper limit at ``z`` standard deviations (a test that fails only when
    the rate is really off)."""
    return rate + z * np.sqrt(rate * (1 - rate) / n)


# --------------------------------------------------------------------------- noise test
def _noise_only_statistic(rng, n_fit, n_out, p, sigma, n_rest):
    """One noise-only case: a linear model with ``p`` parameters fitted on ``n_fit`` 3-D samples,
    its out-of-sample residual over ``n_out`` others, the noise estimated from ``n_rest`` rest
    pairs like :func:`~ctrplan.discrepancy.decision.estimate_noise` (median of |d|)."""
    X = rng.normal(size=(3 * n_fit, p))
    b = rng.normal(size=p)
    y = X @ b + rng.normal(0, sigma, 3 * n_fit)
    b_hat = np.linalg.lstsq(X, y, rcond=None)[0]
    Xo = rng.normal(size=(3 * n_out, p))
    r = Xo @ b - Xo @ b_hat + rng.normal(0, sigma, 3 * n_out)
    d = np.linalg.norm(rng.normal(0, sigma, (n_rest, 3)) - rng.normal(0, sigma, (n_rest, 3)), axis=1)
    rms = np.median(d) / (1.5382 * np.sqrt(2.0)) * np.sqrt(3.0)
    return float(np.mean(r * r)), (rms ** 2) / 3.0


@pytest.mark.parametrize("p, n_fit", [(5, 30), (8, 200)])
def test_noise_test_false_alarm_rate_holds_with_fitted_parameters(p, n_fit):
    """Noise only, parameters fitted on few samples (p / n up to 1/6 of the 3 n_fit components):
    the test calls the residual NOT consistent with noise in at most its stated 5 % of 600 seeds
    (plus binomial slack). Catches a test that ignores the fitted parameters (rate far above
    5 % when p / n is large) or the noise estimate's own scatter."""
    rng = np.random.default_rng(90817)
    alpha, reps = 0.05, 600
    rejected = 0
    for _ in range(reps):
        ms, s2 = _noise_only_statistic(rng, n_fit, 120, p, 0.5e-3, 60)
        t = noise_test(ms, 360, s2, 0.6 * 3 * 60, n_parameters=p, n_fitted=3 * n_fit, alpha=alpha)
        rejected += not t["consistent"]
    assert rejected / reps <= _binomial_upper(alpha, reps), rejected


def test_noise_test_sees_a_residual_30_percent_above_the_noise():
    """A residual whose rms is 1.3 times the noise (a missed effect of 0.8 noise rms), 300
    samples, noise from 200 rest pairs: the test rejects in at least 90 % of seeds. Catches a
    test made safe by never rejecting."""
    rng = np.random.default_rng(4471)
    hits = 0
    for _ in range(200):
        r = rng.normal(0, 0.5e-3, 900) + rng.normal(0, 0.5e-3 * np.sqrt(1.3 ** 2 - 1), 900)
        d = np.linalg.norm(rng.normal(0, 0.5e-3, (200, 3)) - rng.normal(0, 0.5e-3, (200, 3)), axis=1)
        s2 = (np.median(d) / (1.5382 * np.sqrt(2.0)) * np.sqrt(3.0)) ** 2 / 3.0
        hits += not noise_test(float(np.mean(r * r)), 900, s2, 0.6 * 600, n_parameters=5, n_fitted=600,
                               alpha=0.01)["consistent"]
    assert hits >= 180, hits


def test_noise_test_with_a_stated_noise_is_a_chi_square_test():
    """Stated noise (no estimate): the threshold is chi2(n).ppf(1 - alpha) / n times the inflation."""
    t = noise_test(1.0, 300, 1.0, None, n_parameters=6, n_fitted=200, alpha=0.01)
    assert t["inflation"] == pytest.approx(1.03)
    assert t["threshold"] == pytest.approx(stats.chi2(300).ppf(0.99) / 300)
    assert t["statistic"] == pytest.approx(1 / 1.03)


# --------------------------------------------------------------------------- paired improvement, Holm
def test_sign_flip_test_has_its_size_and_power_and_its_interval_covers_the_truth():
    """Differences with no systematic sign (heavy-tailed, unequal unit sizes): p < 0.05 in about 5 %
    of 400 seeds. A true improvement of 0.3 per unit (noise 1 per sample, 40 samples per unit,
    20 units) is found in nearly every seed, and the 95 % t-interval covers 0.3 in about 95 %.
    Catches a p-value computed over samples (serially correlated in real data) instead of units,
    a one-sided test pointing the wrong way, and an interval of the wrong width."""
    rng = np.random.default_rng(70321)
    size_hits, power_hits, covered, reps = 0, 0, 0, 400
    for _ in range(reps):
        units = np.repeat(np.arange(20), rng.integers(20, 60, 20))
        k = units.size
        base = rng.standard_t(3, k) + 5.0
        null = paired_improvement(base, base + rng.standard_t(3, k), units, n_permutations=999,
                                  seed=int(rng.integers(1 << 30)))
        size_hits += null["p_value"] < 0.05
        shift = 0.3 + rng.normal(0, 0.2, 20)[units]              # unit-level scatter of the improvement
        cand = base - shift + rng.normal(0, 1.0, k)
        hit = paired_improvement(base, cand, units, n_permutations=999, seed=1)
        power_hits += hit["p_value"] < 0.05
        lo, hi = hit["ci"]
        covered += lo <= 0.3 <= hi
    assert size_hits / reps <= _binomial_upper(0.05, reps), size_hits
    assert power_hits / reps >= 0.9, power_hits
    assert 0.88 <= covered / reps <= 0.99, covered


def test_sign_flip_test_is_exact_for_few_units():
    """Five units all improving by the same amount: the exact one-sided p-value is 1 / 2^5."""
    units = np.repeat(np.arange(5), 3)
    out = paired_improvement(np.full(15, 2.0), np.full(15, 1.0), units)
    assert out["p_value"] == pytest.approx(1 / 32)
    assert out["mean_difference"] == pytest.approx(1.0) and out["positive_units"] == 5


def test_holm_steps_down_and_stops_at_the_first_failure():
    p = {"a": 0.001, "b": 0.012, "c": 0.02, "d": 0.04}
    # a: 0.001 <= 0.05/4; b: 0.012 <= 0.05/3; c: 0.02 <= 0.05/2; d: 0.04 <= 0.05 -> all
    assert holm(p, 0.05) == {"a": True, "b": True, "c": True, "d": True}
    # at 0.04: a <= 0.01 yes; b 0.012 <= 0.0133 yes; c 0.02 <= 0.02 yes; d 0.04 <= 0.04 yes
    assert all(holm(p, 0.04).values())
    # at 0.03: b 0.012 > 0.01 -> b and everything after it fail, even d (0.04 > 0.03 anyway)
    assert holm(p, 0.03) == {"a": True, "b": False, "c": False, "d": False}


# --------------------------------------------------------------------------- block bootstrap
def test_block_bootstrap_covers_the_mean_of_serially_correlated_errors():
    """AR(1) errors (phi = 0.9) in 20 blocks of 50: the interval of the mean over blocks covers the
    true mean in at least 85 % of 150 seeds, where one that resamples samples would cover far
    less (its interval is about 4 times too narrow). Catches a bootstrap over samples."""
    rng = np.random.default_rng(55102)
    units = np.repeat(np.arange(20), 50)
    covered = 0
    naive = 0
    for _ in range(150):
        e = np.zeros(1000)
        w = rng.normal(0, 1, 1000)
        for i in range(1, 1000):
            e[i] = 0.9 * e[i - 1] + w[i]
        x = 3.0 + e
        out = block_bootstrap({"x": x}, units, lambda s: float(np.mean(s["x"])), n_resamples=400,
                              seed=int(rng.integers(1 << 30)))
        covered += out["ci"][0] <= 3.0 <= out["ci"][1]
        half = 1.96 * x.std() / np.sqrt(x.size)
        naive += abs(x.mean() - 3.0) <= half
    assert covered / 150 >= 0.85, covered
    assert naive / 150 < 0.7           # the data really is serially correlated


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


@pytest.mark.parametrize("k", [300, 1307, 2000])
def test_time_block_split_never_cuts_a_block_and_uses_each_development_block_once(k):
    """A continuous motion of k samples: 20 contiguous blocks; the test split is 4 of them spread
    over the motion (not one end); every development block is validated in exactly one fold and
    no test sample is in a fold."""
    s = make_split(_data(k), test_fraction=0.2, n_blocks=20, n_folds=4, seed=31)
    assert s.unit_kind == "time block" and np.unique(s.units).size == 20
    assert np.all(np.diff(s.units) >= 0)                      # contiguous, in time order
    assert np.all(s.fold[s.test_rows] == -1) and np.all(s.fold[~s.test_rows] >= 0)
    for u in np.unique(s.units):
        assert np.unique(s.fold[s.units == u]).size == 1      # a block is never cut
    test_units = np.unique(s.units[s.test_rows])
    assert test_units.size == 4 and np.ptp(test_units) >= 10  # spread over the motion
    for kf in range(4):
        assert not np.any(s.calibration_rows(kf) & s.validation_rows(kf))
        assert np.all(s.calibration_rows(kf) | s.validation_rows(kf) | s.test_rows)


def test_grid_protocol_split_keeps_each_configuration_group_whole():
    """The paper's protocol: four approaches per configuration. A configuration's rows share a
    unit, so none is split between the test split and a fold, or between folds."""
    config = np.repeat(np.arange(60), 4)
    s = make_split(_data(240, config_id=config, sequence=np.arange(240)), n_blocks=20, seed=5)
    assert s.unit_kind == "configuration group"
    for c in range(60):
        rows = config == c
        assert np.unique(s.fold[rows]).size == 1


def test_too_few_units_for_the_split_is_refused_naming_the_file():
    with pytest.raises(DataFileError, match="toy.csv.*too few"):
        make_split(_data(40), n_blocks=4, n_folds=4)
