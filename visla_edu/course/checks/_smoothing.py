"""Checks of notebooks 13 and 14 (smoothing): the motion factor, the Schur complement, a Gauss-Newton step
and the poses' marginal covariance.

Conventions: :mod:`visla_edu.lie`'s; the Gauss-Newton system is ``H dx = -g``.
"""

import numpy as np
import scipy.linalg

from visla_edu import lie
from visla_edu.course import numdiff
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, ok, rng, student
from visla_edu.course.checks._inputs import random_pose, swap_twist
from visla_edu.smoother import motion_residuals

__all__ = ["check_motion_residual", "check_schur_reduce", "check_pose_marginal_covariance", "check_gauss_newton_step",
           "reference_motion_residual", "reference_schur_reduce", "reference_pose_marginal_covariance",
           "reference_gauss_newton_step"]


# --------------------------------------------------------------------------- the motion factor


def reference_motion_residual(world_T_prev, world_T_next, step_inv):
    """``e = log(step_inv T_prev^{-1} T_next)`` and its Jacobians (the library's motion factor).

    Parameters
    ----------
    world_T_prev, world_T_next, step_inv : ndarray, shape (4, 4)
        The poses at the start and the end of the step; ``exp(-tau u^)``, the inverse of the IMU's step.

    Returns
    -------
    e : ndarray, shape (6,)
        The residual twist ``[rho; phi]``.
    J_prev, J_next : ndarray, shape (6, 6)
        For the right perturbations of the two poses: ``J_next = J_r(e)^-1``,
        ``J_prev = -J_r(e)^-1 Ad(T_next^-1 T_prev)`` (:func:`visla_edu.smoother.motion_residuals`).
    """
    e, J_prev, J_next = motion_residuals(np.stack([world_T_prev, world_T_next]), step_inv[None])
    return e[0], J_prev[0], J_next[0]


def _motion_cases(generator, hidden):
    """``(T_prev, T_next, step_inv)``: the next pose is the IMU prediction times a small error."""
    sizes = [0.0, 1e-7, 0.3, 0.9] if hidden else [0.05, 0.2, 0.5]
    cases = []
    for size in sizes:
        T_prev = random_pose(generator)
        step = lie.se3_exp(np.r_[generator.normal(scale=1.0, size=3), generator.normal(scale=0.1, size=3)])
        error = lie.se3_exp(size * generator.normal(size=6) / np.sqrt(6))
        cases.append((T_prev, T_prev @ step @ error, lie.se3_inv(step)))
    return cases


def _motion_variants(T_prev, T_next, step_inv):
    """Deliberate mistakes of each output: ``(e variants, J_prev variants, J_next variants)``."""
    e, J_prev, J_next = reference_motion_residual(T_prev, T_next, step_inv)
    Jinv, Ad = lie.se3_right_jacobian_inv(e), lie.adjoint(lie.se3_inv(T_next) @ T_prev)
    e_variants = [
        ("the residual has the wrong sign: e = log(exp(-tau u^) T_t^-1 T_t+1)", lambda: -e),
        ("the IMU increment exp(-tau u^) is missing from the residual",
         lambda: lie.se3_log(lie.se3_inv(T_prev) @ T_next)),
        ("the IMU increment is on the wrong side: it multiplies from the left",
         lambda: lie.se3_log(lie.se3_inv(T_prev) @ T_next @ step_inv)),
        ("wrong twist order: se3_log gives [rho; phi], linear first", lambda: swap_twist(e)),
    ]
    next_variants = [
        ("J_next is missing J_r(e)^-1\nperturbing T_t+1 by exp(b^) moves e by J_r(e)^-1 b", lambda: np.eye(6)),
        ("J_next uses J_r(e), not its inverse J_r(e)^-1", lambda: lie.se3_right_jacobian(e)),
        ("J_next uses the left Jacobian J_r(-e)^-1; use J_r(e)^-1",
         lambda: lie.se3_right_jacobian_inv(-e)),
    ]
    prev_variants = [
        ("J_prev is missing the adjoint Ad(T_t+1^-1 T_t)", lambda: -Jinv),
        ("J_prev has the wrong sign: J_prev = -J_r(e)^-1 Ad(T_t+1^-1 T_t)", lambda: -J_prev),
        ("J_prev uses the adjoint of the wrong relative pose: Ad(T_t+1^-1 T_t)",
         lambda: -Jinv @ lie.adjoint(lie.se3_inv(T_prev) @ T_next)),
        ("J_prev has the adjoint transposed", lambda: -Jinv @ Ad.T),
        ("J_prev is missing J_r(e)^-1 in front of the adjoint", lambda: -Ad),
    ]
    return e_variants, prev_variants, next_variants


