"""The discrepancy workflow: calibrate, diagnose residuals, try candidate effects, name the missing one.

1. Calibrate the baseline (standard model; by default in-plane precurvatures and relative
   bending stiffnesses, plus the registration when the data are in a tracker frame) by least
   squares on Eq. (49) of Ha, Fagogenis & Dupont 2019, on a calibration split made of whole
   configurations or sequences.
2. Diagnose the held-out residuals with one signature test per candidate effect
   (:mod:`ctrplan.discrepancy.signatures`).
3. Try each candidate: switch it on, fit its parameters with the baseline's refitted (friction
   coefficients by grid search, Section V-C; the clearance and friction candidates share tube
   parameters refitted once with the clearance model, as in the paper's Table VII), and measure
   the error on the held-out split.
4. Name the missing effect: among candidates whose signature test is significant, whose held-out
   improvement is significant (paired sign-flip test over held-out units) and whose BIC beats
   the baseline's by :data:`BIC_MARGIN` (eligible), the plausible one (fitted values within
   their plausible ranges, :mod:`ctrplan.discrepancy.parameters`) with the largest held-out
   improvement; others that explain the held-out data equally well are listed. When none is
   named, say whether the baseline's held-out residual is consistent with the sensor noise
   (stated, or estimated from rests or repeats) or not explained by any candidate.
   Candidates include the history effects of :mod:`ctrplan.discrepancy.history` (drive
   backlash, tracker time offset, gradually developing friction).
5. Write the updated robot model file, load it back and check that it reproduces the errors.

``run_discrepancy`` composes these stages; each returns a frozen result in SI units (m, rad, s;
Eq. (49) residuals and costs in the paper's mm + deg), and millimetres and degrees appear only in
the results dictionary and in progress messages:

1. :func:`load_inputs` -> :class:`DiscrepancySetup`: robot, data, baseline parameters, effects,
   and the store of finished stages under :func:`stage_key`;
2. :func:`split_samples` -> :class:`SampleSplit`: calibration, fitted and held-out rows;
3. :func:`calibrate_baseline` -> :class:`Baseline`, its held-out errors by
   :func:`evaluate_held_out` -> :class:`HeldOut`;
4. :func:`diagnose_residuals` -> one :class:`~ctrplan.discrepancy.signatures.SignatureTest` per
   effect;
5. :func:`check_noise` -> :class:`NoiseCheck`;
6. :func:`refit_contact_baseline` and :func:`fit_candidates` -> one :class:`Candidate` per effect;
7. :func:`name_effect` -> :class:`Naming`;
8. :func:`fit_second_effect` -> :class:`Combination`;
9. :func:`predict_with_history` -> :class:`HistoryPrediction` (with :class:`EnvelopeCoverage`);
10. :func:`write_updated_model` -> :class:`UpdatedModel`, :func:`check_reproduction` ->
    :class:`Reproduction`;
11. :func:`discrepancy_results`: the plain dictionary (JSON-ready, mm) plus arrays for plots;
    :mod:`ctrplan.discrepancy.report` writes the report folder.

Every stage that fits or evaluates reads its result from ``out_dir/.stages`` when an earlier run
with the same :func:`stage_key` finished it, and stores it there otherwise.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping

import numpy as np

from ..errors import CtrplanError, DataFileError, PhysicalParameterError
from ..io.atomic import atomic_write_text
from ..mechanics import ModelSettings
from .calibrate import (CalibrationResult, calibrate, eq49_residuals,
                        grid_search_friction, information_criterion, pose_errors, predict)
from .data import MeasuredData, configuration_groups, load_measured_data, split_data
from .parameters import REGISTRATION, apply_parameters, parameter, read_parameters, registration_transform
from .history import rotation_direction, rotation_since_reversal, tip_velocity
from .signatures import (EFFECT_LABELS, angle_features, friction_signature, overlap_features,
                         registration_signature, regression_signature, twist_features, untestable,
                         vector_signature)

__all__ = ["DiscrepancyOptions", "run_discrepancy", "default_baseline_parameters", "effect_parameters",
           "paired_improvement", "EFFECTS", "DiscrepancySetup", "SampleSplit", "HeldOut", "Baseline", "NoiseCheck",
           "Candidate", "Naming", "Combination", "EnvelopeCoverage", "HistoryPrediction", "UpdatedModel",
           "Reproduction", "stage_key", "load_inputs", "split_samples", "evaluate_held_out", "calibrate_baseline",
           "diagnose_residuals", "noise_check", "check_noise", "refit_contact_baseline", "fit_candidates",
           "name_effect", "fit_second_effect", "predict_with_history", "write_updated_model", "check_reproduction",
           "discrepancy_results"]

Echo = Callable[[str], Any]

#: Candidate effects, in the order they are tried (gradual friction after friction: it starts
#: from the friction fit).
EFFECTS = ("friction", "clearance", "offplane", "poisson", "registration", "backlash", "time_offset",
           "gradual_friction")
#: The held-out residual is "consistent with the sensor noise" when its rms position error is at
#: most this multiple of the noise rms (a calibrated model adds a little parameter error).
NOISE_RATIO = 1.25
#: Rests (consecutive samples at identical joints) needed to estimate the noise from the data.
MIN_REST_PAIRS = 10
#: Trial values of the history candidates' 1-D start scans: backlash [rad] (all moving tubes
#: alike), time offset [s], friction angle theta_c [rad] (0 = the abrupt friction model).
BACKLASH_SCAN = tuple(np.deg2rad([0.0, 1.0, 2.0, 4.0, 8.0]))
TIME_OFFSET_SCAN = (-0.4, -0.2, -0.1, 0.0, 0.1, 0.2, 0.4)
FRICTION_ANGLE_SCAN = tuple(np.deg2rad([0.0, 5.0, 10.0, 20.0, 40.0]))
#: Reference theta_c of the gradual-friction signature [rad].
FRICTION_ANGLE_REFERENCE = float(np.deg2rad(15.0))
#: Finite-difference step of d tip / d alpha_i in the backlash signature [rad].
ALPHA_STEP = 1e-3
#: A candidate must lower the BIC by at least this much (Kass & Raftery: > 6 is strong evidence).
BIC_MARGIN = 6.0
#: A fitted friction coefficient above this is flagged as implausible for NiTi on NiTi (the
#: paper's calibrated values are 0.22 and 0.12, Table VII of Ha et al. 2019).
PLAUSIBLE_MU = 0.5
#: Bins that group nearby configurations of a continuous trajectory for the friction test.
TRAJECTORY_ROTATION_BIN = np.deg2rad(15.0)
TRAJECTORY_TRANSLATION_BIN = 5e-3
#: Held-out samples (whole configuration groups) re-evaluated with the written model file to
#: check it; a continuous trajectory is re-evaluated whole.
REPRODUCE_SAMPLES = 256


@dataclass(frozen=True)
class DiscrepancyOptions:
    """Options of :func:`run_discrepancy`.

    Attributes
    ----------
    fit : tuple of str or None
        Baseline parameters (default :func:`default_baseline_parameters`).
    effects : tuple of str
        Candidate effects to test and try (subset of :data:`EFFECTS`).
    frame : {"robot", "tracker"} or None
        Frame of the measurements (default from the file type, see
        :func:`ctrplan.discrepancy.data.load_measured_data`). "tracker" fits a registration.
    calibration_fraction : float
        Share of units (configurations / sequences / time blocks) used for calibration.
    block_samples : int
        Length of the time blocks that split one continuous trajectory (every k-th block for
        calibration, :func:`~ctrplan.discrepancy.data.split_data`); shorter blocks spread the
        calibration samples over more of the motion.
    max_calibration_samples : int
        Calibration samples used by the least-squares fits (whole units, evenly chosen).
    significance : float
        Level of the signature and held-out improvement tests.
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
    """

    fit: tuple | None = None
    effects: tuple = EFFECTS
    frame: str | None = None
    calibration_fraction: float = 0.25
    block_samples: int = 100
    max_calibration_samples: int = 300
    significance: float = 0.01
    n_permutations: int = 999
    friction_grid: tuple = (0.0, 0.1, 0.2, 0.3, 0.4)
    friction_search_samples: int = 96
    max_evaluations: int = 400
    max_contact_evaluations: int = 150
    ds: float = 3e-3
    n_jobs: int = 1
    seed: int = 0
    noise_position: float | None = None
    envelope_samples: int = 0
    reference_friction: tuple | None = None

    def settings(self) -> ModelSettings:
        # no multistart stability search in calibration: it does not change the solution found
        return ModelSettings(ds=self.ds, multistart=0)


#: Version of the fitting procedure in the stage key: 2 = two-stage least squares (error components,
#: then Eq. (49)); 3 = stage 2 with the norms' curvature in its Gauss-Newton model and the BIC
#: stopping rule (:data:`~ctrplan.discrepancy.calibrate.BIC_TOLERANCE`). Stages written by an
#: earlier version (1: Eq. (49) alone; 2: stage 2 stopped at its budget) are redone.
FIT_VERSION = 3
#: Options added after stages were first written, with their defaults (see the stage key).
_LATER_OPTIONS = {"block_samples": 100}


def _curved_tubes(robot):
    return [i for i, t in enumerate(robot.tubes) if any(not s.is_straight for s in t.sections)]


def default_baseline_parameters(robot, register: bool) -> tuple:
    """Default baseline parameters: in-plane precurvature of every curved tube [1/m], bending
    stiffness of tubes 2..n relative to tube 1 [-] (the calibrated parameters of Tables VI and
    VII of Ha et al. 2019), and the six registration parameters [rad, m] when ``register``.

    Returns
    -------
    tuple of str
        Names in :mod:`ctrplan.discrepancy.parameters`.
    """
    names = [f"precurvature_y_{i + 1}" for i in _curved_tubes(robot)]
    names += [f"k_xy_relative_{i + 1}" for i in range(1, robot.n_tubes)]
    if register:
        names += list(REGISTRATION)
    return tuple(names)


def _rotating_tubes(robot, data=None):
    """Tubes with a rotation joint (and, given data, whose recorded angle moves)."""
    from ..robot import ROTATION

    tubes = sorted({j.tube for j in robot.joints if j.kind == ROTATION})
    if data is not None:
        tubes = [i for i in tubes if np.ptp(data.alpha[:, i]) > 1e-6]
    return tubes


def effect_parameters(robot, effect: str, data=None) -> tuple:
    """Parameters an effect adds: friction coefficients mu_k [-] (Section III), none for
    clearance (nominal diameters, as in Section V-C), off-plane precurvatures [1/m], Poisson
    ratios [-], the registration [rad, m], the backlash of every rotating tube [rad] (those
    whose angle moves in ``data`` when given), the time offset [s], or the friction angle
    [rad] (gradual friction; its friction coefficients come from the friction fit).

    Returns
    -------
    tuple of str

    Raises
    ------
    ValueError
        ``effect`` not in :data:`EFFECTS`.
    """
    if effect == "friction":
        return tuple(f"mu_{k + 1}" for k in range(robot.n_tubes - 1))
    if effect == "clearance":
        return ()
    if effect == "offplane":
        return tuple(f"precurvature_x_{i + 1}" for i in _curved_tubes(robot))
    if effect == "poisson":
        return tuple(f"poisson_ratio_{i + 1}" for i in range(robot.n_tubes))
    if effect == "registration":
        return REGISTRATION
    if effect == "backlash":
        return tuple(f"backlash_{i + 1}" for i in _rotating_tubes(robot, data))
    if effect == "time_offset":
        return ("time_offset",)
    if effect == "gradual_friction":
        return ("friction_angle",)
    raise ValueError(f"unknown effect {effect!r}; expected one of {EFFECTS}")


_MODEL_OF = {"friction": "friction", "clearance": "clearance", "offplane": "standard",
             "poisson": "standard", "registration": "standard", "backlash": "standard",
             "time_offset": "standard", "gradual_friction": "friction"}


def paired_improvement(err_base, err_cand, units, *, n_permutations: int = 9999, seed: int = 0) -> dict:
    """Held-out improvement of a candidate over the baseline, tested over units.

    Per unit (a configuration group or time block), the mean of ``err_base - err_cand``; the
    statistic is their mean, the null flips the sign of every unit's difference (no systematic
    improvement), one-sided.

    Parameters
    ----------
    err_base, err_cand : ndarray, shape (K,)
        Per-sample errors (e.g. Eq. (49) residuals or tip distances); NaN rows dropped.
    units : ndarray of int, shape (K,)

    Returns
    -------
    dict
        ``mean_difference``, ``p_value``, ``n_units``.
    """
    ok = np.isfinite(err_base) & np.isfinite(err_cand)
    _, u = np.unique(np.asarray(units)[ok], return_inverse=True)
    u = u.ravel()
    n_u = int(u.max()) + 1 if u.size else 0
    if n_u < 2:
        return {"mean_difference": float("nan"), "p_value": 1.0, "n_units": n_u}
    d = np.bincount(u, (err_base - err_cand)[ok], n_u) / np.bincount(u, minlength=n_u)
    obs = float(d.mean())
    rng = np.random.default_rng(seed)
    signs = rng.choice((-1.0, 1.0), size=(n_permutations, n_u))
    null = (signs * d).mean(axis=1)
    p = float((1 + np.count_nonzero(null >= obs)) / (1 + n_permutations))
    return {"mean_difference": obs, "p_value": p, "n_units": n_u}


def _error_summary(pos, ang, seconds, n) -> dict:
    """Table VIII row: tip position error mean, std, max [mm]; tangent mean, max [deg]."""
    pos_mm = pos[np.isfinite(pos)] * 1e3
    ang_deg = np.rad2deg(ang[np.isfinite(ang)])
    return {"position_mean_mm": float(pos_mm.mean()) if pos_mm.size else None,
            "position_std_mm": float(pos_mm.std()) if pos_mm.size else None,
            "position_max_mm": float(pos_mm.max()) if pos_mm.size else None,
            "tangent_mean_deg": float(ang_deg.mean()) if ang_deg.size else None,
            "tangent_max_deg": float(ang_deg.max()) if ang_deg.size else None,
            "evaluation_ms_per_sample": 1e3 * seconds / max(n, 1),
            "n_samples": int(n), "n_failed": int(np.count_nonzero(~np.isfinite(pos)))}


def _most_strained_tube(robot) -> int:
    strain = []
    for t in robot.tubes:
        kappa = max(np.hypot(*s.precurvature) for s in t.sections)
        strain.append((t.r_out or 0.0) * kappa)
    return int(np.argmax(strain)) if max(strain) > 0 else robot.n_tubes - 1


def _twist(robot, alpha, beta, tube: int, settings) -> np.ndarray:
    """Twist psi(end) - psi(base) of one tube in the standard model, shape (K,) [rad]."""
    from ..mechanics import solve_standard

    out = np.full(alpha.shape[0], np.nan)
    for k in range(alpha.shape[0]):
        try:
            sol = solve_standard(robot, alpha[k], beta[k], settings)
        except CtrplanError:
            continue
        psi = sol.psi[:, tube]
        fin = np.flatnonzero(np.isfinite(psi))
        if fin.size:
            out[k] = psi[fin[-1]] - psi[fin[0]]
    return out


def _configurations_repeat(config_id) -> bool:
    """True for a protocol that revisits configurations (the paper's grid approached from several
    directions): at least half the rows share their configuration with another row. A continuous
    trajectory that merely passes a configuration twice (its home, a pause) is not one."""
    _, inverse, counts = np.unique(config_id, return_inverse=True, return_counts=True)
    return bool(np.mean(counts[inverse.ravel()] > 1) >= 0.5) if len(config_id) else False


def _units(data: MeasuredData, block: int = 50) -> np.ndarray:
    """Exchangeable units of held-out data: configuration groups when configurations repeat,
    else time blocks of ``block`` samples within each sequence."""
    if _configurations_repeat(data.config_id):
        return data.config_id
    _, q = np.unique(data.sequence, return_inverse=True)
    pos = np.zeros(data.n_samples, int)
    for s in np.unique(q):
        idx = np.flatnonzero(q == s)
        pos[idx] = np.arange(idx.size) // block
    return q.ravel() * 100000 + pos


def _subsample(data: MeasuredData, rows: np.ndarray, limit: int, seed: int) -> np.ndarray:
    """At most ``limit`` of ``rows``: whole configuration groups when they repeat, else evenly
    spaced rows (keeping the time order)."""
    if rows.sum() <= limit:
        return rows
    sub = data.take(rows)
    idx = np.flatnonzero(rows)
    if _configurations_repeat(sub.config_id):
        groups = np.unique(sub.config_id)
        per = sub.n_samples / groups.size
        chosen = np.random.default_rng(seed).choice(groups, size=max(1, int(limit // per)), replace=False)
        keep = idx[np.isin(sub.config_id, chosen)]
    else:
        keep = idx[np.linspace(0, idx.size - 1, limit).round().astype(int)]
    out = np.zeros_like(rows)
    out[keep] = True
    return out


class _Stages:
    """Finished stages on disk (JSON), so an interrupted run resumes without redoing them."""

    def __init__(self, folder: Path, key: str):
        self.folder = folder / ".stages"
        self.key = key

    def path(self, name):
        return self.folder / f"{self.key}-{name}.json"

    def load(self, name):
        p = self.path(name)
        return json.loads(p.read_text()) if p.exists() else None

    def save(self, name, value):
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path(name), json.dumps(value, default=_jsonable))


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    raise TypeError(type(x))


def _result_from(d: dict) -> CalibrationResult:
    return CalibrationResult(d["model"], tuple(d["parameters"]), np.array(list(d["parameters"].values()), float),
                             np.array(list(d["initial"].values()), float), dict(d["fixed"]), d["cost"],
                             d["n_samples"], d["n_failed"], d["evaluations"], d["seconds"], d["message"],
                             d.get("converged", True))


# --------------------------------------------------------------------------- stage results
@dataclass(frozen=True, eq=False)
class DiscrepancySetup:
    """Stage 1: what a run works on.

    Attributes
    ----------
    robot_path, data_path : pathlib.Path
        The robot model file and the measured data as given.
    out_dir : pathlib.Path
        Report folder.
    robot : Robot
        The loaded robot (lengths [m], precurvatures [1/m], angles [rad]).
    data : MeasuredData
        All measured samples (joints [rad, m], tip [m], time [s]).
    register : bool
        The data are in a tracker frame: the baseline fits a registration.
    settings : ModelSettings
        Model settings of every fit and evaluation (arc-length step ``ds`` [m], no multistart).
    base_names : tuple of str
        Baseline parameters (:mod:`ctrplan.discrepancy.parameters`).
    effects : tuple of str
        Candidate effects to test and try, in the order they are tried.
    skipped : mapping of str to str
        Requested effects the data cannot show -> why.
    key : str
        Stage key (:func:`stage_key`).
    stages : _Stages
        Finished stages on disk (``out_dir/.stages``), read and written under ``key``.
    """

    robot_path: Path
    data_path: Path
    out_dir: Path
    robot: Any
    data: MeasuredData
    register: bool
    settings: ModelSettings
    base_names: tuple
    effects: tuple
    skipped: Mapping[str, str]
    key: str
    stages: Any


@dataclass(frozen=True, eq=False)
class SampleSplit:
    """Stage 2: calibration and held-out samples.

    Attributes
    ----------
    how : str
        One line saying how the split was made (:func:`~ctrplan.discrepancy.data.split_data`).
    calibration_rows, validation_rows, fit_rows : ndarray of bool, shape (N,)
        Rows of ``setup.data`` in the calibration split, the held-out split, and the
        calibration rows the least-squares fits use (at most ``max_calibration_samples``).
    n_calibration : int
        Samples in the calibration split.
    fit_data : MeasuredData
        The fitted rows.
    val : MeasuredData
        The held-out rows (K samples), the only ones any held-out statistic reads.
    units : ndarray of int, shape (K,)
        Exchangeable unit of each held-out sample for the paired tests (:func:`_units`).
    """

    how: str
    calibration_rows: np.ndarray
    validation_rows: np.ndarray
    fit_rows: np.ndarray
    n_calibration: int
    fit_data: MeasuredData
    val: MeasuredData
    units: np.ndarray

    @property
    def n_fit(self) -> int:
        """Samples the fits use."""
        return self.fit_data.n_samples


@dataclass(frozen=True, eq=False)
class HeldOut:
    """A model's errors on the held-out samples (the Eq. (49) terms).

    Attributes
    ----------
    position : ndarray, shape (K,)
        Tip position error [m]; NaN where the model failed.
    angle : ndarray, shape (K,)
        Tip tangent error [rad]; NaN where it failed or the tangent is not measured.
    residual_base : ndarray, shape (K, 3)
        Measured minus predicted tip, rotated into the robot's base frame [m].
    tip_base : ndarray, shape (K, 3)
        Predicted tip in the robot's base frame [m].
    seconds : float
        Evaluation time [s].
    """

    position: np.ndarray
    angle: np.ndarray
    residual_base: np.ndarray
    tip_base: np.ndarray
    seconds: float

    def as_dict(self) -> dict:
        """The stage file's content (arrays as arrays; SI units)."""
        return {"position": self.position, "angle": self.angle, "residual_base": self.residual_base,
                "tip_base": self.tip_base, "seconds": self.seconds}


