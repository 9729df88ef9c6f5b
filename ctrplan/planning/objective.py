"""OMPL optimization objective: joint-space length plus the integrated friction bound.

For a straight joint-space motion :math:`q(\\lambda)` of weighted length :math:`L` (the metric
of :class:`~ctrplan.planning.space.JointStateSpace`, [m]) the motion cost is

.. math:: c = L + w \\int_0^L b(q(\\ell))\\, d\\ell ,

with :math:`b` the friction bound on the tip position (Section III of Ha, Fagogenis & Dupont
2019, doi:10.1109/TRO.2018.2878906) interpolated from a :class:`~ctrplan.planning.BoundField`
[m], and :math:`w` = ``bound_weight`` [1/m]. The integral is the trapezoid rule on samples spaced
at most ``sample_spacing`` apart along the segment. With ``bound_weight = 0`` the objective is
the plain weighted path length (the bound-blind baseline with identical metric).

Following the project's OMPL notes this subclasses ``ob.OptimizationObjective`` directly (a
Python ``StateCostIntegralObjective`` subclass is ignored by the planners) and caches b(q) per
state and the cost per motion, since RRT* re-evaluates the same few hundred states ~10^5 times.
With a :class:`~ctrplan.boundmap.BoundField` as the bound (or with weight 0), a motion's cost
(metric, samples, interpolation, trapezoid rule) is one compiled call (:func:`_segment_cost`,
4-6 us against 120-150 us for the same steps in numpy, equal to 1e-15), cheaper than the cache
lookup, so those motions are not cached (RRT* asked for 157 000 motion costs in 600 iterations
of the obstacles scenario, 0.4 % of them twice); any other bound callable goes through numpy
and the caches.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from ompl import base as ob

from ..boundmap.interp import corner_sum, locate


__all__ = ["BoundCostObjective", "motion_cost_kernel", "DEFAULT_BOUND_WEIGHT", "DEFAULT_SAMPLE_SPACING"]

# Cost weight of the integrated bound [1/m]: with 1000 /m, moving through a region with a 1 mm
# tip-error bound costs twice as much per unit length as moving where the bound is zero.
DEFAULT_BOUND_WEIGHT = 1000.0

# Largest spacing of bound samples along a motion [m of the weighted joint metric]; about a
# third of a grid cell of a 24 x 24 x 8 field on the paper's robot (0.02 m/rad x 2 pi / 24).
DEFAULT_SAMPLE_SPACING = 2e-3

# Cost of the bound where the field is invalid [m] (finite so that OMPL's cost arithmetic stays
# well defined; such states are also rejected by the validity checker).
DEFAULT_INVALID_PENALTY = 1.0


@njit(cache=True)
def _segment_cost(q0, q1, periodic, weights, is_rotation, spacing, weight, penalty, matrix, offset, axes, start, size,
                  periodic_u, strides, values, valid, column, eps):
    """Compiled :meth:`BoundCostObjective.segment_cost` with a bound map: weighted length L of
    the straight motion (short way round periodic joints), then L + w * trapezoid integral of the
    map's bound at m + 1 equally spaced samples, m = ceil(L / spacing); invalid or non-finite
    values count as ``penalty``. The interpolation is that of the map
    (:mod:`ctrplan.boundmap.interp`), with the work arrays allocated once per motion. Returns
    (cost, number of bound samples)."""
    n = q0.shape[0]
    dq = np.empty(n)
    rot = 0.0
    tr = 0.0
    for j in range(n):
        x = q1[j] - q0[j]
        if periodic[j]:
            x = (x + np.pi) % (2.0 * np.pi) - np.pi
        dq[j] = x
        if is_rotation[j]:
            rot += abs(x) * weights[j]
        else:
            tr += x * x
    length = rot + np.sqrt(tr)
    if weight == 0.0 or length == 0.0:
        return length, 0
    m = max(1, int(np.ceil(length / spacing)))
    d = matrix.shape[0]
    # map coordinates are affine in t: u(t) = u0 + t du
    u0 = np.empty(d)
    du = np.empty(d)
    for i in range(d):
        a = offset[i]
        b = 0.0
        for j in range(n):
            a += matrix[i, j] * q0[j]
            b += matrix[i, j] * dq[j]
        u0[i] = a
        du[i] = b
    lo = np.empty(d, dtype=np.int64)
    hi = np.empty(d, dtype=np.int64)
    tt = np.empty(d)
    u = np.empty(d)
    acc = 0.0
    for k in range(m + 1):
        t = k / m
        for i in range(d):
            u[i] = u0[i] + t * du[i]
        locate(u, axes, start, size, periodic_u, lo, hi, tt)
        b, ok = corner_sum(lo, hi, tt, strides, values, valid, column, eps)
        if not ok or not np.isfinite(b):
            b = penalty
        acc += 0.5 * b if (k == 0 or k == m) else b
    return length + weight * length * acc / m, m + 1


def motion_cost_kernel(joint_space, bound, bound_weight: float, sample_spacing: float = DEFAULT_SAMPLE_SPACING,
                       invalid_penalty: float = DEFAULT_INVALID_PENALTY, quantity: str = "position"):
    """The arguments after ``q0, q1`` of the compiled motion cost :func:`_segment_cost`, or None
    when the bound is neither a bound map (anything with ``kernel_arrays``) nor weighted 0.

    ``_segment_cost(q0, q1, *motion_cost_kernel(...))`` returns ``(cost [m], bound samples)``: the
    cost ``L + w integral(b) dl`` of the straight motion, as :class:`BoundCostObjective` and the
    roadmap (:mod:`ctrplan.planning.roadmap`) use it.

    Parameters
    ----------
    joint_space : JointStateSpace
    bound : BoundField or None
    bound_weight : float
        w [1/m].
    sample_spacing : float
        Largest spacing of bound samples along a motion [m].
    invalid_penalty : float
        Bound where the map is invalid [m].
    quantity : str
        The map's quantity integrated (``"position"``: the friction bound; the roadmap also
        integrates ``"translation_last_position"`` along translations).

    Returns
    -------
    tuple or None
    """
    js = joint_space
    head = (np.ascontiguousarray(js.periodic), np.ascontiguousarray(js.weights, dtype=float),
            np.ascontiguousarray(js.is_rotation), float(sample_spacing), float(bound_weight), float(invalid_penalty))
    if bound_weight > 0.0 and hasattr(bound, "kernel_arrays"):
        return head + tuple(bound.kernel_arrays(quantity))
    if bound_weight == 0.0:   # never reads the map arrays
        n = len(js.periodic)
        return head + (np.zeros((0, n)), np.zeros(0), np.zeros(0), np.zeros(0, np.int64),
                       np.zeros(0, np.int64), np.zeros(0, np.bool_), np.zeros(0, np.int64),
                       np.zeros((0, 1)), np.zeros(0, np.bool_), 0, 0.0)
    return None


class BoundCostObjective(ob.OptimizationObjective):
    """Weighted joint-space length plus ``bound_weight`` x integral of the bound.

    Parameters
    ----------
    si : ob.SpaceInformation
        Built on ``joint_space.space``.
    joint_space : JointStateSpace
    bound : callable or None
        ``bound(q (m, n_joints)) -> (m,)`` [m], e.g. a :class:`BoundField` (its ``position``
        quantity). Non-finite values are replaced by ``invalid_penalty``. None only with
        ``bound_weight = 0``.
    bound_weight : float, keyword-only
        w [1/m], >= 0.
    sample_spacing : float, keyword-only
        Largest spacing of bound samples along a motion [m].
    invalid_penalty : float, keyword-only
        Bound used where ``bound`` is not finite [m].

    Attributes
    ----------
    n_bound_evaluations : int
        Bound values interpolated (state cache misses plus samples inside motions).
    n_motion_calls : int
        ``motionCost`` calls (cached or not).

    Raises
    ------
    ValueError
        Negative weight, non-positive spacing, or a positive weight without ``bound``.
    """

    def __init__(self, si, joint_space, bound=None, *, bound_weight: float = DEFAULT_BOUND_WEIGHT,
                 sample_spacing: float = DEFAULT_SAMPLE_SPACING,
                 invalid_penalty: float = DEFAULT_INVALID_PENALTY):
        super().__init__(si)
        if not np.isfinite(bound_weight) or bound_weight < 0.0:
            raise ValueError(f"bound_weight must be >= 0 [1/m], got {bound_weight!r}")
        if bound_weight > 0.0 and bound is None:
            raise ValueError("a positive bound_weight needs a bound function (e.g. a BoundField)")
        if not np.isfinite(sample_spacing) or sample_spacing <= 0.0:
            raise ValueError(f"sample_spacing must be > 0 m, got {sample_spacing!r}")
        self._si = si
        self.joint_space = joint_space
        self.bound = bound
        self.bound_weight = float(bound_weight)
        self.sample_spacing = float(sample_spacing)
        self.invalid_penalty = float(invalid_penalty)
        self._state_cache: dict[bytes, float] = {}
        self._motion_cache: dict[tuple[bytes, bytes], float] = {}
        self.n_bound_evaluations = 0
        self.n_motion_calls = 0
        # compiled motion cost: with a BoundField, or for the plain length (weight 0)
        self._kernel = motion_cost_kernel(joint_space, bound, self.bound_weight, self.sample_spacing,
                                          self.invalid_penalty)

    @classmethod
    def factory(cls, bound=None, **kwargs):
        """A ``(si, joint_space) -> BoundCostObjective`` callable for :func:`~ctrplan.planning.plan_leg`."""
        def make(si, joint_space):
            return cls(si, joint_space, bound, **kwargs)
        return make

    # ------------------------------------------------------------------ numpy core
    def bound_values(self, q) -> np.ndarray:
        """Bound at joint vectors with invalid values replaced by the penalty.

        Parameters
        ----------
        q : ndarray, shape (m, n_joints)
            [rad or m]

        Returns
        -------
        ndarray, shape (m,)
            [m]
        """
        if self.bound is None:
            return np.zeros(len(q))
        b = np.asarray(self.bound(np.atleast_2d(q)), dtype=float).reshape(-1)
        self.n_bound_evaluations += len(b)
        return np.where(np.isfinite(b), b, self.invalid_penalty)

    def state_bound(self, q) -> float:
        """Cached bound of one joint vector ``q`` (shape (n_joints,)) [m]."""
        q = np.asarray(q, dtype=float)
        k = q.tobytes()
        v = self._state_cache.get(k)
        if v is None:
            v = float(self.bound_values(q[None, :])[0])
            self._state_cache[k] = v
        return v

    def segment_cost(self, q0, q1) -> float:
        """Motion cost of the straight segment ``q0 -> q1`` (shapes (n_joints,)) [m]."""
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        if self._kernel is not None:
            cost, m = _segment_cost(q0, q1, *self._kernel)
            self.n_bound_evaluations += m
            return float(cost)
        length = float(self.joint_space.distance(q0, q1))
        if self.bound_weight == 0.0 or length == 0.0:
            return length
        m = max(1, int(np.ceil(length / self.sample_spacing)))
        b = np.empty(m + 1)
        b[0] = self.state_bound(q0)
        b[-1] = self.state_bound(q1)
        if m > 1:
            b[1:-1] = self.bound_values(self.joint_space.interpolate(q0, q1, np.arange(1, m) / m))
        integral = length * (0.5 * (b[0] + b[-1]) + b[1:-1].sum()) / m
        return length + self.bound_weight * integral

    def path_cost(self, waypoints) -> float:
        """Cost of a piecewise-straight path, shape (K, n_joints) [rad or m] -> [m]."""
        w = np.asarray(waypoints, dtype=float)
        return float(sum(self.segment_cost(a, b) for a, b in zip(w[:-1], w[1:])))

    # ------------------------------------------------------------------ OMPL overrides
    def stateCost(self, s):
        return ob.Cost(self.state_bound(self.joint_space.to_numpy(s)))

    def motionCost(self, s1, s2):
        q0 = self.joint_space.to_numpy(s1)
        q1 = self.joint_space.to_numpy(s2)
        if self._kernel is not None:   # a few us: cheaper than a cache lookup
            self.n_motion_calls += 1
            cost, m = _segment_cost(q0, q1, *self._kernel)
            self.n_bound_evaluations += m
            return ob.Cost(cost)
        k0, k1 = q0.tobytes(), q1.tobytes()
        key = (k0, k1) if k0 <= k1 else (k1, k0)  # the segment cost is symmetric
        self.n_motion_calls += 1
        c = self._motion_cache.get(key)
        if c is None:
            c = self.segment_cost(q0, q1)
            self._motion_cache[key] = c
        return ob.Cost(c)

    def motionCostHeuristic(self, s1, s2):
        # admissible: the bound integral is >= 0
        return ob.Cost(self._si.distance(s1, s2))

    def clear_cache(self) -> None:
        """Forget cached state bounds and motion costs (after changing the bound)."""
        self._state_cache.clear()
        self._motion_cache.clear()
