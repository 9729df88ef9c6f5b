"""Where a bound map's nodes lie along each map coordinate.

A map is a tensor grid over the map coordinates (:mod:`ctrplan.coordinates`):

- a **periodic** rotation coordinate has ``n`` uniform nodes ``-pi + 2 pi k / n``,
  ``k = 0..n-1`` (no duplicated endpoint; interpolation wraps round);
- a **bounded** coordinate (a translation, or a rotation with limits narrower than 2 pi) has
  ``n`` nodes from its lower to its upper end, inclusive: uniform (``placement="uniform"``), or
  placed where the bound bends (``placement="adaptive"``).

Why adaptive placement. Along the translations the bound is smooth over most of the range but
changes within millimetres where the precurved section of an inner tube passes the end of an
outer tube (the contact set changes there): along a line of the six-joint robot of Table II it
falls from 20 mm to 2.4 mm over the last 10 mm of ``beta_3``, and along one of the calibrated
robot of Table VII it peaks at 9.7 mm 10 mm before the end of the ``beta_3`` range and falls to
3.3 mm at that end (exact model; ``docs/boundmaps.md``). The former uniform map, with nodes every
14 mm there, was off by up to 2.2 mm. Adaptive placement evaluates the exact bound along a few
**pilot lines** parallel to the coordinate (the other coordinates at random joint
configurations, seeded), at a fine step, and inserts nodes greedily where linear interpolation
through the nodes so far misses the pilot values most (:func:`place_nodes`). The nodes are a
deterministic function of the robot, the model settings and the spec, so a map's key is known
before it is computed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..choices import JointKind, MapPlacement

__all__ = ["MapSpec", "PLACEMENTS", "uniform_axis", "place_nodes", "pilot_design", "DEFAULT_PILOT_LINES",
           "DEFAULT_PILOT_STEP_M", "DEFAULT_PILOT_STEP_RAD"]

#: Node placements along a bounded coordinate (``MapSpec.placement``).
PLACEMENTS = tuple(MapPlacement)

# Pilot lines per adaptive coordinate: enough different positions of the other coordinates for
# the kinks of the bound (whose positions move with them) to show, few enough that the pilots
# cost a few percent of a map (6 lines x 81 points on the six-joint robot's beta_3 - beta_1).
DEFAULT_PILOT_LINES = 6
# Spacing of pilot samples along a translation coordinate [m]: below the ~2 mm width of the
# steepest transitions seen (docs/boundmaps.md).
DEFAULT_PILOT_STEP_M = 1e-3
# Spacing of pilot samples along a bounded rotation coordinate [rad] (1.1 deg).
DEFAULT_PILOT_STEP_RAD = 0.02
# Seed of the pilot lines' positions in the other coordinates.
DEFAULT_PILOT_SEED = 0

# Among abscissae with equal interpolation error, prefer the one farthest from any node
# (weight of that distance in the greedy score [m of error per m or rad of coordinate]).
_TIE_BREAK = 1e-9


@dataclass(frozen=True)
class MapSpec:
    """How to lay out a bound map's grid.

    Parameters
    ----------
    resolution : tuple of int, shape (d,)
        Nodes per map coordinate (>= 2), in the order of
        :attr:`~ctrplan.coordinates.MapCoordinates.names`.
    placement : MapPlacement or str
        Node placement along bounded coordinates, ``"uniform"`` or ``"adaptive"`` (periodic ones
        are always uniform); stored as the member.
    pilot_lines : int, keyword-only
        Pilot lines per adaptive coordinate.
    pilot_step_m, pilot_step_rad : float, keyword-only
        Pilot sample spacing along translation [m] and bounded rotation [rad] coordinates.
    pilot_seed : int, keyword-only
        Seed of the pilot lines' positions.

    Raises
    ------
    ValueError
        Resolution below 2, unknown placement, non-positive pilot settings.
    """

    resolution: tuple
    placement: MapPlacement = MapPlacement.UNIFORM
    pilot_lines: int = DEFAULT_PILOT_LINES
    pilot_step_m: float = DEFAULT_PILOT_STEP_M
    pilot_step_rad: float = DEFAULT_PILOT_STEP_RAD
    pilot_seed: int = DEFAULT_PILOT_SEED

    def __post_init__(self):
        res = tuple(int(n) for n in np.atleast_1d(self.resolution))
        object.__setattr__(self, "resolution", res)
        if any(n < 2 for n in res):
            raise ValueError(f"resolution must be >= 2 nodes per map coordinate, got {self.resolution!r}")
        if self.placement not in PLACEMENTS:
            raise ValueError(f"placement must be one of {', '.join(PLACEMENTS)}, got {self.placement!r}")
        object.__setattr__(self, "placement", MapPlacement(self.placement))
        if int(self.pilot_lines) < 1 or not self.pilot_step_m > 0 or not self.pilot_step_rad > 0:
            raise ValueError(f"pilot settings must be positive: lines {self.pilot_lines!r}, "
                             f"steps {self.pilot_step_m!r} m, {self.pilot_step_rad!r} rad")

    def for_coordinates(self, coords) -> "MapSpec":
        """Check the resolution against a robot's map coordinates; a single number applies to all.

        Raises
        ------
        ValueError
            Wrong number of values, naming the coordinates.
        """
        res = self.resolution
        if len(res) == 1 and coords.dim != 1:
            res = res * coords.dim
        if len(res) != coords.dim:
            raise ValueError(f"resolution needs 1 or {coords.dim} values, one per map coordinate "
                             f"({', '.join(coords.names)}), got {self.resolution!r}")
        return MapSpec(res, self.placement, pilot_lines=self.pilot_lines, pilot_step_m=self.pilot_step_m,
                       pilot_step_rad=self.pilot_step_rad, pilot_seed=self.pilot_seed)

    def as_dict(self) -> dict:
        """JSON-ready (part of a map's identity)."""
        d = {"resolution": list(self.resolution), "placement": self.placement.value}
        if self.placement == MapPlacement.ADAPTIVE:
            d.update(pilot_lines=int(self.pilot_lines), pilot_step_m=float(self.pilot_step_m),
                     pilot_step_rad=float(self.pilot_step_rad), pilot_seed=int(self.pilot_seed))
        return d

    def adaptive(self, coords) -> list[int]:
        """Indices of the coordinates whose nodes come from pilot lines."""
        if self.placement != MapPlacement.ADAPTIVE:
            return []
        return [k for k in range(coords.dim) if not coords.periodic[k]]


def uniform_axis(lower: float, upper: float, n: int, periodic: bool) -> np.ndarray:
    """Uniform nodes of one coordinate.

    Parameters
    ----------
    lower, upper : float
        Range [rad or m].
    n : int
        Nodes (>= 2).
    periodic : bool
        ``lower + 2 pi k / n`` (k < n) instead of ``linspace(lower, upper, n)``.

    Returns
    -------
    ndarray, shape (n,)
    """
    if periodic:
        return lower + 2.0 * np.pi * np.arange(n) / n
    return np.linspace(lower, upper, n)


def pilot_design(coords, robot, spec: MapSpec, k: int):
    """Pilot lines of adaptive coordinate ``k``: abscissae and line positions.

    Each line holds the other coordinates at the map coordinates of a joint vector drawn
    uniformly from the joint box (seeded by ``spec.pilot_seed`` and ``k``), so the lines cover
    the region the planner queries.

    Parameters
    ----------
    coords : MapCoordinates
    robot : Robot
    spec : MapSpec
    k : int
        Coordinate index (not periodic).

    Returns
    -------
    x : ndarray, shape (m,)
        Abscissae from the coordinate's lower to its upper end, spacing at most the pilot step
        [rad or m].
    points : ndarray, shape (L, m, d)
        Map coordinates of every pilot sample (L = ``spec.pilot_lines``).
    """
    lo, hi = coords.lower[k], coords.upper[k]
    step = spec.pilot_step_m if coords.kinds[k] == JointKind.TRANSLATION else spec.pilot_step_rad
    m = max(2, int(np.ceil((hi - lo) / step - 1e-9)) + 1)
    x = np.linspace(lo, hi, m)
    rng = np.random.default_rng([int(spec.pilot_seed), int(k)])
    q = robot.joint_lower + rng.random((int(spec.pilot_lines), len(robot.joints))) * (robot.joint_upper
                                                                                       - robot.joint_lower)
    base = coords.from_joints(q)
    points = np.repeat(base[:, None, :], m, axis=1)
    points[:, :, k] = x[None, :]
    return x, points


def place_nodes(x, values, n: int) -> np.ndarray:
    """Greedy node placement from pilot samples.

    Starts from both ends and repeatedly adds the pilot abscissa where piecewise-linear
    interpolation through the nodes so far misses the pilot values most (mean absolute miss
    over the lines, NaN samples ignored), until ``n`` nodes.

    Parameters
    ----------
    x : array-like, shape (m,)
        Increasing pilot abscissae [rad or m].
    values : array-like, shape (L, m)
        Pilot values of the quantity to resolve (the friction bound [m]) per line; NaN where the
        model failed.
    n : int
        Nodes wanted, 2 <= n <= m.

    Returns
    -------
    ndarray, shape (n,)
        Increasing node abscissae, a subset of ``x`` with both ends.

    Raises
    ------
    ValueError
        ``n`` outside [2, m] or shapes that do not match.
    """
    x = np.asarray(x, dtype=float)
    v = np.atleast_2d(np.asarray(values, dtype=float))
    m = x.size
    if v.shape[1] != m:
        raise ValueError(f"values need shape (L, {m}), got {v.shape}")
    if not 2 <= int(n) <= m:
        raise ValueError(f"cannot place {n} nodes on {m} pilot abscissae (need 2 <= n <= {m})")
    chosen = np.zeros(m, dtype=bool)
    chosen[[0, m - 1]] = True
    while chosen.sum() < n:
        err = np.zeros(m)
        count = np.zeros(m)
        for line in v:
            ok = np.isfinite(line)
            nodes = chosen & ok
            if nodes.sum() < 2:
                continue
            fit = np.interp(x, x[nodes], line[nodes])
            e = np.abs(fit - line)
            err += np.where(ok, e, 0.0)
            count += ok
        mean = np.where(count > 0, err / np.maximum(count, 1), 0.0)
        idx = np.flatnonzero(chosen)
        gap = np.min(np.abs(x[:, None] - x[idx][None, :]), axis=1)
        score = np.where(chosen, -np.inf, mean + _TIE_BREAK * gap)
        chosen[int(np.argmax(score))] = True
    return x[chosen]
