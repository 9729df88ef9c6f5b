"""The discrepancy workflow: calibrate, diagnose residuals, try candidate effects, name the missing one.

:func:`run_discrepancy` is the list of its stages, each in the module of its kind and each
returning a frozen result in SI units (m, rad, s; Eq. (49) residuals and costs in the paper's
mm + deg of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906):

1. :func:`~ctrplan.discrepancy.setup.load_inputs`: robot, data, baseline parameters, the
   candidate effects of the registry (:mod:`ctrplan.effects`) the data can show, and the store
   of finished stages (:mod:`ctrplan.discrepancy.stages`);
2. :func:`~ctrplan.discrepancy.split.split_samples`: an untouched test split held back, the rest
   (development) in blocked cross-validation folds;
3. :func:`~ctrplan.discrepancy.baseline.pilot_fit` and
   :func:`~ctrplan.discrepancy.baseline.calibrate_baseline`: a pilot fit on the development samples
   chooses the buffer around validation and test blocks and the prior's scale; then the standard
   model by least squares on Eq. (49) with a prior toward the robot file's tube parameters whose
   strength the out-of-fold error chooses, on the development samples and without each fold;
4. :func:`~ctrplan.discrepancy.signatures.diagnose_residuals`: each effect's signature test on the
   baseline's out-of-fold residuals;
5. :func:`~ctrplan.discrepancy.decision.check_noise`: the sensor noise against them;
6. :func:`~ctrplan.discrepancy.fitting.refit_contact_baseline` and
   :func:`~ctrplan.discrepancy.fitting.fit_candidates`: every candidate fitted by its entry's
   strategy and cross-validated;
7. :func:`~ctrplan.discrepancy.decision.name_effect`: the verdict (named, ambiguous or none);
8. :func:`~ctrplan.discrepancy.pairs.fit_second_effect`: a second effect fitted together with
   it, compared in both directions;
9. :func:`~ctrplan.discrepancy.output.evaluate_test_split`: the final model's gain on the test
   split, with intervals (the only use of the test split for a decision's figures);
10. :func:`~ctrplan.discrepancy.envelope.predict_with_history`: the history-aware prediction and
    the friction envelope on the test split (:func:`~ctrplan.discrepancy.output.validate_prediction`),
    and :func:`~ctrplan.discrepancy.coverage.check_bound`: the friction bound's coverage of the
    measured tips and a bound calibrated to cover a chosen share;
11. :func:`~ctrplan.discrepancy.output.write_updated_model` and
    :func:`~ctrplan.discrepancy.output.check_reproduction`: one robot file with what was learned,
    reloaded and checked; :func:`~ctrplan.discrepancy.output.run_cautions`: what a reader must not
    overlook.

The stages' results make one :class:`DiscrepancyResult`, which :mod:`ctrplan.discrepancy.report`
formats (``results.json``, ``report.md``, plots; millimetres and degrees only there).

Every stage that fits or evaluates reads its result from ``out_dir/.stages`` when an earlier run
with the same stage key finished it, and stores it there otherwise. The workflow logs its progress
through :mod:`logging` (loggers under ``ctrplan.discrepancy``) and prints nothing itself.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from .._log import deprecated_echo
from .baseline import Baseline, calibrate_baseline, pilot_fit
from .coverage import BoundCalibration, check_bound
from .decision import Naming, NoiseCheck, check_noise, name_effect
from .envelope import HistoryPrediction, predict_with_history
from .fitting import CrossValidated, fit_candidates, refit_contact_baseline
from .options import DiscrepancyOptions
from .output import (PredictionCheck, Reproduction, TestSplit, UpdatedModel, check_reproduction, evaluate_test_split,
                     final_candidate, final_parameters, run_cautions, validate_prediction, write_updated_model)
from .pairs import Combination, fit_second_effect
from .setup import DiscrepancySetup, load_inputs
from .signatures import diagnose_residuals
from .split import DataSplit, split_samples

__all__ = ["run_discrepancy", "DiscrepancyOptions", "DiscrepancyResult"]


@dataclass(frozen=True, eq=False)
class DiscrepancyResult:
    """What a run of the discrepancy workflow found: every stage's result, in SI units (Eq. (49)
    residuals and costs in the paper's mm + deg).

    Attributes
    ----------
    setup : DiscrepancySetup
        Stage 1: the robot, the data, the baseline parameters and the effects tried.
    split : DataSplit
        Stage 2: the test split, the folds and the buffer.
    baseline : Baseline
        Stage 3: the calibrated baseline and the choice of its prior.
    tests : mapping of str to SignatureTest
        Stage 4: each effect's signature test on the baseline's out-of-fold residuals.
    noise : NoiseCheck
        Stage 5.
    contact : CrossValidated or None
        Stage 6a: the clearance-model refit of the tube parameters.
    naming : Naming
        Stages 6b and 7: every candidate, fitted and cross-validated, and the verdict.
    combination : Combination or None
        Stage 8: a second effect fitted with the named one.
    test : TestSplit
        Stage 10: the robot file, the baseline and the final model on the untouched test split.
    prediction : HistoryPrediction or None
        Stage 9: the history-aware prediction (None without a friction candidate).
    prediction_check : PredictionCheck or None
    bound : BoundCalibration or None
        The friction bound against the measured tips and its calibration (None when
        ``options.bound_samples`` is 0).
    updated : UpdatedModel
        Stage 11: the written robot file.
    reproduction : Reproduction
        Stage 12: that file reloaded, on the test split.
    options : DiscrepancyOptions
    cautions : tuple of str
        What a reader must not overlook (:func:`~ctrplan.discrepancy.output.run_cautions`).
    seconds : float
        Wall time of the run [s].
    """

    setup: DiscrepancySetup
    split: DataSplit
    baseline: Baseline
    tests: dict
    noise: NoiseCheck
    contact: CrossValidated | None
    naming: Naming
    combination: Combination | None
    test: TestSplit
    prediction: HistoryPrediction | None
    prediction_check: PredictionCheck | None
    bound: BoundCalibration | None
    updated: UpdatedModel
    reproduction: Reproduction
    options: DiscrepancyOptions
    cautions: tuple
    seconds: float

    @property
    def verdict(self) -> str:
        """``"named"``, ``"ambiguous"`` or ``"none"``."""
        return self.naming.verdict

    @property
    def named_effect(self) -> str | None:
        """The best eligible effect (the first of an ambiguous pair), or None."""
        return self.naming.named

    @property
    def named_effects(self) -> tuple:
        """The effects of the final model (the written robot file), e.g. a named pair."""
        return self.updated.named_effects

    @property
    def final(self):
        """The final model's :class:`~ctrplan.discrepancy.fitting.Candidate` (None: the
        recalibrated baseline)."""
        return final_candidate(self.naming, self.combination)

    @property
    def final_parameters(self) -> dict:
        """The final model's parameters [SI]."""
        return final_parameters(self.naming, self.combination, self.baseline)

    @property
    def updated_model_file(self) -> Path:
        """The written robot file."""
        return self.updated.path

    def to_dict(self) -> dict:
        """The results as ``results.json`` stores them (:func:`ctrplan.discrepancy.report.results_dict`;
        report units where a key ends ``_mm`` or ``_deg``)."""
        from .report import results_dict

        return results_dict(self)


