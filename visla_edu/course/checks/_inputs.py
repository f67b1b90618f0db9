"""Inputs the checks draw (rotations, twists, poses, points in view, rigs) and shared mistakes.

``rng`` is a :class:`numpy.random.Generator`; ``hidden`` selects the hidden cases' inputs.
"""

import numpy as np

from visla_edu import camera as cam
from visla_edu import lie

__all__ = [
    "NEAR_ZERO_HINT",
    "TRANSPOSED_R_HINT",
    "unit",
    "rotation_vectors",
    "twists",
    "random_pose",
    "rig",
    "stereo_camera",
    "notebook_rig_variant",
    "points_in_view",
    "random_covariance",
    "swap_twist",
    "not_rotation",
    "not_se3",
    "rotation_transposed",
    "wrong_inverses",
    "transposed_rotation_variants",
    "project_with",
]

NEAR_ZERO_HINT = (
    "near angle 0: use the small-angle series\n"
    "For tiny angles a closed form like sin(t)/t or (1 - cos t)/t^2 divides 0 by 0 (and loses its "
    "digits well before): below a small angle (visla-edu switches at 0.1 rad) use the Taylor series "
    "(sin(t)/t ~ 1 - t^2/6, (1 - cos t)/t^2 ~ 1/2 - t^2/24, (t - sin t)/t^3 ~ 1/6 - t^2/120).")

TRANSPOSED_R_HINT = (
    "looks like you used R instead of R^T (a transposed rotation)\n"
    "A rotation block was transposed somewhere: inv(world_T_imu) = [[R^T, -R^T p], [0, 1]] (both "
    "R^T), world_T_imu maps IMU coordinates into the world with R (not R^T), and cam_T_imu = "
    "inv(imu_T_cam) (use lie.se3_inv rather than transposing by hand).")


def unit(rng):
    """A random unit 3-vector (3,), uniformly distributed: a standard normal draw over its norm."""
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def rotation_vectors(rng, hidden=False):
    """Rotation vectors (3,) over every regime: zero, tiny, at the series switch, generic, near pi.

    A list: ``angle * axis`` with a random unit axis for 13 angles from 0 to pi (hidden: 11 others,
    0.0999 and 0.1001 among them), then 4 standard normal vectors.
    """
    angles = [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.05, 0.1, 0.5, 1.0, 2.0, 3.0, np.pi - 1e-6, np.pi]
    if hidden:
        angles = [0.0, 1e-15, 3e-8, 2e-4, 0.0999, 0.1001, 0.7, 1.5, 2.5, np.pi - 1e-9, np.pi - 1e-3]
    return [a * unit(rng) for a in angles] + [rng.normal(size=3) for _ in range(4)]


def twists(rng, hidden=False):
    """Twists ``[v; w]`` (6,): each :func:`rotation_vectors` ``w`` with ``v`` of std 3, then rest and a translation."""
    out = [np.concatenate([rng.normal(scale=3.0, size=3), w]) for w in rotation_vectors(rng, hidden)]
    return out + [np.zeros(6), np.array([2.0, -1.0, 0.5, 0.0, 0.0, 0.0])]


def random_pose(rng, scale=10.0):
    """A random pose (4, 4) ``se3_exp([v; w])``: ``v`` normal, std ``scale`` (m); ``w`` standard normal (rad)."""
    u = np.concatenate([rng.normal(scale=scale, size=3), rng.normal(size=3)])
    return lie.se3_exp(u)


def rig(hidden=False):
    """A KITTI-like stereo rig: left intrinsics ``K`` (3, 3), baseline ``b`` (m), left camera ``imu_T_cam`` (4, 4).

    Visible: :func:`visla_edu.simulate.default_rig`, the notebooks' rig. Hidden: KITTI odometry's focal
    lengths (``fsv`` slightly off ``fsu``) and baseline and a camera mounted elsewhere, so that a
    function using the notebook's rig (``rig.Ks``, ``rig.cam_T_imu``) instead of its arguments fails.
    """
    from visla_edu.simulate import default_rig

    K, b, imu_T_cam = default_rig()
    if not hidden:
        return K, b, imu_T_cam
    moved = np.eye(4)
    moved[:3, :3] = imu_T_cam[:3, :3] @ lie.so3_exp(np.array([0.03, -0.05, 0.04]))
    moved[:3, 3] = [0.8, -0.3, 1.2]
    return np.array([[721.5, 0.0, 609.6], [0.0, 716.0, 172.9], [0.0, 0.0, 1.0]]), 0.54, moved


def stereo_camera(hidden=False):
    """A new :class:`~visla_edu.camera.StereoCamera` of :func:`rig`."""
    return cam.StereoCamera(*rig(hidden))


