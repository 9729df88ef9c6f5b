"""Obstacle types and their registry (ctrplan.obstacles).

- A cylinder type defined and registered here, in this file only, is read from a scenario file
  (with the file errors of the built-in types), checked by the collision checker, planned around
  and drawn by both plots: every place that dispatches on an obstacle's type goes through the
  registry.
- The built-in types: dicts round-trip, the boxes contain the obstacles, the older dict
  spellings still work, and loading or checking obstacles imports no plotting library.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Literal

import numpy as np
import pytest
from pydantic import field_validator

import ctrplan.planning.outputs.figures as plots
from ctrplan.errors import ModelFileError
from ctrplan.io.scenario import load_scenario
from ctrplan.mechanics import ModelSettings
from ctrplan.obstacles import (OBSTACLE_TYPES, Obstacle, PositiveFloat, Vector3, convex_triangles, obstacle_from_dict,
                               register_obstacle_type, rotation_z_to, unregister_obstacle_type)
from ctrplan.planning import (BoundCostObjective, CollisionChecker, JointStateSpace, plan_route,
                              route_checks)
from ctrplan.planning.outputs.figures import plot_robot_shapes
from ctrplan.planning.outputs.view import WaypointFrames, plan_view_figure
from test_planning_verify import dense_reference_violations  # exact model, whole body, 0.005 rad / 0.1 mm

REPO = Path(__file__).resolve().parents[1]
T7 = REPO / "model" / "ha2019-table7-calibrated.toml"
SETTINGS = ModelSettings(ds=3e-3)
START = np.array([0.0, 0.0, -0.05])
GOAL = np.array([0.8, 0.0, -0.05])
# A post across the tip's path from START to GOAL (the tip passes (99.5, 16.3, 170.5) mm at
# alpha_2 = 0.4 rad), tilted so that its pose is a real rotation.
POST = {"center_m": (0.0995, 0.0163, 0.1705), "axis": (0.3, 0.3, 1.0), "radius_m": 0.002, "length_m": 0.008}


class Cylinder(Obstacle):
    """Solid cylinder: axis through ``center_m`` along ``axis``, ``length_m`` long, radius ``radius_m``."""

    type: Literal["cylinder"] = "cylinder"
    center_m: Vector3
    axis: Vector3
    radius_m: PositiveFloat
    length_m: PositiveFloat

    @field_validator("axis")
    @classmethod
    def _nonzero(cls, axis):
        if not np.linalg.norm(axis) > 0.0:
            raise ValueError(f"axis must not be zero, got {list(axis)!r}")
        return axis

    def _unit_axis(self):
        return np.array(self.axis) / np.linalg.norm(self.axis)

    def collision_object(self):
        import fcl

        return fcl.CollisionObject(fcl.Cylinder(self.radius_m, self.length_m),
                                   fcl.Transform(rotation_z_to(self.axis), np.array(self.center_m)))

    def aabb(self):
        u = self._unit_axis()
        half = self.radius_m * np.sqrt(1.0 - u ** 2) + 0.5 * self.length_m * np.abs(u)
        return np.array(self.center_m) - half, np.array(self.center_m) + half

    def triangles(self, resolution=24):
        t = np.linspace(0.0, 2 * np.pi, resolution, endpoint=False)
        ring = np.column_stack([self.radius_m * np.cos(t), self.radius_m * np.sin(t), np.zeros_like(t)])
        local = np.concatenate([ring - [0.0, 0.0, 0.5 * self.length_m], ring + [0.0, 0.0, 0.5 * self.length_m]])
        return convex_triangles(local @ rotation_z_to(self.axis).T + np.array(self.center_m))

    # for the tests: where a point lies relative to the solid
    def axial_radial(self, points):
        """Axial coordinate from the centre and distance from the axis of ``points`` (N, 3) [m]."""
        d = np.asarray(points, dtype=float) - np.array(self.center_m)
        s = d @ self._unit_axis()
        return s, np.linalg.norm(d - s[:, None] * self._unit_axis(), axis=1)


@pytest.fixture
def cylinder_type():
    """The cylinder registered for one test, and unregistered after it (so other tests see the
    built-in types only)."""
    register_obstacle_type(Cylinder)
    yield Cylinder
    unregister_obstacle_type("cylinder")


def _scenario_text(obstacle_table: str) -> str:
    return f"""
