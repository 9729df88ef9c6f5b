"""Numerical constants shared by the mechanics (one place, never inline)."""

# Below this rotation angle [rad] the closed forms of exp, its left Jacobian and their
# derivatives switch to Taylor series (closed forms lose digits to cancellation there;
# the series are truncated after the theta^4 term, error < 1e-12 at this threshold).
SMALL_ANGLE = 0.1

# Two standard-model equilibria whose base torsions differ by more than this twist over a tube's
# length are distinct [rad] (the shooting converges to 1e-9 1/m, so same solutions agree to ~1e-9).
DISTINCT_EQUILIBRIUM_TWIST = 1e-5

# Grid points closer than this are merged when building the arc-length grid [m].
GRID_MERGE_TOL = 1e-9

# The contact models' outer loop gives up after this many consecutive re-linearizations whose
# complementarity solve failed: such a solve does not recover, and each failed step costs up to
# the whole Newton budget (seconds).
MAX_FAILED_INNER_STEPS = 10

# Mixing parameter beta of the Anderson-accelerated outer loop (_contact_fast.Anderson). With
# beta = 1 the loop stopped at 1 um steps up to 11.8 um away from the converged solution on the
# 4x4x4 grid (slow contraction), and some configurations cycled between two contact states;
# beta = 0.5 brings the first to 3.1 um and ends most cycles (docs/mechanics.md Sec. 10).
ANDERSON_MIXING = 0.5

# The outer loop gives up, unconverged, when its centerline change has not reached a new minimum
# for this many iterations (it wanders instead of contracting).
OUTER_STAGNATION_WINDOW = 15

# Continuation of a friction solution in mu (mechanics/continuation.py): first and largest step
# and smallest step, as fractions of the robot's mu, and the growth of the step after a converged
# solve. 1/256 brackets where a branch ends to within 0.0008 at mu = 0.2; on the four folds of
# the 8x8x8 grid that took 14-16 solves from a first step of 1/4.
CONTINUATION_INITIAL_STEP = 0.25
CONTINUATION_MIN_STEP = 1.0 / 256
CONTINUATION_GROWTH = 1.5

# Inexact outer iterations of the contact models (_contact_fast._inner_tolerance): each
# complementarity solve stops at INNER_TOL_FACTOR x (last centerline change / outer_tol) x
# complementarity_tol, at most INNER_TOL_MAX (the first one) and at least complementarity_tol,
# which the converged iteration uses. On the 4x4x4 grid: 85 -> 62 Newton iterations
# per contact solve, 7.29 -> 7.35 outer iterations, tips within 0.9 um (outer_tol is 1 um).
# INNER_TOL_MAX 1e-3 -> 3e-2 (it only loosens the first solve of
# each contact model, whose multipliers the next linearization replaces): 194.3 -> 179.1 Newton
# iterations per bound, 37.0 -> 37.4 outer; tips as far from solves run to 1e-9 as before
# (largest 3.09 um against 3.12 um).
INNER_TOL_FACTOR = 0.1
INNER_TOL_MAX = 3e-2

# The standard model's Newton shooting from no twist is first run on a grid this many times
# coarser (same breakpoints) and the fine grid's Newton starts from its base torsions: the
# RK4 solutions differ by little at that step, so the fine Newton needs about two sweeps.
PREDICTOR_STEP_FACTOR = 4.0

# Shooting tolerance of that coarse predictor [1/m] (it only has to land near the fine solution;
# looser than 1e-4 costs the fine Newton more sweeps than it saves, docs/mechanics.md Sec. 10).
PREDICTOR_TOL = 1e-4

# Version of the mechanics' results. A bound map records it in its key, so a map computed by
# other mechanics is recognised as stale instead of silently used. Bump it with every change
# that moves a tip, a bound or a stability flag by more than the solvers' tolerances (shooting
# 1e-9 1/m, contact outer loop 1e-6 m), and recompute the shipped maps (docs/boundmaps.md).
MECHANICS_VERSION = "2026.11.22.2"

# Relative inflation of the worst-case torsional coupling in the uniqueness screen of the standard
# model (mechanics/_uniqueness.py): the O(h^2) error of the discretized smallest eigenvalue is far
# below this, so the screen never certifies a configuration past the continuous critical value.
UNIQUENESS_SCREEN_MARGIN = 0.1

# Motion history (planned paths and recorded data alike): a relative rotation reverses the friction
# direction only once it has turned back by more than this hysteresis [rad], and a base translation
# larger than this [m] after a pair's last rotation releases its friction (translation-last).
HISTORY_ROTATION_TOL = 1e-3
HISTORY_TRANSLATION_TOL = 1e-4
