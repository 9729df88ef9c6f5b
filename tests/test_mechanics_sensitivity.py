"""Exact tip derivatives of the standard model (``ctrplan.mechanics.sensitivity``): against
central differences of ``solve_standard``, a Taylor test, invariants, and bad input; the batch
entry point against the single one."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from ctrplan.errors import ConvergenceError, ElasticInstabilityError
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, StandardTipDerivatives, solve_standard, standard_tip_derivatives
from ctrplan.mechanics.sensitivity import standard_tip_derivatives_batch
from ctrplan.robot import Joint, Robot, Section, Tube

MODELS = Path(__file__).resolve().parents[1] / "model"
TIGHT = ModelSettings(shooting_tol=1e-12)
FD_STEP = 1e-5          # relative step of the central differences
FD_RTOL = 1e-6          # of the column norm (measured: 2e-8 at most)

# (robot file, joint vectors): three tubes nominal and calibrated, and the two-tube pair
CASES = [
    ("ha2019-table2-nominal.toml", ([1.1, -2.0, -0.06], [0.3, 2.5, -0.09], [-2.8, 0.7, -0.04])),
    ("ha2019-table1-tube-pair.toml", ([0.7], [2.5])),
    ("ha2019-table7-calibrated.toml", ([1.1, -2.0, -0.06], [2.0, -1.0, -0.1])),
]


def _via_batch(robot, alpha, beta, settings=None):
    """:func:`standard_tip_derivatives` through the batch entry point: one row from the base
    torsions of ``solve_standard``, unpacked into a :class:`StandardTipDerivatives`."""
    sol = solve_standard(robot, alpha, beta, settings, check_stability=False)
    b = standard_tip_derivatives_batch(robot, alpha[None], beta[None], sol.base_torsion[None], settings)
    assert b.ok[0]
    n = robot.n_tubes
    S = (b.d_position.shape[2] // n - 3) // 2
    cuts = [n, n + 2 * n * S, 2 * n + 2 * n * S]
    pa, pc, px, pz = np.split(b.d_position[0], cuts, axis=1)
    ta, tc, tx, tz = np.split(b.d_tangent[0], cuts, axis=1)
    return StandardTipDerivatives(
        tip_position=b.tip_position[0], tip_tangent=b.tip_tangent[0], base_torsion=b.base_torsion[0],
        d_position_d_alpha=pa, d_tangent_d_alpha=ta, d_position_d_precurvature=pc.reshape(3, n, S, 2),
        d_tangent_d_precurvature=tc.reshape(3, n, S, 2), d_position_d_k_xy=px, d_tangent_d_k_xy=tx,
        d_position_d_k_z=pz, d_tangent_d_k_z=tz, d_base_torsion=b.d_base_torsion[0],
        shooting_determinant=float(b.shooting_determinant[0]))


ENTRIES = {"single": standard_tip_derivatives, "batch": _via_batch}


@pytest.fixture
def no_joint_check(monkeypatch):
    """A straight section given a small precurvature becomes a curved one, which
    ``Robot.check_configuration`` refuses behind the most distal base (a joint-limit rule, not
    a numerical one): switched off for the differences."""
    monkeypatch.setattr(Robot, "check_configuration", lambda self, alpha, beta: None)


def _perturbed(robot, d_curv, d_kxy, d_kz):
    """``robot`` with its section precurvatures moved by ``d_curv`` (n, S, 2) [1/m], and k_xy,
    k_z by ``d_kxy``, ``d_kz`` (n,) [N m^2] (k_z through the Poisson ratio)."""
    tubes = []
    for i, t in enumerate(robot.tubes):
        secs = tuple(dataclasses.replace(sec, precurvature=(sec.precurvature[0] + d_curv[i, k, 0],
                                                            sec.precurvature[1] + d_curv[i, k, 1]))
                     for k, sec in enumerate(t.sections))
        kxy, kz = t.k_xy + d_kxy[i], t.k_z + d_kz[i]
        tubes.append(dataclasses.replace(t, sections=secs, k_xy=kxy, poisson_ratio=kxy / kz - 1.0))
    return robot.replace(tubes=tuple(tubes))


def _parameters(robot):
    """Parameter vector q in the column order of ``StandardTipDerivatives.jacobian`` (without
    alpha): precurvature (n, S, 2), k_xy (n,), k_z (n,); and a mask of the real entries."""
    n = robot.n_tubes
    S = max(len(t.sections) for t in robot.tubes)
    curv = np.zeros((n, S, 2))
    real = np.zeros((n, S, 2), dtype=bool)
    for i, t in enumerate(robot.tubes):
        for k, sec in enumerate(t.sections):
            curv[i, k] = sec.precurvature
            real[i, k] = True
    kxy = np.array([t.k_xy for t in robot.tubes])
    kz = np.array([t.k_z for t in robot.tubes])
    return curv, kxy, kz, real


def _tip(robot, alpha, beta, dq, guess):
    """Tip position and tangent of ``solve_standard`` with the parameters moved by ``dq`` (P,)
    (alpha, precurvature, k_xy, k_z), started from the base torsions ``guess``."""
    n = robot.n_tubes
    curv, _, _, _ = _parameters(robot)
    S = curv.shape[1]
    da, dc, dx, dz = np.split(dq, [n, n + 2 * n * S, 2 * n + 2 * n * S])
    moved = robot if not np.any(dq[n:]) else _perturbed(robot, dc.reshape(n, S, 2), dx, dz)
    sol = solve_standard(moved, alpha + da, beta, TIGHT, initial_guess=guess, check_stability=False)
    assert sol.diagnostics.converged
    return np.concatenate([sol.tip_position, sol.tip_tangent])


def _scales(robot):
    """Natural size of each parameter, shape (P,): 1 rad, |uhat| (at least 1 1/m), k."""
    n = robot.n_tubes
    curv, kxy, kz, _ = _parameters(robot)
    c = np.maximum(np.abs(curv), 1.0).ravel()
    return np.concatenate([np.ones(n), c, kxy, kz])


def _fd_errors(robot, q, derivatives=standard_tip_derivatives):
    """Largest relative error per column kind of the exact derivative (of the entry point
    ``derivatives``) against central differences: {kind: max_col |J_fd - J| / |J_fd|}, position
    and tangent together."""
    alpha, beta = robot.configuration(q)
    d = derivatives(robot, alpha, beta, TIGHT)
    Jp, Jt = d.jacobian()
    J = np.vstack([Jp, Jt])
    n = robot.n_tubes
    _, _, _, real = _parameters(robot)
    kinds = (["alpha"] * n + ["precurvature"] * real.size + ["k_xy"] * n + ["k_z"] * n)
    mask = np.concatenate([np.ones(n, bool), real.ravel(), np.ones(2 * n, bool)])
    scales = _scales(robot)
    errors = {}
    for col in np.flatnonzero(mask):
        h = FD_STEP * scales[col]
        e = np.zeros(J.shape[1])
        e[col] = h
        fd = (_tip(robot, alpha, beta, e, d.base_torsion) - _tip(robot, alpha, beta, -e, d.base_torsion)) / (2 * h)
        for part, rows in (("position", slice(0, 3)), ("tangent", slice(3, 6))):
            err = np.linalg.norm(J[rows, col] - fd[rows]) / np.linalg.norm(fd[rows])
            key = f"{kinds[col]} {part}"
            errors[key] = max(errors.get(key, 0.0), err)
    # padded entries (no such section) are exactly zero
    assert np.all(d.d_position_d_precurvature[:, ~real] == 0.0)
    return errors


@pytest.mark.usefixtures("no_joint_check")
@pytest.mark.parametrize("entry", ENTRIES)
@pytest.mark.parametrize("name, joints", CASES, ids=[c[0].split("-")[1] for c in CASES])
def test_every_column_matches_central_differences(name, joints, entry):
    """Catches any missing or wrong term of the chain (largest relative error when dropped, on
    these cases): the sigma0 correction of the implicit-function theorem (0.27 on alpha, up to
    1.8), the precurvature or stiffness forcing of the RK4 stages (0.5-1.5 on their columns),
    the stiffness weights of the bending (1.4 on k_xy), the Hermite midpoint's torsion term
    (1.6e-5 on alpha, 1.5e-4 on k_z)."""
    robot = load_robot(MODELS / name)
    for q in joints:
        errors = _fd_errors(robot, q, ENTRIES[entry])
        worst = max(errors, key=errors.get)
        assert errors[worst] < FD_RTOL, f"{name} at {q}: {worst} relative error {errors[worst]:.3g}"


@pytest.mark.usefixtures("no_joint_check")
def test_taylor_remainder_is_quadratic():
    """|tip(q + h v) - tip(q) - h J v| falls like h^2 over three decades of h (a wrong J leaves
    a remainder linear in h), in a random direction v of all parameters at once."""
    robot = load_robot(MODELS / "ha2019-table7-calibrated.toml")
    alpha, beta = robot.configuration([0.9, -1.7, -0.07])
    d = standard_tip_derivatives(robot, alpha, beta, TIGHT)
    Jp, Jt = d.jacobian()
    J = np.vstack([Jp, Jt])
    _, _, _, real = _parameters(robot)
    n = robot.n_tubes
    mask = np.concatenate([np.ones(n, bool), real.ravel(), np.ones(2 * n, bool)])
    v = np.random.default_rng(7).standard_normal(J.shape[1]) * _scales(robot) * mask
    v[2 * n + real.size:] *= 0.1     # stiffness changes of a few per cent at h = 0.1
    tip0 = _tip(robot, alpha, beta, np.zeros_like(v), d.base_torsion)
    hs = np.array([1e-1, 1e-2, 1e-3, 1e-4])
    rem = [np.linalg.norm(_tip(robot, alpha, beta, h * v, d.base_torsion) - tip0 - h * J @ v) for h in hs]
    slopes = np.diff(np.log10(rem)) / np.diff(np.log10(hs))
    assert np.all(np.abs(slopes - 2.0) < 0.05), (rem, slopes)


@pytest.mark.parametrize("entry", ENTRIES)
@pytest.mark.parametrize("name, joints", [CASES[0], CASES[2]], ids=["table2", "table7"])
def test_common_rotation_and_stiffness_scaling(name, joints, entry):
    """Two invariants of the model, computed without finite differences: rotating every base by
    the same angle rotates the robot about z (sum_i d tip / d alpha_i = e_z x tip, the same for
    the tangent), and scaling every stiffness by one factor changes nothing (no external load:
    sum_i k_(i,xy) d tip / d k_(i,xy) + k_(i,z) d tip / d k_(i,z) = 0)."""
    robot = load_robot(MODELS / name)
    _, kxy, kz, _ = _parameters(robot)
    ez = np.array([0.0, 0.0, 1.0])
    for q in joints:
        d = ENTRIES[entry](robot, *robot.configuration(q))
        np.testing.assert_allclose(d.d_position_d_alpha.sum(axis=1), np.cross(ez, d.tip_position), atol=1e-12)
        np.testing.assert_allclose(d.d_tangent_d_alpha.sum(axis=1), np.cross(ez, d.tip_tangent), atol=1e-11)
        for dk_xy, dk_z in ((d.d_position_d_k_xy, d.d_position_d_k_z), (d.d_tangent_d_k_xy, d.d_tangent_d_k_z)):
            scale = np.abs(dk_xy * kxy).max()
            np.testing.assert_allclose(dk_xy @ kxy + dk_z @ kz, 0.0, atol=1e-9 * scale)


def test_shapes_and_reuse_of_a_solution():
    robot = load_robot(MODELS / "ha2019-table2-nominal.toml")
    alpha, beta = robot.configuration([0.4, -0.9, -0.05])
    sol = solve_standard(robot, alpha, beta)
    d = standard_tip_derivatives(robot, alpha, beta, solution=sol)
    assert isinstance(d, StandardTipDerivatives)
    assert d.d_position_d_alpha.shape == d.d_tangent_d_alpha.shape == (3, 3)
    assert d.d_position_d_precurvature.shape == (3, 3, 2, 2)
    assert d.d_position_d_k_xy.shape == d.d_position_d_k_z.shape == (3, 3)
    assert d.jacobian()[0].shape == (3, 3 * (3 + 2 * 2))
    np.testing.assert_array_equal(d.tip_position, sol.tip_position)
    again = standard_tip_derivatives(robot, alpha, beta)
    np.testing.assert_allclose(again.jacobian()[0], d.jacobian()[0], rtol=1e-6, atol=1e-12)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.tip_position = None


def test_refuses_bad_input():
    robot = load_robot(MODELS / "ha2019-table2-nominal.toml")
    alpha, beta = robot.configuration([0.4, -0.9, -0.05])
    with pytest.raises(ValueError, match=r"alpha must have shape \(3,\)"):
        standard_tip_derivatives(robot, alpha[:2], beta)
    with pytest.raises(ValueError, match=r"beta must have shape \(3,\)"):
        standard_tip_derivatives(robot, alpha, np.zeros((3, 1)))
    sol = solve_standard(robot, alpha, beta)
    with pytest.raises(ValueError, match="solution is for alpha"):
        standard_tip_derivatives(robot, alpha + 0.1, beta, solution=sol)
    other = _perturbed(robot, np.full((3, 2, 2), 0.5), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="does not belong to this robot"):
        standard_tip_derivatives(other, alpha, beta, solution=sol)
    stiffer = _perturbed(robot, np.zeros((3, 2, 2)), np.array([0.0, 0.0, 1e-3]), np.zeros(3))
    with pytest.raises(ValueError, match="does not belong to this robot"):
        standard_tip_derivatives(stiffer, alpha, beta, solution=sol)
    failed = dataclasses.replace(sol, diagnostics=dataclasses.replace(sol.diagnostics, converged=False,
                                                                      message="shooting did not converge"))
    with pytest.raises(ConvergenceError, match="did not converge"):
        standard_tip_derivatives(robot, alpha, beta, solution=failed)
    with pytest.raises(ConvergenceError, match="did not converge"):
        standard_tip_derivatives(robot, alpha, beta, ModelSettings(max_shooting_iterations=1))


def test_refuses_an_unstable_equilibrium():
    """Equal long tubes past the bifurcation at 180 deg (test_mechanics_standard): the shooting
    Jacobian's determinant is negative there, and the derivative is refused."""
    k = 5.07e-2
    kappa = 1 / 0.06
    t1 = Tube("tube 1", (Section(0.15, (0.0, kappa)),), k, 0.3, inner_diameter=1.1e-3)
    t2 = Tube("tube 2", (Section(0.15, (0.0, kappa)),), k, 0.3, outer_diameter=1.0e-3)
    pair = Robot("pair", (t1, t2), (0.0,), (Joint("rotation", 1, -np.pi, np.pi),))
    alpha, beta = pair.configuration([np.pi - 0.05])
    with pytest.raises(ElasticInstabilityError, match="determinant"):
        standard_tip_derivatives(pair, alpha, beta)