@exercise_check
def check_motion_residual(motion_residual, hidden=False):
    """Exercise 13: ``motion_residual(T_prev, T_next, step_inv) -> (e (6,), J_prev (6, 6), J_next (6, 6))``.

    A tuple of three for steps whose next pose is the IMU prediction times an error: compares with
    :func:`reference_motion_residual` (``e``: ``rtol=1e-7``, ``atol=1e-9``; Jacobians ``rtol=1e-6``,
    ``atol=1e-9``). Hides it, the library's motion factor and ``numdiff.central_jacobian``.
    """
    name = "motion_residual"
    call = student(motion_residual, name, hide=[motion_residuals, reference_motion_residual,
                                                             numdiff.central_jacobian])
    for T_prev, T_next, step_inv in _motion_cases(rng(hidden), hidden):
        out = call(T_prev, T_next, step_inv)
        if not isinstance(out, tuple) or len(out) != 3:
            raise fail(name, "return the tuple (e, J_prev, J_next)", f"got {type(out).__name__}")
        e_ref, prev_ref, next_ref = reference_motion_residual(T_prev, T_next, step_inv)
        e_var, prev_var, next_var = _motion_variants(T_prev, T_next, step_inv)
        where = f"for a step whose residual has size {np.linalg.norm(e_ref):.2g}"
        compare(name, as_array(out[0], name, (6,), "residual e"), e_ref, where, e_var, rtol=1e-7, atol=1e-9)
        compare(name, as_array(out[2], name, (6, 6), "J_next"), next_ref, where, next_var, rtol=1e-6, atol=1e-9)
        compare(name, as_array(out[1], name, (6, 6), "J_prev"), prev_ref, where, prev_var, rtol=1e-6, atol=1e-9)
    ok(f"{name}: e = log(exp(-tau u^) T_t^-1 T_t+1), J_next = J_r(e)^-1, J_prev = -J_r(e)^-1 Ad", hidden)


# --------------------------------------------------------------------------- the Schur complement


def reference_schur_reduce(H_pp, H_pm, H_mm, g_p, g_m):
    """Eliminate the landmarks from ``[[H_pp, H_pm], [H_pm^T, blockdiag(H_mm)]] dx = -[g_p; g_m]``.

    Parameters
    ----------
    H_pp, H_pm, g_p, g_m : ndarray, shapes (p, p), (p, 3 L), (p,), (3 L,)
    H_mm : ndarray, shape (L, 3, 3)
        The landmarks' diagonal blocks (each inverted with ``numpy.linalg.inv``).

    Returns
    -------
    S : ndarray, shape (p, p)
        ``H_pp - H_pm H_mm^-1 H_pm^T``.
    b : ndarray, shape (p,)
        ``g_p - H_pm H_mm^-1 g_m``; the reduced system is ``S dp = -b``.
    """
    L = len(H_mm)
    H_mm_inv = np.zeros((3 * L, 3 * L))
    for j in range(L):
        H_mm_inv[3 * j:3 * j + 3, 3 * j:3 * j + 3] = np.linalg.inv(H_mm[j])
    return H_pp - H_pm @ H_mm_inv @ H_pm.T, g_p - H_pm @ H_mm_inv @ g_m


