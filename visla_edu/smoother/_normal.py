"""Cost, linearisation and the Schur-complement step of a :class:`~._problem.Problem`.

With the whitened residuals ``r`` and Jacobian ``J`` (right perturbations of the pose variables, then the landmark
positions), the robust cost ``C = sum_obs rho(s_i) + sum_t |W_t^{-1/2} e_t|^2 (+ priors)`` and IRLS weights
``w_i = rho'(s_i) / sigma^2``, Gauss-Newton solves::

    [[H_pp, H_pm], [H_mp, H_mm]] [dp; dm] = -[g_p; g_m],     H = J^T W J,  g = J^T W r

``H_mm`` is block diagonal (one 3x3 block per landmark), so the landmarks are eliminated first (Schur complement)::

    S = H_pp - H_pm H_mm^{-1} H_mp,   S dp = -g_p + H_pm H_mm^{-1} g_m,
    dm = -H_mm^{-1} (g_m + H_mp dp)

``S`` is an :class:`~._envelope.EnvelopeSystem` with ``V_j = H_pj L_j^{-T}`` (``H_mm,j = L_j L_j^T``), never formed
densely; Levenberg-Marquardt damping adds ``lambda diag(H)``. The functions take the ``problem``, ``world_T_imu``
(T, 4, 4) by dataset frame and ``landmarks`` (L, 3), the problem's (world frame, local order); ``n`` is the number
of pose variables, ``N`` of observations (landmark-major, active or not).
"""

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from visla_edu import lie
from visla_edu.camera import single_intrinsics
from visla_edu.smoother import _envelope
from visla_edu.smoother._factors import motion_residuals, robust_loss

__all__ = ["Linearization", "Step", "observation_errors", "evaluate", "linearize", "solve_step",
           "apply_step", "marginals", "normal_equations"]


#: Upper-triangle indices of a 6x6 block (the pose information is symmetric).
_UPPER = np.triu_indices(6)


@dataclass
class Linearization:
    """Gauss-Newton blocks at one state (IRLS weights from the same state) and its ``cost``.

    Attributes
    ----------
    Hpp, sub, g_p : ndarray, shape (n, 6, 6), (n - 1, 6, 6), (n, 6)
        Diagonal pose blocks; ``H[l + 1, l]`` from the motion factors; the pose gradient.
    Hpm, Hmm, g_m : ndarray, shape (6, 3, N), (L, 3, 3), (L, 3)
        ``Hpm`` per observation, observation index last (zero at held frames and when inactive).
    """

    cost: float
    Hpp: np.ndarray
    sub: np.ndarray
    g_p: np.ndarray
    Hpm: np.ndarray
    Hmm: np.ndarray
    g_m: np.ndarray


@dataclass
class Step:
    """A damped Gauss-Newton step (:func:`solve_step`, applied by :func:`apply_step`).

    Attributes
    ----------
    d_pose, d_landmark : ndarray, shape (n, 6), (L, 3)
        Right perturbations ``[v; w]`` of the pose variables, ``T <- T exp(d_pose^)``; world-frame landmark increments
        (m), ``m <- m + d_landmark``, zero for inactive landmarks.
    predicted : float
        The decrease the damped linear model predicts, ``-g^T d + lambda d^T diag(H) d`` (the gain ratio's denominator).
    factor : EnvelopeFactor or None
        Of the damped reduced system ``S`` it solved (its inverse approximates the pose covariance at the step's start).
    """

    d_pose: np.ndarray
    d_landmark: np.ndarray
    predicted: float
    factor: object = None


def _camera_points(problem, world_T_imu, landmarks):
    """Per observation ``R = world_R_imu`` (3, 3, N), ``p_imu = R^T (m - t)``, ``q = R_c p_imu + t_c`` (3, N)."""
    poses = world_T_imu[problem.obs_frame]
    d = landmarks[problem.obs_landmark] - poses[:, :3, 3]
    p_imu = (poses[:, :3, :3] * d[:, :, None]).sum(axis=1).T  # R^T d
    R = np.moveaxis(poses[:, :3, :3], 0, -1)
    return R, p_imu, problem.cam_T_imu[:3, :3] @ p_imu + problem.cam_T_imu[:3, 3:]


