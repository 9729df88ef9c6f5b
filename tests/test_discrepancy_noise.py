"""The sensor noise estimate and the noise test of ctrplan.discrepancy.measured.noise, checked by simulation
independent of the mechanics: the rms recovered from rests for white and for time-correlated
(AR(1)) noise on the rest structures of a 10 Hz trajectory and of Ha's measured trajectory, the
honesty of the estimate's degrees of freedom, the test's false-alarm rate and power on
out-of-sample residuals of a fitted model, the failure of the former lag-1 estimate, and the
fallbacks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal, stats

from ctrplan.discrepancy.measured.data import MeasuredData
from ctrplan.discrepancy.verdict.consistency import NoiseTest, noise_test
from ctrplan.discrepancy.measured.noise import NoiseEstimate, _median_constant, estimate_noise
from ctrplan.discrepancy.outputs.words import noise_text
from ctrplan.history import MotionRecord

#: rms length of the simulated 3-D noise vector [m] (per component 0.5 / sqrt(3) mm).
NOISE_RMS = 0.5e-3
#: Lag-1 coefficient of the correlated noise (per sample at 10 Hz).
PHI = 0.8
#: Rest runs of Ha's measured trajectory (samples at identical joints), 1307 samples at 10 Hz.
HA_RESTS = (2, 3, 4, 6, 9, 12, 15, 24, 31)
HA_SAMPLES = 1307


def _binomial_upper(rate: float, n: int, z: float = 3.0) -> float:
    """A rejection count's upper limit at ``z`` standard deviations."""
    return rate + z * np.sqrt(rate * (1 - rate) / n)


# --------------------------------------------------------------------------- simulated records
def _configurations(rng, n_samples: int, lengths) -> np.ndarray:
    """Configuration index (K,) of a motion of ``n_samples`` samples that rests ``lengths``
    samples at a time (in random order, at least one moving sample between rests) and is at a
    new configuration at each sample between rests."""
    lengths = rng.permutation(np.asarray(lengths, int))
    moving = n_samples - int(lengths.sum())
    cuts = np.sort(rng.choice(np.arange(1, moving), lengths.size, replace=False))
    starts = cuts + np.concatenate([[0], np.cumsum(lengths)[:-1]])
    config = np.arange(n_samples)
    for s, m in zip(starts, lengths):
        config[s:s + m] = s
    return config


def _trajectory(rng, n_samples: int, n_rests: int) -> np.ndarray:
    """:func:`_configurations` of a 10 Hz trajectory whose moves end in rests of 0.3-1.5 s
    (3-15 samples)."""
    return _configurations(rng, n_samples, rng.integers(3, 16, n_rests))


def _noise(rng, n: int, phi: float, rms: float = NOISE_RMS) -> np.ndarray:
    """Stationary AR(1) noise (n, 3) [m], lag-1 coefficient ``phi`` per component (white at 0),
    rms length of the 3-D vector ``rms``."""
    sigma = rms / np.sqrt(3.0)
    x0 = rng.standard_normal(3)
    w = rng.standard_normal((n - 1, 3)) * np.sqrt(1.0 - phi ** 2)
    x = np.vstack([x0, signal.lfilter([1.0], [1.0, -phi], w, axis=0, zi=phi * x0[None, :])[0]])
    return sigma * x


def _data(tip, config) -> MeasuredData:
    """Measured data of tips ``tip`` (K, 3) [m] at configurations ``config`` (K,) (two tubes,
    the first one's rotation encodes the configuration), one motion."""
    k = tip.shape[0]
    alpha = np.stack([np.asarray(config, float) * 1e-3, np.zeros(k)], axis=1)
    beta = np.zeros((k, 2))
    sequence = np.zeros(k, int)
    return MeasuredData(alpha=alpha, beta=beta, tip=np.asarray(tip, float), tangent=None, eta=np.zeros((k, 1), int),
                        translation_last=np.zeros((k, 1), bool), sequence=sequence, config_id=np.asarray(config),
                        subset=None, time=None, file="toy.csv", frame="robot",
                        record=MotionRecord(alpha, beta, sequence=sequence),
                        rows=np.arange(k), given_eta=np.zeros((k, 1), int))


