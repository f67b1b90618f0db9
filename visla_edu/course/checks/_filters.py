"""Checks of notebooks 05, 07-09 (the EKF): landmark and pose updates, observation noise, the joint Jacobian, memory,
marginals."""

import numpy as np

from visla_edu import camera as cam
from visla_edu import ekf, lie
from visla_edu.course import capstone, kalman
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, ok, rng, student
from visla_edu.course.checks._inputs import (not_se3, notebook_rig_variant, points_in_view, random_covariance,
                                      random_pose, stereo_camera, swap_twist, transposed_rotation_variants)

__all__ = [
    "check_landmark_update",
    "check_pose_update",
    "check_landmark_observation_noise",
    "check_slam_jacobian",
    "check_dense_covariance_bytes",
    "reference_dense_covariance_bytes",
    "check_marginalize",
]

#: The visla-edu state is [pose (6); landmarks (3 each)].
_POSE_DIM = 6


def _landmark_update_with(m, Sigma, z, imu_T_world, Ks, cam_T_imu, noise_var):
    """One EKF update of a landmark with explicit transforms: ``(m_new (3,), Sigma_new (3, 3))``."""
    q = cam_T_imu @ imu_T_world @ np.r_[m, 1.0]
    H = Ks @ cam.projection_jacobian(q) @ cam_T_imu @ imu_T_world[:, :3]
    gain = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(4))
    return m + gain @ (z - Ks @ cam.projection(q)), (np.eye(3) - gain @ H) @ Sigma


def _landmark_update_reference(m, Sigma, z, T, camera, noise_var):
    """The library's single-landmark update (mean (3,), covariance (3, 3))."""
    m_new, S_new = ekf.landmark_update(m[None], Sigma[None], z[None], T, camera, noise_var)
    return m_new[0], S_new[0]


_SQUARED_NOISE_HINT = ("noise_var is a variance: S gets noise_var I, not noise_var^2 I\n"
                       "S = H Sigma H^T + noise_var I; noise_var is already sigma^2 (pixels squared)")


def _landmark_mean_variants(m, Sigma, z, T, camera, noise_var):
    flipped_z = 2 * camera.predict(T, m[None])[0] - z
    Ks, cam_T_imu = camera.Ks, camera.cam_T_imu
    return [
        ("the innovation must be z - z_pred (observed minus predicted)",
         lambda: _landmark_update_reference(m, Sigma, flipped_z, T, camera, noise_var)[0]),
        ("the mean did not move: add K (z - z_pred)", lambda: m),
        (_SQUARED_NOISE_HINT,
         lambda: _landmark_update_with(m, Sigma, z, lie.se3_inv(T), Ks, cam_T_imu, noise_var**2)[0]),
    ] + transposed_rotation_variants(lambda C, W: _landmark_update_with(m, Sigma, z, W, Ks, C, noise_var)[0],
                                     cam_T_imu, T)


def _landmark_covariance_variants(m, Sigma, T, camera, noise_var):
    H = camera.jacobian_landmark(T, m[None])[0]
    gain = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(4))
    return [
        ("Sigma_new = (I - L H) Sigma, with a minus sign", lambda: (np.eye(3) + gain @ H) @ Sigma),
        ("the covariance did not change: Sigma_new = (I - L H) Sigma", lambda: Sigma),
        ("the observation noise is missing from S = H Sigma H^T + noise_var I",
         lambda: Sigma - Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T) @ H @ Sigma),
    ]


def _pair(out, name, what):
    if not isinstance(out, tuple) or len(out) != 2:
        raise fail(name, f"must return a tuple {what}, got {type(out).__name__}")
    return out


