"""Tests for visla_edu.checks: each check passes the library and names each typical mistake.

For every exercise there is a correct implementation (the library's, adapted to the
exercise's signature) and a list of deliberately wrong ones; each wrong one must fail the
check with an AssertionError whose message contains the expected hint.
"""

import numpy as np
import pytest
from scipy import stats

from visla_edu import camera as cam
from visla_edu import checks, ekf, lie, metrics, motion
from visla_edu.simulate import default_rig

K_RIG, B_RIG, IMU_T_CAM = default_rig()


def _passes(check, fn, capsys):
    check(fn)
    assert capsys.readouterr().out.startswith("\u2713")


def _fails(check, fn, hint):
    with pytest.raises(AssertionError) as info, np.errstate(all="ignore"):
        check(fn)
    assert hint.lower() in str(info.value).lower(), str(info.value)


def _stub(*args, **kwargs):
    raise NotImplementedError("exercise: write your solution here")


# --------------------------------------------------------------------------- 00 data


def observations_at(features, t):
    ids = np.nonzero(features[0, :, t] != -1)[0]
    return ids, features[:, ids, t].T


def track_spans(features):
    seen = features[0] != -1
    out = np.full((features.shape[1], 2), -1)
    for i, row in enumerate(seen):
        frames = np.nonzero(row)[0]
        if len(frames):
            out[i] = frames[0], frames[-1]
    return out


def _spans_argmax(features):
    seen = features[0] != -1
    return np.stack([np.argmax(seen, axis=1), seen.shape[1] - 1 - np.argmax(seen[:, ::-1], axis=1)], axis=1)


def _spans_exclusive(features):
    out = track_spans(features)
    out[out[:, 1] >= 0, 1] += 1
    return out


WRONG = {
    "observations_at": [
        (lambda f, t: (np.arange(f.shape[1]), f[:, :, t].T), "keep only the observed"),
        (lambda f, t: (observations_at(f, t)[0], observations_at(f, t)[1].T), "transposed"),
        (lambda f, t: (observations_at(f, t)[0], observations_at(f, t)[1][:, [0, 2, 1, 3]]), "[uL, vL, uR, vR]"),
    ],
    "track_spans": [
        (_spans_argmax, "never observed"),
        (_spans_exclusive, "off by one"),
        (lambda f: track_spans(f)[:, ::-1], "swapped"),
    ],
}


def test_data_checks(capsys):
    _passes(checks.check_observations_at, observations_at, capsys)
    _passes(checks.check_track_spans, track_spans, capsys)
    for fn, hint in WRONG["observations_at"]:
        _fails(checks.check_observations_at, fn, hint)
    for fn, hint in WRONG["track_spans"]:
        _fails(checks.check_track_spans, fn, hint)


# --------------------------------------------------------------------------- 01 kinematics


def _rodrigues_naive(w):
    t = np.linalg.norm(w)
    W = lie.hat(w)
    return np.eye(3) + np.sin(t) / t * W + (1 - np.cos(t)) / t**2 * W @ W


def _se3_naive(u):
    v, w = u[:3], u[3:]
    t = np.linalg.norm(w)
    W = lie.hat(w)
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(t) / t * W + (1 - np.cos(t)) / t**2 * W @ W
    T[:3, 3] = (np.eye(3) + (1 - np.cos(t)) / t**2 * W + (t - np.sin(t)) / t**3 * W @ W) @ v
    return T


def _se3_v_only(u):
    T = lie.se3_exp(u)
    T[:3, 3] = u[:3]
    return T


def _se3_bad_bottom(u):
    T = lie.se3_exp(u)
    T[3, 3] = 0.0
    return T


def _rodrigues_no_square(w):
    t = np.linalg.norm(w)
    return np.eye(3) + lie.hat(w) * (np.sin(t) / t if t > 0 else 1.0)


def _dr_left(ts, u):
    out = [np.eye(4)]
    for t, tau in enumerate(np.diff(ts)):
        out.append(lie.se3_exp(tau * u[t]) @ out[-1])
    return np.array(out)


def _dr_no_tau(ts, u):
    out = [np.eye(4)]
    for t in range(len(ts) - 1):
        out.append(out[-1] @ lie.se3_exp(u[t]))
    return np.array(out)