def _lag1_estimate(tip, config) -> tuple[float, int]:
    """The former estimate (``decision.estimate_noise`` before this module): median length of
    the lag-1 tip differences at rest over the Maxwell median 1.5382 sqrt(2), times sqrt(3)
    [m]; and the number of pairs."""
    same = np.diff(config) == 0
    d = np.linalg.norm(np.diff(tip, axis=0)[same], axis=1)
    return float(np.median(d) / (1.5382 * np.sqrt(2.0)) * np.sqrt(3.0)), int(d.size)


STRUCTURES = {
    "trajectory": lambda rng: _trajectory(rng, 900, 45),
    "ha": lambda rng: _configurations(rng, HA_SAMPLES, HA_RESTS),
}


# --------------------------------------------------------------------------- the estimate
@pytest.mark.parametrize("structure, phi, median_tol, spread_tol", [
    ("trajectory", 0.0, 0.03, 0.10),
    ("trajectory", PHI, 0.08, 0.45),
    ("ha", 0.0, 0.06, 0.30),
    ("ha", PHI, 0.15, 0.80),
])
def test_estimate_recovers_the_rms_and_its_degrees_of_freedom_are_honest(structure, phi, median_tol, spread_tol):
    """White and AR(1) (phi 0.8) noise of 0.5 mm rms on the rests of a 10 Hz trajectory (900
    samples, 45 rests of 3-15 samples) and of Ha's trajectory (runs of 2-31 samples), 30 seeds
    each: the median estimate is within ``median_tol`` of 0.5 mm (about 4 standard errors of
    the median: 3 % white / 8 % correlated on the trajectory, 6 % / 15 % on Ha's nine rests),
    every estimate within ``spread_tol`` (measured over two sets of 30 seeds: at most 0.05,
    0.33, 0.21, 0.58), and the chi-square interval of the reported ``dof`` (95 %) covers the
    true variance in at least 24 of the 30 seeds (measured 27-30).

    Catches a lag-1 (white-noise) estimate on correlated noise (0.22 mm: median 55 % low), a
    fit that takes the semivariance of the first lags for the sill, and ``dof`` counted as if
    the pairs were independent (0.6 x 3 lag-1 pairs: on AR noise the interval is then several
    times too narrow and covers 9-12 of 30)."""
    rng = np.random.default_rng({"trajectory": 3101, "ha": 3102}[structure] + int(10 * phi))
    config = STRUCTURES[structure](rng)
    ratios, covered = [], 0
    for seed in range(30):
        est = estimate_noise(_data(_noise(rng, config.size, phi), config), seed=seed)
        assert est.source == "rests" and est.dof > 0
        ratios.append(est.position_rms_m / NOISE_RMS)
        s2, nu = est.variance_m2, est.dof
        truth = NOISE_RMS ** 2 / 3.0
        covered += s2 * nu / stats.chi2(nu).ppf(0.975) <= truth <= s2 * nu / stats.chi2(nu).ppf(0.025)
    ratios = np.array(ratios)
    assert abs(np.median(ratios) - 1.0) <= median_tol, np.round(ratios, 3)
    assert np.all(np.abs(ratios - 1.0) <= spread_tol), np.round(ratios, 3)
    assert covered >= 24, covered


def test_median_of_few_squared_distances_is_scaled_by_its_expected_value():
    """The semivariance of a lag with N pairs is the median of |d|^2 over the expected median
    of N chi-square(3) values: 3.0 (the mean) for N = 1 and 2, 2.654 for 3, towards 2.366
    (the population median) for many; checked against 20000 simulated medians within 1 %.
    Catches the population median used for few pairs (27 % high at 1 or 2)."""
    rng = np.random.default_rng(12)
    for n in (1, 2, 3, 4, 7, 30):
        simulated = np.median(rng.chisquare(3, (20000, n)), axis=1).mean()
        assert _median_constant(n) == pytest.approx(simulated, rel=0.01)
    assert _median_constant(1) == pytest.approx(3.0) and _median_constant(2) == pytest.approx(3.0)
    assert _median_constant(2001) == pytest.approx(stats.chi2(3).median(), rel=1e-3)


