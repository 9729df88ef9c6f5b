"""Map coordinates: the joint-space quantities the friction bound depends on.

The mechanics of Ha, Fagogenis & Dupont 2019 (doi:10.1109/TRO.2018.2878906) are invariant under
two motions of the whole tube set:

- a **common base rotation** of every tube by the same angle about the base axis z rotates the
  standard, clearance and friction solutions rigidly about z (the equilibrium equations have no
  preferred direction about z, the friction directions eta depend on relative rotations only);
- a **common base translation** of every tube by the same length moves every solution rigidly
  along z (no feature of the model is fixed in space: the tubes are clamped at their own bases).

The bound, a distance and an angle between tips of such solutions, is therefore a function of
the base rotations and translations of tubes 2..n *relative to tube 1*:

.. math:: u = (\\alpha_2 - \\alpha_1, \\dots, \\alpha_n - \\alpha_1,
               \\beta_2 - \\beta_1, \\dots, \\beta_n - \\beta_1) ,

of which a bound map keeps the components that the robot's joints can change. For the paper's
three-joint robot (tube 1 fixed, tube 2 translating with it) these are ``alpha_2 - alpha_1``,
``alpha_3 - alpha_1`` and ``beta_3 - beta_1``, i.e. the joints themselves; for a robot whose
three tubes each rotate and translate (six joints) they are four, so its map is 4-D, not 6-D.
(Both invariances are checked against the exact model in ``tests/test_boundmap_coordinates.py``.)

A map node ``u`` is evaluated at a representative configuration: tube 1 at its home base
rotation and translation, the others at tube 1's plus ``u`` (:meth:`MapCoordinates.configuration`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .choices import JointKind


__all__ = ["MapCoordinates", "map_coordinates", "ROTATION_COORDINATE", "TRANSLATION_COORDINATE"]

#: Kind of a map coordinate that is a relative base rotation [rad] (``MapCoordinates.kinds``).
ROTATION_COORDINATE = JointKind.ROTATION
#: Kind of a map coordinate that is a relative base translation [m] (``MapCoordinates.kinds``).
TRANSLATION_COORDINATE = JointKind.TRANSLATION

# Coefficients of the affine joint -> configuration map smaller than this are zero (they are
# sums of 0 and +-1 entries, so anything else is rounding).
_ZERO_COEFFICIENT = 1e-12


def _affine_configuration(robot):
    """alpha = Ka q + ka, beta = Kb q + kb: the affine map of :meth:`Robot.configuration`,
    read off the robot by evaluating it column by column (so links and home values are
    handled exactly as the robot handles them; limits are not checked: q0 + e_j may leave
    them). Returns (Ka (n, m), ka (n,), Kb, kb)."""
    m = len(robot.joints)
    n = robot.n_tubes
    # a joint vector inside the limits (mid-range); columns by unit steps of one joint
    q0 = 0.5 * (robot.joint_lower + robot.joint_upper)
    a0, b0 = robot.configuration(q0, check_limits=False)
    Ka = np.zeros((n, m))
    Kb = np.zeros((n, m))
    for j in range(m):
        q = q0.copy()
        q[j] += 1.0
        a, b = robot.configuration(q, check_limits=False)
        Ka[:, j] = a - a0
        Kb[:, j] = b - b0
    Ka[np.abs(Ka) < _ZERO_COEFFICIENT] = 0.0
    Kb[np.abs(Kb) < _ZERO_COEFFICIENT] = 0.0
    return Ka, a0 - Ka @ q0, Kb, b0 - Kb @ q0


@dataclass(frozen=True)
class MapCoordinates:
    """The coordinates of a robot's bound map and their link to its joints.

    Coordinate k is ``u_k = matrix[k] @ q + offset[k]``: a base rotation (``kind`` "rotation",
    [rad]) or translation ("translation", [m]) of one tube relative to tube 1.

    Attributes
    ----------
    names : tuple of str, shape (d,)
        E.g. ``("alpha_2-alpha_1", "alpha_3-alpha_1", "beta_3-beta_1")``.
    kinds : tuple of str, shape (d,)
        ``"rotation"`` or ``"translation"``.
    tubes : tuple of int, shape (d,)
        Zero-based index of the tube whose rotation or translation (relative to tube 1) it is.
    periodic : tuple of bool, shape (d,)
        Rotation coordinates whose range spans 2 pi (the map wraps round).
    lower, upper : tuple of float, shape (d,)
        Range over the joint box [rad or m]; periodic coordinates span [-pi, pi).
    matrix : ndarray, shape (d, n_joints)
        Joint-to-coordinate matrix [-].
    offset : ndarray, shape (d,)
        [rad or m].
    fixed_alpha, fixed_beta : ndarray, shape (n,)
        Base rotations [rad] and translations [m] relative to tube 1 of every tube at the
        representative configurations (the joint-independent part; a map coordinate overrides
        its own entry).
    home_alpha_1, home_beta_1 : float
        Tube 1's base rotation [rad] and translation [m] at the representative configurations.
    """

    names: tuple
    kinds: tuple
    tubes: tuple
    periodic: tuple
    lower: tuple
    upper: tuple
    matrix: np.ndarray
    offset: np.ndarray
    fixed_alpha: np.ndarray
    fixed_beta: np.ndarray
    home_alpha_1: float
    home_beta_1: float

    @property
    def dim(self) -> int:
        """Number of map coordinates d."""
        return len(self.names)

    def from_joints(self, q) -> np.ndarray:
        """Map coordinates of joint vectors.

        Parameters
        ----------
        q : array-like, shape (n_joints,) or (m, n_joints)
            [rad or m], in the robot's joint order.

        Returns
        -------
        ndarray, shape (d,) or (m, d)
            [rad or m]; periodic coordinates are not wrapped.

        Raises
        ------
        ValueError
            Wrong number of joint values.
        """
        q = np.asarray(q, dtype=float)
        if q.shape[-1] != self.matrix.shape[1]:
            raise ValueError(f"joint vectors need {self.matrix.shape[1]} values, got shape {q.shape}")
        return q @ self.matrix.T + self.offset

    def configuration(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Representative base rotations and translations of map coordinates.

        Tube 1 sits at its home rotation and translation; every other tube at tube 1's plus its
        relative coordinate (a map coordinate, or the joint-independent value).

        Parameters
        ----------
        u : array-like, shape (d,) or (m, d)
            Map coordinates [rad or m].

        Returns
        -------
        alpha, beta : ndarray, shape (n,) or (m, n)
            [rad], [m].
        """
        u = np.asarray(u, dtype=float)
        single = u.ndim == 1
        u = np.atleast_2d(u)
        if u.shape[1] != self.dim:
            raise ValueError(f"map coordinates need {self.dim} values ({', '.join(self.names)}), got {u.shape}")
        alpha = np.tile(self.fixed_alpha, (u.shape[0], 1))
        beta = np.tile(self.fixed_beta, (u.shape[0], 1))
        for k, (kind, tube) in enumerate(zip(self.kinds, self.tubes)):
            (alpha if kind == ROTATION_COORDINATE else beta)[:, tube] = u[:, k]
        alpha += self.home_alpha_1
        beta += self.home_beta_1
        return (alpha[0], beta[0]) if single else (alpha, beta)

    def as_dict(self) -> dict:
        """JSON-ready description (part of a map's identity)."""
        return {"names": list(self.names), "kinds": list(self.kinds), "tubes": [int(t) for t in self.tubes],
                "periodic": [bool(p) for p in self.periodic], "lower": [float(x) for x in self.lower],
                "upper": [float(x) for x in self.upper], "matrix": self.matrix.tolist(),
                "offset": self.offset.tolist(), "fixed_alpha": self.fixed_alpha.tolist(),
                "fixed_beta": self.fixed_beta.tolist(), "home_alpha_1": float(self.home_alpha_1),
                "home_beta_1": float(self.home_beta_1)}