#: ``held_out(name, model, params) -> HeldOut``: :func:`evaluate_held_out` bound to one run.
HeldOutFn = Callable[[str, str, Mapping], HeldOut]


@dataclass(frozen=True, eq=False)
class Baseline:
    """Stage 3: the calibrated baseline (standard model).

    Attributes
    ----------
    fit : CalibrationResult
        Its least-squares fit on ``SampleSplit.fit_data`` (cost in (mm + deg)^2, Eq. (49)).
    params : dict of str to float
        Every parameter of the fit (fitted and fixed) [SI: 1/m, -, rad, m].
    bic : float
        Its Bayesian information criterion (:func:`information_criterion`).
    held_out : HeldOut
        Its held-out errors [m, rad].
    r : ndarray, shape (K,)
        Its held-out Eq. (49) residuals [mm + deg] (:func:`eq49_residuals`).
    """

    fit: CalibrationResult
    params: dict
    bic: float
    held_out: HeldOut
    r: np.ndarray


@dataclass(frozen=True, eq=False)
class NoiseCheck:
    """Stage 5: is the baseline's held-out residual more than the sensor noise?

    Attributes
    ----------
    noise : dict
        :func:`estimate_noise` (``position_rms_m`` [m] or None, ``source``, ``n``,
        ``upper_bound``, ``description``).
    rms_m : float
        rms of the baseline's held-out position errors [m] (NaN without a finite one).
    ratio : float or None
        ``rms_m`` over the noise rms; None when the noise is unknown.
    consistent : bool or None
        ``ratio <= NOISE_RATIO``; None when the noise is unknown.
    """

    noise: dict
    rms_m: float
    ratio: float | None
    consistent: bool | None

    def as_dict(self) -> dict:
        """The report's form (``results.json["noise"]``; mm)."""
        sigma = self.noise["position_rms_m"]
        return {"rms_mm": self.rms_m * 1e3, "noise_rms_mm": None if sigma is None else sigma * 1e3,
                "ratio": self.ratio, "consistent": self.consistent, "threshold_ratio": NOISE_RATIO,
                "noise": self.noise}


