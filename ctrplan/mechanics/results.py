"""Settings and result types of the mechanics (pure data)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..constants import GRID_MERGE_TOL

# Slack of the body's tests [m]: the grid rounds breakpoints (tube bases and ends) to multiples
# of GRID_MERGE_TOL, so the node at the most distal base can sit up to half of it behind the
# base; a smaller slack (1e-12 before) dropped that node for some translations and the exposed
# body jumped by one grid step (0.77 mm on the six-joint robot).
BODY_TOL = 2.0 * GRID_MERGE_TOL

__all__ = ["ModelSettings", "Diagnostics", "StandardSolution", "ContactSolution", "BoundResult"]


@dataclass(frozen=True)
class ModelSettings:
    """Numerical settings shared by the standard, clearance and friction models.

    Parameters
    ----------
    ds : float
        Largest arc-length step of the discretization [m]. Section boundaries, tube bases and
        tube ends are always grid points, so steps can be shorter. Default 3 mm: the paper's
        three-tube problem has 630 curvature unknowns over 587 mm of tube (Section II-D), a
        step of about 2.8 mm.
    shooting_tol : float
        Tolerance on the tip torsion residual of the standard model's shooting [1/m].
    max_shooting_iterations : int
        Newton iterations of the shooting method per start.
    multistart : int
        Number of extra initial guesses used to detect more than one equilibrium (elastic
        instability); 0 disables the check.
    refine_ratio : float
        Step at the tube bases, tube ends and section boundaries that border an overlap of two or
        more tubes, as a fraction of ``ds``, in (0, 1]. Default 0.25. Point contacts sit within
        millimetres of these breakpoints; with the uniform grid of the paper (1.0) the contact
        models' tips are 0.1-0.8 mm from a converged run at ds = 3 mm (docs/mechanics.md, Sec. 1).
    refine_length : float
        Distance over which the step grows linearly from ``refine_ratio * ds`` back to ``ds``
        [m], >= 0. Default 45 mm.
    outer_tol : float
        Outer re-linearization loop stops when the largest centerline change is below this [m]
        (the paper's gamma on |Delta u|, Section II-E, expressed as a displacement). The loop
        contracts, so the remaining error is of this order.
    max_outer_iterations : int
        Outer re-linearization iterations (the paper reports tens).
    anderson_depth : int
        Iterates mixed by Anderson acceleration of the outer loop (0: plain iteration, as in
        the paper with alpha = 1).
    complementarity_tol : float
        Tolerance of the contact complementarity solve, relative to the clearance [-].
    max_newton_iterations : int
        Semismooth-Newton iterations of one contact solve on one working set (the solve grows
        its working set of contacts in rounds; each round has this budget, and again if its
        natural-residual phase gives up and it starts over with Fischer-Burmeister).

    Raises
    ------
    ValueError
        If ``refine_ratio`` is not in (0, 1] or ``refine_length`` is negative.
    """

    ds: float = 3e-3
    refine_ratio: float = 0.25
    refine_length: float = 0.045
    shooting_tol: float = 1e-9
    max_shooting_iterations: int = 50
    multistart: int = 4
    outer_tol: float = 1e-6
    max_outer_iterations: int = 60
    anderson_depth: int = 3
    complementarity_tol: float = 1e-6
    max_newton_iterations: int = 100

    def __post_init__(self):
        # the grid settings reach compiled code (the batch) without build_grid's checks
        if not 0.0 < self.refine_ratio <= 1.0:
            raise ValueError(f"ModelSettings.refine_ratio must be in (0, 1], got {self.refine_ratio!r}")
        if not self.refine_length >= 0.0:
            raise ValueError(f"ModelSettings.refine_length must be >= 0 m, got {self.refine_length!r}")

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)

    def replace(self, **changes) -> "ModelSettings":
        return dataclasses.replace(self, **changes)


@dataclass
class Diagnostics:
    """What a solver did.

    Attributes
    ----------
    converged : bool
    iterations : int
        Outer iterations (shooting Newton steps, or re-linearizations).
    inner_iterations : int
        Total inner iterations (contact Newton steps); 0 for the standard model.
    unstable : bool
        True when more than one equilibrium was found or the equilibrium is elastically
        unstable; such a result must not be trusted as unique.
    n_equilibria : int
        Distinct stable-looking equilibria found by the multistart check (1 when unique; 0 when
        the check did not run: ``check_stability=False``, ``multistart=0`` or no convergence).
    message : str
    residual : float
        Final residual of the solver (units depend on the solver; see ``message``).
    """

    converged: bool
    iterations: int = 0
    inner_iterations: int = 0
    unstable: bool = False
    n_equilibria: int = 0
    message: str = ""
    residual: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.converged and not self.unstable


@dataclass
class StandardSolution:
    """Zero-clearance, torsionally compliant equilibrium (Section II-A; refs [10], [11]).

    Attributes
    ----------
    s : ndarray, shape (K,)
        Arc-length grid [m], from the most proximal base to the distal end.
    centerline : ndarray, shape (K, 3)
        Shared centerline p(s) [m].
    frames : ndarray, shape (K, 3, 3)
        Twist-free (Bishop) frame of the shared centerline; tube i's material frame is
        ``frames @ Rz(psi[:, i])``.
    psi : ndarray, shape (K, n)
        Tube body-frame angles about z relative to the common frame [rad]; NaN where absent.
    torsion : ndarray, shape (K, n)
        Torsional curvature u_(i,z) = d psi_i / ds [1/m]; NaN where the tube is absent.
    bending : ndarray, shape (K, 2)
        Shared bending curvature (u_x, u_y) in the common frame [1/m].
    alpha, beta : ndarray, shape (n,)
        Configuration [rad], [m].
    tip_position : ndarray, shape (3,)
        [m]
    tip_tangent : ndarray, shape (3,)
        Unit tangent at the tip.
    tip_rotation : ndarray, shape (3, 3)
        Material frame of the innermost tube reaching the tip.
    diagnostics : Diagnostics
    base_torsion : ndarray, shape (n,)
        Torsion u_(i,z) at each tube's base [1/m]: pass as ``initial_guess`` to follow a branch.
    psi_mid, torsion_mid : ndarray, shape (K - 1, n)
        Tube angles [rad] and torsions [1/m] at interval midpoints (linearization of Eq. (11)).
    bending_mid : ndarray, shape (K - 1, 2)
        Shared bending curvature at interval midpoints [1/m].
    grid : ArcLengthGrid
    """

    s: np.ndarray
    centerline: np.ndarray
    frames: np.ndarray
    psi: np.ndarray
    torsion: np.ndarray
    bending: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    tip_position: np.ndarray
    tip_tangent: np.ndarray
    tip_rotation: np.ndarray
    diagnostics: Diagnostics
    base_torsion: np.ndarray = field(default=None, repr=False)
    psi_mid: np.ndarray = field(default=None, repr=False)
    torsion_mid: np.ndarray = field(default=None, repr=False)
    bending_mid: np.ndarray = field(default=None, repr=False)
    grid: object = field(default=None, repr=False)

    def tube_curvature(self, i: int) -> np.ndarray:
        """Curvature u_i(s) of tube i in its own body frame, shape (K, 3) [1/m]; NaN where the
        tube is absent: ``u_i = (Rz(-psi_i) u_xy, psi_i')`` (Eq. (2) with the shared centerline).
        """
        c, s = np.cos(self.psi[:, i]), np.sin(self.psi[:, i])
        ux, uy = self.bending[:, 0], self.bending[:, 1]
        return np.column_stack([c * ux + s * uy, -s * ux + c * uy, self.torsion[:, i]])

    def tube_frames(self, i: int) -> np.ndarray:
        """Material frames R_i(s) of tube i, shape (K, 3, 3); NaN where the tube is absent."""
        c, s = np.cos(self.psi[:, i]), np.sin(self.psi[:, i])
        Rz = np.zeros((c.size, 3, 3))
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
        return self.frames @ Rz

    def body(self, robot) -> tuple[np.ndarray, np.ndarray]:
        """Robot body for collision checking: centerline points distal to the most distal
        tube base (the part outside the drive) and the outer radius of the outermost tube
        present at each point.

        Returns
        -------
        points : ndarray, shape (K', 3) [m]
        radii : ndarray, shape (K',) [m]
        """
        s_front = float(np.max(self.beta))
        ends = robot.tube_ends(self.beta)
        tol = BODY_TOL
        keep = self.s >= s_front - tol
        pts = self.centerline[keep]
        radii = np.empty(pts.shape[0])
        for k, sk in enumerate(self.s[keep]):
            present = [i for i in range(robot.n_tubes) if self.beta[i] - tol <= sk <= ends[i] + tol]
            radii[k] = robot.outer_radius(min(present)) if present else 0.0
        return pts, radii


@dataclass
class ContactSolution:
    """Clearance-model (Section II) or friction-model (Section III) equilibrium.

    Per-tube arrays are lists with one entry per tube (outermost first).

    Attributes
    ----------
    s : list of ndarray, shape (N_i,)
        Node arc lengths of tube i [m] (base first).
    centerlines : list of ndarray, shape (N_i, 3)
        Centerline p_i at the nodes [m].
    frames : list of ndarray, shape (N_i, 3, 3)
        Body frames R_i at the nodes.
    curvatures : list of ndarray, shape (N_i - 1, 3)
        Curvature u_i of each segment [1/m] (torsion in the z component).
    contact_s : ndarray, shape (M,)
        Arc length of each contact constraint [m].
    contact_pair : ndarray of int, shape (M,)
        Zero-based index i of the pair (i, i+1) of each constraint.
    contact_force : ndarray, shape (M,)
        Normal contact force magnitude f_k = c_i lambda_k [N] (Eq. (33)).
    contact_direction : ndarray, shape (M, 3)
        Unit direction of the normal force on the outer tube (world frame).
    contact_gap : ndarray, shape (M,)
        Radial offset |P S p| between the centerlines at the constraint [m] (<= clearance).
    eta : ndarray of int, shape (n - 1,)
        Friction directions (+1 CCW, -1 CW); all zero for the frictionless clearance model.
    mu : ndarray, shape (n - 1,)
        Friction coefficients used.
    tip_position, tip_tangent : ndarray, shape (3,)
        Of the tube reaching furthest [m], [-].
    tip_rotation : ndarray, shape (3, 3)
    diagnostics : Diagnostics
    """

    s: list
    centerlines: list
    frames: list
    curvatures: list
    contact_s: np.ndarray
    contact_pair: np.ndarray
    contact_force: np.ndarray
    contact_direction: np.ndarray
    contact_gap: np.ndarray
    eta: np.ndarray
    mu: np.ndarray
    tip_position: np.ndarray
    tip_tangent: np.ndarray
    tip_rotation: np.ndarray
    diagnostics: Diagnostics
    multipliers: np.ndarray = field(default=None, repr=False)


@dataclass
class BoundResult:
    """Friction-induced tip error bound of one configuration.

    Attributes
    ----------
    position : float
        Largest tip-position distance between any friction solution and the standard model [m].
    angle : float
        Largest tip-tangent angle between any friction solution and the standard model [rad].
    translation_last_position : float
        Tip-position distance of the clearance-only (mu = 0) solution from the standard model [m]:
        what remains after a final translation (Section V-B).
    translation_last_angle : float
        Tip-tangent angle of the clearance-only solution from the standard model [rad].
    standard : StandardSolution
    clearance : ContactSolution
    friction : dict
        ``{eta tuple: ContactSolution}`` for all 2^(n-1) friction directions.
    diagnostics : Diagnostics
        Converged only when every solve converged; unstable when the standard model is.
    """

    position: float
    angle: float
    translation_last_position: float
    translation_last_angle: float
    standard: StandardSolution
    clearance: ContactSolution
    friction: dict
    diagnostics: Diagnostics