def _schur_cases(generator, hidden):
    """Small systems ``(H_pp, H_pm, H_mm blocks, g_p, g_m)`` of ``J^T J`` form."""
    shapes = [(6, 1), (12, 5), (18, 7), (6, 40)] if hidden else [(6, 2), (12, 4)]
    cases = []
    for p, L in shapes:
        J = generator.normal(size=(4 * (p + 3 * L), p + 3 * L)) * (generator.uniform(size=(1, p + 3 * L)) + 0.2)
        H = J.T @ J
        blocks = np.stack([H[p + 3 * j:p + 3 * j + 3, p + 3 * j:p + 3 * j + 3] for j in range(L)])
        g = generator.normal(size=p + 3 * L)
        cases.append((H[:p, :p], H[:p, p:], blocks, g[:p], g[p:]))
    return cases


def _schur_variants(H_pp, H_pm, H_mm, g_p, g_m):
    """Deliberate mistakes: ``(S variants, b variants)``."""
    S, b = reference_schur_reduce(H_pp, H_pm, H_mm, g_p, g_m)
    C = H_pp - S  # H_pm H_mm^-1 H_pm^T
    blocks = scipy.linalg.block_diag(*H_mm)
    S_variants = [
        ("S = H_pp - H_pm H_mm^-1 H_pm^T: you added the correction", lambda: H_pp + C),
        ("use the inverse of H_mm between H_pm and H_pm^T, not H_mm itself",
         lambda: H_pp - H_pm @ blocks @ H_pm.T),
        ("S is H_pp minus a correction: you returned the correction alone", lambda: C),
        ("the landmarks were dropped, not eliminated: S = H_pp - H_pm H_mm^-1 H_pm^T", lambda: H_pp),
    ]
    reduction = g_p - b  # H_pm H_mm^-1 g_m
    b_variants = [
        ("the gradient needs the same reduction: b = g_p - H_pm H_mm^-1 g_m", lambda: g_p),
        ("b = g_p - H_pm H_mm^-1 g_m: you added the correction", lambda: g_p + reduction),
        ("use the inverse of H_mm in b, not H_mm itself", lambda: g_p - H_pm @ blocks @ g_m),
    ]
    return S_variants, b_variants


@exercise_check
def check_schur_reduce(schur_reduce, hidden=False):
    """Exercise 13: ``schur_reduce(H_pp, H_pm, H_mm (L, 3, 3), g_p, g_m) -> (S (p, p), b (p,))``.

    For random systems of ``J^T J`` form, the tuple ``(S, b)``: compares with
    :func:`reference_schur_reduce`, which it hides.
    """
    name = "schur_reduce"
    call = student(schur_reduce, name, hide=[reference_schur_reduce])
    for H_pp, H_pm, H_mm, g_p, g_m in _schur_cases(rng(hidden), hidden):
        out = call(H_pp, H_pm, H_mm, g_p, g_m)
        if not isinstance(out, tuple) or len(out) != 2:
            raise fail(name, "return the tuple (S, b)", f"got {type(out).__name__}")
        p, L = len(H_pp), len(H_mm)
        S_ref, b_ref = reference_schur_reduce(H_pp, H_pm, H_mm, g_p, g_m)
        S_var, b_var = _schur_variants(H_pp, H_pm, H_mm, g_p, g_m)
        where = f"for {p // 6} poses and {L} landmarks"
        compare(name, as_array(out[0], name, (p, p), "reduced matrix S"), S_ref, where, S_var, rtol=1e-7, atol=1e-9)
        compare(name, as_array(out[1], name, (p,), "reduced gradient b"), b_ref, where, b_var, rtol=1e-7, atol=1e-9)
    ok(f"{name}: S = H_pp - H_pm H_mm^-1 H_pm^T, b = g_p - H_pm H_mm^-1 g_m", hidden)


