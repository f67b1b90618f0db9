"""A project submission written outside the library: dead reckoning plus a landmark VIO, numpy only.

The tests grade it with ``visla-edu project grade``. From visla_edu it takes only the types of the
interface (``StepRecord``, the observation codes); the filter (SE(3), the stereo model, the EKF) is
written here. Conventions as the course's: twist ``u = [v; w]``, poses ``world_T_imu``, right
perturbation ``T = mu exp(delta^)``.

VIO: each landmark is placed once, at its first observation with enough disparity (stereo
triangulation; its covariance from the pixel noise), and stays fixed; the pose is updated with the
observations of placed landmarks inside a chi-square gate, whose noise includes the landmark's own
uncertainty.
"""

import numpy as np

from visla_edu.codes import OBS_FAR, OBS_GATED, OBS_IGNORED, OBS_NEW, OBS_NO_DEPTH, OBS_USED
from visla_edu.filters import StepRecord


def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def se3_exp(xi):
    """exp of the twist ``xi = [v; w]``: ``[[R, V v], [0, 1]]`` (series below 1e-4 rad)."""
    v, w = xi[:3], xi[3:]
    theta = np.linalg.norm(w)
    W = hat(w)
    if theta < 1e-4:
        a, b, c = 1.0 - theta**2 / 6, 0.5 - theta**2 / 24, 1.0 / 6 - theta**2 / 120
    else:
        a, b, c = np.sin(theta) / theta, (1 - np.cos(theta)) / theta**2, (theta - np.sin(theta)) / theta**3
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + a * W + b * W @ W
    T[:3, 3] = (np.eye(3) + b * W + c * W @ W) @ v
    return T


def inverse(T):
    R, p = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R.T, -R.T @ p
    return out


def adjoint(T):
    """``[[R, p^ R], [0, R]]``, the adjoint of ``T`` on twists ``[v; w]``."""
    R, p = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3], A[:3, 3:], A[3:, 3:] = R, hat(p) @ R, R
    return A


def dpi_dq(q):
    return np.array([[1, 0, -q[0] / q[2], 0], [0, 1, -q[1] / q[2], 0], [0, 0, 0, 0], [0, 0, -q[3] / q[2], 1]]) / q[2]


def sigmas(value):
    return np.broadcast_to(np.asarray(value, dtype=float), (3,))


