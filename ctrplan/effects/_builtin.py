"""The built-in effects (Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906,
and the history effects of a real drive and tracker).

Each entry is complete: parameters with units, typical ranges and optimizer bounds, what it
changes (robot, motion or measurement), its signature test, its ``ctrplan synth`` option, its
fitting strategy and what planning does with it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..choices import EffectStore
from ..history import HistoryOperator, play, time_shift
from ..robot import ROTATION, Section
from ._fit import GRID, NO_FIT, SCAN
from ._registry import Effect, ParameterSpec, register

__all__ = ["BACKLASH_SCAN", "TIME_OFFSET_SCAN", "FRICTION_ANGLE_SCAN", "FRICTION_ANGLE_REFERENCE",
           "overlap_features", "angle_features", "twist_features", "curved_tubes", "rotating_tubes",
           "registration_transform"]

#: Start scans of the history candidates (every fitted parameter alike): backlash [rad], time
#: offset [s], friction angle theta_c [rad] (0 = the abrupt friction model).
BACKLASH_SCAN = tuple(np.deg2rad([0.0, 1.0, 2.0, 4.0, 8.0]))
#: The time offset is profiled on a fine grid (10 ms) before its least-squares refinement: the cost
#: of a lag has a minimum per multiple of the motion's period of reversal, and a coarse scan can
#: start the refinement in the wrong one.
TIME_OFFSET_SCAN = tuple(np.round(np.arange(-0.4, 0.4001, 0.01), 3))
FRICTION_ANGLE_SCAN = tuple(np.deg2rad([0.0, 5.0, 10.0, 20.0, 40.0]))
#: Reference theta_c of the gradual-friction signature [rad].
FRICTION_ANGLE_REFERENCE = float(np.deg2rad(15.0))
#: Typical off-plane precurvature: this fraction of the tube's in-plane precurvature (a
#: shape-setting error that tilts the bending plane by up to atan(0.25) = 14 deg), at least
#: :data:`OFFPLANE_FLOOR` [1/m].
OFFPLANE_FRACTION = 0.25
OFFPLANE_FLOOR = 0.5


# --------------------------------------------------------------------------- robot helpers
def curved_tubes(robot) -> list:
    """Tubes (0-based) with a curved section."""
    return [i for i, t in enumerate(robot.tubes) if any(not s.is_straight for s in t.sections)]


def rotating_tubes(robot, data=None) -> list:
    """Tubes (0-based) with a rotation joint and, given data, whose recorded angle moves."""
    tubes = sorted({j.tube for j in robot.joints if j.kind == ROTATION})
    if data is not None:
        tubes = [i for i in tubes if np.ptp(data.alpha[:, i]) > 1e-6]
    return tubes


def _first_curved(robot, i):
    return next(j for j, s in enumerate(robot.tubes[i].sections) if not s.is_straight)


def _has_clearance(robot) -> bool:
    from ..errors import PhysicalParameterError

    try:
        c = robot.clearances
    except PhysicalParameterError:
        return False
    return c is not None and bool(np.all(np.isfinite(c)))


def _contact_requirement(robot, data=None):
    if robot.n_tubes < 2:
        return "the robot has one tube"
    if not _has_clearance(robot):
        return "the robot file gives no tube diameters (no clearance)"
    return None


def _motion_requirement(data):
    if data is not None and np.unique(data.sequence).size == data.n_samples:
        return "every sequence holds one sample: there is no recorded motion between samples"
    return None


def _indexed(values, prefix, n):
    return np.array([float(values.get(f"{prefix}_{i + 1}", 0.0)) for i in range(n)])


# --------------------------------------------------------------------------- features
def overlap_features(robot, beta) -> np.ndarray:
    """Tube-overlap features of the clearance signature, shape (K, 3 (n - 1)) [m].

    For each pair (i, i+1): the length over which curved sections of both overlap, the length of
    tube i+1's straight (transmission) sections inside curved sections of tube i, and of tube
    i's straight sections around curved sections of tube i+1 (Section II-B: clearance lets an
    inner tube move inside an outer one where their curvatures differ).
    """
    beta = np.atleast_2d(np.asarray(beta, float))
    n = robot.n_tubes
    out = np.zeros((beta.shape[0], 3 * (n - 1)))

    def spans(i, b, curved):
        br = robot.tubes[i].section_breaks() + b
        return [(br[j], br[j + 1]) for j, sec in enumerate(robot.tubes[i].sections)
                if (not sec.is_straight) == curved]

    def overlap(a, c):
        return sum(max(0.0, min(x1, y1) - max(x0, y0)) for x0, x1 in a for y0, y1 in c)

    for r, b in enumerate(beta):
        for i in range(n - 1):
            co, ci = spans(i, b[i], True), spans(i + 1, b[i + 1], True)
            so, si = spans(i, b[i], False), spans(i + 1, b[i + 1], False)
            out[r, 3 * i:3 * i + 3] = (overlap(co, ci), overlap(si, co), overlap(so, ci))
    return out


def angle_features(alpha, moving=None) -> np.ndarray:
    """First and second harmonics of the absolute tube angles, shape (K, 4 m).

    Parameters
    ----------
    alpha : ndarray, shape (K, n) [rad]
    moving : sequence of int, optional
        Tubes to use (default: those whose angle varies in the data).
    """
    alpha = np.asarray(alpha, float)
    if moving is None:
        moving = [i for i in range(alpha.shape[1]) if np.ptp(alpha[:, i]) > 1e-6]
    cols = []
    for i in moving:
        a = alpha[:, i]
        cols += [np.cos(a), np.sin(a), np.cos(2 * a), np.sin(2 * a)]
    return np.column_stack(cols) if cols else np.zeros((alpha.shape[0], 0))


def twist_features(twist, model_tip) -> np.ndarray:
    """Twist features of the stiffness / Poisson signature, shape (K, 6).

    ``[tau, tau^2] x [1, cos phi, sin phi]`` with ``tau`` the twist of the most strained tube
    [rad] and ``phi`` the azimuth of the model tip (the direction the residual takes rotates
    with the bending plane).
    """
    twist = np.asarray(twist, float)
    phi = np.arctan2(model_tip[:, 1], model_tip[:, 0])
    base = [np.ones_like(phi), np.cos(phi), np.sin(phi)]
    return np.column_stack([t * b for t in (twist, twist ** 2) for b in base])


def _most_strained_tube(robot) -> int:
    strain = []
    for t in robot.tubes:
        kappa = max(np.hypot(*s.precurvature) for s in t.sections)
        strain.append((t.r_out or 0.0) * kappa)
    return int(np.argmax(strain)) if max(strain) > 0 else robot.n_tubes - 1


def registration_transform(values) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (3, 3) and translation t (3,) [m] of registration values
    ``registration_r{x,y,z}`` [rad], ``registration_t{x,y,z}`` [m] (missing ones 0):
    ``p_tracker = R p_base + t``."""
    from scipy.spatial.transform import Rotation

    r = np.array([float(values.get(f"registration_r{a}", 0.0)) for a in "xyz"])
    t = np.array([float(values.get(f"registration_t{a}", 0.0)) for a in "xyz"])
    return Rotation.from_rotvec(r).as_matrix(), t


