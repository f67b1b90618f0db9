"""Tests for visla_edu.course.checks: each check passes a correct answer and names each typical mistake.

For every exercise there is a correct implementation (tests/answers.py, written without the
library function the check hides) and a list of deliberately wrong ones; each wrong one must
fail the check with an AssertionError whose FIRST line (at most 79 characters, what
``nbgrader validate`` shows) contains the expected hint. The hiding, the fresh copies for
graded cells and the hidden cases are tested in tests/test_checks_guard.py.
"""

import numpy as np
import pytest
from scipy import stats
from scipy.linalg import block_diag, expm
from scipy.spatial.transform import Rotation

import answers as A  # tests/answers.py
from visla_edu import camera as cam
from visla_edu import lie
from visla_edu.course import checks


def _passes(check, fn, capsys):
    check(fn)
    assert capsys.readouterr().out.startswith("\u2713")


def _first_line(err):
    return str(err).split("\n", 1)[0]


def _fails(check, fn, hint):
    """``check(fn)`` fails and the first line of the message (<= 79 characters) contains ``hint``."""
    with pytest.raises(AssertionError) as info, np.errstate(all="ignore"):
        check(fn)
    first = _first_line(info.value)
    assert len(first) <= 79, f"first line of {len(first)} characters: {first!r}"
    assert hint.lower() in first.lower(), str(info.value)
    return str(info.value)


def _stub(*args, **kwargs):
    raise NotImplementedError("exercise: write your solution here")


def _transposed_R(T):
    out = np.array(T, dtype=float)
    out[:3, :3] = out[:3, :3].T
    return out


def _inverse_R_not_RT(T):
    """An inverse written as [[R, -R p]]: R where R^T belongs."""
    return A.se3_inv(_transposed_R(T))


TRANSPOSED = "R instead of R^T (a transposed rotation)"

# --------------------------------------------------------------------------- 00 data


def _spans_argmax(features):
    seen = features[0] != -1
    return np.stack([np.argmax(seen, axis=1), seen.shape[1] - 1 - np.argmax(seen[:, ::-1], axis=1)], axis=1)


def _spans_exclusive(features):
    out = A.track_spans(features)
    out[out[:, 1] >= 0, 1] += 1
    return out


def test_data_checks(capsys):
    _passes(checks.check_observations_at, A.observations_at, capsys)
    _passes(checks.check_track_spans, A.track_spans, capsys)
    _fails(checks.check_observations_at, lambda f, t: (np.arange(f.shape[1]), f[:, :, t].T), "keep only the observed")
    _fails(checks.check_observations_at, lambda f, t: (A.observations_at(f, t)[0], A.observations_at(f, t)[1].T),
           "transposed")
    _fails(checks.check_observations_at,
           lambda f, t: (A.observations_at(f, t)[0], A.observations_at(f, t)[1][:, [0, 2, 1, 3]]), "[uL, vL, uR, vR]")
    # pixels stacked row by row: np.array([]) of an empty frame has shape (0,); the message says so
    def stacked(f, t):
        ids = A.observations_at(f, t)[0]
        return ids, np.array([f[:, i, t] for i in ids])

    message = _fails(checks.check_observations_at, stacked, "wrong shape of the pixels z")
    assert "an empty frame gives ids of shape (0,) and z of shape (0, 4)" in message.replace("\n", " ")
    assert "at frame 0, where 0 landmarks are observed" in message
    _fails(checks.check_track_spans, _spans_argmax, "never observed")
    _fails(checks.check_track_spans, _spans_exclusive, "off by one")
    _fails(checks.check_track_spans, lambda f: A.track_spans(f)[:, ::-1], "swapped")


# --------------------------------------------------------------------------- 00b Kalman primer


def _update_1d_with_gain(gain_of, mean_sign=1.0, variance_of=None):
    """A scalar update with a (wrong) gain, innovation sign or variance formula."""
    def update(m, var, z, r):
        gain = gain_of(var, r)
        new_var = (1 - gain) * var if variance_of is None else variance_of(var, gain)
        return m + mean_sign * gain * (z - m), new_var
    return update


def test_primer_checks(capsys):
    _passes(checks.check_kalman_update_1d, A.kalman_update_1d, capsys)
    _passes(checks.check_kalman_predict, A.kalman_predict, capsys)
    right_gain = lambda var, r: var / (var + r)  # noqa: E731

    _fails(checks.check_kalman_update_1d, lambda m, var, z, r: (A.kalman_update_1d(m, var, z, r)[0], var),
           "variance must shrink")
    _fails(checks.check_kalman_update_1d, _update_1d_with_gain(lambda var, r: r / (var + r)), "swapped")
    _fails(checks.check_kalman_update_1d,
           _update_1d_with_gain(lambda var, r: np.sqrt(var) / (np.sqrt(var) + np.sqrt(r))), "standard deviations")
    _fails(checks.check_kalman_update_1d, _update_1d_with_gain(right_gain, mean_sign=-1.0), "z - mean")
    _fails(checks.check_kalman_update_1d, _update_1d_with_gain(lambda var, r: var / r), "not variance / V")
    _fails(checks.check_kalman_update_1d, _update_1d_with_gain(right_gain, variance_of=lambda var, k: var - k),
           "not variance - L")
    _fails(checks.check_kalman_update_1d, lambda *a: A.kalman_update_1d(*a)[::-1], "in this order")
    _fails(checks.check_kalman_update_1d, lambda *a: A.kalman_update_1d(*a)[0], "return the pair")
    _fails(checks.check_kalman_update_1d, lambda m, var, z, r: (m + 0.5 * (z - m), var / 2), "no known mistake")

    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F @ x, F @ P @ F.T), "motion noise W")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F @ x, F.T @ P @ F + Q), "transposed")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F @ x, F @ P + Q), "F.T on the right")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F @ x, F @ P @ F + Q), "second F")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F @ x, F @ (P + Q) @ F.T), "after propagating")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (x, F @ P @ F.T + Q), "mean moves")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F.T @ x, F @ P @ F.T + Q), "not F.T @ x")
    _fails(checks.check_kalman_predict, lambda x, P, F, Q: (F @ x, (F @ P @ F.T + Q).ravel()), "wrong shape")


# --------------------------------------------------------------------------- 01 kinematics


def _rodrigues_naive(w):
    t = np.linalg.norm(w)
    W = A.hat(w)
    return np.eye(3) + np.sin(t) / t * W + (1 - np.cos(t)) / t**2 * W @ W


def _rodrigues_zero_guard(w):
    """Closed form everywhere except exactly at 0: no small-angle series."""
    t = np.linalg.norm(w)
    return np.eye(3) if t == 0 else _rodrigues_naive(w)


