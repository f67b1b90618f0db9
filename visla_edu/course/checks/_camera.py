"""Checks of notebooks 02 and 05 (the stereo camera): Ks, projection, triangulation, initialisation."""

import numpy as np

from visla_edu import camera as cam
from visla_edu import ekf, lie
from visla_edu.course import capstone
from visla_edu.course.checks._core import as_array, compare, exercise_check, fmt, ok, rng, student
from visla_edu.course.checks._inputs import (TRANSPOSED_R_HINT, notebook_rig_variant, points_in_view, project_with,
                                      random_pose, rig, rotation_transposed, stereo_camera,
                                      transposed_rotation_variants)

__all__ = ["check_stereo_matrix", "check_project", "check_triangulate", "check_init_landmark"]


def _calibrations(generator, hidden=False):
    """``(K, b)`` pairs: the simulator's rig, a KITTI-like one and random ones."""
    out = [] if hidden else [rig()[:2], (np.array([[552.55, 0, 682.05], [0, 552.55, 238.77], [0, 0, 1]]), 0.5962)]
    for _ in range(4 if hidden else 2):
        f = generator.uniform(300, 900)
        K = np.array([[f, 0, generator.uniform(300, 700)], [0, f * generator.uniform(0.9, 1.1),
                                                            generator.uniform(150, 300)], [0, 0, 1]])
        out.append((K, generator.uniform(0.1, 1.0)))
    return out


@exercise_check
def check_stereo_matrix(stereo_matrix, hidden=False):
    """Exercise 02: ``stereo_matrix(K (3, 3), b) -> Ks (4, 4)``, the baseline ``b`` in m.

    Compares with :func:`visla_edu.camera.stereo_matrix` for the simulator's rig, a KITTI-like one
    and random ones (hidden: random ones only). Hides ``camera.stereo_matrix``.
    """
    name = "stereo_matrix"
    call = student(stereo_matrix, name, hide=[cam.stereo_matrix])
    for K, b in _calibrations(rng(hidden), hidden):
        got = as_array(call(K, b), name, (4, 4))
        ref = cam.stereo_matrix(K, b)
        plus = ref.copy()
        plus[2, 3] *= -1
        no_f = ref.copy()
        no_f[2, 3] = -b
        compare(name, got, ref, f"for fsu = {K[0, 0]:.2f}, b = {b:.3f}", [
            ("the sign of the baseline term: the entry is -fsu b\nthe right camera sits at +b along x, "
             "so a point at depth z appears at uR = uL - fsu b / z", lambda: plus),
            ("the baseline term must be in pixels: -fsu * b, not -b", lambda: no_f),
            ("Ks is transposed", lambda: ref.T),
        ])
    ok(f"{name}: Ks agrees with the library for 4 calibrations", hidden)


def _project_variants(Ks, cam_T_imu, imu_T_cam, world_T_imu, p_world):
    """The deliberate mistakes of ``project``: (hint, callable) pairs."""
    imu_T_world = lie.se3_inv(world_T_imu)
    return [
        ("you used world_T_imu where its inverse is needed\nthe point in the IMU frame is "
         "inv(world_T_imu) @ m", lambda: project_with(Ks, cam_T_imu, world_T_imu, p_world)),
        ("you used imu_T_cam where cam_T_imu is needed\ncam_T_imu = inv(imu_T_cam), written o_T_i",
         lambda: project_with(Ks, imu_T_cam, imu_T_world, p_world)),
        ("divide by the depth q3 (the third coordinate), not q4",
         lambda: (np.c_[p_world, np.ones(len(p_world))] @ (cam_T_imu @ imu_T_world).T) @ Ks.T),
    ] + transposed_rotation_variants(lambda C, W: project_with(Ks, C, W, p_world), cam_T_imu, world_T_imu)


@exercise_check
def check_project(project, hidden=False):
    """Exercise 02: ``project(Ks, cam_T_imu, world_T_imu (4, 4 each), p_world (M, 3)) -> z (M, 4)``.

    Pixels ``[uL, vL, uR, vR]``, compared with :meth:`visla_edu.camera.StereoCamera.predict`
    (``rtol=1e-7``, ``atol=1e-6`` px) at the identity and random poses, for points in view from 2 m
    to 300 m. Hides the ``StereoCamera`` methods ``predict``, ``predict_with_jacobians`` and
    ``points_in_camera``, ``camera.stereo_projection``, ``camera.project_points`` and the ``project``
    of ``capstone.library_parts()``.
    """
    name = "project"
    generator, camera = rng(hidden), stereo_camera(hidden)
    imu_T_cam = camera.imu_T_cam
    call = student(project, name, hide=[cam.StereoCamera.predict, cam.StereoCamera.predict_with_jacobians,
                                        cam.StereoCamera.points_in_camera, capstone._project, cam.stereo_projection,
                                        cam.project_points])
    for trial in range(6 if hidden else 4):
        world_T_imu = np.eye(4) if trial == 0 else random_pose(generator)
        M = 1 if hidden and trial == 1 else 12
        p_world = points_in_view(generator, world_T_imu, imu_T_cam, M, depth=(2.0, 300.0 if trial == 3 else 60.0))
        got = as_array(call(camera.Ks, camera.cam_T_imu, world_T_imu, p_world), name, (M, 4))
        compare(name, got, camera.predict(world_T_imu, p_world), f"for a random pose and {M} points in view",
                _project_variants(camera.Ks, camera.cam_T_imu, imu_T_cam, world_T_imu, p_world)
                + notebook_rig_variant(hidden, lambda: stereo_camera().predict(world_T_imu, p_world)),
                rtol=1e-7, atol=1e-6)
    ok(f"{name}: pixels agree with StereoCamera.predict at 4 poses, points from 2 m to 300 m", hidden)


