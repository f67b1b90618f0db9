"""Correct answers to the exercises, written as a student would (numpy and the allowed library calls).

The checks hide the library's own version of each exercise while they run the student's
function, so these answers never call it: each is written out, like the solutions in
``solutions/``. Deliberately wrong answers in the tests are built from these.
"""

import numpy as np
from scipy import stats
from scipy.linalg import block_diag


def hat(w):
    w1, w2, w3 = np.asarray(w, dtype=float)
    return np.array([[0.0, -w3, w2], [w3, 0.0, -w1], [-w2, w1, 0.0]])


def _coefficients(theta2):
    """``A = sin t/t``, ``B = (1 - cos t)/t^2``, ``C = (t - sin t)/t^3``, series below 0.1 rad."""
    theta = np.sqrt(theta2)
    if theta < 0.1:
        A = 1 - theta2 / 6 * (1 - theta2 / 20 * (1 - theta2 / 42))
        B = 0.5 * (1 - theta2 / 12 * (1 - theta2 / 30 * (1 - theta2 / 56)))
        C = (1 - theta2 / 20 * (1 - theta2 / 42 * (1 - theta2 / 72))) / 6
        return A, B, C
    return np.sin(theta) / theta, (1 - np.cos(theta)) / theta2, (theta - np.sin(theta)) / (theta2 * theta)


def so3_exp(w):
    w = np.asarray(w, dtype=float)
    A, B, _ = _coefficients(float(w @ w))
    W = hat(w)
    return np.eye(3) + A * W + B * W @ W


def se3_exp(u):
    u = np.asarray(u, dtype=float)
    v, w = u[:3], u[3:]
    A, B, C = _coefficients(float(w @ w))
    W = hat(w)
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + A * W + B * W @ W
    T[:3, 3] = (np.eye(3) + B * W + C * W @ W) @ v
    return T


def se3_inv(T):
    R, p = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R.T, -R.T @ p
    return out


def dead_reckon(time_stamps, twists, lag=0, left=False, scale_tau=True, clip=True):
    time_stamps, twists = np.asarray(time_stamps, dtype=float), np.asarray(twists, dtype=float)
    poses = [np.eye(4)]
    for t, tau in enumerate(np.diff(time_stamps)):
        index = min(max(t + lag, 0), len(twists) - 1) if clip else (t + lag) % len(twists)
        step = se3_exp((tau if scale_tau else 1.0) * twists[index])
        poses.append(step @ poses[-1] if left else poses[-1] @ step)
    return np.array(poses)


def so3_log(R, angle="atan2", sign=1.0):
    """The rotation vector of R; ``angle="arccos"`` or ``"arcsin"`` make the tests' wrong answers."""
    R = np.asarray(R, dtype=float)
    s = sign * 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    c = 0.5 * (np.trace(R) - 1)
    sin_t = np.linalg.norm(s)
    theta = {"atan2": np.arctan2(sin_t, c), "arccos": np.arccos(np.clip(c, -1, 1)),
             "arcsin": np.arcsin(min(sin_t, 1.0))}[angle]
    factor = 1 + theta**2 / 6 if sin_t < 1e-6 else theta / sin_t
    return factor * s


def white_noise(twists, robust=True, scale=1.4826, divide=np.sqrt(6)):
    second = np.diff(np.asarray(twists, dtype=float), n=2, axis=0)
    spread = np.median(np.abs(second - np.median(second, axis=0)), axis=0) if robust else np.std(second, axis=0)
    return (scale if robust else 1.0) * spread / divide


def stereo_matrix(K, b):
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.array([[fsu, 0, cu, 0], [0, fsv, cv, 0], [fsu, 0, cu, -fsu * b], [0, fsv, cv, 0]], dtype=float)


def projection(q):
    q = np.asarray(q, dtype=float)
    return q / q[..., 2:3]


def project(Ks, cam_T_imu, world_T_imu, p_world, inverse=se3_inv):
    q = np.c_[p_world, np.ones(len(p_world))] @ (cam_T_imu @ inverse(world_T_imu)).T
    return projection(q) @ Ks.T


