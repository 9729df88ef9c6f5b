"""The obstacle interface (:class:`Obstacle`), the field types of its schemas and shared geometry."""

from __future__ import annotations

from abc import abstractmethod
from typing import Annotated, Mapping

import numpy as np
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer

__all__ = ["Obstacle", "Vector3", "PositiveFloat", "DRAWING_RESOLUTION", "rotation_from_rpy", "rotation_z_to",
           "convex_triangles"]

#: Points per great circle of a curved surface drawn by :meth:`Obstacle.triangles` when the
#: caller gives no resolution.
DRAWING_RESOLUTION = 24

# A direction within this of +-z (cosine distance) gets the identity or the half-turn about x
# in rotation_z_to (and in ctrplan.planning.collision._capsule_poses, which imports it).
AXIS_PARALLEL_TOL = 1e-12


def _as_list(value):
    """Let a tuple or an ndarray through a strict ``list`` schema (TOML gives lists already)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return value


def _as_tuple(value):
    """A validated list (of lists) stored as a tuple (of tuples): hashable, read-only."""
    return tuple(_as_tuple(v) if isinstance(v, list) else v for v in value)


def _as_plain_list(value):
    """A stored tuple (of tuples) dumped as a list (of lists), as a file or JSON holds it."""
    return [_as_plain_list(v) if isinstance(v, tuple) else v for v in value]


# Validation of a list field of an obstacle schema, appended to its Annotated list type after the
# Field constraints (which keeps pydantic's messages about lengths): a tuple or an array is let
# through the strict list schema, the result is stored as a tuple and dumped as a list.
_AS_TUPLE = (BeforeValidator(_as_list), AfterValidator(_as_tuple), PlainSerializer(_as_plain_list, return_type=list))

#: Field type of a 3-vector in an obstacle schema: three finite numbers (a list in a file; a
#: list, tuple or array in Python), stored as a tuple of float. The key's suffix names the
#: unit (``_m``, ``_rad``).
Vector3 = Annotated[list[float], Field(min_length=3, max_length=3), *_AS_TUPLE]

#: Field type of a length or a factor in an obstacle schema: a finite number > 0.
PositiveFloat = Annotated[float, Field(gt=0.0)]


class Obstacle(BaseModel):
    """Base class of the obstacle types: a schema, a collision object, a box and a drawing.

    A subclass is a frozen pydantic model whose fields are the keys of its ``[[obstacles]]``
    table in a scenario file (SI units, the unit in the key's suffix) plus a field
    ``type: Literal["<name>"] = "<name>"``; :func:`~ctrplan.obstacles.register_obstacle_type`
    makes ``type = "<name>"`` known to scenario files, dicts, the collision checker and both
    drawings. Unknown keys, missing keys, wrong types and non-finite numbers are errors (strict
    validation); a scenario file reports them as a :class:`~ctrplan.errors.ModelFileError`
    naming the file, the dotted key (``obstacles[2].radius_m``) and the value. Construct with
    keywords: ``Sphere(center_m=(0.0, 0.0, 0.1), radius_m=0.005)``.

    Everything is in the robot base frame [m]. A subclass implements :meth:`collision_object`,
    :meth:`aabb` and :meth:`triangles`.

    Raises
    ------
    pydantic.ValidationError
        (A ``ValueError``.) A field is missing, unknown or has a bad value.
    TypeError
        Positional arguments, or a subclass that leaves an abstract method out.
    """

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)

    @abstractmethod
    def collision_object(self):
        """The obstacle as a python-fcl collision object.

        Returns
        -------
        fcl.CollisionObject
            Its geometry (``fcl.Sphere``, ``fcl.Box``, ``fcl.Cylinder``, ``fcl.BVHModel``, ...)
            placed by an ``fcl.Transform`` (rotation shape (3, 3), translation shape (3,) [m]) in
            the robot base frame.
        """

    @abstractmethod
    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box containing the obstacle, in the robot base frame.

        The collision checker's broad phase culls the body capsules outside this box (inflated
        by :data:`ctrplan.planning.collision.AABB_MARGIN`): a box that misses part of the
        obstacle lets bodies through it. A larger box is safe, only slower.

        Returns
        -------
        lo, hi : ndarray, shape (3,)
            Lowest and highest corner [m].
        """

    @abstractmethod
    def triangles(self, resolution: int = DRAWING_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
        """The obstacle's surface as triangles, for drawing (plotly and matplotlib).

        Parameters
        ----------
        resolution : int
            Points per great circle of a curved surface; flat surfaces ignore it.

        Returns
        -------
        vertices : ndarray, shape (V, 3)
            In the robot base frame [m].
        faces : ndarray of int, shape (F, 3)
            Vertex indices of each triangle.
        """

    def input_files(self) -> tuple[str, ...]:
        """The files the obstacle is read from (none for a shape given by its keys).

        Stored plans of a scenario are keyed by these files' bytes besides the scenario's and
        the robot file's (:func:`ctrplan.studies.input_key`); a type that reads a file returns it.

        Returns
        -------
        tuple of str
            Paths, as the obstacle resolved them.
        """
        return ()

    def as_dict(self) -> dict:
        """Plain dict with the scenario file's keys, ``type`` included (JSON types: lists, str).

        Returns
        -------
        dict
            Input of :func:`~ctrplan.obstacles.obstacle_from_dict`, which gives back an equal
            obstacle.
        """
        return self.model_dump(mode="json")

    @classmethod
    def from_dict(cls, d: Mapping) -> "Obstacle":
        """Validate a dict with this type's keys (and its ``type``) into an obstacle.

        :func:`~ctrplan.obstacles.obstacle_from_dict` calls it on the class its ``type`` names; a
        subclass may override it to accept older spellings of its keys.

        Parameters
        ----------
        d : mapping
            The keys of the type's scenario table; vectors as lists, tuples or arrays.

        Returns
        -------
        Obstacle

        Raises
        ------
        pydantic.ValidationError
            A key is missing, unknown or has a bad value.
        """
        return cls.model_validate(dict(d))


# ---------------------------------------------------------------------------------- geometry
def rotation_from_rpy(rpy) -> np.ndarray:
    """Rotation matrix from roll, pitch, yaw (fixed x, then y, then z axes: ``Rz @ Ry @ Rx``).

    Parameters
    ----------
    rpy : array-like, shape (3,)
        Roll, pitch, yaw [rad].

    Returns
    -------
    ndarray, shape (3, 3)
        Obstacle-to-base rotation.
    """
    r, p, y = np.asarray(rpy, dtype=float).reshape(3)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def rotation_z_to(direction) -> np.ndarray:
    """Rotation taking +z onto the direction of ``direction`` (the smallest such rotation).

    FCL's capsules and cylinders lie along their local z axis, centred at the origin; this
    rotation and the segment's midpoint place one along a segment.

    Parameters
    ----------
    direction : array-like, shape (3,)
        Any non-zero length [m or -].

    Returns
    -------
    ndarray, shape (3, 3)
        ``I + [v]x + [v]x^2 / (1 + c)`` with ``v = z x d``, ``c = z . d`` for the unit vector
        ``d``; the identity within 1e-12 of +z, the half-turn about x within 1e-12 of -z.
    """
    z = np.array([0.0, 0.0, 1.0])
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    c = float(np.dot(z, d))
    if c > 1.0 - AXIS_PARALLEL_TOL:
        return np.eye(3)
    if c < -1.0 + AXIS_PARALLEL_TOL:
        return np.diag([1.0, -1.0, -1.0])
    v = np.cross(z, d)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def convex_triangles(points) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of the convex hull of ``points`` (a drawing of a convex obstacle from samples
    of its surface; scipy's Qhull).

    Parameters
    ----------
    points : array-like, shape (N, 3)
        Surface points [m], N >= 4, not all in one plane.

    Returns
    -------
    vertices : ndarray, shape (N, 3)
        ``points`` [m].
    faces : ndarray of int, shape (F, 3)
        Hull triangles; every edge is shared by exactly two of them.

    Raises
    ------
    ValueError
        Fewer than 4 points, or all in one plane.
    """
    from scipy.spatial import ConvexHull, QhullError

    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError) as exc:
        raise ValueError(f"no convex hull of {len(pts)} points: {str(exc).splitlines()[0]}") from None
    return pts, hull.simplices.astype(np.int64)