# --------------------------------------------------------------------------- friction
def _friction_parameters(robot):
    return tuple(ParameterSpec(f"mu_{k + 1}", "mu", k, "-", 0.0, 2.0, 0.05, (0.0, 0.5),
                               "Coulomb friction of NiTi on NiTi: Ha et al. 2019 calibrated 0.22 and 0.12 on "
                               "the three-tube robot (Table VII); a larger fitted value measures a "
                               "direction-dependent error that another hysteretic effect (e.g. backlash or lag "
                               "in a rotation drive) may cause, not a material property",
                               check="the tube surfaces (wear, lubrication) and whether another hysteretic effect, "
                                     "such as backlash or lag in a rotation drive, is present",
                               vanishes_at_lower=True)
                 for k in range(robot.n_tubes - 1))


def _friction_apply(robot, values):
    mu = list(robot.friction_coefficients)
    for k in range(robot.n_tubes - 1):
        if f"mu_{k + 1}" in values:
            mu[k] = float(values[f"mu_{k + 1}"])
    return robot.replace(friction_coefficients=tuple(mu))


register(Effect(
    name="friction", label="torsional friction", model="friction", parameters=_friction_parameters,
    description="maximal torsional Coulomb friction against the last relative rotation of each pair "
                "(Section III, Eqs. (37)-(47))",
    store=EffectStore.ROBOT, apply_robot=_friction_apply,
    read=lambda robot: {f"mu_{k + 1}": 0.0 for k in range(robot.n_tubes - 1)},
    active=lambda v: any(x > 0 for x in v.values()),
    present=lambda robot: any(mu > 0 for mu in robot.friction_coefficients),
    signature=lambda ctx: ctx.direction_test("friction"),
    synth_option="--mu", synth_help="Friction coefficient per tube pair, e.g. 0.22,0.12.",
    fit=GRID, requires=_contact_requirement, contains=("clearance",),
    plan="the friction coefficients of the robot file: the bound, the prediction and compensated targeting",
    separated_by="a translation after a rotation (it releases friction, not a dead band or a lag) and the same "
                 "configuration approached from both directions"))


