"""Model-discrepancy analysis: which effect is missing from a robot model, judged on measured data.

- :mod:`.simulate`: the models along a measured motion history (branch following, friction
  direction and translation-last from the history; Sections III and V-B of Ha, Fagogenis &
  Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906).
- :mod:`.effects`: candidate effects (friction, clearance, off-plane precurvature, Poisson
  ratios, registration) as modifications of a robot.
- :mod:`.synth`: measured-like data with hidden effects and sensor noise (``ctrplan synth``).
"""

from .effects import Effects, apply_effects, apply_registration, registration_matrix
from .simulate import History, Simulation, motion_history, simulate
from .synth import Noise, SynthResult, synthesize, truth_path, write_synth

__all__ = [
    "Effects", "apply_effects", "apply_registration", "registration_matrix",
    "History", "Simulation", "motion_history", "simulate",
    "Noise", "SynthResult", "synthesize", "truth_path", "write_synth",
]
