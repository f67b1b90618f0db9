"""Perspective projection of stereo points and the Jacobians of the observation model (one copy).

:func:`project_points` is the stereo observation of points given in any frame ``x`` and moved
into the left camera by a transform ``A = cam_T_x``::

    q = A [p; 1],    z = Ks pi(q)
    J_z_point     = Ks dpi/dq(q) A P^T                      (4 x 3)
    J_z_transform = Ks dpi/dq(q) A odot([p; 1])            (4 x 6, right perturbation A exp(delta^))
                  = [J_z_point, -J_z_point hat(p)]

:func:`stereo_projection` is its use for landmarks ``m`` in the world seen from IMU poses
``T = world_T_imu`` (``A = cam_T_imu``, ``p = inv(T) m``): ``J_z_landmark = J_z_point R^T`` and,
since ``inv(T exp(delta^)) m = exp(-delta^) inv(T) m``, ``J_z_pose = -J_z_transform`` (the
formulas of :mod:`visla_edu.camera`). The visual odometry uses :func:`project_points` with ``A``
the motion between two camera frames.
"""

import numpy as np

from visla_edu import lie

__all__ = ["projection", "projection_jacobian", "project_points", "stereo_projection"]


def projection(q):
    """Perspective division ``pi(q) = q / q3`` of homogeneous camera points, (..., 4) -> (..., 4)."""
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"projection: expected shape (..., 4), got {q.shape}")
    return q / q[..., 2:3]


def projection_jacobian(q):
    """Jacobian ``dpi/dq`` of :func:`projection`, (..., 4) -> (..., 4, 4).

    ``dpi/dq = (1/q3) [[1, 0, -q1/q3, 0], [0, 1, -q2/q3, 0], [0, 0, 0, 0], [0, 0, -q4/q3, 1]]``
    """
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"projection_jacobian: expected shape (..., 4), got {q.shape}")
    inv_q3 = 1.0 / q[..., 2]
    J = np.zeros(q.shape[:-1] + (4, 4))
    for i in (0, 1, 3):
        J[..., i, i] = inv_q3
        J[..., i, 2] = -q[..., i] * inv_q3**2
    return J


def project_points(Ks, A, p, jacobians=True):
    """Stereo pixels ``z = Ks pi(A [p; 1])`` of points ``p`` moved by ``A``, and the module's Jacobians.

    Parameters
    ----------
    Ks : ndarray, shape (4, 4)
    A : ndarray, shape (..., 4, 4)
        ``cam_T_x``: one transform for all points (``cam_T_imu``), or one per batch entry (the
        odometry's frame-to-frame motions, ``(P, 4, 4)`` or ``(P, H, 4, 4)``).
    p : ndarray, shape (..., N, 3)
        The points in frame ``x``.

    Returns
    -------
    z, q : ndarray, shape (..., N, 4)
        The pixels, and the homogeneous points in the left camera (``q[..., 2]`` is the depth).
    J_z_point, J_z_transform : ndarray, shape (..., N, 4, 3) and (..., N, 4, 6)
        Only if ``jacobians``.
    """
    A = np.asarray(A, dtype=float)
    q = p @ np.swapaxes(A[..., :, :3], -1, -2) + A[..., None, :, 3]
    z = projection(q) @ Ks.T
    if not jacobians:
        return z, q
    Ks_dpi = Ks @ projection_jacobian(q)  # (..., N, 4, 4)
    J_z_point = Ks_dpi @ (A[:, :3] if A.ndim == 2 else A[..., None, :, :3])
    return z, q, J_z_point, np.concatenate([J_z_point, -(J_z_point @ lie.hat(p))], axis=-1)


def stereo_projection(Ks, cam_T_imu, world_T_imu, p_world, jacobians=True):
    """Predicted stereo pixels of world landmarks, ``z = Ks pi(cam_T_imu inv(T) m)``, and the Jacobians.

    Parameters
    ----------
    Ks, cam_T_imu : ndarray, shape (4, 4)
    world_T_imu : ndarray, shape (4, 4) or (N, 4, 4)
        One pose ``T`` for every landmark (a filter's frame), or the pose of each observation (a
        smoother's).
    p_world : ndarray, shape (N, 3)
        The landmark ``m`` of each observation.

    Returns
    -------
    z : ndarray, shape (N, 4)
    depth : ndarray, shape (N,)
        ``q3``, the landmark's depth in the left camera.
    J_z_landmark, J_z_pose : ndarray, shape (N, 4, 3) and (N, 4, 6)
        Only if ``jacobians``; ``J_z_pose`` for the right perturbation of ``T``.
    """
    imu_T_world = lie.se3_inv(world_T_imu)
    R_t = imu_T_world[..., :3, :3]
    if R_t.ndim == 2:
        p_imu = p_world @ R_t.T + imu_T_world[:3, 3]
    else:
        p_imu = np.einsum("nij,nj->ni", R_t, p_world) + imu_T_world[:, :3, 3]
    if not jacobians:
        z, q = project_points(Ks, cam_T_imu, p_imu, jacobians=False)
        return z, q[:, 2]
    z, q, J_z_imu, J_z_move = project_points(Ks, cam_T_imu, p_imu)
    return z, q[:, 2], J_z_imu @ R_t, -J_z_move
