"""Exact Jacobian columns of standard-model fits (``_Objective.standard_columns``): the standard
model's tip derivatives (implicit-function theorem on the shooting residual) chained with what
each fitted parameter changes (packed precurvatures and stiffnesses, the motion history's base
rotations) and the output map, checked against central differences of the whole Eq. (49)
error components, which solve the model again at every step."""

from __future__ import annotations

import importlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ctrplan.discrepancy import FitRun, Noise, SynthProtocol, synthesize, write_synth
from ctrplan.discrepancy.fits.parameters import parameter, read_parameters
from ctrplan.discrepancy.measured.data import load_measured_data
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings

calibration = importlib.import_module("ctrplan.discrepancy.fits.calibrate")
objective = importlib.import_module("ctrplan.discrepancy.fits.objective")

ROOT = Path(__file__).resolve().parents[1]
COARSE = ModelSettings(ds=6e-3)
#: Relative step of the reference central differences of a mechanical parameter: at 1e-5 the
#: shooting tolerance of the three solves shows (a planar configuration solved exactly beside two
#: that stop at their tolerance), at 1e-2 the truncation does; at 1e-3 both are below 1e-7 of
#: the column.
REFERENCE_STEP = 1e-3
#: ... and of a parameter of the motion history (backlash, time offset), whose map is piecewise
#: linear: a step of 1e-3 rad or s crosses the kinks of samples near a reversal or a sample time.
HISTORY_STEP = 1e-5
HISTORY = ("backlash", "time_offset")
#: Agreement asked of every column, relative to its largest entry.
TOLERANCE = 1e-6

CASES = {
    # robot file, hidden effect, fitted parameters with their starting values (None: the file's)
    "pair": ("ha2019-table1-tube-pair.toml", {"time_offset": {"time_offset": 0.3}},
             {"precurvature_y_1": None, "precurvature_y_2": None, "k_xy_relative_2": None,
              "precurvature_x_2": 0.8, "poisson_ratio_2": None, "backlash_2": 0.02, "time_offset": 0.113,
              "registration_rz": 0.01}),
    "three-tube": ("ha2019-table2-nominal.toml", {"backlash": {"backlash_3": 0.03}},
                   {"precurvature_y_1": None, "precurvature_y_3": None, "k_xy_relative_2": None,
                    "k_xy_relative_3": None, "precurvature_x_1": -0.6, "poisson_ratio_3": None,
                    "backlash_3": 0.02, "time_offset": 0.113}),
}


def _case(tmp_path, key, samples=60):
    name, hidden, start = CASES[key]
    robot = load_robot(ROOT / "model" / name)
    robot = robot.replace(friction_coefficients=tuple(0.0 for _ in robot.friction_coefficients))
    path = tmp_path / f"{key}.csv"
    write_synth(path, synthesize(robot, hidden, protocol=SynthProtocol.trajectory(samples),
                                 noise=Noise(position_rms=0.2e-3, angle_rms=float(np.deg2rad(0.2))), seed=5,
                                 settings=COARSE))
    data = load_measured_data(path, robot)
    names = tuple(start)
    x0 = read_parameters(robot, names)
    for j, v in enumerate(start.values()):
        if v is not None:
            x0[j] = v
    specs = [parameter(robot, n) for n in names]
    obj = objective.FitObjective(robot, data, "standard", names, {}, COARSE, 1)
    bounds = (np.array([p.lower for p in specs]), np.array([p.upper for p in specs]),
              np.array([p.scale for p in specs]))
    return robot, data, names, x0, obj, bounds


def _central(jac, x0, j, step=REFERENCE_STEP):
    h = step * max(1.0, abs(x0[j]))
    xp, xm = x0.copy(), x0.copy()
    xp[j] += h
    xm[j] -= h
    return (jac.components(xp)[0] - jac.components(xm)[0]) / (2 * h)


def _column_errors(obj, bounds, x0, names):
    """Largest error of each mechanical column against central differences, relative to the
    column's largest entry, and the columns that came from exact derivatives."""
    jac = objective.ComponentJacobians(obj, *bounds)
    _, _, ok, jc = jac.exact(x0)
    derived = obj.standard_columns(x0, np.flatnonzero(jac.mech))
    errors = {}
    for j in derived:
        central = _central(jac, x0, j, HISTORY_STEP if names[j].startswith(HISTORY) else REFERENCE_STEP)
        errors[j] = np.abs(jc[ok, :, j] - central[ok]).max() / np.abs(central[ok]).max()
    return errors, set(derived)


