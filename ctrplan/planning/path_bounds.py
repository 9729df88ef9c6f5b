"""The exact model along a plan (part of stage 5): the bounds along an ordered path, interpolated
from the map, and the exact bound given the last motion at its waypoints (:class:`PathBounds`,
:func:`bounds_along_path`); the tip predicted at every ordered waypoint for the motion history the
ordered path creates (:class:`WaypointPredictions`, :func:`predict_waypoints`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..choices import MotionKind
from ..errors import CtrplanError
from ..history import pair_friction
from ..mechanics import evaluate_bound, predict_tip
from .approach import path_history
from .ordering import bounds_given_last_motion

__all__ = ["PATH_SAMPLE_SPACING", "PathBounds", "bounds_along_path", "WaypointPredictions", "predict_waypoints"]


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


@dataclass(frozen=True, eq=False)
class WaypointPredictions:
    """Tip predicted at every ordered waypoint for the history the ordered path creates.

    Attributes
    ----------
    tip : ndarray, shape (K, 3)
        Predicted tip position [m]; NaN where the prediction failed.
    offset : ndarray, shape (K,)
        Its distance from the standard model's tip [m]; NaN where it failed.
    eta, translation_last : ndarray, shape (K, n_tubes - 1)
        The path's history per pair (:func:`ctrplan.planning.approach.path_history`).
    state : HistoryState
        The whole history state of the path (offsets of the configuration the tubes reach, e.g.
        a drive's backlash; friction state per pair).
    eta_used : ndarray of int, shape (K, n_tubes - 1)
        Friction direction applied per pair (0: frictionless there).
    cases, model, message : list of str, length K
        Per-pair cases joined by ``;``, the model used, and the solver's or the error's message.
    ok : ndarray of bool, shape (K,)
    n_solved : int
        Contact solves made (the others reused the exact bound's solutions).
    time_s : float
        [s]
    shape : tuple of (ndarray, shape (N_k, 3), or None), length K
        Predicted centerline of the innermost tube (base to tip) [m], from the same solution as
        ``tip``; None where the prediction failed.
    """

    tip: np.ndarray
    offset: np.ndarray
    eta: np.ndarray
    translation_last: np.ndarray
    eta_used: np.ndarray
    cases: list
    model: list
    ok: np.ndarray
    message: list
    n_solved: int
    time_s: float
    state: Any = None
    shape: tuple = ()


def predict_waypoints(ordered, robot, settings, exact) -> WaypointPredictions:
    """Tip predicted at every ordered waypoint for the history the ordered path creates.

    The history (:func:`ctrplan.planning.approach.path_history`) gives per pair eta and whether
    a translation followed the last rotation; :func:`ctrplan.mechanics.predict_tip` reuses the
    exact bound's clearance or friction solution at the waypoint when it is the one needed, and
    solves only partial histories.

    Parameters
    ----------
    ordered : OrderedPath
        K waypoints, shape (K, n_joints) [rad or m].
    robot : Robot
    settings : ModelSettings
        Settings of the exact model.
    exact : LastMotionBounds
        The exact bound at the K waypoints (``PathBounds.exact``), whose solutions are reused.

    Returns
    -------
    WaypointPredictions
        In m; waypoints where the bound failed, or the prediction raises, get NaN and their
        message.
    """
    t0 = time.perf_counter()
    hist = path_history(robot, ordered.q)
    mu_robot = robot.friction_coefficients
    K, m = len(ordered), robot.n_tubes - 1
    tips = np.full((K, 3), np.nan)
    offsets = np.full(K, np.nan)
    eta_used = np.zeros((K, m), dtype=int)
    cases, models, messages = [""] * K, [""] * K, [""] * K
    ok = np.zeros(K, dtype=bool)
    shapes = [None] * K
    n_solved = 0
    for k in range(K):
        res = exact.results[k]
        state = hist.at(k)
        try:
            if res is None:
                raise CtrplanError("the exact bound failed here")
            alpha, beta = robot.configuration(ordered.q[k], check_limits=False)
            p = predict_tip(robot, alpha, beta, settings=settings, state=state, bound=res)
        except (CtrplanError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            messages[k] = f"{type(exc).__name__}: {exc}"
            eta_used[k], _, c = pair_friction(state, mu_robot)
            cases[k] = ";".join(c)
            continue
        n_solved += not p.reused
        tips[k], offsets[k], eta_used[k] = p.tip_position, p.offset, p.eta
        cases[k], models[k], ok[k] = ";".join(p.cases), p.model, p.ok
        shapes[k] = np.asarray(p.solution.centerlines[-1])
        messages[k] = p.solution.diagnostics.message
    return WaypointPredictions(tip=tips, offset=offsets, eta=hist.eta, translation_last=hist.released,
                               eta_used=eta_used, cases=cases, model=models, ok=ok, message=messages,
                               n_solved=n_solved, time_s=time.perf_counter() - t0, state=hist, shape=tuple(shapes))