@dataclass(frozen=True, eq=False)
class Candidate:
    """A candidate effect (or, in :class:`Combination`, a pair of effects) fitted and evaluated.

    Attributes
    ----------
    effects : tuple of str
        The effect, or the named effect and the second one.
    label : str
    model : str
        Mechanics model it is evaluated with (``"standard"``, ``"clearance"``, ``"friction"``).
    fit : CalibrationResult
    params : dict of str to float
        Every parameter of the fit (fitted and fixed) [SI].
    shown : dict of str to float
        The parameters reported as its own [SI: -, 1/m, rad, m, s].
    units : dict of str to str
        Unit of each shown parameter.
    implausible : list of dict
        Shown values outside their plausible range (:func:`_implausible`; SI).
    n_parameters : int
        Parameters counted in its BIC (the baseline's included).
    bic, delta_bic : float
        BIC, and its difference to the baseline's (to the named effect's, for a pair).
    held_out : HeldOut
        Held-out errors [m, rad].
    r : ndarray, shape (K,)
        Held-out Eq. (49) residuals [mm + deg].
    improvement_eq49, improvement_position : dict
        :func:`paired_improvement` of the Eq. (49) residuals [mm + deg] and of the position
        errors [m] over the baseline (over the named effect, for a pair).
    fit_note : str
        What its fit says about itself ("" if nothing); for a pair, that its fit stopped at
        the budget.
    signature_significant, improvement_significant, bic_better, eligible : bool or None
        The naming rule's verdicts (:func:`name_effect`; for a pair, :func:`fit_second_effect`
        sets the last three and ``eligible`` is None).
    significant : bool or None
        A pair's verdict (:func:`fit_second_effect`).
    """

    effects: tuple
    label: str
    model: str
    fit: CalibrationResult
    params: dict
    shown: dict
    units: dict
    implausible: list
    n_parameters: int
    bic: float
    delta_bic: float
    held_out: HeldOut
    r: np.ndarray
    improvement_eq49: dict
    improvement_position: dict
    fit_note: str = ""
    signature_significant: bool | None = None
    improvement_significant: bool | None = None
    bic_better: bool | None = None
    eligible: bool | None = None
    significant: bool | None = None

    @property
    def plausible(self) -> bool:
        """Every shown value within its plausible range."""
        return not self.implausible


@dataclass(frozen=True, eq=False)
class Naming:
    """Stage 7: the named effect.

    Attributes
    ----------
    candidates : mapping of str to Candidate
        Every tried candidate with the naming rule's verdicts.
    decision : dict
        :func:`_decide`'s ``named``, ``eligible``, ``equally_good``, ``passed_over_implausible``,
        ``notes``, and ``no_effect_case`` (``"noise"``, ``"unexplained"``, ``"unknown"``) when
        none is named.
    """

    candidates: Mapping[str, Candidate]
    decision: dict

    @property
    def named(self) -> str | None:
        """The named effect, or None."""
        return self.decision["named"]


@dataclass(frozen=True, eq=False)
class Combination:
    """Stage 8: a second effect fitted on top of the named one.

    Attributes
    ----------
    first, first_label : str
        The named effect.
    named : str or None
        The second effect named with it.
    tried : mapping of str to Candidate
        Second effect -> the pair fitted and evaluated.
    notes : tuple of str
    rule : str
        The rule a pair is named by.
    """

    first: str
    first_label: str
    named: str | None
    tried: Mapping[str, Candidate]
    notes: tuple
    rule: str


@dataclass(frozen=True, eq=False)
class EnvelopeCoverage:
    """Coverage of the friction envelope at evenly spaced held-out samples.

    Attributes
    ----------
    n, inside : int
        Samples with every bounding solution, and those within the envelope plus the margin.
    fraction_inside : float
    margin_m : float
        :data:`ENVELOPE_NOISE_FACTOR` times the noise rms [m] (0 when unknown).
    outside_median_m, outside_p95_m, outside_max_m : float or None
        How far beyond the margin the others lie [m]; None if none.
    size_median_m : float or None
        Median largest distance between two bounding tips [m].
    description : str
    coefficients : dict of str to float
        Friction coefficients used [-].
    label : str
        ``"fitted"`` or ``"reference ..."``.
    """

    n: int
    inside: int
    fraction_inside: float
    margin_m: float
    outside_median_m: float | None
    outside_p95_m: float | None
    outside_max_m: float | None
    size_median_m: float | None
    description: str
    coefficients: dict
    label: str

    def as_dict(self) -> dict:
        """The report's form (mm)."""
        mm = (lambda x: None if x is None else x * 1e3)
        return {"n": self.n, "inside": self.inside, "fraction_inside": self.fraction_inside,
                "margin_mm": self.margin_m * 1e3, "outside_median_mm": mm(self.outside_median_m),
                "outside_p95_mm": mm(self.outside_p95_m), "outside_max_mm": mm(self.outside_max_m),
                "size_median_mm": mm(self.size_median_m), "description": self.description,
                "coefficients": self.coefficients, "label": self.label}


@dataclass(frozen=True, eq=False)
class HistoryPrediction:
    """Stage 9: held-out errors of the standard and the history-aware models.

    Attributes
    ----------
    rows : tuple of (str, ndarray of shape (K,))
        Label and held-out position errors [m] of each model compared.
    envelopes : tuple of EnvelopeCoverage
        Empty when ``options.envelope_samples`` is 0.
    """

    rows: tuple
    envelopes: tuple


@dataclass(frozen=True, eq=False)
class UpdatedModel:
    """Stage 10: the updated robot model file.

    Attributes
    ----------
    path : pathlib.Path
        The written model file (history effects beside it, :func:`history_sidecar`).
    model : str
        Mechanics model it is evaluated with.
    params : dict of str to float
        Its calibrated parameters [SI].
    named_effects : tuple of str
    candidate : Candidate or None
        The candidate it comes from (None: the recalibrated baseline).
    held_out : HeldOut
        Its held-out errors as the workflow evaluated them [m, rad].
    """

    path: Path
    model: str
    params: dict
    named_effects: tuple
    candidate: Candidate | None
    held_out: HeldOut


@dataclass(frozen=True, eq=False)
class Reproduction:
    """Stage 11: the written model file reloaded and re-evaluated.

    Attributes
    ----------
    rows : ndarray of bool, shape (K,)
        Held-out samples re-evaluated.
    position : ndarray, shape (rows.sum(),)
        Their tip position errors with the reloaded file [m].
    reproduced : bool
        Equal to the workflow's errors within 1 nm (NaN where both failed).
    """

    rows: np.ndarray
    position: np.ndarray
    reproduced: bool

    @property
    def n_samples(self) -> int:
        return int(self.rows.sum())


# --------------------------------------------------------------------------- stages
def stage_key(robot_path, data_path, options: DiscrepancyOptions) -> str:
    """The key under which a run's finished stages are stored.

    The stages depend on the inputs and on the options that change a fit, not on the number of
    workers, the tests' permutations and level (the tests are not stored), the stated noise, the
    envelope or the reference friction. Options added later (:data:`_LATER_OPTIONS`) enter the
    key only when set away from their default, so the stages of earlier runs stay valid;
    :data:`FIT_VERSION` enters it so that stages of an earlier least-squares procedure are not
    reused.

    Parameters
    ----------
    robot_path, data_path : path
        The input files (their bytes enter the key).
    options : DiscrepancyOptions

    Returns
    -------
    str
        12 hexadecimal digits of a SHA-256.
    """
    keyed = {k: v for k, v in asdict(options).items()
             if k not in ("n_jobs", "n_permutations", "significance", "noise_position", "envelope_samples",
                          "reference_friction")
             and not (k in _LATER_OPTIONS and v == _LATER_OPTIONS[k])}
    keyed["fit_version"] = FIT_VERSION   # stages of an earlier least-squares procedure are not reused
    return hashlib.sha256(Path(robot_path).read_bytes() + Path(data_path).read_bytes()
                          + json.dumps(keyed, sort_keys=True, default=str).encode()).hexdigest()[:12]


def load_inputs(robot_path, data_path, out_dir, options: DiscrepancyOptions) -> DiscrepancySetup:
    """Stage 1: read the robot and the data, and choose the baseline parameters and the effects.

    Registration is not a candidate for tracker-frame data (the baseline fits it); friction,
    clearance and gradual friction need a robot of two or more tubes with diameters; gradual
    friction needs the friction candidate; backlash needs a rotation that moves in the data and
    the time offset a ``time`` column (else they are listed in ``skipped``).

    Parameters
    ----------
    robot_path : path
        Robot model file (TOML, SI units).
    data_path : path
        Measured data (:func:`~ctrplan.discrepancy.data.load_measured_data`; SI units).
    out_dir : path
        Report folder.
    options : DiscrepancyOptions

    Returns
    -------
    DiscrepancySetup

    Raises
    ------
    DataFileError
        Bad data.
    ModelFileError, PhysicalParameterError
        Bad robot file.
    CtrplanError
        A baseline parameter belongs to a candidate effect.
    """
    from ..io.robot_file import load_robot

    robot = load_robot(robot_path)
    data = load_measured_data(data_path, robot, frame=options.frame)
    register = data.frame == "tracker"
    base_names = tuple(options.fit) if options.fit else default_baseline_parameters(robot, register)
    effects = [e for e in options.effects if not (e == "registration" and register)]
    for e in effects:
        clash = set(effect_parameters(robot, e)) & set(base_names)
        if clash:
            raise CtrplanError(f"baseline parameters {sorted(clash)} belong to the candidate effect "
                               f"{e!r}; a parameter of a tested effect cannot be fitted in the baseline "
                               f"(calibration would absorb the effect)")
    has_clearance = robot.n_tubes > 1 and _has_clearance(robot)
    effects = [e for e in effects if has_clearance or e not in ("friction", "clearance", "gradual_friction")]
    if "gradual_friction" in effects and "friction" not in effects:
        effects.remove("gradual_friction")   # it starts from the friction fit
    skipped = {}
    if "backlash" in effects and not effect_parameters(robot, "backlash", data):
        skipped["backlash"] = "no rotation joint moves in the data"
    if "time_offset" in effects and data.time is None:
        skipped["time_offset"] = "the data has no 'time' column"
    effects = [e for e in effects if e not in skipped]
    key = stage_key(robot_path, data_path, options)
    out_dir = Path(out_dir)
    return DiscrepancySetup(robot_path=Path(robot_path), data_path=Path(data_path), out_dir=out_dir, robot=robot,
                            data=data, register=register, settings=options.settings(), base_names=base_names,
                            effects=tuple(effects), skipped=MappingProxyType(skipped), key=key,
                            stages=_Stages(out_dir, key))


def split_samples(setup: DiscrepancySetup, options: DiscrepancyOptions, echo: Echo = print) -> SampleSplit:
    """Stage 2: split the data into calibration and held-out samples, whole units at a time.

    Parameters
    ----------
    setup : DiscrepancySetup
    options : DiscrepancyOptions
        ``calibration_fraction``, ``block_samples``, ``max_calibration_samples``, ``seed``.
    echo : callable
        Progress messages.

    Returns
    -------
    SampleSplit

    Raises
    ------
    DataFileError
        Either split empty, or no more fitted samples than the baseline's parameters plus the
        largest effect's.
    """
    data, robot, base_names = setup.data, setup.robot, setup.base_names
    cal_rows, val_rows, how = split_data(data, options.calibration_fraction, block_samples=options.block_samples,
                                         seed=options.seed)
    fit_rows = _subsample(data, cal_rows, options.max_calibration_samples, options.seed)
    cal, fit_data, val = data.take(cal_rows), data.take(fit_rows), data.take(val_rows)
    n_fit = fit_data.n_samples
    if n_fit <= len(base_names) + max((len(effect_parameters(robot, e)) for e in setup.effects), default=0):
        raise DataFileError(f"{data.file}: {n_fit} calibration samples are not more than the "
                            f"{len(base_names)} baseline parameters plus the largest effect's; "
                            f"give more samples")
    echo(f"data: {data.n_samples} samples ({data.frame} frame) from {data.file}; split {how}; "
         f"fitting on {n_fit} calibration samples, validating on {val.n_samples}")
    return SampleSplit(how=how, calibration_rows=cal_rows, validation_rows=val_rows, fit_rows=fit_rows,
                       n_calibration=cal.n_samples, fit_data=fit_data, val=val, units=_units(val))