def _pixels(problem, q):
    """Stereo pixels ``Ks pi(q)`` (:func:`visla_edu.camera.stereo_matrix` row by row) of ``q`` (3, N), (N, 4)."""
    Ks = problem.Ks
    inv_z = 1.0 / q[2]
    u = Ks[0, 0] * q[0] * inv_z + Ks[0, 2]
    v = Ks[1, 1] * q[1] * inv_z + Ks[1, 2]
    if single_intrinsics(Ks):
        return np.stack([u, v, u + Ks[2, 3] * inv_z, v], axis=1)
    u_right = Ks[2, 0] * q[0] * inv_z + Ks[2, 2] + Ks[2, 3] * inv_z
    return np.stack([u, v, u_right, Ks[3, 1] * q[1] * inv_z + Ks[3, 2]], axis=1)


def observation_errors(problem, world_T_imu, landmarks):
    """``s = |h - z|^2 / sigma_pixel^2`` (chi-square, 4 dof, for an inlier) and the depths ``q_z`` (m), (N,) each.

    ``h = Ks pi(cam_T_imu inv(T_t) m_j)``; the depth is not positive behind the camera.
    """
    _, _, q = _camera_points(problem, world_T_imu, landmarks)
    r = _pixels(problem, q) - problem.obs_z
    return (r * r).sum(axis=1) / problem.sigma_pixel**2, q[2]


def _motion_poses(problem, world_T_imu):
    return world_T_imu[problem.motion_from:problem.last_frame + 1]


def _prior_residual(problem, world_T_imu):
    """Whitened prior residual ``U log(mean^{-1} T)`` and its Jacobian, or None."""
    prior = problem.prior
    if prior is None:
        return None
    e = lie.se3_log(lie.se3_inv(prior.mean) @ world_T_imu[prior.frame])
    return prior.sqrt_information @ e, prior.sqrt_information @ lie.se3_right_jacobian_inv(e)


def evaluate(problem, world_T_imu, landmarks, errors=None):
    """Robust cost ``C``; ``inf`` if an active observation is nearer than ``min_depth``; ``errors`` if known."""
    s, depth = observation_errors(problem, world_T_imu, landmarks) if errors is None else errors
    act = problem.active
    if np.any(depth[act] < problem.min_depth):
        return np.inf
    cost = robust_loss(s[act], problem.loss, problem.loss_scale)[0].sum()
    e = motion_residuals(_motion_poses(problem, world_T_imu), problem.step_inv, jacobians=False)
    cost += np.sum((e * problem.motion_sqrt_information) ** 2)
    prior = _prior_residual(problem, world_T_imu)
    if prior is not None:
        cost += prior[0] @ prior[0]
    if problem.landmark_prior is not None:
        cost += _landmark_prior_cost(problem, landmarks)
    return float(cost)


def _landmark_prior_cost(problem, landmarks):
    """``sum_j m^T Lambda m - 2 m^T eta + c`` over the active landmarks (a sum of squares, >= 0)."""
    info, eta, const = problem.landmark_prior
    act = problem.landmark_active
    m = landmarks[act]
    return float(np.sum(m * (info[act] @ m[:, :, None])[:, :, 0]) - 2 * np.sum(m * eta[act]) + np.sum(const[act]))


def _projection_information(problem, q, wr, w):
    """``A^T w A`` (3, 3, N) and ``A^T w r`` (3, N), ``A = d(Ks pi(q)) / d q``, in closed form.

    ``A`` has rows ``fu/z [1, 0, -x/z]`` (uL), ``fv/z [0, 1, -y/z]`` (vL and vR) and
    ``fu/z [1, 0, -(x - b)/z]`` (uR); two intrinsics: :func:`_projection_information_two`.
    """
    if not single_intrinsics(problem.Ks):
        return _projection_information_two(problem, q, wr, w)
    fu, fv = problem.Ks[0, 0], problem.Ks[1, 1]
    inv_z = 1.0 / q[2]
    a, c = fu * inv_z, fv * inv_z
    e_left, e_v = -a * q[0] * inv_z, -c * q[1] * inv_z
    e_right = e_left - problem.Ks[2, 3] * inv_z * inv_z  # Ks[2, 3] = -fu b
    B = np.zeros((3, 3, len(w)))
    B[0, 0] = 2 * w * a * a
    B[0, 2] = B[2, 0] = w * a * (e_left + e_right)
    B[1, 1] = 2 * w * c * c
    B[1, 2] = B[2, 1] = 2 * w * c * e_v
    B[2, 2] = w * (e_left**2 + e_right**2 + 2 * e_v**2)
    Atr = np.stack([a * (wr[:, 0] + wr[:, 2]), c * (wr[:, 1] + wr[:, 3]),
                    e_left * wr[:, 0] + e_right * wr[:, 2] + e_v * (wr[:, 1] + wr[:, 3])])
    return B, Atr


