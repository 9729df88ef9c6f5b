"""Measured-like data from a robot model with hidden effects (``ctrplan synth``).

The "truth" is a robot model with the chosen effects applied (an :class:`ctrplan.effects.EffectSet`
of registered effects), evaluated along one of two protocols, shown as the measurement shows it
(e.g. in the tracker frame of a registration) and perturbed by sensor noise:

- ``paper``: Section V-C of Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019,
  doi:10.1109/TRO.2018.2878906: an N x N x ... grid over the robot's joints, each configuration
  approached from the 2^(n-1) relative rotation directions by 90 deg rotations, the every-other
  node subset (4 x 4 x 4 for N = 8) for calibration, the rest for validation;
- ``trajectory``: a seeded continuous joint motion with reversals, sampled at 10 Hz, like the
  measured trajectory of Ha et al.'s robot (``load_ha_trajectory``).

Truth model: the most complete mechanics model the active effects need
(:func:`ctrplan.effects.model_of`: friction when a friction coefficient is positive, with the
friction state of the approach or of the motion history, :mod:`ctrplan.history`; else the
clearance model when clearances are set; else the standard model). History effects (drive
backlash, a tracker time lag, gradually developing friction) change the motion the truth is
evaluated along, not the recorded joints (trajectory protocol only). Noise defaults to the
paper's EM sensor (Section V-C): 1.4 mm rms position, 0.5 deg rms orientation.

The truth (effects, seed, counts) goes to a JSON sidecar for tests and reports; analysis code
must not read it.
"""

from __future__ import annotations

import itertools
import json
import os
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ...choices import ProtocolKind
from ...effects import REGISTRY, EffectSet, apply_output_effects, apply_robot_effects, history_state, model_of
from ...errors import PhysicalParameterError
from ...history import MotionRecord, motion_state
from ...mechanics import ModelSettings
from ...models import MODEL_INFO
from ...robot import ROTATION, TRANSLATION
from ..fits.simulate import simulate

__all__ = ["PROTOCOLS", "SynthProtocol", "Noise", "SynthResult", "truth_model", "paper_protocol",
           "trajectory_protocol", "approach_path", "add_noise", "synthesize", "parse_values", "truth_path",
           "write_synth"]

PROTOCOLS = tuple(k.value for k in ProtocolKind)

# Relative rotation of each pair on the way to a configuration (Section V-C: "Each of the
# relative rotations is performed by 90 deg of tube base rotation") [rad].
APPROACH_ROTATION = np.pi / 2
# Trajectory protocol: sample rate [Hz], samples, joint speeds and move sizes.
TRAJECTORY_RATE_HZ = 10.0
TRAJECTORY_SAMPLES = 1200
ROTATION_SPEED = 0.6          # [rad/s] peak-average speed of a rotation move
TRANSLATION_SPEED = 0.02      # [m/s]
ROTATION_STEP = (np.deg2rad(20.0), np.deg2rad(120.0))   # size range of one rotation move [rad]
MIN_TRANSLATION_STEP = 0.005  # [m]
DWELL_S = (0.3, 1.5)          # rest between moves [s]
REVERSAL_PROBABILITY = 0.5    # chance that a joint's next rotation reverses its direction
MAX_TURN = 2.0 * np.pi        # beyond this |rotation| [rad] the next rotation turns back


