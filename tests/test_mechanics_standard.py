"""Standard zero-clearance model: closed forms, symmetries, convergence, stability."""

import numpy as np
import pytest

from ctrplan.errors import ElasticInstabilityError, JointLimitError
from ctrplan.mechanics import ModelSettings, solve_standard
from ctrplan.robot import Joint, Robot, Section, Tube

from _robots import table1_pair, table2_robot


def _arc(p, R, kappa, length):
    """Advance a planar arc bending about the local y axis (closed form)."""
    th = kappa * length
    if kappa == 0:
        return p + R[:, 2] * length, R
    local = np.array([(1 - np.cos(th)) / kappa, 0.0, np.sin(th) / kappa])
    Ry = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    return p + R @ local, R @ Ry


def test_aligned_tubes_follow_constant_curvature_arcs():
    """All precurvatures aligned: no torsion; the shape is a chain of arcs whose curvature is
    the stiffness-weighted mean (Eq. (2) with u_xy = sum k_i uhat_i / sum k_i)."""
    robot = table2_robot()
    alpha, beta = robot.configuration([0.0, 0.0, -0.034])
    sol = solve_standard(robot, alpha, beta, ModelSettings(ds=1e-3))
    k1 = k2 = 5.07e-2
    k3 = 1.45e-2
    kap12 = (k1 + k2) * (1 / 0.265) / (k1 + k2 + k3)
    p, R = np.array([0.0, 0.0, 0.0]), np.eye(3)
    p, R = _arc(p, R, kap12, 0.150)
    p, R = _arc(p, R, 1 / 0.055, 0.0864)
    np.testing.assert_allclose(sol.tip_position, p, atol=1e-9)
    np.testing.assert_allclose(sol.tip_tangent, R[:, 2], atol=1e-9)
    assert np.nanmax(np.abs(sol.torsion)) < 1e-9


def test_base_rotation_of_all_tubes_rotates_the_robot():
    """Rotating every base by the same angle rotates the shape about z (invariance)."""
    robot = table2_robot()
    alpha, beta = robot.configuration([1.1, -2.0, -0.06])
    a = solve_standard(robot, alpha, beta)
    b = solve_standard(robot, alpha + 0.7, beta)
    Rz = np.array([[np.cos(0.7), -np.sin(0.7), 0], [np.sin(0.7), np.cos(0.7), 0], [0, 0, 1]])
    np.testing.assert_allclose(b.tip_position, Rz @ a.tip_position, atol=1e-9)


def test_mirror_symmetry_of_the_tube_pair():
    """Base angle +theta and -theta give tips mirrored about the xz plane."""
    robot = table1_pair()
    for th in (0.5, 2.0, 3.0):
        a = solve_standard(robot, *robot.configuration([th]))
        b = solve_standard(robot, *robot.configuration([-th]))
        np.testing.assert_allclose(b.tip_position, a.tip_position * [1, -1, 1], atol=1e-9)


def test_converges_as_the_step_shrinks():
    robot = table2_robot()
    alpha, beta = robot.configuration([2.5, 1.0, -0.05])
    tips = [solve_standard(robot, alpha, beta, ModelSettings(ds=ds)).tip_position for ds in (4e-3, 2e-3, 1e-3, 0.25e-3)]
    errs = [np.linalg.norm(t - tips[-1]) for t in tips[:-1]]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-5  # 1 mm step within 0.01 mm of the 0.25 mm reference


def _long_pair(kappa):
    k = 5.07e-2
    t1 = Tube("tube 1", (Section(0.15, (0.0, kappa)),), k, 0.3, inner_diameter=1.1e-3)
    t2 = Tube("tube 2", (Section(0.15, (0.0, kappa)),), k, 0.3, outer_diameter=1.0e-3)
    return Robot("pair", (t1, t2), (0.0,), (Joint("rotation", 1, -np.pi, np.pi),))


def test_detects_elastic_instability():
    """Equal tubes of length L and curvature kappa: the 180 deg configuration bifurcates when
    L^2 kappa^2 (1 + nu) > (pi/2)^2 (Dupont et al. 2010; Ha et al. 2015)."""
    stable = _long_pair(1 / 0.15)     # lambda = 1.3 < 2.47
    unstable = _long_pair(1 / 0.06)   # lambda = 8.1 > 2.47
    sol = solve_standard(stable, *stable.configuration([np.pi - 0.05]))
    assert sol.diagnostics.converged and not sol.diagnostics.unstable
    sol = solve_standard(unstable, *unstable.configuration([np.pi - 0.05]))
    assert sol.diagnostics.unstable
    with pytest.raises(ElasticInstabilityError):
        solve_standard(unstable, *unstable.configuration([np.pi - 0.05]), raise_on_failure=True)


