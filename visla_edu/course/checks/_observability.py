"""Checks of the unobservable directions: the joint SLAM null space (08), the invariant pose Jacobian (10).

Moving the whole world (every pose and landmark) by one rigid motion leaves every pixel unchanged:
the joint Jacobian ``H`` maps these six directions to zero. In the right perturbation they depend on
the estimate (``Ad(inv(mu))`` and ``hat(m_j)`` in the null space ``N``); in the invariant error not.
"""

import numpy as np

from visla_edu import ekf, lie
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, ok, rng, student
from visla_edu.course.checks._inputs import notebook_rig_variant, points_in_view, random_pose, stereo_camera

__all__ = ["reference_slam_null_space", "check_slam_null_space", "check_invariant_pose_jacobian"]


def reference_slam_null_space(world_T_imu, p_landmarks):
    """The state directions ``[[Ad(inv(mu))]; [I, -hat(m_1)]; ...; [I, -hat(m_n)]]`` of moving the whole world.

    Column ``k``: the first-order change of the right-perturbation state ``[delta; m_1; ...; m_n]``
    when every pose and landmark is moved by ``exp(hat(eps))`` on the left (in the world frame),
    ``eps = e_k = [eps_v; eps_w]``: ``exp(hat(eps)) T = T exp(hat(Ad(inv(T)) eps))`` and
    ``exp(hat(eps)) m ~ m + eps_v + eps_w x m``.

    Parameters
    ----------
    world_T_imu : ndarray, shape (4, 4)
        The pose estimate ``mu``.
    p_landmarks : ndarray, shape (n, 3)
        The landmark estimates, in state order.

    Returns
    -------
    ndarray, shape (6 + 3 n, 6)
    """
    p_landmarks = np.asarray(p_landmarks, dtype=float).reshape(-1, 3)
    return np.vstack([lie.adjoint(lie.se3_inv(world_T_imu))] + [_landmark_rows(m) for m in p_landmarks])


def _landmark_rows(m):
    """A landmark's rows ``[I, -hat(m)]`` (3, 6) of the null space."""
    return np.hstack([np.eye(3), -lie.hat(m)])


def _null_space_variants(T, p):
    """(hint, callable) pairs: the null space of each likely mistake."""
    def with_blocks(pose_block, landmark_block=_landmark_rows):
        return np.vstack([pose_block] + [landmark_block(m) for m in p])

    Ad_inv = lie.adjoint(lie.se3_inv(T))
    return [
        ("the pose block is Ad(inv(mu)), not Ad(mu)\nthe world moves on the left, the perturbation is on "
         "the right: exp(eps^) mu = mu exp((Ad(inv(mu)) eps)^)",
         lambda: with_blocks(lie.adjoint(T))),
        ("the pose block is not the identity\nthe right perturbation is in the body frame: moving the "
         "world by eps moves it by Ad(inv(mu)) eps", lambda: with_blocks(np.eye(6))),
        ("the landmark block's hat(m) has the wrong sign\nexp(eps^) m ~ m + eps_v + eps_w x m "
         "= m + [I, -hat(m)] eps", lambda: with_blocks(Ad_inv, lambda m: np.hstack([np.eye(3), lie.hat(m)]))),
        ("wrong twist order in the landmark block: eps = [eps_v; eps_w]\nits columns are [I, -hat(m)]",
         lambda: with_blocks(Ad_inv, lambda m: np.hstack([-lie.hat(m), np.eye(3)]))),
        ("the landmarks move with the world too\neach landmark's rows are [I, -hat(m_j)], not zero",
         lambda: with_blocks(Ad_inv, lambda m: np.zeros((3, 6)))),
        ("the landmark rows use the point in the IMU frame\nthe landmarks are in the world frame: "
         "[I, -hat(m_j)] with m_j itself",
         lambda: with_blocks(Ad_inv, lambda m: _landmark_rows((lie.se3_inv(T) @ np.r_[m, 1.0])[:3]))),
    ]


def _null_space_cases(generator, hidden):
    """``(world_T_imu, p_landmarks)`` of 0, 1, 4 (hidden: 2, 7) landmarks around random poses."""
    counts = (2, 7, 1) if hidden else (0, 1, 4)
    return [(random_pose(generator, scale=20.0), generator.normal(scale=30.0, size=(n, 3))) for n in counts]


