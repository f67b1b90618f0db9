"""The BLAS thread limit every driver runs under (the filter, the stepper, the smoothers)."""

import contextlib
import functools

import numpy as np

__all__ = ["limit_blas_threads", "check_blas_threads"]


def limit_blas_threads(n):
    """Context manager limiting the BLAS threads of numpy and scipy to ``n`` (None: leave as is).

    ``n`` >= 1 (ValueError otherwise, :func:`check_blas_threads`). The drivers run with one thread
    unless told otherwise: the filter's per-step matrices are a few hundred rows at most, and on a
    2-core machine a multi-threaded BLAS spends more time synchronising than computing.
    """
    if check_blas_threads(n) is None:
        return contextlib.nullcontext()
    return _blas_controller().limit(limits=int(n), user_api="blas")


def check_blas_threads(n):
    """``n`` if it is a positive integer (not a bool) or None (numpy's setting), else ValueError."""
    if n is not None and (isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1):
        raise ValueError(f"blas_threads must be a positive integer or None, got {n!r}")
    return n


# Looked up once per process: a lookup costs about as much as a filter step (1.5 ms), and the stepper
# enters the limit at every move.
@functools.cache
def _blas_controller():
    """The BLAS libraries loaded in this process (numpy's and scipy's), looked up once."""
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS before the lookup)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()