#: The hint of a function that used the notebook's rig instead of its calibration arguments.
NOTEBOOK_RIG_HINT = (
    "the notebook's rig was used, not the calibration arguments\n"
    "the hidden cases pass another camera: compute with the arguments (Ks, cam_T_imu or K, b, imu_T_cam), "
    "not with rig.Ks, rig.cam_T_imu or other variables of the notebook")


def notebook_rig_variant(hidden, variant):
    """``[(NOTEBOOK_RIG_HINT, variant)]`` if ``hidden`` (only the hidden rig differs from the notebook's), else ``[]``.

    ``variant()``: the output with the visible rig, ``stereo_camera()``.
    """
    return [(NOTEBOOK_RIG_HINT, variant)] if hidden else []


def points_in_view(rng, world_T_imu, imu_T_cam, n, depth=(2.0, 60.0)):
    """World points (n, 3) the left camera sees at depths in ``depth`` (m).

    In the camera frame ``[a d, c d, d]``: ``d`` uniform in ``depth``, ``a`` in [-0.8, 0.8] and
    ``c`` in [-0.3, 0.3] (inside :func:`rig`'s image), then mapped by ``world_T_imu @ imu_T_cam``.
    """
    d = rng.uniform(*depth, size=n)
    x = rng.uniform(-0.8, 0.8, size=n) * d
    y = rng.uniform(-0.3, 0.3, size=n) * d
    p_cam = np.stack([x, y, d], axis=1)
    world_T_cam = world_T_imu @ imu_T_cam
    return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


def random_covariance(rng, D):
    """A random covariance (D, D) ``A A^T + D I``, ``A`` standard normal: eigenvalues >= D (well conditioned)."""
    A = rng.normal(size=(D, D))
    return A @ A.T + D * np.eye(D)


def swap_twist(u):
    """``[w; v]`` (6,) for ``u = [v; w]``, the other twist order (a new float array)."""
    u = np.asarray(u, dtype=float)
    return np.concatenate([u[3:], u[:3]])


def not_rotation(R):
    """A hint if ``R`` (3, 3) is not a rotation (``R R^T - I`` over 1e-9, or ``det R < 0``), else ""."""
    R = np.asarray(R)
    if not np.allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-9):
        return "the result is not a rotation (R R^T != I)\nIs a term of Rodrigues' formula missing?"
    if np.linalg.det(R) < 0:
        return "det(R) = -1: a reflection, not a rotation"
    return ""


def not_se3(T):
    """A hint if ``T`` (4, 4) is not a pose, else "": its bottom row (``atol=1e-9``), then :func:`not_rotation`."""
    T = np.asarray(T)
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        return "the bottom row of a pose must be [0, 0, 0, 1]: the result is not in SE(3)"
    return not_rotation(T[:3, :3]).replace("the result is not a rotation", "the rotation block is not a rotation")


def rotation_transposed(T):
    """A copy (4, 4) of ``T`` with its rotation block transposed and its translation kept."""
    out = np.array(T, dtype=float)
    out[:3, :3] = out[:3, :3].T
    return out


def wrong_inverses(T):
    """Wrong inverses (4, 4) of ``T = [[R, p], [0, 1]]``: ``[[R, -R p]]``, ``[[R, -R^T p]]``, ``[[R^T, -R p]]``."""
    R, p = T[:3, :3], T[:3, 3]
    out = []
    for block, shift in ((R, -R @ p), (R, -R.T @ p), (R.T, -R @ p)):
        W = np.eye(4)
        W[:3, :3], W[:3, 3] = block, shift
        out.append(W)
    return out


def transposed_rotation_variants(with_transforms, cam_T_imu, world_T_imu):
    """``(TRANSPOSED_R_HINT, variant)`` pairs: ``with_transforms(cam_T_imu, imu_T_world)`` with each of the
    :func:`wrong_inverses` of ``world_T_imu`` for ``imu_T_world``, then with ``cam_T_imu``'s rotation transposed."""
    variants = [lambda W=W: with_transforms(cam_T_imu, W) for W in wrong_inverses(world_T_imu)]
    variants.append(lambda: with_transforms(rotation_transposed(cam_T_imu), lie.se3_inv(world_T_imu)))
    return [(TRANSPOSED_R_HINT, variant) for variant in variants]


def project_with(Ks, cam_T_imu, imu_T_world, p_world):
    """Stereo pixels (M, 4) ``Ks pi(cam_T_imu imu_T_world m)`` of world points (M, 3), ``pi(q) = q / q_3``.

    Explicit transforms, so that the checks can pass wrong ones to get a mistake's pixels.
    """
    p_h = np.c_[p_world, np.ones(len(p_world))]
    return cam.projection(p_h @ (cam_T_imu @ imu_T_world).T) @ Ks.T
