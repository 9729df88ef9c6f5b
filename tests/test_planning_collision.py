import numpy as np
import pytest
import trimesh

from ctrplan.obstacles import Box, Capsule, Mesh, Sphere, obstacle_from_dict
from ctrplan.planning import CollisionChecker
from test_planning_helpers import FakeSolution, fake_robot

# body: straight line on the z axis from 0 to 0.1 m, radius 1 mm
POINTS = np.linspace([0, 0, 0], [0, 0, 0.1], 51)
RADII = np.full(51, 1e-3)


def check(obstacle, **kw):
    return CollisionChecker([obstacle]).check_body(POINTS, RADII, **kw)


@pytest.mark.parametrize("obstacle, hit", [
    (Sphere(center_m=(0.003, 0, 0.05), radius_m=0.0025), True),      # gap -0.5 mm
    (Sphere(center_m=(0.010, 0, 0.05), radius_m=0.005), False),      # gap 4 mm
    (Sphere(center_m=(0, 0, 0.104), radius_m=0.0035), True),         # beyond the tip, touches the end cap
    (Capsule(a_m=(-0.01, 0.001, 0.05), b_m=(0.01, 0.001, 0.05), radius_m=0.0005), True),
    (Capsule(a_m=(-0.01, 0.002, 0.05), b_m=(0.01, 0.002, 0.05), radius_m=0.0005), False),
    (Box(center_m=(0.0035, 0, 0.05), size_m=(0.002, 0.01, 0.01)), False),                    # face at x = 2.5 mm
    (Box(center_m=(0.0035, 0, 0.05), size_m=(0.002, 0.01, 0.01), rpy_rad=(0, 0, np.pi / 2)), True),  # yawed: x = -1.5 mm
])
def test_primitives(obstacle, hit):
    assert check(obstacle).collides is hit


def test_min_distance_sphere():
    rep = check(Sphere(center_m=(0.010, 0, 0.05), radius_m=0.005), distance=True)
    assert not rep.collides
    assert rep.min_distance == pytest.approx(0.004, abs=1e-5)


def test_mesh_stl(tmp_path):
    path = tmp_path / "slab.stl"
    trimesh.creation.box(extents=(2.0, 10.0, 10.0)).export(path)  # millimetres
    miss = Mesh(file=path, scale=1e-3, translation_m=(0.0035, 0, 0.05))
    hit = Mesh(file=path, scale=1e-3, translation_m=(0.0015, 0, 0.05))  # face at x = 0.5 mm
    assert not check(miss).collides
    assert check(hit).collides
    assert check(miss, distance=True).min_distance == pytest.approx(0.0015, abs=5e-5)


def test_dicts_and_solution_interface():
    robot = fake_robot()
    checker = CollisionChecker([{"type": "sphere", "center_m": [0.03, 0, 0.03], "radius_m": 0.004},
                                {"type": "box", "center_m": [0, 0, -0.5], "size_m": [0.1, 0.1, 0.1]}])
    alpha, beta = robot.configuration([0.0, 0.0, -0.07])
    sol = FakeSolution(alpha, beta)  # tip at (0.03, 0, 0.03): inside the sphere
    assert checker.collides(sol, robot)
    alpha, beta = robot.configuration([np.pi, np.pi, -0.07])  # tip at (-0.03, 0, 0.03)
    assert not checker.collides(FakeSolution(alpha, beta), robot)
    assert CollisionChecker([]).check_body(POINTS, RADII, distance=True).min_distance == np.inf
    with pytest.raises(ValueError, match="type"):
        obstacle_from_dict({"type": "cone"})
    with pytest.raises(ValueError, match="radius_m"):
        CollisionChecker([{"type": "sphere", "center_m": (0, 0, 0), "radius_m": -1.0}])
