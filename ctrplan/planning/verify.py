"""The final check of a path: exact model, exact obstacles, and no body point skipping an obstacle.

During the search a planner may check motions coarsely, lazily or in batches. What it returns is
executed as the rotation and translation phases of :func:`~ctrplan.planning.order_path`, and
every phase is checked here before any path leaves ctrplan:

1. states along the straight joint-space phase as OMPL's discrete motion validator places them
   at the validity-checking ``resolution`` (:meth:`JointStateSpace.segment_count`; 2 mm, as the
   pipeline checked motions before its search became coarser: 0.032 rad of rotation or 0.7 mm
   of translation between states on the paper's robot);
2. at every state: joint limits, kinematic feasibility, the bound map's validity, the standard
   model (Section II-A of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906; the
   compiled solver :func:`~ctrplan.mechanics.solve_standard_bodies`, the same discretization and
   tolerances as :func:`~ctrplan.mechanics.solve_standard`) converged and stable by the
   determinant test;
3. **swept-body refinement**: between consecutive states no point of the body may move more
   than ``max_body_step`` (points matched by their arc length from the tip, plus the change of
   the body's length); intervals that move more are bisected until they do not. A body that
   still jumps after ``max_refinements`` bisections is rejected (a snap between equilibria, or a
   branch change);
4. collisions of every state's body with the obstacles (python-fcl on the capsule chain of
   :class:`~ctrplan.planning.CollisionChecker`), the capsules **inflated by half the body
   step**. A body point moving at most ``max_body_step`` between two checked states passes
   within half a step of one of them, so an obstacle that the motion crosses, however thin,
   touches an inflated body: a path cannot tunnel through a thin wall between two samples, as a
   check of states alone can.

A phase that fails is reported with the reason and where; the ordering then bisects or repairs
the segment, or the plan fails (``UnreachableGoalError``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import CtrplanError
from .space import JointStateSpace

__all__ = ["MotionVerifier", "MotionCheck", "body_step", "DEFAULT_MAX_BODY_STEP", "DEFAULT_VERIFY_RESOLUTION"]

# Largest motion of any body point between two checked states [m]: the obstacles are checked
# with bodies inflated by half of it (0.25 mm, against tube radii of 0.9-1.3 mm). Along a
# rotation phase of the paper's robot, 0.5 mm of tip motion is ~0.03 rad.
DEFAULT_MAX_BODY_STEP = 0.5e-3

# Spacing of the first states along a phase [m of the weighted joint metric]: the search's
# default (ctrplan.planning.planners.DEFAULT_VALIDITY_RESOLUTION).
DEFAULT_VERIFY_RESOLUTION = 2e-3

# Bisections of one interval between checked states before a body that keeps jumping is rejected.
DEFAULT_MAX_REFINEMENTS = 10

_MODEL_ERRORS = (CtrplanError, np.linalg.LinAlgError, FloatingPointError)


def body_step(p0, p1) -> float:
    """Largest displacement between two robot bodies [m].

    Points are matched by their arc length measured back from the tip (the tip with the tip),
    each body's centerline interpolated linearly between its points; the change of the body's
    length is added (the base of the exposed body moves along the drive axis when tubes
    translate).

    Parameters
    ----------
    p0, p1 : ndarray, shape (K0, 3) and (K1, 3)
        Body centerlines from the most distal base to the tip [m].

    Returns
    -------
    float
        [m]
    """
    def from_tip(p):
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        return s[-1] - s, s[-1]

    u0, l0 = from_tip(p0)
    u1, l1 = from_tip(p1)
    u = np.union1d(u0, u1)
    u = u[u <= min(l0, l1)]
    a = np.column_stack([np.interp(u, u0[::-1], p0[::-1, k]) for k in range(3)])
    b = np.column_stack([np.interp(u, u1[::-1], p1[::-1, k]) for k in range(3)])
    return float(np.max(np.linalg.norm(a - b, axis=1)) + abs(l0 - l1))


@dataclass
class MotionCheck:
    """Outcome of :meth:`MotionVerifier.check`.

    Attributes
    ----------
    valid : bool
    reason : str
        ``"ok"``, or what failed and where (fraction of the motion).
    n_states : int
        States evaluated.
    max_body_step : float
        Largest body displacement between consecutive checked states [m].
    fraction : float
        Where along the motion (0..1) the first failure is; NaN when valid.
    """

    valid: bool
    reason: str
    n_states: int
    max_body_step: float
    fraction: float = float("nan")


class MotionVerifier:
    """The final check of straight joint-space motions (module docstring).

    Parameters
    ----------
    robot : Robot
    obstacles : sequence of Obstacle or dict
        As for :class:`~ctrplan.planning.CollisionChecker` (empty: no collision test).
    field : object, optional
        ``is_valid(q (m, n_joints)) -> bool (m,)``, e.g. the planner's ``BoundField``.
    settings : ModelSettings, optional
        Standard-model settings (``multistart`` ignored: the map flags multi-equilibrium regions).
    joint_space : JointStateSpace, keyword-only, optional
    resolution : float, keyword-only
        Validity-checking resolution of the first states [m of the weighted metric], as OMPL's
        (:meth:`JointStateSpace.segment_count`).
    max_body_step : float, keyword-only
        Largest body displacement between checked states [m]; bodies are inflated by half of it.
    segment_length : float, keyword-only
        Capsule length of the collision bodies [m] (as the search's checker).
    padding : float, keyword-only
        Extra inflation of every body [m], on top of half the body step.
    max_refinements : int, keyword-only
        Bisections of an interval before a still-jumping body is rejected.
    collision : CollisionChecker, keyword-only, optional
        The collision test of ``obstacles`` already built with these bodies' padding
        (``padding + max_body_step / 2``) and ``segment_length``, e.g. another verifier's
        ``collision``; default: built here.

    Attributes
    ----------
    n_motions, n_states : int
        Motions and states checked.
    seconds : float
        Wall time spent checking [s].
    """

    def __init__(self, robot, obstacles=(), field=None, settings=None, *, joint_space: JointStateSpace | None = None,
                 resolution: float = DEFAULT_VERIFY_RESOLUTION, max_body_step: float = DEFAULT_MAX_BODY_STEP,
                 segment_length: float | None = None, padding: float = 0.0,
                 max_refinements: int = DEFAULT_MAX_REFINEMENTS, collision=None):
        from ..mechanics import ModelSettings
        from .collision import DEFAULT_SEGMENT_LENGTH, CollisionChecker

        if not (resolution > 0 and max_body_step > 0):
            raise ValueError(f"resolution and max_body_step must be > 0, got {resolution!r}, {max_body_step!r}")
        self.robot = robot
        self.field = field
        self.settings = settings or ModelSettings()
        self.joint_space = joint_space if joint_space is not None else JointStateSpace(robot)
        self.resolution = float(resolution)
        self.max_body_step = float(max_body_step)
        self.max_refinements = int(max_refinements)
        obstacles = list(obstacles)
        self.collision = collision if collision is not None or not obstacles else CollisionChecker(
            obstacles, segment_length=DEFAULT_SEGMENT_LENGTH if segment_length is None else segment_length,
            padding=float(padding) + 0.5 * self.max_body_step)
        self.n_motions = 0
        self.n_states = 0
        self.seconds = 0.0

    def __call__(self, q0, q1) -> bool:
        """True if the motion ``q0 -> q1`` (shapes (n_joints,)) passes :meth:`check`."""
        return self.check(q0, q1).valid

    def _states(self, Q):
        """(ok (m,), reason list, bodies) of the states Q (m, n_joints)."""
        from ..mechanics import solve_standard_bodies

        m = Q.shape[0]
        self.n_states += m
        ok = np.ones(m, dtype=bool)
        reasons = [""] * m
        alpha = np.zeros((m, self.robot.n_tubes))
        beta = np.zeros((m, self.robot.n_tubes))
        for i, q in enumerate(Q):
            try:
                alpha[i], beta[i] = self.robot.configuration(q)
                self.robot.check_configuration(alpha[i], beta[i])
            except CtrplanError as exc:
                ok[i], reasons[i] = False, f"impossible configuration: {exc}"
        if self.field is not None:
            fv = np.asarray(self.field.is_valid(Q), dtype=bool).reshape(-1)
            for i in np.flatnonzero(ok & ~fv):
                ok[i], reasons[i] = False, "next to an unstable or failed node of the bound map"
        try:
            bodies = solve_standard_bodies(self.robot, alpha, beta, self.settings)
        except _MODEL_ERRORS as exc:   # pragma: no cover - the compiled solver flags rather than raises
            return np.zeros(m, dtype=bool), [f"standard model failed: {exc}"] * m, None
        bad = ok & ~(bodies.converged & ~bodies.unstable)
        for i in np.flatnonzero(bad):
            ok[i] = False
            reasons[i] = ("standard model did not converge" if not bodies.converged[i]
                          else "elastically unstable (shooting-Jacobian determinant <= 0)")
        return ok, reasons, bodies

    def check(self, q0, q1) -> MotionCheck:
        """Check the straight joint-space motion ``q0 -> q1``, both ends included.

        Parameters
        ----------
        q0, q1 : array-like, shape (n_joints,)
            [rad or m]; periodic joints move the way :class:`JointStateSpace` interpolates.

        Returns
        -------
        MotionCheck
        """
        t0 = time.perf_counter()
        try:
            return self._check(q0, q1)
        finally:
            self.seconds += time.perf_counter() - t0

    def _check(self, q0, q1) -> MotionCheck:
        self.n_motions += 1
        js = self.joint_space
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        n = max(1, js.segment_count(q0, q1, self.resolution))
        t = np.linspace(0.0, 1.0, n + 1)
        Q = js.interpolate(q0, q1, t)
        ok, reasons, bodies = self._states(Q)
        n_eval = Q.shape[0]
        if not np.all(ok):
            i = int(np.flatnonzero(~ok)[0])
            return MotionCheck(False, reasons[i], n_eval, float("nan"), float(t[i]))
        pts = [bodies.points[i, :bodies.counts[i]] for i in range(len(t))]
        rad = [bodies.radii[i, :bodies.counts[i]] for i in range(len(t))]
        steps = [body_step(pts[i], pts[i + 1]) for i in range(len(t) - 1)]
        for _ in range(self.max_refinements):
            wide = [i for i, s in enumerate(steps) if s > self.max_body_step]
            if not wide:
                break
            tm = np.array([0.5 * (t[i] + t[i + 1]) for i in wide])
            Qm = js.interpolate(q0, q1, tm)
            okm, rm, bm = self._states(Qm)
            n_eval += len(tm)
            if not np.all(okm):
                j = int(np.flatnonzero(~okm)[0])
                return MotionCheck(False, rm[j], n_eval, float(max(steps)), float(tm[j]))
            # splice the midpoints in (from the back so indices stay valid)
            for j, i in sorted(enumerate(wide), key=lambda x: -x[1]):
                pm, rmid = bm.points[j, :bm.counts[j]], bm.radii[j, :bm.counts[j]]
                t = np.insert(t, i + 1, tm[j])
                pts.insert(i + 1, pm)
                rad.insert(i + 1, rmid)
                steps[i:i + 1] = [body_step(pts[i], pm), body_step(pm, pts[i + 2])]
        largest = float(max(steps)) if steps else 0.0
        if largest > self.max_body_step:
            i = int(np.argmax(steps))
            return MotionCheck(False, f"the body jumps by {largest * 1e3:.2f} mm between t = {t[i]:.4f} and "
                                      f"{t[i + 1]:.4f} of the motion after {self.max_refinements} bisections "
                                      "(a snap between equilibria or a branch change)", n_eval, largest, float(t[i]))
        if self.collision is not None:
            P = max(len(p) for p in pts)
            points = np.full((len(pts), P, 3), np.nan)
            radii = np.full((len(pts), P), np.nan)
            counts = np.array([len(p) for p in pts], dtype=np.int64)
            for i, (p, r) in enumerate(zip(pts, rad)):
                points[i, :len(p)], radii[i, :len(p)] = p, r
            hit = self.collision.collides_batch(points, radii, counts)
            if np.any(hit):
                i = int(np.flatnonzero(hit)[0])
                return MotionCheck(False, f"collision (bodies inflated by {0.5 * self.max_body_step * 1e3:.2f} mm) "
                                          f"at t = {t[i]:.4f} of the motion", n_eval, largest, float(t[i]))
        return MotionCheck(True, "ok", n_eval, largest)