@pytest.mark.parametrize("key", sorted(CASES))
def test_exact_columns_match_central_differences(tmp_path, key):
    """Every mechanical column of a standard-model fit that has exact derivatives agrees with
    central differences of the re-solved model to 1e-6 of its largest entry; a time offset on a
    motion that translates a tube (the three-tube trajectory) has none and is differenced, one
    on a motion that only rotates (the pair) has one. Catches a chain term with a wrong sign,
    unit or parameter, a derivative taken at another solution than the fit's, and a column
    claimed exact where the discrete map is only piecewise smooth."""
    robot, data, names, x0, obj, bounds = _case(tmp_path, key)
    errors, derived = _column_errors(obj, bounds, x0, names)
    translates = bool(np.ptp(data.record.beta, axis=0).max() > 0)
    mechanical = {j for j, n in enumerate(names) if not n.startswith("registration")}
    expected = mechanical - ({names.index("time_offset")} if translates else set())
    assert derived == expected, ([names[j] for j in derived], translates)
    assert translates == (key == "three-tube")
    bad = {names[j]: e for j, e in errors.items() if not e < TOLERANCE}
    assert not bad, bad


def test_dropping_a_term_of_the_chain_fails_the_check(tmp_path, monkeypatch):
    """With the tip derivatives of one input left out (the base rotations, the precurvatures, the
    bending or the torsional stiffnesses), some column misses the central differences by far
    more than the tolerance of the check above: the check can see each term."""
    robot, data, names, x0, obj, bounds = _case(tmp_path, "three-tube")
    n = robot.n_tubes
    true_batch = objective.standard_tip_derivatives_batch

    def without(block):
        def batch(*args, **kwargs):
            d = true_batch(*args, **kwargs)
            P = d.d_position.shape[2]
            cols = {"alpha": slice(0, n), "precurvature": slice(n, P - 2 * n), "k_xy": slice(P - 2 * n, P - n),
                    "k_z": slice(P - n, P)}[block]
            pos, tan = d.d_position.copy(), d.d_tangent.copy()
            pos[:, :, cols] = 0.0
            tan[:, :, cols] = 0.0
            return replace(d, d_position=pos, d_tangent=tan)
        return batch

    for block in ("alpha", "precurvature", "k_xy", "k_z"):
        monkeypatch.setattr(objective, "standard_tip_derivatives_batch", without(block))
        obj._cache.clear()
        errors, _ = _column_errors(obj, bounds, x0, names)
        assert max(errors.values()) > 1e3 * TOLERANCE, block


def test_taylor_remainder_falls_as_the_square_of_the_step(tmp_path):
    """|c(x + h e) - c(x) - h J e| falls about a hundredfold per tenfold smaller h (slope 2 in
    log-log) along a direction that moves every mechanical parameter: the Jacobian is the
    derivative, not just close to it."""
    robot, data, names, x0, obj, bounds = _case(tmp_path, "pair")
    jac = objective.ComponentJacobians(obj, *bounds)
    c0, _, ok, jc = jac.exact(x0)
    rng = np.random.default_rng(4)
    e = rng.normal(size=x0.size) * bounds[2] * jac.mech
    remainders = []
    for h in (0.1, 0.01):
        c = jac.components(x0 + h * e)[0]
        remainders.append(np.abs((c - c0 - h * jc @ e)[ok]).max())
    slope = np.log10(remainders[0] / remainders[1])
    assert 1.8 < slope < 2.2, remainders


def test_exact_columns_reach_the_minimum_of_differences_with_fewer_solves(tmp_path, monkeypatch):
    """A standard-model fit with exact columns ends at the minimum of the same fit on forward
    differences and rank-one updates (BIC within 0.05) and solves the model fewer times; its
    message counts the columns of each kind."""
    robot, data, names, x0, obj, bounds = _case(tmp_path, "pair", samples=100)
    fitted = ("precurvature_y_1", "precurvature_y_2", "k_xy_relative_2", "time_offset")
    fit = calibration.calibrate(robot, data, "standard", fitted, max_evaluations=400, run=FitRun(settings=COARSE))
    monkeypatch.setattr(objective.FitObjective, "standard_columns", lambda self, x, columns: {})
    differenced = calibration.calibrate(robot, data, "standard", fitted, max_evaluations=400,
                                        run=FitRun(settings=COARSE))
    assert fit.converged and differenced.converged
    assert "mechanical columns from exact derivatives, 0 by forward differences" in fit.message, fit.message
    assert fit.evaluations < differenced.evaluations, (fit.message, differenced.message)
    assert abs(data.n_samples * np.log(fit.cost / differenced.cost)) < 0.05
