"""Checks of notebooks 03 and 05 (Jacobians): dpi/dq, odot, a gradient checker, pose and landmark Jacobians."""

import numpy as np

from visla_edu import camera as cam
from visla_edu import lie
from visla_edu.course import capstone, numdiff
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, fmt, ok, rng, student
from visla_edu.course.checks._inputs import (notebook_rig_variant, points_in_view, random_pose, stereo_camera,
                                      transposed_rotation_variants)

__all__ = [
    "reference_numerical_jacobian",
    "check_projection_jacobian",
    "check_odot",
    "check_numerical_jacobian",
    "check_pose_jacobian",
    "check_landmark_jacobian",
]

#: The central-difference Jacobian the gradient-checker exercise is compared with.
reference_numerical_jacobian = numdiff.central_jacobian


@exercise_check
def check_projection_jacobian(projection_jacobian, hidden=False):
    """Exercise 03: ``projection_jacobian(q (4,)) -> dpi/dq (4, 4)`` of ``pi(q) = q / q3``.

    At random camera-frame ``q = [x, y, z, 1]`` with depths 1 to 50 (hidden: also depths 1e-3 and 500
    and ``q4 = 0.5``); compares with :func:`visla_edu.camera.projection_jacobian` (``rtol=1e-7``,
    ``atol=1e-12``), which it hides.
    """
    name = "projection_jacobian"
    generator = rng(hidden)
    call = student(projection_jacobian, name, hide=[cam.projection_jacobian])
    cases = [np.r_[generator.normal(size=2) * 5, generator.uniform(1, 50), 1.0] for _ in range(6)]
    if hidden:
        cases += [np.array([0.0, 0.0, 1e-3, 1.0]), np.array([3.0, -2.0, 500.0, 1.0]), np.array([1.0, 2.0, 4.0, 0.5])]
    for q in cases:
        got = as_array(call(q), name, (4, 4))
        ref = cam.projection_jacobian(q)
        compare(name, got, ref, f"at q = {fmt(q)}", [
            ("the Jacobian is transposed: row i holds the derivatives of pi_i", lambda: ref.T),
            ("the 1/q3 factor in front of the matrix is missing", lambda: ref * q[2]),
            ("the third column has the wrong sign: d(q1/q3)/dq3 = -q1/q3^2",
             lambda: ref * np.array([1.0, 1.0, -1.0, 1.0])),
            ("the last row is wrong: pi_4 = q4/q3 depends on q3 and q4\nit is [0, 0, -q4/q3^2, 1/q3]",
             lambda: np.r_[ref[:3], [np.zeros(4)]]),
        ], rtol=1e-7, atol=1e-12)
    ok(f"{name}: agrees with the library (and so with finite differences)", hidden)


@exercise_check
def check_odot(odot, hidden=False):
    """Exercise 03: ``odot(s (4,)) -> (4, 6)`` with ``twist_hat(u) @ s == odot(s) @ u``.

    ``[[I, -hat(s)], [0, 0]]`` at random points ``s = [p, 1]`` (hidden: also the origin and a point of
    size 1e4); compares with :func:`visla_edu.lie.odot`, which it hides.
    """
    name = "odot"
    generator = rng(hidden)
    call = student(odot, name, hide=[lie.odot])
    cases = [np.r_[generator.normal(scale=10, size=3), 1.0] for _ in range(5)]
    if hidden:
        cases += [np.array([0.0, 0.0, 0.0, 1.0]), np.r_[generator.normal(scale=1e4, size=3), 1.0]]
    for s in cases:
        got = as_array(call(s), name, (4, 6))
        ref = lie.odot(s)
        compare(name, got, ref, f"for s = {fmt(s)}", [
            ("the sign of the hat block: s^odot = [[I, -hat(s)], [0, 0]]\nbecause hat(w) s = -hat(s) w",
             lambda: np.c_[ref[:, :3], -ref[:, 3:]]),
            ("the blocks are swapped: the identity block comes first\nwith u = [v; w] (linear first) the "
             "identity block multiplies v", lambda: np.c_[ref[:, 3:], ref[:, :3]]),
        ])
    ok(f"{name}: twist_hat(u) @ s == odot(s) @ u for twists [v; w]", hidden)


