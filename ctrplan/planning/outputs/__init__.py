"""The outputs of a plan, the only part of planning that converts to millimetres and degrees,
and the readers beside their writers:

- :mod:`~ctrplan.planning.outputs.writer`: :func:`write_plan_report` writes a run's files
  (``path.csv``, ``trajectory.csv``, the figures, ``plan.html``, ``summary.json`` last, each
  atomically) and :func:`log_summary` prints the summary;
- :mod:`~ctrplan.planning.outputs.summary`: :func:`plan_summary`, the run as the dict
  ``summary.json`` stores (report units: keys ending ``_mm``, ``_deg``, ``_m``, ``_s``), and
  :func:`read_plan_record`, the plans' headline numbers back from it;
- :mod:`~ctrplan.planning.outputs.folder`: a plan's folder, its files' columns and formats
  (:func:`write_plan_outputs`, :func:`path_columns`, :func:`write_trajectory_csv`,
  :func:`format_summary`) and :func:`read_plan_folder`, a plan's folder read back;
- :mod:`~ctrplan.planning.outputs.figures`: the PNG figures (robot shapes and obstacles, the
  bound along the path, the joint trajectories);
- :mod:`~ctrplan.planning.outputs.view`: ``plan.html``, the interactive 3-D view of the ordered
  waypoints (plotly).
"""

from .folder import (PATH_FILE, SUMMARY_FILE, TRAJECTORY_FILE, PlanFolder, format_summary, path_columns,
                    read_plan_folder, write_plan_outputs, write_trajectory_csv)
from .summary import COMPARED, PlanRecord, plan_summary, read_plan_record
from .writer import log_summary, path_rows, write_plan_report

# the figures and the view import matplotlib and plotly: loaded on first use, so that planning
# without writing a report does not import them
_LAZY = {"BoundProfile": "figures", "plot_bound_along_path": "figures", "plot_joint_trajectories": "figures",
         "plot_robot_shapes": "figures", "PLAN_VIEW_FILE": "view", "WaypointFrames": "view",
         "plan_view_figure": "view", "write_plan_view": "view"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "write_plan_report", "log_summary", "path_rows",
    "plan_summary", "COMPARED", "PlanRecord", "read_plan_record",
    "write_plan_outputs", "path_columns", "write_trajectory_csv", "format_summary", "PlanFolder", "read_plan_folder",
    "PATH_FILE", "TRAJECTORY_FILE", "SUMMARY_FILE",
    "plot_robot_shapes", "BoundProfile", "plot_bound_along_path", "plot_joint_trajectories",
    "PLAN_VIEW_FILE", "WaypointFrames", "plan_view_figure", "write_plan_view",
]