def evaluate_held_out(setup: DiscrepancySetup, split: SampleSplit, name: str, model: str, params: Mapping,
                      *, n_jobs: int = 1, progress: bool = True, echo: Echo = print) -> HeldOut:
    """A model's errors on the held-out samples, read from the stage ``validation-<name>`` if
    an earlier run finished it, else evaluated and stored there.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    name : str
        Stage name (e.g. ``"baseline"``, an effect, ``"combination-<a>+<b>"``).
    model : str
        ``"standard"``, ``"clearance"`` or ``"friction"``.
    params : mapping of str to float
        Parameters applied to the robot (a registration maps into the data's frame) [SI].
    n_jobs : int
    progress : bool
        Progress bar of the evaluation.
    echo : callable

    Returns
    -------
    HeldOut
        Errors of the K held-out samples [m, rad].
    """
    cached = setup.stages.load(f"validation-{name}")
    if cached is not None:
        return HeldOut(**{k: np.array(v, float) if isinstance(v, list) else v for k, v in cached.items()})
    val = split.val
    echo(f"  evaluating {name} ({model} model) on {val.n_samples} held-out samples ...")
    pred = predict(setup.robot, tuple(params), tuple(params.values()), val, model, setup.settings,
                   n_jobs=n_jobs, progress=progress)
    pos, ang, vec = pose_errors(pred, val)
    R, _ = registration_transform(tuple(params), tuple(params.values()))
    res = HeldOut(position=pos, angle=ang, residual_base=vec @ R, tip_base=pred.tip_base, seconds=pred.seconds)
    setup.stages.save(f"validation-{name}", res.as_dict())
    return res


def calibrate_baseline(setup: DiscrepancySetup, split: SampleSplit, options: DiscrepancyOptions,
                       held_out: HeldOutFn, echo: Echo = print) -> Baseline:
    """Stage 3: calibrate the baseline (standard model) on the fitted calibration samples, by
    least squares on Eq. (49) of Ha, Fagogenis & Dupont 2019 (:func:`calibrate`), and evaluate
    it on the held-out samples. A baseline fit finished by an earlier run is reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    options : DiscrepancyOptions
        ``max_evaluations``, ``n_jobs``.
    held_out : callable
        ``held_out(name, model, params) -> HeldOut`` (:func:`evaluate_held_out` bound to the run).
    echo : callable

    Returns
    -------
    Baseline
    """
    stages = setup.stages
    done = stages.load("baseline")
    if done is None:
        echo(f"calibrating the baseline (standard model) on {', '.join(setup.base_names)} ...")
        base = calibrate(setup.robot, split.fit_data, "standard", setup.base_names, settings=setup.settings,
                         n_jobs=options.n_jobs, register=setup.register, max_evaluations=options.max_evaluations)
        stages.save("baseline", base.as_dict())
    else:
        base = _result_from(done)
        echo("baseline calibration: reused from an earlier run")
    echo(f"  baseline: cost {base.cost:.4g} on {base.n_samples} samples, {base.evaluations} model "
         f"evaluations, {base.seconds:.1f} s ({base.message})")
    base_all = dict(zip(*base.all_parameters()))
    base_val = held_out("baseline", "standard", base_all)
    return Baseline(fit=base, params=base_all, bic=information_criterion(base.cost, base.n_samples, len(base.names)),
                    held_out=base_val, r=eq49_residuals(base_val.position, base_val.angle))


def diagnose_residuals(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                       options: DiscrepancyOptions, echo: Echo = print) -> dict:
    """Stage 4: one signature test per candidate effect on the baseline's held-out residuals
    (:mod:`ctrplan.discrepancy.signatures`).

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
        Only its held-out samples are read.
    baseline : Baseline
        Its held-out residual vectors [m] are tested.
    options : DiscrepancyOptions
        ``n_permutations``, ``seed``, ``n_jobs``.
    echo : callable

    Returns
    -------
    dict of str to SignatureTest
        One per candidate effect (``effect_size_m`` [m]), in :data:`EFFECTS` order except the
        time offset last.
    """
    robot, data, val, settings, effects, stages = (setup.robot, setup.data, split.val, setup.settings,
                                                   setup.effects, setup.stages)
    base_val, base_all = baseline.held_out, baseline.params
    echo("testing residual signatures ...")
    E = base_val.residual_base
    groups = val.config_id if _configurations_repeat(val.config_id) else configuration_groups(
        val.alpha, val.beta, TRAJECTORY_ROTATION_BIN, TRAJECTORY_TRANSLATION_BIN)
    base_robot = apply_parameters(robot, tuple(base_all), tuple(base_all.values()))
    tests = {}
    perm = dict(n_permutations=options.n_permutations, seed=options.seed)
    if "friction" in effects:
        tests["friction"] = friction_signature(E, val.eta, groups, **perm)
    if "clearance" in effects:
        tests["clearance"] = regression_signature(
            "clearance", E, overlap_features(robot, val.beta), val.config_id, sequence=val.sequence,
            description="curved-curved overlap and transmission sections in curved sections, per pair", **perm)
    if "offplane" in effects:
        tests["offplane"] = regression_signature(
            "offplane", E, angle_features(val.alpha), val.config_id, sequence=val.sequence,
            description="cos/sin of 1x and 2x the absolute angle of every rotating tube", **perm)
    if "poisson" in effects:
        tube = _most_strained_tube(robot)
        twist = _twist(base_robot, val.alpha, val.beta, tube, settings)
        tests["poisson"] = regression_signature(
            "poisson", E, twist_features(twist, base_val.tip_base), val.config_id, sequence=val.sequence,
            description=f"twist of tube {tube + 1} (most strained) and its square, times 1, cos, sin of "
                        f"the tip azimuth", **perm)
    if "registration" in effects:
        tests["registration"] = registration_signature(E, base_val.tip_base, val.config_id, **perm)
    if {"backlash", "gradual_friction"} & set(effects):
        jac = stages.load("alpha-jacobian")
        if jac is None:
            jac = _alpha_jacobian(base_robot, val, settings, options.n_jobs, _rotating_tubes(robot, data))
            stages.save("alpha-jacobian", {str(i): v for i, v in jac.items()})
        else:
            jac = {int(i): np.array(v, float) for i, v in jac.items()}
        single = np.unique(val.sequence).size == val.n_samples
        if "backlash" in effects:
            if single:
                tests["backlash"] = untestable("backlash", "every sequence holds one sample: no drive has a "
                                                           "recorded motion to lag behind")
            else:
                s_dir = rotation_direction(val.alpha, val.sequence)
                tubes = sorted(jac)
                X = np.stack([-jac[i] for i in tubes], axis=2)
                tests["backlash"] = vector_signature(
                    "backlash", E, X, groups, sequence=val.sequence, signs=s_dir[:, tubes],
                    description="-s_i d tip/d alpha_i per rotating tube, s_i the direction of its last rotation; "
                                "an offset along d tip/d alpha_i is projected out", **perm)
        if "gradual_friction" in effects:
            pairs = [i - 1 for i in sorted(jac) if i >= 1]
            if single or not pairs:
                tests["gradual_friction"] = untestable(
                    "gradual_friction", "every sequence holds one sample: no rotation since a reversal to "
                                        "develop over" if single else "no pair's inner tube rotates")
            else:
                d = rotation_since_reversal(val.alpha, val.sequence)
                eta = val.eta.astype(float)
                full = np.stack([eta[:, k, None] * jac[k + 1] for k in pairs], axis=2)
                ramp = np.stack([eta[:, k, None] * np.exp(-d[:, k, None] / FRICTION_ANGLE_REFERENCE) * jac[k + 1]
                                 for k in pairs], axis=2)
                tests["gradual_friction"] = vector_signature(
                    "gradual_friction", E, ramp, groups, sequence=val.sequence, control=full,
                    description=f"eta_k exp(-rotation since reversal / {np.rad2deg(FRICTION_ANGLE_REFERENCE):.0f} "
                                f"deg) d tip/d alpha_(k+1), beyond eta_k d tip/d alpha_(k+1)", **perm)
    if "time_offset" in effects:
        v = tip_velocity(base_val.tip_base, val.time, val.sequence)
        tests["time_offset"] = vector_signature(
            "time_offset", E, -v[:, :, None], groups, sequence=val.sequence,
            description="-d tip/dt of the baseline model along the recorded motion", **perm)
    for e, t in tests.items():
        if t.testable:
            echo(f"  {EFFECT_LABELS[e]:>30s}: effect {t.effect_size_m * 1e3:.3f} mm, p = {t.p_value:.4f}")
        else:
            echo(f"  {EFFECT_LABELS[e]:>30s}: {t.description}")
    return tests


def noise_check(position, noise: dict) -> NoiseCheck:
    """Held-out rms position error against the noise rms (ratio <= :data:`NOISE_RATIO`:
    consistent).

    Parameters
    ----------
    position : ndarray, shape (K,)
        Held-out tip position errors [m]; NaN rows ignored.
    noise : dict
        :func:`estimate_noise` (``position_rms_m`` [m] or None).

    Returns
    -------
    NoiseCheck
    """
    pos = position[np.isfinite(position)]
    rms = float(np.sqrt(np.mean(pos * pos))) if pos.size else float("nan")
    sigma = noise["position_rms_m"]
    ratio = rms / sigma if sigma else None
    return NoiseCheck(noise=noise, rms_m=rms, ratio=ratio,
                      consistent=None if ratio is None else bool(ratio <= NOISE_RATIO))


def check_noise(setup: DiscrepancySetup, baseline: Baseline, options: DiscrepancyOptions,
                echo: Echo = print) -> NoiseCheck:
    """Stage 5: the sensor noise (stated in ``options.noise_position`` [m], else estimated from
    all the data's rests or repeats, :func:`estimate_noise`) against the baseline's held-out
    residual (:func:`noise_check`).

    Returns
    -------
    NoiseCheck
    """
    noise = estimate_noise(setup.data, options.noise_position)
    check = noise_check(baseline.held_out.position, noise)
    echo(f"  sensor noise: {noise['description']}; held-out baseline rms {check.rms_m * 1e3:.3f} mm"
         + (f" = {check.ratio:.2f} x noise" if check.ratio is not None else ""))
    return check


def refit_contact_baseline(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                           options: DiscrepancyOptions, echo: Echo = print) -> CalibrationResult | None:
    """Stage 6a: the baseline parameters refitted once with the clearance model, shared by the
    clearance and friction candidates (Section V-C; Table VII of Ha et al. 2019), within
    ``options.max_contact_evaluations``. Reused when an earlier run finished it.

    Returns
    -------
    CalibrationResult or None
        None when neither friction nor clearance is a candidate.
    """
    if not ("friction" in setup.effects or "clearance" in setup.effects):
        return None
    base = baseline.fit
    done = setup.stages.load("contact-baseline")
    if done is None:
        echo("recalibrating the baseline parameters with the clearance model (shared by the clearance "
             "and friction candidates) ...")
        contact = calibrate(setup.robot, split.fit_data, "clearance", base.names, fixed=base.fixed,
                            initial=base.values, settings=setup.settings, n_jobs=options.n_jobs,
                            max_evaluations=options.max_contact_evaluations)
        setup.stages.save("contact-baseline", contact.as_dict())
    else:
        contact = _result_from(done)
    echo(f"  clearance-model parameters: cost {contact.cost:.4g}, {contact.evaluations} evaluations, "
         f"{contact.seconds:.1f} s" + ("" if contact.converged else "; NOT converged (stopped at its budget)"))
    return contact


