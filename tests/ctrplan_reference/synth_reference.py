"""Measured-like data with known hidden effects, made independently of the code that fits it.

The discrepancy workflow fits history effects through ``ctrplan.history``, ``ctrplan.effects``
and ``ctrplan.discrepancy.fits.simulate``; ``ctrplan.discrepancy.measured.synth`` hides effects through the same
code, so a sign or convention error in an operator would hide itself. This module makes the data
another way:

- the motion is analytic (:func:`reference_motion`): seeded rest-to-rest moves with a quintic
  minimum-jerk profile (Flash & Hogan, J. Neurosci. 5(7):1688, 1985), evaluated at any time;
- the history effects are the rules of :mod:`history_reference` (drive backlash on a fine time
  grid of the analytic motion, the tracker's lag as an exact evaluation time, the friction
  state by an event loop per pair);
- the truth poses come from the frozen reference solvers of this directory
  (:mod:`standard_reference` with branch following, :mod:`contact_reference` for the clearance
  and friction models of Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019,
  doi:10.1109/TRO.2018.2878906).

It imports from ``ctrplan`` only the robot description (``robot.joints``, limits,
``robot.configuration``) and the ``ModelSettings`` the reference solvers take.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ctrplan.mechanics.results import ModelSettings

from . import contact_reference, standard_reference
from .history_reference import applied_friction, pair_history, play_band, tracker_times

__all__ = ["ReferenceMotion", "reference_motion", "synthesize_reference", "synthesize_reference_grid", "ROTATION_STEP_DEG",
           "TRANSLATION_STEP_MIN", "REST_S"]

#: Rotation of one move [deg]: uniform in this range (docs/discrepancy.md, trajectory protocol).
ROTATION_STEP_DEG = (20.0, 120.0)
#: Smallest translation of one move [m].
TRANSLATION_STEP_MIN = 5e-3
#: Rest after every move [s]: uniform in this range. The lower end is above the sampling
#: interval of a 10 Hz record, so no sample interval spans a reversal.
REST_S = (0.3, 1.5)
#: Mean speeds that set a move's duration: rotation [rad/s], translation [m/s]; durations are
#: clipped to MOVE_S [s].
ROTATION_SPEED = np.deg2rad(60.0)
TRANSLATION_SPEED = 0.02
MOVE_S = (0.8, 3.0)
#: Shares of the move kinds when the robot has both joint kinds: pure translation, concurrent
#: rotation and translation (the rest are pure rotations).
PURE_TRANSLATION_SHARE = 0.25
CONCURRENT_SHARE = 0.25
#: A periodic rotation joint turns back when a move would take it beyond this angle [rad].
TURN_LIMIT = 2.0 * np.pi
#: Fine grid of the drive backlash: this many steps per sampling interval.
FINE_STEPS_PER_SAMPLE = 20


def _min_jerk(u):
    """Quintic rest-to-rest profile s(u), s'(u), s''(u) for u in [0, 1] (s(0) = 0, s(1) = 1)."""
    u = np.clip(u, 0.0, 1.0)
    s = u ** 3 * (10.0 - 15.0 * u + 6.0 * u ** 2)
    ds = 30.0 * u ** 2 * (1.0 - u) ** 2
    dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return s, ds, dds


