"""The experiment design: a motion, safe to run, that best separates the open hypotheses or best
determines the uncertain parameters, found by a budgeted greedy search over primitives.

The search is the sequential (greedy) construction of optimum-design practice (Atkinson, Donev &
Tobias 2007, ch. 12; Fedorov 1972): from the start configuration, the feasible primitive
(:mod:`._motions`) with the largest gain of the criterion (:mod:`._criteria`) per second of motion
is appended, until the budget is spent or no primitive adds. A primitive's samples depend on the
motion before them (history effects), so each is evaluated after the motion chosen so far; the
samples already chosen do not change when a primitive is appended (every effect acts on the past
of the motion), which makes the gains exact sums.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from ..choices import DesignMode, JointKind
from ..drive import DriveLimits
from ._criteria import (Information, ds_criterion, information, long_run_factor, noise_weight, prior_precision,
                        sensitivities)
from ._hypotheses import DesignInputError
from ._verdict import _pair_name, naming_table, preference_table, recorded_rows, workflow_split
from ._motions import feasible, joint_configurations, motion_data, primitives, sample, trajectory

logger = logging.getLogger(__name__)

#: Significance level of the predicted power [-] (the discrepancy workflow's default).
POWER_LEVEL = 0.01
#: Control rate of a drive derived from the recorded motion [Hz].
DEFAULT_CONTROL_RATE = 250.0
#: Drive limits of joints the recorded motion did not move (the shipped scenarios' values):
#: velocity, acceleration, jerk for rotations [rad/s^k] and translations [m/s^k].
FALLBACK_DRIVE = {JointKind.ROTATION: (1.0, 4.0, 40.0), JointKind.TRANSLATION: (0.01, 0.04, 0.4)}
#: Predicted correlation [-] from which a parameter is reported as confounded with another.
CONFOUNDED_CORRELATION = 0.9
#: Spacing of the states checked along a primitive's segments [m of the planner's weighted joint
#: metric; 0.025 rad of rotation]: finer than the planner's (0.1 rad), since the regions of several
#: equilibria near a relative rotation of pi can be narrower than that.
CHECK_RESOLUTION = 5e-4
#: The search aims at about this many primitives in a budget: a reversal is cycled up to the
#: budget / TARGET_STEPS (fewer, longer steps; each step costs an evaluation of every candidate).
TARGET_STEPS = 20
#: A candidate piece's information is summed over at most this many of its samples, evenly spaced
#: with both ends, and scaled to all of them (a quadrature of the information along the piece):
#: the ranking of the candidates needs it to a few percent; the designed motion, the recording and
#: the comparisons are evaluated at every sample.
PIECE_SAMPLES = 12


@dataclass(frozen=True, eq=False)
class DesignResult:
    """A designed experiment and what it is predicted to show.

    Attributes
    ----------
    mode : DesignMode
        Separating two or more hypotheses (T-optimality) or determining parameters of one
        (Ds-optimality).
    hypotheses : tuple of Hypothesis
    interest : tuple of str
        Parameters of interest (``"parameters"`` mode).
    primitives : tuple of Primitive
        The designed motion, in order.
    trajectory : Trajectory
        Its jerk-limited trajectory at the drive's control rate.
    time : ndarray, shape (K,)
        Sensor sample times of the designed motion [s].
    joints : ndarray, shape (K, n_joints)
        Joint values at those times [rad or m].
    tips : ndarray, shape (H, K, 3)
        Each hypothesis's predicted tip positions there, in the data's frame [m].
    separation : dict
        ``"recorded"``, ``"designed"`` (recorded and designed together), ``"repeated"`` (the
        recording and a repetition of the same duration as the design), ``"random"`` (recorded
        and each random motion of the same budget) and ``"designed_alone"`` (the designed motion
        without the recording): ``{"a>b": T}`` per ordered pair [-], the expected evidence for a
        against b refitted. Empty in parameters mode.
    stderr : dict
        Parameters mode: the same five keys, ``{parameter: predicted standard error}`` [SI].
    power : dict
        Separate mode: the same keys, the smallest predicted power over the pairs of a 1-degree-of-
        freedom likelihood-ratio test at level :data:`POWER_LEVEL`.
    preference : dict
        Separate mode: ``"recorded"`` and ``"designed"`` (recorded and designed together), each
        ``{"a>b": probability}`` per ordered pair [-]: that the discrepancy workflow's fold
        comparison finds a's error significantly lower than b's at :data:`POWER_LEVEL` when a is
        true (:func:`~ctrplan.design._verdict.preference_probability`; the recording as the
        samples the design evaluated, :func:`~ctrplan.design._verdict.recorded_rows`). Empty in
        parameters mode.
    naming : dict
        Separate mode with a baseline given: ``"recorded"`` and ``"designed"``, each ``{key:
        probability}`` per hypothesis [-]: that the workflow names it alone when it is true, its
        error significantly below the baseline's (Holm's first step) and every rival's
        (:func:`~ctrplan.design._verdict.naming_probability`). Empty otherwise.
    noise_position : float
        Sensor noise per coordinate used [m].
    noise_inflation : float
        Long-run variance factor of the noise used [-] (:attr:`SensorNoise.long_run_factor`).
    noise_lower_bound : bool
        The noise is only a lower bound (:attr:`SensorNoise.lower_bound`): the predicted
        separations and powers are upper bounds, the standard errors lower bounds.
    budget : float
        Duration allowed [s].
    seconds : dict
        Wall time by stage [s].
    evaluations : int
        Model evaluations.
    random_primitives : tuple of tuple of Primitive
        The random motions compared with.
    confounded : dict
        Parameters mode: per parameter of interest, the other free parameters whose predicted
        correlation with it after the design is at least :data:`CONFOUNDED_CORRELATION` in magnitude
        (``{name: correlation}``): what keeps it undetermined when the design cannot shrink it.
    search : DesignSearch or None
        How the search ran (its random motions, seed and primitives).
    """

    mode: DesignMode
    hypotheses: tuple
    interest: tuple
    primitives: tuple
    trajectory: object
    time: np.ndarray
    joints: np.ndarray
    tips: np.ndarray
    separation: dict
    stderr: dict
    power: dict
    noise_position: float
    noise_inflation: float
    budget: float
    noise_lower_bound: bool = False
    seconds: dict = field(default_factory=dict)
    evaluations: int = 0
    random_primitives: tuple = ()
    confounded: dict = field(default_factory=dict)
    preference: dict = field(default_factory=dict)
    search: object = None
    naming: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Duration of the designed motion [s]."""
        return self.trajectory.duration


