"""The one home of each check that a calibration or a rigid transform is valid and plausible.

*Valid* is what the math needs: ``K = [[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]`` with positive focal lengths
(:func:`check_intrinsics`), a positive baseline (:func:`check_baseline`), a pose in SE(3)
(:func:`nonrigid_frames`, :func:`check_rigid`, :func:`check_rigid_poses`). *Plausible* is what a real rig can
be (:func:`check_plausible_calibration`): a well-formed file can still be wrong (millimetres stored as metres).
Each range is wide enough for any real rig; its message says what is plausible and what was probably meant:

========================  ====================  ============================================
quantity                  plausible             why
========================  ====================  ============================================
focal lengths fsu, fsv    4 .. 250,000 px       ``f = (W/2) / tan(FOV/2)`` for images 100 to
                                                20,000 px wide and fields of view 5 to 170 deg
fsv / fsu                 0.2 .. 5              pixels are close to square (1 on course rigs)
principal point cu, cv    > 0 .. 20,000 px      inside an image at most 20,000 px wide;
                                                exactly 0 (the image's corner) is refused
baseline b                0.005 .. 5 m          a phone's stereo pair to a rig across a truck
extrinsic translation     <= 20 m               camera and IMU ride the same vehicle
========================  ====================  ============================================

A drive's plausible time stamps, velocities and pixels are :mod:`visla_edu.data._plausible`'s. Every check
raises a one-line ``ValueError`` that starts with ``subject``, the caller's name of the input
(``"stereo_matrix: K"``, ``"path: key 'K'"``), and says what was expected and what was found.
"""

import numpy as np

__all__ = [
    "RIGID_TOL",
    "POSE_RIGID_TOL",
    "FOCAL_RANGE",
    "ASPECT_RANGE",
    "PRINCIPAL_POINT_RANGE",
    "BASELINE_RANGE",
    "MAX_EXTRINSIC_TRANSLATION",
    "magnitude",
    "check_intrinsics",
    "check_baseline",
    "check_stereo_calibration",
    "check_plausible_calibration",
    "nonrigid_frames",
    "rigid_detail",
    "check_rigid",
    "check_rigid_poses",
]

#: Tolerance on ``R^T R = I`` of a camera extrinsic (:func:`check_rigid`).
RIGID_TOL = 1e-6
#: Tolerance on ``R^T R = I`` and the last row of a pose: ground truth, trajectory files, the ATE's
#: inputs, a graded filter's poses. KITTI's 0020 poses reach 2e-7, the filters and smoothers 1e-14.
POSE_RIGID_TOL = 1e-3

FOCAL_RANGE = (4.0, 2.5e5)  # px
ASPECT_RANGE = (0.2, 5.0)  # fsv / fsu
PRINCIPAL_POINT_RANGE = (0.0, 2e4)  # px, 0 excluded
BASELINE_RANGE = (0.005, 5.0)  # m
MAX_EXTRINSIC_TRANSLATION = 20.0  # m


def magnitude(vectors):
    """Norms ``hypot(hypot(v1, v2), v3)`` (...) of ``vectors`` (..., 3), without overflow (1e200 stays 1e200)."""
    v = np.asarray(vectors, dtype=float)
    return np.hypot(np.hypot(v[..., 0], v[..., 1]), v[..., 2])