@pytest.mark.parametrize("theta", [np.pi, np.pi - 0.02])
def test_stability_determinant_from_the_predictor_has_the_fine_grids_sign(theta):
    """``standard._shoot`` takes the shooting-Jacobian determinant (the elastic-stability test)
    from the coarse predictor unless it is small, and only then sweeps the fine grid with
    sensitivities. Across the bifurcation of two equal tubes at 180 deg (L^2 kappa^2 (1 + nu) =
    (pi/2)^2 at 1/kappa = 0.1089 m for L = 0.15 m; Dupont et al. 2010) the determinant passes
    through zero: the returned one must have the sign of the fine grid's own determinant at the
    returned base torsion, and equal it to 1e-3 relative where it came from the predictor."""
    from ctrplan.mechanics.packed import pack_robot
    from ctrplan.mechanics.standard import _COARSE_DET_MIN, _newton, _Problem

    settings = ModelSettings()
    dets = []
    for radius in np.linspace(0.100, 0.118, 10):
        robot = _long_pair(1 / radius)
        packed = pack_robot(robot)
        alpha, beta = robot.configuration([theta])
        problem = _Problem(robot, alpha, beta, settings)
        sig0, _, _, ok, det, _ = problem.newton(np.zeros(2), settings, predict=True)
        assert ok
        g = problem.grid
        _, _, _, ok_f, det_fine, _, _ = _newton(g.s, g.present, g.precurvature, packed.k_xy, packed.stiffness_ratio,
                                                alpha, sig0, packed.lengths, settings.shooting_tol,
                                                settings.max_shooting_iterations, np.empty((2, 2)))
        assert ok_f
        assert np.sign(det) == np.sign(det_fine)
        if abs(det) >= _COARSE_DET_MIN:
            assert abs(det - det_fine) <= 1e-3 * abs(det_fine)
        else:
            assert det == det_fine   # the fine sweep's own value
        dets.append(det_fine)
    dets = np.array(dets)
    assert np.any(dets > 0) and np.any(dets < 0)          # the family crosses the bifurcation
    assert np.any(np.abs(dets) < _COARSE_DET_MIN)         # and exercises the fine fallback


def test_follows_a_branch_from_an_initial_guess():
    """Continuation in the base angle with the previous base torsion keeps the solution on
    one branch: the tip moves continuously."""
    robot = _long_pair(1 / 0.06)
    guess = None
    prev = None
    for th in np.linspace(2.0, 3.0, 11):
        sol = solve_standard(robot, *robot.configuration([th]), initial_guess=guess, check_stability=False)
        if prev is not None:
            assert np.linalg.norm(sol.tip_position - prev) < 0.02
        prev, guess = sol.tip_position, sol.base_torsion


def test_rejects_impossible_configurations():
    robot = table2_robot()
    with pytest.raises(JointLimitError, match="beta_3"):
        robot.configuration([0.0, 0.0, -0.2])
    alpha, beta = robot.configuration([0.0, 0.0, -0.05])
    beta[2] = 0.01  # inner base in front of the outer bases
    with pytest.raises(JointLimitError, match="tube 3"):
        solve_standard(robot, alpha, beta)


