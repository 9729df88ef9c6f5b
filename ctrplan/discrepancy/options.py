"""Options of the discrepancy workflow and the constants of its rules."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io.ros2 import BagSelection
from ..mechanics import ModelSettings

__all__ = ["DiscrepancyOptions", "FIT_VERSION", "MIN_REST_PAIRS", "ALPHA_STEP",
           "TRAJECTORY_ROTATION_BIN", "TRAJECTORY_TRANSLATION_BIN", "ENVELOPE_NOISE_FACTOR",
           "CONFIDENCE", "BOOTSTRAP_RESAMPLES", "NOT_IN_STAGE_KEY"]

#: Field metadata of an option that changes no stored stage (a worker count, a test's level, what
#: is evaluated after the fits): :func:`~ctrplan.discrepancy.stages.stage_key` leaves it out.
NOT_IN_STAGE_KEY = {"stage_key": False}

#: Rests (consecutive samples at identical joints) needed to estimate the noise from the data.
MIN_REST_PAIRS = 10
#: Level of the reported intervals (improvements, parameters, the test split's figures).
CONFIDENCE = 0.95
#: Block-bootstrap resamples of the test split's intervals.
BOOTSTRAP_RESAMPLES = 2000
#: Finite-difference step of d tip / d alpha_i in the backlash and gradual-friction signatures [rad].
ALPHA_STEP = 1e-3
#: Bins that group nearby configurations of a continuous trajectory for the friction test.
TRAJECTORY_ROTATION_BIN = float(np.deg2rad(15.0))
TRAJECTORY_TRANSLATION_BIN = 5e-3
#: Envelope margin: 95 % of 3-D Gaussian noise vectors are shorter than 2.80 sigma per component,
#: i.e. 1.62 times their rms length.
ENVELOPE_NOISE_FACTOR = 1.62
#: Version of the fitting procedure in the stage key: 2 = two-stage least squares (error components,
#: then Eq. (49)); 3 = stage 2 with the norms' curvature in its Gauss-Newton model and the BIC
#: stopping rule; 4 = effects from the registry, the history of every pair from ctrplan.history
#: along the whole record; 5 = a test split and cross-validation folds, parameter uncertainties,
#: baseline parameters bounded about the robot file's values; 6 = every fold fit from the same cold
#: start as the development fit, buffers, a prior toward the robot file's tube parameters, bounds
#: widened where a fit ends at them, pairs fitted jointly, a smooth time-shift interpolant; 7 =
#: contact solves of a fit started from the fit's previous evaluation at the same sample, to
#: the tighter tolerances of :data:`~ctrplan.discrepancy.fits.simulate.WARM_OUTER_TOL`; 8 = standard
#: errors over clusters of neighbouring blocks with t intervals, values left on a bound widened
#: without a refit flagged, blocks lengthened where the residuals' correlation needs a longer
#: buffer, comparisons of two candidates corrected for the folds' shared training data; 9 =
#: Jacobians of both least-squares stages moved by rank-one updates between forward differences,
#: the evaluation budget counted in model evaluations. Stages written by an earlier version are
#: redone.
FIT_VERSION = 9


@dataclass(frozen=True)
class DiscrepancyOptions:
    """Options of :func:`~ctrplan.discrepancy.workflow.run_discrepancy`.

    The options that change no stored stage carry :data:`NOT_IN_STAGE_KEY` in their field
    metadata (a rerun with another value reuses the finished fits and evaluations).

    Attributes
    ----------
    fit : tuple of str or None
        Baseline parameters (default :func:`~ctrplan.discrepancy.setup.default_baseline_parameters`).
    effects : tuple of str or None
        Candidate effects to test and try (names of :data:`ctrplan.effects.REGISTRY`); None: every
        registered effect, in registry order.
    frame : PoseFrame, str or None
        Frame of the measurements (default from the file type, see
        :func:`ctrplan.discrepancy.measured.data.load_measured_data`). "tracker" fits a registration.
    bag : BagSelection or None
        What to read when the data is a ROS 2 bag (:class:`ctrplan.io.ros2.BagSelection`; None:
        the bag's only joint-state and pose topics).
    test_fraction : float
        Share of the units held back as the untouched test split, at least
        :data:`~ctrplan.discrepancy.measured.split.MIN_TEST_UNITS` units
        (:func:`~ctrplan.discrepancy.measured.split.make_split`).
    n_blocks : int or None
        Time blocks a continuous motion is cut into (the units of its split and tests); None: from
        the record's length.
    n_folds : int or None
        Cross-validation folds of the development data; None: from the number of units.
    max_calibration_samples : int
        Calibration samples a least-squares fit uses at most (whole units, evenly chosen).
    max_contact_samples : int
        Of those, the samples a fit of the clearance or friction model uses at most (evenly
        chosen; a contact solve costs about 30 standard ones); the coarse friction grid uses
        ``friction_search_samples``.
    significance : float
        Family-wise level of the cross-validated improvement tests (Holm over the candidates
        tried alone, and over the pairs), the level of the comparisons between candidates and of
        the signature tests, and the false-alarm rate of the noise test.
    prior_strengths : tuple of float
        Strengths tau of the prior toward the robot file's tube parameters among which the
        baseline's out-of-fold error chooses (:func:`~ctrplan.discrepancy.fits.baseline.calibrate_baseline`;
        a relative change tau costs one residual of the pilot fit's rms); 0 (the robot file's
        parameters, only a registration fitted) is always among them, ``inf`` is no prior.
    n_permutations : int
    friction_grid : tuple of float
        Coarse grid of every friction coefficient.
    friction_search_samples : int
        Samples scoring the coarse friction grid.
    max_evaluations : int
        Model evaluations allowed per least-squares fit with the standard model (Jacobian
        columns included; about 6 per step for 5 parameters).
    max_contact_evaluations : int
        The same for the clearance-model refit (about 30 times dearer per evaluation).
    ds : float
        Arc-length step [m].
    n_jobs : int
    seed : int
    noise_position : float or None
        rms tip position noise of the sensor [m] as the data's source states it (e.g. 0.2 mm
        for Ha's trajectory); None: estimated from rests (consecutive samples at identical
        joints) or repeated configurations, if the data has them.
    envelope_samples : int
        Held-out samples (evenly spaced) at which the friction envelope (all 2^(n-1) bounding
        solutions) is evaluated for the coverage figures; 0 skips it.
    reference_friction : tuple of float, shape (n - 1,), or None
        Friction coefficients [-] (e.g. published for the robot) with which the history-aware
        prediction and the envelope are also evaluated, next to the fitted ones.
    bound_target : float
        Share of measured tips the calibrated bound is to cover
        (:mod:`~ctrplan.discrepancy.verdict.coverage`).
    bound_samples : int
        Development samples (and, separately, test samples) at which the friction bound is
        evaluated for its calibration and its check; 0 skips them.
    """

    fit: tuple | None = None
    effects: tuple | None = field(default=None, metadata=NOT_IN_STAGE_KEY)   # the effects tried enter it
    frame: str | None = None
    bag: BagSelection | None = None
    test_fraction: float = 0.2
    n_blocks: int | None = None
    n_folds: int | None = None
    max_calibration_samples: int = 300
    max_contact_samples: int = 150
    significance: float = field(default=0.01, metadata=NOT_IN_STAGE_KEY)
    prior_strengths: tuple = (0.003, 0.01, 0.03, 0.1, float("inf"))
    n_permutations: int = field(default=999, metadata=NOT_IN_STAGE_KEY)
    friction_grid: tuple = (0.0, 0.1, 0.2, 0.3, 0.4)
    friction_search_samples: int = 96
    max_evaluations: int = 400
    max_contact_evaluations: int = 150
    ds: float = 3e-3
    n_jobs: int = field(default=1, metadata=NOT_IN_STAGE_KEY)
    seed: int = 0
    noise_position: float | None = field(default=None, metadata=NOT_IN_STAGE_KEY)
    envelope_samples: int = field(default=0, metadata=NOT_IN_STAGE_KEY)
    reference_friction: tuple | None = field(default=None, metadata=NOT_IN_STAGE_KEY)
    bound_target: float = field(default=0.9, metadata=NOT_IN_STAGE_KEY)
    bound_samples: int = field(default=200, metadata=NOT_IN_STAGE_KEY)

    def settings(self) -> ModelSettings:
        """Model settings of every fit and evaluation (no multistart stability search in
        calibration: it does not change the solution found)."""
        return ModelSettings(ds=self.ds, multistart=0)