def _se3_naive(u, guard=False):
    v, w = u[:3], u[3:]
    t = np.linalg.norm(w)
    if guard and t == 0:
        return np.block([[np.eye(3), v[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
    W = A.hat(w)
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(t) / t * W + (1 - np.cos(t)) / t**2 * W @ W
    T[:3, 3] = (np.eye(3) + (1 - np.cos(t)) / t**2 * W + (t - np.sin(t)) / t**3 * W @ W) @ v
    return T


def _se3_v_only(u):
    T = A.se3_exp(u)
    T[:3, 3] = u[:3]
    return T


def _se3_v_transposed(u):
    """V with the wrong sign of its hat(w) term, I - B hat(w) + C hat(w)^2 = V^T."""
    u = np.asarray(u, dtype=float)
    v, w = u[:3], u[3:]
    _, B, C = A._coefficients(float(w @ w))
    T = A.se3_exp(u)
    T[:3, 3] = (np.eye(3) - B * A.hat(w) + C * A.hat(w) @ A.hat(w)) @ v
    return T


def _se3_bad_bottom(u):
    T = A.se3_exp(u)
    T[3, 3] = 0.0
    return T


def _rodrigues_no_square(w):
    t = np.linalg.norm(w)
    return np.eye(3) + lie.hat(w) * (np.sin(t) / t if t > 0 else 1.0)


def test_kinematics_checks(capsys):
    _passes(checks.check_hat, A.hat, capsys)
    _passes(checks.check_so3_exp, A.so3_exp, capsys)
    _passes(checks.check_se3_exp, A.se3_exp, capsys)
    _passes(checks.check_dead_reckon, A.dead_reckon, capsys)

    _fails(checks.check_hat, lambda w: A.hat(w).T, "signs are flipped")
    _fails(checks.check_hat, lambda w: A.hat(np.asarray(w, dtype=float)[[2, 0, 1]]), "wrong places")
    _fails(checks.check_hat, lambda w: np.zeros(3), "wrong shape")
    _fails(checks.check_hat, lambda w: np.abs(A.hat(w)), "skew-symmetric")

    _fails(checks.check_so3_exp, lambda w: A.so3_exp(w).T, "R^T")
    _fails(checks.check_so3_exp, _rodrigues_naive, "NaN")
    _fails(checks.check_so3_exp, _rodrigues_no_square, "not a rotation")
    _fails(checks.check_so3_exp, lambda w: A.so3_exp(w)[:2], "wrong shape")

    _fails(checks.check_se3_exp, lambda u: A.se3_exp(np.r_[u[3:], u[:3]]), "twist order")
    _fails(checks.check_se3_exp, lambda u: A.se3_exp(-u), "inverse pose")
    _fails(checks.check_se3_exp, lambda u: A.se3_inv(A.se3_exp(u)), "inverse pose")
    _fails(checks.check_se3_exp, _se3_v_only, "J_l v")
    _fails(checks.check_se3_exp, _se3_v_only, "translation is v,")
    # first wrong at a tiny angle, where V^T v, v and V v nearly coincide: named as V^T, not as v
    _fails(checks.check_se3_exp, _se3_v_transposed, "you used J_l^T")
    _fails(checks.check_se3_exp, _se3_naive, "NaN")
    _fails(checks.check_se3_exp, _se3_bad_bottom, "bottom row")

    dr = checks.check_dead_reckon
    _fails(dr, lambda ts, u, lag=0: A.dead_reckon(ts, u, lag, left=True), "on the left")
    _fails(dr, lambda ts, u, lag=0: A.dead_reckon(ts, u[:, [3, 4, 5, 0, 1, 2]], lag), "twist order")
    _fails(dr, lambda ts, u, lag=0: A.dead_reckon(ts, u), "lag was ignored")
    _fails(dr, lambda ts, u, lag=0: A.dead_reckon(ts, u, -lag), "wrong sign")
    _fails(dr, lambda ts, u, lag=0: A.dead_reckon(ts, u, lag, scale_tau=False), "time step")
    _fails(dr, lambda ts, u, lag=0: A.dead_reckon(ts[0] + np.mean(np.diff(ts)) * np.arange(len(ts)), u, lag),
           "own tau_t")
    _fails(dr, lambda ts, u, lag=0: np.array([A.se3_inv(T) for T in A.dead_reckon(ts, u, lag)]), "imu_T_world")
    _fails(dr, lambda ts, u, lag=0: np.moveaxis(A.dead_reckon(ts, u, lag), 0, -1), "shape")
    _fails(dr, lambda ts, u: A.dead_reckon(ts, u), "third argument, the lag")
    # an index that wraps around at the end: only the hidden lags (-1, +2) reach it at the first step
    with pytest.raises(AssertionError, match="wraps around"):
        dr(lambda ts, u, lag=0: A.dead_reckon(ts, u, lag, clip=False), hidden=True)
    dr(A.dead_reckon, hidden=True)

    _passes(checks.check_so3_log, A.so3_log, capsys)
    checks.check_so3_log(A.so3_log, hidden=True)
    _passes(checks.check_so3_log, lambda R: Rotation.from_matrix(R).as_rotvec(), capsys)
    message = _fails(checks.check_so3_log, lambda R: A.so3_log(R, angle="arccos"), "arccos loses its digits")
    assert "atan2(|s|, (tr R - 1)/2)" in message.replace("\n", " ")
    _fails(checks.check_so3_log, lambda R: A.so3_log(R, angle="arcsin"), "arcsin")
    _fails(checks.check_so3_log, lambda R: A.so3_log(R, sign=-1.0), "-w")
    _fails(checks.check_so3_log, lambda R: 2 * A.so3_log(R), "twice")
    _fails(checks.check_so3_log, lambda R: 0.5 * A.so3_log(R), "half")
    def log_without_guard(R):  # theta / sin(theta) with no care at the identity: 0 / 0
        s = 0.5 * lie.vee(R - R.T)
        theta = np.arctan2(np.linalg.norm(s), 0.5 * (np.trace(R) - 1))
        return theta / np.linalg.norm(s) * s

    _fails(checks.check_so3_log, log_without_guard, "at the identity")
    _fails(checks.check_so3_log, lambda R: A.hat(A.so3_log(R)), "not a matrix")


def test_the_translation_needs_the_small_angle_series_and_rodrigues_does_not(capsys):
    """Guarded only at exactly 0: R keeps full precision and passes, V v loses digits near 1e-7 rad and fails."""
    _passes(checks.check_so3_exp, _rodrigues_zero_guard, capsys)
    message = _fails(checks.check_se3_exp, lambda u: _se3_naive(u, guard=True), "no small-angle series")
    assert "1/2 - t^2/24" in message and "of size t |v|" in message.replace("\n", " ")
    # an se3_exp that is exact in V but takes its rotation from a zero-guarded closed form passes
    _passes(checks.check_se3_exp, lambda u: np.block([[_rodrigues_zero_guard(u[3:]), A.se3_exp(u)[:3, 3:]],
                                                      [np.zeros((1, 3)), np.ones((1, 1))]]), capsys)
    # accurate forms without a series pass: scipy's quaternions
    _passes(checks.check_so3_exp, lambda w: Rotation.from_rotvec(w).as_matrix(), capsys)
    # a first-order shortcut below a threshold is caught at the tiny angles
    _fails(checks.check_so3_exp, lambda w: np.eye(3) + A.hat(w) if np.linalg.norm(w) < 1e-4 else A.so3_exp(w),
           "wrong values")


# --------------------------------------------------------------------------- 02 camera


def _ks_plus(K, b):
    Ks = A.stereo_matrix(K, b)
    Ks[2, 3] *= -1
    return Ks


def _triangulate_backwards(z, K, b):
    return -A.triangulate(z, K, b)


def test_camera_checks(capsys):
    _passes(checks.check_stereo_matrix, A.stereo_matrix, capsys)
    _passes(checks.check_project, A.project, capsys)
    _passes(checks.check_triangulate, A.triangulate, capsys)
    _passes(checks.check_triangulate, A.triangulate_bearing, capsys)

    _fails(checks.check_stereo_matrix, _ks_plus, "sign of the baseline")
    _fails(checks.check_stereo_matrix, lambda K, b: A.stereo_matrix(K, b).T, "transposed")

    _fails(checks.check_project, lambda Ks, o, T, p: A.project(Ks, o, A.se3_inv(T), p), "inverse is needed")
    _fails(checks.check_project, lambda Ks, o, T, p: A.project(Ks, A.se3_inv(o), T, p), "cam_T_imu")
    _fails(checks.check_project, lambda *a: A.project(*a).T, "transposed")

    _fails(checks.check_triangulate, _triangulate_backwards, "disparity sign")
    _fails(checks.check_triangulate, lambda z, K, b: A.triangulate(z, K, b) / K[0, 0], "focal length")


@pytest.mark.parametrize("wrong_inverse", [
    _inverse_R_not_RT,  # [[R, -R p]]
    lambda T: np.block([[T[:3, :3], -T[:3, :3].T @ T[:3, 3:]], [T[3:]]]),  # [[R, -R^T p]]
], ids=["R,-Rp", "R,-RTp"])
def test_transposed_rotation_is_named_in_project_and_jacobians(wrong_inverse):
    _fails(checks.check_project, lambda *a: A.project(*a, inverse=wrong_inverse), TRANSPOSED)
    _fails(checks.check_pose_jacobian, lambda *a: A.pose_jacobian(*a, inverse=wrong_inverse), TRANSPOSED)
    _fails(checks.check_landmark_update, lambda *a: A.landmark_update(*a, inverse=wrong_inverse), TRANSPOSED)
    _fails(checks.check_pose_update, lambda *a: A.pose_update(*a, inverse=wrong_inverse), TRANSPOSED)


def test_transposed_rotation_is_named_in_init_landmark_and_landmark_jacobian():
    _fails(checks.check_project, lambda Ks, o, T, p: A.project(Ks, _transposed_R(o), T, p), TRANSPOSED)
    _fails(checks.check_init_landmark, lambda z, K, b, X, T: A.init_landmark(z, K, b, X, _transposed_R(T)),
           TRANSPOSED)
    _fails(checks.check_init_landmark, lambda z, K, b, X, T: A.init_landmark(z, K, b, _transposed_R(X), T),
           TRANSPOSED)
    _fails(checks.check_landmark_jacobian, lambda Ks, o, T, m: A.landmark_jacobian(Ks, _transposed_R(o), T, m),
           TRANSPOSED)
    _fails(checks.check_landmark_jacobian, lambda *a: A.landmark_jacobian(*a, inverse=_inverse_R_not_RT), TRANSPOSED)


# --------------------------------------------------------------------------- 03 Jacobians


def _numjac_forward(f, x, eps=1e-6):
    f0 = np.asarray(f(x))
    return np.stack([(np.asarray(f(x + eps * e)) - f0) / eps for e in np.eye(len(x))], axis=-1)


def _pose_jacobian_left(Ks, cam_T_imu, mu, m):
    q = cam_T_imu @ A.se3_inv(mu) @ np.r_[m, 1.0]
    return -Ks @ A.projection_jacobian(q) @ cam_T_imu @ A.se3_inv(mu) @ A.odot(np.r_[m, 1.0])


def test_jacobian_checks(capsys):
    _passes(checks.check_projection_jacobian, A.projection_jacobian, capsys)
    _passes(checks.check_odot, A.odot, capsys)
    _passes(checks.check_numerical_jacobian, A.numerical_jacobian, capsys)
    _passes(checks.check_pose_jacobian, A.pose_jacobian, capsys)
    _passes(checks.check_pose_jacobian, lambda Ks, o, mu, m: -Ks @ cam.projection_jacobian(o @ lie.se3_inv(mu) @ np.r_[
        m, 1]) @ o @ lie.odot(lie.se3_inv(mu) @ np.r_[m, 1]), capsys)  # the library's pieces are allowed

    _fails(checks.check_projection_jacobian, lambda q: A.projection_jacobian(q).T, "transposed")
    _fails(checks.check_projection_jacobian, lambda q: A.projection_jacobian(q) * q[2], "1/q3")

    _fails(checks.check_odot, lambda s: np.c_[np.eye(4, 3), A.hat(s[:3]).tolist() + [[0, 0, 0]]], "sign of the hat")
    _fails(checks.check_odot, lambda s: np.c_[A.odot(s)[:, 3:], A.odot(s)[:, :3]], "blocks are swapped")
    _fails(checks.check_odot, lambda s: A.odot(s)[:3], "wrong shape")

    _fails(checks.check_numerical_jacobian, _numjac_forward, "forward differences")
    _fails(checks.check_numerical_jacobian, lambda f, x: A.numerical_jacobian(f, x).T, "transposed")
    _fails(checks.check_numerical_jacobian, lambda f, x: 2 * A.numerical_jacobian(f, x), "2 eps")

    _fails(checks.check_pose_jacobian, lambda *a: -A.pose_jacobian(*a), "minus sign")
    _fails(checks.check_pose_jacobian, lambda *a: np.roll(A.pose_jacobian(*a), 3, axis=1), "twist order")
    _fails(checks.check_pose_jacobian, _pose_jacobian_left, "left perturbation")
    _fails(checks.check_pose_jacobian, lambda Ks, o, mu, m: -Ks @ cam.projection_jacobian(
        o @ lie.se3_inv(mu) @ np.r_[m, 1.0]) @ o @ lie.odot(np.r_[m, 1.0]), "not on the world point")


# --------------------------------------------------------------------------- 04 mapping


def _without_dpi(J_dpi):
    """A Jacobian written with ``J_dpi(q)`` in place of ``dpi/dq(q)``: (pose, landmark) answers."""

    def pose(Ks, cam_T_imu, mu, m):
        s = A.se3_inv(mu) @ np.r_[m, 1.0]
        return -Ks @ J_dpi(cam_T_imu @ s) @ cam_T_imu @ A.odot(s)

    def landmark(Ks, cam_T_imu, world_T_imu, m):
        imu_T_world = A.se3_inv(world_T_imu)
        return Ks @ J_dpi(cam_T_imu @ imu_T_world @ np.r_[m, 1.0]) @ cam_T_imu @ imu_T_world[:, :3]

    return pose, landmark


@pytest.mark.parametrize("J_dpi", [lambda q: np.eye(4), lambda q: np.eye(4) / q[2]], ids=["identity", "1/q3"])
def test_jacobians_without_the_projection_derivative_are_named(J_dpi):
    pose, landmark = _without_dpi(J_dpi)
    _fails(checks.check_pose_jacobian, pose, "the derivative of the projection dpi/dq is missing")
    _fails(checks.check_landmark_jacobian, landmark, "the derivative of the projection dpi/dq is missing")


def test_pose_jacobian_with_the_odot_sign_flipped_is_named():
    def flipped(Ks, cam_T_imu, mu, m):
        s = A.se3_inv(mu) @ np.r_[m, 1.0]
        odot = A.odot(s)
        odot[:3, 3:] *= -1
        return -Ks @ A.projection_jacobian(cam_T_imu @ s) @ cam_T_imu @ odot

    _fails(checks.check_pose_jacobian, flipped, "odot has the wrong sign of its hat block")


def test_mapping_checks(capsys):
    _passes(checks.check_landmark_jacobian, A.landmark_jacobian, capsys)
    _passes(checks.check_init_landmark, A.init_landmark, capsys)
    _passes(checks.check_init_landmark, lambda z, K, b, X, T: (T @ X @ np.r_[cam.triangulate_disparity(z, K, b), 1])[
        :3], capsys)  # notebook 05 allows camera.triangulate_disparity
    _passes(checks.check_landmark_update, A.landmark_update, capsys)

    _fails(checks.check_landmark_jacobian, lambda *a: np.c_[A.landmark_jacobian(*a), np.zeros(4)], "P^T")
    _fails(checks.check_landmark_jacobian, lambda *a: -A.landmark_jacobian(*a), "sign")

    _fails(checks.check_init_landmark, lambda z, K, b, X, T: A.triangulate(z, K, b), "camera frame")
    _fails(checks.check_init_landmark,
           lambda z, K, b, X, T: (T @ A.se3_inv(X) @ np.r_[A.triangulate(z, K, b), 1])[:3], "cam_T_imu")

    _fails(checks.check_landmark_update, lambda *a: A.landmark_update(*a, flip=True), "z - z_pred")
    _fails(checks.check_landmark_update, lambda *a: A.landmark_update(*a, plus=True), "minus sign")
    _fails(checks.check_landmark_update, lambda m, S, *a: (A.landmark_update(m, S, *a)[0], S), "did not change")
    _fails(checks.check_landmark_update, lambda *a: A.landmark_update(*a[:-1], a[-1] ** 2), "not noise_var^2")


# --------------------------------------------------------------------------- 05 pose


def test_pose_checks(capsys):
    _passes(checks.check_curly_hat, A.curly_hat, capsys)
    _passes(checks.check_pose_transition, A.pose_transition, capsys)
    _passes(checks.check_pose_transition, lambda u, tau: expm(-tau * lie.curly_hat(u)), capsys)
    _passes(checks.check_pose_update, A.pose_update, capsys)

    _fails(checks.check_curly_hat, lambda u: A.curly_hat(np.r_[u[3:], u[:3]]), "twist order")
    _fails(checks.check_curly_hat, lambda u: -A.curly_hat(u), "signs are flipped")
    _fails(checks.check_curly_hat, lambda u: A.curly_hat(u).T, "transposed")
    _fails(checks.check_curly_hat, lambda u: np.block([[A.hat(u[3:]), np.zeros((3, 3))],
                                                       [A.hat(u[:3]), A.hat(u[3:])]]), "upper-right")

    _fails(checks.check_pose_transition, lambda u, tau: A.pose_transition(u, -tau), "minus sign")
    _fails(checks.check_pose_transition, lambda u, tau: A.pose_transition(u, tau).T, "transposed")
    _fails(checks.check_pose_transition, lambda u, tau: A.se3_exp(-tau * u), "6x6")
    _fails(checks.check_pose_transition, lambda u, tau: np.eye(6) - tau * A.curly_hat(u), "first-order")

    _fails(checks.check_pose_update, lambda *a: A.pose_update(*a, side="left"), "on the left")
    _fails(checks.check_pose_update, lambda *a: A.pose_update(*a, sign=-1.0), "wrong sign")
    _fails(checks.check_pose_update, lambda mu, S, *a: (mu, A.pose_update(mu, S, *a)[1]), "did not move")
    _fails(checks.check_pose_update, _pose_update_twist_swapped, "twist order")
    _fails(checks.check_pose_update, lambda *a: A.pose_update(*a[:-1], a[-1] ** 2), "not the argument noise_var")
    _fails(checks.check_pose_update, _pose_update_innovation_by_columns, "not stacked like H")


def _pose_update_innovation_by_columns(mu, Sigma, z, p_world, Ks, cam_T_imu, noise_var):
    """H stacked observation by observation, the innovation (z - z_pred).T.ravel(): all uL first."""
    H = np.concatenate([A.pose_jacobian(Ks, cam_T_imu, mu, m) for m in p_world])
    K = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(len(H)))
    delta = K @ (np.asarray(z) - A.project(Ks, cam_T_imu, mu, p_world)).T.ravel()
    return mu @ A.se3_exp(delta), (np.eye(6) - K @ H) @ Sigma


def test_left_pose_prediction_check(capsys):
    _passes(checks.check_left_pose_prediction, A.left_pose_prediction, capsys)
    checks.check_left_pose_prediction(A.left_pose_prediction, hidden=True)
    wrong = A.left_pose_prediction
    _fails(checks.check_left_pose_prediction,
           lambda mu, S, u, tau, W: (wrong(mu, S, u, tau, W)[0], A.pose_transition(u, tau) @ S
                                     @ A.pose_transition(u, tau).T + W), "right perturbation's")
    _fails(checks.check_left_pose_prediction, lambda *a: wrong(*a, transition=True), "do not apply F")
    _fails(checks.check_left_pose_prediction, lambda *a: wrong(*a, rotate=False), "rotate it into the world")
    _fails(checks.check_left_pose_prediction, lambda *a: wrong(*a, at="before"), "pose after the step")
    _fails(checks.check_left_pose_prediction, lambda *a: wrong(*a, at="inverse"), "Ad(mu_next^-1)")
    _fails(checks.check_left_pose_prediction, lambda *a: wrong(*a, at="transposed"), "transposed")
    _fails(checks.check_left_pose_prediction,
           lambda mu, S, u, tau, W: (A.se3_exp(tau * u) @ mu, wrong(mu, S, u, tau, W)[1]), "moves on the right")
    _fails(checks.check_left_pose_prediction, lambda *a: wrong(*a)[1], "return the pair")


@pytest.mark.parametrize("noise", [lambda r: 4.0, lambda r: r ** 2, np.sqrt], ids=["fixed 4", "squared", "root"])
@pytest.mark.parametrize("hidden", [False, True], ids=["visible", "hidden"])
def test_pose_update_must_use_its_noise_variance(noise, hidden):
    """The cases change noise_var: an update with a fixed 4 px^2 (the old cases' value) fails, named."""
    def answer(mu, Sigma, z, p_world, Ks, cam_T_imu, noise_var):
        return A.pose_update(mu, Sigma, z, p_world, Ks, cam_T_imu, noise(noise_var))

    with pytest.raises(AssertionError, match="the pixel noise is not the argument noise_var"):
        checks.check_pose_update(answer, hidden=hidden)


def test_curly_hat_success_line_claims_only_the_comparison(capsys):
    checks.check_curly_hat(A.curly_hat)
    out = capsys.readouterr().out
    assert "agrees with the library on 5 twists" in out  # what the check compares
    assert "expm" not in out  # the check does not evaluate expm(curly_hat(u))


def test_pose_update_success_line_names_what_it_compared_with(capsys):
    checks.check_pose_update(A.pose_update)
    out = capsys.readouterr().out
    assert "the reference update mu exp(L r), (I - L H) Sigma" in out  # the check's own formula
    assert "ekf.pose_update" not in out  # the check never calls it


# --------------------------------------------------------------------------- 06 SLAM


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
    S = Sigma[np.ix_(keep, keep)]
    if not len(drop):
        return S
    return S - Sigma[np.ix_(keep, drop)] @ np.linalg.solve(Sigma[np.ix_(drop, drop)], Sigma[np.ix_(drop, keep)])


def test_slam_checks(capsys):
    _passes(checks.check_slam_jacobian, A.slam_jacobian, capsys)
    _passes(checks.check_dense_covariance_bytes, A.dense_covariance_bytes, capsys)
    _passes(checks.check_marginalize, A.marginalize, capsys)

    _fails(checks.check_slam_jacobian, _slam_jacobian_report_order, "pose columns come first")
    _fails(checks.check_slam_jacobian, _slam_jacobian_no_offset, "6 + 3 s")
    _fails(checks.check_slam_jacobian, lambda *a: A.slam_jacobian(*a).T, "transposed")

    _fails(checks.check_dense_covariance_bytes, lambda M, s=1: (3 * -(-M // s)) ** 2 * 8, "6 dimensions")
    _fails(checks.check_dense_covariance_bytes, lambda M, s=1: (6 + 3 * -(-M // s)) ** 2 * 4, "8 bytes")
    _fails(checks.check_dense_covariance_bytes, lambda M, s=1: (6 + 3 * (M // s)) ** 2 * 8, "ceil")

    _fails(checks.check_marginalize, _schur, "Schur complement")
    _fails(checks.check_marginalize, lambda S, keep: S[keep], "wrong shape")


def test_slam_null_space_check(capsys):
    _passes(checks.check_slam_null_space, A.slam_null_space, capsys)
    checks.check_slam_null_space(A.slam_null_space, hidden=True)
    _fails(checks.check_slam_null_space, lambda T, p: A.slam_null_space(T, p, pose_block="forward"), "not Ad(mu)")
    _fails(checks.check_slam_null_space, lambda T, p: A.slam_null_space(T, p, pose_block="identity"), "not the identity")
    _fails(checks.check_slam_null_space, lambda T, p: A.slam_null_space(T, p, sign=1.0), "wrong sign")
    _fails(checks.check_slam_null_space, lambda T, p: A.slam_null_space(T, p, swap=True), "twist order")
    _fails(checks.check_slam_null_space, lambda T, p: A.slam_null_space(T, p, landmarks=False), "move with the world")
    _fails(checks.check_slam_null_space,
           lambda T, p: A.slam_null_space(T, (np.c_[p, np.ones(len(p))] @ A.se3_inv(T).T)[:, :3]), "IMU frame")
    _fails(checks.check_slam_null_space, lambda T, p: A.slam_null_space(T, p).T, "transposed")


def test_null_space_is_the_kernel_of_the_joint_jacobian():
    """H N = 0 at the estimate: moving the whole world leaves every pixel unchanged (the check's reference)."""
    generator = np.random.default_rng(3)
    camera = cam.StereoCamera(*__import__("visla_edu.simulate", fromlist=["default_rig"]).default_rig())
    T = lie.se3_exp(np.r_[generator.normal(scale=5, size=3), generator.normal(size=3)])
    world_T_cam = T @ camera.imu_T_cam
    p_cam = np.c_[generator.uniform(-5, 5, 6), generator.uniform(-2, 2, 6), generator.uniform(5, 40, 6)]
    p = p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]
    _, J_landmark, J_pose = camera.predict_with_jacobians(T, p)
    H = A.slam_jacobian(J_pose, J_landmark, np.arange(6), 6)
    N = checks.reference_slam_null_space(T, p)
    assert np.abs(H @ N).max() < 1e-9 * np.abs(H).max() * np.abs(N).max()
    assert np.linalg.matrix_rank(N) == 6


def test_invariant_pose_jacobian_check(capsys):
    _passes(checks.check_invariant_pose_jacobian, A.invariant_pose_jacobian, capsys)
    checks.check_invariant_pose_jacobian(A.invariant_pose_jacobian, hidden=True)
    _fails(checks.check_invariant_pose_jacobian, A.pose_jacobian, "right perturbation's pose Jacobian")
    _fails(checks.check_invariant_pose_jacobian, lambda *a: -A.invariant_pose_jacobian(*a), "wrong sign")
    _fails(checks.check_invariant_pose_jacobian, lambda *a: A.invariant_pose_jacobian(*a)[:, [3, 4, 5, 0, 1, 2]],
           "swapped")
    _fails(checks.check_invariant_pose_jacobian,
           lambda Ks, C, T, m: np.hstack([-A.landmark_jacobian(Ks, C, T, m), A.landmark_jacobian(Ks, C, T, m) @ A.hat(m)]),
           "shares the pose's rotation")
    _fails(checks.check_invariant_pose_jacobian, lambda *a: A.landmark_jacobian(*a), "4x3")
    with pytest.raises(AssertionError, match="notebook's rig"):
        from visla_edu.course.checks import _inputs
        notebook = _inputs.stereo_camera()
        checks.check_invariant_pose_jacobian(
            lambda Ks, C, T, m: A.invariant_pose_jacobian(notebook.Ks, notebook.cam_T_imu, T, m), hidden=True)


def test_white_noise_check(capsys):
    _passes(checks.check_white_noise, A.white_noise, capsys)
    checks.check_white_noise(A.white_noise, hidden=True)
    _fails(checks.check_white_noise, lambda u: A.white_noise(u, robust=False), "robust spread")
    _fails(checks.check_white_noise, lambda u: A.white_noise(u, divide=1.0), "divide by sqrt(6)")
    _fails(checks.check_white_noise, lambda u: A.white_noise(u, divide=6.0), "not by 6")
    _fails(checks.check_white_noise, lambda u: A.white_noise(u, scale=1.0), "1.4826")
    _fails(checks.check_white_noise, lambda u: 1.4826 * np.median(np.abs(np.diff(u, axis=0) - np.median(
        np.diff(u, axis=0), axis=0)), axis=0) / np.sqrt(2), "second differences")
    _fails(checks.check_white_noise, lambda u: A.white_noise(u).mean(), "wrong shape")


def test_landmark_observation_noise_check(capsys):
    f = A.landmark_observation_noise
    _passes(checks.check_landmark_observation_noise, f, capsys)
    checks.check_landmark_observation_noise(f, hidden=True)
    _fails(checks.check_landmark_observation_noise, lambda J, S, r: f(J, 0 * S, r), "not exact")
    _fails(checks.check_landmark_observation_noise, lambda J, S, r: f(J, S, 0.0), "pixel noise")
    _fails(checks.check_landmark_observation_noise, lambda J, S, r: f(J, S, r**2), "do not square")
    _fails(checks.check_landmark_observation_noise, lambda J, S, r: f(J, S, np.sqrt(r)), "square root")
    _fails(checks.check_landmark_observation_noise, lambda J, S, r: f(J, np.linalg.inv(S), r), "not its inverse")
    _fails(checks.check_landmark_observation_noise, lambda J, S, r: f(J, S, r).sum(axis=0), "wrong shape")


# --------------------------------------------------------------------------- 07 consistency


def test_consistency_checks(capsys):
    _passes(checks.check_motion_noise, A.motion_noise, capsys)
    _passes(checks.check_nees, A.nees, capsys)
    _passes(checks.check_average_nees_bounds, A.average_nees_bounds, capsys)

    _fails(checks.check_motion_noise, lambda tau, sv, sw: A.motion_noise(tau, sw, sv), "twist order")
    _fails(checks.check_motion_noise, lambda tau, sv, sw: np.diag(np.repeat([sv**2, sw**2], 3)), "tau^2")
    _fails(checks.check_motion_noise, lambda tau, sv, sw: np.diag(np.repeat([tau * sv, tau * sw], 3)), "square")

    _fails(checks.check_nees, lambda e, P: float(e @ P @ e), "inverse")
    _fails(checks.check_nees, lambda e, P: e[None] @ np.linalg.solve(P, e)[:, None], "one number, not an array")
    _fails(checks.check_nees, lambda e, P: float(np.sqrt(e @ np.linalg.solve(P, e))), "square root")

    _fails(checks.check_average_nees_bounds,
           lambda dof, n, p=0.95: tuple(stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof * n)), "divide")
    _fails(checks.check_average_nees_bounds,
           lambda dof, n, p=0.95: tuple(stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof)), "n * dof")



def test_average_nees_bounds_in_the_wrong_order_are_named():
    _fails(checks.check_average_nees_bounds,
           lambda dof, n, p=0.95: tuple(stats.chi2.ppf([(1 + p) / 2, (1 - p) / 2], dof * n) / n), "swapped")


def _se3_translation(u, V):
    T = A.se3_exp(u)
    T[:3, 3] = V @ u[:3]
    return T


def _series_v(w, swap):
    t = np.linalg.norm(w)
    a, b = ((1 - np.cos(t)) / t**2, (t - np.sin(t)) / t**3) if t > 1e-3 else (0.5 - t**2 / 24, 1 / 6 - t**2 / 120)
    W = A.hat(w)
    return np.eye(3) + (b * W + a * W @ W if swap else a * W + b * W @ W)


def test_se3_exp_translation_mistakes_are_named():
    """R v instead of V v, V's coefficients exchanged, and V transposed (the right Jacobian, V^T)."""
    _fails(checks.check_se3_exp, lambda u: _se3_translation(u, A.so3_exp(u[3:])), "translation is R v")
    _fails(checks.check_se3_exp, lambda u: _se3_translation(u, _series_v(u[3:], swap=True)), "coefficients are swapped")
    _fails(checks.check_se3_exp, lambda u: _se3_translation(u, _series_v(u[3:], swap=False).T), "you used J_l^T")

# --------------------------------------------------------------------------- 08 smoothing


def _motion_parts(T_prev, T_next, step_inv, e=None, J_prev=None, J_next=None):
    """The correct motion factor with one part replaced (a deliberate mistake)."""
    right = A.motion_residual(T_prev, T_next, step_inv)
    return tuple(right[i] if part is None else part(right) for i, part in enumerate((e, J_prev, J_next)))


def _schur_added(H_pp, H_pm, H_mm, g_p, g_m):
    S, b = A.schur_reduce(H_pp, H_pm, H_mm, g_p, g_m)
    return 2 * H_pp - S, b


def _landmark_update_in_place(m, Sigma, z, world_T_imu, Ks, cam_T_imu, noise_var):
    """Correct, but it updates the mean and the covariance it was given in place."""
    m_new, Sigma_new = A.landmark_update(m.copy(), Sigma.copy(), z, world_T_imu, Ks, cam_T_imu, noise_var)
    m += m_new - m
    Sigma -= Sigma - Sigma_new
    return m, Sigma


def _schur_reduce_in_place(H_pp, H_pm, H_mm, g_p, g_m):
    """Correct, but it subtracts from H_pp and g_p themselves."""
    S, b = A.schur_reduce(H_pp, H_pm, H_mm, g_p, g_m)
    H_pp -= H_pp - S
    g_p -= g_p - b
    return H_pp, g_p


def test_correct_code_that_updates_its_inputs_in_place_passes(capsys):
    """The check's reference is computed from the inputs after the student's call: they must be copies."""
    _passes(checks.check_landmark_update, _landmark_update_in_place, capsys)
    _passes(checks.check_schur_reduce, _schur_reduce_in_place, capsys)


def test_single_precision_and_complex_results_are_named(capsys):
    """float32 is not blamed on the math ("no small-angle series"); imaginary parts are not dropped."""
    _fails(checks.check_so3_exp, lambda w: A.so3_exp(w).astype(np.float32), "float32 (single precision)")
    _fails(checks.check_project, lambda *a: A.project(*a).astype(np.float32), "float32 (single precision)")
    _fails(checks.check_pose_update, lambda *a: (A.pose_update(*a)[0], A.pose_update(*a)[1].astype(np.float32)),
           "float32 (single precision)")
    _fails(checks.check_hat, lambda w: A.hat(w) + 1e-3j, "complex: it has imaginary parts")
    _fails(checks.check_so3_exp, lambda w: A.so3_exp(w) + 0.5j * np.eye(3), "complex")
    _passes(checks.check_so3_exp, lambda w: A.so3_exp(w) + 1e-17j, capsys)  # rounding noise of an eig or expm
    _passes(checks.check_hat, lambda w: A.hat(w).tolist(), capsys)


def _landmark_update_by_kalman(m, Sigma, z, world_T_imu, Ks, cam_T_imu, noise_var):
    from visla_edu.course import kalman

    H = A.landmark_jacobian(Ks, cam_T_imu, world_T_imu, m)
    z_pred = Ks @ A.projection(cam_T_imu @ np.linalg.inv(world_T_imu) @ np.r_[m, 1.0])
    return kalman.update(m, Sigma, z - z_pred, H, noise_var * np.eye(4))


def _se3_exp_from_the_smoothers_jacobian(u):
    from visla_edu import smoother

    T = np.eye(4)
    T[:3, :3] = A.so3_exp(u[3:])
    T[:3, 3] = smoother.se3_right_jacobian(-np.asarray(u, dtype=float))[:3, :3] @ u[:3]
    return T


def _motion_residual_by_finite_differences(T_prev, T_next, step_inv):
    from visla_edu.course import numdiff

    def e(T0, T1):
        return lie.se3_log(step_inv @ np.linalg.inv(T0) @ T1)

    J_prev = numdiff.central_jacobian(lambda d: e(T_prev @ lie.se3_exp(d), T_next), np.zeros(6))
    J_next = numdiff.central_jacobian(lambda d: e(T_prev, T_next @ lie.se3_exp(d)), np.zeros(6))
    return e(T_prev, T_next), J_prev, J_next


def test_library_shortcuts_to_an_exercise_are_hidden_inside_its_check():
    _fails(checks.check_landmark_update, _landmark_update_by_kalman, "kalman.update")
    _fails(checks.check_se3_exp, _se3_exp_from_the_smoothers_jacobian, "se3_right_jacobian")
    _fails(checks.check_motion_residual, _motion_residual_by_finite_differences, "numdiff.central_jacobian")


def test_gate_check(capsys):
    _passes(checks.check_gate, A.gate, capsys)
    checks.check_gate(A.gate, hidden=True)
    _fails(checks.check_gate, lambda r, S, p: A.gate(r, S, 1 - p), "not 1 - p")
    _fails(checks.check_gate, lambda r, S, p: A.gate(r, S, p, dof=2), "4 degrees of freedom")
    _fails(checks.check_gate, lambda r, S, p: ~A.gate(r, S, p), "rejected ones")
    _fails(checks.check_gate, lambda r, S, p: A.gate(r, np.linalg.inv(S), p), "not r^T S r")
    _fails(checks.check_gate, lambda r, S, p: A.gate(r, np.broadcast_to(np.eye(4), S.shape), p), "not |r|^2")
    _fails(checks.check_gate, lambda r, S, p: np.sqrt(np.einsum("ki,ki->k", r, np.linalg.solve(S, r[..., None])[
        ..., 0])) <= stats.chi2.ppf(p, 4), "SQUARED distance")


def test_align_rigid_check(capsys):
    _passes(checks.check_align_rigid, A.align_rigid, capsys)
    checks.check_align_rigid(A.align_rigid, hidden=True)
    _fails(checks.check_align_rigid, lambda e, g: A.align_rigid(e, g, fix_reflection=False), "reflection")
    _fails(checks.check_align_rigid, lambda e, g: np.linalg.inv(A.align_rigid(e, g)), "inverse")
    _fails(checks.check_align_rigid, lambda e, g: A.align_rigid(g, e), "inverse")

    def transposed(e, g):
        T = A.align_rigid(e, g)
        R = T[:3, :3].T
        T[:3, :3], T[:3, 3] = R, g.mean(axis=0) - R @ e.mean(axis=0)
        return T

    def centroid_not_rotated(e, g):
        T = A.align_rigid(e, g)
        T[:3, 3] = g.mean(axis=0) - e.mean(axis=0)
        return T

    _fails(checks.check_align_rigid, transposed, "transposed")
    _fails(checks.check_align_rigid, centroid_not_rotated, "rotate the centroid")
    _fails(checks.check_align_rigid, lambda e, g: A.align_rigid(e - e.mean(axis=0) * 0, g)[:3], "wrong shape")


def _pose_update_twist_swapped(mu, Sigma, *args):
    """The right update, but its correction applied as [w; v]."""
    mu_new, Sigma_new = A.pose_update(mu, Sigma, *args)
    delta = lie.se3_log(np.linalg.inv(mu) @ mu_new)
    return mu @ lie.se3_exp(np.r_[delta[3:], delta[:3]]), Sigma_new


def test_smoothing_checks(capsys):
    from visla_edu import smoother

    _passes(checks.check_motion_residual, A.motion_residual, capsys)
    _passes(checks.check_schur_reduce, A.schur_reduce, capsys)
    _passes(checks.check_gauss_newton_step, A.gauss_newton_step, capsys)

    mr = checks.check_motion_residual
    _fails(mr, lambda *a: _motion_parts(*a, e=lambda r: -r[0]), "wrong sign")
    _fails(mr, lambda T0, T1, s: _motion_parts(T0, T1, s, e=lambda r: lie.se3_log(np.linalg.inv(T0) @ T1)),
           "increment exp(-tau u^) is missing")
    _fails(mr, lambda *a: _motion_parts(*a, J_next=lambda r: np.eye(6)), "missing J_r(e)^-1")
    _fails(mr, lambda *a: _motion_parts(*a, J_next=lambda r: smoother.se3_right_jacobian(r[0])), "not its inverse")
    _fails(mr, lambda *a: _motion_parts(*a, J_prev=lambda r: -r[2]), "missing the adjoint")
    _fails(mr, lambda *a: _motion_parts(*a, J_prev=lambda r: -r[1]), "J_prev has the wrong sign")
    _fails(mr, lambda *a: A.motion_residual(*a)[:2], "return the tuple")

    _fails(checks.check_schur_reduce, _schur_added, "added the correction")
    _fails(checks.check_schur_reduce, lambda H_pp, H_pm, H_mm, g_p, g_m: (A.schur_reduce(
        H_pp, H_pm, H_mm, g_p, g_m)[0], g_p), "same reduction")
    _fails(checks.check_schur_reduce, lambda H_pp, H_pm, H_mm, g_p, g_m: A.schur_reduce(
        H_pp, H_pm, np.linalg.inv(H_mm), g_p, g_m), "inverse of H_mm")
    _fails(checks.check_schur_reduce, lambda H_pp, H_pm, H_mm, g_p, g_m: (H_pp, g_p), "dropped, not eliminated")

    _passes(checks.check_pose_marginal_covariance, A.pose_marginal_covariance, capsys)
    checks.check_pose_marginal_covariance(A.pose_marginal_covariance, hidden=True)
    _passes(checks.check_pose_marginal_covariance,  # the dense inverse of the whole system is right too
            lambda H_pp, H_pm, H_mm: np.linalg.inv(np.block([[H_pp, H_pm], [H_pm.T, block_diag(*H_mm)]]))[
                :len(H_pp), :len(H_pp)], capsys)
    pm = checks.check_pose_marginal_covariance
    _fails(pm, lambda H_pp, H_pm, H_mm: np.linalg.inv(H_pp), "conditions on the landmarks")
    _fails(pm, lambda H_pp, H_pm, H_mm: A.schur_reduce(H_pp, H_pm, H_mm, np.zeros(len(H_pp)),
                                                       np.zeros(H_pm.shape[1]))[0], "not S itself")
    _fails(pm, lambda H_pp, H_pm, H_mm: A.pose_marginal_covariance(H_pp, H_pm, np.linalg.inv(H_mm)), "inverse of H_mm")
    _fails(pm, lambda H_pp, H_pm, H_mm: np.linalg.inv(2 * H_pp - np.linalg.inv(
        A.pose_marginal_covariance(H_pp, H_pm, H_mm))), "added the correction")

    def step_plus(T, p_body, q_world):  # the step of -r: twice the distance the other way
        return A.gauss_newton_step(T, p_body, 2 * (p_body @ T[:3, :3].T + T[:3, 3]) - q_world)

    def step_left(T, p_body, q_world):  # exp(delta^) T for the right step's delta
        return np.linalg.inv(T) @ A.gauss_newton_step(T, p_body, q_world) @ T

    _fails(checks.check_gauss_newton_step, step_plus, "wrong sign")
    _fails(checks.check_gauss_newton_step, step_left, "on the right")
    _fails(checks.check_gauss_newton_step, lambda T, p, q: T, "wrong values")


# --------------------------------------------------------------------------- shared behaviour


ALL_CHECKS = [getattr(checks, name) for name in checks.__all__ if name.startswith("check_")]


@pytest.mark.parametrize("hidden", [False, True], ids=["visible", "hidden"])
@pytest.mark.parametrize("check", ALL_CHECKS, ids=lambda c: c.__name__)
def test_stub_raises_not_implemented(check, hidden):
    with pytest.raises(NotImplementedError, match="not implemented yet") as info:
        check(_stub, hidden=hidden)
    # nbgrader validate shows "    NotImplementedError: <first line>" and cuts it at 87 characters
    assert len(f"    NotImplementedError: {_first_line(info.value)}") <= 87
    # and every later line indented by 4: wrapped at 79, they show whole (TEACHING.md, "Feedback")
    lines = str(info.value).split("\n")
    assert all(len(line) <= 79 for line in lines), lines
    assert lines[-1].endswith("then run this check again")


@pytest.mark.parametrize("check", ALL_CHECKS, ids=lambda c: c.__name__)
def test_crashing_function_gives_assertion(check):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("boom")

    with pytest.raises(AssertionError, match="ZeroDivisionError") as info:
        check(broken)
    assert len(_first_line(info.value)) <= 79


def test_an_answer_calling_an_unfinished_exercise_names_that_exercise():
    """pose_jacobian written with the student's odot, still a stub: the message names odot."""
    def odot(s):
        raise NotImplementedError("odot: write your solution here")

    def pose_jacobian(Ks, cam_T_imu, mu, m):
        s = A.se3_inv(mu) @ np.r_[m, 1.0]
        q = cam_T_imu @ s
        return -Ks @ A.projection_jacobian(q) @ cam_T_imu @ odot(s)

    with pytest.raises(NotImplementedError) as info:
        checks.check_pose_jacobian(pose_jacobian)
    first, rest = str(info.value).split("\n", 1)
    assert first == "pose_jacobian calls odot, which is not implemented yet"
    assert "write odot first" in rest and "odot: write your solution here" in rest
    assert all(len(line) <= 79 for line in str(info.value).split("\n"))
    # the stub of the exercise itself still says so
    with pytest.raises(NotImplementedError, match="^pose_jacobian is not implemented yet"):
        checks.check_pose_jacobian(_stub)


def test_checks_are_deterministic(capsys):
    checks.check_so3_exp(A.so3_exp)
    first = capsys.readouterr().out
    checks.check_so3_exp(A.so3_exp)
    assert capsys.readouterr().out == first


def test_long_first_lines_are_wrapped():
    from visla_edu.course.checks._core import fail

    err = fail("average_nees_bounds", "a hint that is much too long for one line " * 3 + "\nthe details")
    first, rest = str(err).split("\n", 1)
    assert len(first) <= 79 and first.startswith("average_nees_bounds: a hint")
    assert rest.endswith("the details") and "too long" in rest


def test_compare_names_the_closest_mistake_not_the_first_that_matches_loosely():
    """Where mistakes nearly coincide (tiny angles), the first loose match is not the mistake."""
    from visla_edu.course.checks._core import compare

    expected = np.array([1.0, 2.0])
    got = expected + [3e-7, 0.0]  # wrong (beyond 1e-7 relative) but within the loose match of all below
    variants = [("far mistake", lambda: expected + [6e-7, 0.0]), ("exact mistake", lambda: got.copy()),
                ("also exact", lambda: got.copy())]
    with pytest.raises(AssertionError, match="^f: exact mistake"):
        compare("f", got, expected, "here", variants)
    # a mistake no closer to the answer than the right one names nothing
    with pytest.raises(AssertionError, match="^f: wrong values"):
        compare("f", got, expected, "here", [("no better than right", lambda: expected - [3e-7, 0.0])])


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


@pytest.mark.parametrize("num_landmarks, stride, words", [
    (100, 0, r"stride must be a positive integer \(1 keeps every landmark\), got 0"),
    (100, -3, "stride must be a positive integer .*, got -3"),
    (100, 2.5, "stride must be a positive integer .*, got 2.5"),
    (-1, 1, "num_landmarks must be a non-negative integer, got -1"),
    (10.0, 1, "num_landmarks must be a non-negative integer, got 10.0")])
def test_reference_dense_covariance_bytes_refuses_bad_counts(num_landmarks, stride, words):
    with pytest.raises(ValueError, match=words):
        checks.reference_dense_covariance_bytes(num_landmarks, stride)


def test_the_reference_fallbacks_agree_with_independent_answers():
    """checks.reference_* (the notebooks' fallbacks while an exercise is unfinished) are correct."""
    rng = np.random.default_rng(5)
    for M, stride in [(5105, 1), (13289, 20), (0, 1), (7, 3)]:
        assert checks.reference_dense_covariance_bytes(M, stride) == A.dense_covariance_bytes(M, stride)
    A_p = rng.normal(size=(12, 12))
    H_pm = rng.normal(size=(12, 9))
    blocks = np.stack([B @ B.T + 3 * np.eye(3) for B in rng.normal(size=(3, 3, 3))])
    g_p, g_m = rng.normal(size=12), rng.normal(size=9)
    for got, expected in zip(checks.reference_schur_reduce(A_p @ A_p.T, H_pm, blocks, g_p, g_m),
                             A.schur_reduce(A_p @ A_p.T, H_pm, blocks, g_p, g_m)):
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-10)
    truth = lie.se3_exp(rng.normal(size=6))
    p_body = rng.normal(scale=5.0, size=(10, 3))
    q_world = p_body @ truth[:3, :3].T + truth[:3, 3]
    start = truth @ lie.se3_exp(0.1 * rng.normal(size=6))
    np.testing.assert_allclose(checks.reference_gauss_newton_step(start, p_body, q_world),
                               A.gauss_newton_step(start, p_body, q_world), atol=1e-9)


def test_among_mistakes_that_match_the_closest_one_is_named():
    """At an input too small to tell two mistakes apart within the tolerance, the one the answer
    equals is named, not the first in the list (se3_exp at 1e-6 rad: V = I and a swapped V)."""
    from visla_edu.course.checks import _core

    expected = np.array([1.0, 2.0, 3.0])
    got = expected + 4e-7
    variants = [("first, close only by the tolerance", lambda: expected + 1e-6),
                ("the very mistake", lambda: got.copy())]
    assert _core._matching_variant(got, variants, 1e-7, 1e-9, expected) == "the very mistake"
    assert _core._matching_variant(got, variants[:1], 1e-7, 1e-9, expected) is None  # no closer than the right one


def test_the_reference_gauss_newton_jacobian_matches_finite_differences():
    """J_i = R [I, -p_i^] of reference_gauss_newton_step is d r / d delta for T <- T exp(delta^)."""
    from fdiff import fd_jacobian  # tests/fdiff.py
    from visla_edu.course.checks import _smoothing

    rng = np.random.default_rng(6)
    for n in (1, 4):
        T = lie.se3_exp(rng.normal(size=6))
        p_body, q_world = rng.normal(scale=5.0, size=(n, 3)), rng.normal(scale=5.0, size=(n, 3))
        r, J = _smoothing._residual_and_jacobian(T, p_body, q_world)
        assert r.shape == (3 * n,) and J.shape == (3 * n, 6)
        J_fd = fd_jacobian(lambda d: _smoothing._residual_and_jacobian(T @ lie.se3_exp(d), p_body, q_world)[0],
                           np.zeros(6), 1e-5)
        np.testing.assert_allclose(J, J_fd, rtol=1e-8, atol=1e-8)