def triangulate(z, K, b):
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    depth = fsu * b / (z[..., 0] - z[..., 2])
    return np.stack([(z[..., 0] - cu) * depth / fsu, (z[..., 1] - cv) * depth / fsv, depth], axis=-1)


def triangulate_bearing(z, K, b):
    """The course's bearing triangulation for the rectified pair (R = I, p = [b, 0, 0])."""
    K_inv = np.linalg.inv(K)
    z1 = np.c_[z[:, 0], z[:, 1], np.ones(len(z))] @ K_inv.T
    z2 = np.c_[z[:, 2], z[:, 3], np.ones(len(z))] @ K_inv.T
    a = z1 - z2
    lam = (a @ np.array([b, 0.0, 0.0])) / np.einsum("ij,ij->i", a, a)
    return lam[:, None] * z1


def projection_jacobian(q):
    q1, q2, q3, q4 = np.asarray(q, dtype=float)
    return np.array([[1, 0, -q1 / q3, 0], [0, 1, -q2 / q3, 0], [0, 0, 0, 0], [0, 0, -q4 / q3, 1]]) / q3


def odot(s):
    out = np.zeros((4, 6))
    out[:3, :3] = np.eye(3)
    out[:3, 3:] = -hat(s[:3])
    return out


def numerical_jacobian(f, x, eps=1e-6):
    x = np.asarray(x, dtype=float)
    cols = [(np.asarray(f(x + eps * e)) - np.asarray(f(x - eps * e))) / (2 * eps) for e in np.eye(x.size)]
    return np.stack(cols, axis=-1)


def pose_jacobian(Ks, cam_T_imu, mu, m, inverse=se3_inv):
    s = inverse(mu) @ np.r_[m, 1.0]
    q = cam_T_imu @ s
    return -Ks @ projection_jacobian(q) @ cam_T_imu @ odot(s)


def landmark_jacobian(Ks, cam_T_imu, world_T_imu, m, inverse=se3_inv):
    imu_T_world = inverse(world_T_imu)
    q = cam_T_imu @ imu_T_world @ np.r_[m, 1.0]
    return Ks @ projection_jacobian(q) @ cam_T_imu @ imu_T_world[:, :3]


def init_landmark(z, K, b, imu_T_cam, world_T_imu):
    return (world_T_imu @ imu_T_cam @ np.r_[triangulate(z, K, b), 1.0])[:3]


def landmark_update(m, Sigma, z, world_T_imu, Ks, cam_T_imu, noise_var, flip=False, plus=False, inverse=se3_inv):
    q = cam_T_imu @ inverse(world_T_imu) @ np.r_[m, 1.0]
    H = landmark_jacobian(Ks, cam_T_imu, world_T_imu, m, inverse)
    K = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(4))
    r = Ks @ projection(q) - z if flip else z - Ks @ projection(q)
    return m + K @ r, (np.eye(3) + (1 if plus else -1) * K @ H) @ Sigma


def curly_hat(u):
    out = np.zeros((6, 6))
    out[:3, :3] = out[3:, 3:] = hat(u[3:])
    out[:3, 3:] = hat(u[:3])
    return out


def pose_transition(u, tau):
    X = se3_exp(-tau * np.asarray(u, dtype=float))
    R, p = X[:3, :3], X[:3, 3]
    F = np.zeros((6, 6))
    F[:3, :3] = F[3:, 3:] = R
    F[:3, 3:] = hat(p) @ R
    return F


def adjoint(T):
    R, p = T[:3, :3], T[:3, 3]
    out = np.zeros((6, 6))
    out[:3, :3] = out[3:, 3:] = R
    out[:3, 3:] = hat(p) @ R
    return out