# --------------------------------------------------------------------------- clearance
def _clearance_parameters(robot):
    return tuple(ParameterSpec(f"clearance_{k + 1}", "clearance", k, "m", 1e-7, 1e-2, 1e-5, (1e-6, 5e-3),
                               "radial gap between nested tubes: 0.01-3 mm (Table I of Ha et al. 2019)")
                 for k in range(robot.n_tubes - 1))


def _clearance_apply(robot, values):
    names = [f"clearance_{k + 1}" for k in range(robot.n_tubes - 1)]
    if not any(n in values for n in names):
        return robot
    base = np.asarray(robot.clearances, float)
    c = tuple(float(values.get(n, base[k])) for k, n in enumerate(names))
    return robot.replace(clearances_override=c)


def _clearance_signature(ctx):
    return ctx.regression_test("clearance", overlap_features(ctx.robot, ctx.data.beta),
                               "curved-curved overlap and transmission sections in curved sections, per pair")


register(Effect(
    name="clearance", label="clearance", model="clearance", parameters=_clearance_parameters,
    description="radial clearance between nested tubes: the inner tube moves inside the outer one "
                "(Sections II-B to II-E, Eq. (15)); nominal diameters",
    store=EffectStore.ROBOT, fitted=lambda robot, data: (), apply_robot=_clearance_apply,
    read=lambda robot: {f"clearance_{k + 1}": float(c) for k, c in enumerate(robot.clearances)}
    if _has_clearance(robot) else {},
    signature=_clearance_signature, synth_option="--clearance-m",
    synth_help="Radial clearance per pair [m] (default: from the tube diameters).",
    fit=NO_FIT, requires=_contact_requirement,
    plan="the tube diameters of the robot file: the clearance model of the bound and the prediction",
    separated_by="translations that change which curved sections overlap"))


# --------------------------------------------------------------------------- off-plane precurvature
def _offplane_parameters(robot):
    out = []
    for i in curved_tubes(robot):
        ky = abs(robot.tubes[i].sections[_first_curved(robot, i)].precurvature[1])
        limit = max(OFFPLANE_FRACTION * ky, OFFPLANE_FLOOR)
        out.append(ParameterSpec(f"precurvature_x_{i + 1}", "precurvature_x", i, "1/m", -200.0, 200.0, 0.5,
                                 (-limit, limit),
                                 f"off-plane precurvature of a shape-set tube: at most {OFFPLANE_FRACTION:g} of its "
                                 f"in-plane precurvature ({ky:.3g} 1/m; a bending plane tilted by up to 14 deg), "
                                 f"at least {OFFPLANE_FLOOR:g} 1/m; Table VII of Ha et al. 2019 has 0.3 1/m on "
                                 f"16 1/m",
                                 check="the shape setting of the tube (the plane of its curved section) and "
                                       "whether the robot file's in-plane precurvature is right",
                                 limit=(-1000.0, 1000.0)))
    return tuple(out)


def _offplane_apply(robot, values):
    tubes = list(robot.tubes)
    for i in curved_tubes(robot):
        name = f"precurvature_x_{i + 1}"
        if name not in values:
            continue
        secs = tuple(sec if sec.is_straight else Section(sec.length, (float(values[name]), sec.precurvature[1]))
                     for sec in tubes[i].sections)
        tubes[i] = dataclasses.replace(tubes[i], sections=secs)
    return robot.replace(tubes=tuple(tubes))


