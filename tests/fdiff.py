"""Finite differences shared by the Jacobian tests."""

import numpy as np


def fd_jacobian(f, x, h):
    """Five-point central difference ``df/dx``; output shape ``f(x).shape + (len(x),)``."""
    x = np.asarray(x, float)
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((f(x - 2 * e) - 8 * f(x - e) + 8 * f(x + e) - f(x + 2 * e)) / (12 * h))
    return np.stack(cols, axis=-1)
