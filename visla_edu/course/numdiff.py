"""Central-difference Jacobians: the reference a gradient checker is compared with.

Notebook 03 builds its own and compares; the exercise checks use this one (as
``checks.reference_numerical_jacobian``). It lives outside :mod:`visla_edu.course.checks` so that
the function object stays the same when a graded cell reloads the checks: a check can then hide
it from the student's code, whatever name the student bound it to.
"""

import numpy as np

__all__ = ["central_jacobian"]


def central_jacobian(f, x, eps=1e-6):
    """Central-difference Jacobian of ``f: R^n -> R^m`` at ``x``, error ``O(eps^2)`` plus ``1e-16 |f| / eps``.

    Parameters
    ----------
    f : callable
        Maps an array of shape (n,) to an array of shape (m,) (or any shape ``S``).
    x : array_like, shape (n,)
    eps : float
        Step along each coordinate.

    Returns
    -------
    ndarray, shape (m, n) (``S + (n,)`` in general)
        ``(f(x + eps e_i) - f(x - eps e_i)) / (2 eps)`` in column ``i``.
    """
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = eps
        cols.append((np.asarray(f(x + dx), dtype=float) - np.asarray(f(x - dx), dtype=float)) / (2 * eps))
    return np.stack(cols, axis=-1)
