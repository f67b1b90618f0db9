"""Checks of notebook 06 (pose uncertainty): curly-hat, the transition F, the left-perturbation prediction."""

import numpy as np

from visla_edu import lie, motion
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, fmt, ok, rng, student
from visla_edu.course.checks._inputs import NEAR_ZERO_HINT, random_covariance, random_pose, swap_twist, twists

__all__ = ["check_curly_hat", "check_pose_transition", "check_left_pose_prediction",
           "reference_left_pose_prediction"]


@exercise_check
def check_curly_hat(curly_hat, hidden=False):
    """Exercise 06: ``curly_hat(u) -> (6, 6)`` for ``u = [v; w]``: ``[[hat(w), hat(v)], [0, hat(w)]]``.

    On ``[1, 2, 3, 4, 5, 6]`` and random twists (hidden: zero, a tiny rotation and random ones);
    compares with :func:`visla_edu.lie.curly_hat`, which it hides.
    """
    name = "curly_hat"
    generator = rng(hidden)
    fixed = [np.zeros(6), np.array([0.0, 0, 0, 1e-9, 0, 0])] if hidden else [np.array([1.0, 2, 3, 4, 5, 6])]
    call = student(curly_hat, name, hide=[lie.curly_hat])
    cases = fixed + [generator.normal(size=6) for _ in range(4)]
    for u in cases:
        got = as_array(call(u), name, (6, 6))
        ref = lie.curly_hat(u)
        v, w = lie.hat(u[:3]), lie.hat(u[3:])
        Z = np.zeros((3, 3))
        compare(name, got, ref, f"for u = {fmt(u)}", [
            ("wrong twist order: u = [v; w]\nthe diagonal blocks are hat(w) = hat(u[3:]) and the "
             "off-diagonal one hat(v) = hat(u[:3])", lambda: lie.curly_hat(swap_twist(u))),
            ("hat(v) belongs in the upper-right block\n[[hat(w), hat(v)], [0, hat(w)]] for [v; w]",
             lambda: np.block([[w, Z], [v, w]])),
            ("the signs are flipped (you built curly_hat(-u))", lambda: -ref),
            ("curly_hat is transposed", lambda: ref.T),
        ])
    ok(f"{name}: [[hat(w), hat(v)], [0, hat(w)]] agrees with the library on {len(cases)} twists [v; w]", hidden)


@exercise_check
def check_pose_transition(pose_transition, hidden=False):
    """Exercise 06: ``pose_transition(u, tau) -> F (6, 6) = exp(-tau curly_hat(u))`` in closed form.

    ``F`` acts on right perturbations, ``u = [v; w]`` is a body twist. On every other
    :func:`~visla_edu.course.checks._inputs.twists` (``w = 0`` among them), ``tau`` of 0.05 to 0.2 s;
    a 4x4 result fails at once. Compares with :func:`visla_edu.motion.pose_transition`
    (``rtol=1e-7``, ``atol=1e-9``). Hides it, ``motion.imu_step`` and ``lie.adjoint``; ``lie.se3_exp`` stays.
    """
    name = "pose_transition"
    generator = rng(hidden)
    call = student(pose_transition, name, hide=[motion.pose_transition, motion.imu_step, lie.adjoint])
    for u in twists(generator, hidden)[1 if hidden else 0::2]:
        tau = float(generator.uniform(0.05, 0.2))
        out = call(u, tau)
        if np.shape(out) == (4, 4):
            raise fail(name, "got a 4x4 matrix; F is 6x6, it acts on perturbations",
                       "use the adjoint of exp(-tau u^), a 6x6 matrix")
        got = as_array(out, name, (6, 6))
        ref = motion.pose_transition(u, tau)
        compare(name, got, ref, f"for u = {fmt(u)}, tau = {tau:.3f}", [
            ("missing minus sign: F = exp(-tau curly_hat(u)) = Ad(exp(-tau u^))\nthe perturbation is "
             "carried backwards through the motion step", lambda: motion.pose_transition(u, -tau)),
            ("F is transposed", lambda: ref.T),
            ("wrong twist order: u = [v; w]", lambda: motion.pose_transition(swap_twist(u), tau)),
            ("you used I - tau curly_hat(u), the first-order approximation\nuse the exact closed form "
             "Ad(exp(-tau u^))", lambda: np.eye(6) - tau * lie.curly_hat(u)),
        ], rtol=1e-7, atol=1e-9, nan_hint=NEAR_ZERO_HINT)
    ok(f"{name}: closed form agrees with expm(-tau curly_hat(u)), including at rest", hidden)


def reference_left_pose_prediction(mu, Sigma, u, tau, W):
    """The library's left-perturbation prediction of a pose: ``(mu exp(tau u^), Sigma + Ad(mu_next) W Ad(mu_next)^T)``.

    The pose part of :func:`visla_edu.motion.predict_invariant_covariance`: the transition is the
    identity, the step's body-frame noise enters rotated into the world frame (``J_r(tau u)`` dropped
    as in the right form). Notebooks fall back on it (:func:`~visla_edu.course.checks._core.student_or_reference`).

    Parameters
    ----------
    mu : ndarray, shape (4, 4)
    Sigma, W : ndarray, shape (6, 6)
        Covariance of the left perturbation ``xi = [p; theta]`` of ``T = exp(xi^) mu``; the twist noise.
    u : ndarray, shape (6,)
        The body twist ``[v; w]``.
    tau : float
        The step (s).

    Returns
    -------
    mu_next : ndarray, shape (4, 4)
    Sigma_next : ndarray, shape (6, 6)
    """
    mu_next = motion.predict_pose(mu, u, tau)
    return mu_next, motion.predict_invariant_covariance(np.array(Sigma, dtype=float), mu_next, np.zeros((0, 3)), W)


