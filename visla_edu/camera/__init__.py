"""Calibrated stereo camera: the stereo matrix Ks, projection, Jacobians, triangulation.

Model (rectified stereo pair: the right camera is the left one translated by ``+b`` along the
left camera's x axis, with the same orientation; left camera optical frame ``o``: x right, y
down, z forward)::

    q = cam_T_imu @ inv(world_T_imu) @ m          # homogeneous point in the left camera
    z = Ks @ pi(q) = [uL, vL, uR, vR]             # pixels, left then right image

    Ks = [[fsu, 0,   cu, 0       ],
          [0,   fsv, cv, 0       ],
          [fsu, 0,   cu, -fsu * b],
          [0,   fsv, cv, 0       ]]
    pi(q) = q / q3

With the right perturbation ``world_T_imu = mu @ exp(twist_hat(delta))`` (the convention and the
``J_out_in`` names of :mod:`visla_edu.lie`) the pose Jacobian is
``J_z_pose = -Ks dpi/dq(q) cam_T_imu odot(inv(mu) m)`` and the landmark Jacobian
``J_z_landmark = Ks dpi/dq(q) cam_T_imu inv(mu) P^T`` with ``P = [I 0]``. Both are computed in
one place, :func:`project_points`, which :func:`stereo_projection`, the filters, the smoothers,
the visual odometry and the capstone all call.

Private modules, all re-exported here: ``_projection`` (``pi``, ``dpi/dq``, the two above),
``_intrinsics`` (``Ks`` of one or two intrinsics: rows 3 and 4 are the right camera's),
``_extrinsics`` (the rig from two extrinsics, read in one of four ways), ``_triangulation``
(depth from disparity and from bearings, its Jacobian), ``_rig`` (:class:`StereoCamera`).
"""

from visla_edu.camera._extrinsics import (DIRECTIONS, FRAMES, MAX_OFF_AXIS, MAX_RIG_ROTATION, REGULAR_T_OPTICAL,
                                         RigReading, extrinsic_readings, reading_name, rectified_baseline,
                                         rig_geometry, write_extrinsic)
from visla_edu.camera._intrinsics import (STEREO_ROWS, disparity, left_in_right_u, right_in_left_pixels,
                                          same_intrinsics, single_intrinsics, stereo_matrix, stereo_rows)
from visla_edu.camera._projection import project_points, projection, projection_jacobian, stereo_projection
from visla_edu.camera._rig import StereoCamera
from visla_edu.camera._triangulation import triangulate_bearing, triangulate_disparity, triangulation_jacobian

__all__ = [
    "STEREO_ROWS",
    "REGULAR_T_OPTICAL",
    "DIRECTIONS",
    "FRAMES",
    "MAX_RIG_ROTATION",
    "MAX_OFF_AXIS",
    "RigReading",
    "stereo_matrix",
    "stereo_rows",
    "same_intrinsics",
    "single_intrinsics",
    "right_in_left_pixels",
    "left_in_right_u",
    "disparity",
    "rig_geometry",
    "rectified_baseline",
    "reading_name",
    "extrinsic_readings",
    "write_extrinsic",
    "projection",
    "projection_jacobian",
    "project_points",
    "stereo_projection",
    "triangulate_disparity",
    "triangulate_bearing",
    "triangulation_jacobian",
    "StereoCamera",
]