def test_lag1_estimate_reads_a_fifth_of_correlated_noise_the_semivariogram_all_of_it():
    """AR(1) noise, phi 0.8 per sample at 10 Hz, 0.5 mm rms, on the rests of a 10 Hz trajectory
    (1300 samples, 60 rests of 3-15): the former estimate from lag-1 differences reads
    sqrt(1 - phi) of the rms, about 0.22 mm, and its F test (3 K white degrees of freedom)
    calls a noise-only residual NOT consistent with noise in nearly every seed; the
    semivariogram's sill reads 0.5 mm with the correlation (lag-1 about 0.8, a few samples long;
    seen within the rests in most seeds, in about 12 % the fit's correlation outlasts them and
    the value is a lower bound) and its test accepts the same residual. Catches the bug: a noise from lag-1 differences
    only, or a sill taken before the semivariogram levels off."""
    rng = np.random.default_rng(2207)
    config = _trajectory(rng, 1300, 60)
    old, new, old_alarm, new_alarm, lag1, seen = [], [], 0, 0, [], 0
    for seed in range(10):
        tip = _noise(rng, config.size, PHI)
        old_rms, pairs = _lag1_estimate(tip, config)
        est = estimate_noise(_data(tip, config), seed=seed)
        old.append(old_rms)
        new.append(est.position_rms_m)
        lag1.append(est.lag1_correlation)
        seen += est.correlation_seen and not est.lower_bound
        r = tip[:400]                                       # a residual that is pure noise
        ms = float(np.mean(r * r))
        f_old = ms / (old_rms ** 2 / 3.0)
        old_alarm += f_old > stats.f(r.size, 0.6 * 3 * pairs).ppf(0.99)
        new_alarm += not noise_test(r, np.arange(400), np.zeros(400, int), est, n_parameters=0, n_fitted=1,
                                    alpha=0.01, leave_out_rests=False).consistent
    assert np.median(old) == pytest.approx(NOISE_RMS * np.sqrt(1 - PHI), rel=0.1)   # 0.224 mm
    assert np.median(new) == pytest.approx(NOISE_RMS, rel=0.15)     # 0.55 mm here; +2 % over many seeds
    assert 0.65 <= np.median(lag1) <= 0.9
    assert seen >= 7, seen                  # the rest: "at least", correlation outlasting the rests
    assert old_alarm >= 9 and new_alarm <= 1, (old_alarm, new_alarm)


@pytest.mark.parametrize("phi", [0.0, PHI])
def test_tracker_outliers_barely_move_the_estimate(phi):
    """2 % of the samples (about 7 % of the pairs at each lag) hit by 10 mm spikes, 20 times
    the noise: the estimate moves by at most 8 % (measured at most 5 %), where a mean of
    squared differences would read several times the noise. Catches a non-robust (mean-based)
    semivariogram."""
    rng = np.random.default_rng(31 + int(10 * phi))
    config = _trajectory(rng, 900, 45)
    for seed in range(5):
        tip = _noise(rng, config.size, phi)
        spiked = tip.copy()
        hit = rng.random(config.size) < 0.02
        spiked[hit] += rng.normal(0.0, 10e-3, (int(hit.sum()), 3))
        clean, dirty = estimate_noise(_data(tip, config)), estimate_noise(_data(spiked, config))
        assert dirty.position_rms_m == pytest.approx(clean.position_rms_m, rel=0.08)


def test_rests_too_short_to_see_the_correlation_give_a_lower_bound_said_so():
    """Rests of only 2 samples (lag 1 alone) on AR(1) noise, and rests of 3-15 samples on noise
    correlated over 30 samples (phi 0.967): the correlation cannot be seen; the estimate is a
    lower bound, its sentence says "at least", and it is never reported as the noise (a
    lag-1 value silently taken for the noise is the bug this catches)."""
    rng = np.random.default_rng(77)
    config = _configurations(rng, 600, [2] * 60)
    tip = _noise(rng, config.size, PHI)
    est = estimate_noise(_data(tip, config))
    assert est.source == "rests" and est.lower_bound and not est.correlation_seen
    text = noise_text(est.as_dict())
    assert text.startswith("at least") and "too few to see a correlation" in text
    assert est.position_rms_m < 0.8 * NOISE_RMS
    config = _trajectory(rng, 1300, 60)
    est = estimate_noise(_data(_noise(rng, config.size, np.exp(-1 / 30)), config))
    text = noise_text(est.as_dict())
    assert est.lower_bound and text.startswith("at least") and "outlasts the rests" in text


