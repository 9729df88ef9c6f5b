"""The built-in obstacle types: sphere, capsule, box, mesh file, inline triangles."""

from __future__ import annotations

import os
from functools import cached_property
from pathlib import Path
from typing import Annotated, Literal, Mapping

import numpy as np
from pydantic import AfterValidator, BeforeValidator, Field, PlainSerializer, ValidationInfo, field_validator

from ._base import _AS_TUPLE, DRAWING_RESOLUTION, Obstacle, PositiveFloat, Vector3, convex_triangles, \
    rotation_from_rpy, rotation_z_to
from ._registry import register_obstacle_type

__all__ = ["Sphere", "Capsule", "Box", "Mesh", "Triangles"]

# Corners of the unit box centred at the origin (index 4 ix + 2 iy + iz) and its 12 triangles,
# two per face.
_BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
_BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                       [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=np.int64)


def _unit_ball(resolution: int) -> np.ndarray:
    """Points of the unit sphere, shape (N, 3): ``resolution`` meridians, ``resolution // 2 + 1``
    parallels, the poles once."""
    u = np.linspace(0.0, 2 * np.pi, resolution, endpoint=False)
    v = np.linspace(0.0, np.pi, resolution // 2 + 1)
    ball = np.stack([np.outer(np.sin(v), np.cos(u)), np.outer(np.sin(v), np.sin(u)),
                     np.outer(np.cos(v), np.ones_like(u))], axis=-1).reshape(-1, 3)
    return np.unique(np.round(ball, 12), axis=0)          # the poles repeat along u


def _bvh_object(vertices: np.ndarray, faces: np.ndarray):
    """python-fcl triangle mesh (``BVHModel``) at the identity pose; vertices (V, 3) [m]."""
    import fcl

    model = fcl.BVHModel()
    model.beginModel(len(vertices), len(faces))
    model.addSubModel(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64))
    model.endModel()
    return fcl.CollisionObject(model, fcl.Transform())