def _fit_candidate(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline, contact_all, friction,
                   effect: str, options: DiscrepancyOptions, echo: Echo) -> CalibrationResult:
    """One candidate's fit (read from its stage, else fitted and stored)."""
    robot, fit_data, settings = setup.robot, split.fit_data, setup.settings
    base, base_all = baseline.fit, baseline.params
    model = _MODEL_OF[effect]
    extra = effect_parameters(robot, effect, setup.data)
    done = setup.stages.load(f"fit-{effect}")
    if done is not None:
        echo(f"candidate {EFFECT_LABELS[effect]}: fit reused from an earlier run")
        return _result_from(done)
    echo(f"candidate {EFFECT_LABELS[effect]}: fitting {', '.join(extra) or 'no parameters'} "
         f"({model} model) ...")
    if effect == "friction":
        fit = grid_search_friction(robot, fit_data, contact_all, settings=settings, n_jobs=options.n_jobs,
                                   coarse=options.friction_grid, search_samples=options.friction_search_samples,
                                   seed=options.seed, progress=_grid_progress(echo))
    elif effect == "clearance":
        fit = calibrate(robot, fit_data, "clearance", (), fixed=contact_all, settings=settings,
                        n_jobs=options.n_jobs)
    elif effect == "gradual_friction":
        fit = _scan_fit(robot, fit_data, "friction", dict(friction.params), "friction_angle", FRICTION_ANGLE_SCAN,
                        settings, options.n_jobs)
    else:
        # nested in the baseline: start at the baseline's values with the effect switched off (so
        # the fit can only lower the calibration cost), the history effects from the best point
        # of a 1-D scan
        names = tuple(base.names) + extra
        start = apply_parameters(robot, tuple(base_all), tuple(base_all.values()))
        init = np.concatenate([base.values, read_parameters(start, extra)])
        if effect in ("backlash", "time_offset"):
            # start: best of a 1-D scan, then the effect's own parameters alone with the baseline
            # held (a few parameters: cheap steps), then everything together
            scan = BACKLASH_SCAN if effect == "backlash" else TIME_OFFSET_SCAN
            best = _scan_fit(robot, fit_data, "standard", base_all, extra, scan, settings, options.n_jobs)
            alone = calibrate(robot, fit_data, "standard", extra, fixed=base_all, initial=best.values,
                              settings=settings, n_jobs=options.n_jobs, max_evaluations=options.max_evaluations)
            init[len(base.names):] = alone.values
        fit = calibrate(start, fit_data, "standard", names, initial=init, settings=settings,
                        n_jobs=options.n_jobs, max_evaluations=options.max_evaluations)
    setup.stages.save(f"fit-{effect}", fit.as_dict())
    return fit


def fit_candidates(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                   contact: CalibrationResult | None, options: DiscrepancyOptions, held_out: HeldOutFn,
                   echo: Echo = print) -> dict:
    """Stage 6b: switch each candidate effect on, fit its parameters with the baseline's
    refitted (friction coefficients by grid search, Section V-C; the clearance and friction
    candidates from ``contact``'s tube parameters; gradual friction from the friction fit; the
    others nested in the baseline), and measure its error on the held-out samples. Fits
    finished by an earlier run are reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    baseline : Baseline
    contact : CalibrationResult or None
        :func:`refit_contact_baseline`.
    options : DiscrepancyOptions
    held_out : callable
        ``held_out(name, model, params) -> HeldOut``.
    echo : callable

    Returns
    -------
    dict of str to Candidate
        One per effect of ``setup.effects``, in order, without the naming verdicts.
    """
    robot, val, units = setup.robot, split.val, split.units
    base, base_val = baseline.fit, baseline.held_out
    contact_all = dict(zip(*contact.all_parameters())) if contact is not None else None
    candidates = {}
    for e in setup.effects:
        model = _MODEL_OF[e]
        extra = effect_parameters(robot, e, setup.data)
        fit = _fit_candidate(setup, split, baseline, contact_all, candidates.get("friction"), e, options, echo)
        params = dict(zip(*fit.all_parameters()))
        val_e = held_out(e, model, params)
        r = eq49_residuals(val_e.position, val_e.angle)
        extra_all = tuple(extra) + (effect_parameters(robot, "friction") if e == "gradual_friction" else ())
        k_total = len(set(setup.base_names) | set(extra_all))
        bic = information_criterion(fit.cost, fit.n_samples, k_total)
        test = paired_improvement(baseline.r, r, units, seed=options.seed)
        pos_test = paired_improvement(base_val.position, val_e.position, units, seed=options.seed)
        shown = {n: float(params[n]) for n in extra_all}
        fit_note = "; ".join(n for n in (
            ("the clearance-model refit of the tube parameters it shares did not converge (stopped at "
             f"the budget of {options.max_contact_evaluations} evaluations): the candidate may be underrated"
             if e in ("friction", "clearance", "gradual_friction") and not contact.converged else ""),
            _fit_note(e, fit, base, base_val, val_e)) if n)
        c = candidates[e] = Candidate(
            effects=(e,), label=EFFECT_LABELS[e], model=model, fit=fit, params=params, shown=shown,
            units={n: parameter(robot, n).unit for n in shown}, implausible=_implausible(robot, shown),
            n_parameters=k_total, bic=bic, delta_bic=bic - baseline.bic, held_out=val_e, r=r,
            improvement_eq49=test, improvement_position=pos_test, fit_note=fit_note)
        held = _error_summary(val_e.position, val_e.angle, val_e.seconds, val.n_samples)
        echo(f"  {EFFECT_LABELS[e]}: {', '.join(f'{n} = {params[n]:.4g}' for n in extra_all) or 'nominal'}; "
             f"held-out mean {held['position_mean_mm']:.3f} mm, max {held['position_max_mm']:.3f} mm; "
             f"dBIC {c.delta_bic:.1f}; improvement p = {test['p_value']:.4f}"
             + (f"; {c.fit_note}" if c.fit_note else ""))
    return candidates


def name_effect(split: SampleSplit, candidates: Mapping[str, Candidate], tests: Mapping, noise: NoiseCheck,
                options: DiscrepancyOptions, echo: Echo = print) -> Naming:
    """Stage 7: name the missing effect.

    A candidate is eligible when its signature test is significant, its held-out Eq. (49)
    improvement is significant (paired sign-flip test over held-out units, one-sided) and its
    BIC beats the baseline's by more than :data:`BIC_MARGIN`; among the eligible, :func:`_decide`
    names the plausible one with the largest held-out improvement. When none is named, the
    decision says whether the baseline's held-out residual is consistent with the noise.

    Parameters
    ----------
    split : SampleSplit
        Its held-out ``units``.
    candidates : mapping of str to Candidate
        :func:`fit_candidates`.
    tests : mapping of str to SignatureTest
        :func:`diagnose_residuals`.
    noise : NoiseCheck
    options : DiscrepancyOptions
        ``significance``, ``seed``.
    echo : callable

    Returns
    -------
    Naming
    """
    judged = {}
    eligible = []
    for e, c in candidates.items():
        sig = tests.get(e)
        signature = bool(sig is not None and sig.testable and sig.p_value < options.significance)
        improvement = bool(c.improvement_eq49["p_value"] < options.significance
                           and c.improvement_eq49["mean_difference"] > 0)
        bic_better = bool(c.delta_bic < -BIC_MARGIN)
        judged[e] = replace(c, signature_significant=signature, improvement_significant=improvement,
                            bic_better=bic_better, eligible=signature and improvement and bic_better)
        if judged[e].eligible:
            eligible.append(e)
    decision = _decide({e: _decision_record(c) for e, c in judged.items()}, eligible, split.units, options)
    named = decision["named"]
    if named:
        echo(f"named effect: {EFFECT_LABELS[named]}")
        for line in decision["notes"]:
            echo(f"  {line}")
    else:
        decision["no_effect_case"] = ("noise" if noise.consistent else
                                      "unexplained" if noise.consistent is False else "unknown")
        echo("no effect named: " + _no_effect_sentence(decision, noise.as_dict(),
                                                        _candidate_reports(judged, split.val.n_samples)))
    return Naming(candidates=MappingProxyType(judged), decision=decision)


def _decision_record(c: Candidate) -> dict:
    """What :func:`_decide` reads of a candidate."""
    return {"label": c.label, "plausible": c.plausible, "implausible": c.implausible,
            "improvement_eq49": c.improvement_eq49, "_r": c.r}


def fit_second_effect(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline, naming: Naming,
                      options: DiscrepancyOptions, held_out: HeldOutFn, echo: Echo = print) -> Combination | None:
    """Stage 8: whether a second effect, fitted on top of the named one, still improves the
    held-out error (issue 13, Sec. 5).

    Tried: every other candidate whose signature test was significant, except pairs in
    :data:`_NOT_COMBINED` (one contains the other). Fit on the calibration split only, starting
    from the named effect's fit and the second effect's own fit: with the standard model, the
    second effect's parameters alone (the named fit held), then everything together (nested: the
    calibration cost cannot rise); with a contact model (dearer by ~30x), the second effect's
    parameters alone, with ``options.max_contact_evaluations``. The pair is named by the
    workflow's rule for single effects, with the named effect in place of the baseline: held-out
    Eq. (49) improvement significant (paired sign-flip test over held-out units, one-sided,
    ``options.significance``), BIC lower by more than :data:`BIC_MARGIN`, and every fitted value
    plausible; among such pairs the largest held-out improvement. (Not "plausible alone": fitted
    alone, an effect absorbs the other one and can look implausible, e.g. a backlash of 9.9 deg
    for a hidden 4.6 deg plus a 0.15 s lag; the pair's own values must be plausible.) Fits
    finished by an earlier run are reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    baseline : Baseline
    naming : Naming
    options : DiscrepancyOptions
    held_out : callable
        ``held_out(name, model, params) -> HeldOut``.
    echo : callable

    Returns
    -------
    Combination or None
        None when no effect is named.
    """
    named = naming.named
    if not named:
        return None
    robot, data, fit_data, val, units, settings = (setup.robot, setup.data, split.fit_data, split.val, split.units,
                                                   setup.settings)
    candidates = naming.candidates
    first = candidates[named]
    p_first = dict(first.params)
    first_names = _effect_names(robot, named, data)
    first_held = _error_summary(first.held_out.position, first.held_out.angle, first.held_out.seconds,
                                val.n_samples)
    notes = []
    rule = (f"held-out Eq. (49) improvement over {first.label} alone significant at {options.significance} "
            f"(paired sign-flip test), BIC lower by more than {BIC_MARGIN}, fitted values plausible")
    pool = [e for e in candidates if e != named and {e, named} not in _NOT_COMBINED
            and candidates[e].signature_significant]
    skipped = [e for e in candidates if e != named and e not in pool]
    if skipped:
        notes.append("not tried on top of " + first.label + ": " + ", ".join(
            f"{candidates[e].label} ("
            + ("contained in it or containing it" if {e, named} in _NOT_COMBINED else "signature not significant")
            + ")"
            for e in skipped))
    tried = {}
    for e in pool:
        model = _combined_model(named, e)
        second_names = tuple(n for n in _effect_names(robot, e, data) if n not in p_first)
        if not second_names:
            continue
        init2 = np.array([candidates[e].params[n] for n in second_names], float)
        tag = f"{named}+{e}"
        done = setup.stages.load(f"fit-{tag}")
        if done is not None:
            fit = _result_from(done)
        else:
            echo(f"second effect: {candidates[e].label} on top of {first.label} ({model} model) ...")
            budget = options.max_evaluations if model == "standard" else options.max_contact_evaluations
            fit = calibrate(robot, fit_data, model, second_names, fixed=p_first, initial=init2, settings=settings,
                            n_jobs=options.n_jobs, max_evaluations=budget)
            if model == "standard":
                names = tuple(p_first) + second_names
                init = np.concatenate([np.array(list(p_first.values()), float), fit.values])
                joint = calibrate(robot, fit_data, "standard", names, initial=init, settings=settings,
                                  n_jobs=options.n_jobs, max_evaluations=options.max_evaluations)
                if joint.cost <= fit.cost or not fit.converged:
                    fit = joint
            setup.stages.save(f"fit-{tag}", fit.as_dict())
        params = dict(zip(*fit.all_parameters()))
        val_c = held_out(f"combination-{tag}", model, params)
        r = eq49_residuals(val_c.position, val_c.angle)
        shown_names = first_names + tuple(n for n in _effect_names(robot, e, data) if n not in first_names)
        shown = {n: float(params[n]) for n in shown_names}
        k_total = len(set(setup.base_names) | set(shown_names))
        bic = information_criterion(fit.cost, fit.n_samples, k_total)
        test = paired_improvement(first.r, r, units, seed=options.seed)
        implausible = _implausible(robot, shown)
        improvement = bool(test["p_value"] < options.significance and test["mean_difference"] > 0)
        bic_better = bool(bic - first.bic < -BIC_MARGIN)
        c = tried[e] = Candidate(
            effects=(named, e), label=f"{first.label} + {candidates[e].label}", model=model, fit=fit,
            params=params, shown=shown, units={n: parameter(robot, n).unit for n in shown},
            implausible=implausible, n_parameters=k_total, bic=bic, delta_bic=bic - first.bic, held_out=val_c,
            r=r, improvement_eq49=test,
            improvement_position=paired_improvement(first.held_out.position, val_c.position, units,
                                                    seed=options.seed),
            fit_note="" if fit.converged else ("its fit did not converge (stopped at the evaluation budget): the "
                                               "pair may be underrated"),
            improvement_significant=improvement, bic_better=bic_better,
            significant=improvement and bic_better and not implausible)
        held = _error_summary(val_c.position, val_c.angle, val_c.seconds, val.n_samples)
        echo(f"  {c.label}: " + ", ".join(display_value(n, v, c.units[n]) for n, v in shown.items())
             + f"; held-out mean {held['position_mean_mm']:.3f} mm (alone {first_held['position_mean_mm']:.3f}); "
               f"dBIC {c.delta_bic:.1f}; improvement p = {test['p_value']:.4f}"
             + ("" if fit.converged else "; fit NOT converged"))
    passing = [e for e, c in tried.items() if c.significant]
    second = None
    if passing:
        second = max(passing, key=lambda e: tried[e].improvement_eq49["mean_difference"])
        c = tried[second]
        after = _error_summary(c.held_out.position, c.held_out.angle, c.held_out.seconds, val.n_samples)
        echo(f"named combination: {c.label} (held-out mean {first_held['position_mean_mm']:.3f} -> "
             f"{after['position_mean_mm']:.3f} mm, p = {c.improvement_eq49['p_value']:.4f})")
    elif tried:
        notes.append("no second effect improves the held-out error of " + first.label + " significantly: "
                     + "; ".join(f"{c.label}: p = {c.improvement_eq49['p_value']:.4f}, dBIC "
                                 f"{c.delta_bic:.1f}" + ("" if c.plausible else ", implausible")
                                 for c in tried.values()))
    return Combination(first=named, first_label=first.label, named=second, tried=MappingProxyType(tried),
                       notes=tuple(notes), rule=rule)


