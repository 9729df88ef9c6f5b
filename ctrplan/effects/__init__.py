"""Effects a robot model may miss, in one registry.

Each :class:`Effect` entry carries everything about one effect: its parameters with units,
typical ranges and optimizer bounds (:class:`ParameterSpec`), the mechanics model it needs,
how it changes the robot, the motion (:mod:`ctrplan.history`) or the measurement, its
signature test, its ``ctrplan synth`` option, how the discrepancy workflow fits it, and what
planning does with it. The CLI, ``synth``, the parameter tables, the workflow and the report
iterate :data:`REGISTRY` (the read-only view of :data:`EFFECT_REGISTRY`, a
:class:`ctrplan.registry.Registry`); adding an effect is one :func:`register` call.

Built in (``_builtin``): torsional friction, clearance, off-plane precurvature, Poisson ratio,
registration (Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906),
drive backlash, tracker time offset and gradually developing friction.

:class:`EffectSet` holds effect values; :func:`apply_robot_effects`, :func:`history_state` and
:func:`apply_output_effects` apply them; a robot file keeps the history and measurement effects
in its ``[effects]`` table (:func:`effects_from_file`).
"""

from ._fit import FIT_STRATEGIES, GRID, NESTED, NO_FIT, SCAN, FitStrategy
from ._registry import (EFFECT_REGISTRY, REGISTRY, STORES, Effect, ParameterSpec, effect_names,
                        effect_of_parameter, get, parameter_spec, register, registered, unregister)
from . import _builtin  # noqa: F401  (registers the built-in effects)
from ._builtin import (BACKLASH_SCAN, FRICTION_ANGLE_REFERENCE, FRICTION_ANGLE_SCAN, TIME_OFFSET_SCAN,
                       angle_features, curved_tubes, overlap_features, registration_transform, rotating_tubes,
                       twist_features)
from ._values import (EffectSet, apply_output_effects, apply_robot_effects, effects_from_file, effects_to_file,
                      file_key, history_operators, history_state, model_of, robot_effects)

__all__ = ["Effect", "ParameterSpec", "EFFECT_REGISTRY", "REGISTRY", "FitStrategy", "FIT_STRATEGIES", "NESTED",
           "GRID", "NO_FIT", "SCAN", "STORES", "register", "unregister", "registered", "get", "effect_names", "effect_of_parameter", "parameter_spec",
           "EffectSet", "robot_effects", "apply_robot_effects", "history_operators", "history_state",
           "apply_output_effects", "model_of", "file_key", "effects_from_file", "effects_to_file",
           "BACKLASH_SCAN", "TIME_OFFSET_SCAN", "FRICTION_ANGLE_SCAN", "FRICTION_ANGLE_REFERENCE",
           "overlap_features", "angle_features", "twist_features", "curved_tubes", "rotating_tubes",
           "registration_transform"]