def test_only_the_allowed_rows_and_only_true_rests_are_used():
    """The estimate uses the samples in ``rows`` only (a test split's rests with 20 times the
    noise leave it unchanged) and only runs adjacent in the record: taking every other sample
    (``data.rows`` differ by 2) leaves no rest, so the estimate falls back. Catches a test split
    leaking into the noise, and "rests" made of samples that were not consecutive."""
    rng = np.random.default_rng(515)
    config = _trajectory(rng, 900, 45)
    tip = _noise(rng, config.size, 0.0)
    test = np.arange(config.size) >= 700
    loud = tip.copy()
    loud[test] *= 20.0
    a = estimate_noise(_data(tip, config), rows=~test)
    b = estimate_noise(_data(loud, config), rows=~test)
    assert a.position_rms_m == b.position_rms_m and a.dof == b.dof
    assert b.position_rms_m == pytest.approx(NOISE_RMS, rel=0.1)
    assert np.all(b.rest_rows < 700)
    thinned = _data(tip, config).take(np.arange(0, config.size, 2))
    assert estimate_noise(thinned).source != "rests"


def test_fallbacks_stated_repeated_configurations_unknown():
    """Too few rests: the stated value (no dof: the test is then chi-square); no rests and no
    statement: the spread at repeated configurations, an upper bound; neither: unknown, and
    the test refuses it."""
    rng = np.random.default_rng(8)
    k = 200
    moving = np.arange(k)
    tip = _noise(rng, k, 0.0)
    est = estimate_noise(_data(tip, moving), stated=0.3e-3)
    assert est.source == "stated" and est.position_rms_m == 0.3e-3 and est.dof is None
    visits = np.repeat(np.arange(50), 4)
    order = rng.permutation(k)                            # revisits, never consecutive at rest
    visits = visits[order]
    visits[1:][np.diff(visits) == 0] += 1000              # break any accidental rest
    est = estimate_noise(_data(tip, visits))
    assert est.source == "repeated configurations" and est.upper_bound
    assert est.position_rms_m == pytest.approx(NOISE_RMS, rel=0.2)
    est = estimate_noise(_data(tip, moving))
    assert est.source is None and est.position_rms_m is None and noise_text(est.as_dict()).startswith("unknown")
    with pytest.raises(ValueError, match="must be known"):
        noise_test(tip, np.arange(k), np.zeros(k, int), est, n_parameters=1, n_fitted=10, alpha=0.01)
    with pytest.raises(ValueError, match="positive"):
        estimate_noise(_data(tip, moving), stated=-1.0)
    with pytest.raises(ValueError, match="boolean mask"):
        estimate_noise(_data(tip, moving), rows=np.arange(k))


def test_estimate_is_reproducible_and_json_ready():
    """The same seed gives the same estimate and dof; ``as_dict`` survives JSON."""
    rng = np.random.default_rng(4)
    config = _trajectory(rng, 700, 40)
    data = _data(_noise(rng, config.size, PHI), config)
    a, b = estimate_noise(data, seed=3), estimate_noise(data, seed=3)
    assert a.dof == b.dof and a.position_rms_m == b.position_rms_m
    out = json.loads(json.dumps(a.as_dict()))
    assert out["source"] == "rests" and len(out["lags"]) == len(out["semivariance_m2"]) == len(out["pair_counts"])
    assert "description" not in out and noise_text(out) == noise_text(a.as_dict())
    assert noise_text(out).startswith(f"{a.position_rms_m * 1e3:.3f} mm rms from {a.n_runs} rests ({a.n_pairs} pairs")


# --------------------------------------------------------------------------- the test
def _known(phi: float) -> NoiseEstimate:
    """The true noise model as an estimate with (nearly) exact variance."""
    return NoiseEstimate(position_rms_m=NOISE_RMS, source="rests", nugget_share=0.0, lag1_correlation=phi,
                         correlation_length=-1.0 / np.log(phi), dof=1e6)