def left_pose_prediction(mu, Sigma, u, tau, W, at="next", transition=False, rotate=True):
    """The left perturbation's prediction; the keywords make the tests' wrong answers."""
    mu_next = mu @ se3_exp(tau * np.asarray(u, dtype=float))
    Ad = {"next": adjoint(mu_next), "before": adjoint(mu), "inverse": adjoint(se3_inv(mu_next)),
          "transposed": adjoint(mu_next).T}[at]
    F = pose_transition(u, tau) if transition else np.eye(6)
    return mu_next, F @ Sigma @ F.T + (Ad @ W @ Ad.T if rotate else W)


def pose_update(mu, Sigma, z, p_world, Ks, cam_T_imu, noise_var, side="right", sign=1.0, inverse=se3_inv):
    H = np.concatenate([pose_jacobian(Ks, cam_T_imu, mu, m, inverse) for m in p_world])
    z_pred = project(Ks, cam_T_imu, mu, p_world, inverse)
    K = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(len(H)))
    delta = sign * K @ (np.asarray(z) - z_pred).ravel()
    return (mu @ se3_exp(delta) if side == "right" else se3_exp(delta) @ mu), (np.eye(6) - K @ H) @ Sigma


def landmark_observation_noise(J_landmark, Sigma_landmark, noise_var):
    return np.array([noise_var * np.eye(4) + J @ S @ J.T for J, S in zip(J_landmark, Sigma_landmark)])


def slam_jacobian(J_pose, J_landmark, slots, n):
    H = np.zeros((4 * len(slots), 6 + 3 * n))
    for i, s in enumerate(slots):
        H[4 * i:4 * i + 4, :6] = J_pose[i]
        H[4 * i:4 * i + 4, 6 + 3 * s:9 + 3 * s] = J_landmark[i]
    return H


def slam_null_space(world_T_imu, p_landmarks, pose_block="inverse", sign=-1.0, swap=False, landmarks=True):
    """The world's rigid motions as joint-state directions; the keywords make the tests' wrong answers."""
    blocks = [{"inverse": adjoint(se3_inv(world_T_imu)), "forward": adjoint(world_T_imu), "identity": np.eye(6)}[pose_block]]
    for m in np.asarray(p_landmarks, dtype=float).reshape(-1, 3):
        block = np.hstack([sign * hat(m), np.eye(3)] if swap else [np.eye(3), sign * hat(m)])
        blocks.append(block if landmarks else np.zeros((3, 6)))
    return np.vstack(blocks)


def invariant_pose_jacobian(Ks, cam_T_imu, world_T_imu, m):
    return np.hstack([-landmark_jacobian(Ks, cam_T_imu, world_T_imu, m), np.zeros((4, 3))])


def dense_covariance_bytes(num_landmarks, stride=1):
    return (6 + 3 * -(-num_landmarks // stride)) ** 2 * 8


def marginalize(Sigma, keep):
    return Sigma[np.ix_(keep, keep)]


def motion_noise(tau, sigma_v, sigma_w):
    return np.diag(np.r_[np.full(3, (tau * sigma_v) ** 2), np.full(3, (tau * sigma_w) ** 2)])


def nees(error, cov):
    return float(error @ np.linalg.solve(cov, error))


def average_nees_bounds(dof, n, probability=0.95):
    tail = (1 - probability) / 2
    return tuple(stats.chi2.ppf([tail, 1 - tail], dof * n) / n)


def gate(innovations, S, probability, dof=4):
    d2 = np.array([r @ np.linalg.solve(S_i, r) for r, S_i in zip(innovations, S)])
    return d2 <= stats.chi2.ppf(probability, dof)


def align_rigid(p_est, p_gt, fix_reflection=True):
    c_est, c_gt = p_est.mean(axis=0), p_gt.mean(axis=0)
    U, _, Vt = np.linalg.svd((p_est - c_est).T @ (p_gt - c_gt))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) if fix_reflection else 1.0])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, c_gt - R @ c_est
    return T


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


# --------------------------------------------------------------------------- 00b Kalman primer


def kalman_update_1d(mean, variance, z, noise_variance):
    gain = variance / (variance + noise_variance)
    return mean + gain * (z - mean), (1 - gain) * variance


