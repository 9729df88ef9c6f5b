"""LAPACK's LU factorization (``dgetrf``/``dgetrs``) callable from numba-compiled kernels.

The contact solver factors one dense system per line-search trial (the active block of
Appendix A, size 2 x active contacts, 40-110) and one Newton matrix per iteration. A plain
compiled LU runs at about 4 GFlop/s there; LAPACK's blocked one (OpenBLAS, shipped with scipy)
is 2.1-2.5x faster at those sizes (measured 10.3 vs 23.2 us at n = 52, 19.5 vs 46.4 us at
n = 70, one core, against the better of two compiled variants; docs/mechanics.md Sec. 10).

The routines are scipy's own (``scipy.linalg.cython_lapack``), bound by name into LLVM's symbol
table, so the kernels that call them stay cacheable (``cache=True``): a cached kernel refers to
the symbol name, which is bound again at every import before any kernel is loaded. The symbol
names carry the Fortran integer width scipy was built with (LP64 or ILP64), so a cache written
against one width fails to link against the other instead of passing the wrong integers.

Arrays are C-ordered. LAPACK reads a C-ordered (n, n) array as the transpose, so
:func:`lu_factor` factors A^T and the solves use ``trans = 'T'``; a matrix right-hand side B of
shape (n, k) is passed as its transpose, a C-ordered (k, n) array.
"""

from __future__ import annotations

import llvmlite.binding as _llvm
import numpy as np
from numba import njit, types
from numba.extending import get_cython_function_address


def _scipy_lapack_is_ilp64():
    """Whether scipy's cython_lapack takes 64-bit Fortran integers (scipy's build record)."""
    try:
        from scipy.__config__ import CONFIG
        return bool(CONFIG["Build Dependencies"]["blas"]["cython blas ilp64"])
    except (ImportError, KeyError, TypeError):
        return False   # builds without that record are all LP64


_ILP64 = _scipy_lapack_is_ilp64()
PIVOT_DTYPE = np.int64 if _ILP64 else np.int32
_INT = types.int64 if _ILP64 else types.int32
_SUFFIX = "ilp64" if _ILP64 else "lp64"

_ip = types.CPointer(_INT)
_dp = types.CPointer(types.float64)
_cp = types.CPointer(types.uint8)
_llvm.add_symbol(f"ctrplan_dgetrf_{_SUFFIX}",
                 get_cython_function_address("scipy.linalg.cython_lapack", "dgetrf"))
_llvm.add_symbol(f"ctrplan_dgetrs_{_SUFFIX}",
                 get_cython_function_address("scipy.linalg.cython_lapack", "dgetrs"))
# dgetrf(m, n, a, lda, ipiv, info); dgetrs(trans, n, nrhs, a, lda, ipiv, b, ldb, info)
_dgetrf = types.ExternalFunction(f"ctrplan_dgetrf_{_SUFFIX}", types.void(_ip, _ip, _dp, _ip, _ip, _ip))
_dgetrs = types.ExternalFunction(f"ctrplan_dgetrs_{_SUFFIX}",
                                 types.void(_cp, _ip, _ip, _dp, _ip, _ip, _dp, _ip, _ip))


@njit(cache=True)
def lu_factor(A, piv):
    """LU factors with partial pivoting of a C-ordered square matrix, in place.

    Parameters
    ----------
    A : ndarray, shape (n, n), C-ordered
        Overwritten by the factors (of A^T in LAPACK's column-major view; only
        :func:`lu_solve` and :func:`lu_solve_matrix` read them).
    piv : ndarray of PIVOT_DTYPE, shape (n,)
        Pivot indices, written.

    Returns
    -------
    bool
        False if A has a non-finite entry or is exactly singular (then A and piv hold garbage).
    """
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            if not np.isfinite(A[i, j]):
                return False
    if n == 0:
        return True
    dims = np.full(1, n, dtype=PIVOT_DTYPE)
    info = np.zeros(1, dtype=PIVOT_DTYPE)
    _dgetrf(dims.ctypes, dims.ctypes, A.ctypes, dims.ctypes, piv.ctypes, info.ctypes)
    return info[0] == 0


@njit(cache=True)
def _getrs(LU, piv, b, nrhs):
    if LU.shape[0] == 0 or nrhs == 0:
        return
    trans = np.full(1, ord("T"), dtype=np.uint8)
    dims = np.full(1, LU.shape[0], dtype=PIVOT_DTYPE)
    k = np.full(1, nrhs, dtype=PIVOT_DTYPE)
    info = np.zeros(1, dtype=PIVOT_DTYPE)
    _dgetrs(trans.ctypes, dims.ctypes, k.ctypes, LU.ctypes, dims.ctypes, piv.ctypes, b.ctypes,
            dims.ctypes, info.ctypes)


@njit(cache=True)
def lu_solve(LU, piv, b):
    """Solve A x = b in place with the factors of :func:`lu_factor`.

    Parameters
    ----------
    LU, piv : from :func:`lu_factor`
    b : ndarray, shape (n,), contiguous
        Right-hand side, overwritten by x.
    """
    _getrs(LU, piv, b, 1)


@njit(cache=True)
def lu_solve_matrix(LU, piv, Bt):
    """Solve A X = B in place for k right-hand sides with the factors of :func:`lu_factor`.

    Parameters
    ----------
    LU, piv : from :func:`lu_factor`
    Bt : ndarray, shape (k, n), C-ordered
        B transposed, overwritten by X transposed.
    """
    _getrs(LU, piv, Bt, Bt.shape[0])