@dataclass(frozen=True, eq=False)
class ReferenceMotion:
    """A continuous joint motion made of rest-to-rest moves, evaluated exactly at any time.

    Moves do not overlap in time; all joints of one move share its start, duration and profile
    (so every relative angle is monotone within a move). Outside ``[0, end_time]`` the motion
    is held at its first / last value.

    Attributes
    ----------
    joint_names : tuple of str, length J
        ``robot.joint_names``.
    rotation : ndarray of bool, shape (J,)
        Which joints are rotations (the others translations).
    q0 : ndarray, shape (J,)
        Joint values at rest at time 0 [rad or m].
    starts : ndarray, shape (M,)
        Start time of each move [s], increasing.
    durations : ndarray, shape (M,)
        Duration of each move [s].
    steps : ndarray, shape (M, J)
        Change of every joint in each move [rad or m] (0 for joints that do not move).
    times : ndarray, shape (K,)
        Sample times [s], ``k / rate_hz``.
    end_time : float
        Last sample time [s].
    """

    joint_names: tuple
    rotation: np.ndarray
    q0: np.ndarray
    starts: np.ndarray
    durations: np.ndarray
    steps: np.ndarray
    times: np.ndarray
    end_time: float

    def _locate(self, t):
        t = np.minimum(np.maximum(np.asarray(t, dtype=float).reshape(-1), 0.0), self.end_time)
        move = np.searchsorted(self.starts, t, side="right") - 1
        before = self.q0[None, :] + np.vstack([np.zeros((1, self.q0.size)), np.cumsum(self.steps, axis=0)])
        idx = np.maximum(move, 0)
        u = np.where(move >= 0, (t - self.starts[idx]) / self.durations[idx], 0.0)
        return move, idx, u, before

    def __call__(self, t) -> np.ndarray:
        """Joint values at times ``t`` (array-like, shape (K,) [s]): ndarray, shape (K, J)."""
        move, idx, u, before = self._locate(t)
        s, _, _ = _min_jerk(u)
        q = before[idx] + self.steps[idx] * s[:, None]         # before[m]: joints at the start of move m
        return np.where((move >= 0)[:, None], q, self.q0[None, :])

    def velocity(self, t) -> np.ndarray:
        """Joint velocities at times ``t`` [rad/s or m/s], shape (K, J)."""
        move, idx, u, _ = self._locate(t)
        _, ds, _ = _min_jerk(u)
        return np.where((move >= 0)[:, None], self.steps[idx] * (ds / self.durations[idx])[:, None], 0.0)

    def acceleration(self, t) -> np.ndarray:
        """Joint accelerations at times ``t`` [rad/s^2 or m/s^2], shape (K, J)."""
        move, idx, u, _ = self._locate(t)
        _, _, dds = _min_jerk(u)
        return np.where((move >= 0)[:, None], self.steps[idx] * (dds / self.durations[idx] ** 2)[:, None], 0.0)

    def reversals(self) -> np.ndarray:
        """Number of direction reversals of each joint, shape (J,) int (consecutive moves of the
        joint in opposite directions; each happens at rest)."""
        out = np.zeros(self.q0.size, dtype=int)
        for j in range(self.q0.size):
            s = np.sign(self.steps[:, j])
            s = s[s != 0]
            out[j] = int(np.sum(s[1:] != s[:-1]))
        return out


