"""Write a Dataset as a 2025+ course file, the extrinsics in a chosen reading.

The inverse of :func:`~visla_edu.data._format2025.load_course2025` for the drives we simulate (the tests
exercise every direction and frame the format may use).
"""

import numpy as np

from visla_edu._files import atomic_write, expand_user
from visla_edu.camera import DIRECTIONS, FRAMES, reading_name, write_extrinsic

__all__ = ["save_course2025", "VELOCITY_LAYOUTS"]

#: How ``v_t`` and ``w_t`` may be stored: one row per frame (the course's) or one column.
VELOCITY_LAYOUTS = ("T x 3", "3 x T")


def save_course2025(dataset, path, direction=DIRECTIONS[0], frame=FRAMES[1], velocity_layout=VELOCITY_LAYOUTS[0],
                    features=True):
    """Write ``dataset`` as a 2025+ course file (``np.save`` of the dict of :mod:`visla_edu.data`); return the path.

    The right camera is the left one (``imu_T_cam``) moved by ``b`` along its x axis; both extrinsics are written
    in the reading ``(direction, frame)`` (:func:`visla_edu.camera.write_extrinsic`). ``path`` gets ``.npy``
    appended if missing and is written atomically; the path returned is absolute.

    Parameters
    ----------
    direction : {"camera->IMU", "IMU->camera"}
        ``imu_T_cam`` as stored, or its inverse.
    frame : {"regular", "optical"}
        The x-forward, y-left, z-up camera frame, or the x-right, y-down, z-forward one.
    velocity_layout : {"T x 3", "3 x T"}
    features : bool
        False writes ``features = None`` (a dataset shipped with images).
    """
    reading_name(direction, frame)  # checks both
    if velocity_layout not in VELOCITY_LAYOUTS:
        raise ValueError(f"save_course2025: velocity_layout must be one of {VELOCITY_LAYOUTS}, got {velocity_layout!r}")
    path = expand_user(path)
    if path.suffix != ".npy":
        path = path.with_name(path.name + ".npy")
    imu_T_left = np.asarray(dataset.imu_T_cam, dtype=float)
    left_T_right = np.eye(4)
    left_T_right[0, 3] = float(dataset.b)
    contents = {
        "timestamps": np.asarray(dataset.time_stamps, dtype=float),
        "v_t": _layout(dataset.linear_velocity, velocity_layout),
        "w_t": _layout(dataset.angular_velocity, velocity_layout),
        "features": dataset.to_dense_features() if features else None,
        "K_l": np.asarray(dataset.K, dtype=float),
        "K_r": np.asarray(dataset.K if dataset.K_right is None else dataset.K_right, dtype=float),
        "extL_T_imu": write_extrinsic(imu_T_left, direction, frame),
        "extR_T_imu": write_extrinsic(imu_T_left @ left_T_right, direction, frame),
    }
    with atomic_write(path, "wb") as f:
        np.save(f, contents, allow_pickle=True)
    return path.resolve()


def _layout(velocity, layout):
    """``(T, 3)`` velocities as stored in ``layout`` (:data:`VELOCITY_LAYOUTS`)."""
    velocity = np.asarray(velocity, dtype=float)
    return velocity if layout == VELOCITY_LAYOUTS[0] else velocity.T
