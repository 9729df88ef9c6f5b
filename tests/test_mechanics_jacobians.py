"""Analytic J_p and J_omega (Appendix B of Ha et al. 2019) against finite differences."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from ctrplan.mechanics import ModelSettings, chain_jacobians, forward_kinematics, solve_standard
from ctrplan.mechanics._lie import (d_left_jacobian_ez, exp_so3, left_jacobian_so3, skew)
from ctrplan_reference.contact_reference import _Setup
from ctrplan.mechanics.discrete import TubeChain

from _robots import table2_robot


def _fd_jacobians(chain, u, eps=1e-6):
    N = chain.n_nodes
    R, p = forward_kinematics(chain, u)
    Jp = np.zeros((N, 3, N - 1, 3))
    Jw = np.zeros((N, 3, N - 1, 3))
    for k in range(N - 1):
        for c in range(3):
            du = np.zeros_like(u)
            du[k, c] = eps
            Rp, pp = forward_kinematics(chain, u + du)
            Rm, pm = forward_kinematics(chain, u - du)
            Jp[:, :, k, c] = (pp - pm) / (2 * eps)
            wp = Rotation.from_matrix(np.einsum("jba,jbc->jac", R, Rp)).as_rotvec()
            wm = Rotation.from_matrix(np.einsum("jba,jbc->jac", R, Rm)).as_rotvec()
            Jw[:, :, k, c] = (wp - wm) / (2 * eps)
    return Jp, Jw


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("curv_scale", [0.0, 5.0, 60.0])
def test_chain_jacobians_match_finite_differences(seed, curv_scale):
    rng = np.random.default_rng(seed)
    N = 10
    h = rng.uniform(0.5e-3, 3e-3, N - 1)
    chain = TubeChain(0, np.concatenate([[0.0], np.cumsum(h)]), h, np.zeros((N - 1, 3)),
                      np.ones((N - 1, 3)), alpha=rng.uniform(-3, 3), beta=-0.02)
    u = rng.normal(size=(N - 1, 3)) * curv_scale
    R, p = forward_kinematics(chain, u)
    Jp, Jw = chain_jacobians(chain, u, R, p)
    Jp_fd, Jw_fd = _fd_jacobians(chain, u)
    scale_p = max(np.abs(Jp_fd).max(), 1e-12)
    assert np.abs(Jp - Jp_fd).max() < 1e-6 * scale_p
    assert np.abs(Jw - Jw_fd).max() < 1e-6 * np.abs(Jw_fd).max()
    # proximal nodes do not depend on distal curvatures (Appendix B: blocks j <= k vanish)
    for j in range(N):
        assert np.all(Jp[j, :, j:, :] == 0.0)


def test_jacobians_at_a_real_linearization_point():
    """J_p and J_omega of each tube at the standard solution of the Table II robot."""
    robot = table2_robot()
    alpha, beta = robot.configuration([2.0, -1.0, -0.07])
    settings = ModelSettings(ds=5e-3)
    std = solve_standard(robot, alpha, beta, settings, check_stability=False)
    setup = _Setup(robot, std, None, np.zeros(2))
    for chain, u in zip(setup.chains, setup.u0):
        R, p = forward_kinematics(chain, u)
        Jp, Jw = chain_jacobians(chain, u, R, p)
        Jp_fd, Jw_fd = _fd_jacobians(chain, u)
        assert np.abs(Jp - Jp_fd).max() < 1e-6 * np.abs(Jp_fd).max()
        assert np.abs(Jw - Jw_fd).max() < 1e-6 * np.abs(Jw_fd).max()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3), st.sampled_from([1e-6, 1e-3, 0.09, 0.11, 1.0]))
def test_lie_closed_forms_and_series(vec, scale):
    """exp, V and d(V e_z)/dphi agree with expm and finite differences on both sides of the
    series threshold (seeded property test)."""
    phi = np.asarray(vec) * scale
    np.testing.assert_allclose(exp_so3(phi), expm(skew(phi)), atol=1e-13)
    # V is the integral of exp along the segment: V = int_0^1 exp(t [phi]x) dt
    ts = np.linspace(0.0, 1.0, 401)
    V_num = np.trapezoid(np.array([expm(skew(t * phi)) for t in ts]), ts, axis=0)
    np.testing.assert_allclose(left_jacobian_so3(phi), V_num, atol=1e-5)
    eps = 1e-6
    M_fd = np.column_stack([(left_jacobian_so3(phi + eps * e)[:, 2] - left_jacobian_so3(phi - eps * e)[:, 2]) / (2 * eps)
                            for e in np.eye(3)])
    np.testing.assert_allclose(d_left_jacobian_ez(phi), M_fd, atol=2e-9)