def drive_from_data(robot, data, control_rate_hz: float = DEFAULT_CONTROL_RATE) -> DriveLimits:
    """Drive limits the recorded motion shows: per joint the 99th percentile of its speed and of
    its acceleration along the record, jerk ten times the acceleration per second (the shipped
    scenarios' ratio); joints the record does not move get :data:`FALLBACK_DRIVE`.

    Raises
    ------
    DesignInputError
        Data without sample times.
    """
    rec = data.record
    if rec.time is None:
        raise DesignInputError(f"{data.file}: no sample times; give the drive limits (a scenario's [drive])")
    q = np.array([robot.joint_vector(a, b) for a, b in zip(rec.alpha, rec.beta)])
    vel, acc, jerk = [], [], []
    seq = rec.sequence if rec.sequence is not None else np.zeros(len(q), int)
    for i, j in enumerate(robot.joints):
        v_all, a_all = [], []
        for s in np.unique(seq):
            m = seq == s
            t, x = rec.time[m], q[m, i]
            if len(t) < 3:
                continue
            v = np.diff(x) / np.diff(t)
            a = np.diff(v) / np.diff(t[1:])
            v_all.append(np.abs(v))
            a_all.append(np.abs(a))
        v99 = float(np.percentile(np.concatenate(v_all), 99)) if v_all else 0.0
        a99 = float(np.percentile(np.concatenate(a_all), 99)) if a_all else 0.0
        fv, fa, fj = FALLBACK_DRIVE[j.kind]
        if v99 > 0 and a99 > 0:
            vel.append(v99)
            acc.append(a99)
            jerk.append(10.0 * a99)
        else:
            vel.append(fv)
            acc.append(fa)
            jerk.append(fj)
    return DriveLimits(control_rate_hz, np.array(vel), np.array(acc), np.array(jerk), tuple(robot.joint_names))