name = "post"
robot = "{T7.as_posix()}"
[start]
q = {{alpha_2 = {START[0]}, alpha_3 = {START[1]}, beta_3 = {START[2]}}}
[[goals]]
type = "joint"
q = {{alpha_2 = {GOAL[0]}, alpha_3 = {GOAL[1]}, beta_3 = {GOAL[2]}}}
[[obstacles]]
type = "sphere"
center_m = [0.0, 0.0, -0.5]
radius_m = 0.01
{obstacle_table}
"""


def _cylinder_table(**changes) -> str:
    keys = {**{k: list(v) if isinstance(v, tuple) else v for k, v in POST.items()}, **changes}
    return "[[obstacles]]\ntype = \"cylinder\"\n" + "".join(f"{k} = {v}\n" for k, v in keys.items() if v is not None)


def _write(tmp_path, text) -> Path:
    path = tmp_path / "post.toml"
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------- a new type
def test_a_registered_type_is_read_from_a_scenario_file_with_the_file_errors(tmp_path, cylinder_type):
    """The table becomes a Cylinder with its values (catches a loader that builds only the
    built-in types, or a schema cached from before the registration). A bad value is a one-line
    ModelFileError naming the file, the key and the value, as for the built-in types (catches
    errors of the new type escaping as raw pydantic errors). Once unregistered, the type is an
    unknown tag again (catches a schema cached from before the removal)."""
    sc = load_scenario(_write(tmp_path, _scenario_text(_cylinder_table())))
    post = sc.obstacles[1]
    assert type(post) is Cylinder and post.radius_m == 0.002 and post.axis == (0.3, 0.3, 1.0)
    assert post == Cylinder(**POST)

    for changes, key, value in [({"radius_m": -0.002}, "obstacles[2].radius_m", "-0.002"),
                                ({"axis": [0.0, 0.0, 0.0]}, "obstacles[2].axis", "[0.0, 0.0, 0.0]"),
                                ({"axis": [0.0, 1.0]}, "obstacles[2].axis", "[0.0, 1.0]"),
                                ({"length_m": None}, "obstacles[2].length_m", "missing required key"),
                                ({"colour": 3}, "obstacles[2].colour", "center_m, axis, radius_m, length_m")]:
        path = _write(tmp_path, _scenario_text(_cylinder_table(**changes)))
        with pytest.raises(ModelFileError) as info:
            load_scenario(path)
        err = info.value
        assert (err.file, err.key) == (str(path), key), str(err)
        assert value in str(err) and "\n" not in str(err)

    unregister_obstacle_type("cylinder")
    try:
        with pytest.raises(ModelFileError, match="'cylinder'.*'sphere', 'capsule', 'box', 'mesh'") as info:
            load_scenario(_write(tmp_path, _scenario_text(_cylinder_table())))
        assert info.value.key == "obstacles[2]"
    finally:
        register_obstacle_type(Cylinder)


def test_registering_checks_the_class(cylinder_type):
    """Catches a registry that accepts a class the loader and the checker cannot use."""
    assert OBSTACLE_TYPES["cylinder"] is Cylinder
    assert register_obstacle_type(Cylinder) is Cylinder                     # the same class again: no-op

    class Other(Cylinder):
        pass

    with pytest.raises(ValueError, match="'cylinder' is already registered"):
        register_obstacle_type(Other)                                         # the name is taken

    class Untyped(Obstacle):
        radius_m: PositiveFloat

        def collision_object(self):
            return None

        def aabb(self):
            return np.zeros(3), np.zeros(3)

        def triangles(self, resolution=24):
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=int)

    with pytest.raises(TypeError, match="Literal"):
        register_obstacle_type(Untyped)

    class Undrawn(Obstacle):
        type: Literal["undrawn"] = "undrawn"

        def collision_object(self):
            return None

        def aabb(self):
            return np.zeros(3), np.zeros(3)

    with pytest.raises(TypeError, match="triangles"):
        register_obstacle_type(Undrawn)
    with pytest.raises(TypeError):
        register_obstacle_type(dict)
    assert set(OBSTACLE_TYPES) == {"sphere", "capsule", "box", "mesh", "triangles", "cylinder"}
    with pytest.raises(KeyError, match="unknown obstacle type 'cone'; registered: sphere"):
        unregister_obstacle_type("cone")


def test_the_collision_object_and_the_box_are_the_cylinder(cylinder_type):
    """A small ball just inside and just outside the side, the caps and the rim hits and misses
    as the geometry says (catches an fcl cylinder left along z, or placed by its end instead of
    its centre); the box is exactly the solid's box (catches a box that misses part of the
    solid, which would let the broad phase cull real contacts); the dict form goes through the
    registry to the same obstacle."""
    post = Cylinder(**POST)
    u = post._unit_axis()
    n = np.cross(u, [1.0, 0.0, 0.0])
    n /= np.linalg.norm(n)
    c = np.array(post.center_m)
    ball = 1e-5
    checker = CollisionChecker([{"type": "cylinder", **POST}])
    assert checker.obstacles == [post]

    def hits(point):
        return checker.check_body(np.asarray(point)[None, :], np.array([ball])).collides

    probes, expected = [], []
    for s in (0.0, 0.002, -0.002):                                             # the side, r = 2 mm
        probes += [c + s * u + (0.002 - 2 * ball) * n, c + s * u + (0.002 + 3 * ball) * n]
        expected += [True, False]
    for e in (-1.0, 1.0):                                                       # the caps, L / 2 = 4 mm
        probes += [c + e * (0.004 - 2 * ball) * u + 0.0019 * n, c + e * (0.004 + 3 * ball) * u + 0.0019 * n]
        expected += [True, False]
    assert [hits(p) for p in probes] == expected
    # the batched check (broad phase on the boxes) agrees, also at the rims, far from the centre
    batch = checker.collides_batch(np.array(probes)[:, None, :], np.full((len(probes), 1), ball),
                                   np.ones(len(probes), dtype=int))
    assert batch.tolist() == expected

    lo, hi = post.aabb()
    t = np.linspace(0.0, 2 * np.pi, 3601)
    m = np.cross(u, n)
    rim = np.concatenate([c + e * 0.004 * u + 0.002 * (np.cos(t)[:, None] * n + np.sin(t)[:, None] * m)
                          for e in (-1.0, 1.0)])
    np.testing.assert_allclose(lo, rim.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(hi, rim.max(axis=0), atol=1e-9)
    box_lo, box_hi = checker.obstacle_aabbs()
    np.testing.assert_allclose(box_lo[0], lo - 1e-5)


def test_a_route_goes_around_a_registered_obstacle_from_a_scenario_file(tmp_path, cylinder_type):
    """The straight motion from start to goal crosses the post: the planner's batched check
    (broad phase on the type's box, narrow phase on its fcl object) refuses it, and so does a
    dense exact check (so the test is not vacuous: a checker that ignored the new type would
    return the straight path). The planned route then never touches the post on the dense check
    (catches a cylinder missing from the search or the final check, or culled by a wrong box)
    and ends at the goal."""
    sc = load_scenario(_write(tmp_path, _scenario_text(_cylinder_table())))
    robot, obstacles = sc.robot, list(sc.obstacles)
    js = JointStateSpace(robot)
    checks = route_checks(robot, obstacles, None, SETTINGS, joint_space=js)
    assert not checks.search.check_motion(START, GOAL)
    assert dense_reference_violations(robot, obstacles, [START, GOAL])
    route = plan_route(robot, START, [GOAL], checks, BoundCostObjective.factory(None, bound_weight=0.0),
                       iterations=1000, seed=2, joint_space=js)
    assert dense_reference_violations(robot, obstacles, route.ordered.q) == []
    np.testing.assert_allclose(js.difference(route.ordered.q[-1], GOAL), 0.0, atol=1e-9)


def _on_the_surface(post, points_m, tol=1e-9):
    """Every point on the side or a cap of ``post``, and both caps reached."""
    s, r = post.axial_radial(points_m)
    side = np.isclose(r, post.radius_m, atol=tol) & (np.abs(s) <= 0.5 * post.length_m + tol)
    cap = np.isclose(np.abs(s), 0.5 * post.length_m, atol=tol) & (r <= post.radius_m + tol)
    half = 0.5 * post.length_m
    return bool(np.all(side | cap)) and abs(s.min() + half) <= tol and abs(s.max() - half) <= tol


def test_both_plots_draw_a_registered_obstacle_where_it_is(tmp_path, monkeypatch, cylinder_type):
    """The matplotlib figure and the plotly view draw the scenario's cylinder (and the same one
    given as a dict) as triangles on its surface, in mm (catches a drawing dispatched on the
    built-in type names, drawn in m, or drawn somewhere else)."""
    sc = load_scenario(_write(tmp_path, _scenario_text(_cylinder_table())))
    post = sc.obstacles[1]
    drawn = []

    class Spy(plots.Poly3DCollection):
        def __init__(self, polys, *args, **kwargs):
            drawn.append(np.asarray(polys, dtype=float))
            super().__init__(polys, *args, **kwargs)

    monkeypatch.setattr(plots, "Poly3DCollection", Spy)
    shape = np.column_stack([np.zeros(5), np.zeros(5), np.linspace(0.0, 0.17, 5)])
    out = plot_robot_shapes(tmp_path / "shapes.png", [shape], [post, {"type": "cylinder", **POST}])
    assert out.stat().st_size > 1000
    assert len(drawn) == 2
    for polys in drawn:
        assert polys.shape[1:] == (3, 3) and len(polys) >= 2 * plots.SPHERE_RESOLUTION
        assert _on_the_surface(post, polys.reshape(-1, 3) / 1e3)

    fig = plan_view_figure(WaypointFrames([shape]), obstacles=sc.obstacles)
    (trace,) = [t for t in fig.data if t.name == "obstacle 2 (cylinder)"]
    verts_mm = np.column_stack([trace.x, trace.y, trace.z])
    assert _on_the_surface(post, verts_mm / 1e3, tol=1e-7)              # the view rounds to 0.1 um
    assert len(trace.i) == len(post.triangles(24)[1])


# ---------------------------------------------------------------------------------- built-in types
BUILT_IN = [
    {"type": "sphere", "center_m": [0.03, 0.0, 0.15], "radius_m": 0.01},
    {"type": "capsule", "a_m": [0.0, 0.0, 0.2], "b_m": [0.0, 0.05, 0.21], "radius_m": 0.002},
    {"type": "box", "center_m": [0.0, 0.05, 0.15], "size_m": [0.1, 0.01, 0.1], "rpy_rad": [0.2, -0.1, 0.3]},
    {"type": "triangles", "vertices_m": [[0.0, 0.0, 0.1], [0.01, 0.0, 0.1], [0.0, 0.01, 0.1], [0.0, 0.0, 0.11]],
     "faces": [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]},
]


def _mesh_dict(folder: Path) -> dict:
    import trimesh

    trimesh.creation.box(extents=(2.0, 3.0, 4.0)).export(folder / "box.stl")            # mm
    return {"type": "mesh", "file": str(folder / "box.stl"), "scale": 1e-3, "translation_m": [0.0, 0.0, 0.05],
            "rpy_rad": [0.0, 0.4, 0.0]}


def test_built_in_types_round_trip_and_their_boxes_contain_them(tmp_path):
    """``as_dict`` gives the dict back and ``obstacle_from_dict`` the equal obstacle (catches a
    key renamed on one side); each box contains the obstacle's triangles and, for the exact
    shapes, touches them (catches a box too small, which culls real contacts)."""
    for d in BUILT_IN + [_mesh_dict(tmp_path)]:
        o = obstacle_from_dict(d)
        assert o.type == d["type"]
        assert o.as_dict() == ({**d, "file": str(Path(d["file"]).resolve())} if "file" in d else d)
        assert obstacle_from_dict(o.as_dict()) == o
        lo, hi = o.aabb()
        verts, faces = o.triangles(64)
        assert faces.shape[1] == 3 and faces.max() < len(verts)
        assert np.all(verts >= lo - 1e-12) and np.all(verts <= hi + 1e-12)
        if d["type"] in ("box", "mesh", "triangles"):                         # vertices are the extremes
            np.testing.assert_allclose([verts.min(axis=0), verts.max(axis=0)], [lo, hi], atol=1e-12)
        else:                                                                   # sampled curves: within the sag
            np.testing.assert_allclose([verts.min(axis=0), verts.max(axis=0)], [lo, hi], atol=1e-5)


def test_older_dict_spellings_are_accepted(tmp_path):
    """Mesh dicts with ``path`` and no ``scale``, and inline ``vertices``/``faces``, as the plots
    and the checker took them before; an unknown type names the registered ones."""
    mesh = _mesh_dict(tmp_path)
    old = obstacle_from_dict({"type": "mesh", "path": mesh["file"]})
    assert old.file == Path(mesh["file"]).resolve() and old.scale == 1.0
    inline = obstacle_from_dict({"type": "mesh", "vertices": BUILT_IN[3]["vertices_m"], "faces": BUILT_IN[3]["faces"]})
    assert inline == obstacle_from_dict(BUILT_IN[3])
    with pytest.raises(ValueError, match="unknown type 'cone' .*sphere, capsule, box, mesh, triangles"):
        obstacle_from_dict({"type": "cone"})
    with pytest.raises(ValueError, match=r"^box obstacle: key 'size_m\[2\]': Input should be greater than 0; got -1"):
        obstacle_from_dict({"type": "box", "center_m": [0, 0, 0], "size_m": [1, -1, 1]})
    with pytest.raises(ValueError, match="mesh file 'missing.stl' not found"):
        obstacle_from_dict({"type": "mesh", "path": "missing.stl"})


def test_loading_and_checking_obstacles_imports_no_plotting_library(tmp_path):
    """The scenario loader and the collision checker use the obstacle classes without importing
    matplotlib or plotly; the loader does not import python-fcl or trimesh either (run in a
    fresh interpreter)."""
    _mesh_dict(tmp_path)                                                        # writes box.stl
    text = _scenario_text("[[obstacles]]\ntype = \"mesh\"\nfile = \"box.stl\"\nscale = 0.001\n")
    path = _write(tmp_path, text)
    code = ("import sys\n"
            "from ctrplan.io.scenario import load_scenario\n"
            f"sc = load_scenario({str(path)!r})\n"
            "print(','.join(m for m in ('fcl', 'trimesh', 'matplotlib', 'plotly') if m in sys.modules))\n"
            "from ctrplan.planning import CollisionChecker\n"
            "CollisionChecker(sc.obstacles).obstacle_aabbs()\n"
            "print(','.join(m for m in ('matplotlib', 'plotly') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert out.stdout.splitlines() == ["", ""], out.stdout