def _forward_jacobian(f, x, eps=1e-6):
    f0 = np.asarray(f(x), dtype=float)
    return np.stack([(np.asarray(f(x + eps * e), dtype=float) - f0) / eps for e in np.eye(x.size)], axis=-1)


def _jacobian_cases(generator, hidden):
    """``(f, x, exact Jacobian)`` triples: a linear map and a curved one (hidden: m = 1, n = 1)."""
    A = generator.normal(size=(4, 3))

    def linear(x):
        return A @ x

    def curved(x):
        return np.array([np.exp(3 * x[0]) * x[1], np.sin(2 * x[1]) + x[0] ** 3])

    def one_output(x):
        return np.array([x[0] * x[1] * x[2]])

    def one_input(x):
        return np.array([np.cos(x[0]), x[0] ** 2, 2.0 * x[0]])

    x = np.array([0.7, 1.3])
    exact_curved = np.array([[3 * np.exp(3 * x[0]) * x[1], np.exp(3 * x[0])], [3 * x[0] ** 2, 2 * np.cos(2 * x[1])]])
    if not hidden:
        return [(linear, generator.normal(size=3), A), (curved, x, exact_curved)]
    y, t = np.array([0.5, -1.5, 2.0]), np.array([0.3])
    return [(one_output, y, np.array([[y[1] * y[2], y[0] * y[2], y[0] * y[1]]])),
            (one_input, t, np.array([[-np.sin(t[0])], [2 * t[0]], [2.0]])),
            (linear, generator.normal(size=3), A)]


@exercise_check
def check_numerical_jacobian(numerical_jacobian, hidden=False):
    """Exercise 03: ``numerical_jacobian(f, x (n,), eps=1e-6) -> (m, n)`` by central differences, ``f(x)`` (m,).

    Called as ``numerical_jacobian(f, x)`` (the student's default ``eps``) on maps with known
    Jacobians, which it compares with (``rtol=atol=1e-7``). Hides ``numdiff.central_jacobian``.
    """
    name = "numerical_jacobian"
    call = student(numerical_jacobian, name, hide=[numdiff.central_jacobian])
    for f, x, exact in _jacobian_cases(rng(hidden), hidden):
        got = as_array(call(f, x), name, exact.shape)
        compare(name, got, exact, f"for f = {f.__name__} at x = {fmt(x)}", [
            ("the Jacobian is transposed\nit has one row per output and one column per input", lambda: exact.T),
            ("central differences divide by 2 eps\n(f(x + eps e_i) - f(x - eps e_i)) / (2 eps)",
             lambda: 2 * exact),
            ("central differences divide by 2 eps, not eps / 2", lambda: 0.5 * exact),
            ("forward differences are only accurate to O(eps): use central ones\n"
             "(f(x + eps) - f(x - eps)) / (2 eps) is accurate to O(eps^2)", lambda: _forward_jacobian(f, x)),
        ], rtol=1e-7, atol=1e-7)
    ok(f"{name}: central differences match the exact Jacobians", hidden)


def _pose_jacobian_with(Ks, cam_T_imu, imu_T_world, m):
    """``-Ks dpi/dq(q) cam_T_imu odot(s)``, ``s = imu_T_world m``, with explicit transforms."""
    s = imu_T_world @ np.r_[m, 1.0]
    q = cam_T_imu @ s
    return -Ks @ cam.projection_jacobian(q) @ cam_T_imu @ lie.odot(s)


_NO_DPI_HINT = ("the derivative of the projection dpi/dq is missing\nz = Ks pi(q) with pi(q) = q / q3, so the "
                "chain rule puts dpi/dq(q) right after Ks (dividing by q3 alone is not its derivative)")