def _projection_information_two(problem, q, wr, w):
    """:func:`_projection_information` for a rig with two intrinsics: each product a sum over ``Ks``'s rows."""
    Ks = problem.Ks
    inv_z = 1.0 / q[2]
    a, a_r = Ks[0, 0] * inv_z, Ks[2, 0] * inv_z
    c, c_r = Ks[1, 1] * inv_z, Ks[3, 1] * inv_z
    e_left, e_right = -a * q[0] * inv_z, -a_r * q[0] * inv_z - Ks[2, 3] * inv_z * inv_z
    e_v, e_v_r = -c * q[1] * inv_z, -c_r * q[1] * inv_z
    B = np.zeros((3, 3, len(w)))
    B[0, 0] = w * (a * a + a_r * a_r)
    B[0, 2] = B[2, 0] = w * (a * e_left + a_r * e_right)
    B[1, 1] = w * (c * c + c_r * c_r)
    B[1, 2] = B[2, 1] = w * (c * e_v + c_r * e_v_r)
    B[2, 2] = w * (e_left**2 + e_right**2 + e_v**2 + e_v_r**2)
    Atr = np.stack([a * wr[:, 0] + a_r * wr[:, 2], c * wr[:, 1] + c_r * wr[:, 3],
                    e_left * wr[:, 0] + e_right * wr[:, 2] + e_v * wr[:, 1] + e_v_r * wr[:, 3]])
    return B, Atr


def _rotate_symmetric(Rc, B):
    """``R_c^T B R_c`` for symmetric ``B`` (3, 3, N), with two matrix products over all N at once."""
    C = (Rc.T @ B.reshape(3, -1)).reshape(B.shape)  # R_c^T B
    return (Rc.T @ np.swapaxes(C, 0, 1).reshape(3, -1)).reshape(B.shape)  # R_c^T (R_c^T B)^T = R_c^T B R_c


def _times(A, B):
    """``A B`` per observation for (3, 3, N) stacks (three broadcast products: faster than einsum here)."""
    return A[:, 0, None] * B[None, 0] + A[:, 1, None] * B[None, 1] + A[:, 2, None] * B[None, 2]


def _times_transpose(A, B):
    """``A B^T`` per observation for (3, 3, N) stacks."""
    return A[:, 0, None] * B[None, :, 0] + A[:, 1, None] * B[None, :, 1] + A[:, 2, None] * B[None, :, 2]


def _hat_times(p, X):
    """``hat(p) X`` per observation: ``p`` (3, N), ``X`` (3, k, N) -> (3, k, N) (cross products)."""
    return np.stack([p[1] * X[2] - p[2] * X[1], p[2] * X[0] - p[0] * X[2], p[0] * X[1] - p[1] * X[0]])


