"""The discrepancy workflow: calibrate, diagnose residuals, try candidate effects, name the missing one.

:func:`run_discrepancy` is the list of its stages, each in the module of its kind and each
returning a frozen result in SI units (m, rad, s; Eq. (49) residuals and costs in the paper's
mm + deg of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906):

1. :func:`~ctrplan.discrepancy.setup.load_inputs`: robot, data, baseline parameters, the
   candidate effects of the registry (:mod:`ctrplan.effects`) the data can show, and the store
   of finished stages (:mod:`ctrplan.discrepancy.stages`);
2. :func:`~ctrplan.discrepancy.split.split_samples`: an untouched test split held back, the rest
   (development) in blocked cross-validation folds;
3. :func:`~ctrplan.discrepancy.fitting.pilot_fit` and
   :func:`~ctrplan.discrepancy.fitting.calibrate_baseline`: a pilot fit on the development samples
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
8. :func:`~ctrplan.discrepancy.fitting.fit_second_effect`: a second effect fitted together with
   it, compared in both directions;
9. :func:`~ctrplan.discrepancy.output.evaluate_test_split`: the final model's gain on the test
   split, with intervals (the only use of the test split for a decision's figures);
10. :func:`~ctrplan.discrepancy.envelope.predict_with_history`: the history-aware prediction and
    the friction envelope on the test split (:func:`~ctrplan.discrepancy.output.validate_prediction`),
    and :func:`~ctrplan.discrepancy.coverage.check_bound`: the friction bound's coverage of the
    measured tips and a bound calibrated to cover a chosen share;
11. :func:`~ctrplan.discrepancy.output.write_updated_model` and
    :func:`~ctrplan.discrepancy.output.check_reproduction`: one robot file with what was learned,
    reloaded and checked;
12. :func:`~ctrplan.discrepancy.output.discrepancy_results`: the results dictionary, which
    :mod:`ctrplan.discrepancy.report` formats.

Every stage that fits or evaluates reads its result from ``out_dir/.stages`` when an earlier run
with the same stage key finished it, and stores it there otherwise.
"""

from __future__ import annotations

import time

from .decision import check_noise, name_effect
from .envelope import predict_with_history
from .fitting import calibrate_baseline, fit_candidates, fit_second_effect, pilot_fit, refit_contact_baseline
from .options import DiscrepancyOptions
from .coverage import check_bound
from .output import (check_reproduction, discrepancy_results, evaluate_test_split, final_candidate, final_parameters,
                     validate_prediction, write_updated_model)
from .setup import load_inputs
from .signatures import diagnose_residuals
from .split import split_samples

__all__ = ["run_discrepancy", "DiscrepancyOptions"]


def run_discrepancy(robot_path, data_path, out_dir, options: DiscrepancyOptions = DiscrepancyOptions(),
                    echo=print, progress: bool = True) -> dict:
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
        with the same inputs and options.
    options : DiscrepancyOptions
    echo : callable
        Receives one line per step.
    progress : bool
        Progress bars of model evaluations.

    Returns
    -------
    dict
        JSON-ready results; arrays for plots under the key ``"_arrays"``.

    Raises
    ------
    DataFileError
        Bad data (see :func:`load_measured_data`), or too few samples for the split.
    ModelFileError, PhysicalParameterError
        Bad robot file.
    """
    t_start = time.perf_counter()
    setup = load_inputs(robot_path, data_path, out_dir, options)
    split = split_samples(setup, options, echo)
    split, scale, _ = pilot_fit(setup, split, options, echo)
    baseline = calibrate_baseline(setup, split, options, echo, progress, residual_scale=scale)
    tests = diagnose_residuals(setup, split, baseline, options, echo)
    noise = check_noise(setup, split, baseline, options, echo)
    contact = refit_contact_baseline(setup, split, baseline, options, echo)
    candidates = fit_candidates(setup, split, baseline, contact, options, echo, progress)
    naming = name_effect(split, candidates, tests, noise, options, echo)
    combination = fit_second_effect(setup, split, baseline, contact, naming, options, echo, progress)
    test = evaluate_test_split(setup, split, baseline, naming, combination, options, echo, progress)
    prediction = predict_with_history(setup, split, baseline, naming, noise, options, echo, progress,
                                      final_params=final_parameters(naming, combination, baseline))
    prediction_check = validate_prediction(prediction, split, options.seed)
    final = final_candidate(naming, combination)
    bound = (check_bound(setup, split, baseline.cv if final is None else final.cv, test.final,
                         final_parameters(naming, combination, baseline), noise, options, echo)
             if options.bound_samples > 0 else None)
    updated = write_updated_model(setup, baseline, naming, combination, test, echo, bound=bound,
                                  prediction_check=prediction_check)
    reproduction = check_reproduction(setup, split, updated, test, options, echo)
    results = discrepancy_results(setup, split, baseline, contact, tests, noise, naming, combination, test, prediction,
                                  updated, reproduction, options, echo, bound=bound, prediction_check=prediction_check)
    results["seconds"] = time.perf_counter() - t_start
    return results
