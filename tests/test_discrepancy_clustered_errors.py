"""Standard errors clustered over merged neighbouring units with t intervals, and values left on a
bound that was widened too late to be refitted.

The coverage test is independent of the mechanics: a straight line fitted by least squares to
AR(1) noise cut into many short time blocks, its Jacobian handed to
:func:`ctrplan.discrepancy.fits.estimates.covariance` (the function :func:`calibrate` calls). The
bound tests fit only a registration translation, which needs one mechanics solve of 12 samples.
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.signal import lfilter

from ctrplan.discrepancy import FitRun, FitStart, Noise, SynthProtocol, synthesize, write_synth
from ctrplan.discrepancy.measured.data import load_measured_data
from ctrplan.discrepancy.fits.estimates import covariance, interval_quantile, parameter_table
from ctrplan.discrepancy.options import CONFIDENCE
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings

calibration = importlib.import_module("ctrplan.discrepancy.fits.calibrate")

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
COARSE = ModelSettings(ds=6e-3)
#: AR(1) coefficient of the simulated noise along the motion.
PHI = 0.85
#: Samples of the motion and samples per time block (200 blocks).
N_SAMPLES, BLOCK = 1000, 5
#: Simulated records.
N_SEEDS = 400
#: True intercept and slope of the line.
TRUTH = np.array([1.0, 0.5])


def _line_fit(seed: int):
    """A line ``y = a + b t`` (t in [-1, 1]) with AR(1) noise fitted by least squares: its
    Jacobian (N, 2), residuals (N,) and the estimate (2,)."""
    rng = np.random.default_rng(seed)
    innovation = rng.standard_normal(N_SAMPLES)
    innovation[0] /= np.sqrt(1.0 - PHI ** 2)          # stationary from the first sample
    noise = lfilter([1.0], [1.0, -PHI], innovation)
    t = np.linspace(-1.0, 1.0, N_SAMPLES)
    X = np.column_stack([np.ones(N_SAMPLES), t])
    y = X @ TRUTH + noise
    estimate = np.linalg.lstsq(X, y, rcond=None)[0]
    return X, X @ estimate - y, estimate


def test_merged_clusters_with_t_quantile_cover_at_the_nominal_rate_where_raw_blocks_do_not():
    """AR(1) noise (phi 0.85) in 200 blocks of 5 samples: the intercept's interval from the raw
    blocks with a normal quantile covers the truth in about 73 % of 400 records (the seams
    between blocks carry most of the correlation); after merging neighbouring blocks
    (``motion`` and ``position`` given) with the t quantile on G - 1 degrees of freedom, in
    about 93 % (the nominal 95 % less the cluster-robust variance's own small-sample bias).
    Catches standard errors clustered on blocks whose residuals are correlated across their
    seams, and a normal quantile for few clusters."""
    z = interval_quantile(None)
    blocks = np.arange(N_SAMPLES) // BLOCK
    motion, position = np.zeros(N_SAMPLES, int), np.arange(N_SAMPLES)
    raw, merged, n_clusters = [], [], []
    for seed in range(N_SEEDS):
        X, f, estimate = _line_fit(seed)
        se_raw, _ = covariance(X, f, N_SAMPLES, clusters=blocks)
        raw.append(abs(estimate[0] - TRUTH[0]) <= z * se_raw[0])
        unc = covariance(X, f, N_SAMPLES, clusters=blocks, motion=motion, position=position)
        merged.append(abs(estimate[0] - TRUTH[0]) <= interval_quantile(unc.dof) * unc.stderr[0])
        n_clusters.append(unc.n_clusters)
    raw_share, merged_share = np.mean(raw), np.mean(merged)
    assert raw_share < 0.82, raw_share
    assert 0.90 <= merged_share <= 0.98, merged_share
    assert merged_share - raw_share > 0.12, (raw_share, merged_share)
    assert 8 <= min(n_clusters) and max(n_clusters) < N_SAMPLES // BLOCK, (min(n_clusters), max(n_clusters))


def test_units_of_several_motions_are_not_merged_and_one_cluster_leaves_the_error_undefined():
    """Configuration groups (each unit a set of whole motions, no serial order between them) are
    used as they are, and a single cluster gives NaN standard errors (its scores sum to the zero
    gradient), carried to a table row without an interval. Catches merging units that are not
    neighbours in time, and a falsely tiny error (or a crash) from one cluster."""
    X, f, _ = _line_fit(0)
    motion = np.arange(N_SAMPLES) // 50                 # 20 motions
    groups = motion % 10                                # 10 groups, each of two motions
    unc = covariance(X, f, N_SAMPLES, clusters=groups, motion=motion, position=np.arange(N_SAMPLES))
    assert unc.n_clusters == 10 and unc.dof == 9 and "not merged" in unc.note
    assert np.all(np.isfinite(unc.stderr))
    one = covariance(X, f, N_SAMPLES, clusters=np.zeros(N_SAMPLES), motion=motion, position=np.arange(N_SAMPLES))
    assert one.n_clusters == 1 and np.all(np.isnan(one.stderr))
    assert interval_quantile(one.dof) != interval_quantile(one.dof)     # NaN: no interval


@pytest.fixture(scope="module")
def pair_samples(tmp_path_factory):
    """The Table I pair (friction off) and 12 samples of a trajectory with 0.2 mm / 0.2 deg noise."""
    robot = load_robot(PAIR).replace(friction_coefficients=(0.0,))
    path = tmp_path_factory.mktemp("bounds") / "pair.csv"
    noise = Noise(position_rms=0.2e-3, angle_rms=float(np.deg2rad(0.2)))
    write_synth(path, synthesize(robot, {}, protocol=SynthProtocol.trajectory(12), noise=noise, seed=1,
                                 settings=COARSE))
    return robot, load_measured_data(path, robot)


def _flagged(robot, fit) -> bool:
    """The value's row of the parameter table says it is at a bound."""
    return parameter_table(robot, fit, fit.names)[0].at_bound


def test_a_bound_widened_on_the_last_allowed_pass_is_flagged(pair_samples, monkeypatch):
    """Measured tips 8 m off in x, two widenings allowed: ``registration_tx`` is fitted to its
    bounds 1 m, then 3 m, then 7 m, and the bound widened to 10 m after the last pass is never
    fitted beyond. The value (7 m) is flagged at its bound, the fit not converged, and the table
    row says so. Catches the flag computed with the widened bounds only, which left the value on
    the old bound unflagged (and the fit "converged")."""
    robot, data = pair_samples
    monkeypatch.setattr(calibration, "MAX_WIDENINGS", 2)
    far = replace(data, tip=data.tip + np.array([8.0, 0.0, 0.0]))
    fit = calibration.calibrate(robot, far, "standard", ("registration_tx",), max_evaluations=40,
                                run=FitRun(settings=COARSE))
    assert fit.values[0] == pytest.approx(7.0, abs=1e-5), fit.message
    assert fit.widened[-1] == "registration_tx upper bound to 10 m"
    assert len(fit.at_bound) == 1 and fit.at_bound[0].startswith("registration_tx (upper bound 7 m")
    assert "not refitted: 2 widenings, the most allowed" in fit.at_bound[0]
    assert not fit.converged and "at a bound, not converged" in fit.message
    assert _flagged(robot, fit)


def test_a_bound_widened_when_the_budget_is_spent_is_flagged(pair_samples):
    """A continuation (warm start) at the upper bound of ``registration_tx`` (1 m) with the
    optimum at 8 m and a budget of one evaluation: the bound is widened, the budget is spent,
    the value stays at 1 m (the optimizer even reports its gradient tolerance met). It is flagged
    at its bound and the fit is not converged. Catches a spent budget leaving a value on the old
    bound unflagged and the fit "converged", and so a candidate that could be named."""
    robot, data = pair_samples
    far = replace(data, tip=data.tip + np.array([8.0, 0.0, 0.0]))
    fit = calibration.calibrate(robot, far, "standard", ("registration_tx",), start=FitStart([1.0], warm=True),
                                max_evaluations=1, run=FitRun(settings=COARSE))
    assert fit.values[0] == pytest.approx(1.0, abs=1e-5), fit.message
    assert fit.widened == ("registration_tx upper bound to 3 m",)
    assert fit.at_bound == ("registration_tx (upper bound 1 m, widened to 3 m but not refitted: the evaluation "
                            "budget is spent)",)
    assert not fit.converged
    assert _flagged(robot, fit)


def test_calibrate_records_the_clusters_and_the_table_uses_t_with_their_dof(pair_samples):
    """A registration fit with its samples in 4 time blocks (too few to merge): the result
    records G = 4 and 3 degrees of freedom (also through ``as_dict`` / ``from_dict``), and the
    table's interval is ``value +- t(3) stderr``. Catches G or the dof lost on the way to the
    interval, and a normal quantile where the errors are clustered."""
    robot, data = pair_samples
    names = ("registration_tx", "registration_ty")
    fit = calibration.calibrate(robot, data, "standard", names,
                                run=FitRun(settings=COARSE, clusters=np.arange(12) // 3))
    assert fit.n_clusters == 4 and fit.dof == 3
    again = calibration.CalibrationResult.from_dict(fit.as_dict())
    assert again.n_clusters == 4 and again.dof == 3
    row = parameter_table(robot, fit, names)[0]
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, 3)) * row.stderr
    assert row.ci == pytest.approx((row.value - half, row.value + half), rel=1e-12)
    plain = calibration.calibrate(robot, data, "standard", names, run=FitRun(settings=COARSE))
    assert plain.n_clusters is None and plain.dof is None
    row = parameter_table(robot, plain, names)[0]
    assert row.ci[1] - row.value == pytest.approx(float(stats.norm.ppf(0.5 + CONFIDENCE / 2)) * row.stderr)