@deprecated_echo
def run_discrepancy(robot_path, data_path, out_dir, options: DiscrepancyOptions = DiscrepancyOptions(),
                    echo=None, progress: bool = True) -> DiscrepancyResult:
    """Run the whole workflow and return its results (see the module docstring).

    Parameters
    ----------
    robot_path : path
        Robot model file with the candidate effects switched off (or not: the baseline uses
        the standard model, which ignores friction and clearance).
    data_path : path
        Measured data (:func:`ctrplan.discrepancy.data.load_measured_data`).
    out_dir : path
        Report folder; finished stages are kept in ``out_dir/.stages`` and reused by a rerun
        with the same inputs and options. The updated robot file is written there;
        :func:`ctrplan.discrepancy.report.write_report` writes the report.
    options : DiscrepancyOptions
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).
    progress : bool
        Progress bars of model evaluations.

    Returns
    -------
    DiscrepancyResult

    Raises
    ------
    DataFileError
        Bad data (see :func:`load_measured_data`), or too few samples for the split.
    ModelFileError, PhysicalParameterError
        Bad robot file.
    """
    t_start = time.perf_counter()
    setup = load_inputs(robot_path, data_path, out_dir, options)
    split = split_samples(setup, options)
    split, scale, _ = pilot_fit(setup, split, options)
    baseline = calibrate_baseline(setup, split, options, progress, residual_scale=scale)
    tests = diagnose_residuals(setup, split, baseline, options)
    noise = check_noise(setup, split, baseline, options)
    contact = refit_contact_baseline(setup, split, baseline, options)
    candidates = fit_candidates(setup, split, baseline, contact, options, progress)
    naming = name_effect(split, candidates, tests, noise, options)
    combination = fit_second_effect(setup, split, baseline, contact, naming, options, progress)
    test = evaluate_test_split(setup, split, baseline, naming, combination, options, progress)
    final_params = final_parameters(naming, combination, baseline)
    prediction = predict_with_history(setup, split, baseline, naming, noise, options, progress,
                                      final_params=final_params)
    prediction_check = validate_prediction(prediction, split)
    final = final_candidate(naming, combination)
    bound = (check_bound(setup, split, baseline.cv if final is None else final.cv, test.final, final_params, noise,
                         options) if options.bound_samples > 0 else None)
    updated = write_updated_model(setup, baseline, naming, combination, test, bound=bound,
                                  prediction_check=prediction_check)
    reproduction = check_reproduction(setup, split, updated, test, options)
    notes = run_cautions(naming, combination, baseline, test)
    return DiscrepancyResult(setup=setup, split=split, baseline=baseline, tests=tests, noise=noise, contact=contact,
                             naming=naming, combination=combination, test=test, prediction=prediction,
                             prediction_check=prediction_check, bound=bound, updated=updated,
                             reproduction=reproduction, options=options, cautions=notes,
                             seconds=time.perf_counter() - t_start)
