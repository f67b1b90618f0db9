"""A stereo rig from the two cameras' extrinsics, and the four ways a file's extrinsics can be read.

visla-edu's rig is the left camera's pose ``imu_T_cam`` (optical frame) and a baseline ``b``
(a rectified pair, :mod:`visla_edu.camera`). Two extrinsics ``imu_T_left``, ``imu_T_right``
(both cameras' optical frames in the IMU frame) give it when
``left_T_right = inv(imu_T_left) imu_T_right`` is a translation along x (:func:`rig_geometry`,
:func:`rectified_baseline`).

A file's extrinsic ``E`` may be ``imu_T_cam`` ("camera->IMU") or ``cam_T_imu`` ("IMU->camera"),
in the optical frame or a "regular" one (x forward, y left, z up). The four readings
(:data:`DIRECTIONS` x :data:`FRAMES`, :func:`extrinsic_readings`) give four candidate rigs::

    imu_T_left = E  |  inv(E)  |  E @ REGULAR_T_OPTICAL  |  inv(E) @ REGULAR_T_OPTICAL

and evidence decides between them: this geometry, and the motion the IMU and the camera see
(:mod:`visla_edu.diagnostics`).
"""

from dataclasses import dataclass

import numpy as np

from visla_edu import lie

__all__ = ["REGULAR_T_OPTICAL", "DIRECTIONS", "FRAMES", "MAX_RIG_ROTATION", "MAX_OFF_AXIS", "RigReading",
           "rig_geometry", "rectified_baseline", "reading_name", "extrinsic_readings", "write_extrinsic"]

#: The optical camera frame (x right, y down, z forward) in the "regular" one (x forward, y left,
#: z up): optical x = -regular y, optical y = -regular z, optical z = regular x.
REGULAR_T_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
#: How an extrinsic ``E`` may point: ``E = imu_T_cam`` or ``E = cam_T_imu``.
DIRECTIONS = ("camera->IMU", "IMU->camera")
#: Which camera frame it may use.
FRAMES = ("optical", "regular")
#: Largest rotation between the two cameras of a rectified pair (rad, 0.57 deg): a rectified
#: pair has none; this allows for rounding and for the raw poses of a rectified rig.
MAX_RIG_ROTATION = 0.01
#: Largest offset of the right camera off the left camera's x axis, as a share of the baseline
#: (2%: 1.1 deg of direction).
MAX_OFF_AXIS = 0.02


def rig_geometry(imu_T_left, imu_T_right):
    """The right camera in the left camera's frame, and why it is not a rectified pair (if not).

    Parameters
    ----------
    imu_T_left, imu_T_right : ndarray, shape (4, 4)

    Returns
    -------
    left_T_right : ndarray, shape (4, 4)
    rotation : float
        Angle between the cameras (rad), ``|so3_log(R)|``.
    offset : ndarray, shape (3,)
        The right camera's position in the left camera frame (m); ``[b, 0, 0]`` for a rectified pair.
    problem : str
        ``""`` within :data:`MAX_RIG_ROTATION` and :data:`MAX_OFF_AXIS`, else the reason in words.
    """
    left_T_right = lie.se3_inv(np.asarray(imu_T_left, dtype=float)) @ np.asarray(imu_T_right, dtype=float)
    rotation = float(np.linalg.norm(lie.so3_log(left_T_right[:3, :3])))
    offset = left_T_right[:3, 3].copy()
    b = float(np.linalg.norm(offset))
    off_axis = float(np.hypot(offset[1], offset[2]))
    if rotation > MAX_RIG_ROTATION:
        problem = (f"the right camera is rotated {np.degrees(rotation):.3g} deg from the left one (a rectified pair: "
                   f"at most {np.degrees(MAX_RIG_ROTATION):.2g} deg)")
    elif b == 0:
        problem = "both cameras are at the same place (no baseline)"
    elif off_axis > MAX_OFF_AXIS * b:
        problem = (f"the right camera sits at {_fmt(offset)} m in the left camera frame, {off_axis:.3g} m off its x "
                   f"axis (a rectified pair: at most {100 * MAX_OFF_AXIS:g}% of the baseline {b:.3g} m)")
    elif offset[0] < 0:
        problem = (f"the right camera sits at {_fmt(offset)} m in the left camera frame, on the left camera's left "
                   "(-x): are the left and right extrinsics swapped?")
    else:
        problem = ""
    return left_T_right, rotation, offset, problem