@exercise_check
def check_landmark_update(landmark_update, hidden=False):
    """Exercise 05: ``landmark_update(m, Sigma, z, world_T_imu, Ks, cam_T_imu, noise_var) -> (m, Sigma)``.

    ``m`` (3,), ``Sigma`` (3, 3), ``z`` (4,), ``noise_var`` in px^2. A landmark at 4 to 40 m seen with
    2 px noise, a prior mean 1 m off: the tuple must agree with :func:`visla_edu.ekf.landmark_update`
    (mean ``rtol=atol=1e-6``; covariance ``rtol=1e-6``, ``atol=1e-8``). Hides it, ``ekf.joint_update``,
    ``ekf.cholesky_update`` and ``kalman.update``.
    """
    name = "landmark_update"
    generator, camera = rng(hidden), stereo_camera(hidden)
    call = student(landmark_update, name, hide=[ekf.landmark_update, ekf.joint_update, ekf.cholesky_update,
                                                                 kalman.update])
    noise_var = 1.0 if hidden else 4.0
    for trial in range(6 if hidden else 4):
        T = random_pose(generator)
        m_true = points_in_view(generator, T, camera.imu_T_cam, 1, depth=(4.0, 40.0))[0]
        z = camera.predict(T, m_true[None])[0] + generator.normal(scale=2.0, size=4)
        m = m_true + generator.normal(scale=1.0, size=3)
        A = generator.normal(size=(3, 3))
        Sigma = A @ A.T + np.eye(3)
        out = _pair(call(m, Sigma, z, T, camera.Ks, camera.cam_T_imu, noise_var), name, "(m_new, Sigma_new)")
        m_ref, S_ref = _landmark_update_reference(m, Sigma, z, T, camera, noise_var)
        compare(name, as_array(out[0], name, (3,), "mean"), m_ref, "(mean)",
                _landmark_mean_variants(m, Sigma, z, T, camera, noise_var) + notebook_rig_variant(
                    hidden, lambda: _landmark_update_reference(m, Sigma, z, T, stereo_camera(), noise_var)[0]),
                rtol=1e-6, atol=1e-6)
        compare(name, as_array(out[1], name, (3, 3), "covariance"), S_ref, "(covariance)",
                _landmark_covariance_variants(m, Sigma, T, camera, noise_var), rtol=1e-6, atol=1e-8)
    ok(f"{name}: mean and covariance agree with ekf.landmark_update", hidden)


def _pose_update_with(mu, Sigma, z, p_world, Ks, cam_T_imu, noise_var, imu_T_world=None, side="right", sign=1.0,
                      swap=False, order="C"):
    """The visual pose update from its formula (the reference); its keywords make the mistakes.

    ``order="F"`` stacks the innovation column by column (all uL first), unlike ``H``.
    """
    imu_T_world = lie.se3_inv(mu) if imu_T_world is None else imu_T_world
    s = np.c_[p_world, np.ones(len(p_world))] @ imu_T_world.T  # (k, 4) landmarks in the IMU frame
    q = s @ cam_T_imu.T
    H = (-Ks @ cam.projection_jacobian(q) @ cam_T_imu @ lie.odot(s)).reshape(-1, _POSE_DIM)
    gain = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(len(H)))
    delta = sign * gain @ (z - cam.projection(q) @ Ks.T).ravel(order=order)
    delta = swap_twist(delta) if swap else delta  # the correction read as [w; v]
    mu_new = mu @ lie.se3_exp(delta) if side == "right" else lie.se3_exp(delta) @ mu
    return mu_new, (np.eye(_POSE_DIM) - gain @ H) @ Sigma


#: ``noise_var`` of the pose-update cases: a function that ignores its argument fails.
_POSE_NOISE_VARS = (4.0, 1.0, 9.0, 2.25, 0.25)

_NOISE_HINT = ("the pixel noise is not the argument noise_var\nS = H Sigma H^T + noise_var I: noise_var is "
               "already a variance (do not square it or take its root), and it changes from call to call")