def _observation_blocks(problem, world_T_imu, landmarks):
    """Per-observation weighted blocks (component-first) and the robust cost.

    With ``J_q = A R_c``, the Jacobians of :func:`visla_edu.camera.stereo_projection` are ``J_m = J_q R^T`` and
    ``J_p = [-J_q, J_q P]``, ``P = hat(p_imu)``; so with ``K = J_q^T w J_q`` and ``h = J_q^T w r``::

        J_p^T w J_p = [[K, -K P], [P K, -P K P]]     J_p^T w r = [-h; -P h]
        J_p^T w J_m = -[K R^T; P K R^T]              J_m^T w J_m = R K R^T,   J_m^T w r = R h

    Blocks: ``Hpp`` (21, N) (upper triangle, :data:`_UPPER`), ``g_p`` (6, N), ``Hpm`` (6, 3, N), ``Hmm`` (3, 3, N),
    ``g_m`` (3, N).
    """
    R, p_imu, q = _camera_points(problem, world_T_imu, landmarks)
    r = _pixels(problem, q) - problem.obs_z
    s = (r * r).sum(axis=1) / problem.sigma_pixel**2
    rho, weight = robust_loss(s, problem.loss, problem.loss_scale)
    w = np.where(problem.active, weight / problem.sigma_pixel**2, 0.0)
    B, Atr = _projection_information(problem, q, w[:, None] * r, w)
    Rc = problem.cam_T_imu[:3, :3]
    K = _rotate_symmetric(Rc, B)
    h = Rc.T @ Atr
    PK = _hat_times(p_imu, K)
    KRt = _times_transpose(K, R)
    on_var = problem.obs_var() >= 0  # held poses are not variables
    Hpp = np.empty((6, 6, len(w)))
    Hpp[:3, :3], Hpp[3:, :3] = K, PK
    Hpp[:3, 3:] = np.swapaxes(PK, 0, 1)
    Hpp[3:, 3:] = np.swapaxes(_hat_times(p_imu, np.swapaxes(PK, 0, 1)), 0, 1)  # -P K P
    blocks = {
        "Hpp": Hpp[_UPPER] * on_var, "g_p": -np.concatenate([h, _hat_times(p_imu, h[:, None])[:, 0]]) * on_var,
        "Hpm": -np.concatenate([KRt, _hat_times(p_imu, KRt)]) * on_var,
        "Hmm": _times(R, KRt), "g_m": (R * h[None]).sum(axis=1),
    }
    return blocks, float(rho[problem.active].sum())


def _add_motion(problem, world_T_imu, Hpp, sub, g_p):
    """Add the motion factors (and the pose prior) to the pose blocks, in place; return their cost."""
    e, J_prev, J_next = motion_residuals(_motion_poses(problem, world_T_imu), problem.step_inv)
    sq = problem.motion_sqrt_information
    e, J_prev, J_next = e * sq, J_prev * sq[:, :, None], J_next * sq[:, :, None]
    prev = np.arange(problem.motion_from, problem.last_frame) - problem.first_var
    nxt, var = prev + 1, prev >= 0
    J_nextT, J_prevT = np.swapaxes(J_next, 1, 2), np.swapaxes(J_prev, 1, 2)
    Hpp[nxt] += J_nextT @ J_next
    g_p[nxt] += (J_nextT @ e[:, :, None])[:, :, 0]
    Hpp[prev[var]] += (J_prevT @ J_prev)[var]
    g_p[prev[var]] += (J_prevT @ e[:, :, None])[var, :, 0]
    sub[prev[var]] += (J_nextT @ J_prev)[var]
    cost = float(np.sum(e * e))
    prior = _prior_residual(problem, world_T_imu)
    if prior is not None:
        r, J = prior
        v = problem.prior.frame - problem.first_var
        Hpp[v] += J.T @ J
        g_p[v] += J.T @ r
        cost += float(r @ r)
    return cost


def linearize(problem, world_T_imu, landmarks):
    """The :class:`Linearization` (Gauss-Newton blocks and cost) at a state."""
    obs, cost = _observation_blocks(problem, world_T_imu, landmarks)
    n = problem.num_vars
    upper = np.asarray(problem.frame_sum @ np.ascontiguousarray(obs["Hpp"].T))
    Hpp = np.empty((n, 6, 6))
    Hpp[:, _UPPER[0], _UPPER[1]] = upper
    Hpp[:, _UPPER[1], _UPPER[0]] = upper
    g_p = np.asarray(problem.frame_sum @ obs["g_p"].T)
    sub = np.zeros((max(n - 1, 0), 6, 6))
    cost += _add_motion(problem, world_T_imu, Hpp, sub, g_p)
    Hmm = np.moveaxis(_landmark_sum(problem, obs["Hmm"]), -1, 0)
    g_m = _landmark_sum(problem, obs["g_m"]).T
    if problem.landmark_prior is not None:
        info, eta, _ = problem.landmark_prior
        Hmm += info
        g_m += (info @ landmarks[:, :, None])[:, :, 0] - eta
        cost += _landmark_prior_cost(problem, landmarks)
    return Linearization(cost, Hpp, sub, g_p, obs["Hpm"], Hmm, g_m)


