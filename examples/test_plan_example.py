"""A plan checked in a pytest suite: copy this file into your own tests.

Plans the shipped task-target scenario with a small RRT* budget into pytest's temporary folder
and applies the four assertions of ``ctrplan.testing``. Run with ``python -m pytest -q``.
"""

import math
from pathlib import Path

import ctrplan
from ctrplan.testing import (assert_bound_below, assert_collision_free, assert_rotations_before_translations,
                             assert_trajectory_within_limits)

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "task-target.toml"


def test_task_target_plan(tmp_path):
    result = ctrplan.plan_scenario(SCENARIO, tmp_path / "out", iterations=60, compare_blind=False)
    assert result.goal_waypoints == (len(result.q) - 1,)                    # the goal is the last waypoint
    # exact bound below 15 mm at the waypoints and every 30 deg / 10 mm between them [m, rad]
    assert_bound_below(result, 0.015, resolution=(math.radians(30.0), 0.01))
    assert_rotations_before_translations(result)
    assert_collision_free(result, clearance_m=1e-3)                            # 1 mm [m]
    assert_trajectory_within_limits(tmp_path / "out")                          # the folder works too