def test_residual_degrees_of_freedom_match_the_variance_of_a_correlated_mean_square():
    """AR(1) noise (phi 0.8) on three runs of record rows with gaps: the effective degrees of
    freedom of the test, 3 K^2 / sum rho^2 (Bayley & Hammersley), equal 2 / Var(ms / sigma^2)
    over 4000 simulations within 7 % (measured 202 against 195), and with the noise known the
    test rejects 5 % of them at alpha 0.05 (3.5-6.5 %; measured 5.8 %); with white noise the dof
    are 3 K. Catches a test that counts 3 K independent squares on correlated noise (here 4.6
    times too many: 22 % false alarms)."""
    rng = np.random.default_rng(99)
    index = np.concatenate([np.arange(0, 120), np.arange(125, 245), np.arange(400, 460)])
    n = 4000
    x = np.stack([_noise(rng, 460, PHI)[index] for _ in range(n)])
    ms = np.mean(x * x, axis=(1, 2)) / (NOISE_RMS ** 2 / 3.0)
    t = noise_test(x[0], index, np.zeros(index.size, int), _known(PHI), n_parameters=0, n_fitted=1, alpha=0.05)
    assert t.dof_residual == pytest.approx(2.0 / np.var(ms), rel=0.07)
    assert t.dof_residual < 0.3 * 3 * index.size
    assert 0.035 <= np.mean(ms > t.threshold) <= 0.065


def test_a_stated_noise_of_unknown_correlation_is_tested_with_conservative_degrees_of_freedom():
    """A stated noise rms (no rests: its correlation unknown) against 1500 residuals of pure
    noise of that rms on 300 consecutive record rows. White noise: about 5 % false alarms at
    alpha 0.05 (2.5-7.5 %) with nearly 3 K degrees of freedom. AR(1) noise at phi 0.8: at most
    5 % plus binomial slack, where counting 3 K independent squares (the white-noise chi-square
    threshold) gives more than 15 %. Catches a stated noise tested as white whatever the
    residual's correlation."""
    rng = np.random.default_rng(2024)
    index = np.arange(300)
    seq = np.zeros(index.size, int)
    stated = NoiseEstimate(position_rms_m=NOISE_RMS, source="stated")
    white_threshold = stats.chi2(3 * index.size).ppf(0.95) / (3 * index.size)
    reps = 1500
    for phi in (0.0, 0.8):
        alarms = white_alarms = 0
        for _ in range(reps):
            x = _noise(rng, index.size, phi)
            t = noise_test(x, index, seq, stated, n_parameters=0, n_fitted=1, alpha=0.05)
            alarms += not t.consistent
            white_alarms += t.statistic > white_threshold
            assert t.dof_noise is None and t.residual_lag1 is not None
        rate = alarms / reps
        if phi == 0.0:
            assert 0.025 <= rate <= 0.075, rate
            assert t.dof_residual > 0.8 * 3 * index.size
        else:
            assert rate <= _binomial_upper(0.05, reps), rate
            assert white_alarms / reps > 0.15, white_alarms


def test_noise_test_result_is_frozen_and_its_dict_is_plain_json():
    """``noise_test`` returns a frozen :class:`NoiseTest` whose ``as_dict`` has the keys of the
    former dict result, in order (then the stated noise's residual lag-1 correlation), with plain
    Python values (JSON round trip unchanged). Catches a
    numpy scalar or a renamed key reaching ``results.json``."""
    rng = np.random.default_rng(7)
    index = np.arange(200)
    r = _noise(rng, 200, PHI)
    t = noise_test(r, index, np.zeros(200, int), _known(PHI), n_parameters=2, n_fitted=600, alpha=0.05)
    assert isinstance(t, NoiseTest)
    with pytest.raises(AttributeError):
        t.consistent = not t.consistent
    d = t.as_dict()
    assert list(d) == ["statistic", "threshold", "p_value", "inflation", "n_fitted_effective", "dof_residual",
                       "dof_noise", "n_samples", "n_rest_samples_left_out", "consistent", "false_alarm_rate",
                       "noise_lower_bound", "noise_upper_bound", "residual_lag1"]
    assert d["residual_lag1"] is None                       # an estimated noise carries its own correlation
    assert all(type(v) in (float, int, bool) for k, v in d.items() if k != "residual_lag1")
    assert json.loads(json.dumps(d)) == d and d["consistent"] is t.consistent and d["n_samples"] == 200