def test_tube_curvatures_and_frames_are_consistent():
    """Per-tube curvature u_i and frame R_i: z torsion equals psi_i', bending moments balance,
    R_i(beta_i) = Rz(alpha_i) (Eq. (3)), and tubes share the tangent (zero clearance)."""
    robot = table2_robot()
    alpha, beta = robot.configuration([1.2, -2.2, -0.05])
    sol = solve_standard(robot, alpha, beta, ModelSettings(ds=1e-3))
    k = np.array([t.k_xy for t in robot.tubes])
    present = ~np.isnan(sol.psi)
    moment = np.zeros((sol.s.size, 2))
    for i, t in enumerate(robot.tubes):
        u = sol.tube_curvature(i)
        R = sol.tube_frames(i)
        first = np.nonzero(present[:, i])[0][0]
        np.testing.assert_allclose(R[first], np.array([[np.cos(alpha[i]), -np.sin(alpha[i]), 0],
                                                       [np.sin(alpha[i]), np.cos(alpha[i]), 0], [0, 0, 1]]), atol=1e-12)
        np.testing.assert_allclose(R[present[:, i], :, 2], sol.frames[present[:, i], :, 2], atol=1e-12)
        # bending moment of tube i in the common frame: R_z(psi_i) k_i (u_i - uhat_i)
        s_local = sol.s - beta[i]
        br = t.section_breaks()
        idx = np.clip(np.searchsorted(br, s_local, side="right") - 1, 0, len(t.sections) - 1)
        uhat = np.array([sec.precurvature for sec in t.sections])[idx]
        m_body = k[i] * (u[:, :2] - uhat)
        c, s = np.cos(sol.psi[:, i]), np.sin(sol.psi[:, i])
        m = np.column_stack([c * m_body[:, 0] - s * m_body[:, 1], s * m_body[:, 0] + c * m_body[:, 1]])
        moment += np.where(present[:, i, None], m, 0.0)
    # away from section boundaries the tubes' bending moments balance (no external load)
    breaks = np.concatenate([beta[i] + t.section_breaks() for i, t in enumerate(robot.tubes)])
    interior = np.min(np.abs(sol.s[:, None] - breaks[None, :]), axis=1) > 2e-3
    assert np.max(np.abs(moment[interior])) < 1e-9


def test_batch_equals_single_solves():
    """solve_standard_batch reproduces solve_standard (check_stability=False) configuration by
    configuration, flags impossible configurations instead of raising, and checks shapes."""
    from ctrplan.mechanics import solve_standard_batch

    robot = table2_robot()
    rng = np.random.default_rng(7)
    qs = [[rng.uniform(-np.pi, np.pi), rng.uniform(-np.pi, np.pi), rng.uniform(-0.104, -0.034)]
          for _ in range(6)]
    configs = [robot.configuration(q) for q in qs]
    alpha = np.array([a for a, _ in configs])
    beta = np.array([b for _, b in configs])
    beta[-1, 2] = 0.01  # inner base in front of the outer bases: impossible
    settings = ModelSettings(ds=3e-3)
    res = solve_standard_batch(robot, alpha, beta, settings)
    assert not res.valid[-1] and np.all(np.isnan(res.tip_position[-1]))
    for k in range(5):
        st = solve_standard(robot, alpha[k], beta[k], settings, check_stability=False)
        np.testing.assert_allclose(res.tip_position[k], st.tip_position, atol=1e-10)
        np.testing.assert_allclose(res.tip_tangent[k], st.tip_tangent, atol=1e-10)
        np.testing.assert_allclose(res.base_torsion[k], st.base_torsion, atol=1e-8)
        assert res.converged[k] == st.diagnostics.converged
        assert res.unstable[k] == st.diagnostics.unstable
    # threads share the configurations without changing any result
    par = solve_standard_batch(robot, alpha, beta, settings, n_threads=2, compile_threads=True)
    np.testing.assert_array_equal(par.tip_position, res.tip_position)
    np.testing.assert_array_equal(par.iterations, res.iterations)
    with pytest.raises(ValueError, match="shape"):
        solve_standard_batch(robot, alpha[:, :2], beta, settings)
    with pytest.raises(ValueError, match="n_threads"):
        solve_standard_batch(robot, alpha, beta, settings, n_threads=0)


