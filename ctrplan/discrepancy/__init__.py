"""Model-discrepancy analysis: which effect is missing from a robot model, judged on measured data.

- :mod:`.data`: measured data with its whole recorded motion, configuration groups and the split;
- :mod:`.simulate`: the models along a motion (branch following; the friction state comes from
  :mod:`ctrplan.history`; Sections III and V-B of Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019,
  doi:10.1109/TRO.2018.2878906);
- :mod:`.synth`: measured-like data with hidden effects of the registry :mod:`ctrplan.effects`
  and sensor noise (``ctrplan synth``);
- :mod:`.parameters`: calibration parameters (baseline tube parameters and effect parameters);
- :mod:`.calibrate`: least squares on Eq. (49), Kabsch registration; :mod:`.gridsearch`: the
  grid search of friction coefficients;
- :mod:`.noise`: the sensor noise from rests; :mod:`.consistency`: is a residual noise;
- :mod:`.statistics`: comparisons of cross-validated models and intervals over units;
- the workflow (``ctrplan discrepancy``, :func:`run_discrepancy`, which returns a
  :class:`DiscrepancyResult`), by stage: :mod:`.options`, :mod:`.stages`, :mod:`.setup`,
  :mod:`.split`, :mod:`.evaluation`, :mod:`.baseline`, :mod:`.signatures`, :mod:`.decision`,
  :mod:`.fitting`, :mod:`.estimates`, :mod:`.pairs`, :mod:`.envelope`, :mod:`.coverage`,
  :mod:`.output`, :mod:`.workflow`;
- :mod:`.report`: the report folder (markdown, ``results.json``, plots), the only module that
  converts results to millimetres and degrees; the markdown is formatted from ``results.json``
  alone (:func:`write_report_from_results` writes it again).
"""

from .simulate import Simulation, simulate
from .synth import Noise, SynthResult, synthesize, truth_path, write_synth
from .predictions import pose_errors, predict
from .calibrate import CalibrationResult, calibrate
from .gridsearch import grid_search
from .data import MeasuredData, load_measured_data
from .split import DataSplit, make_split
from .parameters import apply_parameters, read_parameters
from .signatures import SignatureTest, friction_signature, regression_signature, registration_signature
from .options import DiscrepancyOptions
from .workflow import DiscrepancyResult, run_discrepancy
from .report import write_report, write_report_from_results

__all__ = [
    "Simulation", "simulate",
    "Noise", "SynthResult", "synthesize", "truth_path", "write_synth",
    "CalibrationResult", "calibrate", "grid_search", "pose_errors", "predict",
    "MeasuredData", "load_measured_data", "DataSplit", "make_split", "apply_parameters", "read_parameters",
    "SignatureTest", "friction_signature", "regression_signature", "registration_signature",
    "DiscrepancyOptions", "DiscrepancyResult", "run_discrepancy", "write_report", "write_report_from_results",
]