def _no_dpi_variants(Ks, q, rest):
    """``Ks D rest`` with ``D = I`` and ``D = I / q3`` in place of ``dpi/dq(q)``: (hint, callable) pairs."""
    return [(_NO_DPI_HINT, lambda D=D: Ks @ D @ rest) for D in (np.eye(4), np.eye(4) / q[2])]


def _pose_jacobian_variants(camera, mu, m, ref):
    imu_T_world = lie.se3_inv(mu)
    Ks, cam_T_imu = camera.Ks, camera.cam_T_imu
    s = imu_T_world @ np.r_[m, 1.0]
    q = cam_T_imu @ s
    return [
        ("the minus sign is missing\nz = Ks pi(o_T_i exp(-delta^) mu^-1 m), so the Jacobian is "
         "-Ks dpi/dq o_T_i (mu^-1 m)^odot", lambda: -ref),
        ("wrong twist order: the columns must be [d/dv, d/dw] for u = [v; w]",
         lambda: np.c_[ref[:, 3:], ref[:, :3]]),
        ("this is the Jacobian for the left perturbation exp(delta^) mu\nvisla-edu perturbs on the right, "
         "T = mu exp(delta^), so odot acts on the IMU-frame point mu^-1 m",
         lambda: -Ks @ cam.projection_jacobian(q) @ cam_T_imu @ imu_T_world @ lie.odot(np.r_[m, 1.0])),
        ("odot acts on the IMU-frame point mu^-1 m, not on the world point m\nthe Jacobian is "
         "-Ks dpi/dq o_T_i (mu^-1 m)^odot",
         lambda: -Ks @ cam.projection_jacobian(q) @ cam_T_imu @ lie.odot(np.r_[m, 1.0])),
        ("odot has the wrong sign of its hat block\ns^odot = [[I, -hat(s)], [0, 0]] for s = mu^-1 m",
         lambda: -Ks @ cam.projection_jacobian(q) @ cam_T_imu @ (lie.odot(s) * np.r_[1.0, 1, 1, -1, -1, -1])),
    ] + _no_dpi_variants(-Ks, q, cam_T_imu @ lie.odot(s)) + transposed_rotation_variants(
        lambda C, W: _pose_jacobian_with(Ks, C, W, m), cam_T_imu, mu)


@exercise_check
def check_pose_jacobian(pose_jacobian, hidden=False):
    """Exercise 03: ``pose_jacobian(Ks, cam_T_imu, mu, m (3,)) -> (4, 6)`` for ``T = mu exp(delta^)``.

    ``-Ks dpi/dq(q) cam_T_imu odot(inv(mu) m)``, ``mu = world_T_imu``, columns ``[v; w]``, for one world
    landmark ``m`` at 2 to 60 m (hidden: to 200 m): compares with
    :meth:`visla_edu.camera.StereoCamera.jacobian_pose` (``rtol=1e-6``, ``atol=1e-8``). Hides it,
    ``StereoCamera.predict_with_jacobians``, ``camera.stereo_projection``, ``camera.project_points``
    and the ``pose_jacobian`` of ``capstone.library_parts()``.
    """
    name = "pose_jacobian"
    generator, camera = rng(hidden), stereo_camera(hidden)
    call = student(pose_jacobian, name, hide=[cam.StereoCamera.jacobian_pose, cam.StereoCamera.predict_with_jacobians,
                                              capstone._pose_jacobian, cam.stereo_projection,
                                              cam.project_points])
    for trial in range(6 if hidden else 4):
        mu = np.eye(4) if trial == 0 else random_pose(generator)
        m = points_in_view(generator, mu, camera.imu_T_cam, 1, depth=(2.0, 200.0 if hidden else 60.0))[0]
        got = as_array(call(camera.Ks, camera.cam_T_imu, mu, m), name, (4, 6))
        ref = camera.jacobian_pose(mu, m[None])[0]
        compare(name, got, ref, f"for a random pose and m = {fmt(m)}", _pose_jacobian_variants(camera, mu, m, ref)
                + notebook_rig_variant(hidden, lambda: stereo_camera().jacobian_pose(mu, m[None])[0]),
                rtol=1e-6, atol=1e-8)
    ok(f"{name}: agrees with the library (and so with finite differences of mu exp(delta^))", hidden)