def _fmt(v):
    return "[" + ", ".join(f"{x:.3g}" for x in v) + "]"


def rectified_baseline(imu_T_left, imu_T_right):
    """The baseline ``b = |offset|`` (m) of :func:`rig_geometry`'s two poses, or a ValueError with its ``problem``."""
    _, _, offset, problem = rig_geometry(imu_T_left, imu_T_right)
    if problem:
        raise ValueError(f"not a rectified stereo pair: {problem}; visla-edu's stereo model needs the right camera "
                         "translated along the left camera's x axis, with the same orientation")
    return float(np.linalg.norm(offset))


def reading_name(direction, frame):
    """``"camera->IMU, regular"`` etc.: the name of one reading of :func:`extrinsic_readings`."""
    if direction not in DIRECTIONS or frame not in FRAMES:
        raise ValueError(f"an extrinsic reading needs a direction in {DIRECTIONS} and a frame in {FRAMES}, "
                         f"got {direction!r} and {frame!r}")
    return f"{direction}, {frame}"


@dataclass(frozen=True)
class RigReading:
    """One reading of a file's two extrinsics: the rig it gives, and whether that rig is rectified.

    ``name``: :func:`reading_name`, e.g. ``"camera->IMU, regular"``; ``direction``, ``frame``: of
    :data:`DIRECTIONS` and :data:`FRAMES`; ``imu_T_left``, ``imu_T_right`` (4, 4): under this
    reading; ``rotation``, ``offset``, ``problem``: as in :func:`rig_geometry`.
    """

    name: str
    direction: str
    frame: str
    imu_T_left: np.ndarray
    imu_T_right: np.ndarray
    rotation: float
    offset: np.ndarray
    problem: str

    @property
    def rectified(self):
        """Whether the right camera is the left one translated along its x axis (no ``problem``)."""
        return not self.problem


def _imu_T_optical(E, direction, frame):
    T = np.asarray(E, dtype=float) if direction == DIRECTIONS[0] else lie.se3_inv(E)
    return T @ REGULAR_T_OPTICAL if frame == FRAMES[1] else T


def extrinsic_readings(ext_left, ext_right):
    """The four readings (:data:`DIRECTIONS` x :data:`FRAMES`) of two extrinsics, as a tuple of :class:`RigReading`.

    ``ext_left``, ``ext_right`` (4, 4): the file's extrinsics of the two cameras (read the same way).
    Order: camera->IMU optical, camera->IMU regular, IMU->camera optical, IMU->camera regular.
    """
    readings = []
    for direction in DIRECTIONS:
        for frame in FRAMES:
            left, right = _imu_T_optical(ext_left, direction, frame), _imu_T_optical(ext_right, direction, frame)
            _, rotation, offset, problem = rig_geometry(left, right)
            readings.append(RigReading(reading_name(direction, frame), direction, frame, left, right, rotation, offset,
                                       problem))
    return tuple(readings)


def write_extrinsic(imu_T_cam, direction, frame):
    """The extrinsic ``E`` (4, 4) a file written in reading ``(direction, frame)`` stores for ``imu_T_cam`` (optical).

    The inverse of the reading: ``_imu_T_optical(write_extrinsic(T, d, f), d, f) == T``.
    """
    reading_name(direction, frame)  # checks both
    T = np.asarray(imu_T_cam, dtype=float)
    if frame == FRAMES[1]:
        T = T @ lie.se3_inv(REGULAR_T_OPTICAL)
    return T if direction == DIRECTIONS[0] else lie.se3_inv(T)