@exercise_check
def check_triangulate(triangulate, hidden=False):
    """Exercise 02: ``triangulate(z (M, 4), K, b) -> (M, 3)`` points in the left camera (disparity form).

    From the exact pixels ``[uL, vL, uR, vR]`` of points at 1.5 to 120 m (hidden: to 400 m), for the
    calibrations ``K`` (3, 3), ``b`` (m) of :func:`check_stereo_matrix`; compares with the true points
    (``rtol=atol=1e-6``). Hides ``camera.triangulate_disparity`` and ``camera.triangulate_bearing``.
    """
    name = "triangulate"
    generator = rng(hidden)
    call = student(triangulate, name, hide=[cam.triangulate_disparity, cam.triangulate_bearing])
    for K, b in _calibrations(generator, hidden):
        d = generator.uniform(1.5, 400.0 if hidden else 120.0, 10)
        p = np.stack([generator.uniform(-0.8, 0.8, 10) * d, generator.uniform(-0.3, 0.3, 10) * d, d], axis=1)
        z = cam.projection(np.c_[p, np.ones(10)]) @ cam.stereo_matrix(K, b).T
        got = as_array(call(z, K, b), name, (10, 3))
        compare(name, got, p, f"for fsu = {K[0, 0]:.1f} px, b = {b:.3f} m", [
            ("disparity sign: depth = fsu b / (uL - uR)\nthe disparity uL - uR is positive for points in front",
             lambda: -p),
            ("depth uses the wrong focal length or units\ndepth = fsu * b / disparity (fsu in px, b in m)",
             lambda: cam.triangulate_disparity(z, K, b) / K[0, 0]),
            ("x and y are not scaled by the depth\nx = (uL - cu) * depth / fsu, y = (vL - cv) * depth / fsv",
             lambda: np.c_[(z[:, 0] - K[0, 2]) / K[0, 0], (z[:, 1] - K[1, 2]) / K[1, 1], p[:, 2]]),
            ("x and y used the same focal length: y = (vL - cv) * depth / fsv",
             lambda: np.c_[p[:, 0], (z[:, 1] - K[1, 2]) * p[:, 2] / K[0, 0], p[:, 2]]),
        ], rtol=1e-6, atol=1e-6)
    ok(f"{name}: recovers points from 1.5 m to 120 m for 4 calibrations", hidden)


def _init_variants(p_cam, imu_T_cam, T):
    """The deliberate mistakes of ``init_landmark``: (hint, callable) pairs."""
    p_h = np.r_[p_cam, 1.0]
    transposed = [lambda: (rotation_transposed(T) @ imu_T_cam @ p_h)[:3],
                  lambda: (T @ rotation_transposed(imu_T_cam) @ p_h)[:3],
                  lambda: (rotation_transposed(T) @ rotation_transposed(imu_T_cam) @ p_h)[:3]]
    return [
        ("the point is still in the camera frame\nmap it with world_T_imu @ imu_T_cam", lambda: p_cam),
        ("the point is in the IMU frame: also apply world_T_imu", lambda: (imu_T_cam @ p_h)[:3]),
        ("you used cam_T_imu (the inverse of imu_T_cam)\nworld_T_cam = world_T_imu @ imu_T_cam",
         lambda: (T @ lie.se3_inv(imu_T_cam) @ p_h)[:3]),
        ("you used inv(world_T_imu)\nworld_T_cam = world_T_imu @ imu_T_cam",
         lambda: (lie.se3_inv(T) @ imu_T_cam @ p_h)[:3]),
    ] + [(TRANSPOSED_R_HINT, variant) for variant in transposed]


@exercise_check
def check_init_landmark(init_landmark, hidden=False):
    """Exercise 05: ``init_landmark(z (4,), K, b, imu_T_cam, world_T_imu) -> (3,)`` world point.

    From one noise-free observation of a landmark at 2 to 60 m (hidden: to 200 m), ``K`` (3, 3) and
    ``b`` (m), at the identity and random poses; compares with the true landmark (``rtol=atol=1e-6``).
    Hides ``StereoCamera.triangulate``, ``ekf.initialize_landmarks`` and the ``init_landmark`` of
    ``capstone.library_parts()``.
    """
    name = "init_landmark"
    generator, (K, b, imu_T_cam), camera = rng(hidden), rig(hidden), stereo_camera(hidden)
    call = student(init_landmark, name, hide=[cam.StereoCamera.triangulate, ekf.initialize_landmarks,
                                              capstone._init_landmark])
    for trial in range(6 if hidden else 4):
        T = np.eye(4) if trial == 0 else random_pose(generator)
        m = points_in_view(generator, T, imu_T_cam, 1, depth=(2.0, 200.0 if hidden else 60.0))[0]
        z = camera.predict(T, m[None])[0]
        got = as_array(call(z, K, b, imu_T_cam, T), name, (3,))
        p_cam = cam.triangulate_disparity(z, K, b)
        compare(name, got, m, f"for z = {fmt(z)}", _init_variants(p_cam, imu_T_cam, T) + notebook_rig_variant(
            hidden, lambda: (T @ rig()[2] @ np.r_[cam.triangulate_disparity(z, *rig()[:2]), 1.0])[:3]),
            rtol=1e-6, atol=1e-6)
    ok(f"{name}: triangulated points land on the true landmarks in the world frame", hidden)
