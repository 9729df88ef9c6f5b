"""OMPL joint space of a concentric tube robot and numpy conversions.

The joint vector ``q`` (shape ``(n_joints,)``, order of ``robot.joints``, [rad] for rotations and
[m] for translations) is mapped onto an ``ob.CompoundStateSpace``:

- one ``ob.SO2StateSpace`` per *periodic* rotation joint (limits spanning 2 pi; angles wrap to
  [-pi, pi) and interpolate the short way across +-pi);
- one bounded ``ob.RealVectorStateSpace(1)`` per *bounded* rotation joint (limits narrower than
  2 pi, so that sampling and interpolation never leave the limits);
- one bounded ``ob.RealVectorStateSpace(k)`` holding all ``k`` translation joints.

Distances are OMPL's compound distance: the weighted **sum** of the subspace distances,

.. math:: d(q, q') = \\ell_\\alpha \\sum_{rot} |\\mathrm{wrap}(q_j - q'_j)|
          + \\lVert \\beta - \\beta' \\rVert_2 ,

with :math:`\\ell_\\alpha` = ``meters_per_radian``. The default
:data:`DEFAULT_METERS_PER_RADIAN` = 0.02 m/rad: turning a precurved distal section of about
50 mm length and 60-100 mm radius of curvature by 1 rad moves the tip by roughly 15-25 mm
(lateral offset l^2 / (2 R) per unit rotation), i.e. one radian of rotation "costs" about as
much tip motion as 20 mm of translation. This keeps rotation and translation comparable in the
planner's metric for robots like the three-tube robot of Ha, Fagogenis & Dupont 2019
(doi:10.1109/TRO.2018.2878906); pass another value for very different tube sets.
"""

from __future__ import annotations

import numpy as np
from ompl import base as ob

from ..robot import ROTATION, TRANSLATION

__all__ = ["DEFAULT_METERS_PER_RADIAN", "JointStateSpace", "wrap_angle", "unwrap_path"]

# Length [m] that one radian of tube rotation is worth in the planner metric (see module doc).
DEFAULT_METERS_PER_RADIAN = 0.02

TWO_PI = 2.0 * np.pi


def wrap_angle(x):
    """Wrap angles to [-pi, pi).

    Parameters
    ----------
    x : float or ndarray, any shape
        Angles [rad].

    Returns
    -------
    ndarray or float, same shape
        Wrapped angles [rad].
    """
    return (np.asarray(x, dtype=float) + np.pi) % TWO_PI - np.pi


def unwrap_path(waypoints, robot):
    """Make the periodic rotation columns of a path continuous (``numpy.unwrap``).

    OMPL's SO2 spaces store angles in [-pi, pi) and interpolate the short way across +-pi, so a
    planned path can jump from +3.1 to -3.1 rad between consecutive waypoints. Drives and
    time-parameterization need the continuous angle; this removes the 2 pi jumps.

    Parameters
    ----------
    waypoints : array-like, shape (K, n_joints)
        Joint vectors in the order of ``robot.joints`` [rad or m].
    robot : Robot

    Returns
    -------
    ndarray, shape (K, n_joints)
        Copy with periodic rotation columns unwrapped [rad]; other columns unchanged.
    """
    w = np.array(waypoints, dtype=float, copy=True)
    if w.ndim != 2 or w.shape[1] != len(robot.joints):
        raise ValueError(f"waypoints need shape (K, {len(robot.joints)}), got {w.shape}")
    for j, joint in enumerate(robot.joints):
        if joint.periodic and w.shape[0] > 1:
            w[:, j] = np.unwrap(w[:, j])
    return w


