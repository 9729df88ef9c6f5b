"""Assertions on a plan for pytest suites: ``from ctrplan.testing import assert_bound_below``.

Each assertion takes either a :class:`ctrplan.api.PlanResult` (:func:`ctrplan.plan`) or
the output folder of ``ctrplan plan`` (``path.csv``, ``trajectory.csv`` and ``summary.json``,
whose ``scenario_file`` names the scenario, read again for its robot, obstacles and drive
limits). Arguments are in SI units (m, rad); a failure raises :class:`AssertionError` whose
message names the waypoint (its 0-based index, the row of ``path.csv``), the quantity, its value
and the limit in mm and degrees.

- :func:`assert_bound_below`: the exact friction bound given the last motion (Section V-B of
  Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906) at every waypoint and, optionally,
  between waypoints;
- :func:`assert_rotations_before_translations`: every phase moves only its joint group, and each
  goal is reached by a rotation-then-translation motion (never a rotation after a translation);
- :func:`assert_collision_free`: the robot body clear of the scenario's obstacles by a margin;
- :func:`assert_trajectory_within_limits`: the drive trajectory within the joint and drive
  limits, through every waypoint.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .choices import JointKind, MotionKind
from .api import PlanResult
from .errors import CtrplanError

__all__ = ["assert_bound_below", "assert_rotations_before_translations", "assert_collision_free",
           "assert_trajectory_within_limits", "DEFAULT_RESOLUTION"]

# Largest joint step between the points checked along a segment: rotations [rad], translations
# [m]. Each point costs one exact-bound evaluation (17 ms each measured on the task-target plan);
# 10 deg and 5 mm give 16 points on its 19 waypoints.
DEFAULT_RESOLUTION = (math.radians(10.0), 5e-3)

# A trajectory sample is at a waypoint when every joint is within this [rad or m] (the files keep
# full float precision; ruckig sets segment ends exactly).
WAYPOINT_TOL = 1e-9

# Relative tolerance on the drive's velocity and acceleration limits [-]
# (ctrplan.trajectory.LIMIT_RTOL: ruckig meets its limits to about 1e-12).
LIMIT_RTOL = 1e-6

# Absolute tolerance on the joint limits [rad or m] (ctrplan.trajectory.ABS_TOL).
ABS_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class _Plan:
    """The parts of a plan the assertions read, from a PlanResult or an output folder."""

    label: str
    scenario: Any
    robot: Any
    settings: Any
    q: np.ndarray                   # (K, n_joints) [rad or m]
    motion: list
    bound_position_m: np.ndarray    # (K,) [m]
    goal_waypoints: tuple
    final_motion: str
    traj: Any                       # dict of t (T,), position, velocity, acceleration (T, n_joints), or None


def _settings(scenario):
    from .mechanics import ModelSettings

    return ModelSettings(ds=scenario.bound_field.ds) if scenario.bound_field.ds else ModelSettings()


def _plan(result_or_dir) -> _Plan:
    if isinstance(result_or_dir, PlanResult):
        r = result_or_dir
        t = r.trajectory
        traj = None if t is None else {"t": t.t, "position": t.position, "velocity": t.velocity,
                                       "acceleration": t.acceleration}
        return _Plan(label=str(r.output_dir or f"plan of {r.scenario.name}"), scenario=r.scenario, robot=r.robot,
                     settings=r.run.setup.settings,
                     q=np.asarray(r.q, float), motion=[str(m) for m in r.motion],
                     bound_position_m=np.asarray(r.bound_position_m, float),
                     goal_waypoints=tuple(r.goal_waypoints), final_motion=r.run.aimed.final_motion, traj=traj)
    if not isinstance(result_or_dir, (str, os.PathLike)):
        raise TypeError(f"expected a PlanResult or an output folder, got {type(result_or_dir).__name__}")
    from .io.scenario import load_scenario
    from .planning.outputs import SUMMARY_FILE, read_plan_folder

    folder = read_plan_folder(result_or_dir)
    if folder.scenario_file is None:
        raise ValueError(f"{folder.folder / SUMMARY_FILE}: no 'scenario_file' (written by ctrplan plan since it names "
                         "the scenario); plan again or pass a PlanResult")
    sc = load_scenario(folder.scenario_file)
    if folder.joint_names != tuple(sc.robot.joint_names):
        raise ValueError(f"{folder.folder}: path.csv's joints {folder.joint_names} are not the robot's "
                         f"{tuple(sc.robot.joint_names)} ({folder.scenario_file})")
    return _Plan(label=str(folder.folder), scenario=sc, robot=sc.robot, settings=_settings(sc), q=folder.q,
                 motion=list(folder.motion), bound_position_m=folder.bound_position_m,
                 goal_waypoints=folder.goal_waypoints, final_motion=folder.final_motion,
                 traj=None if folder.trajectory is None else dict(folder.trajectory))


def _unit(kind: str) -> tuple[str, float]:
    """Report unit and factor from SI of a joint kind: degrees for rotations, mm for translations."""
    return ("deg", math.degrees(1.0)) if kind == JointKind.ROTATION else ("mm", 1e3)


def _unwrapped(p: _Plan) -> np.ndarray:
    """Waypoints with periodic angles continuous (each segment turns the short way, as planned)."""
    q = p.q.copy()
    per = np.array([j.periodic for j in p.robot.joints])
    if np.any(per):
        q[:, per] = np.unwrap(q[:, per], axis=0)
    return q


def _between(p: _Plan, resolution):
    """Points strictly inside each segment: (segment k, fraction, q (n_joints,)), at most
    ``resolution`` (rad, m) apart in the joints that move."""
    step_rad, step_m = (float(x) for x in resolution)
    if not (step_rad > 0 and step_m > 0):
        raise ValueError(f"resolution needs two steps > 0 (rad, m), got {resolution!r}")
    kinds = np.array([j.kind for j in p.robot.joints])
    q = _unwrapped(p)
    for k in range(1, len(q)):
        d = np.abs(q[k] - q[k - 1])
        n = max(1, math.ceil(max(np.max(d[kinds == JointKind.ROTATION], initial=0.0) / step_rad,
                                 np.max(d[kinds == JointKind.TRANSLATION], initial=0.0) / step_m)))
        for j in range(1, n):
            yield k, j / n, q[k - 1] + (q[k] - q[k - 1]) * (j / n)


# --------------------------------------------------------------------------- assertions
def assert_bound_below(result_or_dir, limit_m: float, *, between: bool = True,
                       resolution=DEFAULT_RESOLUTION) -> None:
    """Assert that the exact tip-error bound stays below a limit along the plan.

    At every waypoint the bound given the last motion (``bound_position_m`` of ``path.csv``:
    the friction bound after the start and a rotation, the translation-last bound after a
    translation; Section V-B of Ha et al. 2019). With ``between``, the same quantity is
    evaluated with the exact model (:func:`ctrplan.mechanics.evaluate_bound`) at points
    interpolated linearly in joint space inside every segment: the friction bound along a rotation
    phase, the translation-last bound along a translation phase.

    Parameters
    ----------
    result_or_dir : PlanResult or str or path-like
        A plan (:func:`ctrplan.plan`) or the output folder of ``ctrplan plan``.
    limit_m : float
        Largest bound allowed [m].
    between : bool, keyword-only
        Also check between waypoints (one exact-bound evaluation per point).
    resolution : tuple of float, keyword-only
        Largest step between checked points: (rotations [rad], translations [m]); default
        :data:`DEFAULT_RESOLUTION` (10 deg, 5 mm).

    Raises
    ------
    AssertionError
        The bound at a waypoint or between two is not below ``limit_m`` or could not be
        evaluated; the message names the worst point, its bound and the limit in mm.
    ValueError
        Bad ``resolution``.
    """
    from .mechanics import evaluate_bound

    p = _plan(result_or_dir)
    bad = []        # (bound [m], where)
    for k, (b, m) in enumerate(zip(p.bound_position_m, p.motion)):
        if not b < limit_m:
            bad.append((b, f"waypoint {k} ({m}, {'translation-last' if m == 'translation' else 'friction'} bound)"))
    if between:
        for k, s, q in _between(p, resolution):
            where = f"between waypoints {k - 1} and {k} ({p.motion[k]}, {100 * s:.0f} % of the way)"
            try:
                alpha, beta = p.robot.configuration(q)
                res = evaluate_bound(p.robot, alpha, beta, p.settings)
            except CtrplanError as exc:
                bad.append((math.nan, f"{where}: {exc}"))
                continue
            b = res.translation_last_position if p.motion[k] == MotionKind.TRANSLATION else res.position
            if not b < limit_m:
                bad.append((b, where))
    if bad:
        worst_b, where = max(bad, key=lambda x: math.inf if math.isnan(x[0]) else x[0])
        value = "could not be evaluated" if math.isnan(worst_b) else f"{worst_b * 1e3:.3f} mm"
        raise AssertionError(f"{p.label}: tip-error bound at {where}: {value}, not below the limit "
                             f"{limit_m * 1e3:.3f} mm ({len(bad)} point(s) fail)")


def assert_rotations_before_translations(result_or_dir) -> None:
    """Assert the rotate-then-translate order of Section V-B of Ha et al. 2019.

    The planner splits every straight segment of its path into a rotation phase followed by a
    translation phase (:func:`ctrplan.planning.ordering.order_path`), so that a motion ends with
    a translation, which leaves only the clearance-induced error. Between two goals the path is
    several such segments, so a rotation may follow a translation where one planned segment
    ends and the next begins; ``path.csv`` does not mark those joins. What it shows is checked:

    1. the first waypoint is the start, every other one is reached by a ``rotation`` or a
       ``translation`` phase that changes only the joints of its kind (and changes one);
    2. in every part of the path that ends at a goal (from the previous goal's waypoint,
       exclusive, to this goal's waypoint, inclusive), the goal is not reached by a rotation
       right after a translation: the last planned segment did its rotation first.

    A plan made with ``[planner] final_motion = "rotation-last"`` swaps the phases before each
    goal on purpose, and fails the second check.

    Parameters
    ----------
    result_or_dir : PlanResult or str or path-like
        A plan (:func:`ctrplan.plan`) or the output folder of ``ctrplan plan``.

    Raises
    ------
    AssertionError
        Naming the waypoint, its motion and the joints that changed (in degrees or mm).
    """
    p = _plan(result_or_dir)
    kinds = np.array([j.kind for j in p.robot.joints])
    names = p.robot.joint_names
    q = _unwrapped(p)
    if not p.motion or p.motion[0] != MotionKind.START:
        raise AssertionError(f"{p.label}: waypoint 0 has motion {p.motion[0] if p.motion else None!r}, not 'start'")
    for k in range(1, len(q)):
        m = p.motion[k]
        if m not in (MotionKind.ROTATION, MotionKind.TRANSLATION):
            raise AssertionError(f"{p.label}: waypoint {k} has motion {m!r}, not 'rotation' or 'translation'")
        d = q[k] - q[k - 1]
        moved = np.abs(d) > WAYPOINT_TOL
        if not moved.any():
            raise AssertionError(f"{p.label}: waypoint {k} ({m}) repeats waypoint {k - 1}")
        wrong = moved & (kinds != m)
        if wrong.any():
            i = int(np.flatnonzero(wrong)[0])
            unit, f = _unit(kinds[i])
            raise AssertionError(f"{p.label}: waypoint {k} is reached by a {m} phase that also changes the "
                                 f"{kinds[i]} joint {names[i]} by {d[i] * f:.4g} {unit} (limit 0 {unit})")
    start = 0
    for g, gi in enumerate(p.goal_waypoints):
        if gi - 1 > start and p.motion[gi] == MotionKind.ROTATION and p.motion[gi - 1] == MotionKind.TRANSLATION:
            rot = np.flatnonzero(np.abs(q[gi] - q[gi - 1]) > WAYPOINT_TOL)
            turned = ", ".join(f"{names[i]} {math.degrees(q[gi, i] - q[gi - 1, i]):.4g} deg" for i in rot)
            raise AssertionError(
                f"{p.label}: goal {g + 1} (waypoint {gi}) is reached by a rotation ({turned}) after the translation "
                f"to waypoint {gi - 1}: a rotation follows a translation in the segment ending at this goal "
                f"(final motion of the plan: {p.final_motion or 'not recorded'})")
        start = gi


def assert_collision_free(result_or_dir, clearance_m: float = 0.0, *, between: bool = True,
                          resolution=DEFAULT_RESOLUTION) -> None:
    """Assert that the robot body keeps a clearance from the scenario's obstacles.

    The body is the standard model's (:meth:`ctrplan.mechanics.results.StandardSolution.body`,
    capsules of the outer tube radius), checked with the planner's own
    :class:`ctrplan.planning.CollisionChecker` (FCL) with every capsule inflated by
    ``clearance_m``, at every waypoint and, with ``between``, at points interpolated linearly in
    joint space inside every segment.

    Parameters
    ----------
    result_or_dir : PlanResult or str or path-like
        A plan (:func:`ctrplan.plan`) or the output folder of ``ctrplan plan``.
    clearance_m : float
        Smallest body-obstacle distance allowed [m], >= 0.
    between : bool, keyword-only
        Also check between waypoints.
    resolution : tuple of float, keyword-only
        Largest step between checked points: (rotations [rad], translations [m]).

    Raises
    ------
    AssertionError
        The body comes closer than ``clearance_m`` to an obstacle (or the standard model fails);
        the message names the first such point and its distance and the clearance in mm.
    ValueError
        Negative ``clearance_m`` or bad ``resolution``.
    """
    from .mechanics import solve_standard
    from .planning.collision import CollisionChecker

    if not clearance_m >= 0.0:
        raise ValueError(f"clearance_m must be >= 0 m, got {clearance_m!r}")
    p = _plan(result_or_dir)
    obstacles = list(p.scenario.obstacles)
    if not obstacles:
        return
    padded = CollisionChecker(obstacles, padding=clearance_m)
    exact = CollisionChecker(obstacles)
    points = [(f"waypoint {k} ({m})", q) for k, (m, q) in enumerate(zip(p.motion, _unwrapped(p)))]
    if between:
        points += [(f"between waypoints {k - 1} and {k} ({p.motion[k]}, {100 * s:.0f} % of the way)", q)
                   for k, s, q in _between(p, resolution)]
    for where, q in points:
        try:
            alpha, beta = p.robot.configuration(q)
            body = solve_standard(p.robot, alpha, beta, p.settings).body(p.robot)
        except CtrplanError as exc:
            raise AssertionError(f"{p.label}: robot body at {where}: standard model failed: {exc}") from None
        if padded.check_body(*body).collides:
            dist = exact.check_body(*body, distance=True).min_distance
            raise AssertionError(f"{p.label}: robot body at {where}: distance to the nearest obstacle "
                                 f"{max(dist, 0.0) * 1e3:.3f} mm, below the clearance {clearance_m * 1e3:.3f} mm")


def assert_trajectory_within_limits(result_or_dir) -> None:
    """Assert that the drive trajectory respects the limits and passes through every waypoint.

    Positions within the robot's joint limits (periodic joints are unlimited), velocities and
    accelerations within the scenario's ``[drive]`` limits (relative tolerance
    :data:`LIMIT_RTOL`), and every waypoint of the plan reached by a sample, in order (within
    :data:`WAYPOINT_TOL`; periodic angles modulo 2 pi).

    Parameters
    ----------
    result_or_dir : PlanResult or str or path-like
        A plan (:func:`ctrplan.plan`) or the output folder of ``ctrplan plan``.

    Raises
    ------
    AssertionError
        No trajectory or no ``[drive]`` table; or, naming the sample (time [s]) or the waypoint,
        the joint, its value and the limit (degrees or mm, per s and per s^2).
    """
    p = _plan(result_or_dir)
    drive = p.scenario.drive
    if p.traj is None or drive is None:
        raise AssertionError(f"{p.label}: no drive trajectory (the scenario needs a [drive] table)")
    t, pos, vel, acc = (np.asarray(p.traj[k], float) for k in ("t", "position", "velocity", "acceleration"))
    names = p.robot.joint_names
    for arr, what in ((pos, "position"), (vel, "velocity"), (acc, "acceleration")):
        if not np.all(np.isfinite(arr)):
            s, i = np.argwhere(~np.isfinite(arr))[0]
            raise AssertionError(f"{p.label}: trajectory at t = {t[s]:.4f} s: {names[i]} {what} is {arr[s, i]!r}, "
                                 "not a finite number")
    for i, j in enumerate(p.robot.joints):
        unit, f = _unit(j.kind)
        if not j.periodic:
            for value, limit, side in ((pos[:, i], j.lower, "below the lower"), (pos[:, i], j.upper, "above the upper")):
                over = (limit - value) if side.startswith("below") else (value - limit)
                s = int(np.argmax(over))
                if over[s] > ABS_TOL:
                    raise AssertionError(f"{p.label}: trajectory at t = {t[s]:.4f} s: {names[i]} = "
                                         f"{value[s] * f:.4f} {unit}, {side} joint limit {limit * f:.4f} {unit}")
        for arr, limit, what, per in ((vel[:, i], drive.max_velocity[i], "velocity", "/s"),
                                      (acc[:, i], drive.max_acceleration[i], "acceleration", "/s^2")):
            s = int(np.argmax(np.abs(arr)))
            if abs(arr[s]) > limit * (1 + LIMIT_RTOL):
                seg = _segment_of(t[s], t, pos, _unwrapped(p))
                raise AssertionError(f"{p.label}: trajectory at t = {t[s]:.4f} s{seg}: {names[i]} {what} "
                                     f"{arr[s] * f:.4g} {unit}{per}, above the drive limit {limit * f:.4g} {unit}{per}")
    per = np.array([j.periodic for j in p.robot.joints])
    s0 = 0
    for k, qk in enumerate(_unwrapped(p)):
        d = pos[s0:] - qk
        d[:, per] = (d[:, per] + np.pi) % (2 * np.pi) - np.pi
        err = np.max(np.abs(d), axis=1)
        hits = np.flatnonzero(err <= WAYPOINT_TOL)
        if not hits.size:
            s = int(np.argmin(err))
            i = int(np.argmax(np.abs(d[s])))
            unit, f = _unit(p.robot.joints[i].kind)
            raise AssertionError(f"{p.label}: waypoint {k} ({p.motion[k]}) is not on the trajectory after "
                                 f"t = {t[s0]:.4f} s: the nearest sample (t = {t[s0 + s]:.4f} s) differs in "
                                 f"{names[i]} by {abs(d[s, i]) * f:.4g} {unit} (limit {WAYPOINT_TOL * f:.1g} {unit})")
        s0 += int(hits[0])


def _segment_of(tk: float, t, pos, q) -> str:
    """`` (segment from waypoint a to b)`` for the sample at time ``tk``: the last waypoint reached
    at or before it."""
    reached = [int(np.flatnonzero(np.max(np.abs(pos - qk), axis=1) <= WAYPOINT_TOL)[0])
               if np.any(np.max(np.abs(pos - qk), axis=1) <= WAYPOINT_TOL) else None for qk in q]
    before = [k for k, s in enumerate(reached) if s is not None and t[s] <= tk]
    if not before or before[-1] + 1 >= len(q):
        return ""
    return f" (between waypoints {before[-1]} and {before[-1] + 1})"