def _period(data) -> float:
    if data.time is None:
        raise DesignInputError(f"{data.file}: no sample times; the sensor's sample rate is needed")
    d = np.diff(data.record.time)
    d = d[d > 0]
    if not d.size:
        raise DesignInputError(f"{data.file}: sample times do not increase")
    return float(np.median(d))


def _piece_information(robot, hyps, weight, settings, frame, t, alpha, beta, pieces) -> list:
    """:class:`Information` of each piece's samples after the motion ``(t, alpha, beta)`` (a task of
    the candidates' evaluation), with the model evaluations it took."""
    out = []
    n0 = len(t)
    for _, ts, a, b in pieces:
        d = motion_data(robot, np.concatenate([t, ts]), None, frame=frame, rows=np.arange(n0, n0 + len(ts)),
                        history=False, configurations=(np.vstack([alpha, a]), np.vstack([beta, b])))
        sens = [sensitivities(robot, h, d, settings) for h in hyps]
        out.append((information(sens, weight), sum(s.evaluations for s in sens)))
    return out


def _thinned(piece) -> tuple:
    """``(piece at most PIECE_SAMPLES of its samples, evenly spaced with both ends, factor)``: the
    piece's information is about ``factor`` times that of the thinned piece."""
    dur, ts, a, b = piece
    keep = np.unique(np.round(np.linspace(0, len(ts) - 1, min(len(ts), PIECE_SAMPLES))).astype(int))
    return (dur, ts[keep], a[keep], b[keep]), len(ts) / keep.size


class _Evaluator:
    """Evaluates motions for the hypotheses (the candidates of a step on ``n_jobs`` processes) and
    keeps the work counters."""

    def __init__(self, robot, hyps, weight, settings, n_jobs):
        from ..parallel import Executor

        self.robot, self.hyps, self.weight, self.settings, self.n_jobs = robot, hyps, weight, settings, n_jobs
        self.executor = Executor(n_jobs)
        self.evaluations = 0

    def sens(self, data):
        return [self.sens_of(h, data) for h in self.hyps]

    def sens_of(self, hyp, data):
        """:func:`sensitivities` of one hypothesis (counted)."""
        out = sensitivities(self.robot, hyp, data, self.settings, n_jobs=self.n_jobs)
        self.evaluations += out.evaluations
        return out

    def info(self, data) -> Information:
        return information(self.sens(data), self.weight)

    def pieces(self, frame, t, alpha, beta, pieces) -> list:
        """:func:`_piece_information` of every piece, in order, split over the processes."""
        chunks = [list(range(k, len(pieces), self.n_jobs)) for k in range(min(self.n_jobs, len(pieces)))]
        common = (self.robot, self.hyps, self.weight, self.settings, frame, t, alpha, beta)
        out = [None] * len(pieces)
        tasks = [(c, (*common, [pieces[i] for i in chunk])) for c, chunk in enumerate(chunks)]
        for c, results in self.executor.run(_piece_information, tasks, first_here=True):
            for i, (inf, evaluations) in zip(chunks[c], results):
                out[i] = inf
                self.evaluations += evaluations
        return out


