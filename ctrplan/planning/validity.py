"""Batched state and motion validity for planning, and an OMPL motion validator that uses it.

:class:`BatchValidityChecker` accepts exactly the configurations that
:class:`~ctrplan.planning.ValidityChecker` accepts as the pipeline builds it (model settings
with ``multistart=0``), but evaluates many states per call, cheapest test first:

1. joint limits and periodic joints as ``Robot.configuration`` (non-periodic joints within
   their limits +- 1e-12, finite values), full ``alpha``, ``beta`` with the translation links;
2. ``Robot.configurations_possible`` (the tests of ``Robot.check_configuration``);
3. ``field.is_valid(q)`` if a field is given;
4. the standard model (Section II-A of Ha, Fagogenis & Dupont 2019) converged and, with
   ``check_stability``, stable by the shooting-Jacobian determinant test, for all remaining
   states in one compiled call (:func:`~ctrplan.mechanics.solve_standard_bodies`);
5. no collision of the body (:meth:`CollisionChecker.collides_batch`: compiled broad phase,
   python-fcl narrow phase).

:meth:`BatchValidityChecker.check_motion` checks a straight joint-space motion at the states
and in the order of OMPL's ``DiscreteMotionValidator`` (the end state first, then the midpoint,
then the quarter points, ..., with OMPL's segment count), a few states per compiled call, and
stops at the first batch holding an invalid state. :class:`BatchMotionValidator` is the
``ob.MotionValidator`` that calls it from OMPL; :func:`use_motion_validator` installs it.
"""

from __future__ import annotations

import time

import numpy as np
from ompl import base as ob

from ..errors import CtrplanError
from ..robot import ROTATION
from .space import JointStateSpace, wrap_angle

__all__ = ["BatchValidityChecker", "BatchMotionValidator", "use_motion_validator", "bisection_order",
           "DEFAULT_MOTION_BATCH", "DEFAULT_VALIDITY_RESOLUTION"]

# Default spacing of validity checks along a motion [m of the weighted joint metric]: 2 mm is
# 0.1 rad of rotation at 0.02 m/rad, small against the bound field's cells and obstacles.
DEFAULT_VALIDITY_RESOLUTION = 2e-3

# Motion states evaluated per compiled call by check_motion after the end state [-]: a motion
# costs one call for its end state (the state most often invalid: the planner's new sample),
# then its other states in calls of this many. Only 2.6 % of the 1721 motions of 600 RRT*
# iterations on the obstacles scenario were invalid, so a large batch wastes few states, while
# each call costs ~0.3 ms of Python and numpy overhead (in one run, the 1, 1, 2, 4, 8 growth used
# before took 9.1 s against 6.3 s for this at 4 mm and 6.6 against 6.4 s at 6 mm, same plan;
# such runs drift by up to 2x on the shared machine).
DEFAULT_MOTION_BATCH = 8

# Slack of the joint-limit test of Robot.configuration [m or rad] (the same literal there).
_LIMIT_TOL = 1e-12

# Errors that make a state invalid instead of propagating, as in ValidityChecker._evaluate.
_MODEL_ERRORS = (CtrplanError, np.linalg.LinAlgError, FloatingPointError)


def bisection_order(n_segments: int) -> np.ndarray:
    """Indices of the states OMPL's ``DiscreteMotionValidator`` checks, in its order.

    State i sits at fraction i / n_segments of the motion. The end state (index
    ``n_segments``) comes first; then, if ``n_segments >= 2``, the interior 1 .. n_segments - 1
    by breadth-first bisection of index ranges: the middle ``(lo + hi) // 2`` of the range
    [lo, hi], then the ranges [lo, mid - 1] and [mid + 1, hi] (a FIFO queue started with
    [1, n_segments - 1]).

    Parameters
    ----------
    n_segments : int
        OMPL's ``validSegmentCount`` of the motion (0 or 1: only the end state).

    Returns
    -------
    ndarray of int, shape (max(n_segments, 1),)
        State indices; the end state first.
    """
    n = int(n_segments)
    order = [max(n, 1)]
    if n >= 2:
        queue = [(1, n - 1)]
        head = 0
        while head < len(queue):
            lo, hi = queue[head]
            head += 1
            mid = (lo + hi) // 2
            order.append(mid)
            if lo < mid:
                queue.append((lo, mid - 1))
            if hi > mid:
                queue.append((mid + 1, hi))
    return np.asarray(order, dtype=np.int64)


