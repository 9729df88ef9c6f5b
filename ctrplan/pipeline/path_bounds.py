"""The exact bounds along a plan (part of stage 5): the bounds along an ordered path, interpolated
from the map, and the exact bound given the last motion at its waypoints (:class:`PathBounds`,
:func:`bounds_along_path`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..choices import MotionKind
from ..mechanics import evaluate_bound
from ..planning import bounds_given_last_motion

__all__ = ["PATH_SAMPLE_SPACING", "PathBounds", "bounds_along_path"]


#: Spacing of interpolated-bound samples along an ordered path for the bound plot and the
#: max-bound comparison [m of the weighted joint metric].
PATH_SAMPLE_SPACING = 2e-3


@dataclass(frozen=True, eq=False)
class PathBounds:
    """Interpolated bounds sampled along an ordered path and the exact bound at its waypoints.

    Attributes
    ----------
    dense_q : ndarray, shape (N, n_joints)
        Straight-line samples along each ordered phase, ``PATH_SAMPLE_SPACING`` apart at most
        [rad or m].
    dense_s : ndarray, shape (N,)
        Cumulative joint-space length at the samples [m of the weighted metric].
    dense_motion : list of str, length N
        Motion of the phase each sample lies on.
    dense_friction, dense_translation_last : ndarray, shape (N,)
        The map's friction and translation-last bounds at the samples [m].
    dense_given_last : ndarray, shape (N,)
        The bound given the last motion: translation-last along a translation phase, friction
        along a rotation (Section V-B) [m].
    planned : ndarray, shape (K,)
        The map's value of the quantity the exact bound gives at each waypoint [m].
    exact : LastMotionBounds
        The exact bound given the last motion at the K waypoints (``position`` [m], ``angle``
        [rad], the :class:`~ctrplan.mechanics.BoundResult` per waypoint or None).
    """

    dense_q: np.ndarray
    dense_s: np.ndarray
    dense_motion: list
    dense_friction: np.ndarray
    dense_translation_last: np.ndarray
    dense_given_last: np.ndarray
    planned: np.ndarray
    exact: Any


def _dense_path(ordered_q, motions, joint_space, spacing):
    """Straight-line samples along each ordered phase, with cumulative joint-space length."""
    pts, s, seg_motion = [ordered_q[0]], [0.0], [motions[0]]
    total = 0.0
    for k in range(1, len(ordered_q)):
        a, b = ordered_q[k - 1], ordered_q[k]
        d = joint_space.distance(a, b)
        m = max(1, int(np.ceil(d / spacing)))
        for t in np.arange(1, m + 1) / m:
            pts.append(a + (b - a) * t)
            s.append(total + d * t)
            seg_motion.append(motions[k])
        total += d
    return np.array(pts), np.array(s), seg_motion


def bounds_along_path(ordered, robot, field, settings, joint_space, *, exact=None) -> PathBounds:
    """Interpolated bounds sampled along an ordered path, and the exact bound at its waypoints.

    Parameters
    ----------
    ordered : OrderedPath
        K waypoints, shape (K, n_joints) [rad or m], with the motion ending at each.
    robot : Robot
    field : BoundField
        The planner's bound map [m, rad].
    settings : ModelSettings
        Settings of the exact model.
    joint_space : JointStateSpace
        Its metric spaces the samples (:data:`PATH_SAMPLE_SPACING`).
    exact : LastMotionBounds, optional, keyword-only
        The exact bounds at these waypoints, computed before (with another map): reused.

    Returns
    -------
    PathBounds
        In m and rad; the exact bound given the last motion is
        :func:`ctrplan.planning.bounds_given_last_motion` (Section V-B of Ha et al. 2019).
    """
    qd, sd, md = _dense_path(ordered.q, ordered.motions, joint_space, PATH_SAMPLE_SPACING)
    friction = np.asarray(field(qd, "position"))
    tlast = np.asarray(field(qd, "translation_last_position"))
    # along a rotation phase the friction bound applies; along (and after) a translation, the
    # translation-last bound (Section V-B)
    given_last = np.where(np.array(md) == MotionKind.TRANSLATION, tlast, friction)
    # the map's value of the quantity the exact report gives at each waypoint
    motions = np.array(ordered.motions)
    planned = np.where(motions == MotionKind.TRANSLATION, field(ordered.q, "translation_last_position"),
                       field(ordered.q, "position"))
    return PathBounds(dense_q=qd, dense_s=sd, dense_motion=md, dense_friction=friction,
                      dense_translation_last=tlast, dense_given_last=given_last, planned=planned,
                      exact=exact if exact is not None else bounds_given_last_motion(ordered, robot, evaluate_bound,
                                                                                     settings))