def kalman_predict(x, P, F, Q):
    F = np.asarray(F, dtype=float)
    return F @ np.asarray(x, dtype=float), F @ np.asarray(P, dtype=float) @ F.T + np.asarray(Q, dtype=float)


# --------------------------------------------------------------------------- 08 smoothing


def motion_residual(world_T_prev, world_T_next, step_inv):
    from visla_edu import lie, smoother

    e = lie.se3_log(step_inv @ np.linalg.inv(world_T_prev) @ world_T_next)
    J_next = smoother.se3_right_jacobian_inv(e)
    J_prev = -J_next @ lie.adjoint(np.linalg.inv(world_T_next) @ world_T_prev)
    return e, J_prev, J_next


def schur_reduce(H_pp, H_pm, H_mm, g_p, g_m):
    S, b = H_pp.copy(), g_p.copy()
    for j, block in enumerate(H_mm):  # H_mm is block diagonal: one 3x3 solve per landmark
        H_pj = H_pm[:, 3 * j:3 * j + 3]
        S -= H_pj @ np.linalg.solve(block, H_pj.T)
        b -= H_pj @ np.linalg.solve(block, g_m[3 * j:3 * j + 3])
    return S, b


def pose_marginal_covariance(H_pp, H_pm, H_mm):
    S, _ = schur_reduce(H_pp, H_pm, H_mm, np.zeros(len(H_pp)), np.zeros(H_pm.shape[1]))
    return np.linalg.inv(S)


def gauss_newton_step(world_T_body, p_body, q_world):
    from scipy.linalg import expm

    R, t = world_T_body[:3, :3], world_T_body[:3, 3]
    r = (p_body @ R.T + t - q_world).ravel()
    J = np.concatenate([np.hstack([R, -R @ hat(p)]) for p in p_body])
    delta = -np.linalg.solve(J.T @ J, J.T @ r)
    xi = np.zeros((4, 4))
    xi[:3, :3], xi[:3, 3] = hat(delta[3:]), delta[:3]
    return world_T_body @ expm(xi)
# --------------------------------------------------------------------------- 09 capstone


def capstone_predict(parts, world_T_imu, Sigma, u, tau, W):
    F = parts.pose_transition(u, tau)
    out = np.array(Sigma, dtype=float)
    out[:6] = F @ out[:6]
    out[:, :6] = out[:, :6] @ F.T
    out[:6, :6] += W
    return world_T_imu @ parts.se3_exp(tau * np.asarray(u)), out


def capstone_landmarks(parts, world_T_imu, Sigma, z, K, b, imu_T_cam, C_pixels):
    p_new = np.array([parts.init_landmark(z_i, K, b, imu_T_cam, world_T_imu) for z_i in z])
    G = np.concatenate([(world_T_imu @ parts.odot(se3_inv(world_T_imu) @ np.r_[m, 1.0]))[:3] for m in p_new])
    D, k = len(Sigma), len(z)
    out = np.zeros((D + 3 * k, D + 3 * k))
    out[:D, :D] = Sigma
    out[D:, :D] = G @ Sigma[:6]
    out[:D, D:] = out[D:, :D].T
    out[D:, D:] = G @ Sigma[:6, :6] @ G.T + block_diag(*C_pixels)
    return p_new, out


def capstone_slam(parts, world_T_imu, Sigma, p_active, slots, z, Ks, cam_T_imu, noise_var):
    m = p_active[slots]
    J_pose = np.array([parts.pose_jacobian(Ks, cam_T_imu, world_T_imu, m_i) for m_i in m])
    J_lm = np.array([parts.landmark_jacobian(Ks, cam_T_imu, world_T_imu, m_i) for m_i in m])
    H = parts.slam_jacobian(J_pose, J_lm, slots, len(p_active))
    gain = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(len(H)))
    delta = gain @ (z - parts.project(Ks, cam_T_imu, world_T_imu, m)).ravel()
    return (world_T_imu @ parts.se3_exp(delta[:6]), (np.eye(len(Sigma)) - gain @ H) @ Sigma,
            p_active + delta[6:].reshape(-1, 3))