@dataclass(frozen=True)
class SensorNoise:
    """The tip sensor's noise, as the fit will weigh the samples of the designed motion.

    Attributes
    ----------
    position : float
        Noise rms per tip coordinate [m], > 0 (a discrepancy run's
        ``results.json["noise"]["noise"]["position_rms_m"]`` is the rms length of the 3-D noise
        vector, ``sqrt(3)`` times this: :meth:`from_estimate` converts it).
    lag1 : float, optional
        Lag-one correlation ``phi`` of the correlated part of the noise [-] (None: white).
    correlated_share : float
        Share ``c`` of the noise variance in that correlated part, the rest white [-] (1: all
        AR(1)); the long-run variance factor is ``1 + 2 c phi / (1 - phi)``
        (:func:`~ctrplan.design.noise_weight`).
    lower_bound : bool
        The noise is only a lower bound (the discrepancy run's rests were too short to see its
        correlation): the noise may be larger, so the design's predicted evidence is an upper
        bound.
    """

    position: float
    lag1: float | None = None
    correlated_share: float = 1.0
    lower_bound: bool = False

    @property
    def long_run_factor(self) -> float:
        """``1 + 2 c phi / (1 - phi)`` [-] (:func:`~ctrplan.design._criteria.long_run_factor`)."""
        return long_run_factor(self.lag1, self.correlated_share)

    @classmethod
    def from_estimate(cls, estimate, *, where: str = "noise estimate") -> "SensorNoise":
        """The noise per tip coordinate of a discrepancy run's noise estimate, with the
        estimate's own correlation model (its white share and correlation length).

        Parameters
        ----------
        estimate : NoiseEstimate or mapping
            :class:`ctrplan.discrepancy.NoiseEstimate` or its JSON form
            (``results.json["noise"]["noise"]``): ``position_rms_m``, the rms length of the 3-D
            noise vector [m]; ``nugget_share`` (the white share ``1 - c``) and
            ``correlation_length`` (JSON: ``correlation_length_samples``; ``tau`` [samples],
            ``phi = exp(-1 / tau)``; 0 or None: white); ``lower_bound``. An estimate with only
            ``lag1_correlation`` is taken as all AR(1) (``c = 1``).
        where : str
            What the estimate was read from, for the error message.

        Returns
        -------
        SensorNoise
            ``position = position_rms_m / sqrt(3)`` (the estimate's noise is the same and
            independent in x, y and z).

        Raises
        ------
        DesignInputError
            The estimate has no finite positive ``position_rms_m``, or a white share outside
            [0, 1].
        """
        get = estimate.get if hasattr(estimate, "get") else lambda k: getattr(estimate, k, None)
        rms = get("position_rms_m")
        if isinstance(rms, bool) or not (isinstance(rms, (int, float, np.floating)) and 0 < rms < np.inf):
            raise DesignInputError(f"{where}: position_rms_m {rms!r} is not a noise estimate (> 0 m); give "
                                   f"SensorNoise(position) per tip coordinate")
        tau = get("correlation_length")
        tau = get("correlation_length_samples") if tau is None else tau
        nugget = get("nugget_share")
        lower = bool(get("lower_bound") or False)
        if tau is not None and nugget is not None:
            if not 0.0 <= float(nugget) <= 1.0:
                raise DesignInputError(f"{where}: nugget_share {nugget!r} is not a share in [0, 1]")
            if not float(tau) > 0:
                return cls(float(rms) / math.sqrt(3.0), None, 1.0, lower)
            return cls(float(rms) / math.sqrt(3.0), math.exp(-1.0 / float(tau)), 1.0 - float(nugget), lower)
        lag1 = get("lag1_correlation")
        return cls(float(rms) / math.sqrt(3.0), None if lag1 is None else float(lag1), 1.0, lower)


@dataclass(frozen=True, eq=False)
class ExperimentLimits:
    """What the designed motion keeps to.

    Attributes
    ----------
    drive : DriveLimits, optional
        Drive limits of the motion; default :func:`drive_from_data` (the recorded motion's).
    obstacles : sequence of Obstacle
        Scenario obstacles the robot stays clear of.
    start : array-like, shape (n_joints,), optional
        Start configuration [rad or m]; default the robot's home.
    duration : float, optional
        Budget [s]; default the recorded trajectory's duration.
    rest : float
        Rest after each primitive [s].
    """

    drive: DriveLimits | None = None
    obstacles: tuple = ()
    start: object = None
    duration: float | None = None
    rest: float = 1.0


@dataclass(frozen=True)
class DesignSearch:
    """How the search runs and what it is compared with.

    Attributes
    ----------
    n_random : int
        Random motions of the same budget to compare with.
    seed : int
        Seed of the random motions.
    n_jobs : int
        Processes the candidates of each search step are evaluated on
        (:class:`ctrplan.parallel.Executor`).
    compound : bool
        Also offer the search two-step primitives (``shifted reversal``: a move, then a reversal
        about the new value, :func:`~ctrplan.design._motions.primitives`), which a search adding
        one primitive at a time does not reach when the move alone does not pay.
    """

    n_random: int = 3
    seed: int = 0
    n_jobs: int = 1
    compound: bool = False