register(Effect(
    name="offplane", label="off-plane precurvature", model="standard", parameters=_offplane_parameters,
    description="x precurvature of every curved section of a tube (the calibrated x-curvature of Tables VI "
                "and VII, Section V-C)",
    store=EffectStore.ROBOT, apply_robot=_offplane_apply,
    read=lambda robot: {f"precurvature_x_{i + 1}": robot.tubes[i].sections[_first_curved(robot, i)].precurvature[0]
                        for i in curved_tubes(robot)},
    signature=lambda ctx: ctx.regression_test("offplane", angle_features(ctx.data.alpha),
                                              "cos/sin of 1x and 2x the absolute angle of every rotating tube"),
    synth_option="--offplane-per-m", synth_help="x precurvature of each curved tube [1/m] (default: the robot's).",
    plan="the precurvatures of the robot file",
    separated_by="the same relative configuration at other absolute tube angles (it depends on the absolute "
                 "angles)"))


# --------------------------------------------------------------------------- Poisson ratio
def _poisson_parameters(robot):
    return tuple(ParameterSpec(f"poisson_ratio_{i + 1}", "poisson_ratio", i, "-", -0.99, 0.5, 0.05, (-0.5, 0.45),
                               "NiTi: about 0.33; the paper's calibrated effective values reach -0.23 (Tables "
                               "V-VII); below -0.5 the torsional stiffness k_z = k_xy / (1 + nu) would exceed "
                               "twice the bending stiffness",
                               check="the tubes' torsional stiffness (wall thickness, material) and whether "
                                     "an unmodelled torsion (friction, a tube's nonlinear strain) is what it "
                                     "stands for")
                 for i in range(robot.n_tubes))


def _poisson_apply(robot, values):
    tubes = list(robot.tubes)
    for i in range(robot.n_tubes):
        name = f"poisson_ratio_{i + 1}"
        if name in values:
            tubes[i] = dataclasses.replace(tubes[i], poisson_ratio=float(values[name]))
    return robot.replace(tubes=tuple(tubes))


def _poisson_signature(ctx):
    tube = _most_strained_tube(ctx.robot)
    return ctx.regression_test("poisson", twist_features(ctx.twist(tube), ctx.model_tip),
                               f"twist of tube {tube + 1} (most strained) and its square, times 1, cos, sin of the "
                               f"tip azimuth")


register(Effect(
    name="poisson", label="stiffness ratio / Poisson ratio (torsional stiffness)", model="standard",
    parameters=_poisson_parameters,
    description="Poisson ratio of each tube, k_z = k_xy / (1 + nu) (Section II-C; calibrated in Tables V-VII)",
    store=EffectStore.ROBOT, apply_robot=_poisson_apply,
    read=lambda robot: {f"poisson_ratio_{i + 1}": t.poisson_ratio for i, t in enumerate(robot.tubes)},
    signature=_poisson_signature, synth_option="--poisson", synth_help="Poisson ratio per tube.",
    plan="the Poisson ratios of the robot file",
    separated_by="configurations of large and small twist of the most strained tube"))


# --------------------------------------------------------------------------- registration
_REG_AXES = ("rx", "ry", "rz", "tx", "ty", "tz")


def _registration_parameters(robot):
    out = []
    for a, ax in enumerate(_REG_AXES):
        if a < 3:
            out.append(ParameterSpec(f"registration_{ax}", "registration_r", a, "rad", -np.pi, np.pi, 0.01,
                                     (-np.deg2rad(10.0), np.deg2rad(10.0)),
                                     "a robot-frame data file whose frame is off by more than 10 deg is a "
                                     "tracker-frame file: fit its registration in the baseline (--frame tracker)",
                                     check="the frame of the data file (--frame tracker fits a registration)"))
        else:
            out.append(ParameterSpec(f"registration_{ax}", "registration_t", a - 3, "m", -1.0, 1.0, 1e-3,
                                     (-0.02, 0.02),
                                     "a robot-frame data file whose origin is off by more than 20 mm is a "
                                     "tracker-frame file: fit its registration in the baseline (--frame tracker)",
                                     check="the frame of the data file (--frame tracker fits a registration)",
                                     limit=(-10.0, 10.0)))
    return tuple(out)