def _pose_mean_variants(mu, Sigma, z, p_world, camera, noise_var):
    args = (mu, Sigma, z, p_world, camera.Ks, camera.cam_T_imu, noise_var)
    return [
        ("the correction is applied on the left; use mu_new = mu @ se3_exp(L r)\n"
         "with the right perturbation T = mu exp(delta^) the correction K (z - z_pred) multiplies mu "
         "on the right",
         lambda: _pose_update_with(*args, side="left")[0]),
        ("the correction has the wrong sign\ncheck the minus sign of the pose Jacobian "
         "(-Ks dpi/dq o_T_i (mu^-1 m)^odot) and the innovation z - z_pred",
         lambda: _pose_update_with(*args, sign=-1.0)[0]),
        ("the pose did not move", lambda: mu),
        ("wrong twist order: the correction L r is [v; w] (linear first), as se3_exp expects",
         lambda: _pose_update_with(*args, swap=True)[0]),
        ("the innovation is not stacked like H: use (z - z_pred).ravel()\n"
         "H stacks the observations one after the other (4 rows each: uL, vL, uR, vR of observation "
         "1, then of observation 2, ...); (z - z_pred).T.ravel() or .ravel('F') puts all uL first",
         lambda: _pose_update_with(*args, order="F")[0]),
    ] + [(_NOISE_HINT, lambda r=r: _pose_update_with(*args[:-1], r)[0])
         for r in (noise_var ** 2, np.sqrt(noise_var), 4.0) if r != noise_var
         ] + transposed_rotation_variants(
        lambda C, W: _pose_update_with(*args[:5], C, noise_var, imu_T_world=W)[0], camera.cam_T_imu, mu)


@exercise_check
def check_pose_update(pose_update, hidden=False):
    """Exercise 07: ``pose_update(mu, Sigma, z (k, 4), p_world (k, 3), Ks, cam_T_imu, noise_var) -> (mu, Sigma)``.

    Compares with the update written out here (``H`` stacked over the observations, ``L = Sigma
    H^T (H Sigma H^T + noise_var I)^-1``, ``mu exp(L r)``, ``(I - L H) Sigma``; mean ``rtol=1e-6``,
    ``atol=1e-7``; covariance ``rtol=1e-6``, ``atol=1e-10``), ``noise_var`` (px^2) changing from case
    to case, ``Sigma`` (6, 6) that of the right perturbation. Hides ``ekf.pose_update``,
    ``ekf.joint_update``, ``ekf.cholesky_update``, ``kalman.update`` and the ``pose_update`` of
    ``capstone.library_parts()``.
    """
    name = "pose_update"
    generator, camera = rng(hidden), stereo_camera(hidden)
    call = student(pose_update, name, hide=[ekf.pose_update, ekf.joint_update, ekf.cholesky_update,
                                            kalman.update, capstone._pose_update])
    for trial, noise_var in enumerate(_POSE_NOISE_VARS[:5 if hidden else 3]):
        k = 1 if hidden and trial == 0 else 8
        T_true = random_pose(generator)
        p_world = points_in_view(generator, T_true, camera.imu_T_cam, k, depth=(4.0, 40.0))
        z = camera.predict(T_true, p_world) + generator.normal(scale=1.0, size=(k, 4))
        A = generator.normal(size=(6, 6)) * 0.05
        Sigma = A @ A.T + 1e-3 * np.eye(6)
        mu = T_true @ lie.se3_exp(generator.multivariate_normal(np.zeros(6), Sigma))
        args = (mu, Sigma, z, p_world, camera.Ks, camera.cam_T_imu, noise_var)
        out = _pair(call(*args), name, "(mu_new, Sigma_new)")
        mu_ref, S_ref = _pose_update_with(*args)
        compare(name, as_array(out[0], name, (4, 4), "pose"), mu_ref,
                f"(pose mean, {k} observations, noise_var = {noise_var})",
                _pose_mean_variants(mu, Sigma, z, p_world, camera, noise_var) + notebook_rig_variant(
                    hidden, lambda c=stereo_camera(): _pose_update_with(*args[:4], c.Ks, c.cam_T_imu, noise_var)[0]),
                rtol=1e-6, atol=1e-7, extra=not_se3)
        compare(name, as_array(out[1], name, (6, 6), "covariance"), S_ref, "(covariance)", [
            ("the covariance did not change: Sigma_new = (I - L H) Sigma", lambda: Sigma),
        ], rtol=1e-6, atol=1e-10)
    ok(f"{name}: pose and covariance agree with the reference update mu exp(L r), (I - L H) Sigma", hidden)