def map_coordinates(robot) -> MapCoordinates:
    """The bound-map coordinates of a robot (module docstring).

    Parameters
    ----------
    robot : Robot

    Returns
    -------
    MapCoordinates
        One coordinate per relative base rotation and translation that the joints change, in
        the order rotations of tubes 2..n, then translations of tubes 2..n. A robot whose joints
        change nothing relative to tube 1 has none (d = 0).

    Raises
    ------
    ValueError
        The robot has no joints.
    """
    if not robot.joints:
        raise ValueError(f"robot {robot.name!r} has no joints: a bound map needs at least one")
    Ka, ka, Kb, kb = _affine_configuration(robot)
    lo, hi = robot.joint_lower, robot.joint_upper
    names, kinds, tubes, periodic, lower, upper, rows, offs = [], [], [], [], [], [], [], []
    fixed_alpha = ka - ka[0]
    fixed_beta = kb - kb[0]
    for kind, K, k0 in ((ROTATION_COORDINATE, Ka, ka), (TRANSLATION_COORDINATE, Kb, kb)):
        for i in range(1, robot.n_tubes):
            row = K[i] - K[0]
            if not np.any(row != 0.0):
                continue
            off = k0[i] - k0[0]
            # range of an affine function over the joint box
            vmin = off + float(np.sum(np.where(row > 0, row * lo, row * hi)))
            vmax = off + float(np.sum(np.where(row > 0, row * hi, row * lo)))
            per = kind == ROTATION_COORDINATE and vmax - vmin >= 2.0 * np.pi - 1e-12
            if per:   # nodes lower + 2 pi k / n as for a periodic joint with limits [-pi, pi]
                vmin, vmax = -np.pi, np.pi
            sym = "alpha" if kind == ROTATION_COORDINATE else "beta"
            names.append(f"{sym}_{i + 1}-{sym}_1")
            kinds.append(kind)
            tubes.append(i)
            periodic.append(bool(per))
            lower.append(vmin)
            upper.append(vmax)
            rows.append(row)
            offs.append(off)
    matrix = np.array(rows, dtype=float).reshape(len(rows), len(robot.joints))
    return MapCoordinates(names=tuple(names), kinds=tuple(kinds), tubes=tuple(tubes), periodic=tuple(periodic),
                          lower=tuple(lower), upper=tuple(upper), matrix=matrix, offset=np.array(offs, dtype=float),
                          fixed_alpha=fixed_alpha, fixed_beta=fixed_beta, home_alpha_1=float(robot.home_alpha[0]),
                          home_beta_1=float(robot.home_beta[0]))