@pytest.mark.parametrize("block_min_rows", [128, 4])
def test_threads_following_blocks_of_a_path_equal_the_serial_follow(monkeypatch, block_min_rows):
    """With ``follow`` and two threads the threads take contiguous blocks of the rows, handed
    out one at a time, and follow each (the default-jobs command line): here two
    blocks (the default minimum of 128 rows) or ten (a minimum of 4 rows, so that block ends fall
    inside the path). On a seeded path through certified and uncertified rows, with one
    impossible row inside it, every row must get the serial follow's flags and, to the shooting
    tolerance, its tips: a block boundary off by one (a row skipped or solved twice) leaves NaN
    or a wrong row, and a block that started from another block's torsions could land on
    another equilibrium."""
    from ctrplan.mechanics import _standard_batch, solve_standard_batch

    monkeypatch.setattr(_standard_batch, "_FOLLOW_BLOCK_MIN_ROWS", block_min_rows)

    robot = table2_robot()
    rng = np.random.default_rng(23)
    t = np.linspace(0.0, 1.0, 41)
    qs = np.column_stack([2.5 * np.sin(2 * np.pi * t) + 0.05 * rng.standard_normal(t.size),
                          np.pi * (2 * t - 1), -0.104 + 0.07 * t])
    configs = [robot.configuration(q) for q in qs]
    alpha = np.array([a for a, _ in configs])
    beta = np.array([b for _, b in configs])
    beta[17, 2] = 0.01   # impossible row inside a block
    settings = ModelSettings(ds=3e-3)
    serial = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=True)
    par = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=True, n_threads=2,
                               compile_threads=True)
    assert serial.certified.any() and not serial.certified[serial.valid].all()
    assert not par.valid[17] and np.all(np.isnan(par.tip_position[17]))
    ok = serial.valid
    assert np.all(np.isfinite(par.tip_position[ok]))
    np.testing.assert_allclose(par.tip_position[ok], serial.tip_position[ok], atol=1e-10)
    for flag in ("converged", "unstable", "n_equilibria", "certified"):
        np.testing.assert_array_equal(getattr(par, flag), getattr(serial, flag))


def test_following_a_path_meets_the_shooting_tolerance_at_every_row():
    """Rows that follow one another (``follow``) are solved by quasi-Newton sweeps from the rows
    before (``_standard_batch._follow_shoot``: Broyden updates on the coarse grid, the
    fine-coarse offset extrapolated, chord steps on the fine grid). At every row of a smooth
    seeded path the returned base torsions, re-integrated on the fine grid, give tip torsions
    below the shooting tolerance, and the tips equal those of rows solved from scratch to
    1e-10 m, with the same flags. Catches a follow path that accepts an iterate short of the
    tolerance, takes the tip from another sweep than the returned one, or lands on another
    equilibrium."""
    from ctrplan.mechanics import solve_standard_batch
    from ctrplan.mechanics.grid import build_grid
    from ctrplan.mechanics.packed import pack_robot
    from ctrplan.mechanics.standard import _integrate

    robot = table2_robot()
    rng = np.random.default_rng(29)
    t = np.linspace(0.0, 1.0, 121)
    qs = np.column_stack([1.2 * np.sin(2 * np.pi * t) + 0.01 * rng.standard_normal(t.size),
                          0.8 + 0.6 * np.cos(3 * np.pi * t), -0.09 + 0.05 * t])
    configs = [robot.configuration(q) for q in qs]
    alpha = np.array([a for a, _ in configs])
    beta = np.array([b for _, b in configs])
    settings = ModelSettings(ds=3e-3)
    fol = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=True)
    ind = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=False)
    assert fol.certified.sum() > 100 and fol.converged.all()
    np.testing.assert_allclose(fol.tip_position, ind.tip_position, atol=1e-10)
    for flag in ("converged", "unstable", "n_equilibria", "certified"):
        np.testing.assert_array_equal(getattr(fol, flag), getattr(ind, flag))
    pk = pack_robot(robot)
    for k in range(len(qs)):
        g = build_grid(robot, beta[k], settings.ds, settings.refine_ratio, settings.refine_length)
        _, r, _, _, _, _, _ = _integrate(g.s, g.present, g.precurvature, pk.k_xy, pk.stiffness_ratio, alpha[k],
                                         fol.base_torsion[k], False, False)
        assert np.max(np.abs(r)) < settings.shooting_tol, k