def check_intrinsics(K, subject, key="K"):
    """``K`` as a (3, 3) float array ``[[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]`` with positive focal lengths.

    A skew ``K[0, 1] != 0`` is refused: the stereo model (:func:`visla_edu.camera.stereo_matrix`) has none
    (rectified images have none), so it would be silently ignored. ``key`` writes the entries in messages.

    Raises
    ------
    ValueError
        Another shape, a non-finite entry, an entry below the diagonal not 0 or ``K[2, 2] != 1``,
        ``fsu`` or ``fsv`` not positive, or a skew (checked in this order).
    """
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3):
        raise ValueError(f"{subject} must have shape (3, 3), got {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError(f"{subject} needs finite entries, got {K.tolist()}")
    if np.any(K[np.tril_indices(3, -1)] != 0) or K[2, 2] != 1:
        raise ValueError(f"{subject} must be upper triangular with K[2, 2] = 1 "
                         f"([[fsu, s, cu], [0, fsv, cv], [0, 0, 1]]), got {K.tolist()}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{subject} needs positive focal lengths, got fsu = {K[0, 0]}, fsv = {K[1, 1]}")
    if K[0, 1] != 0:
        raise ValueError(
            f"{subject} has a skew {key}[0, 1] = {float(K[0, 1])!r}, but the stereo camera model has none "
            "(K = [[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]; rectified stereo images have zero skew), so it would "
            f"be ignored. Rectify the images, or set {key}[0, 1] = 0 if the skew is a rounding artefact")
    return K


def check_baseline(b, subject):
    """The stereo baseline ``b`` (metres, a float or 0-d array) as a finite positive float, else a ValueError."""
    b = float(b)
    if not np.isfinite(b):
        raise ValueError(f"{subject} (stereo baseline, metres) must be a finite number, got {b!r}")
    if not b > 0:
        raise ValueError(f"{subject} (stereo baseline, metres) must be positive, got {b!r}")
    return b


def check_stereo_calibration(K, b, name):
    """``K`` (:func:`check_intrinsics`) and ``b`` (:func:`check_baseline`), arguments of function ``name``."""
    return check_intrinsics(K, f"{name}: K"), check_baseline(b, f"{name}: b")


def check_plausible_calibration(K, b, path, pose=None, pose_key="imu_T_cam", K_key="K", b_key="b"):
    """Focal lengths, aspect, principal point, baseline and extrinsic translation in their plausible ranges.

    ``K`` (3, 3) must already be valid (:func:`check_intrinsics`), ``b`` (m) positive and ``pose`` (4, 4, the
    extrinsics ``imu_T_cam`` or ``cam_T_imu``) rigid; without ``pose`` its translation is not checked. ``path``
    (the file or dataset name) and the file's keys ``pose_key``, ``K_key``, ``b_key`` are for messages.

    Raises
    ------
    ValueError
        A quantity outside its range in the module's table (:data:`FOCAL_RANGE`, :data:`ASPECT_RANGE`,
        :data:`PRINCIPAL_POINT_RANGE` without 0, :data:`BASELINE_RANGE`, :data:`MAX_EXTRINSIC_TRANSLATION`;
        checked in this order; a length that would fit in millimetres says so).
    """
    fsu, fsv, cu, cv = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    for name, value in (("fsu = K[0, 0]", fsu), ("fsv = K[1, 1]", fsv)):
        if not FOCAL_RANGE[0] <= value <= FOCAL_RANGE[1]:
            raise ValueError(f"{path}: key '{K_key}': focal length {name} = {value:.6g} px is implausible; a camera's "
                             f"focal length is {FOCAL_RANGE[0]:g} to {FOCAL_RANGE[1]:g} px ((W/2) / tan(FOV/2) for "
                             "images 100 to 20,000 px wide and fields of view 5 to 170 deg). Is it in mm or "
                             "metres instead of pixels?")
    if not ASPECT_RANGE[0] <= fsv / fsu <= ASPECT_RANGE[1]:
        raise ValueError(f"{path}: key '{K_key}': fsv / fsu = {fsv / fsu:.4g} is implausible (pixels are close to "
                         f"square: {ASPECT_RANGE[0]:g} to {ASPECT_RANGE[1]:g}); are two entries of K swapped?")
    for name, value in (("cu = K[0, 2]", cu), ("cv = K[1, 2]", cv)):
        if not PRINCIPAL_POINT_RANGE[0] < value <= PRINCIPAL_POINT_RANGE[1]:
            raise ValueError(f"{path}: key '{K_key}': principal point {name} = {value:.6g} px is outside any image (it "
                             f"lies near the image centre, above 0 and at most {PRINCIPAL_POINT_RANGE[1]:g} px)")
    _check_length(b, BASELINE_RANGE, b_key, "the stereo baseline", "(from a phone's stereo pair to a rig across a "
                  "truck)", path)
    if pose is None:
        return
    translation = float(magnitude(pose[:3, 3]))
    _check_length(translation, (0.0, MAX_EXTRINSIC_TRANSLATION), pose_key, "the camera-IMU translation |t|",
                  "(the camera and the IMU ride the same vehicle)", path)


def _check_length(value, plausible, key, what, why, path):
    low, high = plausible
    if low <= value <= high:
        return
    mm = " It looks like millimetres: divide by 1000." if low <= value / 1000 <= high else ""
    raise ValueError(f"{path}: key '{key}': {what} is {value:.6g} m, outside the plausible {low:g} to {high:g} m "
                     f"{why}.{mm}")


def _rigid_errors(poses):
    """``max |R^T R - I|``, the largest last-row deviation from ``[0, 0, 0, 1]`` and ``det R`` of each pose (n,)."""
    R = poses[:, :3, :3]
    orthogonality = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2), initial=0.0)
    bottom = np.abs(poses[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1, initial=0.0)
    return orthogonality, bottom, np.linalg.det(R)


def nonrigid_frames(poses, tolerance, last_row_tolerance=None):
    """Which poses ``[[R, p], [a, b]]`` of a finite batch (n, 4, 4) are not in SE(3), and how far from orthonormal.

    Rigid: every entry of ``|R^T R - I|`` at most ``tolerance``, every entry of ``|[a, b] - [0, 0, 0, 1]|`` at
    most ``last_row_tolerance`` (default ``tolerance``; 0 asks for an exact last row) and ``det R > 0``.

    Returns
    -------
    bad : ndarray of bool, shape (n,)
    orthogonality : ndarray, shape (n,)
        ``max |R^T R - I|`` of each pose (for the message).
    """
    orthogonality, bottom, det = _rigid_errors(poses)
    row_tolerance = tolerance if last_row_tolerance is None else last_row_tolerance
    return (orthogonality > tolerance) | (bottom > row_tolerance) | (det < 0), orthogonality


def rigid_detail(pose, tolerance):
    """What is wrong with a pose (4, 4) that is not rigid, for a message: its orthogonality, ``det R``, last row."""
    orthogonality, _, det = _rigid_errors(pose[None])
    return (f"max |R^T R - I| = {orthogonality[0]:.3g}, det R = {det[0]:.3g}, last row {pose[3].tolist()}; "
            f"expected [[R, p], [0, 0, 0, 1]] with R a rotation, to {tolerance:g}")


def check_rigid(T, subject, tolerance=RIGID_TOL):
    """``T`` (4, 4, finite) in SE(3): ``R^T R = I`` to ``tolerance``, ``det R = +1``, last row exactly ``[0, 0, 0, 1]``.

    Else a ``ValueError`` for the first that fails, in this order (a small excess of ``R^T R - I`` suggests
    rounded entries).
    """
    orthogonality, bottom, det = (float(e[0]) for e in _rigid_errors(T[None]))
    if orthogonality > tolerance:
        raise ValueError(
            f"{subject} is not a rigid transform: max |R^T R - I| = {orthogonality:.3g} > {tolerance:g}"
            + ("; rounded entries? store full precision, or re-orthonormalise R (e.g. U @ Vt of its SVD)"
               if orthogonality < 1e-2 else "")
        )
    if det < 0:
        raise ValueError(f"{subject} is not a rigid transform: det(R) = {det:.6g}, expected +1 (a reflection?)")
    if bottom > 0:
        raise ValueError(f"{subject} is not a rigid transform: last row is {T[3].tolist()}, expected [0, 0, 0, 1]")


def check_rigid_poses(poses, subject, tolerance=POSE_RIGID_TOL):
    """Every pose of ``poses`` (n, 4, 4, finite) in SE(3) to ``tolerance`` (:func:`nonrigid_frames`), else a ValueError.

    Its message is ``f"{subject} of frame {t} is not a rigid transform ({rigid_detail})"`` for the first such ``t``
    (``subject`` e.g. ``"path: key 'ground_truth_world_T_imu': the pose"``).
    """
    bad = np.flatnonzero(nonrigid_frames(poses, tolerance)[0])
    if bad.size:
        t = int(bad[0])
        raise ValueError(f"{subject} of frame {t} is not a rigid transform ({rigid_detail(poses[t], tolerance)})")
