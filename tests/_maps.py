"""Synthetic bound maps for the planning tests: a constant, everywhere-valid field (friction 1 mm,
0.1 rad; translation-last 0.5 mm, 0.05 rad), handed to :func:`ctrplan.plan` or placed in the map
cache of the working folder, where the command line's map lookup reads it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ctrplan.boundmap import BoundField, MapSpec, map_coordinates, map_file, map_identity, map_paths, uniform_axis
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, evaluate_bound

#: Values of the constant field: position [m], angle [rad], translation-last position [m], angle [rad].
SYNTHETIC = (1e-3, 0.1, 5e-4, 0.05)


def constant_field(robot, resolution=(4, 4, 3), key: str = "synthetic") -> BoundField:
    """The constant field over ``robot``'s map coordinates, ``resolution`` nodes per coordinate."""
    coords = map_coordinates(robot)
    axes = [uniform_axis(lo, hi, n, per) for lo, hi, n, per in zip(coords.lower, coords.upper, resolution,
                                                                     coords.periodic)]
    shape = tuple(len(a) for a in axes)
    values = np.broadcast_to(np.array(SYNTHETIC), shape + (4,)).copy()
    return BoundField(axes, coords.periodic, values, np.ones(shape, bool), key=key, coordinates=coords)


def cache_constant_field(robot_file: Path, resolution=(4, 4, 3), ds: float = 0.004,
                         placement: str = "uniform") -> Path:
    """Save the constant field as the cached map of ``robot_file`` for a scenario's ``[bound_field]``
    (``resolution``, ``ds_m``, ``placement``), in the cache folder (``.cache/`` of the working
    folder in the tests: tests/conftest.py); returns its path."""
    robot_file = Path(robot_file)
    robot = load_robot(robot_file)
    key = map_identity(robot, ModelSettings(ds=ds), MapSpec(tuple(resolution), placement), evaluate_bound,
                       robot_file.read_text()).key
    path = map_file(map_paths(robot_file, key)[1], ".npz")
    constant_field(robot, resolution, key=key).save(path)
    return path