@pytest.mark.parametrize("smooth", [True, False])
def test_noise_test_allows_for_parameters_fitted_on_correlated_noise(smooth):
    """The noise known (AR(1), phi 0.8), 8 parameters fitted on 200 samples (blocks of 25
    interleaved with the 200 out-of-sample ones, 1000 seeds). Regressors that vary slowly along
    the motion (smooth): the fitted values' error is that of n / 9 independent observations
    (the long-run factor 1 + 2 phi / (1 - phi)); with that inflation the test rejects at most
    5 % plus 3 binomial standard deviations (measured 5.6 %), with the white-noise 1 + p / n it
    rejects 19 %. Regressors independent from sample to sample (``smooth_regressors=False``):
    1 + p / n holds (measured 4.5 %). Catches a test that ignores the fitted parameters or the
    noise's correlation in them."""
    rng = np.random.default_rng(4242 + smooth)
    p, k, reps = 8, 600, 1000
    t = np.arange(k)
    block = (t // 25) % 3
    fit, out = block == 0, block == 2
    est = _known(PHI)
    seq = np.zeros(out.sum(), int)
    rejected, white = 0, 0
    for _ in range(reps):
        if smooth:
            w = rng.uniform(2 * np.pi / 400, 2 * np.pi / 60, (3, p))
            x = np.cos(t[:, None, None] * w + rng.uniform(0, 2 * np.pi, (3, p)))
        else:
            x = rng.normal(size=(k, 3, p))
        tip = x @ rng.normal(0.0, 1e-3, p) + _noise(rng, k, PHI)
        b = np.linalg.lstsq(x[fit].reshape(-1, p), tip[fit].ravel(), rcond=None)[0]
        r = tip[out] - x[out] @ b
        rejected += not noise_test(r, t[out], seq, est, n_parameters=p, n_fitted=3 * int(fit.sum()), alpha=0.05,
                                   smooth_regressors=smooth).consistent
        white += not noise_test(r, t[out], seq, est, n_parameters=p, n_fitted=3 * int(fit.sum()), alpha=0.05,
                                smooth_regressors=False).consistent
    assert rejected / reps <= _binomial_upper(0.05, reps), rejected
    if smooth:
        assert white / reps > 0.12, white          # the white-noise inflation is not enough


def _cross_validated_case(rng, config, phi, p, seed):
    """One case like the workflow's noise check: a model linear in ``p`` parameters with
    regressors that vary slowly along the motion (constant at rest), noise AR(1) ``phi``; 20
    time blocks, 4 held back as a test split, the other 16 in 4 folds; each fold's residual
    predicted by the fit on the other three. Returns the out-of-fold residual (K, 3) [m], its
    record rows, the residual with a missed effect of 0.83 noise rms added (1.3 times the
    noise in all), the noise estimate from the development rows, and the fitted observations
    of the smallest fold fit."""
    k = config.size
    w = rng.uniform(2 * np.pi / 400, 2 * np.pi / 60, (3, p))
    x = np.cos(config[:, None, None] * w + rng.uniform(0, 2 * np.pi, (3, p)))       # (K, 3, p)
    tip = x @ rng.normal(0.0, 1e-3, p) + _noise(rng, k, phi)
    block = np.arange(k) * 20 // k
    test = block % 5 == 2
    fold = np.where(test, -1, block % 4)
    res = np.full((k, 3), np.nan)
    n_fit = []
    for f in range(4):
        fit, out = (fold >= 0) & (fold != f), fold == f
        b = np.linalg.lstsq(x[fit].reshape(-1, p), tip[fit].ravel(), rcond=None)[0]
        res[out] = tip[out] - x[out] @ b
        n_fit.append(3 * int(fit.sum()))
    dev = np.flatnonzero(~test)
    missed = rng.normal(0.0, NOISE_RMS / np.sqrt(3.0) * np.sqrt(1.3 ** 2 - 1.0), (dev.size, 3))
    est = estimate_noise(_data(tip, config), rows=~test, seed=seed)
    return res[dev], dev, res[dev] + missed, est, min(n_fit)


@pytest.mark.parametrize("phi, reps, power_floor", [(0.0, 150, 0.9), (PHI, 200, 0.5)])
def test_noise_test_false_alarm_rate_and_power(phi, reps, power_floor):
    """Noise only (white, or AR(1) phi 0.8), a 6-parameter model cross-validated in 4 folds on a
    10 Hz trajectory of 1300 samples with 60 rests of 3-15 samples: the test calls the
    out-of-fold residual NOT consistent with noise in at most alpha (0.05 and 0.01) plus
    3 binomial standard deviations of the seeds. With a missed effect that makes the residual
    1.3 times the noise rms, it rejects at alpha 0.05 in at least ``power_floor`` of the seeds
    (measured 0.97 white, 0.6 correlated: on correlated noise the rests hold about 45 degrees of
    freedom of the variance, the Cramer-Rao bound for these rests being 77).

    Catches, end to end, a noise estimate that misses the correlation (lag-1: false alarms in
    nearly every seed), an estimate's dof counted as if its pairs were independent (0.6 x 3
    lag-1 pairs: 21 % false alarms at 5 % on correlated noise), and a test made safe by never
    rejecting. (Here the rests' few degrees of freedom dominate the threshold; the residual's
    dof and the inflation are checked by the two tests above.)"""
    rng = np.random.default_rng(6011 if phi else 6010)
    config = _trajectory(rng, 1300, 60)
    alarms = {0.05: 0, 0.01: 0}
    hits = 0
    for seed in range(reps):
        res, rows, missed, est, n_fit = _cross_validated_case(rng, config, phi, 6, seed)
        seq = np.zeros(rows.size, int)
        for alpha in alarms:
            alarms[alpha] += not noise_test(res, rows, seq, est, n_parameters=6, n_fitted=n_fit,
                                            alpha=alpha).consistent
        hits += not noise_test(missed, rows, seq, est, n_parameters=6, n_fitted=n_fit, alpha=0.05).consistent
    for alpha, count in alarms.items():
        assert count / reps <= _binomial_upper(alpha, reps), (alpha, count)
    assert hits / reps >= power_floor, hits


def test_rests_whose_first_samples_still_move_are_trimmed_and_pure_noise_is_not():
    """A 10 Hz trajectory whose tip, seen through a tracker that lags the joints, still moves
    over the first sample of every rest (a 2.5 mm step decaying to 0.2 mm, 0.5 mm rms white
    noise): the first sample of the rests is left out and the estimate is within 15 % of the
    truth, where keeping it inflates it; on noise alone no sample is left out in at least 18 of
    20 seeds. Catches a noise read from rests that still hold the end of a move."""
    rng = np.random.default_rng(808)
    config = _trajectory(rng, 600, 40)
    noise = _noise(rng, 600, 0.0)
    tip = noise.copy()
    starts = np.flatnonzero(np.r_[True, np.diff(config) != 0] & np.r_[np.diff(config) == 0, False])
    direction = rng.normal(size=(starts.size, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    for s, d in zip(starts, direction):
        tip[s] += 2.5e-3 * d                    # the sample the tube is still arriving at
        tip[s + 1] += 0.2e-3 * d
    est = estimate_noise(_data(tip, config))
    assert est.settled_samples >= 1 and f"the first {est.settled_samples} sample" in noise_text(est.as_dict())
    assert est.position_rms_m == pytest.approx(NOISE_RMS, rel=0.15)
    trimmed = 0
    for seed in range(20):
        r = np.random.default_rng(seed)
        c = _trajectory(r, 600, 40)
        trimmed += estimate_noise(_data(_noise(r, 600, 0.0), c), n_simulations=20).settled_samples > 0
    assert trimmed <= 2, trimmed


def test_the_noise_sentence_names_the_source_and_why_from_the_record():
    """Estimates written by hand: a stated value says why the rests were not used (too few
    pairs, or pairs without variation), repeated configurations give an upper bound with their
    row count, and a results file of an earlier ctrplan, which stored the sentence, is printed as
    stored. Catches a stated value reported without its reason, and the two reasons swapped."""
    from ctrplan.discrepancy.options import MIN_REST_PAIRS

    few = NoiseEstimate(position_rms_m=0.25e-3, source="stated", n_pairs=7, stated_m=0.25e-3).as_dict()
    assert noise_text(few) == (f"0.250 mm rms as stated for the data (it has 7 pairs of consecutive samples at rest, "
                               f"fewer than {MIN_REST_PAIRS})")
    flat = NoiseEstimate(position_rms_m=0.25e-3, source="stated", n_pairs=400, stated_m=0.25e-3,
                         no_variation=True).as_dict()
    assert "400 pairs of consecutive samples at rest that show no variation" in noise_text(flat)
    rep = NoiseEstimate(position_rms_m=0.5e-3, source="repeated configurations", n_pairs=90, upper_bound=True)
    assert noise_text(rep.as_dict()).startswith("at most 0.500 mm rms: spread of 90 rows at repeated configurations")
    assert noise_text({"description": "as stored", "source": "rests"}) == "as stored"