def test_three_tube_sweeps_equal_the_general_integrator():
    """The three-tube RK4 sweeps (``standard._integrate3`` and, with the variational equations,
    ``_integrate3_sens``: the torsion ODE in the pairwise form sum_j b_ij sin(theta_i -
    theta_j), scalar state, coefficients recomputed only where the interval data change) give
    the final angles, torsions and sensitivities d(psi, sigma) / d sigma0 and every node record
    of the general n-tube loop (``_integrate_general``, which integrates
    u_xy x R_z(psi_i) uhat_i tube by tube) to rounding, on seeded random grids whose
    precurvatures point in all directions (not only along x) and change in runs of intervals,
    as do the tubes present (also without the precurvatures). Catches a sign or a pair swapped
    in the pairwise form or its Jacobian, a precurvature direction dropped, a tube that is
    absent but still twisted, and coefficients kept past a change of the interval data."""
    from ctrplan.mechanics.standard import _integrate, _integrate_general

    rng = np.random.default_rng(41)
    for _ in range(40):
        G = int(rng.integers(20, 160))
        s = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5e-3, 4e-3, G - 1))])
        cuts = np.sort(rng.choice(np.arange(1, G - 1), size=4, replace=False))
        present = np.empty((G - 1, 3), dtype=np.bool_)
        uh = np.empty((G - 1, 3, 2))
        for lo, hi in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [G - 1]])):
            pres = rng.random(3) < 0.7
            pres[rng.integers(3)] = True
            present[lo:hi] = pres
            ang = rng.uniform(-np.pi, np.pi, 3)
            mag = rng.uniform(0.0, 20.0, 3) * (rng.random(3) < 0.85)
            uh[lo:hi] = np.column_stack([mag * np.cos(ang), mag * np.sin(ang)])
            if lo > 0 and rng.random() < 0.5:    # tubes present change, precurvatures do not
                uh[lo:hi] = uh[lo - 1]
        kxy = rng.uniform(0.01, 0.1, 3)
        ratio = rng.uniform(1.0, 1.6, 3)
        psi0 = rng.uniform(-np.pi, np.pi, 3)
        sig0 = rng.normal(0.0, 5.0, 3)
        for with_sens in (False, True):
            fast = _integrate(s, present, uh, kxy, ratio, psi0, sig0, True, with_sens)
            general = _integrate_general(s, present, uh, kxy, ratio, psi0, sig0, True, with_sens)
            for i in range(7):
                assert fast[i].shape == general[i].shape
                scale = max(1.0, np.max(np.abs(general[i]), initial=0.0))
                np.testing.assert_allclose(fast[i], general[i], rtol=0, atol=1e-12 * scale)
            # without records: the same final state
            bare = _integrate(s, present, uh, kxy, ratio, psi0, sig0, False, with_sens)
            for i in range(4):
                np.testing.assert_array_equal(bare[i], fast[i])


def test_shooting_restarts_where_newton_stalls():
    """At these two joint values (seeded random draws of the batch benchmark) damped Newton from
    no twist stalls at a local minimum of the shooting residual with a singular Jacobian (the
    first on both grids; the second on the coarse grid, and on the fine grid it escapes only
    after 81 iterations, beyond the budget of 50), so neither converged before the restarts of
    ``standard._shoot`` (tip torsion residual 0.40 and 0.52 1/m). With the
    restarts both the single solve and the batch converge, to a stable equilibrium that the
    multistart search finds unique, whose tip is within 0.001 mm of the paper's uniform grid
    (which converged there without restarts)."""
    from ctrplan.mechanics import solve_standard_batch

    robot = table2_robot()
    qs = [[float.fromhex("0x1.f0b0b0a31a498p-2"), float.fromhex("-0x1.86e79d438254fp+1"),
           float.fromhex("-0x1.a48954f9c7525p-4")],
          [float.fromhex("0x1.141e5ba43a010p-2"), float.fromhex("-0x1.68e6226b7078fp+1"),
           float.fromhex("-0x1.a2a94e8be40f9p-4")]]
    configs = [robot.configuration(q) for q in qs]
    settings = ModelSettings(ds=3e-3)
    batch = solve_standard_batch(robot, np.array([a for a, _ in configs]), np.array([b for _, b in configs]),
                                 settings)
    assert np.all(batch.converged) and not np.any(batch.unstable)
    for k, (a, b) in enumerate(configs):
        st = solve_standard(robot, a, b, settings)
        assert st.diagnostics.converged and not st.diagnostics.unstable
        assert st.diagnostics.n_equilibria == 1
        uniform = solve_standard(robot, a, b, settings.replace(refine_ratio=1.0), check_stability=False)
        assert np.linalg.norm(st.tip_position - uniform.tip_position) < 1e-6
        np.testing.assert_allclose(batch.tip_position[k], st.tip_position, atol=1e-10)


# The 8x8x8 grid (alpha_2, alpha_3 in steps of 45 deg, beta_3 = -120.4 mm plus
# tube 3's curved exposure): its five configurations with three equilibria (found by the
# multistart search of the all-fine-grid reference) and unique neighbours of each.
_GRID8_MULTISTABLE = [(0, 180, 0.0), (0, 180, 12.343), (0, 180, 24.686), (90, 225, 0.0), (270, 135, 0.0)]
_GRID8_UNIQUE = [(0, 180, 37.029), (45, 225, 0.0), (0, 135, 0.0), (90, 180, 0.0), (270, 90, 0.0)]


