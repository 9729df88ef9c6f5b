"""Shared test set-up: single-threaded BLAS (small dense solves are faster that way on the
project's 2-core machines, and parallel tests do not oversubscribe)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

try:  # also applies when numpy was imported before this file
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
except ImportError:  # pragma: no cover
    pass