def reference_pose_marginal_covariance(H_pp, H_pm, H_mm):
    """The poses' marginal covariance ``(H_pp - H_pm H_mm^-1 H_pm^T)^-1``, the inverse of the Schur complement.

    The pose block of ``H^-1``, the landmarks' uncertainty included; inputs as in
    :func:`reference_schur_reduce`.

    Returns
    -------
    ndarray, shape (p, p)
    """
    S, _ = reference_schur_reduce(H_pp, H_pm, H_mm, np.zeros(len(H_pp)), np.zeros(H_pm.shape[1]))
    return np.linalg.inv(S)


def _marginal_variants(H_pp, H_pm, H_mm):
    S_variants, _ = _schur_variants(H_pp, H_pm, H_mm, np.zeros(len(H_pp)), np.zeros(H_pm.shape[1]))
    S = H_pp - S_variants[2][1]()
    return [
        ("inv(H_pp) conditions on the landmarks: use inv(S)\ninv(H_pp) is the poses' covariance if the "
         "landmarks were known exactly; the marginal includes their uncertainty: inv(S) with "
         "S = H_pp - H_pm H_mm^-1 H_pm^T", lambda: np.linalg.inv(H_pp)),
        ("the covariance is inv(S), not S itself\nS is the poses' information matrix", lambda: S),
        ("you added the correction H_pm H_mm^-1 H_pm^T\nS = H_pp - H_pm H_mm^-1 H_pm^T",
         lambda: np.linalg.inv(S_variants[0][1]())),
        ("use the inverse of H_mm inside S, not H_mm itself", lambda: np.linalg.inv(S_variants[1][1]())),
        ("the covariance is inv(S), not inv(H_pp) - inv(S)\n(the block inverse of H)",
         lambda: np.linalg.inv(H_pp) - np.linalg.inv(S)),
    ]


@exercise_check
def check_pose_marginal_covariance(pose_marginal_covariance, hidden=False):
    """Exercise 14: ``pose_marginal_covariance(H_pp, H_pm, H_mm (L, 3, 3)) -> (p, p)``, the poses' marginal.

    On the systems of :func:`check_schur_reduce`; compares with
    :func:`reference_pose_marginal_covariance` (``rtol=1e-6``, ``atol=1e-10``). Hides it and
    :func:`reference_schur_reduce` (the student's own ``schur_reduce`` may be used).
    """
    name = "pose_marginal_covariance"
    call = student(pose_marginal_covariance, name, hide=[reference_pose_marginal_covariance, reference_schur_reduce])
    for H_pp, H_pm, H_mm, _, _ in _schur_cases(rng(hidden), hidden):
        p, L = len(H_pp), len(H_mm)
        got = as_array(call(H_pp, H_pm, H_mm), name, (p, p), "covariance")
        compare(name, got, reference_pose_marginal_covariance(H_pp, H_pm, H_mm), f"for {p // 6} poses and {L} landmarks",
                _marginal_variants(H_pp, H_pm, H_mm), rtol=1e-6, atol=1e-10)
    ok(f"{name}: inv(H_pp - H_pm H_mm^-1 H_pm^T), the poses' marginal with the landmarks' uncertainty", hidden)


# --------------------------------------------------------------------------- a Gauss-Newton step


def _residual_and_jacobian(world_T_body, p_body, q_world, rotate=True, hat_sign=-1.0):
    """``r_i = (T p_i)_xyz - q_i`` stacked (3N,) and ``J`` (3N, 6) for ``T <- T exp(delta^)``."""
    R = world_T_body[:3, :3] if rotate else np.eye(3)
    r = (p_body @ world_T_body[:3, :3].T + world_T_body[:3, 3] - q_world).ravel()
    J = np.concatenate([np.hstack([R, hat_sign * R @ lie.hat(p)]) for p in p_body])
    return r, J


