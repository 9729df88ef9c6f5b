"""The robot as arrays for the compiled kernels (:class:`PackedRobot`, :func:`pack_robot`).

One packing shared by the standard shooting (``standard``), the batch solvers
(``_standard_batch``, ``_standard_bodies``), the grid builder (``grid``) and the contact problem
(``_contact_fast``). A robot is packed once and the result is cached on the (frozen, hashable)
:class:`~ctrplan.robot.Robot`, so a modified robot (``Robot.replace``) gets its own packing.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import PhysicalParameterError

__all__ = ["PackedRobot", "pack_robot"]

# Robots whose packings are kept (a process rarely uses more than a few robots at a time).
_CACHE_SIZE = 32


@dataclass(frozen=True, eq=False)
class PackedRobot:
    """A robot of n tubes (outermost first) as read-only arrays in SI units.

    Attributes
    ----------
    lengths : ndarray, shape (n,)
        Tube lengths [m] (``Tube.length``).
    breaks : ndarray, shape (n, B)
        Section breaks of each tube [m], tube-local: 0 at the tube's base, then the cumulative
        section lengths up to the tube length (``Tube.section_breaks``); zero-padded after
        ``n_breaks[i]`` entries. B is the largest number of sections plus one.
    n_breaks : ndarray of int64, shape (n,)
        Breaks of each tube (its number of sections plus one).
    precurvature : ndarray, shape (n, B - 1, 2)
        Precurvature (u_x, u_y) of each section [1/m] (the paper's uhat_i); zero-padded.
    k_xy : ndarray, shape (n,)
        Bending stiffness E I [N m^2].
    k_z : ndarray, shape (n,)
        Torsional stiffness G J = k_xy / (1 + nu) [N m^2] (``Tube.k_z``, Section II-C).
    stiffness_ratio : ndarray, shape (n,)
        k_xy / k_z [-], computed as that quotient (not as 1 + nu) so that the kernels see the
        same floating-point numbers as before the packing was shared.
    outer_radius : ndarray, shape (n,)
        Outer radius of each tube for collision checking [m] (``Robot.outer_radius``).
    clearance : ndarray, shape (n - 1,)
        Radial clearance c_i of each adjacent pair [m] (``Robot.clearances``, Eq. (15)).
    contact_radius_in, contact_radius_out : ndarray, shape (n - 1,)
        Radii at which friction acts on pair (i, i + 1): r_(i,in) and r_(i+1,out) [m]
        (``Robot.contact_radii``, Eq. (41)); NaN when the robot's diameters do not define them
        (only an error where friction acts, see :meth:`contact_radii`).
    friction : ndarray, shape (n - 1,)
        Coulomb friction coefficient mu of each pair [-] (``Robot.friction_coefficients``).
    """

    lengths: np.ndarray
    breaks: np.ndarray
    n_breaks: np.ndarray
    precurvature: np.ndarray
    k_xy: np.ndarray
    k_z: np.ndarray
    stiffness_ratio: np.ndarray
    outer_radius: np.ndarray
    clearance: np.ndarray
    contact_radius_in: np.ndarray
    contact_radius_out: np.ndarray
    friction: np.ndarray

    @property
    def n_tubes(self) -> int:
        return int(self.lengths.shape[0])

    def contact_radii(self, robot) -> tuple[np.ndarray, np.ndarray]:
        """(r_(i,in), r_(i+1,out)), shapes (n - 1,) [m], as ``robot.contact_radii()``.

        Raises
        ------
        PhysicalParameterError
            If a pair has no diameter to place its friction at (the error of
            ``Robot.contact_radii``, raised by calling it on ``robot``).
        """
        if np.any(np.isnan(self.contact_radius_in)):
            robot.contact_radii()   # raises, naming the pair
        return self.contact_radius_in, self.contact_radius_out


def pack_robot(robot) -> PackedRobot:
    """The robot's :class:`PackedRobot`, built on first use and cached per robot.

    Parameters
    ----------
    robot : Robot

    Returns
    -------
    PackedRobot
        Shared between calls: its arrays are read-only.

    Notes
    -----
    The cache is keyed on the robot's value (``Robot`` is a frozen dataclass: equal robots
    have equal tubes, clearances and friction), so ``robot.replace(...)`` with other parameters
    is packed anew. A robot that cannot be hashed is packed on every call.
    """
    try:
        return _cached(robot)
    except TypeError:   # unhashable field (e.g. a list in place of a tuple)
        return _pack(robot)


@lru_cache(maxsize=_CACHE_SIZE)
def _cached(robot) -> PackedRobot:
    return _pack(robot)


def _pack(robot) -> PackedRobot:
    """Build the arrays of :class:`PackedRobot` (same arithmetic as the four packings it replaces)."""
    tubes = robot.tubes
    n = len(tubes)
    nb = max(len(t.sections) + 1 for t in tubes)
    breaks = np.zeros((n, nb))
    curv = np.zeros((n, nb - 1, 2))
    nbrk = np.zeros(n, dtype=np.int64)
    for i, t in enumerate(tubes):
        b = t.section_breaks()
        breaks[i, :b.size] = b
        nbrk[i] = b.size
        curv[i, :len(t.sections)] = [sec.precurvature for sec in t.sections]
    try:
        r_in, r_out = robot.contact_radii()
    except PhysicalParameterError:
        r_in, r_out = np.full(n - 1, np.nan), np.full(n - 1, np.nan)
    arrays = dict(
        lengths=np.array([t.length for t in tubes]),
        breaks=breaks,
        n_breaks=nbrk,
        precurvature=curv,
        k_xy=np.array([t.k_xy for t in tubes]),
        k_z=np.array([t.k_z for t in tubes]),
        stiffness_ratio=np.array([t.k_xy / t.k_z for t in tubes]),
        outer_radius=np.array([robot.outer_radius(i) for i in range(n)]),
        clearance=np.array(robot.clearances, dtype=float),
        contact_radius_in=np.array(r_in, dtype=float),
        contact_radius_out=np.array(r_out, dtype=float),
        friction=np.array(robot.friction_coefficients, dtype=float),
    )
    for a in arrays.values():
        a.setflags(write=False)
    return PackedRobot(**arrays)
