"""Former home of the stages of a plan, now :mod:`ctrplan.planning` (with the building blocks they
compose: one package for planning). Every name it exported resolves, with a
``DeprecationWarning``, to the same object there; the stages' earlier names ``load_bound_map``,
``time_parameterize`` and ``write_report`` to ``prepare_bound_map``, ``drive_trajectory`` and
``write_plan_report``.
"""

import warnings

# The stages' names before each public name had one meaning: ctrplan.boundmap.load_bound_map reads a
# map file, ctrplan.trajectory.time_parameterize times waypoints and the discrepancy workflow has
# its own write_report.
_RENAMED = {"load_bound_map": "prepare_bound_map", "time_parameterize": "drive_trajectory",
            "write_report": "write_plan_report"}


def __getattr__(name):
    from .. import planning

    new = _RENAMED.get(name, name)
    if new not in planning.__all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"ctrplan.pipeline.{name} is deprecated: use ctrplan.planning.{new}", DeprecationWarning,
                  stacklevel=2)
    return getattr(planning, new)