def test_kinematics_checks(capsys):
    _passes(checks.check_hat, lie.hat, capsys)
    _passes(checks.check_so3_exp, lie.so3_exp, capsys)
    _passes(checks.check_se3_exp, lie.se3_exp, capsys)
    _passes(checks.check_dead_reckon, lambda ts, u: motion.dead_reckon(ts, u), capsys)

    _fails(checks.check_hat, lambda w: lie.hat(w).T, "signs are flipped")
    _fails(checks.check_hat, lambda w: lie.hat(w[[2, 0, 1]]), "wrong places")
    _fails(checks.check_hat, lambda w: np.zeros(3), "wrong shape")
    _fails(checks.check_hat, lambda w: np.abs(lie.hat(w)), "skew-symmetric")

    _fails(checks.check_so3_exp, lambda w: lie.so3_exp(w).T, "R^T")
    _fails(checks.check_so3_exp, _rodrigues_naive, "NaN")
    _fails(checks.check_so3_exp, _rodrigues_no_square, "not a rotation")
    _fails(checks.check_so3_exp, lambda w: lie.so3_exp(w)[:2], "wrong shape")

    _fails(checks.check_se3_exp, lambda u: lie.se3_exp(np.r_[u[3:], u[:3]]), "twist order")
    _fails(checks.check_se3_exp, lambda u: lie.se3_exp(-u), "inverse pose")
    _fails(checks.check_se3_exp, lambda u: lie.se3_inv(lie.se3_exp(u)), "inverse pose")
    _fails(checks.check_se3_exp, _se3_v_only, "V v")
    _fails(checks.check_se3_exp, _se3_naive, "NaN")
    _fails(checks.check_se3_exp, _se3_bad_bottom, "bottom row")

    _fails(checks.check_dead_reckon, _dr_left, "on the left")
    _fails(checks.check_dead_reckon, lambda ts, u: motion.dead_reckon(ts, u[:, [3, 4, 5, 0, 1, 2]]), "twist order")
    _fails(checks.check_dead_reckon, lambda ts, u: motion.dead_reckon(ts, u, lag=1), "u_t")
    _fails(checks.check_dead_reckon, _dr_no_tau, "time step")
    _fails(checks.check_dead_reckon, lambda ts, u: lie.se3_inv(motion.dead_reckon(ts, u)), "imu_T_world")
    _fails(checks.check_dead_reckon, lambda ts, u: np.moveaxis(motion.dead_reckon(ts, u), 0, -1), "shape")


# --------------------------------------------------------------------------- 02 camera


def _project(Ks, cam_T_imu, world_T_imu, p):
    q = np.c_[p, np.ones(len(p))] @ (cam_T_imu @ lie.se3_inv(world_T_imu)).T
    return cam.projection(q) @ Ks.T


def _project_no_inverse(Ks, cam_T_imu, world_T_imu, p):
    q = np.c_[p, np.ones(len(p))] @ (cam_T_imu @ world_T_imu).T
    return cam.projection(q) @ Ks.T


def _project_imu_T_cam(Ks, cam_T_imu, world_T_imu, p):
    q = np.c_[p, np.ones(len(p))] @ (lie.se3_inv(cam_T_imu) @ lie.se3_inv(world_T_imu)).T
    return cam.projection(q) @ Ks.T


def _ks_plus(K, b):
    Ks = cam.stereo_matrix(K, b)
    Ks[2, 3] *= -1
    return Ks


def _triangulate_backwards(z, K, b):
    d = z[:, 2] - z[:, 0]
    depth = K[0, 0] * b / d
    return np.c_[(z[:, 0] - K[0, 2]) * depth / K[0, 0], (z[:, 1] - K[1, 2]) * depth / K[1, 1], depth]


def test_camera_checks(capsys):
    _passes(checks.check_stereo_matrix, cam.stereo_matrix, capsys)
    _passes(checks.check_project, _project, capsys)
    _passes(checks.check_triangulate, cam.triangulate_disparity, capsys)
    _passes(checks.check_triangulate, cam.triangulate_bearing, capsys)

    _fails(checks.check_stereo_matrix, _ks_plus, "sign of the baseline")
    _fails(checks.check_stereo_matrix, lambda K, b: cam.stereo_matrix(K, b).T, "transposed")

    _fails(checks.check_project, _project_no_inverse, "inverse is needed")
    _fails(checks.check_project, _project_imu_T_cam, "cam_T_imu")
    _fails(checks.check_project, lambda *a: _project(*a).T, "transposed")

    _fails(checks.check_triangulate, _triangulate_backwards, "disparity sign")
    _fails(checks.check_triangulate, lambda z, K, b: cam.triangulate_disparity(z, K, b) / K[0, 0], "focal length")


