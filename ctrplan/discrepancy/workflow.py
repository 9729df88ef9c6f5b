"""The discrepancy workflow: calibrate, diagnose residuals, try candidate effects, name the missing one.

:func:`run_discrepancy` is the list of its stages, each in the module of its kind and each
returning a frozen result in SI units (m, rad, s; Eq. (49) residuals and costs in the paper's
mm + deg of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906):

1. :func:`~ctrplan.discrepancy.setup.load_inputs`: robot, data, baseline parameters, the
   candidate effects of the registry (:mod:`ctrplan.effects`) the data can show, and the store
   of finished stages (:mod:`ctrplan.discrepancy.stages`);
2. :func:`~ctrplan.discrepancy.measured.split.split_samples`: an untouched test split held back, the rest
   (development) in blocked cross-validation folds;
3. :func:`~ctrplan.discrepancy.fits.baseline.pilot_fit` and
   :func:`~ctrplan.discrepancy.fits.baseline.calibrate_baseline`: a pilot fit on the development samples
   chooses the buffer around validation and test blocks, the development blocks' length
   (:func:`~ctrplan.discrepancy.measured.split.choose_blocks`: longer blocks, dealt into the folds again,
   where the buffer needs more than half a block) and the prior's scale; then the standard
   model by least squares on Eq. (49) with a prior toward the robot file's tube parameters whose
   strength the out-of-fold error chooses, on the development samples and without each fold;
4. :func:`~ctrplan.discrepancy.verdict.signatures.diagnose_residuals`: each effect's signature test on the
   baseline's out-of-fold residuals;
5. :func:`~ctrplan.discrepancy.verdict.decision.check_noise`: the sensor noise against them;
6. :func:`~ctrplan.discrepancy.fits.fitting.refit_contact_baseline` and
   :func:`~ctrplan.discrepancy.fits.fitting.fit_candidates`: every candidate fitted by its entry's
   strategy and cross-validated;
7. :func:`~ctrplan.discrepancy.verdict.decision.name_effect`: the verdict (named, ambiguous or none);
8. :func:`~ctrplan.discrepancy.fits.pairs.fit_second_effect`: a second effect fitted together with
   it, compared in both directions; when nothing is named, pairs started from the best explanation,
   both effects named together when the pair improves on the baseline at the strictest step of the
   naming rule's family and each adds to the other (:func:`~ctrplan.discrepancy.fits.pairs.joint_naming`);
9. :func:`~ctrplan.discrepancy.outputs.output.evaluate_test_split`: the final model's gain on the test
   split, with intervals (the only use of the test split for a decision's figures);
10. :func:`~ctrplan.discrepancy.verdict.envelope.predict_with_history`: the history-aware prediction and
    the friction envelope on the test split (:func:`~ctrplan.discrepancy.outputs.output.validate_prediction`),
    and :func:`~ctrplan.discrepancy.verdict.coverage.check_bound`: the friction bound's coverage of the
    measured tips and a bound calibrated to cover a chosen share;
11. :func:`~ctrplan.discrepancy.outputs.output.write_updated_model` and
    :func:`~ctrplan.discrepancy.outputs.output.check_reproduction`: one robot file with what was learned,
    reloaded and checked; :func:`~ctrplan.discrepancy.outputs.output.run_cautions`: what a reader must not
    overlook.

The stages' results make one :class:`DiscrepancyResult`, which :mod:`ctrplan.discrepancy.outputs.report`
formats (``results.json``, ``report.md``, plots; millimetres and degrees only there).

Every stage that fits or evaluates reads its result from ``out_dir/.stages`` when an earlier run
with the same stage key finished it, and stores it there otherwise. The workflow logs its progress
through :mod:`logging` (loggers under ``ctrplan.discrepancy``) and prints nothing itself.

Where the time went: :attr:`DiscrepancyResult.stage_seconds` holds the wall time of each stage
(:data:`STAGES`, each candidate separately), :attr:`DiscrepancyResult.stage_reused` the stages
whose stored results came from an earlier run.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from .._log import deprecated_echo
from .fits.baseline import Baseline, calibrate_baseline, pilot_fit
from .verdict.coverage import BoundCalibration, check_bound
from .verdict.decision import Naming, NoiseCheck, check_noise, name_effect
from .verdict.envelope import HistoryPrediction, predict_with_history
from .fits.evaluation import evaluate_rows
from .fits.fitting import CrossValidated, fit_candidates, refit_contact_baseline
from .options import DiscrepancyOptions
from .outputs.output import (PredictionCheck, Reproduction, TestSplit, UpdatedModel, check_reproduction, evaluate_test_split,
                     final_candidate, final_parameters, log_blocks, log_noise, log_pilot, log_split, log_verdict,
                     run_cautions, validate_prediction, write_updated_model)
from .fits.pairs import Combination, fit_second_effect, joint_naming
from .setup import DiscrepancySetup, load_inputs
from .verdict.signatures import diagnose_residuals
from .measured.split import DataSplit, choose_blocks, split_samples

__all__ = ["run_discrepancy", "DiscrepancyOptions", "DiscrepancyResult", "STAGES", "CANDIDATE_STAGE"]

#: The stages of :func:`run_discrepancy` whose wall time :attr:`DiscrepancyResult.stage_seconds`
#: holds, in order (the report's names for them: :data:`ctrplan.discrepancy.outputs.report.STAGE_LABELS`):
#: ``setup`` (:func:`load_inputs`), ``split``, ``baseline`` (the pilot fit and the baseline's
#: calibration), ``signature_tests``, ``noise_check``, ``contact_baseline``, ``candidates`` (one
#: entry per candidate effect, ``CANDIDATE_STAGE.format(effect)``, in the order they are fitted),
#: ``naming``, ``second_effect``, ``test_split``, ``prediction`` (the history-aware prediction
#: and its check), ``bound``, ``updated_model`` (written, reloaded and checked), ``cautions``.
STAGES = ("setup", "split", "baseline", "signature_tests", "noise_check", "contact_baseline", "candidates", "naming",
          "second_effect", "test_split", "prediction", "bound", "updated_model", "cautions")

#: Key of one candidate effect's stage in :attr:`DiscrepancyResult.stage_seconds`.
CANDIDATE_STAGE = "candidate:{}"


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
    cautions : tuple of Caution
        What a reader must not overlook (:func:`~ctrplan.discrepancy.outputs.output.run_cautions`).
    seconds : float
        Wall time of the run [s].
    stage_seconds : dict of str to float
        Wall time of each stage [s], in the order of the run (keys of :data:`STAGES`, with
        ``"candidates"`` replaced by one ``CANDIDATE_STAGE.format(effect)`` per candidate); they
        sum to at most ``seconds``. A candidate's time runs from the end of the one before it to
        the moment its out-of-fold errors were stored (or read), so what its stage does after
        that (its comparisons with the baseline, a few milliseconds) counts to the next candidate
        (the last candidate's runs to the end of the stage). Empty for a result made otherwise.
    stage_reused : dict of str to str
        The stages of ``stage_seconds`` that read stored results of an earlier run (the store of
        ``out_dir/.stages``): ``"reused"`` when they wrote none, ``"partly reused"`` when they also
        computed and stored some. Stages not listed read nothing stored (they computed
        everything, or they store nothing).
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
    stage_seconds: dict = field(default_factory=dict)
    stage_reused: dict = field(default_factory=dict)

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
        """The final model's :class:`~ctrplan.discrepancy.fits.fitting.Candidate` (None: the
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
        """The results as ``results.json`` stores them (:func:`ctrplan.discrepancy.outputs.results.results_dict`;
        report units where a key ends ``_mm`` or ``_deg``)."""
        from .outputs.results import results_dict

        return results_dict(self)