def design_experiment(robot, data, hypotheses, *, noise: SensorNoise, limits: ExperimentLimits = ExperimentLimits(),
                      interest=None, settings=None, search: DesignSearch = DesignSearch(), baseline=None,
                      n_candidates: int | None = None) -> DesignResult:
    """Design the next measured trajectory.

    Parameters
    ----------
    robot : Robot
        The robot file the hypotheses were fitted to.
    data : MeasuredData
        The recorded trajectory (:func:`ctrplan.discrepancy.load_measured_data`).
    hypotheses : sequence of Hypothesis
        Two or more: the motion separates them (T-optimality). One: the motion determines its
        parameters of interest (Ds-optimality).
    noise : SensorNoise
        Sensor noise per tip coordinate [m] and its lag-one autocorrelation.
    limits : ExperimentLimits
        Drive limits, obstacles, start, budget [s] and rests [s] of the motion.
    interest : sequence of str, optional
        Parameters mode: the parameters to determine; default the hypothesis's own effect
        parameters the recorded data left undetermined (:meth:`Hypothesis.undetermined`), else every
        undetermined one, else its effect parameters, else every free one.
    settings : ModelSettings, optional
    search : DesignSearch
        Random motions to compare with, their seed, worker processes.
    baseline : Hypothesis, optional
        Separate mode: the model with no effect as the recording's run fitted it
        (``result_hypotheses(results, ["baseline"])[0]``); given, the result's ``naming`` holds the
        probability that the workflow names each hypothesis alone. It does not change the search.
    n_candidates : int, optional
        With ``baseline``: the candidates the workflow tries alone (its Holm family,
        ``results.json["decision"]["family"]``); default the number of hypotheses.

    Returns
    -------
    DesignResult

    Raises
    ------
    DesignInputError
        No hypothesis, the baseline among the hypotheses, a parameter of interest the hypothesis
        does not fit, data without times, a start that is not valid (outside the limits, unstable,
        in collision), or no feasible primitive from the start.
    """
    from ..planning.collision import CollisionChecker
    from ..planning.planners import ValidityChecker
    from ..planning.validity import BatchValidityChecker

    t_all = time.perf_counter()
    hyps = tuple(hypotheses)
    if not hyps:
        raise DesignInputError("no hypothesis to design for")
    if baseline is not None and any(h.key == baseline.key for h in hyps):
        raise DesignInputError(f"the baseline {baseline.key!r} is given among the hypotheses")
    mode = DesignMode.SEPARATE if len(hyps) > 1 else DesignMode.PARAMETERS
    noise_position, drive, obstacles, start, duration, rest = (noise.position, limits.drive, limits.obstacles,
                                                               limits.start, limits.duration, limits.rest)
    n_random, seed, n_jobs = search.n_random, search.seed, search.n_jobs
    weight, inflation = noise_weight(noise_position, noise.lag1, correlated_share=noise.correlated_share)
    period = _period(data)
    drive = drive or drive_from_data(robot, data)
    rec_t = data.record.time
    budget = float(duration) if duration is not None else float(rec_t[-1] - rec_t[0])
    if not budget > 0:
        raise DesignInputError(f"duration {budget!r} s: must be > 0")
    q0 = (np.asarray(start, float) if start is not None
          else robot.joint_vector(robot.home_alpha, robot.home_beta))
    collision = CollisionChecker(obstacles) if obstacles else None
    # candidates pass the planner's compiled checker (limits, convergence, determinant test, collisions);
    # a primitive is appended only after the states along it, checked one by one with the multistart
    # search for other equilibria, pass too: a measured motion must not pass where the tubes can snap
    quick = BatchValidityChecker(robot, collision, settings=settings, check_stability=True)
    checker = BatchValidityChecker(robot, reference=ValidityChecker(robot, collision, settings=settings,
                                                                    check_stability=True),
                                   resolution=CHECK_RESOLUTION)
    if not checker(q0):
        raise DesignInputError(f"start {dict(zip(robot.joint_names, np.round(q0, 6).tolist()))} is outside the joint "
                               f"limits, unstable or in collision")
    interest_idx = ()
    prior = None
    if mode == DesignMode.PARAMETERS:
        h = hyps[0]
        if not interest:
            own, loose = h.effect_parameters(robot), h.undetermined(robot)
            interest = tuple(n for n in loose if n in own) or loose or own or h.free
        bad = [n for n in interest if n not in h.free]
        if bad:
            raise DesignInputError(f"parameter(s) {', '.join(bad)} not fitted by {h.label}; it fits "
                                   f"{', '.join(h.free)}")
        interest_idx = tuple(h.free.index(n) for n in interest)
        prior = prior_precision(robot, h.free)
    else:
        interest = ()
    ev = _Evaluator(robot, hyps, weight, settings, n_jobs)
    seconds = {}

    # the recorded trajectory's information (a subsample standing for every sample)
    t0 = time.perf_counter()
    K = data.n_samples
    rows = recorded_rows(K)
    recorded_sens = ev.sens(data.take(rows))
    recorded = information(recorded_sens, weight)
    recorded = recorded.scaled(K / max(recorded.n_samples, 1)) if recorded.n_samples else recorded
    seconds["recorded"] = time.perf_counter() - t0

    def value(info: Information) -> float:
        if mode == DesignMode.SEPARATE:
            return min(info.separation().values())
        return -ds_criterion(info, 0, interest_idx, prior)

    target = budget / TARGET_STEPS

    class _Prefix:
        """The motion chosen so far: its primitives and its sensor samples (joint arrays)."""

        def __init__(self):
            self.prims, self.q, self.t_done = [], q0, 0.0
            self.t = np.zeros(0)
            self.alpha = np.zeros((0, robot.n_tubes))
            self.beta = np.zeros((0, robot.n_tubes))

        def candidates(self):
            return [p for p in primitives(robot, self.q, rest, drive=drive, min_duration=target,
                                          compound=search.compound)
                    if feasible(quick, p)]

        def piece(self, prim):
            """The samples ``prim`` adds after this prefix, or None past the budget."""
            traj = trajectory(robot, [prim], drive)
            if self.t_done + traj.duration > budget + 1e-9:
                return None
            k0 = int(np.floor(self.t_done / period + 1e-9)) + (1 if self.prims else 0)
            ts = np.arange(k0, int(np.floor((self.t_done + traj.duration) / period + 1e-9)) + 1) * period
            if not ts.size:
                return None
            local = np.clip(ts - self.t_done, 0.0, traj.duration)
            qs = np.column_stack([np.interp(local, traj.t, traj.position[:, i]) for i in range(traj.n_joints)])
            a, b = joint_configurations(robot, qs)
            return traj.duration, ts, a, b

        def evaluate(self, pieces) -> list:
            """The :class:`Information` of each piece's samples after this prefix: summed over at
            most :data:`PIECE_SAMPLES` of them and scaled to all."""
            thin, factors = zip(*(_thinned(p) for p in pieces)) if pieces else ((), ())
            infos = ev.pieces(data.frame, self.t, self.alpha, self.beta, list(thin))
            return [i if f == 1.0 else i.scaled(f) for i, f in zip(infos, factors)]

        def append(self, prim, piece):
            dur, ts, a, b = piece
            self.prims.append(prim)
            self.q, self.t_done = prim.end, self.t_done + dur
            self.t = np.concatenate([self.t, ts])
            self.alpha, self.beta = np.vstack([self.alpha, a]), np.vstack([self.beta, b])

    # greedy search
    t0 = time.perf_counter()
    prefix, info = _Prefix(), recorded
    current = value(recorded)
    while True:
        ranked = []
        cands = [(prim, prefix.piece(prim)) for prim in prefix.candidates()]
        cands = [(prim, piece) for prim, piece in cands if piece is not None]
        for (prim, piece), piece_info in zip(cands, prefix.evaluate([piece for _, piece in cands])):
            new_info = info + piece_info
            gain = (value(new_info) - current) / max(piece[0], 1e-9)
            ranked.append((gain, len(ranked), prim, piece, new_info))
        ranked.sort(key=lambda r: (-r[0], r[1]))
        best = next((r for r in ranked if r[0] > 0 and feasible(checker, r[2])), None)
        if best is None:
            break
        _, _, prim, piece, info = best
        prefix.append(prim, piece)
        current = value(info)
        logger.info(f"design: {prim.describe(robot.joint_names)} ({prefix.t_done:.1f} of {budget:.1f} s)")
    chosen = prefix.prims
    if not chosen:
        raise DesignInputError("no feasible primitive from the start adds to the criterion within the budget "
                               f"of {budget:.3g} s")
    seconds["search"] = time.perf_counter() - t0

    # the designed motion evaluated whole (one continuous sequence, as it will be run)
    t0 = time.perf_counter()
    traj = trajectory(robot, chosen, drive)
    ts, qs = sample(traj, period)
    d = motion_data(robot, ts, qs, frame=data.frame)
    sens = ev.sens(d)
    alone = information(sens, weight)
    designed = recorded + alone
    tips = np.stack([s.tip for s in sens])
    seconds["designed"] = time.perf_counter() - t0

    # the same budget spent at random, or on repeating the recording
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    randoms, random_walks = [], []
    for _ in range(n_random):
        walk, rinfo = _Prefix(), recorded
        while True:
            options = walk.candidates()
            rng.shuffle(options)
            prim = next((p for p in options if feasible(checker, p)), None)
            if prim is None:
                break
            piece = walk.piece(prim)
            if piece is None:
                break
            walk.append(prim, piece)
        if walk.prims:
            # evaluated whole, as the designed motion is (one continuous sequence, as it would be run)
            wts, wqs = sample(trajectory(robot, list(walk.prims), drive), period)
            rinfo = recorded + ev.info(motion_data(robot, wts, wqs, frame=data.frame))
        randoms.append(rinfo)
        random_walks.append(tuple(walk.prims))
    rec_duration = float(rec_t[-1] - rec_t[0])
    repeated = recorded.scaled(1.0 + traj.duration / rec_duration) if rec_duration > 0 else recorded
    seconds["comparison"] = time.perf_counter() - t0

    cases = {"recorded": [recorded], "designed": [designed], "repeated": [repeated], "random": randoms,
             "designed_alone": [alone]}
    separation, power, stderr = {}, {}, {}
    crit = stats.chi2.ppf(1 - POWER_LEVEL, 1)
    for key, infos in cases.items():
        if mode == DesignMode.SEPARATE:
            seps = [{_pair_name(hyps, a, b): t for (a, b), t in i.separation().items()} for i in infos]
            separation[key] = seps if key == "random" else seps[0]
            pw = [min(float(stats.ncx2.sf(crit, 1, max(t, 1e-12))) for t in s.values()) for s in seps]
            power[key] = pw if key == "random" else pw[0]
        else:
            ses = []
            for i in infos:
                cov = i.covariance(0, prior)
                ses.append({n: float(np.sqrt(cov[j, j])) for n, j in zip(interest, interest_idx)})
            stderr[key] = ses if key == "random" else ses[0]
    preference, naming = {}, {}
    if mode == DesignMode.SEPARATE:
        plans = {"recorded": workflow_split(K, len(rows)), "designed": workflow_split([K, len(ts)], len(rows) + len(ts))}
        for key, parts in (("recorded", [recorded_sens]), ("designed", [recorded_sens, sens])):
            preference[key] = preference_table(hyps, parts, noise, level=POWER_LEVEL, plan=plans[key], seed=seed)
        if baseline is not None:
            t0 = time.perf_counter()
            base_recorded, base_designed = ev.sens_of(baseline, data.take(rows)), ev.sens_of(baseline, d)
            m = len(hyps) if n_candidates is None else int(n_candidates)
            for key, parts in (("recorded", [[*recorded_sens, base_recorded]]),
                               ("designed", [[*recorded_sens, base_recorded], [*sens, base_designed]])):
                naming[key] = naming_table(hyps, parts, noise, level=POWER_LEVEL, n_candidates=m, plan=plans[key],
                                           seed=seed)
            seconds["naming"] = time.perf_counter() - t0
    confounded = {}
    if mode == DesignMode.PARAMETERS:
        cov = designed.covariance(0, prior)
        sd = np.sqrt(np.diag(cov))
        corr = cov / np.outer(sd, sd)
        free = hyps[0].free
        for n, j in zip(interest, interest_idx):
            confounded[n] = {free[k]: float(corr[j, k]) for k in np.argsort(-np.abs(corr[j]))
                             if k != j and abs(corr[j, k]) >= CONFOUNDED_CORRELATION}
    seconds["total"] = time.perf_counter() - t_all
    return DesignResult(mode=mode, hypotheses=hyps, interest=tuple(interest), primitives=tuple(chosen),
                        trajectory=traj, time=ts, joints=qs, tips=tips, separation=separation, stderr=stderr,
                        power=power, noise_position=float(noise_position), noise_inflation=float(inflation),
                        budget=budget, noise_lower_bound=bool(noise.lower_bound), seconds=seconds, evaluations=ev.evaluations,
                        random_primitives=tuple(random_walks), confounded=confounded, preference=preference,
                        search=search, naming=naming)