def _landmark_jacobian_with(Ks, cam_T_imu, imu_T_world, m):
    """``Ks dpi/dq(q) cam_T_imu imu_T_world P^T`` with explicit transforms."""
    q = cam_T_imu @ imu_T_world @ np.r_[m, 1.0]
    return Ks @ cam.projection_jacobian(q) @ cam_T_imu @ imu_T_world[:, :3]


def _landmark_jacobian_variants(camera, T, m, ref):
    imu_T_world = lie.se3_inv(T)
    Ks, cam_T_imu = camera.Ks, camera.cam_T_imu
    q = cam_T_imu @ imu_T_world @ np.r_[m, 1.0]
    return [
        ("you used world_T_imu where inv(world_T_imu) is needed\nthe chain rule ends with "
         "inv(world_T_imu) P^T = [R^T; 0]", lambda: Ks @ cam.projection_jacobian(q) @ cam_T_imu @ T[:, :3]),
        ("Ks is missing: z = Ks pi(q), so the Jacobian starts with Ks dpi/dq",
         lambda: cam.projection_jacobian(q) @ cam_T_imu @ imu_T_world[:, :3]),
        ("the sign is flipped: the landmark enters with a plus sign", lambda: -ref),
    ] + _no_dpi_variants(Ks, q, cam_T_imu @ imu_T_world[:, :3]) + transposed_rotation_variants(
        lambda C, W: _landmark_jacobian_with(Ks, C, W, m), cam_T_imu, T)


@exercise_check
def check_landmark_jacobian(landmark_jacobian, hidden=False):
    """Exercise 05: ``landmark_jacobian(Ks, cam_T_imu, world_T_imu, m (3,)) -> (4, 3)``.

    ``Ks dpi/dq(q) cam_T_imu inv(world_T_imu) P^T``: compares with
    :meth:`visla_edu.camera.StereoCamera.jacobian_landmark` (``rtol=1e-6``, ``atol=1e-9``); a 4x4
    result fails at once. Hides it, ``StereoCamera.predict_with_jacobians``,
    ``camera.stereo_projection``, ``camera.project_points`` and the ``landmark_jacobian`` of
    ``capstone.library_parts()``.
    """
    name = "landmark_jacobian"
    generator, camera = rng(hidden), stereo_camera(hidden)
    call = student(landmark_jacobian, name, hide=[cam.StereoCamera.jacobian_landmark,
                                                  cam.StereoCamera.predict_with_jacobians,
                                                  capstone._landmark_jacobian, cam.stereo_projection,
                                                  cam.project_points])
    for trial in range(6 if hidden else 4):
        T = np.eye(4) if trial == 0 else random_pose(generator)
        m = points_in_view(generator, T, camera.imu_T_cam, 1, depth=(2.0, 200.0 if hidden else 60.0))[0]
        out = call(camera.Ks, camera.cam_T_imu, T, m)
        if np.shape(out) == (4, 4):
            raise fail(name, "got a 4x4 matrix; multiply by P^T = [I; 0] (4x3) on the right",
                       "the landmark has 3 coordinates (its homogeneous 1 is not a variable)")
        got = as_array(out, name, (4, 3))
        ref = camera.jacobian_landmark(T, m[None])[0]
        compare(name, got, ref, f"for m = {fmt(m)}", _landmark_jacobian_variants(camera, T, m, ref)
                + notebook_rig_variant(hidden, lambda: stereo_camera().jacobian_landmark(T, m[None])[0]),
                rtol=1e-6, atol=1e-9)
    ok(f"{name}: agrees with the library at 4 poses", hidden)