#: What the prediction comparison reports (``results.json["prediction"]["description"]``).
PREDICTION_DESCRIPTION = (
    "Held-out tip position errors. Standard: the calibrated baseline, which ignores the motion history. "
    "History-aware: the friction model (Section III of Ha et al. 2019) with each sample's recorded history "
    "(eta of the last relative rotation of each pair; the clearance solution after a final translation), tube "
    "parameters and friction coefficients calibrated on the calibration split only (reference coefficients, if "
    "any, given).")


def predict_with_history(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline, naming: Naming,
                         noise: NoiseCheck, options: DiscrepancyOptions, held_out: HeldOutFn,
                         echo: Echo = print) -> HistoryPrediction | None:
    """Stage 9: held-out prediction errors of the standard and the history-aware models, and the
    coverage of the friction envelope (issue 13, Sec. 3).

    The history-aware model is the friction model along the recorded history with the friction
    candidate's calibrated parameters and, when ``options.reference_friction`` is given, also
    with those coefficients (e.g. published ones) on the same calibrated tube parameters. With
    ``options.envelope_samples`` > 0, the envelope (convex hull of the 2^(n-1) bounding friction
    solutions plus :data:`ENVELOPE_NOISE_FACTOR` times the noise rms) is evaluated at that many
    evenly spaced held-out samples, for each coefficient set.

    Returns
    -------
    HistoryPrediction or None
        None without a friction candidate.
    """
    candidates, named, val = naming.candidates, naming.named, split.val
    if "friction" not in candidates:
        return None
    fr = candidates["friction"]
    rows = [("standard model, calibrated (no history)", baseline.held_out.position),
            ("history-aware: friction model along the recorded history, fitted "
             + ", ".join(f"{k} = {v:.3g}" for k, v in fr.shown.items()), fr.held_out.position)]
    sets = [("fitted", fr.params, f"{len(all_eta_n(setup.robot))}")]
    if options.reference_friction is not None:
        mu = tuple(float(v) for v in options.reference_friction)
        ref = dict(fr.params)
        ref.update({f"mu_{k + 1}": v for k, v in enumerate(mu)})
        tag = "-".join(f"{v:g}" for v in mu)
        val_ref = held_out(f"reference-friction-{tag}", "friction", ref)
        rows.append(("history-aware with the reference friction coefficients "
                     + ", ".join(f"mu_{k + 1} = {v:.3g}" for k, v in enumerate(mu)), val_ref.position))
        sets.append((f"reference {tag}", ref, f"reference-{tag}"))
    if named and named != "friction":
        rows.append((f"named effect: {candidates[named].label}", candidates[named].held_out.position))
    for label, pos in rows:
        s = _stats_mm(pos)
        echo(f"  prediction: {label}: mean {s['mean_mm']:.3f}, p95 {s['p95_mm']:.3f}, max {s['max_mm']:.3f} mm")
    k_env = min(int(options.envelope_samples), val.n_samples)
    if k_env <= 0:
        return HistoryPrediction(rows=tuple(rows), envelopes=())
    rows_env = np.unique(np.linspace(0, val.n_samples - 1, k_env).round().astype(int))
    sub = val.take(rows_env)
    envelopes = []
    for label, params, key in sets:
        stage = f"envelope-{rows_env.size}" if label == "fitted" else f"envelope-{key}-{rows_env.size}"
        env = _envelope(setup.robot, params, sub, noise.noise, setup.stages, stage, setup.settings, options.n_jobs,
                        echo, coefficients={k: float(v) for k, v in params.items() if k.startswith("mu_")},
                        label=label)
        envelopes.append(env)
        e = env.as_dict()
        echo(f"  envelope ({label}): {e['inside']} of {e['n']} inside ({100 * e['fraction_inside']:.0f} %), "
             f"outside by median {_mm(e['outside_median_mm'])}, max {_mm(e['outside_max_mm'])}; size median "
             f"{_mm(e['size_median_mm'])}")
    return HistoryPrediction(rows=tuple(rows), envelopes=tuple(envelopes))


def _prediction_report(prediction: HistoryPrediction | None) -> dict | None:
    """``results.json["prediction"]`` (mm)."""
    if prediction is None:
        return None
    out = {"description": PREDICTION_DESCRIPTION,
           "rows": [{"label": label, **_stats_mm(pos)} for label, pos in prediction.rows]}
    if prediction.envelopes:
        out["envelopes"] = [env.as_dict() for env in prediction.envelopes]
        out["envelope"] = out["envelopes"][0]
    return out


def write_updated_model(setup: DiscrepancySetup, baseline: Baseline, naming: Naming,
                        combination: Combination | None, echo: Echo = print) -> UpdatedModel:
    """Stage 10: write the robot model file with the named effect(s) and their calibrated
    parameters (the recalibrated baseline when none is named) into ``setup.out_dir``, atomically;
    history effects go beside it (:func:`history_sidecar`), a stale sidecar is removed.

    Returns
    -------
    UpdatedModel
    """
    from ..io.robot_file import robot_to_toml

    robot, named = setup.robot, naming.named
    pair = combination.named if combination else None
    final = combination.tried[pair] if pair else (naming.candidates[named] if named else None)
    named_effects = ([named] + ([pair] if pair else [])) if named else []
    final_params = final.params if final else baseline.params
    final_model = final.model if final else "standard"
    reg_names = [n for n in final_params if n in REGISTRATION]
    registration = None
    if reg_names:
        vals = [final_params.get(n, 0.0) for n in REGISTRATION]
        registration = {"rotation_vector_rad": vals[:3], "translation_m": vals[3:]}
    data_name = Path(setup.data_path).name
    updated = apply_parameters(robot, tuple(final_params), tuple(final_params.values()))
    updated = updated.replace(name=f"{robot.name}-{'-'.join(named_effects) or 'recalibrated'}",
                              source=f"{robot.source}; recalibrated by ctrplan discrepancy on {data_name}")
    setup.out_dir.mkdir(parents=True, exist_ok=True)
    model_path = setup.out_dir / f"{updated.name}.toml"
    header = (f"Written by `ctrplan discrepancy` from {Path(setup.robot_path).name} and {data_name}.\n"
              f"Named effect: {' + '.join(EFFECT_LABELS[e] for e in named_effects) or 'none'}; evaluate with the "
              f"{final_model} model.\nCalibrated parameters: "
              + ", ".join(f"{n} = {v:.6g}" for n, v in final_params.items() if n not in REGISTRATION))
    atomic_write_text(model_path, robot_to_toml(updated, header=header, model=final_model,
                                                registration=registration))
    hist_params = {n: float(v) for n, v in final_params.items() if parameter(robot, n).history}
    side = history_sidecar(model_path)
    if hist_params:
        # the robot file has no place for effects of the motion history: they go beside it
        atomic_write_text(side, json.dumps({"note": "history effects of the model file of the same name "
                                                    "(ctrplan.discrepancy.parameters; SI units)",
                                            "parameters": hist_params}, indent=2) + "\n")
    elif side.exists():
        side.unlink()
    return UpdatedModel(path=model_path, model=final_model, params=final_params, named_effects=tuple(named_effects),
                        candidate=final, held_out=final.held_out if final else baseline.held_out)


def check_reproduction(setup: DiscrepancySetup, split: SampleSplit, updated: UpdatedModel,
                       options: DiscrepancyOptions, echo: Echo = print) -> Reproduction:
    """Stage 11: load the written model file back (:func:`reproduce_errors`) and check that it
    gives the workflow's held-out errors: whole configuration groups of a revisiting protocol
    (at most :data:`REPRODUCE_SAMPLES`); a trajectory is re-run whole, since a subsample would
    break its branch following (each sample starts from the previous one).

    Returns
    -------
    Reproduction

    Raises
    ------
    ModelFileError, PhysicalParameterError
        The written file does not load.
    """
    val = split.val
    check_rows = (_subsample(val, np.ones(val.n_samples, bool), REPRODUCE_SAMPLES, options.seed)
                  if _configurations_repeat(val.config_id) else np.ones(val.n_samples, bool))
    check = reproduce_errors(updated.path, val.take(check_rows), setup.settings, n_jobs=options.n_jobs)
    reproduced = bool(np.allclose(check["position"], updated.held_out.position[check_rows], atol=1e-9,
                                  equal_nan=True))
    echo(f"wrote {updated.path}; reloaded, it reproduces the held-out errors of {int(check_rows.sum())} "
         f"samples: {reproduced} "
         f"(mean {np.nanmean(check['position']) * 1e3:.3f} mm)")
    return Reproduction(rows=check_rows, position=check["position"], reproduced=reproduced)


def _candidate_report(c: Candidate, n_val: int) -> dict:
    """A single candidate as ``results.json["candidates"][effect]`` stores it (mm in ``held_out``)."""
    out = {"label": c.label, "model": c.model, "fit": c.fit.as_dict(), "parameters": c.shown, "units": c.units,
           "implausible": c.implausible, "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "held_out": _error_summary(c.held_out.position, c.held_out.angle, c.held_out.seconds, n_val),
           "improvement_eq49": c.improvement_eq49, "improvement_position": c.improvement_position,
           "fit_note": c.fit_note}
    if c.eligible is not None:
        out.update({"signature_significant": c.signature_significant,
                    "improvement_significant": c.improvement_significant, "bic_better": c.bic_better,
                    "eligible": c.eligible, "plausible": c.plausible})
    return out


def _candidate_reports(candidates: Mapping[str, Candidate], n_val: int) -> dict:
    return {e: _candidate_report(c, n_val) for e, c in candidates.items()}


def _pair_report(c: Candidate, n_val: int) -> dict:
    """A pair as ``results.json["combination"]["tried"][effect]`` stores it (mm in ``held_out``)."""
    out = {"effects": list(c.effects), "label": c.label, "model": c.model, "fit": c.fit.as_dict(),
           "parameters": c.shown, "units": c.units, "implausible": c.implausible, "plausible": c.plausible,
           "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "held_out": _error_summary(c.held_out.position, c.held_out.angle, c.held_out.seconds, n_val),
           "improvement_eq49": c.improvement_eq49, "improvement_position": c.improvement_position,
           "converged": bool(c.fit.converged), "improvement_significant": c.improvement_significant,
           "bic_better": c.bic_better, "significant": c.significant}
    if c.fit_note:
        out["note"] = c.fit_note
    return out


