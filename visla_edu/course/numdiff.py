"""Central-difference Jacobians: the checks' reference (``checks.reference_numerical_jacobian``).

Outside :mod:`visla_edu.course.checks` so the function object survives a reload of the checks, which
can then hide it from the student's code whatever name the student bound it to.
"""

import numpy as np

__all__ = ["central_jacobian"]


def central_jacobian(f, x, eps=1e-6):
    """Central-difference Jacobian of ``f: R^n -> R^m`` at ``x``, error ``O(eps^2)`` plus ``1e-16 |f| / eps``.

    ``f`` maps shape (n,) to (m,) (or any shape ``S``); ``x`` has shape (n,); ``eps`` is the step per coordinate.

    Returns
    -------
    ndarray, shape (m, n) (``S + (n,)`` in general)
        ``(f(x + eps e_i) - f(x - eps e_i)) / (2 eps)`` in column ``i``.
    """
    x = np.asarray(x, dtype=float)
    cols = [(np.asarray(f(x + dx), dtype=float) - np.asarray(f(x - dx), dtype=float)) / (2 * eps)
            for dx in eps * np.eye(x.size)]
    return np.stack(cols, axis=-1)
