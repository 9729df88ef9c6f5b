"""A friction solution followed in mu (continuation.py): Section III of Ha et al. 2019 at t mu.

The fold configuration is one of the four of the 8x8x8 grid whose bound does not
converge (Table II robot, tube 3 at beta_3 = -120.4 mm + 86.4 mm / 7, alpha_2 = 45 deg,
alpha_3 = 180 deg; docs/mechanics.md Sec. 5).
"""

import dataclasses

import numpy as np
import pytest

from ctrplan.errors import ConvergenceError
from ctrplan.mechanics import (FrictionBranch, ModelSettings, continue_friction, solve_clearance,
                               solve_friction, solve_standard)

from _robots import table2_robot

BETA = np.array([0.0, -0.017, -0.1204 + 0.0864 / 7])
FOLD_ALPHA = np.radians([0.0, 45.0, 180.0])
FOLD_ETA = (-1, -1)


@pytest.fixture(scope="module")
def robot():
    return table2_robot()


@pytest.fixture(scope="module")
def fold(robot):
    return continue_friction(robot, FOLD_ALPHA, BETA, FOLD_ETA)


def test_a_branch_that_reaches_mu_ends_at_the_direct_solution(robot):
    """Same configuration, the other direction: the branch reaches mu = 0.2 and ends at the
    friction solution solved directly from the clearance solution (a last step to the wrong
    fraction of mu would end elsewhere). It starts at the clearance solution, and along it the
    tip moves at a nearly steady rate (no fold near)."""
    branch = continue_friction(robot, FOLD_ALPHA, BETA, (1, 1))
    assert isinstance(branch, FrictionBranch)
    assert branch.reached and branch.critical_mu is None and np.isnan(branch.failed_fraction)
    assert branch.fraction[0] == 0.0 and branch.fraction[-1] == 1.0
    assert np.all(np.diff(branch.fraction) > 0)
    cl = solve_clearance(robot, FOLD_ALPHA, BETA)
    np.testing.assert_allclose(branch.tip_position[0], cl.tip_position, atol=1e-12)
    direct = solve_friction(robot, FOLD_ALPHA, BETA, (1, 1))
    assert direct.diagnostics.converged
    assert np.linalg.norm(branch.solution.tip_position - direct.tip_position) < 5e-6
    np.testing.assert_allclose(branch.solution.mu, [0.2, 0.2])
    assert branch.tip_sensitivity.max() < 2.0 * branch.tip_sensitivity.min()
    assert "followed to mu = 0.2" in branch.message
    assert branch.solves == 4           # steps of 1/4, none failed


def test_a_branch_ends_at_a_fold_below_the_robots_mu(fold):
    """Under maximal friction in directions (-1, -1) the branch ends near mu = 0.197 < 0.2: the
    end is bracketed to min_step, and the tip's rate of motion per unit mu grows tenfold and more
    as the steps shrink towards it, as at a saddle-node fold (1 / sqrt(mu_c - mu)); a solver that
    merely failed part-way would leave it steady."""
    assert not fold.reached
    lo, hi = fold.critical_mu
    assert lo.shape == (2,) and np.all(lo < hi) and np.all(hi < 0.2)
    assert 0.19 < lo[0] < 0.2
    assert hi[0] - lo[0] <= 0.2 / 256 + 1e-12
    s = fold.tip_sensitivity
    assert s[-1] > 10.0 * s[0]
    assert np.all(np.diff(s[-4:]) > 0)
    assert fold.solution.diagnostics.converged
    np.testing.assert_allclose(fold.solution.mu, 0.2 * fold.fraction[-1])
    assert "ends between mu = 0.19" in fold.message
    assert fold.solves <= 24            # work budget: 16 solves measured


def test_mirror_image_configurations_fold_at_the_same_mu(robot, fold):
    """All precurvatures lie in one plane at alpha = 0, so reflecting that plane maps alpha to
    -alpha, eta to -eta and the tip's y to -y: the mirrored branch folds at the same mu, along
    the mirrored tips. The code has no such symmetry built in; a sign error in one direction's
    friction forces or torques (Eqs. (38), (41)) breaks it."""
    mirror = continue_friction(robot, -FOLD_ALPHA, BETA, tuple(-e for e in FOLD_ETA))
    np.testing.assert_allclose(mirror.fraction, fold.fraction)
    assert mirror.failed_fraction == fold.failed_fraction
    flip = np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(mirror.tip_position, fold.tip_position * flip, atol=5e-6)


def test_the_fold_is_the_models_not_the_steps(robot, fold):
    """Halving the arc-length step moves the fold by less than 1 % of mu (measured: 0.197 at 3 mm,
    0.196 at 1.5 mm): it is a property of the friction model, not of its discretization."""
    fine = continue_friction(robot, FOLD_ALPHA, BETA, FOLD_ETA, ModelSettings(ds=1.5e-3))
    assert not fine.reached
    mid = lambda b: 0.5 * (b.critical_mu[0][0] + b.critical_mu[1][0])
    assert abs(mid(fine) - mid(fold)) < 0.002


def test_without_friction_the_branch_stays_at_the_clearance_solution(robot):
    """mu = 0: every point of the branch is the clearance solution (Sec. 6: the bounds coincide),
    to the outer loop's tolerance (1 um of centerline change; each point is a solve of its own).
    Friction at the robot's mu instead of the given one would move the tip by millimetres."""
    branch = continue_friction(robot, FOLD_ALPHA, BETA, FOLD_ETA, mu=[0.0, 0.0])
    assert branch.reached
    np.testing.assert_allclose(branch.tip_position, branch.tip_position[:1].repeat(len(branch.fraction), 0),
                               atol=2e-6)


def test_bad_input_is_refused(robot):
    with pytest.raises(ValueError, match="eta"):
        continue_friction(robot, FOLD_ALPHA, BETA, (1, 0))
    with pytest.raises(ValueError, match="eta"):
        continue_friction(robot, FOLD_ALPHA, BETA, (1, 1, 1))
    with pytest.raises(ValueError, match="mu"):
        continue_friction(robot, FOLD_ALPHA, BETA, (1, 1), mu=[0.2, -0.1])
    with pytest.raises(ValueError, match="initial_step"):
        continue_friction(robot, FOLD_ALPHA, BETA, (1, 1), initial_step=0.0)
    with pytest.raises(ValueError, match="min_step"):
        continue_friction(robot, FOLD_ALPHA, BETA, (1, 1), initial_step=0.1, min_step=0.2)


def test_an_unconverged_start_raises(robot):
    st = solve_standard(robot, FOLD_ALPHA, BETA)
    cl = solve_clearance(robot, FOLD_ALPHA, BETA, standard=st)
    bad = dataclasses.replace(cl, diagnostics=dataclasses.replace(cl.diagnostics, converged=False))
    with pytest.raises(ConvergenceError, match="clearance solution"):
        continue_friction(robot, FOLD_ALPHA, BETA, (1, 1), standard=st, clearance=bad)