def _combination_report(combination: Combination | None, naming: Naming, n_val: int) -> dict | None:
    """``results.json["combination"]`` (mm)."""
    if combination is None:
        return None
    tried = {e: _pair_report(c, n_val) for e, c in combination.tried.items()}
    steps = []
    if combination.named:
        first = _candidate_report(naming.candidates[combination.first], n_val)
        c = tried[combination.named]
        steps = [
            {"effect": combination.first, "label": first["label"],
             "held_out_mean_mm": first["held_out"]["position_mean_mm"],
             "held_out_max_mm": first["held_out"]["position_max_mm"],
             "improvement_eq49": first["improvement_eq49"], "over": "baseline"},
            {"effect": combination.named, "label": naming.candidates[combination.named].label,
             "held_out_mean_mm": c["held_out"]["position_mean_mm"], "held_out_max_mm": c["held_out"]["position_max_mm"],
             "improvement_eq49": c["improvement_eq49"], "over": combination.first}]
    return {"first": combination.first, "first_label": combination.first_label, "named": combination.named,
            "tried": tried, "steps": steps, "notes": list(combination.notes), "rule": combination.rule}


def discrepancy_results(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                        contact: CalibrationResult | None, tests: Mapping, noise: NoiseCheck, naming: Naming,
                        combination: Combination | None, prediction: HistoryPrediction | None,
                        updated: UpdatedModel, reproduction: Reproduction, options: DiscrepancyOptions,
                        echo: Echo = print) -> dict:
    """Stage 12: the run's results as ``results.json`` stores them (report units: keys ending
    ``_mm`` in mm, ``_deg`` in degrees, others SI), with the cautions a reader must not overlook
    (echoed).

    Parameters
    ----------
    setup, split, baseline, contact, tests, noise, naming, combination, prediction, updated, reproduction
        The results of stages 1-11.
    options : DiscrepancyOptions
    echo : callable
        Receives the cautions.

    Returns
    -------
    dict
        JSON-ready results (``seconds`` is None: :func:`run_discrepancy` sets it); arrays for plots
        under ``"_arrays"`` (SI).
    """
    val, n_val, named = split.val, split.val.n_samples, naming.named
    base, base_val = baseline.fit, baseline.held_out
    base_summary = _error_summary(base_val.position, base_val.angle, base_val.seconds, n_val)
    final_val = updated.held_out
    after = _error_summary(final_val.position, final_val.angle, final_val.seconds, n_val)
    candidates = _candidate_reports(naming.candidates, n_val)
    combination_report = _combination_report(combination, naming, n_val)
    pair = combination.named if combination else None
    final = combination_report["tried"][pair] if pair else (candidates[named] if named else None)
    cautions = _cautions(named, final, base_summary, after, setup.robot)
    for line in cautions:
        echo(f"caution: {line}")
    return {
        "robot_file": str(setup.robot_path), "data_file": str(setup.data_path), "frame": setup.data.frame,
        "n_samples": setup.data.n_samples, "split": split.how, "n_calibration": split.n_calibration,
        "n_fit": split.n_fit, "n_validation": n_val, "baseline_parameters": list(setup.base_names),
        "baseline": {"fit": base.as_dict(), "bic": baseline.bic, "held_out": base_summary},
        "contact_baseline": contact.as_dict() if contact is not None else None,
        "signature_tests": {e: t.as_dict() for e, t in tests.items()},
        "skipped_effects": dict(setup.skipped), "prediction": _prediction_report(prediction),
        "noise": noise.as_dict(), "decision": naming.decision,
        "candidates": candidates,
        "named_effect": named, "named_label": EFFECT_LABELS[named] if named else None,
        "named_effects": list(updated.named_effects), "combination": combination_report,
        "after": after, "updated_model_file": str(updated.path), "updated_model": updated.model,
        "reproduced": reproduction.reproduced, "reproduced_samples": reproduction.n_samples,
        "reproduced_position_mean_mm": float(np.nanmean(reproduction.position) * 1e3),
        "cautions": cautions,
        "significance": options.significance, "bic_margin": BIC_MARGIN, "options": asdict(options),
        "seconds": None,
        "_arrays": {"val_eta": val.eta, "val_tip_base": base_val.tip_base,
                    "before_position": base_val.position, "before_angle": base_val.angle,
                    "before_residual": base_val.residual_base,
                    "after_position": final_val.position, "after_angle": final_val.angle,
                    "after_residual": final_val.residual_base,
                    "reduction": (1.0 - after["position_mean_mm"] / base_summary["position_mean_mm"])
                    if base_summary["position_mean_mm"] else None},
    }


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


#: Envelope margin: 95 % of 3-D Gaussian noise vectors are shorter than 2.80 sigma per component,
#: i.e. 1.62 times their rms length.
ENVELOPE_NOISE_FACTOR = 1.62


def _stats_mm(pos) -> dict:
    p = pos[np.isfinite(pos)] * 1e3
    if not p.size:
        return {"n": 0, "mean_mm": None, "p95_mm": None, "max_mm": None}
    return {"n": int(p.size), "mean_mm": float(p.mean()), "p95_mm": float(np.percentile(p, 95)),
            "max_mm": float(p.max())}


def hull_distance(points, x) -> float:
    """Distance from ``x`` (3,) to the convex hull of ``points`` (m, 3) [same unit]: the nearest
    convex combination, by non-negative least squares with the weights' sum held at 1 by a
    heavily weighted row."""
    from scipy.optimize import nnls

    P = np.asarray(points, float)
    w_row = 1e3 * max(1.0, float(np.abs(P).max()))
    A = np.vstack([P.T, np.full((1, P.shape[0]), w_row)])
    b = np.concatenate([np.asarray(x, float), [w_row]])
    w, _ = nnls(A, b)
    return float(np.linalg.norm(P.T @ w - x))


def all_eta_n(robot):
    from ..mechanics import all_eta

    return all_eta(robot.n_tubes)


def _mm(x):
    return "-" if x is None else f"{x:.2f} mm"


def _envelope(robot, params, sub: MeasuredData, noise, stages, stage, settings, n_jobs, echo, *,
              coefficients: dict, label: str) -> EnvelopeCoverage:
    """Coverage of the friction envelope: the convex hull of the 2^(n-1) bounding friction
    solutions (fixed eta, no release) at each sample of ``sub``, plus
    :data:`ENVELOPE_NOISE_FACTOR` times the noise rms; the bounding tips are kept in the stage
    ``stage``."""
    from .simulate import simulate

    sigma = noise.get("position_rms_m")
    margin = ENVELOPE_NOISE_FACTOR * sigma if sigma else 0.0
    cached = stages.load(stage)
    if cached is None:
        etas = all_eta_n(robot)
        echo(f"  friction envelope: {len(etas)} bounding solutions at {sub.n_samples} held-out samples ...")
        robot_p = apply_parameters(robot, tuple(params), tuple(params.values()))
        R, t = registration_transform(tuple(params), tuple(params.values()))
        tips = []
        for eta in etas:
            sim = simulate(robot_p, sub.alpha, sub.beta, model="friction",
                           eta=np.tile(np.asarray(eta, int), (sub.n_samples, 1)),
                           translation_last=np.zeros(sub.n_samples, bool), sequence=sub.sequence,
                           settings=settings, n_jobs=n_jobs)
            tips.append(sim.tip @ R.T + t)
        cached = {"tips": np.stack(tips, axis=1)}
        stages.save(stage, cached)
    tips = np.asarray(cached["tips"], float)            # (k, 2^(n-1), 3) in the data's frame
    dist = np.full(sub.n_samples, np.nan)
    size = np.full(sub.n_samples, np.nan)
    for k in range(sub.n_samples):
        P = tips[k]
        if np.all(np.isfinite(P)):
            dist[k] = hull_distance(P, sub.tip[k])
            size[k] = max(np.linalg.norm(P[a] - P[b]) for a in range(len(P)) for b in range(len(P)))
    ok = np.isfinite(dist)
    outside = dist[ok] - margin
    far = outside[outside > 0]
    return EnvelopeCoverage(
        n=int(ok.sum()), inside=int(np.sum(outside <= 0)),
        fraction_inside=float(np.mean(outside <= 0)) if ok.any() else float("nan"), margin_m=margin,
        outside_median_m=float(np.median(far)) if far.size else None,
        outside_p95_m=float(np.percentile(far, 95)) if far.size else None,
        outside_max_m=float(far.max()) if far.size else None,
        size_median_m=float(np.nanmedian(size)) if ok.any() else None,
        description=f"{sub.n_samples} evenly spaced held-out samples; convex hull of the "
                    f"{tips.shape[1]} bounding friction solutions (all eta, no release); margin "
                    f"{ENVELOPE_NOISE_FACTOR} x the noise rms ({noise['description']})",
        coefficients=coefficients, label=label)


# --------------------------------------------------------------------------- helpers of the steps
def _alpha_jacobian(robot, data: MeasuredData, settings, n_jobs, tubes) -> dict:
    """d tip / d alpha_i of the standard model along the data's motion, per rotating tube i:
    ``{i: ndarray (K, 3) [m/rad]}`` by central differences of :data:`ALPHA_STEP`, branch
    following (NaN where a solve failed)."""
    from .simulate import simulate

    out = {}
    for i in tubes:
        tips = []
        for sign in (1.0, -1.0):
            a = data.alpha.copy()
            a[:, i] += sign * ALPHA_STEP
            tips.append(simulate(robot, a, data.beta, model="standard", sequence=data.sequence,
                                 settings=settings, n_jobs=n_jobs).tip)
        out[i] = (tips[0] - tips[1]) / (2.0 * ALPHA_STEP)
    return out


def estimate_noise(data: MeasuredData, stated: float | None = None) -> dict:
    """The sensor's rms tip position noise: as stated, else from the data.

    From rests (consecutive samples of a sequence at identical joints: their tip difference is
    noise alone; robust, from the median of |d|, Maxwell-distributed for Gaussian noise), else
    from configurations measured more than once (spread about the configuration mean; an upper
    bound, since it includes whatever else differs between the visits, e.g. the approach
    direction).

    Returns
    -------
    dict
        ``position_rms_m`` (None when unknown), ``source`` ("stated", "rests",
        "repeated configurations", None), ``n`` (pairs or rows used), ``upper_bound`` (bool),
        ``description``.
    """
    if stated is not None:
        return {"position_rms_m": float(stated), "source": "stated", "n": 0, "upper_bound": False,
                "description": f"{stated * 1e3:.3f} mm rms as stated for the data"}
    joints = np.concatenate([data.alpha, data.beta], axis=1)
    same = (np.all(np.abs(np.diff(joints, axis=0)) <= 1e-12, axis=1)
            & (np.diff(data.sequence) == 0))
    d = np.linalg.norm(np.diff(data.tip, axis=0)[same], axis=1)
    d = d[np.isfinite(d)]
    if d.size >= MIN_REST_PAIRS:
        # |d| of two samples with per-component sigma s: Maxwell with scale sqrt(2) s, median
        # 1.5382 sqrt(2) s; position rms = sqrt(3) s
        rms = float(np.median(d) / (1.5382 * np.sqrt(2.0)) * np.sqrt(3.0))
        return {"position_rms_m": rms, "source": "rests", "n": int(d.size), "upper_bound": False,
                "description": f"{rms * 1e3:.3f} mm rms from {d.size} pairs of consecutive samples at rest"}
    _, g, counts = np.unique(data.config_id, return_inverse=True, return_counts=True)
    g = g.ravel()
    rep = counts[g] > 1
    if rep.sum() >= 2 * MIN_REST_PAIRS:
        n_g = int(g.max()) + 1
        mean = np.stack([np.bincount(g, data.tip[:, j], n_g) for j in range(3)], axis=1) / counts[:, None]
        dev = (data.tip - mean[g])[rep]
        dof = int(rep.sum() - np.count_nonzero(counts > 1))
        rms = float(np.sqrt(np.sum(dev * dev) / max(dof, 1)))
        return {"position_rms_m": rms, "source": "repeated configurations", "n": int(rep.sum()),
                "upper_bound": True,
                "description": f"at most {rms * 1e3:.3f} mm rms: spread of {int(rep.sum())} rows at repeated "
                               f"configurations (includes any direction-dependent effect)"}
    return {"position_rms_m": None, "source": None, "n": 0, "upper_bound": False,
            "description": "unknown: not stated (--noise-position-mm) and the data has neither rests nor "
                           "repeated configurations"}