def _reuse(events) -> str | None:
    """``"reused"`` when stage store ``events`` read values an earlier run stored and wrote none,
    ``"partly reused"`` when they did both, else None."""
    kinds = {kind for _, kind, _ in events}
    if "read" not in kinds:
        return None
    return "partly reused" if "written" in kinds else "reused"


class _StageClock:
    """Wall time of each stage of a run, and which stages read stored results of an earlier run
    (from the events of the run's :class:`~ctrplan.discrepancy.stages.StageStore`)."""

    def __init__(self):
        self.seconds = {}
        self.reused = {}
        self.store = None       # the run's StageStore, once the setup has made it
        self._windows = {}      # stage -> (start, end, store events during it)

    @contextmanager
    def stage(self, name: str):
        """Time the block as stage ``name``."""
        n0 = len(self.store.events) if self.store is not None else 0
        t0 = time.perf_counter()
        yield
        t1 = time.perf_counter()
        events = self.store.events[n0:] if self.store is not None else []
        self.seconds[name] = t1 - t0
        self._windows[name] = (t0, t1, events)
        if _reuse(events):
            self.reused[name] = _reuse(events)

    def divide(self, name: str, parts: dict) -> None:
        """Replace stage ``name`` by its ``parts`` (key -> name of the stored value that ends it,
        in order): each part runs from the end of the one before it to the last store event of
        its value, the last part to the end of the stage. Left whole when a part's value was
        neither read nor written during the stage."""
        t0, t1, events = self._windows[name]
        ends = []
        for key, value in parts.items():
            at = [t for n, _, t in events if n == value]
            if not at:
                return
            ends.append(at[-1])
        if not ends:
            return
        ends[-1] = t1
        seconds, reused, start = {}, {}, t0
        for key, end in zip(parts, ends):
            seconds[key] = max(end - start, 0.0)
            inside = [e for e in events if start < e[2] <= end]
            if _reuse(inside):
                reused[key] = _reuse(inside)
            start = max(start, end)
        merged = {}
        for k, v in self.seconds.items():
            merged.update(seconds if k == name else {k: v})
        self.seconds = merged
        self.reused.pop(name, None)
        self.reused.update(reused)


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
        Measured data (:func:`ctrplan.discrepancy.measured.data.load_measured_data`).
    out_dir : path
        Report folder; finished stages are kept in ``out_dir/.stages`` and reused by a rerun
        with the same inputs and options. The updated robot file is written there;
        :func:`ctrplan.discrepancy.outputs.report.write_report` writes the report.
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
    clock = _StageClock()
    with clock.stage("setup"):
        setup = load_inputs(robot_path, data_path, out_dir, options)
    clock.store = setup.stages
    with clock.stage("split"):
        split = split_samples(setup, options)
        log_split(setup.data, split)
    with clock.stage("baseline"):
        split, scale, pilot = pilot_fit(setup, split, options)
        log_pilot(split, scale)
        # the pilot's residuals at the development samples (stored by pilot_fit, read back)
        residual = evaluate_rows(setup, split.dev_rows, "pilot-residual", "standard",
                                 dict(zip(*pilot.all_parameters())), n_jobs=options.n_jobs).residual_base
        piloted, split = split, choose_blocks(setup, split, residual, options)
        log_blocks(piloted, split)
        baseline = calibrate_baseline(setup, split, options, progress, residual_scale=scale)
    with clock.stage("signature_tests"):
        tests = diagnose_residuals(setup, split, baseline, options)
    with clock.stage("noise_check"):
        noise = check_noise(setup, split, baseline, options)
        log_noise(noise)
    with clock.stage("contact_baseline"):
        contact = refit_contact_baseline(setup, split, baseline, options)
    with clock.stage("candidates"):
        candidates = fit_candidates(setup, split, baseline, contact, options, progress)
    # each candidate's stages end with its out-of-fold errors (fitting.cross_validate -> evaluation.out_of_fold)
    clock.divide("candidates", {CANDIDATE_STAGE.format(e): f"oof-{e}" for e in candidates})
    with clock.stage("naming"):
        naming = name_effect(split, candidates, tests, noise, options, baseline=baseline)
        log_verdict(naming, noise)
    with clock.stage("second_effect"):
        combination = fit_second_effect(setup, split, baseline, contact, naming, options, progress)
        joint = joint_naming(naming, combination)
        if joint is not naming:
            naming = joint
            log_verdict(naming, noise)
    with clock.stage("test_split"):
        test = evaluate_test_split(setup, split, baseline, naming, combination, options, progress)
    with clock.stage("prediction"):
        final_params = final_parameters(naming, combination, baseline)
        prediction = predict_with_history(setup, split, baseline, naming, noise, options, progress,
                                          final_params=final_params)
        prediction_check = validate_prediction(prediction, split)
    with clock.stage("bound"):
        final = final_candidate(naming, combination)
        bound = (check_bound(setup, split, baseline.cv if final is None else final.cv, test.final, final_params,
                             noise, options) if options.bound_samples > 0 else None)
    with clock.stage("updated_model"):
        updated = write_updated_model(setup, baseline, naming, combination, test, bound=bound,
                                      prediction_check=prediction_check)
        reproduction = check_reproduction(setup, split, updated, test, options)
    with clock.stage("cautions"):
        notes = run_cautions(naming, combination, baseline, test)
    return DiscrepancyResult(setup=setup, split=split, baseline=baseline, tests=tests, noise=noise, contact=contact,
                             naming=naming, combination=combination, test=test, prediction=prediction,
                             prediction_check=prediction_check, bound=bound, updated=updated,
                             reproduction=reproduction, options=options, cautions=notes,
                             seconds=time.perf_counter() - t_start, stage_seconds=dict(clock.seconds),
                             stage_reused=dict(clock.reused))
