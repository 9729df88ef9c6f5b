"""Every contact solution of the grids of Section IV-D of Ha et al. 2019 (Table II robot, mu = 0.2):
where the friction solves stop and whether they end where friction builds up from the clearance
solution.

- A friction solution (Section III, Eqs. (37)-(43)) is the end, at the robot's mu, of the branch
  that starts at the clearance solution (mu = 0) and follows mu up (``continue_friction``,
  docs/mechanics.md Sec. 5). A direct solve that converges elsewhere found another equilibrium; a
  direct solve that does not converge although the branch reaches mu is a solver failure; one
  whose branch stops below mu is a fold (no equilibrium near it under maximal friction).
- The contact solver stops at ``outer_tol = complementarity_tol = 1e-6``; its tips must stay within
  a few micrometres of solves run to 1e-9 (docs/mechanics.md, accuracy table).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, continue_friction, evaluate_bound
from ctrplan_reference.paper_grids import grid_4x4x4, grid_8x8x8


#: How far [m] a directly converged friction tip may lie from the end of its branch.
ON_BRANCH_TOL = 10e-6
#: How far [m] a converged tip at the default tolerances may lie from a solve to 1e-9.
STOPPING_TOL = 5e-6
ROBOT = Path(__file__).resolve().parents[1] / "model" / "ha2019-table2-nominal.toml"
TIGHT = ModelSettings(outer_tol=1e-9, complementarity_tol=1e-9, max_outer_iterations=200)


@pytest.fixture(scope="module")
def robot():
    return load_robot(ROBOT)


def _grid(robot, which):
    if which == 4:
        return [robot.configuration(q) for q in grid_4x4x4(robot)[1]]
    return grid_8x8x8()


def _classify(robot, configs):
    """Each friction solve of each configuration whose standard solution is stable and whose
    clearance solve converged: ``(index, eta, kind, distance of the direct tip from the branch's end
    [m])``, kind one of "on branch", "off branch", "fold", "solver failure"; and the number of
    configurations skipped."""
    settings = ModelSettings()
    out, skipped = [], 0
    for i, (alpha, beta) in enumerate(configs):
        b = evaluate_bound(robot, alpha, beta, settings)
        if b.standard.diagnostics.unstable or not b.clearance.diagnostics.converged:
            skipped += 1
            continue
        for eta, f in b.friction.items():
            br = continue_friction(robot, alpha, beta, eta, settings, standard=b.standard, clearance=b.clearance)
            d = float(np.linalg.norm(br.solution.tip_position - f.tip_position)) if br.reached else np.inf
            if f.diagnostics.converged:
                kind = "on branch" if d <= ON_BRANCH_TOL else "off branch"
            else:
                kind = "solver failure" if br.reached else "fold"
            out.append((i, tuple(eta), kind, d))
    return out, skipped


def test_every_friction_solution_of_the_4x4x4_grid_is_the_end_of_its_branch(robot):
    """On the paper's 4x4x4 grid every friction solve converges, to the equilibrium that friction
    builds up from the clearance solution: catches a direct solve that lands on another equilibrium
    (a wrong sign of eta in the friction moments, a warm start from the wrong solution) and one that
    stops short where an equilibrium exists (a solver failure)."""
    solves, skipped = _classify(robot, _grid(robot, 4))
    assert skipped <= 2, f"{skipped} of 64 configurations unstable or with an unconverged clearance solve"
    kinds = {k: [s for s in solves if s[2] == k] for k in ("on branch", "off branch", "fold", "solver failure")}
    assert len(solves) == 4 * (64 - skipped)
    assert not kinds["solver failure"], f"direct solves failed where the branch reaches mu: {kinds['solver failure']}"
    assert not kinds["off branch"], f"converged away from their branch's end: {kinds['off branch']}"
    assert not kinds["fold"], f"folds on the 4x4x4 grid: {kinds['fold']}"


def test_converged_tips_lie_within_micrometres_of_a_tight_solve(robot):
    """The contact solver's stopping rule (outer and complementarity tolerances 1e-6) leaves every
    converged tip of the 4x4x4 grid (clearance and all four friction solutions) within 5 um of the
    same solve run to 1e-9: catches a stopping test on the wrong quantity, a tolerance applied in
    the wrong unit, or an outer loop that stops on stagnation before it converged."""
    worst, compared = 0.0, 0
    for alpha, beta in _grid(robot, 4):
        loose, tight = evaluate_bound(robot, alpha, beta), evaluate_bound(robot, alpha, beta, TIGHT)
        pairs = [(loose.clearance, tight.clearance)] + [(loose.friction[e], tight.friction[e]) for e in loose.friction]
        for a, b in pairs:
            if a.diagnostics.converged and b.diagnostics.converged:
                worst = max(worst, float(np.linalg.norm(a.tip_position - b.tip_position)))
                compared += 1
    assert compared >= 0.95 * 64 * 5
    assert worst <= STOPPING_TOL, f"a converged tip lies {worst * 1e6:.2f} um from the tight solve"


@pytest.mark.slow
def test_the_8x8x8_grid_has_four_folds_and_no_solver_failure(robot):
    """On the 8x8x8 grid the configurations whose friction solves do not converge although their
    standard solution is stable are the four of docs/mechanics.md Sec. 5 (97, 105, 473, 481, mirror
    pairs at beta_3 = -108.06 mm), and each of their unconverged solves is a fold below mu. Every
    friction solve of the other 508 configurations is the end of its branch; at the four, where the
    tip moves hundreds of mm per unit mu near the fold, a converged solve may end off its branch
    (at most 15 um; or beyond where the branch stops)."""
    solves, _ = _classify(robot, _grid(robot, 8))
    kinds = {k: [s for s in solves if s[2] == k] for k in ("on branch", "off branch", "fold", "solver failure")}
    folds = {97, 105, 473, 481}
    assert not kinds["solver failure"], kinds["solver failure"]
    assert {s[0] for s in kinds["fold"]} == folds
    assert {s[0] for s in kinds["off branch"]} <= folds, kinds["off branch"]
    assert all(s[3] <= 15e-6 or np.isinf(s[3]) for s in kinds["off branch"]), kinds["off branch"]
