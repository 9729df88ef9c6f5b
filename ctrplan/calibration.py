"""What a robot file records about measurements, as typed objects: its ``[bound_calibration]`` and
``[prediction_validation]`` tables (written by ``ctrplan discrepancy``, read by planning).

:func:`ctrplan.io.robot_file.load_robot_calibration` reads them from a robot file, and a loaded
scenario carries them (``Scenario.calibration``); the planner reads them from there:

- :class:`CalibratedBound`: the friction bound calibrated on measured tips,
  ``factor x (bound + noise_margin_m)``, which ranks paths (:meth:`CalibratedBound.effective_weight`)
  and is reported beside the model's bound (:meth:`CalibratedBound.apply`);
- :class:`PredictionValidation`: how the history-aware prediction did against the standard model
  on measurements, which decides the model task-space goals are aimed with;
- :class:`RobotCalibration`: both, each None when the file has no such table.

All values are in SI units (m); coverages are fractions in [0, 1]. The first two are pydantic
models and are the robot file's schema of their tables: a table read from a file is one of them
(constructing one checks its values the same way and raises ``pydantic.ValidationError``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

__all__ = ["CalibratedBound", "PredictionValidation", "RobotCalibration"]


class _Table(BaseModel):
    """Base of the two tables: they are also the robot file's schema for them
    (:class:`ctrplan.io.robot_file.RobotDocument`), with its rules: unknown keys, coercions and
    non-finite numbers are errors, and a loaded table is immutable."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class CalibratedBound(_Table):
    """A friction bound calibrated on measurements (the robot file's ``[bound_calibration]``).

    The calibrated bound of a configuration whose model bound is ``b`` [m] is
    ``factor x (b + noise_margin_m)``: split-conformal on the ratio of measured tip error to bound,
    so that it covers ``target_coverage`` of measured tips
    (:mod:`ctrplan.discrepancy.verdict.coverage`).

    Attributes
    ----------
    factor : float
        Multiplier c > 0 [-].
    target_coverage : float
        Share of measured tips the calibrated bound is meant to cover, in (0, 1).
    noise_margin_m : float
        Margin m >= 0 added to the bound before scaling (the tracker noise) [m].
    method : str
        How it was calibrated (e.g. ``"split-conformal"``); empty when not recorded.
    noise_multiple : float or None
        The margin in multiples of the tracker noise [-].
    calibration_samples, test_samples : int or None
        Measured samples of the calibration and of the untouched test split.
    test_coverage : float or None
        Share of test-split tips the calibrated bound covers, in [0, 1].
    test_coverage_low, test_coverage_high : float or None
        Its 95 % interval.
    raw_bound_test_coverage : float or None
        Share of test-split tips the model's bound alone covers.
    failing : bool
        The test coverage is below the target (the calibration fails on the test split).
    status : {"shown", "not shown", "failed"} or None
        The verdict of the test split: its coverage interval's lower end at or above the target
        (less the tolerance), its upper end below it, or neither
        (:func:`ctrplan.discrepancy.verdict.coverage.coverage_status`). Files written before this rule
        hold "met", "failing" or "conservative", which are read as they are.
    coverage_tolerance : float or None
        The tolerance behind ``status`` and ``conservative`` [-]: "shown" compares the interval's
        lower end with ``target_coverage - coverage_tolerance`` (None: not recorded, files written
        before it was).
    conservative : bool
        The test coverage's interval lies above the target by more than the tolerance.
    data_file, data_sha256, date : str
        The measurements it was calibrated on (empty when not recorded).
    """

    factor: Annotated[float, Field(gt=0.0)]
    target_coverage: Annotated[float, Field(gt=0.0, lt=1.0)]
    noise_margin_m: Annotated[float, Field(ge=0.0)] = 0.0
    method: str = ""
    noise_multiple: Annotated[float, Field(ge=0.0)] | None = None
    calibration_samples: Annotated[int, Field(ge=0)] | None = None
    test_samples: Annotated[int, Field(ge=0)] | None = None
    test_coverage: Annotated[float, Field(ge=0.0, le=1.0)] | None = None
    test_coverage_low: Annotated[float, Field(ge=0.0, le=1.0)] | None = None
    test_coverage_high: Annotated[float, Field(ge=0.0, le=1.0)] | None = None
    raw_bound_test_coverage: Annotated[float, Field(ge=0.0, le=1.0)] | None = None
    failing: bool = False
    status: Literal["shown", "not shown", "failed", "met", "failing", "conservative"] | None = None
    coverage_tolerance: Annotated[float, Field(ge=0.0, lt=1.0)] | None = None
    conservative: bool = False
    data_file: str = ""
    data_sha256: str = ""
    date: str = ""

    def apply(self, bound) -> np.ndarray:
        """The calibrated bound ``factor (bound + noise_margin_m)``.

        Parameters
        ----------
        bound : array-like
            The model's bound [m], any shape.

        Returns
        -------
        ndarray
            Same shape as ``bound`` [m].
        """
        return self.factor * (np.asarray(bound, float) + self.noise_margin_m)

    def effective_weight(self, weight: float) -> float:
        """The bound weight that ranks paths by the calibrated bound.

        Planning minimises ``L + w integral(b) ds``; with the calibrated bound ``c (b + m)`` in
        place of ``b`` the cost is ``(1 + w c m) L + w c integral(b) ds``, which has the same
        minimiser as ``L + w' integral(b) ds`` with ``w' = w c / (1 + w c m)``.

        Parameters
        ----------
        weight : float
            ``[planner] bound_weight`` w [1/m].

        Returns
        -------
        float
            w' [1/m]; 0 when ``weight`` is 0.
        """
        if weight == 0.0:
            return float(weight)
        c, m = float(self.factor), float(self.noise_margin_m)
        return float(weight * c / (1.0 + weight * c * m))


class PredictionValidation(_Table):
    """The history-aware prediction against the standard model on measurements (the robot file's
    ``[prediction_validation]``): tip position errors on the untouched test split.

    Attributes
    ----------
    standard_mean_m, standard_max_m : float
        Mean and largest tip error of the standard model [m].
    history_mean_m, history_max_m : float
        Mean and largest tip error of the history-aware prediction [m].
    history_beats_standard : bool
        The 95 % interval of the per-unit paired difference of their mean errors (history minus
        standard) lies below zero.
    difference_mean_m, difference_low_m, difference_high_m : float or None
        That difference and its interval [m].
    test_units, test_samples : int or None
        Units (trajectories) and samples of the test split.
    data_file, data_sha256, date : str
        The measurements (empty when not recorded).
    """

    standard_mean_m: Annotated[float, Field(ge=0.0)]
    standard_max_m: Annotated[float, Field(ge=0.0)]
    history_mean_m: Annotated[float, Field(ge=0.0)]
    history_max_m: Annotated[float, Field(ge=0.0)]
    history_beats_standard: bool
    difference_mean_m: float | None = None
    difference_low_m: float | None = None
    difference_high_m: float | None = None
    test_units: Annotated[int, Field(ge=0)] | None = None
    test_samples: Annotated[int, Field(ge=0)] | None = None
    data_file: str = ""
    data_sha256: str = ""
    date: str = ""


@dataclass(frozen=True)
class RobotCalibration:
    """What a robot file records about measurements; the default records nothing.

    Attributes
    ----------
    bound : CalibratedBound or None
        Its ``[bound_calibration]``; None without one (the bound is the model's).
    prediction : PredictionValidation or None
        Its ``[prediction_validation]``; None without one (the prediction is not validated).
    """

    bound: CalibratedBound | None = None
    prediction: PredictionValidation | None = None