def _observation_noise_cases(generator, hidden):
    """``(J_landmark (k, 4, 3), Sigma_landmark (k, 3, 3), noise_var)``: Jacobians of landmarks in view."""
    camera = stereo_camera(hidden)
    cases = []
    for k, noise_var in (((1, 2.25), (6, 0.25), (3, 4.0)) if hidden else ((5, 1.0), (2, 4.0))):
        T = random_pose(generator)
        p_world = points_in_view(generator, T, camera.imu_T_cam, k, depth=(3.0, 80.0))
        J_landmark = camera.jacobian_landmark(T, p_world)
        Sigma_landmark = np.stack([random_covariance(generator, 3) * generator.uniform(0.01, 0.5) for _ in range(k)])
        cases.append((J_landmark, Sigma_landmark, noise_var))
    return cases


def _observation_noise_variants(J, Sigma, noise_var):
    Jt = np.swapaxes(J, 1, 2)
    I4 = np.eye(4)
    return [
        ("the landmarks are not exact: add H_lm Sigma_m H_lm^T\nthe pixel noise alone treats every landmark "
         "as exactly known", lambda: np.broadcast_to(noise_var * I4, (len(J), 4, 4))),
        ("add the pixel noise noise_var * I4 too\nthe observation has its own noise besides the landmark's "
         "uncertainty", lambda: J @ Sigma @ Jt),
        ("noise_var is already a variance: do not square it", lambda: J @ Sigma @ Jt + noise_var**2 * I4),
        ("use noise_var itself, not its square root\nnoise_var is already a variance",
         lambda: J @ Sigma @ Jt + np.sqrt(noise_var) * I4),
        ("use the landmark's covariance, not its inverse\nH_lm Sigma_m H_lm^T + noise_var I",
         lambda: J @ np.linalg.inv(Sigma) @ Jt + noise_var * I4),
    ]


@exercise_check
def check_landmark_observation_noise(landmark_observation_noise, hidden=False):
    """Exercise 07: ``landmark_observation_noise(J_landmark (k, 4, 3), Sigma_landmark (k, 3, 3), noise_var) -> (k, 4, 4)``.

    ``noise_var I4 + H_i Sigma_i H_i^T`` per observation, the pixel noise plus the landmark's
    uncertainty seen in the image: compares with :func:`visla_edu.ekf.innovation_covariances`
    (``rtol=1e-9``, ``atol=1e-12``; ``noise_var`` in px^2). Hides it and :func:`visla_edu.ekf.pose_update`.
    """
    name = "landmark_observation_noise"
    call = student(landmark_observation_noise, name, hide=[ekf.innovation_covariances, ekf.pose_update])
    for J, Sigma, noise_var in _observation_noise_cases(rng(hidden), hidden):
        k = len(J)
        got = as_array(call(J, Sigma, noise_var), name, (k, 4, 4), "noise covariances")
        ref = ekf.innovation_covariances(None, J, None, None, Sigma, noise_var)
        compare(name, got, ref, f"for {k} observation(s), noise_var = {noise_var}",
                _observation_noise_variants(J, Sigma, noise_var), rtol=1e-9, atol=1e-12)
    ok(f"{name}: noise_var I + H_lm Sigma_m H_lm^T for every observation", hidden)


