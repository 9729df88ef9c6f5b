"""The discrepancy workflow: calibrate, diagnose residuals, try candidate effects, name the missing one.

:func:`run_discrepancy` is the list of its stages, each in the module of its kind and each
returning a frozen result in SI units (m, rad, s; Eq. (49) residuals and costs in the paper's
mm + deg of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906):

1. :func:`~ctrplan.discrepancy.setup.load_inputs`: robot, data, baseline parameters, the
   candidate effects of the registry (:mod:`ctrplan.effects`) the data can show, and the store
   of finished stages (:mod:`ctrplan.discrepancy.stages`);
2. :func:`~ctrplan.discrepancy.split.split_samples`: calibration and held-out samples;
3. :func:`~ctrplan.discrepancy.fitting.calibrate_baseline`: the standard model by least squares
   on Eq. (49), evaluated on the held-out samples (:mod:`ctrplan.discrepancy.evaluation`);
4. :func:`~ctrplan.discrepancy.signatures.diagnose_residuals`: each effect's signature test;
5. :func:`~ctrplan.discrepancy.decision.check_noise`: the sensor noise against the residual;
6. :func:`~ctrplan.discrepancy.fitting.refit_contact_baseline` and
   :func:`~ctrplan.discrepancy.fitting.fit_candidates`: every candidate fitted by its entry's
   strategy and scored on the held-out samples;
7. :func:`~ctrplan.discrepancy.decision.name_effect`: the named effect (significant signature,
   significant held-out improvement, BIC, plausible values);
8. :func:`~ctrplan.discrepancy.fitting.fit_second_effect`: a second effect on top of it;
9. :func:`~ctrplan.discrepancy.envelope.predict_with_history`: the history-aware prediction and
   the friction envelope;
10. :func:`~ctrplan.discrepancy.output.write_updated_model` and
    :func:`~ctrplan.discrepancy.output.check_reproduction`: one robot file with what was learned,
    reloaded and checked;
11. :func:`~ctrplan.discrepancy.output.discrepancy_results`: the results dictionary, which
    :mod:`ctrplan.discrepancy.report` formats.

Every stage that fits or evaluates reads its result from ``out_dir/.stages`` when an earlier run
with the same stage key finished it, and stores it there otherwise.
"""

from __future__ import annotations

import time

from .decision import check_noise, name_effect
from .envelope import predict_with_history
from .evaluation import HeldOut, evaluate_held_out
from .fitting import calibrate_baseline, fit_candidates, fit_second_effect, refit_contact_baseline
from .options import DiscrepancyOptions
from .output import check_reproduction, discrepancy_results, write_updated_model
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
        Bad data (see :func:`load_measured_data`), or fewer calibration samples than parameters.
    ModelFileError, PhysicalParameterError
        Bad robot file.
    """
    t_start = time.perf_counter()
    setup = load_inputs(robot_path, data_path, out_dir, options)
    split = split_samples(setup, options, echo)

    def held_out(name, model, params) -> HeldOut:
        return evaluate_held_out(setup, split, name, model, params, n_jobs=options.n_jobs, progress=progress,
                                 echo=echo)

    baseline = calibrate_baseline(setup, split, options, held_out, echo)
    tests = diagnose_residuals(setup, split, baseline, options, echo)
    noise = check_noise(setup, baseline, options, echo)
    contact = refit_contact_baseline(setup, split, baseline, options, echo)
    candidates = fit_candidates(setup, split, baseline, contact, options, held_out, echo)
    naming = name_effect(split, candidates, tests, noise, options, echo)
    combination = fit_second_effect(setup, split, baseline, naming, options, held_out, echo)
    prediction = predict_with_history(setup, split, baseline, naming, noise, options, held_out, echo)
    updated = write_updated_model(setup, baseline, naming, combination, echo)
    reproduction = check_reproduction(setup, split, updated, options, echo)
    results = discrepancy_results(setup, split, baseline, contact, tests, noise, naming, combination, prediction,
                                  updated, reproduction, options, echo)
    results["seconds"] = time.perf_counter() - t_start
    return results
