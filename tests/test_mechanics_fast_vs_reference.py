"""The fast mechanics path (ctrplan.mechanics) against the frozen slow reference (tests/ctrplan_reference).

The reference modules are verbatim copies of the solvers before the speed work. On
seeded random configurations of the Table II robot (the paper's Section IV-D set-up, default
settings, ds = 3 mm) the fast path must reproduce

- standard-model tips and base torsions (same algorithm: to 1e-8 m and 1e-6 1/m);
- clearance and friction tips to 5 um (both stop the outer loop on a 1 um centerline change);
- every contact force to 1 % of the largest contact force of that solution;
- the bound (position, angle, translation-last position) to 1 %.
"""

import numpy as np
import pytest

from ctrplan.mechanics import (ModelSettings, evaluate_bound, solve_clearance, solve_friction,
                               solve_standard)
from ctrplan_reference import bound_reference, contact_reference, standard_reference

from _robots import table1_pair, table2_robot

SETTINGS = ModelSettings()
TIP_TOL = 5e-6          # [m]
FORCE_RTOL = 0.01       # of the largest contact force
BOUND_RTOL = 0.01
GAP_TOL = 2e-6          # [m], radial centerline offsets (clearances 42.5 and 62.5 um)


def _random_configurations(robot, count, seed):
    """Seeded random joint values inside the limits whose reference standard solution is a
    unique, converged equilibrium."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        q = np.array([rng.uniform(j.lower, j.upper) for j in robot.joints])
        alpha, beta = robot.configuration(q)
        st = standard_reference.solve_standard(robot, alpha, beta, SETTINGS)
        if st.diagnostics.ok:
            out.append(q)
    return out


def _assert_forces_close(fast, ref):
    np.testing.assert_array_equal(fast.contact_pair, ref.contact_pair)
    np.testing.assert_allclose(fast.contact_s, ref.contact_s, atol=1e-12)
    scale = max(float(np.max(ref.contact_force)), 1e-9)
    assert np.max(np.abs(fast.contact_force - ref.contact_force)) <= FORCE_RTOL * scale


def _assert_contact_close(fast, ref):
    assert fast.diagnostics.converged == ref.diagnostics.converged
    assert np.linalg.norm(fast.tip_position - ref.tip_position) < TIP_TOL
    assert np.linalg.norm(fast.tip_tangent - ref.tip_tangent) < 1e-3
    for pf, pr in zip(fast.centerlines, ref.centerlines):
        assert np.max(np.linalg.norm(pf - pr, axis=1)) < TIP_TOL
    _assert_forces_close(fast, ref)
    np.testing.assert_allclose(fast.contact_gap, ref.contact_gap, atol=GAP_TOL)


@pytest.mark.parametrize("q", _random_configurations(table2_robot(), 4, seed=4))
def test_standard_matches_reference(q):
    robot = table2_robot()
    alpha, beta = robot.configuration(q)
    for check in (True, False):
        fast = solve_standard(robot, alpha, beta, SETTINGS, check_stability=check)
        ref = standard_reference.solve_standard(robot, alpha, beta, SETTINGS, check_stability=check)
        np.testing.assert_allclose(fast.tip_position, ref.tip_position, atol=1e-8)
        np.testing.assert_allclose(fast.tip_tangent, ref.tip_tangent, atol=1e-8)
        np.testing.assert_allclose(fast.base_torsion, ref.base_torsion, atol=1e-6)
        np.testing.assert_allclose(fast.centerline, ref.centerline, atol=1e-8)
        np.testing.assert_allclose(fast.psi_mid, ref.psi_mid, atol=1e-8)
        assert fast.diagnostics.unstable == ref.diagnostics.unstable
        assert fast.diagnostics.n_equilibria == ref.diagnostics.n_equilibria


@pytest.mark.parametrize("q", _random_configurations(table2_robot(), 3, seed=11))
def test_clearance_and_friction_match_reference(q):
    robot = table2_robot()
    alpha, beta = robot.configuration(q)
    st = standard_reference.solve_standard(robot, alpha, beta, SETTINGS)
    ref_cl = contact_reference.solve_contact(robot, alpha, beta, SETTINGS, standard=st)
    fast_cl = solve_clearance(robot, alpha, beta, SETTINGS, standard=st)
    _assert_contact_close(fast_cl, ref_cl)
    for eta in ((1, -1), (-1, 1)):
        ref = contact_reference.solve_contact(robot, alpha, beta, SETTINGS, eta=eta, standard=st,
                                              warm_start=ref_cl)
        fast = solve_friction(robot, alpha, beta, eta, SETTINGS, standard=st, warm_start=fast_cl)
        _assert_contact_close(fast, ref)
        np.testing.assert_array_equal(fast.eta, ref.eta)


@pytest.mark.parametrize("q", _random_configurations(table2_robot(), 3, seed=23))
def test_bound_matches_reference(q):
    robot = table2_robot()
    alpha, beta = robot.configuration(q)
    ref = bound_reference.evaluate_bound(robot, alpha, beta, SETTINGS)
    fast = evaluate_bound(robot, alpha, beta, SETTINGS)
    assert fast.diagnostics.converged == ref.diagnostics.converged
    assert fast.position == pytest.approx(ref.position, rel=BOUND_RTOL)
    assert fast.angle == pytest.approx(ref.angle, rel=BOUND_RTOL)
    assert fast.translation_last_position == pytest.approx(ref.translation_last_position, rel=BOUND_RTOL)
    assert sorted(fast.friction) == sorted(ref.friction)
    for eta, sol in fast.friction.items():
        assert np.linalg.norm(sol.tip_position - ref.friction[eta].tip_position) < TIP_TOL
        _assert_forces_close(sol, ref.friction[eta])


def test_tube_pair_friction_matches_reference():
    """Two-tube robot of Table I (a single pair, other grid sizes) at a large relative angle."""
    robot = table1_pair(clearance=0.05e-3, mu=0.2)
    settings = ModelSettings(ds=2e-3)
    alpha, beta = robot.configuration([2.5])
    for eta in (None, (1,), (-1,)):
        ref = contact_reference.solve_contact(robot, alpha, beta, settings, eta=eta)
        fast = solve_friction(robot, alpha, beta, eta, settings) if eta else solve_clearance(
            robot, alpha, beta, settings)
        _assert_contact_close(fast, ref)


@pytest.mark.slow
@pytest.mark.parametrize("q", _random_configurations(table2_robot(), 12, seed=101))
def test_bound_matches_reference_many(q):
    test_bound_matches_reference(q)


def _linearize_kernels(prob, u, R, p):
    """Run the per-linearization kernels of the compiled contact solver on ``prob`` at the
    curvatures u (S, 3) with frames R and points p (what ``_contact_fast._outer_step`` does first)."""
    from ctrplan.mechanics import _contact_kernels as ck

    ck.linearize(u, prob.uhat, prob.kinv, prob.h, prob.node_off, R, p, prob._Omega, prob._base,
                 prob._H1, prob._H2, prob._F3, prob._Jpv)
    ck.contact_frames(R, p, prob.jo, prob.ji, prob._Jpv, prob._B, prob._dfree, prob._diagW,
                      prob._H1, prob._H2, prob.pair)
    ck.contact_projections(prob._B, p, prob.jo, prob.ji, prob._H1, prob._H2, prob._Pc)


@pytest.mark.parametrize("eta", [None, (1, -1)])
def test_compliance_kernels_equal_dense_products(eta):
    """Prefix-sum compliance W = A K^-1 A^T, torque columns Z = A K^-1 zt^T, force-free
    displacements and generalized forces A^T phi + zt^T lam of the compiled kernels equal the
    dense products of the reference linearization (Appendix A, B of Ha et al. 2019)."""
    from ctrplan.mechanics import _contact_kernels as ck
    from ctrplan.mechanics._contact_fast import FlatProblem

    robot = table2_robot()
    alpha, beta = robot.configuration([2.0, -1.0, -0.07])
    settings = ModelSettings(ds=5e-3)
    st = solve_standard(robot, alpha, beta, settings, check_stability=False)
    mu = robot.friction_coefficients if eta else np.zeros(2)
    ref = contact_reference._Setup(robot, st, eta, mu)
    rng = np.random.default_rng(3)
    u_list = [u + rng.normal(scale=5.0, size=u.shape) for u in ref.u0]   # off the standard solution
    fk = ref.kinematics(u_list)
    A, b, zt = ref.linearize(u_list, fk)
    AK = A * ref.kinv[None, :]
    W_ref, Z_ref = AK @ A.T, AK @ zt.T
    u_flat = np.concatenate([u.ravel() for u in u_list])
    dfree_ref = b.ravel() - A @ (u_flat - ref.uhat_flat)

    prob = FlatProblem(robot, st, eta, mu)
    u = u_flat.reshape(-1, 3)
    R, p = prob.kinematics(u)
    np.testing.assert_allclose(p, np.concatenate([x for _, x in fk]), atol=1e-14)
    _linearize_kernels(prob, u, R, p)
    M = prob.M
    Wt = np.zeros((2 * M, 2 * M))
    Zt = np.zeros((M, 2 * M))
    geometry, law = prob.contact_geometry(R, p), prob.contact_law(1.0)
    ck.fill_columns(np.arange(M), ck.ContactWork(Wt, Zt, np.zeros(M, dtype=bool), np.ones(M, dtype=bool)),
                    geometry, law)
    W, Z = Wt.T, Zt.T   # stored transposed
    scale = np.abs(W_ref).max()
    assert np.abs(W - W_ref).max() < 1e-10 * scale
    np.testing.assert_allclose(prob._diagW[:, [0, 1], [0, 1]].ravel(), np.diag(W_ref), rtol=1e-10)
    if eta:
        assert np.abs(Z - Z_ref).max() < 1e-10 * np.abs(Z_ref).max()
    # Filled as the solver fills them: a few columns on part of the rows, then the rows extended
    # and the other columns filled. The block of a row whose own column is already computed is
    # copied from it (W symmetric), so each off-diagonal block comes from one of the two block
    # formulas depending on the order: ascending, descending and a random order check both
    # formulas on every block, and the copy's transposition.
    for order in (np.arange(M), np.arange(M)[::-1], rng.permutation(M)):
        cw = ck.ContactWork(np.full((2 * M, 2 * M), np.nan), np.full((M, 2 * M), np.nan),
                            np.zeros(M, dtype=bool), np.zeros(M, dtype=bool))
        first_rows = np.zeros(M, dtype=bool)
        first_rows[order[:M // 2]] = True
        ck.extend_rows(first_rows, cw, geometry, law)
        ck.fill_columns(order[:M // 4], cw, geometry, law)
        ck.extend_rows(np.ones(M, dtype=bool), cw, geometry, law)
        ck.fill_columns(order, cw, geometry, law)
        assert np.abs(cw.Wt.T - W_ref).max() < 1e-10 * scale   # NaN (an entry never set) fails
        if eta:
            assert np.abs(cw.Zt.T - Z_ref).max() < 1e-10 * np.abs(Z_ref).max()
    np.testing.assert_allclose(prob._dfree.ravel(), dfree_ref, atol=1e-12 * np.abs(dfree_ref).max() + 1e-15)
    lam = rng.uniform(0.0, 1.0, M) * (rng.uniform(size=M) < 0.4)
    d = rng.normal(scale=1e-5, size=(M, 2))
    g = np.empty_like(u)
    ck.generalized_curvature(lam, d, geometry, law, prob.uhat, g)
    phi = -lam[:, None] * np.einsum("kab,kb->ka", ref.Mblk, d)
    g_ref = ref.uhat_flat + ref.kinv * (A.T @ phi.ravel() + zt.T @ lam)
    np.testing.assert_allclose(g.ravel(), g_ref, rtol=1e-9, atol=1e-9 * np.abs(g_ref).max())
    # displacements without W's columns: dfree + W phi + Z lam (phi = 0 without the forces),
    # written only outside the known rows
    known = rng.uniform(size=M) < 0.3
    for with_forces in (True, False):
        d_out = d.copy()
        ck._complete_displacements(lam, d_out, known, with_forces, prob._dfree, geometry, law)
        d_ref = dfree_ref + (W_ref @ phi.ravel() if with_forces else 0.0) + Z_ref @ lam
        np.testing.assert_array_equal(d_out[known], d[known])
        err = np.abs(d_out[~known].ravel() - d_ref.reshape(M, 2)[~known].ravel()).max()
        assert err < 1e-9 * np.abs(d_ref).max()


@pytest.mark.parametrize("eta", [None, (1, -1), (-1, 1)])
@pytest.mark.parametrize("q", [[2.0, -1.0, -0.07], [0.3, 2.5, -0.09], [-2.8, 0.7, -0.05]])
def test_constraint_generation_equals_the_full_complementarity_solve(eta, q):
    """The working-set solve (solve_contacts: constraint generation around the FB Newton method)
    reaches the solution of the Newton method over all contacts, at the first linearization
    (standard solution, lambda = 0, where the force-free shape violates most contacts): same
    displacements to 1e-3 of the clearance, same contact forces to 1 % of the largest, and
    no contact outside its final working set violated."""
    from ctrplan.mechanics import _contact_kernels as ck
    from ctrplan.mechanics._contact_fast import FlatProblem

    robot = table2_robot()
    alpha, beta = robot.configuration(q)
    st = solve_standard(robot, alpha, beta, SETTINGS, check_stability=False)
    mu = robot.friction_coefficients if eta else np.zeros(2)
    prob = FlatProblem(robot, st, eta, mu)
    u = prob.u0.copy()
    R, p = prob.kinematics(u)
    _linearize_kernels(prob, u, R, p)
    M = prob.M
    kappa = 1.0 / float(np.mean(prob._diagW[:, [0, 1], [0, 1]]))
    tol = SETTINGS.complementarity_tol
    assert np.sum(np.sum(prob._dfree ** 2, axis=1) > prob.c ** 2) > M // 4   # a hard start

    def run(solver, *extra):
        W = np.empty((2 * M, 2 * M))
        Z = np.empty((M, 2 * M)) if prob.friction else np.empty((1, 1))
        work = ck.ContactWork(W, Z, np.zeros(M, dtype=np.bool_), np.zeros(M, dtype=np.bool_))
        return solver(np.zeros(M), prob._dfree, prob.contact_geometry(R, p), prob.contact_law(kappa), work,
                      tol, 200, *extra)

    lam_g, d_g, ok_g, _, err_g = run(ck.solve_contacts)
    lam_f, d_f, ok_f, _, err_f = run(ck.complementarity, np.ones(M, dtype=np.bool_))
    assert ok_g and ok_f and err_g < tol and err_f < tol
    assert np.max(np.abs(d_g - d_f)) < 1e-3 * prob.c.min()
    forces_g, forces_f = prob.c * lam_g, prob.c * lam_f
    assert np.max(np.abs(forces_g - forces_f)) <= 0.01 * forces_f.max()
    # the stopping test |Phi_k| / (kappa c_k) < tol allows |d_k| up to c_k / (1 - tol), i.e.
    # |d_k|^2 / c_k^2 - 1 up to about 2 tol (seen: 1.8e-6 with tol = 1e-6)
    assert np.all(np.sum(d_g ** 2, axis=1) <= prob.c ** 2 * (1 + 2 * tol))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_newton_residual_is_min_on_active_contacts_and_stops_on_fischer_burmeister(seed):
    """The complementarity residual of the Newton method (``_contact_kernels._residual``),
    written out here from its definition: with a = c lambda, b = kappa c (c / |d| - 1), the
    Fischer-Burmeister function FB(a, b) = a + b - sqrt(a^2 + b^2) on every contact of the
    working set (``natural`` False), or min(a, b) on those with lambda > 0 (``natural`` True),
    with the matching partial derivatives; phi = 0 outside the working set. The stopping
    measure max |FB| / (kappa c) is the same in both modes: the natural residual can be half
    of FB where a is small and b < 0, and a stopping test on it would accept twice the
    violation. Seeded contacts: separated, violated, loaded and degenerate (a = b)."""
    from ctrplan.mechanics import _contact_kernels as ck

    rng = np.random.default_rng(seed)
    M, kappa = 40, 3.0e3
    c = rng.uniform(0.05e-3, 0.2e-3, M)
    lam = np.where(rng.uniform(size=M) < 0.6, rng.uniform(0.0, 5.0, M), 0.0)
    ratio = rng.uniform(0.5, 1.5, M)                     # |d| / c: violated where > 1
    angle = rng.uniform(0.0, 2 * np.pi, M)
    d = (ratio * c)[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
    # two degenerate contacts: lambda chosen so that a = b
    for k in (0, 1):
        ratio[k] = 0.9
        d[k] = ratio[k] * c[k] * np.array([1.0, 0.0])
        lam[k] = kappa * (1 / ratio[k] - 1)
    work = rng.uniform(size=M) < 0.8
    work[:2] = True
    a = c * lam
    b = kappa * c * (c / np.linalg.norm(d, axis=1) - 1)
    r = np.hypot(a, b)
    fb = a + b - r
    err_ref = np.max(np.abs(fb[work]) / (kappa * c[work]))
    for natural in (False, True):
        phi, da, db = np.empty(M), np.empty(M), np.empty(M)
        merit, err = ck._residual(lam, d, c, kappa, phi, da, db, work, natural)
        nat = natural & (lam > 0)
        phi_ref = np.where(nat, np.minimum(a, b), fb)
        da_ref = np.where(nat, (a <= b).astype(float), 1 - a / r)
        db_ref = np.where(nat, (a > b).astype(float), 1 - b / r)
        phi_ref[~work], da_ref[~work], db_ref[~work] = 0.0, 1.0, 0.0
        np.testing.assert_allclose(phi, phi_ref, rtol=1e-12, atol=1e-12 * np.abs(a).max())
        np.testing.assert_allclose(da, da_ref, atol=1e-12)
        np.testing.assert_allclose(db, db_ref, atol=1e-12)
        assert merit == pytest.approx(np.sum(phi_ref ** 2), rel=1e-12)
        assert err == pytest.approx(err_ref, rel=1e-12)
    assert np.any(work & (lam > 0) & (np.abs(np.minimum(a, b)) < 0.6 * np.abs(fb)))   # case present


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_anderson_step_equals_the_least_squares_mixing(seed):
    """The compiled Anderson step of the outer loop (_contact_fast.Anderson) against its
    definition with a dense least-squares solve: gamma = argmin |f - dF gamma| over the last
    ``depth`` differences of the residuals f = g - u, next iterate g - dG gamma - (1 - beta)
    (f - dF gamma); the history restarts when the residual size grows. Seeded random iterates of
    a contraction, a history longer than the depth, one growing residual, and a repeated residual
    (a zero difference column, which the least-squares solve drops)."""
    from ctrplan.mechanics._contact_fast import Anderson

    rng = np.random.default_rng(seed)
    size, depth, beta = 60, 3, 0.5
    A = 0.2 * rng.standard_normal((size, size))
    fast = Anderson(depth, beta)
    f_hist, g_hist, last = [], [], np.inf
    u = rng.standard_normal(size)
    sizes = [1.0, 0.5, 0.3, 0.2, 0.4, 0.1, 0.05, 0.02]   # the fifth grows: history restarts
    for k, res in enumerate(sizes):
        g = np.tanh(A @ u) + 1.0
        if k == 6:
            g = u + f_hist[-1]    # the same residual as the step before: dF has a zero column
        if res > last:
            f_hist, g_hist = [], []
        last = res
        f = g - u
        f_hist, g_hist = (f_hist + [f])[-(depth + 1):], (g_hist + [g])[-(depth + 1):]
        if len(f_hist) < 2:
            expected = g - (1 - beta) * f
        else:
            dF = np.column_stack(np.diff(f_hist, axis=0))
            dG = np.column_stack(np.diff(g_hist, axis=0))
            gamma = np.linalg.lstsq(dF, f, rcond=None)[0]
            expected = g - dG @ gamma - (1 - beta) * (f - dF @ gamma)
        got = fast.step(u, g, res)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
        u = got


def test_problem_with_other_directions_equals_a_fresh_one():
    """FlatProblem.with_directions (the bound's friction solves reuse the clearance problem's
    arrays) gives the same law as building the problem for those directions, keeps the
    original's, and owns its scratch arrays."""
    from ctrplan.mechanics._contact_fast import FlatProblem

    robot = table2_robot()
    alpha, beta = robot.configuration([0.3, 2.5, -0.09])
    st = solve_standard(robot, alpha, beta, SETTINGS, check_stability=False)
    base = FlatProblem(robot, st, None, np.zeros(2))
    for eta in [(1, 1), (1, -1), (-1, 1)]:
        fresh = FlatProblem(robot, st, eta, robot.friction_coefficients)
        derived = base.with_directions(robot, eta, robot.friction_coefficients)
        assert derived.friction and not base.friction
        for name in ["Mblk", "tq_out", "tq_in", "c", "pair", "jo", "ji", "uhat", "kinv", "u0", "h"]:
            np.testing.assert_array_equal(getattr(derived, name), getattr(fresh, name), err_msg=name)
        assert derived._work.Zt.shape == fresh._work.Zt.shape
        assert not np.shares_memory(derived._dfree, base._dfree)
        assert not np.shares_memory(derived._work.Wt, base._work.Wt)
        np.testing.assert_array_equal(base.Mblk, np.broadcast_to(np.eye(2), base.Mblk.shape))
