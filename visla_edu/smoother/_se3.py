"""The SE(3) right Jacobian and its inverse (twists ``x = [rho; phi]``, linear first).

For a small twist ``d``::

    exp(x + d) ~ exp(x) exp(J_r(x) d)        log(exp(x) exp(d)) ~ x + J_r(x)^{-1} d

In block form, with ``A = J_r^{SO3}(phi)`` and ``Q_r(rho, phi) = Q_l(-rho, -phi)``::

    J_r(x)      = [[A, Q_r], [0, A]]
    J_r(x)^{-1} = [[A^{-1}, -A^{-1} Q_r A^{-1}], [0, A^{-1}]]

    A      = I - B phi^ + C phi^2,         B = (1 - cos t) / t^2,  C = (t - sin t) / t^3
    A^{-1} = I + phi^ / 2 + D phi^2,       D = 1 / t^2 - (1 + cos t) / (2 t sin t)
    Q_l(rho, phi) = rho^ / 2 + c1 (phi^ rho^ + rho^ phi^ + phi^ rho^ phi^)
                  + c2 (phi^2 rho^ + rho^ phi^2 - 3 phi^ rho^ phi^)
                  + c3 (phi^ rho^ phi^2 + phi^2 rho^ phi^)
    c1 = (t - sin t) / t^3,  c2 = (t^2 + 2 cos t - 2) / (2 t^4),  c3 = (2 t - 3 sin t + t cos t) / (2 t^5)

with ``t = |phi|``. Below :data:`visla_edu.lie.SMALL_ANGLE` every coefficient is a Taylor
series (the closed forms lose their digits by cancellation). The closed forms hold for
``t < pi``; the smoother only evaluates them on motion residuals, which are small.
"""

import numpy as np

from visla_edu import lie

__all__ = ["so3_right_jacobian", "so3_right_jacobian_inv", "se3_right_jacobian", "se3_right_jacobian_inv"]


def _coefficient(theta, closed, series):
    """``closed(theta)`` above SMALL_ANGLE, ``series(theta^2)`` below (no 0/0 in either branch)."""
    small = theta < lie.SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    return np.where(small, series(theta**2), closed(safe))


def _as_twists(x, name):
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != 6:
        raise ValueError(f"{name}: expected twists of shape (..., 6) as [rho; phi], got {x.shape}")
    return x


def _as_rotation_vectors(phi, name):
    phi = np.asarray(phi, dtype=float)
    if phi.ndim == 0 or phi.shape[-1] != 3:
        raise ValueError(f"{name}: expected rotation vectors of shape (..., 3), got {phi.shape}")
    return phi


def so3_right_jacobian(phi):
    """SO(3) right Jacobian ``I - B phi^ + C phi^2``, shape (..., 3, 3), for ``phi`` (..., 3).

    ``B = (1 - cos t) / t^2``, ``C = (t - sin t) / t^3``, ``t = |phi|`` (Taylor series below
    :data:`visla_edu.lie.SMALL_ANGLE`); ``exp((phi + d)^) ~ exp(phi^) exp((J_r(phi) d)^)``.

    Parameters
    ----------
    phi : array_like, shape (..., 3)
        Rotation vectors (rad).

    Returns
    -------
    ndarray, shape (..., 3, 3)

    Raises
    ------
    ValueError
        ``phi`` does not have shape (..., 3).
    """
    phi = _as_rotation_vectors(phi, "so3_right_jacobian")
    theta = np.linalg.norm(phi, axis=-1)
    B = _coefficient(theta, lambda t: (1 - np.cos(t)) / t**2,
                     lambda t2: 0.5 - t2 / 24 + t2**2 / 720 - t2**3 / 40320)[..., None, None]
    C = _coefficient(theta, lambda t: (t - np.sin(t)) / t**3,
                     lambda t2: 1 / 6 - t2 / 120 + t2**2 / 5040 - t2**3 / 362880)[..., None, None]
    W = lie.hat(phi)
    return np.eye(3) - B * W + C * (W @ W)