def _scan_fit(robot, data: MeasuredData, model: str, fixed: dict, names, values, settings,
              n_jobs) -> CalibrationResult:
    """Best of a 1-D scan: every parameter in ``names`` set to each of ``values`` in turn, the
    others ``fixed``; the cost (Eq. (49)) of each trial in the message."""
    from .calibrate import FAILED_RESIDUAL, _Objective

    t0 = time.perf_counter()
    names = (names,) if isinstance(names, str) else tuple(names)
    obj = _Objective(robot, data, model, names, fixed, settings, n_jobs)
    costs = []
    for v in values:
        r = obj.residuals(np.full(len(names), v))
        costs.append(float(r @ r))
    b = int(np.argmin(costs))
    x = np.full(len(names), values[b])
    r = obj.residuals(x)
    trail = ", ".join(f"{v:.4g}: {c:.4g}" for v, c in zip(values, costs))
    return CalibrationResult(model, names, x, np.zeros(len(names)), dict(fixed), float(r @ r), data.n_samples,
                             int((r == FAILED_RESIDUAL).sum()), obj.evaluations, time.perf_counter() - t0,
                             f"scan of {', '.join(names)} (value: cost) {trail}; best {values[b]:.4g}", True)


def _implausible(robot, params: dict) -> list:
    """Fitted values outside their plausible range: ``[{name, value, plausible, unit, why}]``."""
    out = []
    for name, value in params.items():
        p = parameter(robot, name)
        if not p.is_plausible(value):
            out.append({"name": name, "value": float(value), "plausible": list(p.plausible), "unit": p.unit,
                        "why": p.plausible_note})
    return out


_NESTED = ("offplane", "poisson", "registration", "backlash", "time_offset")


def _fit_note(effect, fit, base, base_val: HeldOut, val_e: HeldOut) -> str:
    """What a candidate's fit says about itself: not converged, worse on the calibration data
    than the baseline, or better there but worse held-out (overfitting)."""
    notes = []
    if not fit.converged:
        notes.append("its fit did not converge (stopped at the evaluation budget)")
    base_mean = float(np.nanmean(base_val.position))
    cand_mean = float(np.nanmean(val_e.position))
    if fit.cost > base.cost * (1 + 1e-9):
        if effect in _NESTED:
            notes.append(f"it fits the calibration data worse than the baseline (cost {fit.cost:.4g} against "
                         f"{base.cost:.4g}) although it contains the baseline: the fit failed")
        else:
            notes.append(f"it fits the calibration data worse than the standard baseline (cost {fit.cost:.4g} "
                         f"against {base.cost:.4g}): the {fit.model} model with the shared refitted tube "
                         f"parameters does not reach the standard model's fit, which costs it in the BIC; "
                         f"either the refit (see its convergence) or the model is at fault")
    elif cand_mean > base_mean:
        notes.append(f"it fits the calibration data better (cost {fit.cost:.4g} against {base.cost:.4g}) but the "
                     f"held-out data worse (mean {cand_mean * 1e3:.3f} against {base_mean * 1e3:.3f} mm): its "
                     f"extra parameters absorb a pattern of the calibration samples that does not hold on the "
                     f"held-out ones (overfitting)")
    return "; ".join(notes)


def _decide(candidates: dict, eligible: list, units, options) -> dict:
    """Name an effect among the eligible ones.

    Plausible candidates first (an effect whose fitted values are implausible is not named
    while a plausible one is eligible); among them the largest held-out improvement. Others
    whose held-out residual does not differ significantly from the named one's (paired
    sign-flip test, ``options.significance``) explain the data equally well and are listed.
    """
    plausible = [e for e in eligible if candidates[e]["plausible"]]
    pool = plausible or eligible
    out = {"named": None, "eligible": list(eligible), "equally_good": [], "passed_over_implausible": [],
           "notes": []}
    if not pool:
        return out
    ranked = sorted(pool, key=lambda e: -candidates[e]["improvement_eq49"]["mean_difference"])
    named = ranked[0]
    out["named"] = named
    label = candidates[named]["label"]
    for e in eligible:
        if e not in pool:
            bad = ", ".join(f"{display_value(b['name'], b['value'], b['unit'])} (plausible "
                            f"{_range_text(b)})"
                            for b in candidates[e]["implausible"])
            out["passed_over_implausible"].append(e)
            out["notes"].append(f"{candidates[e]['label']} also explains the held-out data but needs {bad}; it is "
                                f"not named while the plausible {label} explains the data")
    for e in ranked[1:]:
        t = paired_improvement(candidates[e]["_r"], candidates[named]["_r"], units, seed=options.seed)
        if not (t["p_value"] < options.significance):
            out["equally_good"].append({"effect": e, "label": candidates[e]["label"],
                                        "mean_difference": t["mean_difference"], "p_value": t["p_value"]})
    if out["equally_good"]:
        others = ", ".join(f"{d['label']} (held-out Eq. (49) difference {d['mean_difference']:.3f}, p = "
                           f"{d['p_value']:.3f})" for d in out["equally_good"])
        out["notes"].append(f"{label} and {others} explain the held-out data equally well within their "
                            f"uncertainty: the data cannot tell them apart; {label} is listed first for its "
                            f"larger mean improvement only")
    if candidates[named]["implausible"]:
        out["notes"].append(f"{label} is named although its fitted values are implausible: no plausible "
                            f"candidate explains the data")
    return out


#: Pairs that are not combined: one already contains the other (friction contains the
#: clearance model; gradual friction is friction with a friction angle).
_NOT_COMBINED = ({"friction", "clearance"}, {"gradual_friction", "clearance"}, {"friction", "gradual_friction"})
_CONTACT = ("friction", "clearance")


def _combined_model(first: str, second: str) -> str:
    """Mechanics model of two effects together: friction if either needs it, else clearance if
    either needs it, else standard."""
    models = {_MODEL_OF[first], _MODEL_OF[second]}
    return next((m for m in ("friction", "clearance") if m in models), "standard")


def _effect_names(robot, effect: str, data) -> tuple:
    """Parameters a candidate reports as its own: :func:`effect_parameters`, plus the friction
    coefficients that gradual friction carries."""
    extra = tuple(effect_parameters(robot, effect, data))
    return extra + (effect_parameters(robot, "friction") if effect == "gradual_friction" else ())


def _range_text(b: dict) -> str:
    lo, hi = b["plausible"]
    if b["unit"] == "rad":
        return f"{np.rad2deg(lo):.3g}..{np.rad2deg(hi):.3g} deg"
    return f"{lo:.3g}..{hi:.3g}" + ("" if b["unit"] == "-" else f" {b['unit']}")


def display_value(name: str, value: float, unit: str) -> str:
    """A parameter for a printed report: rad as deg, m as mm, others in their SI unit."""
    if unit == "rad":
        return f"{name} = {np.rad2deg(value):.4g} deg"
    if unit == "m":
        return f"{name} = {value * 1e3:.4g} mm"
    return f"{name} = {value:.4g}" + ("" if unit == "-" else f" {unit}")


def _no_effect_sentence(decision: dict, check: dict, candidates: dict) -> str:
    case = decision["no_effect_case"]
    noise = check["noise"]
    if case == "noise":
        return (f"no candidate is eligible, and the held-out residual of the calibrated baseline (rms "
                f"{check['rms_mm']:.3f} mm) is consistent with the sensor noise ({noise['description']}; "
                f"ratio {check['ratio']:.2f} <= {NOISE_RATIO})")
    if case == "unexplained":
        best = min(candidates, key=lambda e: candidates[e]["held_out"]["position_mean_mm"], default=None)
        tail = (f"; the best candidate, {candidates[best]['label']}, reaches a held-out mean of "
                f"{candidates[best]['held_out']['position_mean_mm']:.3f} mm" if best else "")
        return (f"the held-out residual of the calibrated baseline (rms {check['rms_mm']:.3f} mm) is "
                f"{check['ratio']:.1f} times the sensor noise ({noise['description']}): NOT consistent with "
                f"noise. The model misses something that no candidate explains{tail}")
    return (f"no candidate is eligible; whether the held-out residual (rms {check['rms_mm']:.3f} mm) is noise "
            f"cannot be said: the sensor noise is {noise['description']}")


def history_sidecar(model_path) -> Path:
    """Where the history effects of an updated model file go: ``<model>.history.json``."""
    model_path = Path(model_path)
    return model_path.with_name(model_path.stem + ".history.json")


def reproduce_errors(model_path, data: MeasuredData, settings=None, *, n_jobs: int = 1) -> dict:
    """Load an updated model file and evaluate its held-out errors with the model it names.

    Parameters
    ----------
    model_path : path
        Robot model file written by :func:`run_discrepancy` (its ``model`` key names the
        mechanics model; ``[tracker_registration]`` maps to the data's frame).
    data : MeasuredData
    settings : ModelSettings, optional
    n_jobs : int

    Returns
    -------
    dict
        ``position`` (K,) [m], ``angle`` (K,) [rad]: tip position and tangent errors (Eq. (49)
        terms), NaN where the model failed.

    Raises
    ------
    ModelFileError, PhysicalParameterError
        The file does not load.
    """
    from ..io.robot_file import load_robot

    robot = load_robot(model_path)
    model = robot.metadata.get("model") or "standard"
    reg = robot.metadata.get("tracker_registration")
    names, values = (), ()
    if reg:
        names, values = REGISTRATION, tuple(reg["rotation_vector_rad"]) + tuple(reg["translation_m"])
    side = history_sidecar(model_path)
    if side.exists():
        hist = json.loads(side.read_text())["parameters"]
        names, values = names + tuple(hist), values + tuple(hist.values())
    pred = predict(robot, names, values, data, model, settings, n_jobs=n_jobs)
    pos, ang, _ = pose_errors(pred, data)
    return {"position": pos, "angle": ang}


def _cautions(named, candidate, before: dict, after: dict, robot=None) -> list[str]:
    """What a reader of the named effect must not overlook: a fitted value outside what the
    physics allows, or an addition that lowers the mean error but raises the maximum."""
    out = []
    if named is None:
        return out
    bad = candidate.get("implausible")
    if bad is None:   # a candidate dict without the plausibility check (older results)
        bad = [{"name": n, "value": v, "plausible": [0.0, PLAUSIBLE_MU], "unit": "-", "why": ""}
               for n, v in candidate["parameters"].items() if n.startswith("mu_") and v > PLAUSIBLE_MU]
    for b in bad:
        if b["name"].startswith("mu_"):
            out.append(f"{b['name']} = {b['value']:.3g} is larger than plausible Coulomb friction between NiTi "
                       f"tubes (> {b['plausible'][1]:g}; Table VII of Ha et al. 2019 has 0.22 and 0.12): the "
                       f"direction-dependent error is real, but it may come from another hysteretic effect "
                       f"(e.g. backlash or lag in that tube's rotation drive) that the friction model "
                       f"imitates; read the coefficient as a size, not as a material property")
        else:
            out.append(f"{b['name']} = {b['value']:.4g} {b['unit']} is outside its plausible range "
                       f"{b['plausible'][0]:.3g}..{b['plausible'][1]:.3g} {b['unit']} ({b['why']})")
    if after["position_max_mm"] > before["position_max_mm"]:
        out.append(f"the held-out maximum tip error rises from {before['position_max_mm']:.2f} to "
                   f"{after['position_max_mm']:.2f} mm while the mean falls: the added effect makes some "
                   f"samples worse")
    return out


def _has_clearance(robot) -> bool:
    try:
        c = robot.clearances
    except PhysicalParameterError:   # a diameter is missing
        return False
    return c is not None and np.all(np.isfinite(c))


def _grid_progress(echo):
    state = {"last": -1}

    def report(done, total):
        pct = int(100 * done / total)
        if pct // 10 != state["last"]:
            state["last"] = pct // 10
            echo(f"    friction grid search: {done}/{total} points")
    return report