class BatchValidityChecker:
    """Vectorized, cached state validity and motion checking of a concentric tube robot.

    Accepts exactly the states that ``ValidityChecker(robot, collision, field,
    settings=settings.replace(multistart=0), check_stability=check_stability)`` accepts (the
    pipeline's checker): the multistart search for other equilibria is never run (the bound
    map flags multi-equilibrium regions), the determinant test is. One difference in use: a
    joint vector of the wrong length raises ``ValueError`` here (``ValidityChecker`` calls it
    invalid).

    Parameters
    ----------
    robot : Robot
    collision : CollisionChecker, optional
        Obstacles; its :meth:`~CollisionChecker.collides_batch` checks the bodies.
    field : object, optional
        Anything with ``is_valid(q (m, n_joints)) -> bool (m,)``, e.g. a ``BoundField``.
    settings : ModelSettings, optional
        Standard-model settings (``multistart`` is ignored). Default ``ModelSettings()``.
    check_stability : bool, keyword-only
        Reject states whose standard model did not converge or is unstable by the determinant
        test (``diagnostics.ok`` of ``solve_standard`` with ``multistart=0``). As in
        ``ValidityChecker``, the model runs when this is True or ``collision`` is given.
    joint_space : JointStateSpace, optional, keyword-only
        Metric, interpolation and OMPL segment counts of motions. Default
        ``JointStateSpace(robot)``.
    resolution : float, keyword-only
        Spacing of the states checked along a motion [m of the weighted joint metric], as
        ``plan_leg(validity_resolution=...)`` passes it to OMPL. Default 2 mm.
    batch_size : int, keyword-only
        Largest number of motion states per compiled call (default
        :data:`DEFAULT_MOTION_BATCH`).
    reference : callable, optional, keyword-only
        ``reference(q (n_joints,)) -> bool``, e.g. a ``ValidityChecker``: when given, states are
        evaluated one at a time by it instead of by the compiled tests (for cross-checks); then
        ``collision`` and ``field`` must be None.

    Attributes
    ----------
    n_calls : int
        States queried (``__call__``, ``check`` rows and motion states), cached or not.
    n_evaluations : int
        States evaluated (cache misses).
    n_motions, n_invalid_motions : int
        Motions checked, and those found invalid.
    n_model, n_collision_checked : int
        States that reached the standard model, and the collision test.
    seconds_model, seconds_collision, seconds_reference : float
        Wall time in the standard model, in collision checking and in ``reference`` [s].

    Raises
    ------
    ValueError
        If ``reference`` is combined with ``collision`` or ``field``, or ``batch_size`` < 1.
    """

    def __init__(self, robot, collision=None, field=None, settings=None, *, check_stability: bool = True,
                 joint_space: JointStateSpace | None = None,
                 resolution: float = DEFAULT_VALIDITY_RESOLUTION, batch_size: int = DEFAULT_MOTION_BATCH,
                 reference=None):
        if reference is not None and (collision is not None or field is not None):
            raise ValueError("a reference validity function replaces collision and field checks: pass neither")
        if int(batch_size) < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size!r}")
        if not (np.isfinite(resolution) and resolution > 0.0):
            raise ValueError(f"resolution must be > 0 m, got {resolution!r}")
        from ..mechanics import ModelSettings  # noqa: PLC0415 (heavy, compiled)

        self.robot = robot
        self.collision = collision
        self.field = field
        self.settings = settings or ModelSettings()
        self.check_stability = bool(check_stability)
        self.need_model = reference is None and (collision is not None or self.check_stability)
        self.reference = reference
        self.joint_space = joint_space if joint_space is not None else JointStateSpace(robot)
        self.resolution = float(resolution)
        self.batch_size = int(batch_size)
        self._n_joints = len(robot.joints)
        self._periodic = np.array([j.periodic for j in robot.joints], dtype=bool)
        self._lower = np.array([j.lower for j in robot.joints], dtype=float) - _LIMIT_TOL
        self._upper = np.array([j.upper for j in robot.joints], dtype=float) + _LIMIT_TOL
        self._motion_validators = []   # keeps installed OMPL validators alive
        self._packed = None            # robot arrays of the compiled solve, built on first use
        self._cache: dict[bytes, bool] = {}
        self.n_calls = 0
        self.n_evaluations = 0
        self.n_motions = 0
        self.n_invalid_motions = 0
        self.n_model = 0
        self.n_collision_checked = 0
        self.seconds_model = 0.0
        self.seconds_collision = 0.0
        self.seconds_reference = 0.0

    # ------------------------------------------------------------------ states
    def __call__(self, q) -> bool:
        """Validity of one state (a real ``bool``, as OMPL needs).

        Parameters
        ----------
        q : array-like, shape (n_joints,)
            [rad or m].

        Raises
        ------
        ValueError
            If ``q`` does not hold ``n_joints`` values.
        """
        return bool(self.check(np.asarray(q, dtype=float).reshape(1, -1))[0])

    def check(self, Q) -> np.ndarray:
        """Validity of many states, cached per state.

        Parameters
        ----------
        Q : array-like, shape (m, n_joints)
            Joint vectors in robot joint order [rad or m].

        Returns
        -------
        ndarray of bool, shape (m,)

        Raises
        ------
        ValueError
            If ``Q`` does not have ``n_joints`` columns.
        """
        Q = np.ascontiguousarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self._n_joints:
            raise ValueError(f"states need shape (m, {self._n_joints}) ({', '.join(self.robot.joint_names)}), "
                             f"got {Q.shape}")
        m = Q.shape[0]
        self.n_calls += m
        out = np.empty(m, dtype=bool)
        keys = [row.tobytes() for row in Q]
        todo: dict[bytes, list[int]] = {}
        for i, k in enumerate(keys):
            v = self._cache.get(k)
            if v is None:
                todo.setdefault(k, []).append(i)
            else:
                out[i] = v
        if todo:
            rows = [idx[0] for idx in todo.values()]
            values = self._evaluate(Q[rows])
            self.n_evaluations += len(rows)
            for (k, idx), v in zip(todo.items(), values.tolist()):
                self._cache[k] = v
                out[idx] = v
        return out

    def _evaluate(self, Q) -> np.ndarray:
        """Validity of distinct uncached states Q (m, n_joints), cheapest test first."""
        if self.reference is not None:
            t0 = time.perf_counter()
            v = np.array([bool(self.reference(q)) for q in Q], dtype=bool)
            self.seconds_reference += time.perf_counter() - t0
            return v
        ok = np.all(np.isfinite(Q), axis=1)
        bounded = ~self._periodic
        ok &= np.all(((Q >= self._lower) & (Q <= self._upper)) | ~bounded[None, :], axis=1)
        alpha, beta = self._configurations(Q)
        idx = np.flatnonzero(ok)
        if idx.size:
            ok[idx] = self.robot.configurations_possible(alpha[idx], beta[idx])
        if self.field is not None:
            idx = np.flatnonzero(ok)
            if idx.size:
                ok[idx] = np.asarray(self.field.is_valid(Q[idx]), dtype=bool).reshape(-1)
        if not self.need_model:
            return ok
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            return ok
        t0 = time.perf_counter()
        bodies, failed = self._bodies(alpha[idx], beta[idx])
        self.seconds_model += time.perf_counter() - t0
        self.n_model += idx.size
        good = ~failed
        if self.check_stability:
            good &= bodies.converged & ~bodies.unstable
        ok[idx] = good
        if self.collision is not None:
            sel = np.flatnonzero(good)
            if sel.size:
                t0 = time.perf_counter()
                hit = self.collision.collides_batch(bodies.points[sel], bodies.radii[sel], bodies.counts[sel])
                self.seconds_collision += time.perf_counter() - t0
                self.n_collision_checked += sel.size
                ok[idx[sel]] = ~hit
        return ok

    def _configurations(self, Q):
        """Full (alpha, beta), each (m, n), of joint vectors Q (m, n_joints), as
        ``Robot.configuration`` builds them (home values, joints, then translation links)."""
        robot = self.robot
        m = Q.shape[0]
        alpha = np.tile(np.asarray(robot.home_alpha, dtype=float), (m, 1))
        beta = np.tile(np.asarray(robot.home_beta, dtype=float), (m, 1))
        for j, joint in enumerate(robot.joints):
            if joint.kind == ROTATION:
                alpha[:, joint.tube] = Q[:, j]
            else:
                beta[:, joint.tube] = Q[:, j]
        for link in robot.links:
            beta[:, link.follower] = beta[:, link.leader] + link.offset
        return alpha, beta

    def _bodies(self, alpha, beta):
        """Standard-model bodies of (alpha, beta) (k, n); a batch whose compiled solve raises
        is redone one configuration at a time, and configurations that raise are invalid (as
        in ``ValidityChecker``). Returns (StandardBodies, failed (k,) bool)."""
        from ..mechanics import StandardBodies, solve_standard_bodies_packed  # noqa: PLC0415
        from ..mechanics.packed import pack_robot  # noqa: PLC0415

        if self._packed is None:
            self._packed = pack_robot(self.robot)
        k = alpha.shape[0]
        alpha = np.ascontiguousarray(alpha)
        beta = np.ascontiguousarray(beta)
        possible = np.ones(k, dtype=bool)   # checked by configurations_possible before
        try:
            return solve_standard_bodies_packed(self._packed, alpha, beta, possible, self.settings), np.zeros(k, dtype=bool)
        except _MODEL_ERRORS:
            pass
        parts, failed = [], np.zeros(k, dtype=bool)
        for i in range(k):
            try:
                parts.append(solve_standard_bodies_packed(self._packed, alpha[i:i + 1], beta[i:i + 1], possible[i:i + 1],
                                           self.settings))
            except _MODEL_ERRORS:
                failed[i] = True
                parts.append(None)
        P = max([p.points.shape[1] for p in parts if p is not None], default=0)
        points = np.full((k, P, 3), np.nan)
        radii = np.full((k, P), np.nan)
        counts = np.zeros(k, dtype=np.int64)
        tips = np.full((k, 3), np.nan)
        conv = np.zeros(k, dtype=bool)
        unst = np.zeros(k, dtype=bool)
        valid = np.zeros(k, dtype=bool)
        iters = np.zeros(k, dtype=np.int64)
        for i, p in enumerate(parts):
            if p is None:
                continue
            c = p.points.shape[1]
            points[i, :c], radii[i, :c], counts[i] = p.points[0], p.radii[0], p.counts[0]
            tips[i], conv[i], unst[i], valid[i], iters[i] = (p.tip_position[0], p.converged[0], p.unstable[0],
                                                              p.valid[0], p.iterations[0])
        return (StandardBodies(points=points, radii=radii, counts=counts, tip_position=tips, converged=conv,
                               unstable=unst, valid=valid, iterations=iters), failed)

    # ------------------------------------------------------------------ motions
    def segment_count(self, q0, q1) -> int:
        """OMPL's ``validSegmentCount`` of the motion q0 -> q1 at :attr:`resolution`
        (:meth:`JointStateSpace.segment_count`): consecutive checked states are at most
        ``resolution`` apart in the weighted metric [m].

        Parameters
        ----------
        q0, q1 : array-like, shape (n_joints,)
            [rad or m].

        Returns
        -------
        int
        """
        return self.joint_space.segment_count(q0, q1, self.resolution)

    def motion_states(self, q0, q1, n_segments: int | None = None) -> np.ndarray:
        """The states :meth:`check_motion` checks, in its order.

        Parameters
        ----------
        q0, q1 : array-like, shape (n_joints,)
            Motion start (not checked) and end [rad or m].
        n_segments : int, optional
            Segment count (default :meth:`segment_count`, OMPL's).

        Returns
        -------
        ndarray, shape (max(n_segments, 1), n_joints)
            States at fractions i / n_segments of the straight joint-space segment
            (``JointStateSpace.interpolate``: periodic joints the short way), periodic angles
            wrapped to [-pi, pi) as in OMPL's states; the end state first, then in bisection
            order (:func:`bisection_order`) [rad or m].
        """
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        n = self.segment_count(q0, q1) if n_segments is None else int(n_segments)
        order = bisection_order(n)
        t = order / max(n, 1)
        states = self.joint_space.interpolate(q0, q1, t)
        states[:, self._periodic] = wrap_angle(states[:, self._periodic])
        return states

    def check_motion(self, q0, q1, n_segments: int | None = None) -> bool:
        """Validity of the straight joint-space motion q0 -> q1, the start excluded.

        Checks the states of :meth:`motion_states` (spacing at most :attr:`resolution` in the
        weighted metric, OMPL's segment count and order: end state, midpoint, quarter points,
        ...): the end state alone, then the others in batches of :attr:`batch_size`, stopping
        after the first batch holding an invalid state.

        Parameters
        ----------
        q0, q1 : array-like, shape (n_joints,)
            [rad or m].
        n_segments : int, optional
            Segment count (default :meth:`segment_count`).

        Returns
        -------
        bool
        """
        self.n_motions += 1
        states = self.motion_states(q0, q1, n_segments)
        starts = [0] + list(range(1, states.shape[0], self.batch_size))
        for start, stop in zip(starts, starts[1:] + [states.shape[0]]):
            if not np.all(self.check(states[start:stop])):
                self.n_invalid_motions += 1
                return False
        return True

    def counters(self) -> dict:
        """The work counters as a dict (see the class attributes)."""
        return {"n_calls": self.n_calls, "n_evaluations": self.n_evaluations, "n_motions": self.n_motions,
                "n_invalid_motions": self.n_invalid_motions, "n_model": self.n_model,
                "n_collision_checked": self.n_collision_checked, "seconds_model": self.seconds_model,
                "seconds_collision": self.seconds_collision, "seconds_reference": self.seconds_reference}


