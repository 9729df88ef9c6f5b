"""Robot description: tubes, their sections, the joints that move them and how bases are placed.

Pure data: frozen dataclasses in SI units (m, rad, N m^2). Parsing robot files lives in
:mod:`ctrplan.io.robot_file`; this module only validates physics and joint limits.

Conventions (Section II-A of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906):

- tubes are numbered from the outermost (tube 1, index 0 in code) to the innermost (tube n);
- tube i is clamped at arc length ``s = beta_i`` on the z axis, pointing along +z, with base
  rotation ``alpha_i`` about z (the paper's ``theta_{i,b}`` and ``l_{i,b}``, Eq. (3));
- a tube's sections run from its base to its distal end; each has a constant precurvature
  ``(u_x, u_y)`` [1/m] in the tube's body frame (piecewise-constant precurvature);
- ``k_z = k_xy / (1 + nu)`` (Section II-C).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .choices import JointKind
from .errors import JointLimitError, PhysicalParameterError

__all__ = ["Section", "Tube", "Joint", "TranslationLink", "Robot"]

ROTATION = JointKind.ROTATION
TRANSLATION = JointKind.TRANSLATION

# Tolerances of the configuration tests (check_configuration, configurations_possible) [m]: an
# inner base may lie this far in front of its outer base, a curved section start this far behind
# the most distal base (slack for floating-point rounding).
_BASE_ORDER_TOL = 1e-12
_CURVED_START_TOL = 1e-9


@dataclass(frozen=True)
class Section:
    """One section of a tube with constant precurvature.

    Parameters
    ----------
    length : float
        Section length [m], > 0.
    precurvature : tuple of float, shape (2,)
        Precurvature ``(u_x, u_y)`` in the tube's body frame [1/m]; the paper's ``uhat_i``
        x and y components (its z component, the pre-twist, is zero).
    """

    length: float
    precurvature: tuple[float, float] = (0.0, 0.0)

    @property
    def is_straight(self) -> bool:
        return self.precurvature[0] == 0.0 and self.precurvature[1] == 0.0


@dataclass(frozen=True)
class Tube:
    """A superelastic tube.

    Parameters
    ----------
    name : str
        Human-readable name (e.g. ``"tube 1"``).
    sections : tuple of Section
        From base to distal end.
    k_xy : float
        Bending stiffness E I [N m^2], > 0.
    poisson_ratio : float
        Poisson ratio nu, in (-1, 0.5]; ``k_z = k_xy / (1 + nu)``. Calibrated values can be
        negative (Tables V-VII of Ha et al. 2019).
    outer_diameter, inner_diameter : float or None
        [m]. ``None`` where irrelevant (outer diameter of the outermost tube is only needed for
        collision checking; inner diameter of the innermost tube is never needed).
    """

    name: str
    sections: tuple[Section, ...]
    k_xy: float
    poisson_ratio: float = 0.3
    outer_diameter: float | None = None
    inner_diameter: float | None = None

    def __post_init__(self):
        if len(self.sections) == 0:
            raise PhysicalParameterError(f"{self.name}: a tube needs at least one section")
        for j, sec in enumerate(self.sections):
            if not np.isfinite(sec.length) or sec.length <= 0.0:
                raise PhysicalParameterError(
                    f"{self.name}: section {j + 1} length must be > 0 m, got {sec.length!r}")
            if not all(np.isfinite(sec.precurvature)):
                raise PhysicalParameterError(
                    f"{self.name}: section {j + 1} precurvature is not finite: {sec.precurvature!r}")
        if not np.isfinite(self.k_xy) or self.k_xy <= 0.0:
            raise PhysicalParameterError(f"{self.name}: k_xy must be > 0 N m^2, got {self.k_xy!r}")
        if not (-1.0 < self.poisson_ratio <= 0.5):
            raise PhysicalParameterError(
                f"{self.name}: Poisson ratio must lie in (-1, 0.5], got {self.poisson_ratio!r}")
        od, idia = self.outer_diameter, self.inner_diameter
        for label, v in (("outer diameter", od), ("inner diameter", idia)):
            if v is not None and (not np.isfinite(v) or v <= 0.0):
                raise PhysicalParameterError(f"{self.name}: {label} must be > 0 m, got {v!r}")
        if od is not None and idia is not None and idia >= od:
            raise PhysicalParameterError(
                f"{self.name}: inner diameter {idia * 1e3:.4g} mm must be smaller than outer "
                f"diameter {od * 1e3:.4g} mm")

    @property
    def length(self) -> float:
        """Total tube length [m]."""
        return float(sum(sec.length for sec in self.sections))

    @property
    def k_z(self) -> float:
        """Torsional stiffness G J = k_xy / (1 + nu) [N m^2] (Section II-C)."""
        return self.k_xy / (1.0 + self.poisson_ratio)

    @property
    def r_out(self) -> float | None:
        """Outer radius [m]."""
        return None if self.outer_diameter is None else 0.5 * self.outer_diameter

    @property
    def r_in(self) -> float | None:
        """Inner radius [m]."""
        return None if self.inner_diameter is None else 0.5 * self.inner_diameter

    def section_breaks(self) -> np.ndarray:
        """Arc lengths of section boundaries from the base, shape (n_sections + 1,) [m]."""
        return np.concatenate([[0.0], np.cumsum([sec.length for sec in self.sections])])

    def curved_start(self) -> float:
        """Arc length from the base to the first curved section [m] (tube length if straight)."""
        s = 0.0
        for sec in self.sections:
            if not sec.is_straight:
                return s
            s += sec.length
        return s


@dataclass(frozen=True)
class Joint:
    """An actuated degree of freedom.

    Parameters
    ----------
    kind : JointKind or str
        Base rotation alpha [rad] or base translation beta [m]; a string ``"rotation"`` or
        ``"translation"`` is stored as its :class:`~ctrplan.choices.JointKind` member.
    tube : int
        Zero-based tube index (tube 1 is 0).
    lower, upper : float
        Limits [rad] or [m]. Rotations with limits spanning 2 pi or more are treated as
        unbounded (periodic).
    """

    kind: JointKind
    tube: int
    lower: float
    upper: float

    def __post_init__(self):
        try:
            object.__setattr__(self, "kind", JointKind(self.kind))
        except ValueError:
            raise PhysicalParameterError(f"joint kind must be 'rotation' or 'translation', got {self.kind!r}") from None
        if not self.lower < self.upper:
            raise PhysicalParameterError(
                f"{self.name}: lower limit {self.lower!r} must be below upper limit {self.upper!r}")

    @property
    def name(self) -> str:
        """Column name in the project's CSV schema, e.g. ``alpha_2`` or ``beta_3`` (1-based)."""
        return f"{'alpha' if self.kind == ROTATION else 'beta'}_{self.tube + 1}"

    @property
    def periodic(self) -> bool:
        return self.kind == ROTATION and (self.upper - self.lower) >= 2.0 * np.pi - 1e-12


