"""The BLAS thread limit every driver runs under (the filter, the stepper, the smoothers)."""

import contextlib
import functools

import numpy as np

__all__ = ["limit_blas_threads", "check_blas_threads"]


def limit_blas_threads(n):
    """Context manager limiting the BLAS threads of numpy and scipy to ``n`` (None: leave as is).

    The filter's per-step matrices are a few hundred rows at most; on a 2-core machine a
    multi-threaded BLAS spends more time synchronising than computing, so the driver runs
    with one thread unless told otherwise (the ``blas_threads`` argument of
    :func:`run_filter`, :func:`iterate_filter` and :class:`visla_edu.stepper.Stepper`).
    The BLAS libraries are looked up once per process: a lookup costs about 1.5 ms, as much
    as a filter step, and the stepper enters the limit at every move.

    Parameters
    ----------
    n : int or None
        Threads, >= 1.
    """
    if check_blas_threads(n) is None:
        return contextlib.nullcontext()
    return _blas_controller().limit(limits=int(n), user_api="blas")


def check_blas_threads(n):
    """``n`` if it is a valid BLAS thread count: a positive integer, or None (numpy's setting).

    Parameters
    ----------
    n : int or None

    Returns
    -------
    int or None

    Raises
    ------
    ValueError
        Anything else (a bool, a float, zero or a negative number).
    """
    if n is not None and (isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1):
        raise ValueError(f"blas_threads must be a positive integer or None, got {n!r}")
    return n


@functools.cache
def _blas_controller():
    """The BLAS libraries loaded in this process (numpy's and scipy's), looked up once."""
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS before the lookup)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()
