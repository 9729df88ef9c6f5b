"""Model-discrepancy analysis: which effect is missing from a robot model, judged on measured data.

- :mod:`.simulate`: the models along a measured motion history (branch following, friction
  direction and translation-last from the history; Sections III and V-B of Ha, Fagogenis &
  Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906).
- :mod:`.effects`: candidate effects (friction, clearance, off-plane precurvature, Poisson
  ratios, registration) as modifications of a robot.
- :mod:`.history`: effects on the motion history (drive backlash, tracker time offset,
  gradually developing friction).
- :mod:`.synth`: measured-like data with hidden effects and sensor noise (``ctrplan synth``).
- :mod:`.data`: measured data with its motion history, configuration groups and the split.
- :mod:`.parameters`: calibration parameters and how they change a robot.
- :mod:`.calibrate`: least squares on Eq. (49), Kabsch registration, friction grid search.
- :mod:`.signatures`: one permutation test per candidate effect's residual signature.
- :mod:`.workflow`: ``ctrplan discrepancy`` (calibrate, diagnose, try, name, add, show).
- :mod:`.report`: the report folder (markdown, JSON, plots).
"""

from .effects import Effects, apply_effects, apply_registration, registration_matrix
from .simulate import History, Simulation, motion_history, simulate
from .synth import Noise, SynthResult, synthesize, truth_path, write_synth
from .calibrate import CalibrationResult, calibrate, grid_search_friction, pose_errors, predict
from .data import MeasuredData, load_measured_data, split_data
from .parameters import apply_parameters, read_parameters
from .signatures import SignatureTest, friction_signature, regression_signature, registration_signature
from .workflow import DiscrepancyOptions, run_discrepancy
from .report import write_report

__all__ = [
    "Effects", "apply_effects", "apply_registration", "registration_matrix",
    "History", "Simulation", "motion_history", "simulate",
    "Noise", "SynthResult", "synthesize", "truth_path", "write_synth",
    "CalibrationResult", "calibrate", "grid_search_friction", "pose_errors", "predict",
    "MeasuredData", "load_measured_data", "split_data", "apply_parameters", "read_parameters",
    "SignatureTest", "friction_signature", "regression_signature", "registration_signature",
    "DiscrepancyOptions", "run_discrepancy", "write_report",
]