# --------------------------------------------------------------------------- 03 Jacobians


def _numjac_forward(f, x, eps=1e-6):
    f0 = np.asarray(f(x))
    return np.stack([(np.asarray(f(x + eps * e)) - f0) / eps for e in np.eye(len(x))], axis=-1)


def _pose_jacobian(Ks, cam_T_imu, mu, m):
    s = lie.se3_inv(mu) @ np.r_[m, 1.0]
    q = cam_T_imu @ s
    return -Ks @ cam.projection_jacobian(q) @ cam_T_imu @ lie.odot(s)


def _pose_jacobian_left(Ks, cam_T_imu, mu, m):
    q = cam_T_imu @ lie.se3_inv(mu) @ np.r_[m, 1.0]
    return -Ks @ cam.projection_jacobian(q) @ cam_T_imu @ lie.se3_inv(mu) @ lie.odot(np.r_[m, 1.0])


def test_jacobian_checks(capsys):
    _passes(checks.check_projection_jacobian, cam.projection_jacobian, capsys)
    _passes(checks.check_odot, lie.odot, capsys)
    _passes(checks.check_numerical_jacobian, checks.reference_numerical_jacobian, capsys)
    _passes(checks.check_pose_jacobian, _pose_jacobian, capsys)

    _fails(checks.check_projection_jacobian, lambda q: cam.projection_jacobian(q).T, "transposed")
    _fails(checks.check_projection_jacobian, lambda q: cam.projection_jacobian(q) * q[2], "1/q3")

    _fails(checks.check_odot, lambda s: np.c_[np.eye(4, 3), lie.hat(s[:3]).tolist() + [[0, 0, 0]]], "sign of the hat")
    _fails(checks.check_odot, lambda s: np.c_[lie.odot(s)[:, 3:], lie.odot(s)[:, :3]], "blocks are swapped")
    _fails(checks.check_odot, lambda s: lie.odot(s)[:3], "wrong shape")

    _fails(checks.check_numerical_jacobian, _numjac_forward, "forward differences")
    _fails(checks.check_numerical_jacobian, lambda f, x: checks.reference_numerical_jacobian(f, x).T, "transposed")
    _fails(checks.check_numerical_jacobian, lambda f, x: 2 * checks.reference_numerical_jacobian(f, x), "2 eps")

    _fails(checks.check_pose_jacobian, lambda *a: -_pose_jacobian(*a), "minus sign")
    _fails(checks.check_pose_jacobian, lambda *a: np.roll(_pose_jacobian(*a), 3, axis=1), "twist order")
    _fails(checks.check_pose_jacobian, _pose_jacobian_left, "left perturbation")


# --------------------------------------------------------------------------- 04 mapping


def _landmark_jacobian(Ks, cam_T_imu, T, m):
    q = cam_T_imu @ lie.se3_inv(T) @ np.r_[m, 1.0]
    return Ks @ cam.projection_jacobian(q) @ cam_T_imu @ lie.se3_inv(T)[:, :3]


def _init_landmark(z, K, b, imu_T_cam, T):
    return (T @ imu_T_cam @ np.r_[cam.triangulate_disparity(z, K, b), 1.0])[:3]


def _landmark_update(m, Sigma, z, T, Ks, cam_T_imu, noise_var, flip=False, plus=False):
    q = cam_T_imu @ lie.se3_inv(T) @ np.r_[m, 1.0]
    z_pred = Ks @ cam.projection(q)
    H = _landmark_jacobian(Ks, cam_T_imu, T, m)
    K = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(4))
    r = (z_pred - z) if flip else (z - z_pred)
    return m + K @ r, (np.eye(3) + (1 if plus else -1) * K @ H) @ Sigma


def test_mapping_checks(capsys):
    _passes(checks.check_landmark_jacobian, _landmark_jacobian, capsys)
    _passes(checks.check_init_landmark, _init_landmark, capsys)
    _passes(checks.check_landmark_update, _landmark_update, capsys)

    _fails(checks.check_landmark_jacobian, lambda *a: np.c_[_landmark_jacobian(*a), np.zeros(4)], "P^T")
    _fails(checks.check_landmark_jacobian, lambda *a: -_landmark_jacobian(*a), "sign")

    _fails(checks.check_init_landmark, lambda z, K, b, X, T: cam.triangulate_disparity(z, K, b), "camera frame")
    _fails(checks.check_init_landmark,
           lambda z, K, b, X, T: (T @ lie.se3_inv(X) @ np.r_[cam.triangulate_disparity(z, K, b), 1])[:3], "cam_T_imu")

    _fails(checks.check_landmark_update, lambda *a: _landmark_update(*a, flip=True), "z - z_pred")
    _fails(checks.check_landmark_update, lambda *a: _landmark_update(*a, plus=True), "minus sign")
    _fails(checks.check_landmark_update, lambda m, S, *a: (_landmark_update(m, S, *a)[0], S), "did not change")