@register_obstacle_type
class Sphere(Obstacle):
    """Sphere obstacle (scenario table ``type = "sphere"``).

    Attributes
    ----------
    center_m : tuple of float, shape (3,)
        Centre [m].
    radius_m : float
        Radius [m], > 0.
    """

    type: Literal["sphere"] = "sphere"
    center_m: Vector3
    radius_m: PositiveFloat

    def collision_object(self):
        """``fcl.Sphere`` at the centre (see :meth:`Obstacle.collision_object`)."""
        import fcl

        return fcl.CollisionObject(fcl.Sphere(self.radius_m), fcl.Transform(np.eye(3), np.array(self.center_m)))

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre -/+ radius, each shape (3,) [m] (see :meth:`Obstacle.aabb`)."""
        c = np.array(self.center_m)
        return c - self.radius_m, c + self.radius_m

    def triangles(self, resolution: int = DRAWING_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
        """Convex hull of ``resolution`` meridians by ``resolution // 2 + 1`` parallels: vertices
        (V, 3) [m] on the sphere, faces (F, 3) (see :meth:`Obstacle.triangles`)."""
        return convex_triangles(np.array(self.center_m) + self.radius_m * _unit_ball(resolution))


@register_obstacle_type
class Capsule(Obstacle):
    """Capsule obstacle: the segment from ``a_m`` to ``b_m`` swept by a ball (``type = "capsule"``).

    Attributes
    ----------
    a_m, b_m : tuple of float, shape (3,)
        Ends of the segment [m] (equal ends: a sphere).
    radius_m : float
        Radius [m], > 0.
    """

    type: Literal["capsule"] = "capsule"
    a_m: Vector3
    b_m: Vector3
    radius_m: PositiveFloat

    def _frame(self) -> tuple[np.ndarray, float]:
        """Rotation taking +z along a -> b (identity for equal ends), and the length [m]."""
        d = np.array(self.b_m) - np.array(self.a_m)
        length = float(np.linalg.norm(d))
        return (rotation_z_to(d) if length > 0.0 else np.eye(3)), length

    def collision_object(self):
        """``fcl.Capsule`` along the segment, centred at its midpoint (see
        :meth:`Obstacle.collision_object`)."""
        import fcl

        rot, length = self._frame()
        mid = 0.5 * (np.array(self.a_m) + np.array(self.b_m))
        return fcl.CollisionObject(fcl.Capsule(self.radius_m, length), fcl.Transform(rot, mid))

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Box of the segment, -/+ radius: each shape (3,) [m] (see :meth:`Obstacle.aabb`)."""
        a, b = np.array(self.a_m), np.array(self.b_m)
        return np.minimum(a, b) - self.radius_m, np.maximum(a, b) + self.radius_m

    def triangles(self, resolution: int = DRAWING_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
        """Convex hull of the two hemispherical caps (sampled as :meth:`Sphere.triangles`):
        vertices (V, 3) [m], faces (F, 3) (see :meth:`Obstacle.triangles`)."""
        rot, length = self._frame()
        ball = self.radius_m * _unit_ball(resolution)
        local = np.concatenate([ball[ball[:, 2] <= 0], ball[ball[:, 2] >= 0] + [0.0, 0.0, length]])
        return convex_triangles(local @ rot.T + np.array(self.a_m))


@register_obstacle_type
class Box(Obstacle):
    """Box obstacle (``type = "box"``).

    Attributes
    ----------
    center_m : tuple of float, shape (3,)
        Centre [m].
    size_m : tuple of float, shape (3,)
        Edge lengths along the box's own x, y, z axes [m], each > 0.
    rpy_rad : tuple of float, shape (3,)
        Roll, pitch, yaw [rad] (default 0): box-to-base rotation ``Rz(yaw) Ry(pitch) Rx(roll)``
        (:func:`~ctrplan.obstacles.rotation_from_rpy`).
    """

    type: Literal["box"] = "box"
    center_m: Vector3
    size_m: Annotated[list[PositiveFloat], Field(min_length=3, max_length=3), *_AS_TUPLE]
    rpy_rad: Vector3 = (0.0, 0.0, 0.0)

    def collision_object(self):
        """``fcl.Box`` rotated by ``rpy_rad`` about its centre (see :meth:`Obstacle.collision_object`)."""
        import fcl

        return fcl.CollisionObject(fcl.Box(*self.size_m),
                                   fcl.Transform(rotation_from_rpy(self.rpy_rad), np.array(self.center_m)))

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre -/+ ``|R| size / 2``, each shape (3,) [m]: the box of the rotated corners (see
        :meth:`Obstacle.aabb`)."""
        c = np.array(self.center_m)
        half = np.abs(rotation_from_rpy(self.rpy_rad)) @ (0.5 * np.array(self.size_m))
        return c - half, c + half

    def triangles(self, resolution: int = DRAWING_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
        """The 8 corners (V = 8) [m] and 12 triangles, two per face (see :meth:`Obstacle.triangles`)."""
        verts = (_BOX_CORNERS * np.array(self.size_m)) @ rotation_from_rpy(self.rpy_rad).T + np.array(self.center_m)
        return verts, _BOX_FACES.copy()


def _fspath(value):
    return os.fspath(value) if isinstance(value, os.PathLike) else value


def _existing_file(value: str, info: ValidationInfo) -> Path:
    """The mesh file resolved against the validation context's ``base_dir`` (the scenario file's
    folder; the working directory without one); it must exist."""
    base = (info.context or {}).get("base_dir")
    path = (Path(base) / value if base is not None else Path(value)).resolve()
    if not path.is_file():
        raise ValueError(f"mesh file {value!r} not found (looked for {path})")
    return path


@register_obstacle_type
class Mesh(Obstacle):
    """Triangle-mesh obstacle read from a file by trimesh (STL, OBJ, PLY, ...) (``type = "mesh"``).

    Placed by ``p_base = R(rpy_rad) (scale p_file) + translation_m``, for the collision checker
    and the drawings alike. The file is read on first use and kept.

    Attributes
    ----------
    file : pathlib.Path
        The mesh file, resolved (a relative path in a scenario file is relative to the scenario
        file's folder; from Python, to the working directory); it must exist.
    scale : float
        File units to metres (0.001 for a file in millimetres) [m / file unit], > 0.
    translation_m : tuple of float, shape (3,)
        [m] (default 0).
    rpy_rad : tuple of float, shape (3,)
        Roll, pitch, yaw [rad] (default 0), ``Rz(yaw) Ry(pitch) Rx(roll)``.
    """

    type: Literal["mesh"] = "mesh"
    file: Annotated[str, Field(min_length=1), BeforeValidator(_fspath), AfterValidator(_existing_file),
                    PlainSerializer(str, return_type=str)]
    scale: PositiveFloat
    translation_m: Vector3 = (0.0, 0.0, 0.0)
    rpy_rad: Vector3 = (0.0, 0.0, 0.0)

    @classmethod
    def from_dict(cls, d: Mapping) -> Obstacle:
        """Validate a dict (see :meth:`Obstacle.from_dict`), accepting the older dict spellings.

        Besides the file's keys: ``path`` for ``file``, ``scale`` left out for 1.0, and
        ``{"type": "mesh", "vertices": (V, 3) [m], "faces": (F, 3)}`` (inline triangles in the
        base frame), which gives a :class:`Triangles`.

        Raises
        ------
        pydantic.ValidationError
            A key is missing, unknown or has a bad value.
        """
        d = dict(d)
        if "vertices" in d or "vertices_m" in d:
            d.pop("type", None)
            d["vertices_m"] = d.pop("vertices_m", None) if "vertices_m" in d else d.pop("vertices")
            return Triangles.model_validate({"type": "triangles", **d})
        if "path" in d and "file" not in d:
            d["file"] = d.pop("path")
        d.setdefault("scale", 1.0)
        return cls.model_validate(d)

    def input_files(self) -> tuple[str, ...]:
        """``(file,)``: the mesh file (:meth:`Obstacle.input_files`)."""
        return (str(self.file),)

    @cached_property
    def _placed(self) -> tuple[np.ndarray, np.ndarray]:
        import trimesh

        mesh = trimesh.load(str(self.file), force="mesh")
        if len(mesh.faces) == 0:
            raise ValueError(f"mesh file {self.file} has no triangles")
        verts = self.scale * np.asarray(mesh.vertices, dtype=float)
        verts = verts @ rotation_from_rpy(self.rpy_rad).T + np.array(self.translation_m)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        verts.setflags(write=False)
        faces.setflags(write=False)
        return verts, faces

    def collision_object(self):
        """``fcl.BVHModel`` of the placed triangles (see :meth:`Obstacle.collision_object`).

        Raises
        ------
        ValueError
            The file has no triangles.
        """
        return _bvh_object(*self._placed)

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Box of the placed vertices, each shape (3,) [m] (see :meth:`Obstacle.aabb`)."""
        verts = self._placed[0]
        return verts.min(axis=0), verts.max(axis=0)

    def triangles(self, resolution: int = DRAWING_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
        """The file's triangles, placed: vertices (V, 3) [m], faces (F, 3) (see
        :meth:`Obstacle.triangles`; ``resolution`` is not used)."""
        verts, faces = self._placed
        return verts.copy(), faces.copy()


_Face = Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=3, max_length=3), *_AS_TUPLE]


