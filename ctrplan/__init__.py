"""ctrplan: friction-bounded motion planning for concentric tube robots.

Mechanics from Ha, Fagogenis & Dupont, "Modeling Tube Clearance and Bounding the Effect of
Friction in Concentric Tube Robot Kinematics", IEEE T-RO 35(2):353-370, 2019,
doi:10.1109/TRO.2018.2878906.

``ctrplan.plan`` (the entry point: a loaded scenario, optionally its bound map, in; a typed
result out, files only when asked), ``ctrplan.plan_scenario`` (what ``ctrplan plan`` does with a
scenario file), ``ctrplan.PlanResult`` (:mod:`ctrplan.api`) and ``ctrplan.Planner`` (one goal
after another on a roadmap built once, :mod:`ctrplan.planning.interactive`) are imported on first
use, so ``import ctrplan`` stays light.

Messages go through the standard :mod:`logging` module, under the ``ctrplan`` logger (progress
and summaries INFO, details DEBUG, cautions WARNING), which has only a ``logging.NullHandler``: the
library prints nothing until the caller configures logging, e.g.
``logging.basicConfig(level=logging.INFO)``.
"""

import logging as _logging

from .errors import *  # noqa: F401,F403
from .robot import Joint, Robot, Section, TranslationLink, Tube  # noqa: F401

__version__ = "0.1.0"

_logging.getLogger(__name__).addHandler(_logging.NullHandler())

_LAZY = {"plan": "api", "plan_scenario": "api", "PlanResult": "api", "Planner": "planning.interactive",
         "GoalPlan": "planning.interactive"}


def __getattr__(name):
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