# --------------------------------------------------------------------------- 05 pose


def _pose_update(mu, Sigma, z, p, Ks, cam_T_imu, noise_var, side="right", sign=1.0):
    rig = cam.StereoCamera(K_RIG, B_RIG, IMU_T_CAM)
    assert np.allclose(rig.Ks, Ks) and np.allclose(rig.cam_T_imu, cam_T_imu)
    if side == "right" and sign == 1.0:
        mu_new, S_new, _ = ekf.pose_update(mu, Sigma, p, z, rig, noise_var)
        return mu_new, S_new
    z_pred, _, J = rig.predict_with_jacobians(mu, p)
    H = J.reshape(-1, 6)
    K = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(len(H)))
    d = sign * K @ (z - z_pred).ravel()
    return (mu @ lie.se3_exp(d) if side == "right" else lie.se3_exp(d) @ mu), (np.eye(6) - K @ H) @ Sigma


def test_pose_checks(capsys):
    _passes(checks.check_curly_hat, lie.curly_hat, capsys)
    _passes(checks.check_pose_transition, motion.pose_transition, capsys)
    _passes(checks.check_pose_transition, lambda u, tau: __import__("scipy.linalg").linalg.expm(
        -tau * lie.curly_hat(u)), capsys)
    _passes(checks.check_pose_update, _pose_update, capsys)

    _fails(checks.check_curly_hat, lambda u: lie.curly_hat(np.r_[u[3:], u[:3]]), "twist order")
    _fails(checks.check_curly_hat, lambda u: -lie.curly_hat(u), "signs are flipped")
    _fails(checks.check_curly_hat, lambda u: lie.curly_hat(u).T, "transposed")
    _fails(checks.check_curly_hat, lambda u: np.block([[lie.hat(u[3:]), np.zeros((3, 3))],
                                                       [lie.hat(u[:3]), lie.hat(u[3:])]]), "upper-right")

    _fails(checks.check_pose_transition, lambda u, tau: motion.pose_transition(u, -tau), "minus sign")
    _fails(checks.check_pose_transition, lambda u, tau: motion.pose_transition(u, tau).T, "transposed")
    _fails(checks.check_pose_transition, lambda u, tau: lie.se3_exp(-tau * u), "6x6")
    _fails(checks.check_pose_transition, lambda u, tau: np.eye(6) - tau * lie.curly_hat(u), "first-order")

    _fails(checks.check_pose_update, lambda *a: _pose_update(*a, side="left"), "on the left")
    _fails(checks.check_pose_update, lambda *a: _pose_update(*a, sign=-1.0), "wrong sign")
    _fails(checks.check_pose_update, lambda mu, S, *a: (mu, _pose_update(mu, S, *a)[1]), "did not move")


# --------------------------------------------------------------------------- 06 SLAM


def _slam_jacobian(J_pose, J_landmark, slots, n):
    H = np.zeros((4 * len(slots), 6 + 3 * n))
    for i, s in enumerate(slots):
        H[4 * i:4 * i + 4, :6] = J_pose[i]
        H[4 * i:4 * i + 4, 6 + 3 * s:9 + 3 * s] = J_landmark[i]
    return H


def _slam_jacobian_report_order(J_pose, J_landmark, slots, n):
    H = np.zeros((4 * len(slots), 6 + 3 * n))
    for i, s in enumerate(slots):
        H[4 * i:4 * i + 4, 3 * n:] = J_pose[i]
        H[4 * i:4 * i + 4, 3 * s:3 + 3 * s] = J_landmark[i]
    return H


def _slam_jacobian_no_offset(J_pose, J_landmark, slots, n):
    H = np.zeros((4 * len(slots), 6 + 3 * n))
    for i, s in enumerate(slots):
        H[4 * i:4 * i + 4, :6] = J_pose[i]
        H[4 * i:4 * i + 4, 3 * s:3 + 3 * s] = J_landmark[i]
    return H


