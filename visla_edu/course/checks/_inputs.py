"""Inputs the checks draw (rotations, twists, poses, points in view, rigs) and shared mistakes."""

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
    """A random unit 3-vector.

    Parameters
    ----------
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (3,)
        A standard normal draw divided by its norm (a uniformly distributed direction).
    """
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def rotation_vectors(rng, hidden=False):
    """Rotation vectors over every regime: zero, tiny, at the series switch, generic, near pi.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the axes (:func:`unit`) and the generic vectors.
    hidden : bool
        False: the angles 0, 1e-12, 1e-9, 1e-6, 1e-3, 0.05, 0.1, 0.5, 1, 2, 3, pi - 1e-6 and pi
        (rad); True: 0, 1e-15, 3e-8, 2e-4, 0.0999, 0.1001, 0.7, 1.5, 2.5, pi - 1e-9 and pi - 1e-3.

    Returns
    -------
    list of ndarray, shape (3,)
        ``angle * axis`` with a random unit axis for each angle, then 4 standard normal vectors
        (17 vectors visible, 15 hidden).
    """
    angles = [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.05, 0.1, 0.5, 1.0, 2.0, 3.0, np.pi - 1e-6, np.pi]
    if hidden:
        angles = [0.0, 1e-15, 3e-8, 2e-4, 0.0999, 0.1001, 0.7, 1.5, 2.5, np.pi - 1e-9, np.pi - 1e-3]
    return [a * unit(rng) for a in angles] + [rng.normal(size=3) for _ in range(4)]


def twists(rng, hidden=False):
    """Twists ``[v; w]`` with the rotation vectors of :func:`rotation_vectors`, at rest, pure translation.

    Parameters
    ----------
    rng : numpy.random.Generator
    hidden : bool
        Passed to :func:`rotation_vectors`.

    Returns
    -------
    list of ndarray, shape (6,)
        One twist per rotation vector ``w``, its ``v`` normal with standard deviation 3; then the
        zero twist and the pure translation ``[2, -1, 0.5, 0, 0, 0]`` (19 twists visible, 17
        hidden).
    """
    out = [np.concatenate([rng.normal(scale=3.0, size=3), w]) for w in rotation_vectors(rng, hidden)]
    out.append(np.zeros(6))
    out.append(np.array([2.0, -1.0, 0.5, 0.0, 0.0, 0.0]))
    return out


def random_pose(rng, scale=10.0):
    """A random pose ``se3_exp([v; w])``: translation of the order of ``scale``, any rotation.

    Parameters
    ----------
    rng : numpy.random.Generator
    scale : float
        Standard deviation of each entry of ``v`` (m); ``w`` is standard normal (rad).

    Returns
    -------
    ndarray, shape (4, 4)
    """
    u = np.concatenate([rng.normal(scale=scale, size=3), rng.normal(size=3)])
    return lie.se3_exp(u)


