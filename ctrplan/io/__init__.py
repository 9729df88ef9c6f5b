"""File input/output: robot model files, scenario files, the CSV schema and atomic writes.

Thin layer around the pure numerics: everything here reads or writes files and hands back
:class:`~ctrplan.robot.Robot`, frozen dataclasses, NumPy arrays or pandas tables in SI units.
Formats: ``docs/file-formats.md``.
"""

from .atomic import atomic_path, atomic_savez, atomic_write_bytes, atomic_write_text
from .robot_file import file_hash, load_robot, robot_from_toml_text
from .scenario import Scenario, load_scenario, scenario_from_toml_text
from .tables import Measurements, load_ha_trajectory, read_configurations, read_measurements, write_table

__all__ = [
    "atomic_path",
    "atomic_savez",
    "atomic_write_bytes",
    "atomic_write_text",
    "file_hash",
    "load_robot",
    "robot_from_toml_text",
    "Scenario",
    "load_scenario",
    "scenario_from_toml_text",
    "Measurements",
    "load_ha_trajectory",
    "read_configurations",
    "read_measurements",
    "write_table",
]