def _step(world_T_body, p_body, q_world, sign=-1.0, side="right", swap=False, **jacobian):
    r, J = _residual_and_jacobian(world_T_body, p_body, q_world, **jacobian)
    delta = sign * np.linalg.solve(J.T @ J, J.T @ r)
    delta = swap_twist(delta) if swap else delta
    update = lie.se3_exp(delta)
    return world_T_body @ update if side == "right" else update @ world_T_body


def reference_gauss_newton_step(world_T_body, p_body, q_world):
    """One Gauss-Newton step of ``sum_i |(T p_i)_xyz - q_i|^2`` with ``T <- T exp(delta^)``.

    ``r_i = R p_i + t - q_i``, ``J_i = R [I, -hat(p_i)]`` (3, 6) and
    ``delta = -(J^T J)^-1 J^T r`` over the stacked ``r`` (3N,) and ``J`` (3N, 6).

    Parameters
    ----------
    world_T_body : ndarray, shape (4, 4)
        The current pose ``T = [[R, t], [0, 1]]``.
    p_body, q_world : ndarray, shape (N, 3)
        Points in the body frame and their measured positions in the world frame.

    Returns
    -------
    ndarray, shape (4, 4)
        ``world_T_body @ se3_exp(delta)``.
    """
    return _step(world_T_body, p_body, q_world)


def _gauss_newton_cases(generator, hidden):
    """``(T, p_body (N, 3), q_world (N, 3))``: q from a pose near T, with a little noise."""
    settings = [(3, 0.0), (8, 0.5), (30, 1.5), (4, 1e-6)] if hidden else [(5, 0.2), (12, 0.8)]
    cases = []
    for n, size in settings:
        T = random_pose(generator)
        truth = T @ lie.se3_exp(size * generator.normal(size=6) / np.sqrt(6))
        p_body = generator.normal(scale=5.0, size=(n, 3))
        q_world = p_body @ truth[:3, :3].T + truth[:3, 3] + generator.normal(scale=0.01, size=(n, 3))
        cases.append((T, p_body, q_world))
    return cases


def _gauss_newton_variants(T, p_body, q_world):
    return [
        ("the step has the wrong sign: delta = -(J^T J)^-1 J^T r", lambda: _step(T, p_body, q_world, sign=1.0)),
        ("apply the step on the right: T exp(delta^) (the right perturbation)",
         lambda: _step(T, p_body, q_world, side="left")),
        ("the Jacobian is missing the rotation R: d(T p)/d delta = R [I, -p^]",
         lambda: _step(T, p_body, q_world, rotate=False)),
        ("wrong sign of the rotation part: d(T p)/d delta = R [I, -p^]",
         lambda: _step(T, p_body, q_world, hat_sign=1.0)),
        ("wrong twist order: delta = [rho; phi], linear first", lambda: _step(T, p_body, q_world, swap=True)),
    ]


@exercise_check
def check_gauss_newton_step(gauss_newton_step, hidden=False):
    """Exercise 14: ``gauss_newton_step(world_T_body, p_body (N, 3), q_world (N, 3)) -> world_T_body (4, 4)``.

    With 1 cm noise on ``q_world``; compares with :func:`reference_gauss_newton_step`
    (``rtol=1e-6``, ``atol=1e-8``) and hides the step it computes with.
    """
    name = "gauss_newton_step"
    call = student(gauss_newton_step, name, hide=[_step])
    for T, p_body, q_world in _gauss_newton_cases(rng(hidden), hidden):
        got = as_array(call(T, p_body, q_world), name, (4, 4), "new pose")
        compare(name, got, reference_gauss_newton_step(T, p_body, q_world),
                f"for {len(p_body)} points, starting {np.linalg.norm(lie.se3_log(T)):.2g} from the origin",
                _gauss_newton_variants(T, p_body, q_world), rtol=1e-6, atol=1e-8)
    ok(f"{name}: delta = -(J^T J)^-1 J^T r, J_i = R [I, -p_i^], T <- T exp(delta^)", hidden)
