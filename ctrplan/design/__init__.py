"""Experiment design: the measured trajectory that best settles what a discrepancy run left open.

From the hypotheses a ``ctrplan discrepancy`` result leaves open (an ambiguous pair, or the named
model with parameters the data did not determine), plan a motion, safe to run, that separates the
hypotheses (T-optimality) or determines the parameters (Ds-optimality), and write it ready to run
(``ctrplan design``).

- :mod:`._hypotheses`: hypotheses from a result (:func:`result_hypotheses`);
- :mod:`._criteria`: sensitivities of the hypotheses' predicted tips and the criteria;
- :mod:`._motions`: motion primitives, their feasibility, their jerk-limited trajectory;
- :mod:`._design`: the greedy search (:func:`design_experiment`);
- :mod:`._verdict`: the probability that the workflow's comparison prefers the true hypothesis
  after a motion (:func:`predicted_preference`), and that it names the true hypothesis alone
  (:func:`predicted_naming`);
- :mod:`._from_result`: the design from a discrepancy output folder (:func:`design_from_result`);
- :mod:`._output`: the output folder (:func:`write_design`).
"""

from ._hypotheses import DesignInputError, Hypothesis, read_results, result_hypotheses
from ._criteria import Information, Sensitivities, information, noise_weight, sensitivities
from ._motions import Primitive, motion_data, primitives, sample, trajectory
from ._design import DesignResult, DesignSearch, ExperimentLimits, SensorNoise, design_experiment, drive_from_data
from ._verdict import predicted_naming, predicted_preference
from ._from_result import design_from_result
from ._output import write_design

__all__ = ["DesignInputError", "Hypothesis", "read_results", "result_hypotheses", "Information", "Sensitivities",
           "information", "noise_weight", "sensitivities", "Primitive", "motion_data", "primitives", "sample",
           "trajectory", "DesignResult", "SensorNoise", "ExperimentLimits", "DesignSearch", "design_experiment",
           "design_from_result", "drive_from_data", "predicted_naming", "predicted_preference", "write_design"]