def _landmark_sum(problem, x):
    """Sum per-observation terms ``x`` (..., N) over each landmark's observations -> (..., L)."""
    if x.shape[-1] == 0:
        return np.zeros(x.shape[:-1] + (problem.num_landmarks,))
    return np.add.reduceat(x, problem.landmark_start[:-1], axis=-1)


def _damped(H, damping):
    """``H + damping diag(H)`` for a stack of square blocks."""
    if damping == 0:
        return H
    idx = np.arange(H.shape[-1])
    out = H.copy()
    out[..., idx, idx] += damping * np.maximum(H[..., idx, idx], 1e-12)
    return out


def _landmark_factors(problem, lin, damping):
    """``L_j^{-1}`` of the damped landmark blocks (identity for inactive landmarks), (L, 3, 3)."""
    Hmm = _damped(lin.Hmm, damping)
    Hmm[~problem.landmark_active] = np.eye(3)
    # A landmark whose observations the robust loss has all but switched off has a nearly
    # singular block: a relative floor keeps its Cholesky factor finite (it barely moves).
    Hmm += (1e-12 * np.trace(Hmm, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(3)
    return np.linalg.inv(np.linalg.cholesky(Hmm))


def _reduced_system(problem, lin, damping, L_inv):
    """The Schur complement as an EnvelopeSystem, its right-hand side, and the ``V`` rows."""
    lm = problem.obs_landmark
    V = _times_transpose(lin.Hpm, np.moveaxis(L_inv[lm], 0, -1))  # H_pm L^{-T}, (6, 3, N)
    rows = np.zeros((problem.num_slots, 6, 3))
    on = problem.slot >= 0
    rows[problem.slot[on]] = np.moveaxis(V[:, :, on], -1, 0)
    u = (L_inv @ lin.g_m[:, :, None])[:, :, 0]
    rhs = -lin.g_p + np.asarray(problem.frame_sum @ (V * u[lm].T[None]).sum(axis=1).T)
    keep = problem.landmark_active & (problem.span_hi >= problem.span_lo)
    system = _envelope.EnvelopeSystem(_damped(lin.Hpp, damping), lin.sub, problem.span_lo[keep],
                                      problem.span_hi[keep], problem.span_start[keep], rows)
    return system, rhs, V


def solve_step(problem, lin, damping):
    """Damped Gauss-Newton :class:`Step` (``damping`` = ``lambda`` >= 0); LinAlgError if not positive definite."""
    L_inv = _landmark_factors(problem, lin, damping)
    system, rhs, _ = _reduced_system(problem, lin, damping, L_inv)
    factor = _envelope.cholesky(system)
    d_pose = _envelope.solve(factor, rhs)
    var = problem.obs_var()
    t = _landmark_sum(problem, (lin.Hpm * d_pose[np.maximum(var, 0)].T[:, None]).sum(axis=0)).T
    Hmm_inv = np.swapaxes(L_inv, 1, 2) @ L_inv
    d_landmark = -(Hmm_inv @ (lin.g_m + t)[:, :, None])[:, :, 0]
    d_landmark[~problem.landmark_active] = 0.0
    grad = np.sum(lin.g_p * d_pose) + np.sum(lin.g_m * d_landmark)
    diag = np.sum(np.diagonal(lin.Hpp, axis1=1, axis2=2) * d_pose**2) + \
        np.sum(np.diagonal(lin.Hmm, axis1=1, axis2=2) * d_landmark**2)
    return Step(d_pose, d_landmark, float(-grad + damping * diag), factor)


def apply_step(problem, world_T_imu, landmarks, step):
    """``T <- T exp(dp^)`` on the pose variables, ``m <- m + dm``, in new arrays.

    Returns ``(world_T_imu, landmarks, too_close, errors)``: ``too_close`` (L,) marks the active landmarks the step
    brings closer than ``min_depth`` to (or behind) a camera observing them; ``errors`` is :func:`observation_errors`
    at the new state.
    """
    out = world_T_imu.copy()
    frames = slice(problem.first_var, problem.last_frame + 1)
    out[frames] = world_T_imu[frames] @ lie.se3_exp(step.d_pose)
    moved = landmarks + step.d_landmark
    errors = observation_errors(problem, out, moved)
    too_close = np.zeros(problem.num_landmarks, dtype=bool)
    too_close[problem.obs_landmark[problem.active & ~(errors[1] >= problem.min_depth)]] = True
    return out, moved, too_close, errors


def marginals(problem, lin, landmark_covariance=True):
    """Marginal covariances at the solution: the inverse of the undamped Gauss-Newton Hessian.

    Pose blocks are the diagonal blocks of ``S^{-1}`` (Takahashi recursion); a landmark's is
    ``H_mm^{-1} + Y^T S^{-1}[span, span] Y``, ``Y = H_pm H_mm^{-1}`` over the frames that see it. Returns the pose
    variables' right-perturbation covariances (n, 6, 6) and the landmarks' (L, 3, 3), NaN when inactive (None without
    ``landmark_covariance``); LinAlgError when the reduced system is not positive definite.
    """
    L_inv = _landmark_factors(problem, lin, 0.0)
    system, _, _ = _reduced_system(problem, lin, 0.0, L_inv)
    factor = _envelope.cholesky(system)
    if not landmark_covariance:
        return _envelope.inverse_diagonal(factor), None
    cov = np.swapaxes(L_inv, 1, 2) @ L_inv
    by_lo = np.argsort(system.lo, kind="stable")
    start = np.searchsorted(system.lo[by_lo], np.arange(problem.num_vars + 1))
    keep = np.flatnonzero(problem.landmark_active & (problem.span_hi >= problem.span_lo))

    def visit(lo, hi, Sigma):
        for k in by_lo[start[lo]:start[hi + 1]]:
            off = 6 * (system.lo[k] - lo)
            VL = system.correction(k) @ L_inv[keep[k]]  # Y = V L^{-1} over the landmark's span
            cov[keep[k]] += VL.T @ Sigma[off:off + len(VL), off:off + len(VL)] @ VL

    pose_cov = _envelope.inverse_diagonal(factor, visit)
    cov[~problem.landmark_active] = np.nan
    return pose_cov, cov


def normal_equations(problem, lin):
    """``H``, ``g`` of :class:`~._batch.NormalEquations` at ``lin``, sparse (the solver never builds it)."""
    n, L = problem.num_vars, problem.num_landmarks
    var = problem.obs_var()
    on = var >= 0
    Hpm = np.moveaxis(lin.Hpm, -1, 0)
    Hmm = lin.Hmm.copy()
    Hmm[~problem.landmark_active] = np.eye(3)
    parts = [
        _block_coo(np.arange(n), np.arange(n), lin.Hpp, 6, 6, 0, 0),
        _block_coo(np.arange(1, n), np.arange(n - 1), lin.sub, 6, 6, 0, 0),
        _block_coo(np.arange(n - 1), np.arange(1, n), np.swapaxes(lin.sub, 1, 2), 6, 6, 0, 0),
        _block_coo(var[on], problem.obs_landmark[on], Hpm[on], 6, 3, 0, 6 * n),
        _block_coo(problem.obs_landmark[on], var[on], np.swapaxes(Hpm[on], 1, 2), 3, 6, 6 * n, 0),
        _block_coo(np.arange(L), np.arange(L), Hmm, 3, 3, 6 * n, 6 * n),
    ]
    rows, cols, vals = (np.concatenate(x) for x in zip(*parts))
    H = sparse.csr_matrix((vals, (rows, cols)), shape=(6 * n + 3 * L,) * 2)
    return H, np.concatenate([lin.g_p.ravel(), lin.g_m.ravel()])


def _block_coo(block_rows, block_cols, blocks, bh, bw, row0, col0):
    """COO triplets of dense ``bh x bw`` blocks placed at block coordinates (duplicates add up)."""
    r = row0 + bh * np.asarray(block_rows)[:, None, None] + np.arange(bh)[None, :, None]
    c = col0 + bw * np.asarray(block_cols)[:, None, None] + np.arange(bw)[None, None, :]
    shape = (len(blocks), bh, bw)
    return np.broadcast_to(r, shape).ravel(), np.broadcast_to(c, shape).ravel(), blocks.ravel()