def rig(hidden=False):
    """A KITTI-like stereo rig: the simulator's, or another one for the hidden cases.

    The visible cases use what :func:`visla_edu.simulate.default_rig` returns, the rig of the
    notebooks' simulated drives. The hidden cases use KITTI odometry's focal lengths (``fsv``
    slightly off ``fsu``) and baseline and a camera mounted elsewhere, so a function that
    takes the notebook's rig (``rig.Ks``, ``rig.cam_T_imu``) instead of its arguments fails.

    Parameters
    ----------
    hidden : bool
        Return the hidden cases' rig.

    Returns
    -------
    K : ndarray, shape (3, 3)
        Left camera intrinsics.
    b : float
        Stereo baseline (m).
    imu_T_cam : ndarray, shape (4, 4)
        Pose of the left camera in the IMU frame.
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
    """The :class:`~visla_edu.camera.StereoCamera` of :func:`rig`.

    Parameters
    ----------
    hidden : bool
        The hidden cases' camera.

    Returns
    -------
    visla_edu.camera.StereoCamera
        A new camera object, ``StereoCamera(K, b, imu_T_cam)``.
    """
    return cam.StereoCamera(*rig(hidden))


#: The hint of a function that used the notebook's rig instead of its calibration arguments.
NOTEBOOK_RIG_HINT = (
    "the notebook's rig was used, not the calibration arguments\n"
    "the hidden cases pass another camera: compute with the arguments (Ks, cam_T_imu or K, b, imu_T_cam), "
    "not with rig.Ks, rig.cam_T_imu or other variables of the notebook")


def notebook_rig_variant(hidden, variant):
    """The mistake "used the notebook's rig" as a list of variants for :func:`~visla_edu.course.checks._core.compare`.

    Parameters
    ----------
    hidden : bool
        Only the hidden cases' rig differs from the notebook's (:func:`rig`).
    variant : callable
        The output computed with the visible rig, ``stereo_camera()``, on the case's inputs.

    Returns
    -------
    list of (str, callable)
        ``[(NOTEBOOK_RIG_HINT, variant)]`` if ``hidden``, else empty.
    """
    return [(NOTEBOOK_RIG_HINT, variant)] if hidden else []


def points_in_view(rng, world_T_imu, imu_T_cam, n, depth=(2.0, 60.0)):
    """World points (n, 3) the left camera sees at depths in ``depth`` (m).

    In the left camera frame each point is ``[a d, c d, d]`` with the depth ``d`` uniform in
    ``depth``, ``a`` uniform in [-0.8, 0.8] and ``c`` in [-0.3, 0.3] (inside the image of
    :func:`rig`); it is then mapped to the world with ``world_T_imu @ imu_T_cam``.

    Parameters
    ----------
    rng : numpy.random.Generator
    world_T_imu : ndarray, shape (4, 4)
    imu_T_cam : ndarray, shape (4, 4)
    n : int
    depth : (float, float)
        Range of the camera-frame depth ``z`` (m).

    Returns
    -------
    ndarray, shape (n, 3)
    """
    d = rng.uniform(*depth, size=n)
    x = rng.uniform(-0.8, 0.8, size=n) * d
    y = rng.uniform(-0.3, 0.3, size=n) * d
    p_cam = np.stack([x, y, d], axis=1)
    world_T_cam = world_T_imu @ imu_T_cam
    return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


def random_covariance(rng, D):
    """A well-conditioned random covariance (D, D).

    Parameters
    ----------
    rng : numpy.random.Generator
    D : int

    Returns
    -------
    ndarray, shape (D, D)
        ``A A^T + D I`` with ``A`` standard normal: symmetric, every eigenvalue at least ``D``.
    """
    A = rng.normal(size=(D, D))
    return A @ A.T + D * np.eye(D)


def swap_twist(u):
    """``[w; v]`` for ``u = [v; w]`` (the other twist order).

    Parameters
    ----------
    u : array_like, shape (6,)

    Returns
    -------
    ndarray, shape (6,)
        ``[u[3:]; u[:3]]``, float.
    """
    u = np.asarray(u, dtype=float)
    return np.concatenate([u[3:], u[:3]])


def not_rotation(R):
    """A hint if ``R`` is not a rotation, else "".

    Parameters
    ----------
    R : array_like, shape (3, 3)

    Returns
    -------
    str
        ``"the result is not a rotation (R R^T != I)..."`` when an entry of ``R R^T - I`` exceeds
        1e-9 in size, ``"det(R) = -1: a reflection, not a rotation"`` when ``det R < 0``, else
        ``""``.
    """
    R = np.asarray(R)
    if not np.allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-9):
        return "the result is not a rotation (R R^T != I)\nIs a term of Rodrigues' formula missing?"
    if np.linalg.det(R) < 0:
        return "det(R) = -1: a reflection, not a rotation"
    return ""


def not_se3(T):
    """A hint if ``T`` is not a pose, else "".

    Parameters
    ----------
    T : array_like, shape (4, 4)

    Returns
    -------
    str
        A hint about the bottom row when it is not close to ``[0, 0, 0, 1]`` (``numpy.allclose``
        with ``atol=1e-9``), else the hint of :func:`not_rotation` on the rotation block (worded
        "the rotation block is not a rotation"), else ``""``.
    """
    T = np.asarray(T)
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        return "the bottom row of a pose must be [0, 0, 0, 1]: the result is not in SE(3)"
    hint = _not_rotation_block(T[:3, :3])
    return hint


def _not_rotation_block(R):
    hint = not_rotation(R)
    return hint.replace("the result is not a rotation", "the rotation block is not a rotation")


def rotation_transposed(T):
    """``T`` with its rotation block transposed and its translation kept.

    Parameters
    ----------
    T : array_like, shape (4, 4)

    Returns
    -------
    ndarray, shape (4, 4)
        A new float array; ``T`` is not modified.
    """
    out = np.array(T, dtype=float)
    out[:3, :3] = out[:3, :3].T
    return out


def wrong_inverses(T):
    """Inverses of ``T`` written with R where R^T belongs: ``[[R, -R p]]``, ``[[R, -R^T p]]``, ``[[R^T, -R p]]``.

    Parameters
    ----------
    T : ndarray, shape (4, 4)
        ``[[R, p], [0, 1]]``.

    Returns
    -------
    list of ndarray, shape (4, 4)
        The three wrong inverses in this order, each with the bottom row ``[0, 0, 0, 1]``.
    """
    R, p = T[:3, :3], T[:3, 3]
    out = []
    for block, shift in ((R, -R @ p), (R, -R.T @ p), (R.T, -R @ p)):
        W = np.eye(4)
        W[:3, :3], W[:3, 3] = block, shift
        out.append(W)
    return out


def project_with(Ks, cam_T_imu, imu_T_world, p_world):
    """Stereo pixels (M, 4) ``Ks pi(cam_T_imu imu_T_world m)`` with explicit transforms.

    The checks pass wrong transforms (the pose not inverted, a rotation transposed) to compute
    the pixels a mistake gives.

    Parameters
    ----------
    Ks : ndarray, shape (4, 4)
        Stereo matrix.
    cam_T_imu : ndarray, shape (4, 4)
    imu_T_world : ndarray, shape (4, 4)
    p_world : ndarray, shape (M, 3)

    Returns
    -------
    ndarray, shape (M, 4)
        ``[uL, vL, uR, vR]`` of each point, with ``pi(q) = q / q_3``.
    """
    p_h = np.c_[p_world, np.ones(len(p_world))]
    return cam.projection(p_h @ (cam_T_imu @ imu_T_world).T) @ Ks.T