def reference_motion(robot, *, samples: int = 500, rate_hz: float = 10.0, seed: int = 0,
                     rng: np.random.Generator | None = None) -> ReferenceMotion:
    """A seeded continuous motion of every joint of ``robot``, long enough for ``samples`` samples.

    Starting at rest at the robot's home joint values (clipped to the limits), moves follow
    each other, each followed by a rest of :data:`REST_S` seconds:

    - rotations of :data:`ROTATION_STEP_DEG` degrees of one or more rotation joints, each
      reversing the joint's previous direction with probability 1/2 (turning back before a
      periodic joint would pass :data:`TURN_LIMIT`, or at a limit);
    - translations of one or more translation joints to a uniform value within the limits at
      least :data:`TRANSLATION_STEP_MIN` away;
    - with both joint kinds, :data:`PURE_TRANSLATION_SHARE` of the moves are pure translations
      (translation-last samples) and :data:`CONCURRENT_SHARE` concurrent rotation and
      translation.

    Parameters
    ----------
    robot : ctrplan.robot.Robot
    samples : int
        Number of samples, >= 2.
    rate_hz : float
        Sampling rate [Hz], > 0.
    seed : int
        Seed of the generator (ignored when ``rng`` is given).
    rng : numpy.random.Generator, optional

    Returns
    -------
    ReferenceMotion
        Callable ``q(t)``, with the sample times ``k / rate_hz`` [s].

    Raises
    ------
    ValueError
        ``samples`` < 2, ``rate_hz`` <= 0, or a robot without joints.
    """
    if samples < 2 or not rate_hz > 0:
        raise ValueError(f"need samples >= 2 and rate_hz > 0, got {samples!r} and {rate_hz!r} Hz")
    joints = robot.joints
    if not joints:
        raise ValueError(f"robot {robot.name!r} has no joints to move")
    rng = np.random.default_rng(seed) if rng is None else rng
    J = len(joints)
    rotation = np.array([j.kind == "rotation" for j in joints])
    lower, upper = robot.joint_lower, robot.joint_upper
    periodic = np.array([j.periodic for j in joints])
    q = np.clip(robot.joint_vector(robot.home_alpha, robot.home_beta), lower, upper)
    q0 = q.copy()
    last_dir = rng.choice((-1.0, 1.0), size=J)
    times = np.arange(samples) / rate_hz
    end_time = float(times[-1])
    starts, durations, steps = [], [], []
    rot_idx, trans_idx = np.flatnonzero(rotation), np.flatnonzero(~rotation)
    t = rng.uniform(*REST_S)
    while t < end_time or not starts:
        if rot_idx.size and trans_idx.size:
            x = rng.uniform()
            kind = ("translation" if x < PURE_TRANSLATION_SHARE else
                    "both" if x < PURE_TRANSLATION_SHARE + CONCURRENT_SHARE else "rotation")
        else:
            kind = "rotation" if rot_idx.size else "translation"
        step = np.zeros(J)
        if kind in ("rotation", "both"):
            moving = rot_idx[rng.uniform(size=rot_idx.size) < 0.6]
            if moving.size == 0:
                moving = rng.choice(rot_idx, size=1)
            for j in moving:
                amount = np.deg2rad(rng.uniform(*ROTATION_STEP_DEG))
                d = -last_dir[j] if rng.uniform() < 0.5 else last_dir[j]
                lo, hi = (-TURN_LIMIT, TURN_LIMIT) if periodic[j] else (lower[j], upper[j])
                if not lo <= q[j] + d * amount <= hi:
                    d = -d
                target = np.clip(q[j] + d * amount, lo, hi)
                if abs(target - q[j]) < np.deg2rad(ROTATION_STEP_DEG[0]) / 2:
                    continue
                step[j] = target - q[j]
                last_dir[j] = np.sign(step[j])
        if kind in ("translation", "both"):
            moving = trans_idx[rng.uniform(size=trans_idx.size) < 0.7]
            if moving.size == 0:
                moving = rng.choice(trans_idx, size=1)
            for j in moving:
                if upper[j] - lower[j] < 2 * TRANSLATION_STEP_MIN:
                    continue
                for _ in range(100):
                    target = rng.uniform(lower[j], upper[j])
                    if abs(target - q[j]) >= TRANSLATION_STEP_MIN:
                        step[j] = target - q[j]
                        break
        if not np.any(step):
            continue
        need = max(np.max(np.abs(step[rotation]), initial=0.0) / ROTATION_SPEED,
                   np.max(np.abs(step[~rotation]), initial=0.0) / TRANSLATION_SPEED)
        duration = float(np.clip(need, *MOVE_S) * rng.uniform(0.8, 1.25))
        starts.append(t)
        durations.append(duration)
        steps.append(step)
        q = q + step
        t += duration + rng.uniform(*REST_S)
    return ReferenceMotion(joint_names=tuple(robot.joint_names), rotation=rotation, q0=q0,
                           starts=np.asarray(starts, float), durations=np.asarray(durations, float),
                           steps=np.asarray(steps, float).reshape(-1, J), times=times, end_time=end_time)


def _affine_configuration(robot):
    """The joint-to-configuration map of ``robot.configuration`` as ``alpha = A_a q + a0``,
    ``beta = A_b q + b0`` (it is affine: joints set base values, links add offsets); returns a
    function of q (N, J) -> alpha (N, n), beta (N, n)."""
    J = len(robot.joints)
    a0, b0 = robot.configuration(np.zeros(J), check_limits=False)
    Aa = np.zeros((robot.n_tubes, J))
    Ab = np.zeros((robot.n_tubes, J))
    for j in range(J):
        e = np.zeros(J)
        e[j] = 1.0
        a, b = robot.configuration(e, check_limits=False)
        Aa[:, j], Ab[:, j] = a - a0, b - b0
    return lambda q: (q @ Aa.T + a0, q @ Ab.T + b0)