@dataclass(frozen=True)
class Noise:
    """Sensor noise.

    Parameters
    ----------
    position_rms : float
        Root-mean-square length of the position error vector [m], >= 0; each component is
        Gaussian with sigma = position_rms / sqrt(3). Default 1.4 mm (Section V-C).
    angle_rms : float
        Root-mean-square tangent error angle [rad], >= 0: the tangent is rotated about an axis
        perpendicular to it by a 2-D Gaussian rotation vector with per-component sigma =
        angle_rms / sqrt(2). Default 0.5 deg (Section V-C).
    """

    position_rms: float = 1.4e-3
    angle_rms: float = float(np.deg2rad(0.5))

    def __post_init__(self):
        for name in ("position_rms", "angle_rms"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0.0:
                raise PhysicalParameterError(f"noise {name} must be >= 0, got {v!r}")


@dataclass(frozen=True, eq=False)
class SynthResult:
    """Synthetic measurements and their truth.

    Attributes
    ----------
    frame : pandas.DataFrame
        Rows in the project's CSV schema (``time`` and ``sequence``, joints, ``eta_*``,
        noisy ``tip_*`` [m] and ``tangent_*`` in the tracker frame) plus ``config_id`` and
        ``subset`` (paper protocol).
    truth : dict
        JSON-ready description of how the data were made (effects, model, protocol, noise,
        seed, counts, dropped samples, timing).
    """

    frame: pd.DataFrame
    truth: dict


def truth_model(effects) -> str:
    """Model that generates the data: the most complete one the active effects need
    (``"friction"`` if a friction coefficient is positive, else ``"clearance"`` if clearances
    are set, else ``"standard"``; :func:`ctrplan.effects.model_of`)."""
    return model_of(effects)


# --------------------------------------------------------------------------- protocols
@dataclass(frozen=True)
class SynthProtocol:
    """Where :func:`synthesize` evaluates the truth.

    Attributes
    ----------
    kind : ProtocolKind or {"paper", "trajectory"}
        The paper's grid (:func:`paper_protocol`) or a seeded trajectory
        (:func:`trajectory_protocol`).
    grid : int
        Nodes per joint of the paper protocol, >= 2.
    samples : int
        Samples of the trajectory protocol, >= 2.

    Raises
    ------
    PhysicalParameterError
        An unknown kind, a grid or a sample count out of range.
    """

    kind: ProtocolKind = ProtocolKind.PAPER
    grid: int = 8
    samples: int = TRAJECTORY_SAMPLES

    def __post_init__(self):
        if self.kind not in PROTOCOLS:
            raise PhysicalParameterError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {self.kind!r}")
        object.__setattr__(self, "kind", ProtocolKind(self.kind))
        for name, low in (("grid", 2), ("samples", 2)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise PhysicalParameterError(f"protocol {name} must be an integer >= {low}, got {value!r}")

    @classmethod
    def paper(cls, grid: int = 8) -> "SynthProtocol":
        """The paper protocol on ``grid`` nodes per joint."""
        return cls(ProtocolKind.PAPER, grid=grid)

    @classmethod
    def trajectory(cls, samples: int = TRAJECTORY_SAMPLES) -> "SynthProtocol":
        """The trajectory protocol of ``samples`` samples."""
        return cls(ProtocolKind.TRAJECTORY, samples=samples)

    @classmethod
    def of(cls, protocol) -> "SynthProtocol":
        """``protocol`` itself, or the protocol of that kind with the default grid and samples."""
        return protocol if isinstance(protocol, cls) else cls(protocol)


def _joint_grid(joint, nodes: int) -> np.ndarray:
    if joint.periodic:  # -pi and pi are the same angle: do not sample both
        return joint.lower + (joint.upper - joint.lower) * np.arange(nodes) / nodes
    return np.linspace(joint.lower, joint.upper, nodes)


def paper_protocol(robot, grid: int = 8) -> pd.DataFrame:
    """Planned samples of the paper's protocol (Section V-C of Ha et al. 2019).

    Every node of a ``grid`` per joint grid over ``robot.joints`` (periodic rotations without
    repeating -pi at pi), approached from every combination of relative rotation directions.

    Parameters
    ----------
    robot : Robot
    grid : int
        Nodes per joint, >= 2 (8 in the paper).

    Returns
    -------
    pandas.DataFrame, grid^J * 2^(n-1) rows, configuration-major
        ``sequence`` (one per approach), ``config_id``, ``subset`` (``"calibration"`` when every
        joint index is even: the 4 x 4 x 4 subset for grid 8, else ``"validation"``),
        ``alpha_1..n`` [rad], ``beta_1..n`` [m], ``eta_1..n-1``.

    Raises
    ------
    PhysicalParameterError
        ``grid`` < 2, or a tube whose base must rotate for an approach has no rotation joint.

    Notes
    -----
    Approach with directions eta: tube 1's base stays; the relative angle of each pair,
    ``alpha_(i+1) - alpha_i``, starts 90 deg before its target against eta_i and turns
    monotonically by 90 deg in direction eta_i (all pairs simultaneously, at uniform rates, as
    in Section V-B). In base rotations: tube i+1 starts at
    ``alpha_(i+1) - 90 deg (eta_1 + ... + eta_i)`` and turns by ``90 deg (eta_1 + ... + eta_i)``
    (for three tubes: tube 2 by 90 deg, tube 3 by 0 or 180 deg). Only the target is written;
    the ``eta_*`` columns record the approach. The paper's order of directions: (CCW, CCW),
    (CCW, CW), (CW, CCW), (CW, CW).
    """
    if not isinstance(grid, (int, np.integer)) or grid < 2:
        raise PhysicalParameterError(f"grid must be an integer >= 2 nodes per joint, got {grid!r}")
    n = robot.n_tubes
    rotated = {j.tube for j in robot.joints if j.kind == ROTATION}
    for i in range(1, n):
        if i not in rotated and n > 1:
            raise PhysicalParameterError(
                f"robot {robot.name!r}: the paper protocol rotates {robot.tubes[i].name}'s base to "
                f"approach a configuration, but it has no rotation joint")
    axes = [_joint_grid(j, grid) for j in robot.joints]
    etas = list(itertools.product((1, -1), repeat=n - 1))
    rows = []
    for cid, idx in enumerate(itertools.product(*[range(grid)] * len(axes))):
        q = np.array([axes[j][i] for j, i in enumerate(idx)])
        alpha, beta = robot.configuration(q)
        subset = "calibration" if all(i % 2 == 0 for i in idx) else "validation"
        for a, eta in enumerate(etas):
            row = {"sequence": cid * len(etas) + a, "config_id": cid, "subset": subset}
            row.update({f"alpha_{i + 1}": alpha[i] for i in range(n)})
            row.update({f"beta_{i + 1}": beta[i] for i in range(n)})
            row.update({f"eta_{i + 1}": eta[i] for i in range(n - 1)})
            rows.append(row)
    return pd.DataFrame(rows)


def approach_path(alpha, eta, steps: int = 10) -> np.ndarray:
    """Base rotations along the paper protocol's approach to ``alpha`` with directions ``eta``.

    Tube 1's base stays; the relative angle of each pair i turns monotonically by 90 deg in
    direction eta_i (see :func:`paper_protocol`), linearly in ``steps`` steps.

    Parameters
    ----------
    alpha : array-like, shape (n,)
        Target base rotations [rad].
    eta : array-like of int, shape (n - 1,)
        Directions, +1 or -1.
    steps : int
        Steps of the path, >= 1.

    Returns
    -------
    ndarray, shape (steps + 1, n)
        Base rotations [rad] from the approach start to the target.
    """
    alpha = np.asarray(alpha, dtype=float)
    turn = APPROACH_ROTATION * np.concatenate([[0.0], np.cumsum(np.asarray(eta, dtype=float))])
    frac = np.linspace(-1.0, 0.0, steps + 1)[:, None]
    return alpha[None, :] + frac * turn[None, :]


def _smooth(tau):
    """Minimum-jerk profile 10 tau^3 - 15 tau^4 + 6 tau^5 (rest to rest)."""
    return tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def trajectory_protocol(robot, rng: np.random.Generator, samples: int = TRAJECTORY_SAMPLES,
                        rate: float = TRAJECTORY_RATE_HZ) -> pd.DataFrame:
    """A continuous random joint motion with reversals (one sequence).

    Moves, each rest to rest with a minimum-jerk profile followed by a rest of 0.3-1.5 s: a
    rotation of one or all rotation joints by 20-120 deg each (reversing a joint's previous
    direction with probability 1/2, and always once beyond one turn from zero), a translation of each translation joint to a random value
    in its limits (at least 5 mm away), or both together. Roughly one move in four is a pure
    translation, so many rotations are followed by a translation (translation-last samples).

    Parameters
    ----------
    robot : Robot
    rng : numpy.random.Generator
    samples : int
        Number of samples, >= 2.
    rate : float
        Sample rate [Hz], > 0.

    Returns
    -------
    pandas.DataFrame, ``samples`` rows
        ``time`` [s], ``sequence`` (0), ``alpha_1..n`` [rad], ``beta_1..n`` [m]. Periodic
        rotations are not wrapped (a wrap would look like a full turn).

    Raises
    ------
    PhysicalParameterError
        ``samples`` < 2, ``rate`` <= 0, a robot without joints.
    """
    if not isinstance(samples, (int, np.integer)) or samples < 2:
        raise PhysicalParameterError(f"trajectory samples must be an integer >= 2, got {samples!r}")
    if not np.isfinite(rate) or rate <= 0:
        raise PhysicalParameterError(f"trajectory rate must be > 0 Hz, got {rate!r}")
    joints = robot.joints
    if not joints:
        raise PhysicalParameterError(f"robot {robot.name!r} has no joints to move")
    rot = [k for k, j in enumerate(joints) if j.kind == ROTATION]
    tra = [k for k, j in enumerate(joints) if j.kind == TRANSLATION]
    lo, hi = robot.joint_lower, robot.joint_upper
    q = np.where([j.periodic for j in joints], 0.0, 0.5 * (lo + hi))
    direction = rng.choice([-1.0, 1.0], size=len(joints))
    path = [q.copy()]
    dt = 1.0 / rate
    while len(path) < samples:
        kinds = ["rotation"] * 2 * bool(rot) + ["translation"] * bool(tra) + ["both"] * bool(rot and tra)
        kind = kinds[rng.integers(len(kinds))]
        target = q.copy()
        if kind in ("rotation", "both"):
            moving = rot if rng.random() < 0.5 else [rot[rng.integers(len(rot))]]
            for k in moving:
                if rng.random() < REVERSAL_PROBABILITY:
                    direction[k] = -direction[k]
                if abs(q[k]) > MAX_TURN:  # keep periodic rotations within about a turn
                    direction[k] = -np.sign(q[k])
                step = direction[k] * rng.uniform(*ROTATION_STEP)
                if not joints[k].periodic and not lo[k] <= q[k] + step <= hi[k]:
                    direction[k] = -direction[k]
                    step = -step
                target[k] = np.clip(q[k] + step, lo[k], hi[k]) if not joints[k].periodic else q[k] + step
        if kind in ("translation", "both"):
            for k in tra:
                for _ in range(20):
                    v = rng.uniform(lo[k], hi[k])
                    if abs(v - q[k]) >= MIN_TRANSLATION_STEP:
                        break
                target[k] = v
        dq = np.abs(target - q)
        speed = np.array([ROTATION_SPEED if j.kind == ROTATION else TRANSLATION_SPEED for j in joints])
        duration = max(1.0, float(np.max(1.875 * dq / speed)))  # peak speed of min-jerk = 1.875 avg
        steps = int(np.ceil(duration * rate))
        tau = np.arange(1, steps + 1) / steps
        path.extend(q + _smooth(tau)[:, None] * (target - q))
        q = target
        path.extend([q.copy()] * int(round(rng.uniform(*DWELL_S) * rate)))
    path = np.array(path[:samples])
    n = robot.n_tubes
    data = {"time": np.arange(samples) * dt, "sequence": np.zeros(samples, dtype=int)}
    conf = [robot.configuration(x) for x in path]
    for i in range(n):
        data[f"alpha_{i + 1}"] = np.array([c[0][i] for c in conf])
    for i in range(n):
        data[f"beta_{i + 1}"] = np.array([c[1][i] for c in conf])
    return pd.DataFrame(data)


def _reversals(x) -> int:
    """Number of direction changes of a 1-D motion (ignoring rests)."""
    d = np.sign(np.diff(np.asarray(x, dtype=float)))
    d = d[d != 0]
    return int(np.sum(d[1:] != d[:-1]))


# --------------------------------------------------------------------------- noise
def add_noise(tip, tangent, noise: Noise, rng: np.random.Generator):
    """Add sensor noise to tip poses.

    Parameters
    ----------
    tip : array-like, shape (K, 3)
        [m]
    tangent : array-like, shape (K, 3)
        Unit tangents.
    noise : Noise
    rng : numpy.random.Generator

    Returns
    -------
    tip : ndarray, shape (K, 3)
        ``tip + e``, e Gaussian with per-component sigma ``noise.position_rms / sqrt(3)`` (so
        E|e|^2 = position_rms^2) [m].
    tangent : ndarray, shape (K, 3)
        Rotated by ``exp([v]x)``, v perpendicular to the tangent with 2-D Gaussian components of
        sigma ``noise.angle_rms / sqrt(2)`` (so the rms angle is ``angle_rms``); unit length.
    """
    tip = np.asarray(tip, dtype=float)
    t = np.asarray(tangent, dtype=float)
    K = tip.shape[0]
    e = rng.normal(0.0, noise.position_rms / np.sqrt(3.0), size=(K, 3))
    # orthonormal basis (u, w) of the plane perpendicular to each tangent
    helper = np.where(np.abs(t[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(t, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(t, u)
    c = rng.normal(0.0, noise.angle_rms / np.sqrt(2.0), size=(K, 2))
    axis_vec = c[:, :1] * u + c[:, 1:] * w            # rotation vector, perpendicular to t
    angle = np.linalg.norm(axis_vec, axis=1, keepdims=True)
    unit = np.divide(axis_vec, angle, out=np.zeros_like(axis_vec), where=angle > 0)
    rotated = np.cos(angle) * t + np.sin(angle) * np.cross(unit, t)
    rotated /= np.linalg.norm(rotated, axis=1, keepdims=True)
    return tip + e, rotated


# --------------------------------------------------------------------------- driver
def synthesize(robot, effects=None, *, protocol: SynthProtocol | str = SynthProtocol(), noise: Noise = Noise(),
               seed: int = 0, settings: ModelSettings | None = None, n_jobs: int = 1,
               progress: bool = False) -> SynthResult:
    """Generate measured-like data from ``robot`` with hidden ``effects``.

    Parameters
    ----------
    robot : Robot
        The nominal robot (effects are applied to it).
    effects : EffectSet or mapping, optional
        Hidden effects ``{effect: {parameter: value}}`` of the registry (:mod:`ctrplan.effects`),
        SI units; e.g. the registration maps the robot frame to the tracker frame.
    protocol : SynthProtocol or {"paper", "trajectory"}
        The protocol, e.g. ``SynthProtocol.paper(grid=8)`` or ``SynthProtocol.trajectory(samples=1200)``;
        a kind alone takes the default grid and samples.
    noise : Noise
    seed : int
        Seeds one numpy Generator for the trajectory and the noise.
    settings : ModelSettings, optional
    n_jobs : int
        Worker processes for the model evaluations.
    progress : bool

    Returns
    -------
    SynthResult
        Samples whose truth solve failed (not converged, unstable) are dropped and listed in
        ``truth["dropped"]``.

    Raises
    ------
    PhysicalParameterError
        Unknown protocol or effect, effects that do not fit the robot, an effect that needs
        another one (gradual friction without friction), history effects on the paper protocol,
        friction without a clearance.
    """
    t0 = time.perf_counter()
    spec = SynthProtocol.of(protocol)
    protocol, grid, samples = spec.kind, spec.grid, spec.samples
    settings = settings or ModelSettings()
    rng = np.random.default_rng(seed)
    effects = EffectSet(effects or {}, robot)
    truth_robot = apply_robot_effects(robot, effects)
    model = truth_model(effects)
    info = MODEL_INFO[model]
    moving = [n for n in effects.active() if REGISTRY[n].needs_motion]
    if moving and protocol != ProtocolKind.TRAJECTORY:
        raise PhysicalParameterError(
            f"effects {', '.join(moving)} change the motion history and need the trajectory protocol (protocol "
            f"{protocol.value!r} solves every target without its approach path)")
    if info.contact:
        try:
            truth_robot.clearances  # noqa: B018
        except PhysicalParameterError as exc:
            raise PhysicalParameterError(f"the {model} truth model needs clearances (tube diameters or "
                                         f"the clearance effect): {exc}") from None
    n = robot.n_tubes
    acols = [f"alpha_{i + 1}" for i in range(n)]
    bcols = [f"beta_{i + 1}" for i in range(n)]
    ecols = [f"eta_{i + 1}" for i in range(n - 1)]
    if protocol == ProtocolKind.PAPER:
        frame = paper_protocol(robot, grid)
        alpha, beta = frame[acols].to_numpy(float), frame[bcols].to_numpy(float)
        eta = frame[ecols].to_numpy(int)
        if info.friction:
            state = motion_state(MotionRecord(alpha, beta, sequence=frame["sequence"].to_numpy(int)), given_eta=eta)
            eta_a, mu_a = state.applied(truth_robot.friction_coefficients)
            sim = simulate(truth_robot, alpha, beta, model=model, eta=eta_a, mu=mu_a, settings=settings,
                           n_jobs=n_jobs, progress=progress)
        else:  # the approach does not matter: solve each configuration once
            first = ~frame["config_id"].duplicated().to_numpy()
            once = simulate(truth_robot, alpha[first], beta[first], model=model, settings=settings,
                            n_jobs=n_jobs, progress=progress)
            pick = np.cumsum(first) - 1
            sim = once
            tip, tangent, ok = once.tip[pick], once.tangent[pick], once.ok[pick]
            message = [once.message[k] for k in pick]
        extra = {"grid": int(grid), "approach_rotation_rad": APPROACH_ROTATION}
    else:
        frame = trajectory_protocol(robot, rng, samples)
        alpha, beta = frame[acols].to_numpy(float), frame[bcols].to_numpy(float)
        seq = frame["sequence"].to_numpy(int)
        record = MotionRecord(alpha, beta, frame["time"].to_numpy(float), seq)
        hist = motion_state(record)
        for i, c in enumerate(ecols):
            frame[c] = hist.eta[:, i]   # what the recorded joints say
        # the truth moves along the history the tubes really saw (and the tracker showed)
        state = history_state(truth_robot, record, effects)
        eta_t, mu_t = state.applied(truth_robot.friction_coefficients)
        sim = simulate(truth_robot, state.alpha, state.beta, model=model, eta=eta_t if info.friction else None,
                       mu=mu_t if info.friction else None, sequence=seq, settings=settings, n_jobs=n_jobs,
                       progress=progress)
        extra = {"samples": int(samples), "rate_hz": TRAJECTORY_RATE_HZ,
                 "translation_last_samples": int(np.any(hist.released, axis=1).sum()),
                 "reversals": {j.name: _reversals(frame[j.name]) for j in robot.joints}}
    if protocol == ProtocolKind.TRAJECTORY or info.friction:
        tip, tangent, ok, message = sim.tip, sim.tangent, sim.ok, sim.message
    tip, tangent = apply_output_effects(tip, tangent, effects)
    tip_n, tan_n = add_noise(np.nan_to_num(tip), np.nan_to_num(tangent, nan=1.0), noise, rng)
    for j, c in enumerate(("tip_x", "tip_y", "tip_z")):
        frame[c] = tip_n[:, j]
    for j, c in enumerate(("tangent_x", "tangent_y", "tangent_z")):
        frame[c] = tan_n[:, j]
    dropped = [{"row": int(k), "message": message[k],
                **({"config_id": int(frame["config_id"].iloc[k])} if "config_id" in frame else {})}
               for k in np.flatnonzero(~ok)]
    frame = frame[ok].reset_index(drop=True)
    counts = {"rows": int(len(frame)), "dropped": len(dropped)}
    if "subset" in frame:
        counts.update(configurations=int(frame["config_id"].nunique()),
                      calibration_rows=int((frame["subset"] == "calibration").sum()),
                      validation_rows=int((frame["subset"] == "validation").sum()))
    truth = {
        "note": "truth of synthetic data: for tests and reports; analysis must not read it",
        "robot": robot.name,
        "effects": effects.to_dict(),
        "truth_model": model,
        "protocol": protocol.value,
        **extra,
        "noise": {"position_rms_m": noise.position_rms, "angle_rms_rad": noise.angle_rms},
        "seed": int(seed),
        "settings": settings.as_dict(),
        "counts": counts,
        "dropped": dropped,
        "solver": {"standard_solves": sim.n_standard, "contact_solves": sim.n_contact,
                   "warm_starts": sim.n_warm, "reused": sim.n_reused},
        "elapsed_s": round(time.perf_counter() - t0, 3),
        "n_jobs": int(n_jobs),
    }
    return SynthResult(frame=frame, truth=truth)


def parse_values(option: str, text: str, count: int) -> tuple[float, ...]:
    """Parse a comma-separated option value into ``count`` floats.

    Raises
    ------
    PhysicalParameterError
        Naming the option and the value: not numbers, not finite, or not ``count`` of them.
    """
    try:
        values = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        raise PhysicalParameterError(f"option {option} {text!r}: expected {count} comma-separated "
                                     f"numbers") from None
    if len(values) != count:
        raise PhysicalParameterError(f"option {option} {text!r}: expected {count} comma-separated "
                                     f"numbers, got {len(values)}")
    if not all(np.isfinite(values)):
        raise PhysicalParameterError(f"option {option} {text!r}: values must be finite")
    return values


def truth_path(out: str | os.PathLike) -> str:
    """Path of the truth sidecar of a synthetic CSV: ``<out>.truth.json``."""
    return os.fspath(out) + ".truth.json"


def write_synth(out: str | os.PathLike, result: SynthResult, *, robot_file: str | None = None,
                robot_hash: str | None = None) -> str:
    """Write the CSV (project schema, atomically) and its truth sidecar; returns the sidecar path.

    Parameters
    ----------
    out : path
        CSV path.
    result : SynthResult
    robot_file, robot_hash : str, optional
        Recorded in the sidecar (the robot file and its content hash).
    """
    from ...io.atomic import atomic_write_text
    from ...io.tables import write_table

    truth = dict(result.truth)
    if robot_file is not None:
        truth["robot_file"] = str(robot_file)
    if robot_hash is not None:
        truth["robot_file_hash"] = robot_hash
    write_table(out, result.frame)
    path = truth_path(out)
    atomic_write_text(path, json.dumps(truth, indent=2) + "\n")
    return path