def _registration_output(tip, tangent, values):
    R, t = registration_transform(values)
    tip = np.asarray(tip, float) @ R.T + t
    return tip, (None if tangent is None else np.asarray(tangent, float) @ R.T)


register(Effect(
    name="registration", label="registration", model="standard", parameters=_registration_parameters,
    description="rigid map from the robot base frame to the tracker frame, p_tracker = exp([r]x) p + t",
    store=EffectStore.REGISTRATION, apply_output=_registration_output,
    signature=lambda ctx: ctx.rigid_test("registration"),
    synth_option="--registration",
    synth_help="Robot-to-tracker transform 'rx,ry,rz,tx,ty,tz' (rotation vector [rad], translation [m]).",
    requires=lambda robot, data: ("the baseline fits the registration of tracker-frame data"
                                  if data is not None and data.frame == "tracker" else None),
    plan="not used: it maps the robot frame to the tracker's",
    separated_by="tips far from and near the base (a rigid map grows with the lever arm)"))


# --------------------------------------------------------------------------- drive backlash
def _backlash_parameters(robot):
    return tuple(ParameterSpec(f"backlash_{i + 1}", "backlash", i, "rad", 0.0, float(np.deg2rad(30.0)), 0.005,
                               (0.0, float(np.deg2rad(5.0))), "dead band of a geared rotation stage: up to a few "
                               "degrees (0-5 deg)",
                               check="the couplings and gears of the tube's rotation drive (a set screw or "
                                     "coupling that slips adds a dead band)",
                               vanishes_at_lower=True, resolution=float(BACKLASH_SCAN[1] - BACKLASH_SCAN[0]),
                               limit=(0.0, float(np.pi)))
                 for i in range(robot.n_tubes))


def _backlash_operator(robot, values):
    widths = _indexed(values, "backlash", robot.n_tubes)
    return HistoryOperator("backlash", "drive", lambda record: play(record, widths))


def _backlash_requirement(robot, data):
    if data is None:
        return None
    if not rotating_tubes(robot, data):
        return "no rotation joint moves in the data"
    return _motion_requirement(data)


def _backlash_signature(ctx):
    tubes = rotating_tubes(ctx.robot, ctx.data)
    jac = ctx.alpha_jacobian(tubes)
    X = np.stack([-jac[i] for i in tubes], axis=2)
    return ctx.vector_test("backlash", X, "-s_i d tip/d alpha_i per rotating tube, s_i the direction of its last "
                                          "rotation; an offset along d tip/d alpha_i is projected out",
                           signs=ctx.drive_directions()[:, tubes])


register(Effect(
    name="backlash", label="drive backlash", model="standard", parameters=_backlash_parameters,
    description="dead band in each rotation drive: after a reversal the tube's base angle lags the drive's by up "
                "to half the band (play operator, ctrplan.history.play)",
    fitted=lambda robot, data: tuple(f"backlash_{i + 1}" for i in rotating_tubes(robot, data)),
    operator=_backlash_operator, active=lambda v: any(x > 0 for x in v.values()),
    signature=_backlash_signature, synth_option="--backlash-rad",
    synth_help="Dead band of each tube's rotation drive [rad], e.g. 0,0.05,0.03.",
    needs_motion=True, scan=BACKLASH_SCAN, requires=_backlash_requirement,
    plan="used: the tube angle a drive reaches depends on the direction it last moved (prediction and "
         "compensated targeting)",
    separated_by="rests after reversals (a dead band leaves the tip displaced at rest; a time offset does not) and "
                 "slow and fast passes over the same path (its error does not scale with speed)"))


# --------------------------------------------------------------------------- time offset
def _time_offset_requirement(robot, data):
    if data is None:
        return None
    if data.time is None:
        return "the data has no 'time' column"
    return _motion_requirement(data)