def _schur(Sigma, keep):
    drop = np.setdiff1d(np.arange(len(Sigma)), keep)
    A = Sigma[np.ix_(keep, keep)]
    if not len(drop):
        return A
    return A - Sigma[np.ix_(keep, drop)] @ np.linalg.solve(Sigma[np.ix_(drop, drop)], Sigma[np.ix_(drop, keep)])


def test_slam_checks(capsys):
    _passes(checks.check_slam_jacobian, _slam_jacobian, capsys)
    _passes(checks.check_dense_covariance_bytes, lambda M, s=1: (6 + 3 * -(-M // s)) ** 2 * 8, capsys)
    _passes(checks.check_marginalize, lambda S, keep: S[np.ix_(keep, keep)], capsys)

    _fails(checks.check_slam_jacobian, _slam_jacobian_report_order, "pose columns come first")
    _fails(checks.check_slam_jacobian, _slam_jacobian_no_offset, "6 + 3 s")
    _fails(checks.check_slam_jacobian, lambda *a: _slam_jacobian(*a).T, "transposed")

    _fails(checks.check_dense_covariance_bytes, lambda M, s=1: (3 * -(-M // s)) ** 2 * 8, "6 dimensions")
    _fails(checks.check_dense_covariance_bytes, lambda M, s=1: (6 + 3 * -(-M // s)) ** 2 * 4, "8 bytes")
    _fails(checks.check_dense_covariance_bytes, lambda M, s=1: (6 + 3 * (M // s)) ** 2 * 8, "ceil")

    _fails(checks.check_marginalize, _schur, "Schur complement")
    _fails(checks.check_marginalize, lambda S, keep: S[keep], "wrong shape")


# --------------------------------------------------------------------------- 07 consistency


def test_consistency_checks(capsys):
    _passes(checks.check_motion_noise, motion.motion_noise, capsys)
    _passes(checks.check_nees, lambda e, P: float(e @ np.linalg.solve(P, e)), capsys)
    _passes(checks.check_average_nees_bounds, metrics.average_nees_bounds, capsys)

    _fails(checks.check_motion_noise, lambda tau, sv, sw: motion.motion_noise(tau, sw, sv), "twist order")
    _fails(checks.check_motion_noise, lambda tau, sv, sw: np.diag(np.repeat([sv**2, sw**2], 3)), "tau^2")
    _fails(checks.check_motion_noise, lambda tau, sv, sw: np.diag(np.repeat([tau * sv, tau * sw], 3)), "square")

    _fails(checks.check_nees, lambda e, P: float(e @ P @ e), "inverse")
    _fails(checks.check_nees, lambda e, P: float(np.sqrt(e @ np.linalg.solve(P, e))), "square root")

    _fails(checks.check_average_nees_bounds,
           lambda dof, n, p=0.95: tuple(stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof * n)), "divide")
    _fails(checks.check_average_nees_bounds,
           lambda dof, n, p=0.95: tuple(stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof)), "n * dof")


# --------------------------------------------------------------------------- shared behaviour


ALL_CHECKS = [getattr(checks, name) for name in checks.__all__ if name.startswith("check_")]


@pytest.mark.parametrize("check", ALL_CHECKS, ids=lambda c: c.__name__)
def test_stub_raises_not_implemented(check):
    with pytest.raises(NotImplementedError, match="not implemented yet"):
        check(_stub)


@pytest.mark.parametrize("check", ALL_CHECKS, ids=lambda c: c.__name__)
def test_crashing_function_gives_assertion(check):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("boom")

    with pytest.raises(AssertionError, match="ZeroDivisionError"):
        check(broken)


def test_checks_are_deterministic(capsys):
    checks.check_so3_exp(lie.so3_exp)
    first = capsys.readouterr().out
    checks.check_so3_exp(lie.so3_exp)
    assert capsys.readouterr().out == first


def test_student_or_reference(capsys):
    assert checks.student_or_reference(_stub, lie.hat, np.ones(3)) is lie.hat
    assert "library" in capsys.readouterr().out
    mine = lambda w: lie.hat(w)  # noqa: E731
    assert checks.student_or_reference(mine, lie.hat, np.ones(3)) is mine
    assert checks.student_or_reference(lambda w: -lie.hat(w), lie.hat, np.ones(3)) is lie.hat
    pair = lambda x: (x, np.outer(x, x))  # noqa: E731 - functions returning (mean, covariance)
    same = lambda x: (x.copy(), np.outer(x, x))  # noqa: E731
    assert checks.student_or_reference(same, pair, np.ones(3)) is same
    assert checks.student_or_reference(lambda x: (x, x), pair, np.ones(3)) is pair
