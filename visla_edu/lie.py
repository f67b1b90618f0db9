"""SO(3) and SE(3) kinematics: hat/vee, exponential and logarithm maps, adjoints, Jacobians.

Conventions (used everywhere in visla-edu)
-------------------------------------------
* A twist is ``u = [v; w]`` with the **linear velocity first** and the angular
  velocity second, shape ``(6,)``.
* ``twist_hat(u) = [[hat(w), v], [0, 0]]`` (4x4).
* ``curly_hat(u) = [[hat(w), hat(v)], [0, hat(w)]]`` (6x6), so that
  ``expm(curly_hat(u)) == adjoint(se3_exp(u))``.
* ``odot(s) = [[s4 * I, -hat(s_xyz)], [0, 0]]`` (4x6) for a homogeneous point
  ``s = [s_xyz; s4]``, so that ``twist_hat(u) @ s == odot(s) @ u``.

Perturbations and Jacobians (stated here once; every module follows it)
------------------------------------------------------------------------
* Poses are perturbed on the **right**: ``T = mu exp(twist_hat(delta))``, ``delta = [v; w]``
  (linear first) in the body frame of ``T``; points and landmarks additively,
  ``m = mu_m + delta_m``.
* A Jacobian is named ``J_out_in`` (manif's convention): the derivative of ``out`` with respect
  to the perturbation of ``in``, one row per entry of ``out``. E.g. ``J_z_pose`` (4, 6): stereo
  pixels ``z`` with respect to the right perturbation of ``world_T_imu``; ``J_z_landmark``
  (4, 3); ``J_e_prev`` (6, 6): a motion residual with respect to the earlier pose.
* The **right Jacobian** ``J_r(x)`` of SO(3) or SE(3) (twist ``x``):
  ``exp(x + d) ~ exp(x) exp(J_r(x) d)`` and ``log(exp(x) exp(d)) ~ x + J_r(x)^{-1} d`` to first
  order in ``d``; the **left Jacobian** is ``J_l(x) = J_r(-x)``, ``exp(x + d) ~ exp(J_l(x) d)
  exp(x)``. SO(3): ``J_l(w) = I + B hat(w) + C hat(w)^2`` (the ``V`` of :func:`se3_exp`),
  ``J_r(w) = I - B hat(w) + C hat(w)^2``, ``J_r(w)^{-1} = I + hat(w) / 2 + D hat(w)^2``.
  SE(3), ``x = [rho; phi]``: ``J_r(x) = [[J_r(phi), Q_r], [0, J_r(phi)]]`` and
  ``J_r(x)^{-1} = [[J_r(phi)^{-1}, -J_r(phi)^{-1} Q_r J_r(phi)^{-1}], [0, J_r(phi)^{-1}]]`` with
  ``Q_r(rho, phi) = Q_l(-rho, -phi)``::

      Q_l(rho, phi) = rho^ / 2 + c1 (phi^ rho^ + rho^ phi^ + phi^ rho^ phi^)
                    + c2 (phi^2 rho^ + rho^ phi^2 - 3 phi^ rho^ phi^)
                    + c3 (phi^ rho^ phi^2 + phi^2 rho^ phi^)

  (Barfoot, *State Estimation for Robotics*, ch. 7), ``t = |phi|``, ``B = (1 - cos t) / t^2``,
  ``C = c1 = (t - sin t) / t^3``, ``D = (1 - t sin t / (2 (1 - cos t))) / t^2``,
  ``c2 = (t^2 + 2 cos t - 2) / (2 t^4)``, ``c3 = (2 t - 3 sin t + t cos t) / (2 t^5)``. The
  closed forms of the inverse hold for ``t < pi``.

Every function takes one input or a stack with any leading batch dimensions (``in -> out``
shapes in each docstring). Below ``SMALL_ANGLE`` rad the coefficients use Taylor series, and near
``pi`` the SO(3) log takes its axis from the symmetric part of ``R``: every map is accurate to
about 1e-12 over the whole range.
"""