def _rotated(Sigma, A, W):
    return Sigma + A @ W @ A.T


def _left_covariance_variants(mu, Sigma, u, tau, W):
    """(hint, callable) pairs: the covariance of each likely mistake of the left-perturbation prediction."""
    mu_next = motion.predict_pose(mu, u, tau)
    F = motion.pose_transition(u, tau)
    Ad = lie.adjoint(mu_next)
    return [
        ("that is the right perturbation's F Sigma F^T + W\nfor T = exp(xi^) mu the motion multiplies mu on "
         "the right and leaves the world-frame error alone: F = I, the noise enters as Ad(mu_next) tau n",
         lambda: F @ Sigma @ F.T + W),
        ("F = I for the left perturbation: do not apply F\nthe noise alone moves the world-frame error, "
         "Sigma + Ad(mu_next) W Ad(mu_next)^T", lambda: _rotated(F @ Sigma @ F.T, Ad, W)),
        ("the noise is in the body frame: rotate it into the world\nSigma + Ad(mu_next) W Ad(mu_next)^T, "
         "not Sigma + W", lambda: Sigma + W),
        ("use the pose after the step, Ad(mu exp(tau u^))\nthe step's noise acts at its end: "
         "mu exp(tau u^) exp(tau n^) = exp((Ad(mu_next) tau n)^) mu_next", lambda: _rotated(Sigma, lie.adjoint(mu), W)),
        ("Ad(mu_next^-1) maps the world into the body; the noise goes the other way: Ad(mu_next)",
         lambda: _rotated(Sigma, lie.adjoint(lie.se3_inv(mu_next)), W)),
        ("the adjoint is transposed: Sigma + Ad W Ad^T, not Ad^T W Ad", lambda: _rotated(Sigma, Ad.T, W)),
    ]


def _left_cases(generator, hidden):
    """``(mu, Sigma, u, tau, W)`` cases: generic poses, the last from the identity (hidden: other draws)."""
    cases = []
    chosen = twists(generator, hidden)[2::3]
    for k, u in enumerate(chosen):
        mu = np.eye(4) if k == len(chosen) - 1 else random_pose(generator, scale=20.0)
        tau = float(generator.uniform(0.05, 0.2))
        Sigma = 1e-3 * random_covariance(generator, 6)
        W = motion.motion_noise(tau, generator.uniform(0.05, 0.5, 3), generator.uniform(0.005, 0.05, 3))
        cases.append((mu, Sigma, u, tau, W))
    return cases


@exercise_check
def check_left_pose_prediction(left_pose_prediction, hidden=False):
    """Exercise 06: ``left_pose_prediction(mu, Sigma, u, tau, W) -> (mu_next, Sigma_next)``, left perturbation.

    As :func:`reference_left_pose_prediction` (which it hides) on some of
    :func:`~visla_edu.course.checks._inputs.twists` (tiny angles and rest among them), the last
    from the identity pose: compares the mean (``atol=1e-9``) and the covariance (``rtol=1e-7``,
    ``atol=1e-12``). Also hides :func:`visla_edu.motion.predict_invariant_covariance` and
    :func:`visla_edu.motion.invariant_noise_factor`; ``lie.adjoint`` and ``lie.se3_exp`` stay.
    """
    name = "left_pose_prediction"
    call = student(left_pose_prediction, name,
                   hide=[motion.predict_invariant_covariance, motion.invariant_noise_factor,
                         reference_left_pose_prediction])
    cases = _left_cases(rng(hidden), hidden)
    for mu, Sigma, u, tau, W in cases:
        out = call(mu, Sigma, u, tau, W)
        if not isinstance(out, (tuple, list)) or len(out) != 2:
            raise fail(name, "return the pair (mu_next, Sigma_next)", f"got {fmt(out)}")
        mu_ref, Sigma_ref = reference_left_pose_prediction(mu, Sigma, u, tau, W)
        where = f"for u = {fmt(u)}, tau = {tau:.3f}"
        compare(name, as_array(out[0], name, (4, 4), "mean"), mu_ref, where, [
            ("the mean moves on the right: mu exp(tau u^)\nthe IMU measures body-frame twists, whatever "
             "the error's frame", lambda: lie.se3_exp(tau * np.asarray(u)) @ mu),
        ], atol=1e-9, nan_hint=NEAR_ZERO_HINT)
        compare(name, as_array(out[1], name, (6, 6), "covariance"), Sigma_ref, where,
                _left_covariance_variants(mu, Sigma, u, tau, W), rtol=1e-7, atol=1e-12)
    ok(f"{name}: F = I and the noise rotated into the world, Ad(mu_next) W Ad(mu_next)^T, on {len(cases)} steps",
       hidden)