class BatchMotionValidator(ob.MotionValidator):
    """OMPL motion validator calling :meth:`BatchValidityChecker.check_motion`.

    Converts both states with ``joint_space.to_numpy`` and takes OMPL's own segment count
    (``space.validSegmentCount``), so it checks the states of OMPL's ``DiscreteMotionValidator``
    in the same order. Install it with :func:`use_motion_validator` (before ``si.setup()``).

    Parameters
    ----------
    si : ob.SpaceInformation
    joint_space : JointStateSpace
        The space of ``si``.
    checker : BatchValidityChecker

    Attributes
    ----------
    n_checked, n_invalid : int
        Motions checked through OMPL, and those found invalid (OMPL's own counters of a Python
        validator stay 0).
    """

    def __init__(self, si, joint_space: JointStateSpace, checker: BatchValidityChecker):
        super().__init__(si)
        self.joint_space = joint_space
        self.checker = checker
        self.n_checked = 0
        self.n_invalid = 0

    def checkMotion(self, s1, s2) -> bool:  # noqa: N802 (OMPL's name)
        js = self.joint_space
        n = int(js.space.validSegmentCount(s1, s2))
        ok = bool(self.checker.check_motion(js.to_numpy(s1), js.to_numpy(s2), n_segments=n))
        self.n_checked += 1
        self.n_invalid += not ok
        return ok


def use_motion_validator(si, joint_space: JointStateSpace, checker: BatchValidityChecker) -> BatchMotionValidator:
    """Make ``checker`` the motion and state validity checker of ``si``.

    Sets ``si``'s state validity checker to ``checker`` (real ``bool``), its validity-checking
    resolution to ``checker.resolution`` (as :func:`~ctrplan.planning.plan_leg` does) and its motion
    validator to a :class:`BatchMotionValidator`. Call before ``si.setup()``. The validator is
    kept referenced by ``si`` (an attribute of its Python object) and by ``checker``, so it
    lives as long as either.

    Parameters
    ----------
    si : ob.SpaceInformation
        Built on ``joint_space.space``, not yet set up.
    joint_space : JointStateSpace
    checker : BatchValidityChecker

    Returns
    -------
    BatchMotionValidator
    """
    si.setStateValidityChecker(lambda s: checker(joint_space.to_numpy(s)))
    extent = joint_space.space.getMaximumExtent()
    si.setStateValidityCheckingResolution(min(1.0, checker.resolution / extent))
    mv = BatchMotionValidator(si, joint_space, checker)
    si.setMotionValidator(mv)
    si._ctrplan_motion_validator = mv
    checker._motion_validators.append(mv)
    return mv