@pytest.mark.parametrize("a2, a3, e", _GRID8_MULTISTABLE + _GRID8_UNIQUE)
def test_coarse_grid_multistart_finds_what_the_fine_search_finds(a2, a3, e):
    """The multistart search solves its restarts on the predictor's coarse grid and confirms
    only distinct candidates on the fine one. It must count the same equilibria as
    the frozen reference, which solves every restart on the fine grid: a search that misses a
    branch (e.g. compares a coarse solution with the wrong tolerance, or drops the confirmed
    candidates) fails on the multistable rows, one that invents branches on the unique rows.
    Single solver and batch both."""
    from ctrplan.mechanics import solve_standard_batch
    from ctrplan_reference import standard_reference

    robot = table2_robot()
    alpha = np.radians([0.0, a2, a3])
    beta = np.array([0.0, -0.017, -0.1204 + e * 1e-3])
    settings = ModelSettings()
    ref = standard_reference.solve_standard(robot, alpha, beta, settings)
    expected = 3 if (a2, a3, e) in _GRID8_MULTISTABLE else 1
    assert ref.diagnostics.n_equilibria == expected          # the premise, from the reference
    single = solve_standard(robot, alpha, beta, settings)
    batch = solve_standard_batch(robot, alpha[None], beta[None], settings, check_stability=True)
    assert single.diagnostics.n_equilibria == expected
    assert single.diagnostics.unstable == (expected > 1)
    if not batch.certified[0]:
        assert batch.n_equilibria[0] == expected
    assert bool(batch.unstable[0]) == (expected > 1)


def test_multistart_early_stop_keeps_a_nearby_equilibrium():
    """The multistart search abandons a coarse restart once it is converging to an equilibrium
    already found (``standard._RETURN_TWIST`` = 1e-2 rad, halving distance). At this seeded random
    configuration of the Table II robot (alpha_3 - alpha_2 = 143 deg, 132 mm of tube 3 exposed
    beyond tube 2; the closest case in the 9638 configurations checked) the second
    restart ends at a stable equilibrium only 0.124 rad (max_i |d sigma_i| L_i) from the first,
    approached slowly (0.63, 0.37, 0.23, 0.16, 0.13 rad): a stop radius above 0.124 rad without the
    contraction test would reject it as the known one and miss the instability. The search must
    still find three equilibria (from the search without the early stop) and flag the
    configuration, single solver and batch, in fewer Newton iterations than without the early
    stop (45; 41 with it)."""
    from ctrplan.mechanics import solve_standard_batch

    robot = table2_robot()
    alpha = np.array([0.0, float.fromhex("0x1.bf4a77d7fbea0p-1"), float.fromhex("-0x1.7489b4f794c28p+1")])
    beta = np.array([0.0, float.fromhex("-0x1.bd8b1abe4c920p-8"), float.fromhex("-0x1.0e5bfbca47a4ap-3")])
    settings = ModelSettings()
    single = solve_standard(robot, alpha, beta, settings)
    assert single.diagnostics.converged and single.diagnostics.unstable
    assert single.diagnostics.n_equilibria == 3
    batch = solve_standard_batch(robot, alpha[None], beta[None], settings, check_stability=True)
    assert not batch.certified[0]
    assert batch.n_equilibria[0] == 3 and batch.unstable[0]
    assert batch.iterations[0] < 45