class JointStateSpace:
    """OMPL compound state space over a robot's joints, with numpy conversions.

    Parameters
    ----------
    robot : Robot
        Joints in the order of the joint vector.
    meters_per_radian : float, keyword-only
        Subspace weight of every rotation joint: 1 rad counts as this length [m/rad] in the
        metric (translation weight is 1). Default :data:`DEFAULT_METERS_PER_RADIAN`.

    Attributes
    ----------
    space : ob.CompoundStateSpace
    robot : Robot
    weights : ndarray, shape (n_joints,)
        Metric weight of each joint [m/rad or m/m].
    periodic : ndarray of bool, shape (n_joints,)
        True for periodic rotation joints (SO2 subspaces).
    lower, upper : ndarray, shape (n_joints,)
        Joint limits [rad or m].

    Raises
    ------
    ValueError
        If the robot has no joints or ``meters_per_radian`` is not positive.
    """

    def __init__(self, robot, *, meters_per_radian: float = DEFAULT_METERS_PER_RADIAN):
        if not robot.joints:
            raise ValueError(f"robot {robot.name!r} has no joints to plan over")
        if not np.isfinite(meters_per_radian) or meters_per_radian <= 0.0:
            raise ValueError(f"meters_per_radian must be > 0, got {meters_per_radian!r}")
        self.robot = robot
        self.meters_per_radian = float(meters_per_radian)
        n = len(robot.joints)
        self.n_joints = n
        self.lower = robot.joint_lower
        self.upper = robot.joint_upper
        self.periodic = np.array([j.periodic for j in robot.joints], dtype=bool)
        self.is_rotation = np.array([j.kind == ROTATION for j in robot.joints], dtype=bool)
        self.weights = np.where(self.is_rotation, self.meters_per_radian, 1.0)
        self.space = ob.CompoundStateSpace()
        # layout: list of (kind, joint indices); kind "so2" | "rv"
        self._layout: list[tuple[str, list[int]]] = []
        self._subspaces = []  # keep Python references alive
        for j, joint in enumerate(robot.joints):
            if joint.kind != ROTATION:
                continue
            if joint.periodic:
                sub = ob.SO2StateSpace()
                self._layout.append(("so2", [j]))
            else:
                sub = self._real_vector([j])
                self._layout.append(("rv", [j]))
            self.space.addSubspace(sub, self.meters_per_radian)
            self._subspaces.append(sub)
        trans = [j for j, joint in enumerate(robot.joints) if joint.kind == TRANSLATION]
        if trans:
            sub = self._real_vector(trans)
            self.space.addSubspace(sub, 1.0)
            self._subspaces.append(sub)
            self._layout.append(("rv", trans))

    def _real_vector(self, idx):
        sub = ob.RealVectorStateSpace(len(idx))
        bounds = ob.RealVectorBounds(len(idx))
        for k, j in enumerate(idx):
            bounds.setLow(k, float(self.lower[j]))
            bounds.setHigh(k, float(self.upper[j]))
        sub.setBounds(bounds)
        return sub

    # ------------------------------------------------------------------ conversions
    def to_numpy(self, state) -> np.ndarray:
        """Joint vector of an OMPL state.

        Parameters
        ----------
        state : ob.CompoundState
            State of :attr:`space`.

        Returns
        -------
        ndarray, shape (n_joints,)
            Joint values in robot joint order [rad or m]; periodic angles in [-pi, pi).
        """
        q = np.empty(self.n_joints)
        for k, (kind, idx) in enumerate(self._layout):
            sub = state[k]
            if kind == "so2":
                q[idx[0]] = sub.value
            else:
                for m, j in enumerate(idx):
                    q[j] = sub[m]
        return q

    def set_state(self, state, q) -> None:
        """Write a joint vector into an existing OMPL state (periodic angles are wrapped).

        Parameters
        ----------
        state : ob.CompoundState
        q : array-like, shape (n_joints,)
            [rad or m].

        Raises
        ------
        ValueError
            If ``q`` has the wrong shape or is not finite.
        """
        q = self._check_q(q)
        for k, (kind, idx) in enumerate(self._layout):
            sub = state[k]
            if kind == "so2":
                sub.value = float(wrap_angle(q[idx[0]]))
            else:
                for m, j in enumerate(idx):
                    sub[m] = float(q[j])

    def from_numpy(self, q):
        """Allocate a new OMPL state holding ``q``.

        The Python wrapper owns the state: do **not** call ``space.freeState`` on it (that
        double-frees and crashes at garbage collection, checked with OMPL 2.0.1).

        Parameters
        ----------
        q : array-like, shape (n_joints,)
            [rad or m].

        Returns
        -------
        ob.CompoundState
        """
        s = self.space.allocState()
        self.set_state(s, q)
        return s

    def _check_q(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.n_joints,):
            raise ValueError(f"joint vector needs shape ({self.n_joints},) "
                             f"({', '.join(self.robot.joint_names)}), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError(f"joint vector is not finite: {q}")
        return q

    # ------------------------------------------------------------------ metric in numpy
    def difference(self, q0, q1) -> np.ndarray:
        """Signed joint difference ``q1 - q0`` taking the short way round periodic joints.

        Parameters
        ----------
        q0, q1 : array-like, shape (..., n_joints)
            [rad or m].

        Returns
        -------
        ndarray, shape (..., n_joints)
            [rad or m]; periodic components in [-pi, pi).
        """
        d = np.asarray(q1, dtype=float) - np.asarray(q0, dtype=float)
        return np.where(self.periodic, wrap_angle(d), d)

    def distance(self, q0, q1):
        """OMPL's compound distance between joint vectors (see module doc).

        Parameters
        ----------
        q0, q1 : array-like, shape (..., n_joints)
            [rad or m].

        Returns
        -------
        float or ndarray, shape (...)
            Weighted distance [m].
        """
        d = self.difference(q0, q1)
        rot = np.sum(np.abs(d) * np.where(self.is_rotation, self.weights, 0.0), axis=-1)
        tr = np.sqrt(np.sum(np.where(self.is_rotation, 0.0, d) ** 2, axis=-1))
        return rot + tr

    def segment_count(self, q0, q1, resolution: float) -> int:
        """OMPL's ``validSegmentCount`` of the motion ``q0 -> q1`` at a validity-checking
        resolution: the largest over the subspaces (SO2 per periodic rotation, a real line per
        bounded rotation, one real vector of the translations) of
        ceil(subspace distance / (subspace extent * fraction)), with
        fraction = min(1, resolution / maximum extent of the compound space). The states
        ``q0 + (k / count) (q1 - q0)`` are those OMPL's discrete motion validator checks; they
        are at most ``resolution`` apart in the weighted metric, and on the paper's robot much
        closer (0.032 rad of rotation or 0.7 mm of translation at 2 mm).

        Parameters
        ----------
        q0, q1 : array-like, shape (n_joints,)
            [rad or m].
        resolution : float
            [m of the weighted metric], > 0.

        Returns
        -------
        int
        """
        fraction = min(1.0, float(resolution) / self.space.getMaximumExtent())
        d = self.difference(q0, q1)
        count = 0
        for k, (kind, idx) in enumerate(self._layout):
            seg = self.space.getSubspace(k).getMaximumExtent() * fraction
            dist = abs(d[idx[0]]) if kind == "so2" else float(np.sqrt(np.sum(d[idx] ** 2)))
            count = max(count, int(np.ceil(dist / seg)))
        return count

    def interpolate(self, q0, q1, t) -> np.ndarray:
        """Points on the straight joint-space segment from ``q0`` to ``q1`` (as OMPL does).

        Parameters
        ----------
        q0, q1 : array-like, shape (n_joints,)
            [rad or m].
        t : array-like, shape (m,)
            Fractions in [0, 1].

        Returns
        -------
        ndarray, shape (m, n_joints)
            Continuous (not re-wrapped) joint vectors starting at ``q0`` [rad or m].
        """
        q0 = np.asarray(q0, dtype=float)
        d = self.difference(q0, q1)
        t = np.asarray(t, dtype=float).reshape(-1, 1)
        return q0[None, :] + t * d[None, :]