def _stable_solutions(robot, count, seed):
    """``count`` random configurations within the joint limits with their converged, stable
    solutions (``check_stability=False``: the determinant test only)."""
    rng = np.random.default_rng(seed)
    lo = np.array([j.lower for j in robot.joints])
    hi = np.array([j.upper for j in robot.joints])
    out = []
    while len(out) < count:
        alpha, beta = robot.configuration(lo + (hi - lo) * rng.random(lo.size))
        if not robot.configurations_possible(alpha[None], beta[None])[0]:
            continue
        sol = solve_standard(robot, alpha, beta, check_stability=False)
        if sol.diagnostics.converged and not sol.diagnostics.unstable:
            out.append(sol)
    return out


@pytest.mark.parametrize("name", ["ha2019-table2-six-joint.toml", "ha2019-table1-tube-pair.toml"],
                         ids=["six-joint", "pair"])
def test_batch_equals_single_row_by_row(name):
    """Each row of the batch (its own grid from its beta, from the solution's base torsions)
    equals the single entry point on that solution; a wrong base torsion and an impossible
    configuration are flagged (NaN rows), not raised, and leave the other rows alone."""
    robot = load_robot(MODELS / name)
    sols = _stable_solutions(robot, 5, seed=11)
    alpha = np.array([s.alpha for s in sols])
    beta = np.array([s.beta for s in sols])
    sig0 = np.array([s.base_torsion for s in sols])
    b = standard_tip_derivatives_batch(robot, alpha, beta, sig0)
    n, K = robot.n_tubes, len(sols)
    S = max(len(t.sections) for t in robot.tubes)
    P = n * (3 + 2 * S)
    assert b.d_position.shape == b.d_tangent.shape == (K, 3, P) and b.d_base_torsion.shape == (K, n, P)
    assert b.tip_position.shape == b.tip_tangent.shape == (K, 3)
    assert b.ok.all() and b.valid.all() and np.all(b.residual < 1e-9 * 100)
    for k, sol in enumerate(sols):
        d = standard_tip_derivatives(robot, sol.alpha, sol.beta, solution=sol)
        Jp, Jt = d.jacobian()
        for got, want in ((b.d_position[k], Jp), (b.d_tangent[k], Jt), (b.d_base_torsion[k], d.d_base_torsion),
                          (b.tip_position[k], d.tip_position), (b.tip_tangent[k], d.tip_tangent)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
        assert b.shooting_determinant[k] == pytest.approx(d.shooting_determinant, rel=1e-12)
    # row 1 with a wrong base torsion, row 3 impossible (inner base ahead of its outer tube's)
    bad_sig0, bad_beta = sig0.copy(), beta.copy()
    bad_sig0[1, -1] += 1.0
    bad_beta[3, -1] = bad_beta[3, 0] + 0.01
    f = standard_tip_derivatives_batch(robot, alpha, bad_beta, bad_sig0)
    np.testing.assert_array_equal(f.ok, np.arange(K) % 2 == 0)
    np.testing.assert_array_equal(f.valid, np.arange(K) != 3)
    assert f.residual[1] > 1e-9 * 100
    for field in ("d_position", "d_tangent", "d_base_torsion", "tip_position", "tip_tangent"):
        assert np.all(np.isnan(getattr(f, field)[[1, 3]]))
        np.testing.assert_array_equal(getattr(f, field)[f.ok], getattr(b, field)[f.ok])
    with pytest.raises(ValueError, match=r"base_torsion must have shape"):
        standard_tip_derivatives_batch(robot, alpha, beta, sig0[:, :1])
    with pytest.raises(ValueError, match=r"alpha and beta must both have shape"):
        standard_tip_derivatives_batch(robot, alpha, beta[:2], sig0)