def _slam_jacobian_reference(J_pose, J_landmark, slots, n_landmarks, pose_first=True, offset=_POSE_DIM):
    """``H`` (4k, 6 + 3n); mistakes put the pose columns last (not ``pose_first``) or the landmarks at ``offset``."""
    H = np.zeros((4 * len(slots), _POSE_DIM + 3 * n_landmarks))
    pose_columns = slice(0, _POSE_DIM) if pose_first else slice(3 * n_landmarks, None)
    offset = offset if pose_first else 0
    for i, s in enumerate(slots):
        H[4 * i:4 * i + 4, pose_columns] = J_pose[i]
        H[4 * i:4 * i + 4, offset + 3 * s: offset + 3 * s + 3] = J_landmark[i]
    return H


@exercise_check
def check_slam_jacobian(slam_jacobian, hidden=False):
    """Exercise 08: ``slam_jacobian(J_pose (k,4,6), J_landmark (k,4,3), slots (k,), n) -> H (4k, 6+3n)``.

    ``H`` must equal exactly the matrix with rows ``4 i .. 4 i + 3`` holding ``J_pose[i]`` in
    columns 0-5 and ``J_landmark[i]`` in columns ``6 + 3 slots[i] .. 6 + 3 slots[i] + 2``, zero
    elsewhere (``n`` landmarks in the state). Hides ``ekf.slot_columns`` and the ``slam_jacobian`` of
    ``capstone.library_parts()``.
    """
    name = "slam_jacobian"
    generator = rng(hidden)
    call = student(slam_jacobian, name, hide=[ekf.slot_columns, capstone._slam_jacobian])
    cases = [(5, [3, 0]), (9, [8, 2, 5, 6]), (1, [0])]
    if hidden:
        cases = [(12, [11, 0, 4]), (3, [2, 1, 0]), (20, [19])]
    for n, slots in cases:
        slots = np.array(slots, dtype=int)
        J_pose = generator.normal(size=(len(slots), 4, 6))
        J_landmark = generator.normal(size=(len(slots), 4, 3))
        ref = _slam_jacobian_reference(J_pose, J_landmark, slots, n)
        got = as_array(call(J_pose, J_landmark, slots, n), name, ref.shape)
        compare(name, got, ref, f"for slots {slots.tolist()} of {n} landmarks", [
            ("the pose columns come first: the state is [pose (6); landmarks (3n)]\n"
             "(Javadi's course report orders it [landmarks; pose])",
             lambda: _slam_jacobian_reference(J_pose, J_landmark, slots, n, pose_first=False)),
            ("landmark slot s occupies columns 6 + 3 s ... 6 + 3 s + 2\n(after the 6 pose columns)",
             lambda: _slam_jacobian_reference(J_pose, J_landmark, slots, n, offset=0)),
        ], atol=0)
    ok(f"{name}: H has the pose block first and each landmark in its slot's columns", hidden)