def _tangent_noise(tangent, sigma, rng):
    """Rotate unit tangents (K, 3) about random axes perpendicular to them by a 2-D Gaussian
    rotation vector of per-component standard deviation ``sigma`` [rad]."""
    out = tangent.copy()
    for k, t in enumerate(tangent):
        helper = np.array([1.0, 0.0, 0.0]) if abs(t[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(t, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(t, e1)
        w = sigma * (rng.standard_normal() * e1 + rng.standard_normal() * e2)
        angle = np.linalg.norm(w)
        if angle > 0:
            axis = w / angle
            v = t * np.cos(angle) + np.cross(axis, t) * np.sin(angle)
            out[k] = v / np.linalg.norm(v)
    return out


def _position_noise(K, rms, phi, rng):
    """Isotropic Gaussian position noise (K, 3) [m] whose 3-D rms length is ``rms``, each
    component an AR(1) sequence with coefficient ``phi`` started in its stationary law."""
    sigma = rms / np.sqrt(3.0)
    w = rng.standard_normal((K, 3))
    out = np.empty((K, 3))
    if K:
        out[0] = sigma * w[0]
    for k in range(1, K):
        out[k] = phi * out[k - 1] + np.sqrt(1.0 - phi ** 2) * sigma * w[k]
    return out


def _one_blas_thread():
    """Context limiting BLAS to one thread (small dense solves are faster so, and a shared
    machine is not oversubscribed); a no-op without threadpoolctl."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(1)


def _solve_along(robot, alpha, beta, eta, mu, contact, settings) -> dict:
    """Truth poses along one continuous motion with the reference solvers.

    Each standard solve starts from the previous sample's base torsions (branch following; zero
    twist at the start and after a failed sample). With ``contact`` the friction model
    (directions ``eta``, coefficients ``mu``) is solved where some pair has ``mu > 0``, else the
    clearance model. A sample whose configuration and friction state equal the previous
    sample's reuses its solution.

    Parameters
    ----------
    robot : ctrplan.robot.Robot
    alpha, beta : ndarray, shape (K, n)
        Tube base angles [rad] and translations [m].
    eta : ndarray of int, shape (K, n - 1)
        Applied friction direction (0: none).
    mu : ndarray, shape (K, n - 1)
        Applied friction coefficient [-].
    contact : bool
    settings : ModelSettings

    Returns
    -------
    dict
        ``tip``, ``tangent`` (K, 3) [m], [-] (NaN where failed), ``base_torsion`` (K, n) [1/m],
        ``ok`` (K,) bool, ``model`` and ``message`` (lists of K str), ``counts`` of solves.
    """
    K, n = alpha.shape
    tip = np.full((K, 3), np.nan)
    tangent = np.full((K, 3), np.nan)
    torsion = np.full((K, n), np.nan)
    ok = np.zeros(K, dtype=bool)
    model, messages = [""] * K, [""] * K
    counts = dict(standard=0, clearance=0, friction=0, reused=0)
    prev = None           # (alpha, beta, eta, mu, standard, solution, model) of the previous sample
    for k in range(K):
        a, b, e, m = alpha[k], beta[k], eta[k], mu[k]
        if prev is not None and all(np.array_equal(x, y) for x, y in zip((a, b, e, m), prev[:4])):
            std, sol, model[k] = prev[4], prev[5], prev[6]
            counts["reused"] += 1
        else:
            guess = None if prev is None else prev[4].base_torsion
            try:
                std = standard_reference.solve_standard(robot, a, b, settings, initial_guess=guess,
                                                        check_stability=False)
                counts["standard"] += 1
                if not std.diagnostics.ok:
                    raise RuntimeError(f"standard model: {std.diagnostics.message}")
                sol, model[k] = std, "standard"
                if contact and np.any(m > 0):
                    sol = contact_reference.solve_friction(robot, a, b, np.where(e == 0, 1, e), settings, mu=m,
                                                           standard=std)
                    model[k] = "friction"
                    counts["friction"] += 1
                elif contact:
                    sol = contact_reference.solve_clearance(robot, a, b, settings, standard=std)
                    model[k] = "clearance"
                    counts["clearance"] += 1
                if contact and not sol.diagnostics.converged:
                    raise RuntimeError(sol.diagnostics.message)
            except Exception as exc:  # noqa: BLE001 - any failure drops the sample, as documented
                messages[k] = f"{type(exc).__name__}: {exc}"
                prev = None
                continue
        ok[k] = True
        messages[k] = sol.diagnostics.message
        tip[k], tangent[k], torsion[k] = sol.tip_position, sol.tip_tangent, std.base_torsion
        prev = (a, b, e, m, std, sol, model[k])
    return dict(tip=tip, tangent=tangent, base_torsion=torsion, ok=ok, model=model, message=messages,
                counts=counts)


def synthesize_reference(robot, *, samples: int = 500, rate_hz: float = 10.0, backlash=None,
                         time_offset: float = 0.0, mu=None, friction_angle: float = 0.0, registration=None,
                         noise_position_rms: float = 0.5e-3, noise_angle_rms: float = float(np.deg2rad(0.3)),
                         noise_ar1: float = 0.0, seed: int = 0, ds: float = 3e-3) -> tuple[pd.DataFrame, dict]:
    """A measured-like record of ``robot`` along a seeded continuous motion, with hidden effects.

    Order of the effects: drive backlash turns the commanded (drive) motion into the tubes'
    motion (:func:`history_reference.play_band` on a grid of :data:`FINE_STEPS_PER_SAMPLE` steps
    per sampling interval, holding also every time the tracker reads); the tracker reading at
    time t shows the tubes' motion at ``t - time_offset``
    (:func:`history_reference.tracker_times`); the friction state is read from the tubes' motion
    at those times, sample by sample (:func:`history_reference.pair_history`). The truth is
    solved at the tubes' configurations, each sample's standard solve starting from the
    previous sample's base torsions (branch following; zero twist after a failed sample):

    - ``mu`` None: the standard model (:func:`standard_reference.solve_standard`);
    - ``mu`` given: the contact models of :mod:`contact_reference`, the friction model
      (:func:`contact_reference.solve_friction` with the applied directions and coefficients
      ``|e_k| mu_k``) where some pair carries friction, else the clearance model (all ``mu``
      zero: the clearance model throughout). A sample whose configuration and friction state
      equal the previous sample's (a rest) reuses its solution.

    Then the registration maps the truth to the tracker frame, and noise is added.

    Cost per solved (moving) sample, measured on a shared 2-core machine with one BLAS thread
    (the solves run under ``threadpool_limits(1)``; rest samples reuse the previous solution):
    standard truth 1.4 ms (Table I tube pair) and 2.2 ms (Table VII robot) at ds 3 mm, a
    500-sample record in 0.5-0.7 s; friction truth (the reference contact solver is plain
    Python and numpy) 22 ms (tube pair, ds 6 mm; 90 samples in 1.4 s), 57 ms (tube pair,
    ds 3 mm) and 0.07-0.12 s (Table VII robot, ds 6 mm; 120 samples in 11 s).

    Parameters
    ----------
    robot : ctrplan.robot.Robot
        The truth robot (misspecified tube parameters, off-plane precurvature, Poisson ratios:
        pass them with ``robot.replace(...)``); needs tube diameters when ``mu`` is given.
    samples : int
        Samples of the record (K), >= 2.
    rate_hz : float
        Sampling rate [Hz].
    backlash : array-like, shape (n,), optional
        Dead band of each tube's rotation drive [rad], >= 0 (default none).
    time_offset : float
        tau [s]: the tracker reading at t shows the tubes at ``t - tau``.
    mu : array-like, shape (n - 1,), optional
        Friction coefficient of each pair [-], >= 0; selects the contact truth (see above).
    friction_angle : float
        theta_c of gradually developing friction [rad], >= 0 (0: the paper's abrupt model).
    registration : array-like, shape (6,), optional
        ``(rx, ry, rz, tx, ty, tz)``: rotation vector [rad] and translation [m] of
        ``p_tracker = exp([r]x) p + t`` (default: the robot frame).
    noise_position_rms : float
        rms length of the 3-D position error [m] (per component rms / sqrt(3)).
    noise_angle_rms : float
        rms angle of the tangent error [rad] (a rotation about a random axis perpendicular to
        the tangent, 2-D Gaussian rotation vector).
    noise_ar1 : float
        AR(1) coefficient phi of each position noise component at the sample rate, in
        (-1, 1); the stationary variance keeps the rms as given.
    seed : int
        One ``numpy.random.Generator`` drives the motion and then the noise.
    ds : float
        Largest arc-length step of the solvers [m] (``ModelSettings(ds=ds, multistart=0)``).

    Returns
    -------
    frame : pandas.DataFrame
        Columns ``time`` [s], ``sequence`` (0), ``alpha_1..n`` [rad], ``beta_1..n`` [m] (the
        COMMANDED joints at the sample times), ``tip_x, tip_y, tip_z`` [m],
        ``tangent_x, tangent_y, tangent_z``; rows whose truth solve failed are dropped. Loads
        with :func:`ctrplan.discrepancy.measured.data.load_measured_data` (frame ``"tracker"`` when a
        registration is given).
    truth : dict
        ``motion`` (:class:`ReferenceMotion`), ``times`` (K,) [s], ``kept`` (K,) bool,
        ``dropped`` (list of ``{"row", "time", "message"}``), ``alpha_commanded``,
        ``beta_commanded``, ``alpha``, ``beta`` (K, n) (the tubes' configuration solved
        [rad, m]), ``seen_times`` (K,) [s], ``eta``, ``released``, ``friction`` (K, n - 1) (the
        state), ``eta_applied``, ``mu_applied`` (K, n - 1), ``tip``, ``tangent`` (K, 3) (robot
        frame, noise free, NaN where dropped), ``tip_measured``, ``tangent_measured`` (K, 3),
        ``model`` per sample, ``base_torsion`` (K, n) [1/m], the effects and noise given,
        ``frame``, ``settings``, ``reversals`` (J,), ``translation_last_samples``, ``counts``
        (solves, reuses) and ``seconds``.

    Raises
    ------
    ValueError
        Bad shapes or values of the effects or the noise.
    """
    t_start = _time.perf_counter()
    n, m = robot.n_tubes, robot.n_tubes - 1
    b = np.zeros(n) if backlash is None else np.asarray(backlash, dtype=float).reshape(-1)
    if b.shape != (n,) or not np.all(np.isfinite(b)) or np.any(b < 0):
        raise ValueError(f"backlash must hold {n} finite widths >= 0 rad, got {b.tolist()}")
    if not np.isfinite(time_offset):
        raise ValueError(f"time_offset must be finite, got {time_offset!r} s")
    contact = mu is not None
    mu_pairs = np.zeros(m) if mu is None else np.asarray(mu, dtype=float).reshape(-1)
    if mu_pairs.shape != (m,) or not np.all(np.isfinite(mu_pairs)) or np.any(mu_pairs < 0):
        raise ValueError(f"mu must hold {m} finite values >= 0, got {mu_pairs.tolist()}")
    if not (np.isfinite(friction_angle) and friction_angle >= 0):
        raise ValueError(f"friction_angle must be finite and >= 0 rad, got {friction_angle!r}")
    if not -1.0 < noise_ar1 < 1.0:
        raise ValueError(f"noise_ar1 must be in (-1, 1), got {noise_ar1!r}")
    if noise_position_rms < 0 or noise_angle_rms < 0:
        raise ValueError("noise rms values must be >= 0")
    reg = None if registration is None else np.asarray(registration, dtype=float).reshape(-1)
    if reg is not None and (reg.shape != (6,) or not np.all(np.isfinite(reg))):
        raise ValueError(f"registration must hold 6 finite values (rx, ry, rz [rad], tx, ty, tz [m]), got {reg}")
    settings = ModelSettings(ds=ds, multistart=0)
    rng = np.random.default_rng(seed)
    motion = reference_motion(robot, samples=samples, rate_hz=rate_hz, rng=rng)
    times = motion.times
    K = times.size
    to_config = _affine_configuration(robot)

    # commanded joints at the sample times (recorded), through robot.configuration
    q_cmd = motion(times)
    alpha_cmd = np.empty((K, n))
    beta_cmd = np.empty((K, n))
    for k in range(K):
        alpha_cmd[k], beta_cmd[k] = robot.configuration(q_cmd[k])
    a_chk, b_chk = to_config(q_cmd)
    if not (np.allclose(a_chk, alpha_cmd, rtol=0, atol=1e-12) and np.allclose(b_chk, beta_cmd, rtol=0, atol=1e-12)):
        raise RuntimeError(f"robot {robot.name!r}: robot.configuration is not affine in the joints")

    # the tubes' motion at the times the tracker shows
    seen_times = tracker_times(times, time_offset, 0.0, motion.end_time)
    alpha_seen, beta_seen = to_config(motion(seen_times))
    if np.any(b > 0):
        fine = np.arange(0.0, motion.end_time, 1.0 / (rate_hz * FINE_STEPS_PER_SAMPLE))
        grid = np.unique(np.concatenate([fine, times, seen_times, [motion.end_time]]))
        drive_fine, _ = to_config(motion(grid))
        tubes_fine = play_band(drive_fine, b)
        alpha_seen = tubes_fine[np.searchsorted(grid, seen_times)]

    # friction state along the tubes' motion
    hist = pair_history(alpha_seen, beta_seen, friction_angle=friction_angle)
    eta_applied, mu_applied = applied_friction(hist.friction, mu_pairs)

    # truth solves
    with _one_blas_thread():
        solved = _solve_along(robot, alpha_seen, beta_seen, eta_applied, mu_applied, contact, settings)
    tip, tangent, torsion, ok = solved["tip"], solved["tangent"], solved["base_torsion"], solved["ok"]
    model, messages, counts = solved["model"], solved["message"], solved["counts"]

    # measurement: registration, then noise (drawn for every sample, dropped rows included)
    tip_m, tangent_m = tip.copy(), tangent.copy()
    if reg is not None:
        R = Rotation.from_rotvec(reg[:3]).as_matrix()
        tip_m = tip_m @ R.T + reg[3:]
        tangent_m = tangent_m @ R.T
    tip_m = tip_m + _position_noise(K, noise_position_rms, noise_ar1, rng)
    if noise_angle_rms > 0:
        good = np.isfinite(tangent_m[:, 0])
        tangent_m[good] = _tangent_noise(tangent_m[good], noise_angle_rms / np.sqrt(2.0), rng)

    cols = {"time": times, "sequence": np.zeros(K, dtype=int)}
    cols.update({f"alpha_{i + 1}": alpha_cmd[:, i] for i in range(n)})
    cols.update({f"beta_{i + 1}": beta_cmd[:, i] for i in range(n)})
    cols.update({f"tip_{c}": tip_m[:, a] for a, c in enumerate("xyz")})
    cols.update({f"tangent_{c}": tangent_m[:, a] for a, c in enumerate("xyz")})
    frame = pd.DataFrame(cols)[ok].reset_index(drop=True)
    truth = dict(
        motion=motion, times=times, kept=ok,
        dropped=[{"row": int(k), "time": float(times[k]), "message": messages[k]} for k in np.flatnonzero(~ok)],
        alpha_commanded=alpha_cmd, beta_commanded=beta_cmd, alpha=alpha_seen, beta=beta_seen,
        seen_times=seen_times, eta=hist.eta, released=hist.released, rotated=hist.rotated,
        friction=hist.friction, eta_applied=eta_applied, mu_applied=mu_applied, tip=tip, tangent=tangent,
        tip_measured=tip_m, tangent_measured=tangent_m, model=model, message=messages, base_torsion=torsion,
        backlash=b, time_offset=float(time_offset), mu=None if mu is None else mu_pairs,
        friction_angle=float(friction_angle), registration=reg,
        frame="robot" if reg is None else "tracker",
        noise=dict(position_rms=noise_position_rms, angle_rms=noise_angle_rms, ar1=noise_ar1),
        seed=seed, settings=settings, reversals=motion.reversals(),
        translation_last_samples=int(np.sum(np.any(hist.released & (hist.eta != 0), axis=1))),
        counts=counts, seconds=_time.perf_counter() - t_start)
    return frame, truth


def synthesize_reference_grid(robot, *, grid: int = 5, mu=None, registration=None,
                              noise_position_rms: float = 1.4e-3, noise_angle_rms: float = float(np.deg2rad(0.5)),
                              seed: int = 0, ds: float = 3e-3) -> tuple[pd.DataFrame, dict]:
    """Measured-like data of the paper's protocol (Section V-C of Ha, Fagogenis & Dupont 2019),
    made independently of ``ctrplan.discrepancy.measured.synth``.

    Every node of a ``grid`` per joint grid over ``robot.joints`` (a periodic rotation without its
    upper end, which is its lower end again), approached from every combination of relative
    rotation directions eta in {+1, -1} per pair; only the target is measured. The truth is the
    frozen reference friction model with the approach's eta (``mu`` given), else the standard
    model (the approach does not matter: one solve per node, from zero twist). Noise as
    :func:`synthesize_reference` (white), registration as there.

    Parameters
    ----------
    robot : ctrplan.robot.Robot
    grid : int
        Nodes per joint, >= 2.
    mu : array-like, shape (n - 1,), optional
        Friction coefficients [-] of the truth.
    registration : array-like, shape (6,), optional
        ``(rx, ry, rz, tx, ty, tz)`` [rad, m] of ``p_tracker = exp([r]x) p + t``.
    noise_position_rms, noise_angle_rms : float
        [m], [rad].
    seed : int
    ds : float
        [m].

    Returns
    -------
    frame : pandas.DataFrame
        ``sequence`` (one per approach), ``config_id`` (one per node), ``alpha_1..n`` [rad],
        ``beta_1..n`` [m], ``eta_1..n-1``, ``tip_x..z`` [m], ``tangent_x..z``; nodes whose truth
        solve failed are dropped with all their approaches.
    truth : dict
        ``dropped`` (node indices and messages), ``eta``, ``tip``, ``tangent`` (noise free),
        ``counts``, ``seconds``.
    """
    import itertools

    t_start = _time.perf_counter()
    n, m = robot.n_tubes, robot.n_tubes - 1
    if grid < 2:
        raise ValueError(f"grid must be >= 2, got {grid!r}")
    axes = []
    for j in robot.joints:
        if j.periodic:
            axes.append(j.lower + (j.upper - j.lower) * np.arange(grid) / grid)
        else:
            axes.append(np.linspace(j.lower, j.upper, grid))
    nodes = np.array(list(itertools.product(*axes)), float).reshape(-1, len(robot.joints))
    etas = np.array(list(itertools.product((1, -1), repeat=m)), int).reshape(-1, m)
    settings = ModelSettings(ds=ds, multistart=0)
    rng = np.random.default_rng(seed)
    rows, dropped = [], []
    counts = dict(standard=0, friction=0)
    with _one_blas_thread():
        for c, q in enumerate(nodes):
            alpha, beta = robot.configuration(q)
            try:
                std = standard_reference.solve_standard(robot, alpha, beta, settings, check_stability=False)
                counts["standard"] += 1
                if not std.diagnostics.ok:
                    raise RuntimeError(f"standard model: {std.diagnostics.message}")
                sols = []
                for e in etas:
                    if mu is None:
                        sols.append(std)
                        continue
                    sol = contact_reference.solve_friction(robot, alpha, beta, e, settings, mu=np.asarray(mu, float),
                                                           standard=std)
                    counts["friction"] += 1
                    if not sol.diagnostics.converged:
                        raise RuntimeError(sol.diagnostics.message)
                    sols.append(sol)
            except Exception as exc:  # noqa: BLE001 - a failing node is dropped, as documented
                dropped.append({"node": int(c), "message": f"{type(exc).__name__}: {exc}"})
                continue
            for e, sol in zip(etas, sols):
                rows.append((c, alpha, beta, e, sol.tip_position, sol.tip_tangent))
    K = len(rows)
    tip = np.array([r[4] for r in rows]).reshape(K, 3)
    tangent = np.array([r[5] for r in rows]).reshape(K, 3)
    tip_m, tangent_m = tip.copy(), tangent.copy()
    reg = None if registration is None else np.asarray(registration, float).reshape(6)
    if reg is not None:
        R = Rotation.from_rotvec(reg[:3]).as_matrix()
        tip_m = tip_m @ R.T + reg[3:]
        tangent_m = tangent_m @ R.T
    tip_m = tip_m + _position_noise(K, noise_position_rms, 0.0, rng)
    if noise_angle_rms > 0:
        tangent_m = _tangent_noise(tangent_m, noise_angle_rms / np.sqrt(2.0), rng)
    cols = {"sequence": np.arange(K), "config_id": np.array([r[0] for r in rows], int)}
    cols.update({f"alpha_{i + 1}": np.array([r[1][i] for r in rows]) for i in range(n)})
    cols.update({f"beta_{i + 1}": np.array([r[2][i] for r in rows]) for i in range(n)})
    cols.update({f"eta_{i + 1}": np.array([r[3][i] for r in rows], int) for i in range(m)})
    cols.update({f"tip_{c}": tip_m[:, a] for a, c in enumerate("xyz")})
    cols.update({f"tangent_{c}": tangent_m[:, a] for a, c in enumerate("xyz")})
    truth = dict(dropped=dropped, eta=np.array([r[3] for r in rows], int).reshape(K, m), tip=tip, tangent=tangent,
                 counts=counts, seconds=_time.perf_counter() - t_start)
    return pd.DataFrame(cols), truth