@exercise_check
def check_slam_null_space(slam_null_space, hidden=False):
    """Exercise 08: ``slam_null_space(world_T_imu, p_landmarks (n, 3)) -> N (6 + 3n, 6)``.

    Compares with :func:`reference_slam_null_space` (``rtol=atol=1e-9``), which it hides, at the
    identity and random poses; ``lie.adjoint``, ``lie.hat`` and ``lie.se3_inv`` stay.
    """
    name = "slam_null_space"
    call = student(slam_null_space, name, hide=[reference_slam_null_space])
    cases = _null_space_cases(rng(hidden), hidden)
    if not hidden:
        cases.insert(0, (np.eye(4), np.array([[4.0, -2.0, 10.0], [1.0, 3.0, 25.0]])))
    for T, p in cases:
        ref = reference_slam_null_space(T, p)
        got = as_array(call(T, p), name, ref.shape, "null space N")
        pose = "the identity" if np.array_equal(T, np.eye(4)) else "a random"
        compare(name, got, ref, f"for {len(p)} landmark(s) at {pose} pose", _null_space_variants(T, p),
                rtol=1e-9, atol=1e-9)
    ok(f"{name}: N = [Ad(inv(mu)); [I, -hat(m_j)]...], the world's rigid motions, on {len(cases)} states", hidden)


def _invariant_variants(camera, T, m, J_landmark):
    """(hint, callable) pairs: the pose Jacobian of each likely mistake (J_landmark: the right one's block)."""
    zero = np.zeros((4, 3))
    return [
        ("that is the right perturbation's pose Jacobian\nwith T = exp(xi^) mu and m = exp(theta^) mu_m + e "
         "the point seen is inv(mu) (mu_m + e - p): d z / d xi = [-H_lm, 0]",
         lambda: camera.jacobian_pose(T, m[None])[0]),
        ("wrong sign: the pose's p enters as inv(mu) (m + e - p)\nd z / d p = -H_lm",
         lambda: np.hstack([J_landmark, zero])),
        ("the columns are swapped: xi = [p; theta], p first\n[-H_lm, 0], not [0, -H_lm]",
         lambda: np.hstack([zero, -J_landmark])),
        ("the landmark error shares the pose's rotation theta\nm_j = exp(theta^) mu_j + e_j, so theta "
         "cancels in inv(T) m_j: the theta columns are 0", lambda: np.hstack([-J_landmark, J_landmark @ lie.hat(m)])),
    ]


@exercise_check
def check_invariant_pose_jacobian(invariant_pose_jacobian, hidden=False):
    """Exercise 10: ``invariant_pose_jacobian(Ks, cam_T_imu, world_T_imu, m (3,)) -> (4, 6)``.

    ``[-H_lm, 0]`` in the invariant error ``xi = [p; theta]``, ``H_lm`` the landmark Jacobian of
    notebook 05: compares with :func:`visla_edu.ekf.invariant_pose_jacobian` (the derivation;
    hidden) of :meth:`~visla_edu.camera.StereoCamera.jacobian_landmark` (``rtol=1e-6``,
    ``atol=1e-8``), which the student may use for ``H_lm``; ``m`` is a world point.
    """
    name = "invariant_pose_jacobian"
    generator, camera = rng(hidden), stereo_camera(hidden)
    call = student(invariant_pose_jacobian, name, hide=[ekf.invariant_pose_jacobian])
    trials = 6 if hidden else 4
    for trial in range(trials):
        last = trial == trials - 1  # at the identity the right form's Jacobian and a mistake coincide
        T = np.eye(4) if last else random_pose(generator)
        m = points_in_view(generator, T, camera.imu_T_cam, 1)[0]
        J_landmark = camera.jacobian_landmark(T, m[None])[0]
        ref = ekf.invariant_pose_jacobian(J_landmark[None])[0]
        out = call(camera.Ks, camera.cam_T_imu, T, m)
        if np.shape(out) == (4, 3):
            raise fail(name, "got a 4x3 matrix: the pose error xi = [p; theta] has 6 columns",
                       "the p columns are -H_lm, the theta columns zero")
        got = as_array(out, name, (4, 6))
        visible = stereo_camera()
        compare(name, got, ref, f"for {'the identity' if last else 'a random'} pose and m = {np.round(m, 3)}",
                _invariant_variants(camera, T, m, J_landmark) + notebook_rig_variant(hidden, lambda: (
                    ekf.invariant_pose_jacobian(visible.jacobian_landmark(T, m[None]))[0])),
                rtol=1e-6, atol=1e-8)
    ok(f"{name}: [-H_lm, 0] on {trials} poses: the pixels do not see the shared rotation theta", hidden)
