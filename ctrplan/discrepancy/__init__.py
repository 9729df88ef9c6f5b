"""Model-discrepancy analysis: which effect is missing from a robot model, judged on measured data.

The workflow (``ctrplan discrepancy``, :func:`run_discrepancy`, which returns a
:class:`DiscrepancyResult`) in the order it runs:

- :mod:`.measured`: the measured data, the split and the sensor noise (and synthetic data);
- :mod:`.fits`: the models along the motion, calibration by least squares on Eq. (49) of Ha,
  Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906, the baseline and the
  candidate effects, cross-validated;
- :mod:`.verdict`: signature tests, comparisons, the decision, the prediction with the motion
  history and the friction bound's coverage;
- :mod:`.outputs`: the updated robot file, ``results.json`` and the report;
- beside them: :mod:`.options` (what a run may change), :mod:`.setup` and :mod:`.stages` (the
  inputs and the store of finished stages, so that a run resumes), :mod:`.provenance` (the code
  a result was made with) and :mod:`.workflow` (the stages in order).
"""

from .fits.simulate import Simulation, simulate
from .measured.synth import Noise, SynthProtocol, SynthResult, synthesize, truth_path, write_synth
from .fits.predictions import pose_errors, predict
from .fits.calibrate import CalibrationResult, calibrate
from .fits.fitoptions import FitRun, FitStart, GridSpec
from .fits.gridsearch import grid_search
from .measured.data import MeasuredData, load_measured_data
from .measured.split import DataSplit, make_split
from .fits.parameters import apply_parameters, read_parameters
from .verdict.signatures import SignatureTest, friction_signature, regression_signature, registration_signature
from .options import DiscrepancyOptions
from .workflow import DiscrepancyResult, run_discrepancy
from .outputs.report import write_report, write_report_from_results

__all__ = [
    "Simulation", "simulate",
    "Noise", "SynthProtocol", "SynthResult", "synthesize", "truth_path", "write_synth",
    "CalibrationResult", "FitRun", "FitStart", "GridSpec", "calibrate", "grid_search", "pose_errors", "predict",
    "MeasuredData", "load_measured_data", "DataSplit", "make_split", "apply_parameters", "read_parameters",
    "SignatureTest", "friction_signature", "regression_signature", "registration_signature",
    "DiscrepancyOptions", "DiscrepancyResult", "run_discrepancy", "write_report", "write_report_from_results",
]