def reference_dense_covariance_bytes(num_landmarks, stride=1):
    """Bytes ``(6 + 3 n)^2 * 8`` of the dense float64 joint covariance, ``n = ceil(num_landmarks / stride)``.

    Landmarks ``0, stride, 2 stride, ...`` of the drive's ``num_landmarks`` are kept; ``ValueError`` if
    ``num_landmarks`` is not a non-negative integer or ``stride`` not a positive one. Notebook 09's
    fallback when the exercise is not finished (hidden while its check runs).
    """
    hints = {"num_landmarks": "a non-negative integer", "stride": "a positive integer (1 keeps every landmark)"}
    for name, value, low in (("num_landmarks", num_landmarks, 0), ("stride", stride, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be {hints[name]}, got {value!r}")
    n = len(range(0, num_landmarks, stride))
    return (_POSE_DIM + 3 * n) ** 2 * 8



@exercise_check
def check_dense_covariance_bytes(dense_covariance_bytes, hidden=False):
    """Exercise 09: ``dense_covariance_bytes(num_landmarks, stride=1) -> int`` for float64.

    Compares with :func:`reference_dense_covariance_bytes` (hidden) to within half a byte. The
    success line prints the sizes for 5105 and 13289 landmarks.
    """
    name = "dense_covariance_bytes"
    cases = [(5105, 1), (13289, 1), (5105, 10), (13289, 20), (7, 3), (1, 1)]
    if hidden:  # edge cases, then cases drawn from the teacher's seed
        generator = rng(hidden)
        cases = [(100, 7), (3, 5), (0, 1), (2, 1), (40000, 3), (99, 33)] + [
            (int(generator.integers(1, 50000)), int(generator.integers(1, 60))) for _ in range(3)]
    call = student(dense_covariance_bytes, name, hide=[reference_dense_covariance_bytes])
    for M, stride in cases:
        got = call(M, stride)
        n = len(range(0, M, stride))
        compare(name, got, reference_dense_covariance_bytes(M, stride), f"for {M} landmarks with stride {stride}", [
            ("the pose adds 6 dimensions: the state has 6 + 3 n entries", lambda: (3 * n) ** 2 * 8),
            ("a float64 has 8 bytes", lambda: (6 + 3 * n) ** 2 * 4),
            ("a covariance is D x D: square the dimension", lambda: (6 + 3 * n) * 8),
            ("every stride-th landmark gives ceil(M / stride) landmarks, not M // stride\n"
             "landmarks 0, stride, 2 stride, ... are kept", lambda: (6 + 3 * (M // stride)) ** 2 * 8),
            ("each landmark has 3 coordinates", lambda: (6 + n) ** 2 * 8),
        ], rtol=0, atol=0.5)
    gigabytes = [reference_dense_covariance_bytes(M) / 1e9 for M in (5105, 13289)]
    ok(f"{name}: 5105 landmarks -> {gigabytes[0]:.2f} GB, 13289 -> {gigabytes[1]:.1f} GB",
       hidden)


def _marginal_cases(hidden):
    if hidden:
        return [(21, np.r_[0:6, 9:12, 18:21]), (6, np.arange(6)), (12, np.arange(6)), (15, np.r_[0:6, 12:15])]
    return [(12, np.array([0, 1, 2, 3, 4, 5, 9, 10, 11])), (15, np.arange(9)), (9, np.arange(9))]


@exercise_check
def check_marginalize(marginalize, hidden=False):
    """Exercise 09: ``marginalize(Sigma (D, D), keep (indices)) -> Sigma[keep][:, keep]``.

    Compares with ``Sigma[np.ix_(keep, keep)]`` for random covariances. Hides the ``marginalize``
    of ``capstone.library_parts()``.
    """
    name = "marginalize"
    generator = rng(hidden)
    call = student(marginalize, name, hide=[capstone._marginalize])
    for D, keep in _marginal_cases(hidden):
        Sigma = random_covariance(generator, D)
        got = as_array(call(Sigma, keep), name, (len(keep), len(keep)))
        ref = Sigma[np.ix_(keep, keep)]
        drop = np.setdiff1d(np.arange(D), keep)
        conditioned = ref - Sigma[np.ix_(keep, drop)] @ np.linalg.solve(
            Sigma[np.ix_(drop, drop)], Sigma[np.ix_(drop, keep)]) if len(drop) else ref
        compare(name, got, ref, f"keeping {len(keep)} of {D} dimensions", [
            ("this is the Schur complement (conditioning), not the marginal\nmarginalising a Gaussian in "
             "covariance form just deletes the rows and columns of the removed entries", lambda: conditioned),
            ("you inverted twice: marginalise in covariance form\nno information matrix is needed",
             lambda: np.linalg.inv(np.linalg.inv(Sigma)[np.ix_(keep, keep)])),
        ])
    ok(f"{name}: deleting rows and columns, the exact marginal", hidden)
