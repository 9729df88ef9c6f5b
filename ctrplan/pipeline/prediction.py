"""The prediction along a plan (part of stage 5): the tip predicted at every ordered waypoint for
the motion history the ordered path creates (:class:`WaypointPredictions`, :func:`predict_waypoints`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CtrplanError
from ..history import pair_friction
from ..mechanics import predict_tip
from ..planning.history import path_history

__all__ = ["WaypointPredictions", "predict_waypoints"]


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
        The path's history per pair (:func:`ctrplan.planning.history.path_history`).
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

    The history (:func:`ctrplan.planning.history.path_history`) gives per pair eta and whether
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