def so3_right_jacobian_inv(phi):
    """Inverse SO(3) right Jacobian ``I + phi^ / 2 + D phi^2``, shape (..., 3, 3).

    ``D = 1 / t^2 - (1 + cos t) / (2 t sin t)``, ``t = |phi|`` (Taylor series below
    :data:`visla_edu.lie.SMALL_ANGLE`); the closed form holds for ``t < pi``.

    Parameters
    ----------
    phi : array_like, shape (..., 3)
        Rotation vectors (rad), ``|phi| < pi``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        The inverse of :func:`so3_right_jacobian`.

    Raises
    ------
    ValueError
        ``phi`` does not have shape (..., 3).
    """
    phi = _as_rotation_vectors(phi, "so3_right_jacobian_inv")
    theta = np.linalg.norm(phi, axis=-1)
    D = _coefficient(theta, lambda t: 1 / t**2 - (1 + np.cos(t)) / (2 * t * np.sin(t)),
                     lambda t2: 1 / 12 + t2 / 720 + t2**2 / 30240 + t2**3 / 1209600)[..., None, None]
    W = lie.hat(phi)
    return np.eye(3) + 0.5 * W + D * (W @ W)


def _q_right(x):
    """``Q_r(rho, phi) = Q_l(-rho, -phi)``, shape (..., 3, 3)."""
    theta = np.linalg.norm(x[..., 3:], axis=-1)
    c1 = _coefficient(theta, lambda t: (t - np.sin(t)) / t**3,
                      lambda t2: 1 / 6 - t2 / 120 + t2**2 / 5040 - t2**3 / 362880)
    c2 = _coefficient(theta, lambda t: (t**2 + 2 * np.cos(t) - 2) / (2 * t**4),
                      lambda t2: 1 / 24 - t2 / 720 + t2**2 / 40320 - t2**3 / 3628800)
    c3 = _coefficient(theta, lambda t: (2 * t - 3 * np.sin(t) + t * np.cos(t)) / (2 * t**5),
                      lambda t2: 1 / 120 - t2 / 2520 + t2**2 / 120960 - t2**3 / 9979200)
    P = lie.hat(-x[..., 3:])
    R = lie.hat(-x[..., :3])
    PR, RP = P @ R, R @ P
    PRP = PR @ P
    return (0.5 * R + c1[..., None, None] * (PR + RP + PRP)
            + c2[..., None, None] * (P @ PR + RP @ P - 3 * PRP)
            + c3[..., None, None] * (PRP @ P + P @ PRP))


def se3_right_jacobian(x):
    """SE(3) right Jacobian ``[[A, Q_r], [0, A]]`` of twists ``x = [rho; phi]``.

    Parameters
    ----------
    x : array_like, shape (..., 6)

    Returns
    -------
    ndarray, shape (..., 6, 6)
        ``exp(x + d) ~ exp(x) exp(J_r(x) d)``.
    """
    x = _as_twists(x, "se3_right_jacobian")
    A = so3_right_jacobian(x[..., 3:])
    J = np.zeros(x.shape[:-1] + (6, 6))
    J[..., :3, :3] = A
    J[..., 3:, 3:] = A
    J[..., :3, 3:] = _q_right(x)
    return J


def se3_right_jacobian_inv(x):
    """Inverse SE(3) right Jacobian ``[[A^-1, -A^-1 Q_r A^-1], [0, A^-1]]``.

    Parameters
    ----------
    x : array_like, shape (..., 6)
        Twists ``[rho; phi]`` with ``|phi| < pi``.

    Returns
    -------
    ndarray, shape (..., 6, 6)
        ``log(exp(x) exp(d)) ~ x + J_r(x)^{-1} d``.
    """
    x = _as_twists(x, "se3_right_jacobian_inv")
    A_inv = so3_right_jacobian_inv(x[..., 3:])
    J = np.zeros(x.shape[:-1] + (6, 6))
    J[..., :3, :3] = A_inv
    J[..., 3:, 3:] = A_inv
    J[..., :3, 3:] = -A_inv @ _q_right(x) @ A_inv
    return J