import numpy as np

__all__ = [
    "hat",
    "vee",
    "so3_exp",
    "so3_log",
    "so3_left_jacobian",
    "so3_right_jacobian",
    "so3_right_jacobian_inv",
    "twist_hat",
    "twist_vee",
    "se3_exp",
    "se3_log",
    "se3_right_jacobian",
    "se3_right_jacobian_inv",
    "se3_inv",
    "adjoint",
    "curly_hat",
    "odot",
    "SMALL_ANGLE",
]

#: Below this rotation angle (rad) the exp/log coefficients use Taylor series.
SMALL_ANGLE = 0.1
#: Above ``pi - NEAR_PI`` the SO(3) log takes its axis from the symmetric part of R.
NEAR_PI = 0.1


def _as_vectors(x, length, name):
    """Return ``x`` as a float array whose last axis has ``length`` entries."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != length:
        raise ValueError(f"{name}: expected shape (..., {length}), got {x.shape}")
    return x


def _as_matrices(x, rows, cols, name):
    """Return ``x`` as a float array whose last two axes are ``rows x cols``."""
    x = np.asarray(x, dtype=float)
    if x.ndim < 2 or x.shape[-2:] != (rows, cols):
        raise ValueError(f"{name}: expected shape (..., {rows}, {cols}), got {x.shape}")
    return x


def hat(w):
    """Skew-symmetric matrix of a 3-vector, (..., 3) -> (..., 3, 3): ``hat(w) @ x == cross(w, x)``.

    ``hat(w) = [[0, -w3, w2], [w3, 0, -w1], [-w2, w1, 0]]``.
    """
    w = _as_vectors(w, 3, "hat")
    W = np.zeros(w.shape[:-1] + (3, 3))
    W[..., 0, 1] = -w[..., 2]
    W[..., 0, 2] = w[..., 1]
    W[..., 1, 0] = w[..., 2]
    W[..., 1, 2] = -w[..., 0]
    W[..., 2, 0] = -w[..., 1]
    W[..., 2, 1] = w[..., 0]
    return W


def vee(W):
    """Inverse of :func:`hat`, (..., 3, 3) -> (..., 3), or of :func:`twist_hat`, (..., 4, 4) -> (..., 6) ``[v; w]``."""
    W = np.asarray(W, dtype=float)
    if W.ndim >= 2 and W.shape[-2:] == (4, 4):
        return twist_vee(W)
    W = _as_matrices(W, 3, 3, "vee")
    return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)


def twist_hat(u):
    """4x4 matrix of a twist ``u = [v; w]``, (..., 6) -> (..., 4, 4): ``[[hat(w), v], [0, 0]]``."""
    u = _as_vectors(u, 6, "twist_hat")
    U = np.zeros(u.shape[:-1] + (4, 4))
    U[..., :3, :3] = hat(u[..., 3:])
    U[..., :3, 3] = u[..., :3]
    return U


def twist_vee(U):
    """Inverse of :func:`twist_hat`, (..., 4, 4) -> (..., 6): ``[[hat(w), v], [0, 0]] -> [v; w]``.

    Only ``U[..., :3, 3]`` and ``U32, U13, U21`` are read; the rest of ``U`` is not checked.
    """
    U = _as_matrices(U, 4, 4, "twist_vee")
    return np.concatenate([U[..., :3, 3], vee(U[..., :3, :3])], axis=-1)


def _angle(w):
    """Rotation angle ``|w|`` and its square, shape (...,)."""
    theta2 = np.einsum("...i,...i->...", w, w)
    return np.sqrt(theta2), theta2


def _series_or_closed(theta, theta2, closed, series):
    """Evaluate ``closed(theta)`` for large angles and ``series(theta2)`` below SMALL_ANGLE."""
    small = theta < SMALL_ANGLE
    safe = np.where(small, 1.0, theta)  # avoid 0/0 in the branch that is not used
    return np.where(small, series(theta2), closed(safe))


def _sin_over_theta(theta, theta2):
    """``A = sin(theta) / theta``."""
    return _series_or_closed(
        theta, theta2, lambda t: np.sin(t) / t,
        lambda t2: 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72))),
    )


def _one_minus_cos_over_theta2(theta, theta2):
    """``B = (1 - cos(theta)) / theta^2``."""
    return _series_or_closed(
        theta, theta2, lambda t: (1 - np.cos(t)) / t**2,
        lambda t2: 0.5 * (1 - t2 / 12 * (1 - t2 / 30 * (1 - t2 / 56 * (1 - t2 / 90)))),
    )


def _theta_minus_sin_over_theta3(theta, theta2):
    """``C = (theta - sin(theta)) / theta^3``."""
    return _series_or_closed(
        theta, theta2, lambda t: (t - np.sin(t)) / t**3,
        lambda t2: (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72 * (1 - t2 / 110)))) / 6,
    )


def _inverse_jacobian_coefficient(theta, theta2):
    """``D = (1 - t sin t / (2 (1 - cos t))) / t^2`` of ``J_r(w)^{-1}`` and of ``V^{-1}`` in :func:`se3_log`."""
    return _series_or_closed(
        theta, theta2,
        lambda t: (1 - t * np.sin(t) / (2 * (1 - np.cos(t)))) / t**2,
        lambda t2: 1 / 12 + t2 / 720 + t2**2 / 30240 + t2**3 / 1209600,
    )


def _q_coefficients(theta, theta2):
    """``c2 = (t^2 + 2 cos t - 2) / (2 t^4)`` and ``c3 = (2 t - 3 sin t + t cos t) / (2 t^5)`` of ``Q_l``."""
    c2 = _series_or_closed(theta, theta2, lambda t: (t**2 + 2 * np.cos(t) - 2) / (2 * t**4),
                           lambda t2: 1 / 24 - t2 / 720 + t2**2 / 40320 - t2**3 / 3628800)
    c3 = _series_or_closed(theta, theta2, lambda t: (2 * t - 3 * np.sin(t) + t * np.cos(t)) / (2 * t**5),
                           lambda t2: 1 / 120 - t2 / 2520 + t2**2 / 120960 - t2**3 / 9979200)
    return c2, c3


def so3_exp(w):
    """Rodrigues' formula: ``exp(hat(w)) = I + A hat(w) + B hat(w)^2``, ``A = sin(t) / t``, ``B`` as in the module.

    ``w`` (..., 3): rotation vector (axis times angle, rad) -> (..., 3, 3).
    """
    w = _as_vectors(w, 3, "so3_exp")
    theta, theta2 = _angle(w)
    A = _sin_over_theta(theta, theta2)[..., None, None]
    B = _one_minus_cos_over_theta2(theta, theta2)[..., None, None]
    W = hat(w)
    return np.eye(3) + A * W + B * (W @ W)


def so3_left_jacobian(w):
    """Left Jacobian of SO(3): ``J_l(w) = I + B hat(w) + C hat(w)^2``, the ``V`` of :func:`se3_exp`.

    (..., 3) -> (..., 3, 3).
    """
    w = _as_vectors(w, 3, "so3_left_jacobian")
    theta, theta2 = _angle(w)
    B = _one_minus_cos_over_theta2(theta, theta2)[..., None, None]
    C = _theta_minus_sin_over_theta3(theta, theta2)[..., None, None]
    W = hat(w)
    return np.eye(3) + B * W + C * (W @ W)


def so3_right_jacobian(w):
    """Right Jacobian of SO(3): ``J_r(w) = J_l(-w) = I - B hat(w) + C hat(w)^2``, (..., 3) -> (..., 3, 3)."""
    return so3_left_jacobian(-_as_vectors(w, 3, "so3_right_jacobian"))


def so3_right_jacobian_inv(w):
    """Inverse right Jacobian of SO(3): ``J_r(w)^{-1} = I + hat(w) / 2 + D hat(w)^2``, for ``|w| < pi``.

    (..., 3) -> (..., 3, 3).
    """
    w = _as_vectors(w, 3, "so3_right_jacobian_inv")
    D = _inverse_jacobian_coefficient(*_angle(w))[..., None, None]
    W = hat(w)
    return np.eye(3) + 0.5 * W + D * (W @ W)


def so3_log(R):
    """Rotation vector of a rotation matrix, (..., 3, 3) -> (..., 3), with angle in ``[0, pi]``.

    The angle is ``atan2(|s|, c)`` with ``s = vee(R - R^T) / 2 = sin(t) a`` and
    ``c = (trace(R) - 1) / 2 = cos(t)``. Near ``pi`` the axis ``a`` comes from the
    symmetric part ``(R + R^T) / 2 - c I = (1 - c) a a^T`` instead of ``s``.
    """
    R = _as_matrices(R, 3, 3, "so3_log")
    s = 0.5 * vee(R - np.swapaxes(R, -1, -2))
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1)
    sin_t = np.linalg.norm(s, axis=-1)
    theta = np.arctan2(sin_t, c)
    theta2 = theta**2
    # Generic and small angles: w = (theta / sin(theta)) s.
    w = s / _sin_over_theta(theta, theta2)[..., None]
    near_pi = theta > np.pi - NEAR_PI
    if np.any(near_pi):
        # Only on the near-pi entries: for small angles the symmetric part is ~0 and
        # normalising it would raise 0/0 RuntimeWarnings in mixed batches.
        w[near_pi] = _near_pi_log(R[near_pi], s[near_pi], c[near_pi], theta[near_pi])
    return w


def _near_pi_log(R, s, c, theta):
    """Rotation vector from the symmetric part of R (accurate near pi)."""
    S = 0.5 * (R + np.swapaxes(R, -1, -2)) - c[..., None, None] * np.eye(3)
    diag = np.diagonal(S, axis1=-2, axis2=-1)
    k = np.argmax(diag, axis=-1)
    col = np.take_along_axis(S, k[..., None, None], axis=-1)[..., 0]
    axis = col / np.linalg.norm(col, axis=-1, keepdims=True)
    sign = np.where(np.einsum("...i,...i->...", axis, s) < 0, -1.0, 1.0)
    return (sign * theta)[..., None] * axis


def se3_exp(u):
    """SE(3) exponential of a twist ``u = [v; w]`` in closed form, (..., 6) -> (..., 4, 4).

    ``exp(twist_hat(u)) = [[R, V v], [0, 1]]`` with ``R = so3_exp(w)`` and ``V = J_l(w)``
    (:func:`so3_left_jacobian`).
    """
    u = _as_vectors(u, 6, "se3_exp")
    v, w = u[..., :3], u[..., 3:]
    theta, theta2 = _angle(w)
    A = _sin_over_theta(theta, theta2)[..., None, None]
    B = _one_minus_cos_over_theta2(theta, theta2)[..., None, None]
    C = _theta_minus_sin_over_theta3(theta, theta2)[..., None, None]
    W = hat(w)
    W2 = W @ W
    T = np.zeros(u.shape[:-1] + (4, 4))
    T[..., :3, :3] = np.eye(3) + A * W + B * W2
    V = np.eye(3) + B * W + C * W2
    T[..., :3, 3] = np.einsum("...ij,...j->...i", V, v)
    T[..., 3, 3] = 1.0
    return T


def se3_log(T):
    """SE(3) logarithm: the twist ``u = [v; w]`` with ``se3_exp(u) == T``, (..., 4, 4) -> (..., 6).

    ``w = so3_log(R)`` and ``v = V^{-1} p`` with ``V^{-1} = J_r(-w)^{-1} = I - hat(w)/2 + D hat(w)^2`` (``D`` as
    in the module docstring).
    """
    T = _as_matrices(T, 4, 4, "se3_log")
    w = so3_log(T[..., :3, :3])
    v = np.einsum("...ij,...j->...i", so3_right_jacobian_inv(-w), T[..., :3, 3])
    return np.concatenate([v, w], axis=-1)


def _upper_6x6(diagonal, upper):
    """The 6x6 matrix ``[[diagonal, upper], [0, diagonal]]`` of 3x3 blocks (..., 3, 3) -> (..., 6, 6)."""
    out = np.zeros(diagonal.shape[:-2] + (6, 6))
    out[..., :3, :3] = out[..., 3:, 3:] = diagonal
    out[..., :3, 3:] = upper
    return out


def _q_right(x):
    """``Q_r(rho, phi) = Q_l(-rho, -phi)`` of twists ``x = [rho; phi]`` (..., 6), shape (..., 3, 3)."""
    theta, theta2 = _angle(x[..., 3:])
    c1 = _theta_minus_sin_over_theta3(theta, theta2)[..., None, None]
    c2, c3 = (c[..., None, None] for c in _q_coefficients(theta, theta2))
    P, R = hat(-x[..., 3:]), hat(-x[..., :3])
    PR, RP = P @ R, R @ P
    PRP = PR @ P
    return 0.5 * R + c1 * (PR + RP + PRP) + c2 * (P @ PR + RP @ P - 3 * PRP) + c3 * (PRP @ P + P @ PRP)


def se3_right_jacobian(x):
    """Right Jacobian of SE(3): ``J_r(x) = [[J_r(phi), Q_r], [0, J_r(phi)]]`` for ``x = [rho; phi]``.

    (..., 6) -> (..., 6, 6).
    """
    x = _as_vectors(x, 6, "se3_right_jacobian")
    return _upper_6x6(so3_right_jacobian(x[..., 3:]), _q_right(x))


def se3_right_jacobian_inv(x):
    """Inverse right Jacobian of SE(3): ``[[A^{-1}, -A^{-1} Q_r A^{-1}], [0, A^{-1}]]``, ``A = J_r(phi)``.

    Twists ``x = [rho; phi]`` (..., 6) with ``|phi| < pi`` -> (..., 6, 6).
    """
    x = _as_vectors(x, 6, "se3_right_jacobian_inv")
    A_inv = so3_right_jacobian_inv(x[..., 3:])
    return _upper_6x6(A_inv, -A_inv @ _q_right(x) @ A_inv)


def se3_inv(T):
    """Inverse of a rigid transform, (..., 4, 4) -> (..., 4, 4): ``[[R^T, -R^T p], [0, 1]]``."""
    T = _as_matrices(T, 4, 4, "se3_inv")
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros(T.shape)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def adjoint(T):
    """Adjoint of a pose for twists ``[v; w]``, (..., 4, 4) -> (..., 6, 6): ``[[R, hat(p) R], [0, R]]``.

    Satisfies ``T twist_hat(u) T^{-1} = twist_hat(adjoint(T) u)``.
    """
    T = _as_matrices(T, 4, 4, "adjoint")
    R = T[..., :3, :3]
    return _upper_6x6(R, hat(T[..., :3, 3]) @ R)


def curly_hat(u):
    """The 6x6 ``ad`` matrix of a twist ``u = [v; w]``, (..., 6) -> (..., 6, 6): ``[[hat(w), hat(v)], [0, hat(w)]]``."""
    u = _as_vectors(u, 6, "curly_hat")
    return _upper_6x6(hat(u[..., 3:]), hat(u[..., :3]))


def odot(s):
    """The 4x6 matrix with ``twist_hat(u) @ s == odot(s) @ u`` for homogeneous ``s``, (..., 4) -> (..., 4, 6)."""
    s = _as_vectors(s, 4, "odot")
    out = np.zeros(s.shape[:-1] + (4, 6))
    out[..., :3, :3] = s[..., 3, None, None] * np.eye(3)
    out[..., :3, 3:] = -hat(s[..., :3])
    return out
