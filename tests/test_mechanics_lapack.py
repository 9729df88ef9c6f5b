"""LAPACK's LU (dgetrf/dgetrs) as called from the compiled contact kernels (``_lapack``)."""

import numpy as np
import pytest

from ctrplan.mechanics._lapack import PIVOT_DTYPE, lu_factor, lu_solve, lu_solve_matrix


@pytest.mark.parametrize("n", [1, 2, 7, 40, 71])
def test_lu_solves_equal_numpy(n):
    """Seeded random non-symmetric systems (the active block I + W_aa L_a is not symmetric
    with friction): one and several right-hand sides, C-ordered as the kernels pass them."""
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n)) + n * np.eye(n)
    b = rng.normal(size=n)
    B = rng.normal(size=(n, 5))
    LU = A.copy()
    piv = np.empty(n, dtype=PIVOT_DTYPE)
    assert lu_factor(LU, piv)
    x = b.copy()
    lu_solve(LU, piv, x)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-12, atol=1e-14)
    Xt = B.T.copy()   # B transposed, (k, n), C order (not a view of B: it is overwritten)
    lu_solve_matrix(LU, piv, Xt)
    np.testing.assert_allclose(Xt.T, np.linalg.solve(A, B), rtol=1e-12, atol=1e-14)


def test_lu_factor_reports_singular_and_non_finite_matrices():
    piv = np.empty(3, dtype=PIVOT_DTYPE)
    singular = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert not lu_factor(singular.copy(), piv)
    for bad in (np.nan, np.inf):
        A = np.eye(3)
        A[2, 0] = bad
        assert not lu_factor(A, piv)
    assert lu_factor(np.empty((0, 0)), np.empty(0, dtype=PIVOT_DTYPE))
