"""The shared packed robot (ctrplan.mechanics.packed): values, units, read-only, cache per robot."""

import dataclasses

import numpy as np
import pytest

from ctrplan.errors import PhysicalParameterError
from ctrplan.mechanics import build_grid
from ctrplan.mechanics.packed import PackedRobot, pack_robot
from ctrplan.robot import Robot, Section, Tube

from _robots import table1_pair, table2_robot


def _with_poisson(robot, nus):
    """Copy of ``robot`` whose tube i has Poisson ratio ``nus[i]``."""
    tubes = tuple(dataclasses.replace(t, poisson_ratio=nu) for t, nu in zip(robot.tubes, nus))
    return robot.replace(tubes=tubes)


def test_stiffness_per_tube():
    robot = _with_poisson(table2_robot(), (0.3, -0.2, 0.45))
    pk = pack_robot(robot)
    for i, t in enumerate(robot.tubes):
        assert pk.k_xy[i] == t.k_xy
        assert pk.k_z[i] == pytest.approx(t.k_xy / (1.0 + t.poisson_ratio), rel=1e-15)
        assert pk.stiffness_ratio[i] == pytest.approx(1.0 + t.poisson_ratio, rel=1e-14)
    # each tube its own nu, not the first tube's for all
    assert len(set(pk.k_z / pk.k_xy)) == 3


def test_breaks_are_tube_local_and_end_at_the_length():
    robot = table2_robot()
    pk = pack_robot(robot)
    assert pk.breaks.shape == (3, 3) and pk.precurvature.shape == (3, 2, 2)
    np.testing.assert_array_equal(pk.n_breaks, [2, 3, 3])
    for i, t in enumerate(robot.tubes):
        m = pk.n_breaks[i]
        assert pk.breaks[i, 0] == 0.0
        assert pk.breaks[i, m - 1] == pytest.approx(t.length, abs=1e-15)
        assert pk.lengths[i] == t.length
        assert np.all(np.diff(pk.breaks[i, :m]) > 0)
        np.testing.assert_array_equal(pk.breaks[i, m:], 0.0)
        np.testing.assert_array_equal(pk.precurvature[i, :m - 1], [s.precurvature for s in t.sections])
    # tube 2: 17 mm straight, then 150 mm curved; tube 3: 184 mm straight, then 86.4 mm at 1/55 mm
    np.testing.assert_allclose(pk.breaks[1], [0.0, 0.017, 0.167], atol=1e-15)
    np.testing.assert_allclose(pk.precurvature[2], [[0.0, 0.0], [0.0, 1.0 / 0.055]])


def test_geometry_and_friction_match_the_robot():
    robot = table2_robot(mu=0.15)
    pk = pack_robot(robot)
    r_in, r_out = robot.contact_radii()
    np.testing.assert_array_equal(pk.clearance, robot.clearances)
    np.testing.assert_array_equal(pk.contact_radius_in, r_in)
    np.testing.assert_array_equal(pk.contact_radius_out, r_out)
    np.testing.assert_array_equal(pk.friction, [0.15, 0.15])
    np.testing.assert_array_equal(pk.outer_radius, [robot.outer_radius(i) for i in range(3)])
    assert pk.n_tubes == 3


def test_arrays_are_read_only():
    pk = pack_robot(table1_pair())
    for f in dataclasses.fields(PackedRobot):
        arr = getattr(pk, f.name)
        assert not arr.flags.writeable, f.name
        with pytest.raises(ValueError):
            arr[0] = arr[0]


def test_cache_follows_the_robot_value():
    robot = table2_robot()
    pk = pack_robot(robot)
    assert pack_robot(robot) is pk
    # a modified robot gets its own packing, not the cached one of the original
    stiffer = robot.replace(tubes=(dataclasses.replace(robot.tubes[0], k_xy=0.1),) + robot.tubes[1:])
    pk2 = pack_robot(stiffer)
    assert pk2 is not pk
    assert pk2.k_xy[0] == 0.1 and pk.k_xy[0] == 5.07e-2
    looser = table2_robot(mu=0.3)
    assert pack_robot(looser).friction[0] == 0.3 and pk.friction[0] == 0.2
    # a new but equal robot shares it
    assert pack_robot(table2_robot()) is pk


def test_grid_of_a_modified_robot_uses_its_own_precurvature():
    robot = table1_pair()
    beta = np.array(robot.home_beta)
    g0 = build_grid(robot, beta, 3e-3)
    bent = robot.replace(tubes=(robot.tubes[0], dataclasses.replace(
        robot.tubes[1], sections=(Section(0.017), Section(0.150, (0.0, 10.0))))))
    g1 = build_grid(bent, beta, 3e-3)
    assert np.max(g1.precurvature[:, 1, 1]) == 10.0
    assert np.max(g0.precurvature[:, 1, 1]) == pytest.approx(1.0 / 0.150)


def test_friction_radii_missing_only_fail_where_friction_acts():
    t1 = Tube("outer", (Section(0.1, (0.0, 5.0)),), k_xy=0.05)
    t2 = Tube("inner", (Section(0.12),), k_xy=0.02)
    robot = Robot("no diameters", (t1, t2), friction_coefficients=(0.2,), clearances_override=(5e-5,))
    pk = pack_robot(robot)
    assert np.all(np.isnan(pk.contact_radius_in)) and np.all(np.isnan(pk.contact_radius_out))
    np.testing.assert_array_equal(pk.clearance, [5e-5])
    with pytest.raises(PhysicalParameterError, match="needs a diameter"):
        pk.contact_radii(robot)


def test_read_only_arrays_do_not_recompile_per_robot():
    """numba types read-only arrays apart from writable ones: one specialization serves every
    robot's packing (no compilation per call or per robot)."""
    from ctrplan.mechanics.grid import _grid

    robot = table2_robot()
    beta = np.array(robot.home_beta)
    build_grid(robot, beta, 3e-3)
    n_signatures = len(_grid.signatures)
    for mu in (0.1, 0.3):
        other = table2_robot(mu=mu)
        build_grid(other, beta, 3e-3)
        build_grid(other, beta, 2e-3, 0.5, 0.01)
    assert len(_grid.signatures) == n_signatures