@register_obstacle_type
class Triangles(Obstacle):
    """Triangle-mesh obstacle given inline, in the robot base frame (``type = "triangles"``).

    Attributes
    ----------
    vertices_m : tuple of tuple of float, shape (V, 3)
        Vertices [m], V >= 3.
    faces : tuple of tuple of int, shape (F, 3)
        Vertex indices (0-based, below V) of each triangle, F >= 1.
    """

    type: Literal["triangles"] = "triangles"
    vertices_m: Annotated[list[Vector3], Field(min_length=3), *_AS_TUPLE]
    faces: Annotated[list[_Face], Field(min_length=1), *_AS_TUPLE]

    @field_validator("faces")
    @classmethod
    def _faces_index_vertices(cls, faces, info: ValidationInfo):
        n = len(info.data.get("vertices_m", ()))
        bad = [i for face in faces for i in face if i >= n]
        if n and bad:
            raise ValueError(f"vertex index {bad[0]} is not below the number of vertices ({n})")
        return faces

    def collision_object(self):
        """``fcl.BVHModel`` of the triangles (see :meth:`Obstacle.collision_object`)."""
        return _bvh_object(np.array(self.vertices_m), np.array(self.faces))

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Box of the vertices, each shape (3,) [m] (see :meth:`Obstacle.aabb`)."""
        verts = np.array(self.vertices_m)
        return verts.min(axis=0), verts.max(axis=0)

    def triangles(self, resolution: int = DRAWING_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (V, 3) [m] and faces (F, 3) as given (see :meth:`Obstacle.triangles`;
        ``resolution`` is not used)."""
        return np.array(self.vertices_m, dtype=float), np.array(self.faces, dtype=np.int64)