register(Effect(
    name="time_offset", label="time offset (tracker lag)", model="standard",
    parameters=lambda robot: (ParameterSpec("time_offset", "time_offset", 0, "s", -2.0, 2.0, 0.02, (-0.3, 0.3),
                                            "latency between joint encoders and an EM/optical tracker: tens to a "
                                            "few hundred ms (|tau| <= 0.3 s)",
                                            check="the time stamps of the tracker and the joint encoders (clock "
                                                  "synchronisation, filtering or buffering delay of the tracker)",
                                            resolution=float(np.min(np.diff(TIME_OFFSET_SCAN))),
                                            limit=(-10.0, 10.0)),),
    description="the tracker's readings lag the joint readings by tau: the tip measured at t belongs to the "
                "joints at t - tau (ctrplan.history.time_shift)",
    operator=lambda robot, v: HistoryOperator("time_offset", "tracker",
                                              lambda record: time_shift(record, float(v.get("time_offset", 0.0)))),
    active=lambda v: float(v.get("time_offset", 0.0)) != 0.0,
    signature=lambda ctx: ctx.vector_test("time_offset", -ctx.tip_velocity()[:, :, None],
                                          "-d tip/dt of the baseline model along the recorded motion"),
    synth_option="--time-offset-s", synth_help="Lag of the tracker readings behind the joint readings [s].",
    needs_motion=True, scan=TIME_OFFSET_SCAN, requires=_time_offset_requirement,
    plan="not used: it concerns the tracker, not the robot",
    separated_by="slow and fast passes over the same path (its error scales with speed) and rests (it vanishes "
                 "at rest)"))


# --------------------------------------------------------------------------- gradual friction
def _gradual_signature(ctx):
    tubes = rotating_tubes(ctx.robot, ctx.data)
    pairs = [i - 1 for i in tubes if i >= 1]
    if not pairs:
        return ctx.untestable("gradual_friction", "no pair's inner tube rotates")
    jac = ctx.alpha_jacobian(tubes)
    d = ctx.rotation_since_reversal()
    eta = ctx.state.eta.astype(float)
    full = np.stack([eta[:, k, None] * jac[k + 1] for k in pairs], axis=2)
    ramp = np.stack([eta[:, k, None] * np.exp(-d[:, k, None] / FRICTION_ANGLE_REFERENCE) * jac[k + 1]
                     for k in pairs], axis=2)
    return ctx.vector_test("gradual_friction", ramp,
                           f"eta_k exp(-rotation since reversal / {np.rad2deg(FRICTION_ANGLE_REFERENCE):.0f} deg) "
                           f"d tip/d alpha_(k+1), beyond eta_k d tip/d alpha_(k+1)", control=full)


register(Effect(
    name="gradual_friction", label="gradually developing friction", model="friction",
    parameters=lambda robot: (ParameterSpec("friction_angle", "friction_angle", 0, "rad", 0.0, float(np.pi), 0.05,
                                            (0.0, float(np.deg2rad(30.0))),
                                            "the paper assumes friction develops within its 90 deg approach rotations "
                                            "(Sec. V-B): 95 % after 3 theta_c <= 90 deg",
                                            check="whether the friction really builds up slowly after a reversal, or "
                                                  "a dead band or lag in the rotation drive is what it stands for",
                                            vanishes_at_lower=True,
                                            resolution=float(FRICTION_ANGLE_SCAN[1] - FRICTION_ANGLE_SCAN[0])),),
    description="friction that develops over a relative rotation theta_c after a reversal (Dahl-type state, "
                "ctrplan.history.motion_state)",
    friction_angle=lambda v: float(v.get("friction_angle", 0.0)), active=lambda v: v.get("friction_angle", 0) > 0,
    signature=_gradual_signature, synth_option="--friction-angle-rad",
    synth_help="Relative rotation over which friction develops after a reversal [rad] (needs --mu).",
    needs_motion=True, scan=FRICTION_ANGLE_SCAN, fit=SCAN, after="friction",
    requires=lambda robot, data: _contact_requirement(robot) or _motion_requirement(data),
    contains=("friction", "clearance"),
    plan="used: the friction state follows the rotation amounts the plan makes (prediction and compensated "
         "targeting)",
    separated_by="short and long rotations after reversals (its error grows over theta_c after each reversal)"))
