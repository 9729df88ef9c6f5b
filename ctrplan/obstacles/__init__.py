"""Obstacle types in one registry: each type is one class that knows its file schema, its
collision object, its bounding box and its drawing.

An obstacle type is a subclass of :class:`Obstacle`, a frozen pydantic model whose fields are the
keys of its ``[[obstacles]]`` table in a scenario file (``docs/file-formats.md``). The scenario
loader validates each table straight into the class its ``type`` names; the collision checker
(:class:`ctrplan.planning.CollisionChecker`) takes :meth:`Obstacle.collision_object` (python-fcl)
and :meth:`Obstacle.aabb` (its broad phase); the matplotlib figure
(:func:`ctrplan.planning.outputs.plot_robot_shapes`) and the plotly view
(:mod:`ctrplan.planning.outputs.view`) draw
:meth:`Obstacle.triangles`. A ``type`` name is looked up in :data:`OBSTACLE_TYPES` (scenario files,
dicts, :func:`obstacle_from_dict`); nothing else looks at an obstacle's type, so a new type is one
class and one :func:`register_obstacle_type` call, in any module (``docs/planning.md`` has this
example with a check of the axis):

    from typing import Literal

    import fcl
    import numpy as np
    from ctrplan.obstacles import (Obstacle, PositiveFloat, Vector3, convex_triangles,
                                   register_obstacle_type, rotation_z_to)

    @register_obstacle_type
    class Cylinder(Obstacle):
        type: Literal["cylinder"] = "cylinder"
        center_m: Vector3
        axis: Vector3                      # direction of the axis (any length > 0)
        radius_m: PositiveFloat
        length_m: PositiveFloat

        def collision_object(self):
            return fcl.CollisionObject(fcl.Cylinder(self.radius_m, self.length_m),
                                       fcl.Transform(rotation_z_to(self.axis), np.array(self.center_m)))

        def aabb(self):
            u = np.array(self.axis) / np.linalg.norm(self.axis)
            half = self.radius_m * np.sqrt(1.0 - u**2) + 0.5 * self.length_m * np.abs(u)
            return np.array(self.center_m) - half, np.array(self.center_m) + half

        def triangles(self, resolution=24):
            t = np.linspace(0.0, 2 * np.pi, resolution, endpoint=False)
            ring = np.column_stack([self.radius_m * np.cos(t), self.radius_m * np.sin(t), np.zeros_like(t)])
            local = np.concatenate([ring - [0, 0, self.length_m / 2], ring + [0, 0, self.length_m / 2]])
            return convex_triangles(local @ rotation_z_to(self.axis).T + np.array(self.center_m))

A scenario file may then hold ``[[obstacles]] type = "cylinder"`` tables (every key checked,
errors naming the file, the key and the value), and dicts ``{"type": "cylinder", ...}`` work
wherever obstacles are taken (:func:`obstacle_from_dict`).

Built in: :class:`Sphere`, :class:`Capsule`, :class:`Box`, :class:`Mesh` (a mesh file, read by
trimesh) and :class:`Triangles` (a mesh given inline). python-fcl, trimesh and scipy are imported
when an obstacle is first checked or drawn, not with this package.
"""

from ._base import (AXIS_PARALLEL_TOL, DRAWING_RESOLUTION, Obstacle, PositiveFloat, Vector3, convex_triangles, rotation_from_rpy,
                    rotation_z_to)
from ._registry import (OBSTACLE_REGISTRY, OBSTACLE_TYPES, as_obstacle, obstacle_from_dict, register_obstacle_type,
                        unregister_obstacle_type)
from ._builtin import Box, Capsule, Mesh, Sphere, Triangles

__all__ = [
    "Obstacle", "OBSTACLE_REGISTRY", "OBSTACLE_TYPES", "register_obstacle_type", "unregister_obstacle_type", "obstacle_from_dict",
    "as_obstacle",
    "Sphere", "Capsule", "Box", "Mesh", "Triangles",
    "Vector3", "PositiveFloat", "DRAWING_RESOLUTION", "AXIS_PARALLEL_TOL", "rotation_from_rpy", "rotation_z_to", "convex_triangles",
]