class NumpyVio:
    """Dead reckoning with a 6x6 pose covariance, corrected by fixed triangulated landmarks."""

    def __init__(self, dataset, config):
        self.dataset, self.config = dataset, config
        K, b = dataset.K, dataset.b
        self.fsu, self.fsv, self.cu, self.cv, self.b = K[0, 0], K[1, 1], K[0, 2], K[1, 2], b
        self.Ks = np.array([[K[0, 0], 0, K[0, 2], 0], [0, K[1, 1], K[1, 2], 0],
                            [K[0, 0], 0, K[0, 2], -K[0, 0] * b], [0, K[1, 1], K[1, 2], 0]])
        self.imu_T_cam = dataset.imu_T_cam
        self.cam_T_imu = inverse(dataset.imu_T_cam)
        lag = config.imu_lag
        twists = dataset.twists
        self.step_twists = twists[np.clip(np.arange(len(twists) - 1) + lag, 0, len(twists) - 1)]
        self.noise = np.concatenate([sigmas(config.sigma_linear_velocity), sigmas(config.sigma_angular_velocity)])
        self.pixel_var = config.sigma_pixel**2
        self.gate = config.gate_threshold
        self.mu, self.Sigma = np.eye(4), np.zeros((6, 6))
        self.landmarks = {}  # id -> (p_world (3,), covariance (3, 3))
        self.t = -1

    def predict(self):
        tau = self.dataset.time_steps[self.t - 1]
        step = se3_exp(tau * self.step_twists[self.t - 1])
        F = adjoint(inverse(step))
        self.mu = self.mu @ step
        self.Sigma = F @ self.Sigma @ F.T + np.diag((tau * self.noise) ** 2)

    def triangulate(self, z):
        """World point and its covariance from one stereo observation ``[uL, vL, uR, vR]``."""
        d = z[0] - z[2]
        Z = self.fsu * self.b / d
        x_cam = np.array([(z[0] - self.cu) * Z / self.fsu, (z[1] - self.cv) * Z / self.fsv, Z])
        dZ = np.array([-Z / d, 0.0, Z / d, 0.0])
        J = np.zeros((3, 4))
        J[2] = dZ
        J[0] = (z[0] - self.cu) / self.fsu * dZ + np.array([Z / self.fsu, 0, 0, 0])
        J[1] = (z[1] - self.cv) / self.fsv * dZ + np.array([0, Z / self.fsv, 0, 0])
        world_T_cam = self.mu @ self.imu_T_cam
        R = world_T_cam[:3, :3]
        C = R @ J @ J.T @ R.T * self.pixel_var + self.config.landmark_prior_sigma**2 * np.eye(3)
        return world_T_cam[:3, :3] @ x_cam + world_T_cam[:3, 3], C

    def predict_observation(self, m):
        """Predicted pixels (4,), pose Jacobian (4, 6) and landmark Jacobian (4, 3); None behind the camera."""
        mu_inv = inverse(self.mu)
        s = mu_inv @ np.append(m, 1.0)
        q = self.cam_T_imu @ s
        if q[2] < 0.5:
            return None
        odot = np.zeros((4, 6))
        odot[:3, :3], odot[:3, 3:] = np.eye(3), -hat(s[:3])
        J_pi = self.Ks @ dpi_dq(q)
        return self.Ks @ (q / q[2]), -J_pi @ self.cam_T_imu @ odot, J_pi @ self.cam_T_imu @ mu_inv[:, :3]

    def update(self, ids, z, status, z_pred):
        """Gate and use the observations of placed landmarks; return (NIS, dof)."""
        rows = []
        for k, (i, zk) in enumerate(zip(ids, z)):
            if i not in self.landmarks or status[k] == OBS_NO_DEPTH:
                continue
            predicted = self.predict_observation(self.landmarks[i][0])
            if predicted is None:
                status[k] = OBS_GATED
                continue
            zp, H, J_m = predicted
            z_pred[k] = zp
            R = J_m @ self.landmarks[i][1] @ J_m.T + self.pixel_var * np.eye(4)
            r = zk - zp
            if r @ np.linalg.solve(H @ self.Sigma @ H.T + R, r) > self.gate:
                status[k] = OBS_GATED
                continue
            status[k] = OBS_USED
            rows.append((r, H, R))
        if not rows:
            return np.nan, 0
        r = np.concatenate([row[0] for row in rows])
        H = np.vstack([row[1] for row in rows])
        R = np.zeros((len(r), len(r)))
        for k, row in enumerate(rows):
            R[4 * k:4 * k + 4, 4 * k:4 * k + 4] = row[2]
        S = H @ self.Sigma @ H.T + R
        gain = np.linalg.solve(S, H @ self.Sigma).T
        self.mu = self.mu @ se3_exp(gain @ r)
        A = np.eye(6) - gain @ H
        self.Sigma = A @ self.Sigma @ A.T + gain @ R @ gain.T
        return float(r @ np.linalg.solve(S, r)), len(r)

    def place(self, ids, z, status):
        for k, (i, zk) in enumerate(zip(ids, z)):
            if i in self.landmarks or status[k] == OBS_NO_DEPTH:
                continue
            if zk[0] - zk[2] < self.config.min_init_disparity:
                status[k] = OBS_FAR
                continue
            self.landmarks[i] = self.triangulate(zk)
            status[k] = OBS_NEW

    def step(self):
        self.t += 1
        if self.t > 0:
            self.predict()
        ids, z = self.dataset.observations(self.t)
        status = np.full(len(ids), OBS_IGNORED)
        status[z[:, 0] - z[:, 2] <= 0] = OBS_NO_DEPTH
        z_pred = np.full((len(ids), 4), np.nan)
        nis, dof = self.update(ids, z, status, z_pred)
        self.place(ids, z, status)
        return StepRecord(t=self.t, world_T_imu=self.mu.copy(), pose_cov=self.Sigma.copy(), ids=ids.copy(),
                          z=z.copy(), z_pred=z_pred, status=status, nis=nis, nis_dof=dof,
                          active_ids=np.zeros(0, dtype=np.int64), active_means=np.zeros((0, 3)),
                          active_covs=np.zeros((0, 3, 3)))


def make_filter(dataset, config):
    return NumpyVio(dataset, config)