@dataclass(frozen=True)
class TranslationLink:
    """Tube ``follower``'s base translation equals tube ``leader``'s plus ``offset`` [m].

    For the paper's three-tube robot, tube 2's base sits 17 mm behind tube 1's:
    ``TranslationLink(follower=1, leader=0, offset=-0.017)``.
    """

    follower: int
    leader: int
    offset: float


@dataclass(frozen=True)
class Robot:
    """A concentric tube robot.

    Parameters
    ----------
    name : str
    tubes : tuple of Tube
        Outermost first.
    friction_coefficients : tuple of float, shape (n - 1,)
        Coulomb friction coefficient mu of each adjacent pair (i, i+1) (Section III).
    joints : tuple of Joint
        The actuated joints, in the order of the joint vector ``q``.
    home_alpha : tuple of float, shape (n,)
        Base rotations [rad] of all tubes when not set by a joint.
    home_beta : tuple of float, shape (n,)
        Base translations [m] of all tubes when not set by a joint or a link.
    links : tuple of TranslationLink
        Bases that move together.
    source : str
        Citation of the parameters (paper table, calibration report, ...).
    clearances_override : tuple of float or None, shape (n - 1,)
        Radial clearance c_i [m] of each pair. ``None``: from diameters,
        ``c_i = r_(i,in) - r_(i+1,out)`` (Eq. (15)).
    effects : tuple
        Effects on the motion or the measurement that the robot file records (its ``[effects]``
        table, e.g. drive backlash): ``((effect, ((parameter, value), ...)), ...)`` in SI units,
        validated by :func:`ctrplan.effects.effects_from_file`; read them with
        :func:`ctrplan.effects.robot_effects`.
    """

    name: str
    tubes: tuple[Tube, ...]
    friction_coefficients: tuple[float, ...] = ()
    joints: tuple[Joint, ...] = ()
    home_alpha: tuple[float, ...] = ()
    home_beta: tuple[float, ...] = ()
    links: tuple[TranslationLink, ...] = ()
    source: str = ""
    clearances_override: tuple[float, ...] | None = None
    effects: tuple = ()
    metadata: dict = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self):
        n = len(self.tubes)
        if n < 1:
            raise PhysicalParameterError(f"robot {self.name!r}: needs at least one tube")
        if not self.friction_coefficients:
            object.__setattr__(self, "friction_coefficients", (0.0,) * (n - 1))
        if not self.home_alpha:
            object.__setattr__(self, "home_alpha", (0.0,) * n)
        if not self.home_beta:
            object.__setattr__(self, "home_beta", (0.0,) * n)
        for label, seq, m in (("friction_coefficients", self.friction_coefficients, n - 1),
                              ("home_alpha", self.home_alpha, n), ("home_beta", self.home_beta, n)):
            if len(seq) != m:
                raise PhysicalParameterError(f"robot {self.name!r}: {label} needs {m} values, got {len(seq)}")
        for i, mu in enumerate(self.friction_coefficients):
            if not np.isfinite(mu) or mu < 0.0:
                raise PhysicalParameterError(
                    f"robot {self.name!r}: friction coefficient of tubes {i + 1}-{i + 2} must be >= 0, got {mu!r}")
        for j in self.joints:
            if not 0 <= j.tube < n:
                raise PhysicalParameterError(f"robot {self.name!r}: joint {j.name} refers to a missing tube")
        names = [j.name for j in self.joints]
        if len(set(names)) != len(names):
            raise PhysicalParameterError(f"robot {self.name!r}: duplicate joints {names}")
        for link in self.links:
            if not (0 <= link.follower < n and 0 <= link.leader < n) or link.follower == link.leader:
                raise PhysicalParameterError(f"robot {self.name!r}: bad translation link {link}")
            if any(j.kind == TRANSLATION and j.tube == link.follower for j in self.joints):
                raise PhysicalParameterError(
                    f"robot {self.name!r}: tube {link.follower + 1} is both linked and translated by a joint")
        if self.clearances_override is not None and len(self.clearances_override) != n - 1:
            raise PhysicalParameterError(f"robot {self.name!r}: clearances needs {n - 1} values")
        # Clearance of every pair must be positive (Eq. (15)); computed eagerly so that an
        # impossible tube set fails at load time, naming both tubes.
        self.clearances  # noqa: B018 (validation side effect)

    # ------------------------------------------------------------------ geometry
    @property
    def n_tubes(self) -> int:
        return len(self.tubes)

    @property
    def clearances(self) -> np.ndarray:
        """Radial clearance c_i of each adjacent pair, shape (n - 1,) [m] (Eq. (15)).

        Raises
        ------
        PhysicalParameterError
            If a clearance is not positive (inner tube wider than the outer tube's bore) or
            cannot be computed because a diameter is missing.
        """
        n = self.n_tubes
        if self.clearances_override is not None:
            c = np.asarray(self.clearances_override, dtype=float)
        else:
            c = np.empty(n - 1)
            for i in range(n - 1):
                outer, inner = self.tubes[i], self.tubes[i + 1]
                if outer.inner_diameter is None or inner.outer_diameter is None:
                    raise PhysicalParameterError(
                        f"robot {self.name!r}: clearance between {outer.name} and {inner.name} needs "
                        f"{outer.name}'s inner diameter and {inner.name}'s outer diameter (or an explicit clearance)")
                c[i] = 0.5 * (outer.inner_diameter - inner.outer_diameter)
        for i, ci in enumerate(c):
            if not np.isfinite(ci) or ci <= 0.0:
                outer, inner = self.tubes[i], self.tubes[i + 1]
                raise PhysicalParameterError(
                    f"robot {self.name!r}: clearance between {outer.name} and {inner.name} is "
                    f"{ci * 1e3:.4g} mm; {inner.name} (outer diameter "
                    f"{_mm(inner.outer_diameter)}) must fit in the bore of {outer.name} "
                    f"(inner diameter {_mm(outer.inner_diameter)})")
        return c

    def contact_radii(self) -> tuple[np.ndarray, np.ndarray]:
        """Radii at which friction acts for each pair: (r_(i,in), r_(i+1,out)), shapes (n-1,) [m].

        Falls back to the mean radius from the other tube plus/minus the clearance when only one
        diameter is given. Used by the friction torques of Eq. (41).
        """
        c = self.clearances
        r_in = np.empty(self.n_tubes - 1)
        r_out = np.empty(self.n_tubes - 1)
        for i in range(self.n_tubes - 1):
            ro = self.tubes[i + 1].r_out
            ri = self.tubes[i].r_in
            if ro is None and ri is None:
                raise PhysicalParameterError(
                    f"robot {self.name!r}: friction between {self.tubes[i].name} and "
                    f"{self.tubes[i + 1].name} needs a diameter")
            r_out[i] = ro if ro is not None else ri - c[i]
            r_in[i] = ri if ri is not None else ro + c[i]
        return r_in, r_out

    def outer_radius(self, i: int) -> float:
        """Outer radius of tube i [m] for collision checking (falls back to the tube's own inner
        radius plus 0.2 mm of wall, or 1 mm if no diameter is known)."""
        t = self.tubes[i]
        if t.r_out is not None:
            return t.r_out
        if t.r_in is not None:
            return t.r_in + 2e-4
        return 1e-3

    # ------------------------------------------------------------------ joints
    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def joint_lower(self) -> np.ndarray:
        return np.array([j.lower for j in self.joints], dtype=float)

    @property
    def joint_upper(self) -> np.ndarray:
        return np.array([j.upper for j in self.joints], dtype=float)

    def configuration(self, q, *, check_limits: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Full base rotations and translations from the joint vector.

        Parameters
        ----------
        q : array-like, shape (n_joints,)
            Joint values in the order of ``self.joints`` [rad or m].
        check_limits : bool, keyword-only
            Raise for values outside the joint limits (False: place any finite values, e.g. to
            read off the affine joint-to-configuration map).

        Returns
        -------
        alpha : ndarray, shape (n,)
            Base rotations [rad].
        beta : ndarray, shape (n,)
            Base translations [m].

        Raises
        ------
        JointLimitError
            If ``q`` has the wrong length or a value outside its limits (rotations whose limits
            span 2 pi are periodic and never out of limits).
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.size != len(self.joints):
            raise JointLimitError(f"robot {self.name!r}: expected {len(self.joints)} joint values "
                                  f"({', '.join(self.joint_names)}), got {q.size}")
        alpha = np.array(self.home_alpha, dtype=float)
        beta = np.array(self.home_beta, dtype=float)
        for j, v in zip(self.joints, q):
            if not np.isfinite(v):
                raise JointLimitError(f"joint {j.name} = {v!r} is not finite")
            if check_limits and not j.periodic and not (j.lower - 1e-12 <= v <= j.upper + 1e-12):
                unit = "rad" if j.kind == ROTATION else "m"
                raise JointLimitError(
                    f"joint {j.name} = {v:.6g} {unit} is outside its limits [{j.lower:.6g}, {j.upper:.6g}] {unit}")
            if j.kind == ROTATION:
                alpha[j.tube] = v
            else:
                beta[j.tube] = v
        for link in self.links:
            beta[link.follower] = beta[link.leader] + link.offset
        return alpha, beta

    def joint_vector(self, alpha, beta) -> np.ndarray:
        """Inverse of :meth:`configuration`: pick the joint values from full alpha, beta."""
        alpha = np.asarray(alpha, dtype=float)
        beta = np.asarray(beta, dtype=float)
        return np.array([alpha[j.tube] if j.kind == ROTATION else beta[j.tube] for j in self.joints])

    def configurations_possible(self, alpha, beta) -> np.ndarray:
        """Which of many configurations pass :meth:`check_configuration`, without raising.

        The same tests with the same tolerances, vectorized over configurations (the scalar
        check stays a loop: numpy on one row costs twice as much, and it runs on every solve).

        Parameters
        ----------
        alpha, beta : array-like, shape (K, n)
            Base rotations [rad] and translations [m].

        Returns
        -------
        ndarray of bool, shape (K,)
            True where the configuration is finite, each inner tube's base lies behind (or at)
            its outer tube's base, and no tube is curved proximal to the most distal base (the
            same tests and tolerances as :meth:`check_configuration`).

        Raises
        ------
        ValueError
            If ``alpha`` and ``beta`` are not both of shape (K, n).
        """
        alpha = np.asarray(alpha, dtype=float)
        beta = np.asarray(beta, dtype=float)
        n = self.n_tubes
        if alpha.ndim != 2 or alpha.shape[1] != n or beta.shape != alpha.shape:
            raise ValueError(f"robot {self.name!r}: alpha and beta need shape (K, {n}), "
                             f"got {alpha.shape} and {beta.shape}")
        ok = np.all(np.isfinite(alpha), axis=1) & np.all(np.isfinite(beta), axis=1)
        if n > 1:
            ok &= np.all(beta[:, 1:] <= beta[:, :-1] + _BASE_ORDER_TOL, axis=1)
        starts = np.array([t.curved_start() for t in self.tubes])
        with np.errstate(invalid="ignore"):
            ok &= np.all(beta + starts[None, :] >= np.max(beta, axis=1, keepdims=True) - _CURVED_START_TOL, axis=1)
        return ok

    def check_configuration(self, alpha, beta) -> None:
        """Raise if a full configuration is kinematically impossible.

        Checks: each inner tube's base lies behind (or at) its outer tube's base; no tube is
        curved proximal to the most distal base (where it would sit inside the drive and the
        clamped bases of Eq. (3) could not share a straight axis).

        Parameters
        ----------
        alpha, beta : array-like, shape (n,)
            Base rotations [rad] and translations [m].

        Raises
        ------
        JointLimitError
        """
        alpha = np.asarray(alpha, dtype=float)
        beta = np.asarray(beta, dtype=float)
        n = self.n_tubes
        if alpha.shape != (n,) or beta.shape != (n,):
            raise JointLimitError(f"robot {self.name!r}: alpha and beta need shape ({n},), "
                                  f"got {alpha.shape} and {beta.shape}")
        if not (np.all(np.isfinite(alpha)) and np.all(np.isfinite(beta))):
            raise JointLimitError(f"configuration is not finite: alpha={alpha}, beta={beta}")
        for i in range(n - 1):
            if beta[i + 1] > beta[i] + _BASE_ORDER_TOL:
                raise JointLimitError(
                    f"base of {self.tubes[i + 1].name} (beta_{i + 2} = {beta[i + 1] * 1e3:.3f} mm) lies in "
                    f"front of the base of {self.tubes[i].name} (beta_{i + 1} = {beta[i] * 1e3:.3f} mm)")
        s_clamp = float(np.max(beta))
        for i, t in enumerate(self.tubes):
            if beta[i] + t.curved_start() < s_clamp - _CURVED_START_TOL:
                raise JointLimitError(
                    f"{t.name}: curved section starts at s = {(beta[i] + t.curved_start()) * 1e3:.3f} mm, "
                    f"behind the most distal tube base at {s_clamp * 1e3:.3f} mm")

    def tube_ends(self, beta) -> np.ndarray:
        """Distal end arc length of each tube, ``beta_i + L_i``, shape (n,) [m]."""
        return np.asarray(beta, dtype=float) + np.array([t.length for t in self.tubes])

    def replace(self, **changes) -> "Robot":
        """Copy with fields replaced (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


def _mm(v):
    return "unknown" if v is None else f"{v * 1e3:.4g} mm"