def _path_reference(robot, alpha, beta, settings, guess, follow, check_stability):
    """Rows solved one ``solve_standard`` call at a time with the start rule of
    ``solve_standard_path``: (tips, converged, unstable, base torsions, reused, Newton
    iterations)."""
    K = len(alpha)
    tips = np.full((K, 3), np.nan)
    conv, unst, reused = np.zeros(K, bool), np.zeros(K, bool), np.zeros(K, bool)
    iterations = np.zeros(K, int)
    sig = np.full((K, robot.n_tubes), np.nan)
    prev, prev_start = None, None
    for k in range(K):
        if follow[k]:
            start = None if prev is None else prev.base_torsion
        else:
            start = None if np.isnan(guess[k, 0]) else guess[k]
        try:
            robot.check_configuration(alpha[k], beta[k])
        except JointLimitError:
            prev = prev_start = None
            continue
        same_start = follow[k] or (start is None and prev_start is None) or (
            start is not None and prev_start is not None and np.array_equal(start, prev_start))
        if (prev is not None and same_start and np.array_equal(alpha[k], prev.alpha)
                and np.array_equal(beta[k], prev.beta)):
            sol, reused[k] = prev, True
        else:
            sol = solve_standard(robot, alpha[k], beta[k], settings, initial_guess=start,
                                 check_stability=check_stability)
        prev_start = start
        prev = sol if sol.diagnostics.converged else None
        conv[k], unst[k] = sol.diagnostics.converged, sol.diagnostics.unstable
        iterations[k] = sol.diagnostics.iterations
        if conv[k]:
            tips[k], sig[k] = sol.tip_position, sol.base_torsion
    return tips, conv, unst, sig, reused, iterations


@pytest.mark.parametrize("check_stability", [False, True])
def test_path_equals_solve_standard_row_by_row(check_stability):
    """``solve_standard_path`` gives, row by row, what ``solve_standard`` gives started the way
    a caller following a path starts it: from the last converged row where ``follow`` is set
    (the long pair, whose branch past its bifurcation depends on the way there: up to 97 mm
    from what a cold start finds), from the given guess or from none elsewhere (the
    same Newton iterations, so the same starts); a repeated configuration with the same start is
    reused, and an impossible one breaks the chain."""
    from ctrplan.mechanics import solve_standard_path

    settings = ModelSettings(ds=3e-3)
    pair = _long_pair(1 / 0.08)      # bistable beyond about 2.7 rad: the branch depends on the way there
    th = np.concatenate([np.linspace(2.0, 3.6, 17), [3.6, 3.6], np.linspace(3.5, 2.4, 12)])
    alpha = np.array([pair.configuration([t])[0] for t in th])
    beta = np.array([pair.configuration([t])[1] for t in th])
    K = len(th)
    follow = np.ones(K, bool)
    follow[[0, 20]] = False
    guess = np.full((K, 2), np.nan)
    guess[20] = [0.0, 5.0]
    path = solve_standard_path(pair, alpha, beta, settings, initial_guess=guess, follow=follow,
                               check_stability=check_stability)
    tips, conv, unst, sig, reused, iterations = _path_reference(pair, alpha, beta, settings, guess, follow,
                                                                check_stability)
    np.testing.assert_allclose(path.tip_position[conv], tips[conv], rtol=0, atol=1e-12)
    np.testing.assert_allclose(path.base_torsion[conv], sig[conv], rtol=0, atol=1e-10)
    np.testing.assert_array_equal(path.converged, conv)
    np.testing.assert_array_equal(path.unstable, unst)
    np.testing.assert_array_equal(path.reused, reused)
    np.testing.assert_array_equal(path.iterations[~reused], iterations[~reused])
    assert reused.sum() >= 1
    cold = solve_standard_path(pair, alpha, beta, settings)
    assert np.max(np.linalg.norm(cold.tip_position - path.tip_position, axis=1)) > 0.05

    robot = table2_robot()
    rng = np.random.default_rng(11)
    qs = np.cumsum(rng.normal(0, [0.2, 0.2, 0.004], (12, 3)), axis=0) + [0.0, 0.0, -0.06]
    alpha = np.array([robot.configuration(q, check_limits=False)[0] for q in qs])
    beta = np.array([robot.configuration(q, check_limits=False)[1] for q in qs])
    beta[6, 2] = 0.01     # inner base in front of the outer bases: impossible
    follow = np.ones(12, bool)
    follow[0] = False
    guess = np.full((12, 3), np.nan)
    path = solve_standard_path(robot, alpha, beta, settings, follow=follow, check_stability=check_stability)
    tips, conv, unst, sig, reused, iterations = _path_reference(robot, alpha, beta, settings, guess, follow,
                                                                check_stability)
    assert not path.valid[6] and not path.converged[6]
    np.testing.assert_allclose(path.tip_position[conv], tips[conv], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(path.converged, conv)
    np.testing.assert_array_equal(path.iterations[conv], iterations[conv])
    with pytest.raises(ValueError, match="follow"):
        solve_standard_path(robot, alpha, beta, settings, follow=follow[:3])
