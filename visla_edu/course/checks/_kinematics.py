"""Checks of notebooks 01 and 04 (SE(3) kinematics): hat, the exponentials, the logarithm, dead reckoning."""

import numpy as np
import scipy.linalg

from visla_edu import lie, motion
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, fmt, ok, rng, student
from visla_edu.course.checks._inputs import (NEAR_ZERO_HINT, not_rotation, not_se3, rotation_transposed,
                                      rotation_vectors, swap_twist, twists, unit)

__all__ = [
    "check_hat",
    "check_so3_exp",
    "check_se3_exp",
    "check_dead_reckon",
    "check_so3_log",
]

_EPS = np.finfo(float).eps


def _hat_inputs(generator, hidden):
    if hidden:
        fixed = [np.array([1, -2, 3]), [0.5, 0.0, -1.0], 1e8 * unit(generator)]
    else:
        fixed = [np.array([1.0, 2.0, 3.0]), np.zeros(3)]
    return fixed + [generator.normal(size=3) for _ in range(5)]


@exercise_check
def check_hat(hat, hidden=False):
    """Exercise 01: ``hat(w) -> (3, 3)`` with ``hat(w) @ x == cross(w, x)``.

    On ``[1, 2, 3]``, zero and random vectors (hidden: also an integer array, a list and a vector of
    size 1e8); compares with :func:`visla_edu.lie.hat`, which it hides.
    """
    name = "hat"
    call = student(hat, name, hide=[lie.hat])
    for w in _hat_inputs(rng(hidden), hidden):
        got = as_array(call(w), name, (3, 3))
        w = np.asarray(w, dtype=float)
        ref = lie.hat(w)
        compare(name, got, ref, f"for w = {fmt(w)}", [
            ("the signs are flipped (you built hat(w)^T = -hat(w))\nhat(w) @ x must equal np.cross(w, x)",
             lambda: ref.T),
            ("right numbers in the wrong places\nrow 0 is [0, -w3, w2], row 1 [w3, 0, -w1], row 2 [-w2, w1, 0]",
             lambda: lie.hat(w[[2, 0, 1]])),
        ], extra=lambda g: "" if np.allclose(g, -g.T) else "hat(w) must be skew-symmetric (hat(w)^T = -hat(w))")
    ok(f"{name}: skew-symmetric and hat(w) @ x == cross(w, x)", hidden)


def _rodrigues_with(w, normalised=True, sign=1.0):
    """Rodrigues' ``I + sin(t) W + sign (1 - cos t) W^2``, ``W = hat(w / t)`` (a mistake: not ``normalised``)."""
    t = np.linalg.norm(w)
    W = lie.hat(w) / t if normalised else lie.hat(w)
    return np.eye(3) + np.sin(t) * W + sign * (1 - np.cos(t)) * W @ W


def _tiny_rotation_vectors(generator, hidden):
    """Angles where ``(1 - cos t)/t^2`` and ``(t - sin t)/t^3`` lose digits, axes far from the axes."""
    angles = (3e-7, 3e-6, 2e-5) if hidden else (1e-7, 1e-6, 1e-5)
    out = []
    for t in angles:
        axis = np.array([1.0, -1.0, 1.0]) + generator.uniform(-0.2, 0.2, 3)
        out.append(t * axis / np.linalg.norm(axis))
    return out


def _series_B(t):
    """``(1 - cos t)/t^2`` to full precision for any ``t > 0``: ``2 sin^2(t/2) / t^2``."""
    return 0.5 * (np.sin(t / 2) / (t / 2)) ** 2


def _series_C(t):
    """``(t - sin t)/t^3`` by its series (for ``t <= 1e-4`` the truncation is below 1e-30)."""
    t2 = t * t
    return (1 - t2 / 20 * (1 - t2 / 42)) / 6


def _tiny_angle_failure(name, t, error):
    digits = max(0.0, -np.log10(_EPS / (t * t / 2)))
    return fail(name, f"no small-angle series: digits lost at {t:.0e} rad",
                f"at the angle t = {t:.0e} rad your translation is off by {error:.1e} (relative to |v|); in "
                f"float64 (1 - cos t)/t^2 keeps only about {digits:.0f} correct digit(s) there and (t - sin t)/t^3 "
                "fewer, and in J_l v the first multiplies hat(w) v, of size t |v| only, so its error shows.",
                "Below a small angle (visla-edu switches at 0.1 rad) use the Taylor series "
                "(1 - cos t)/t^2 ~ 1/2 - t^2/24 + t^4/720, (t - sin t)/t^3 ~ 1/6 - t^2/120 + t^4/5040; "
                "a guard at exactly t == 0 is not enough.")


@exercise_check
def check_so3_exp(so3_exp, hidden=False):
    """Exercise 01: Rodrigues' formula ``so3_exp(w (3,) rad) -> (3, 3)``, accurate near 0 and near pi.

    Compares with :func:`visla_edu.lie.so3_exp` (``atol=1e-9``) on
    :func:`~visla_edu.course.checks._inputs.rotation_vectors`, then ``atol=1e-15`` at tiny angles,
    which a closed form guarded at exactly 0 passes (its ``(1 - cos t)/t^2`` loses digits but
    multiplies ``hat(w)^2``, of size ``t^2``; :func:`check_se3_exp` and :func:`check_so3_log` test
    the cancellation). Hides ``lie.so3_exp``, ``lie.se3_exp``, the library's sin(t)/t and
    (1 - cos t)/t^2 and ``scipy.linalg.expm``; ``lie.hat`` stays.
    """
    name = "so3_exp"
    generator = rng(hidden)
    call = student(so3_exp, name, hide=[lie.so3_exp, lie.se3_exp, lie._sin_over_theta,
                                        lie._one_minus_cos_over_theta2, scipy.linalg.expm])
    for w in rotation_vectors(generator, hidden):
        got = as_array(call(w), name, (3, 3))
        ref = lie.so3_exp(w)
        compare(name, got, ref, f"for w = {fmt(w)} (angle {np.linalg.norm(w):.3g} rad)", [
            ("you returned R^T (the rotation by -w)\ncheck the sign of the hat(w) term", lambda: ref.T),
            ("the axis is not normalised\nRodrigues uses hat(w / theta), i.e. "
             "I + sin(t)/t hat(w) + (1 - cos t)/t^2 hat(w)^2", lambda: _rodrigues_with(w, normalised=False)),
            ("the hat(w)^2 term has the wrong sign\nit is + (1 - cos t)/t^2 hat(w)^2",
             lambda: _rodrigues_with(w, sign=-1.0)),
        ], atol=1e-9, nan_hint=NEAR_ZERO_HINT, extra=not_rotation)
    for w in _tiny_rotation_vectors(generator, hidden):
        compare(name, as_array(call(w), name, (3, 3)), lie.so3_exp(w),
                f"for w = {fmt(w)} (angle {np.linalg.norm(w):.0e} rad)", atol=1e-15, nan_hint=NEAR_ZERO_HINT)
    ok(f"{name}: Rodrigues agrees with the library from 0 to pi, to full precision at 1e-7 rad", hidden)


def _se3_with_translation(u, translation):
    """``se3_exp(u)`` with its translation replaced by ``translation`` (a mistake's J_l v)."""
    T = lie.se3_exp(u)
    T[:3, 3] = translation
    return T


def _swapped_v(w):
    """``V`` of SO(3) with its two coefficients exchanged (the mistake)."""
    t = np.linalg.norm(w)
    a, b = ((1 - np.cos(t)) / t**2, (t - np.sin(t)) / t**3) if t > 1e-3 else (0.5 - t**2 / 24, 1 / 6 - t**2 / 120)
    W = lie.hat(w)
    return np.eye(3) + b * W + a * W @ W


def _check_tiny_twist(name, T, u):
    """Fail if ``J_l v`` of ``T = se3_exp(u)`` lost digits at a tiny angle (``B hat(w) v`` is of size ``t |v|``)."""
    v, w = u[:3], u[3:]
    t = float(np.linalg.norm(w))
    wv = np.cross(w, v)
    ref = v + _series_B(t) * wv + _series_C(t) * np.cross(w, wv)
    error = float(np.max(np.abs(T[:3, 3] - ref)) / np.linalg.norm(v))
    if not error <= 1e-12:
        raise _tiny_angle_failure(name, t, error)
    compare(name, T[:3, :3], lie.so3_exp(w), f"the rotation block for w = {fmt(w)}", atol=1e-15)


@exercise_check
def check_se3_exp(se3_exp, hidden=False):
    """Exercise 01: ``se3_exp(u) -> (4, 4)`` for a twist ``u = [v; w]``, closed form.

    Compares with :func:`visla_edu.lie.se3_exp` (``atol=1e-9``) on
    :func:`~visla_edu.course.checks._inputs.twists`; at the tiny angles of :func:`check_so3_exp`
    the translation ``J_l v`` must be within 1e-12 ``|v|`` (a closed form guarded at exactly 0 is
    off by about ``eps / t``: the small-angle series is needed), the rotation ``atol=1e-15``.
    Hides ``lie.se3_exp``, the library's (t - sin t)/t^3, the SE(3) right Jacobian and its inverse
    and ``scipy.linalg.expm``; ``lie.so3_exp`` and ``lie.hat`` stay.
    """
    name = "se3_exp"
    generator = rng(hidden)
    call = student(se3_exp, name, hide=[lie.se3_exp, lie._theta_minus_sin_over_theta3,
                                         lie.se3_right_jacobian, lie.se3_right_jacobian_inv, scipy.linalg.expm])
    for u in twists(generator, hidden):
        got = as_array(call(u), name, (4, 4))
        ref = lie.se3_exp(u)
        compare(name, got, ref, f"for u = {fmt(u)} (angle {np.linalg.norm(u[3:]):.3g} rad)", [
            ("wrong twist order: u = [v; w] (linear first); you used [w; v]",
             lambda: lie.se3_exp(swap_twist(u))),
            ("you returned the inverse pose exp(-u^)\ncheck the signs", lambda: lie.se3_exp(-u)),
            ("the translation is v, but it must be J_l v\nJ_l = I + (1 - cos t)/t^2 hat(w) + "
             "(t - sin t)/t^3 hat(w)^2 (the left Jacobian of SO(3))", lambda: _se3_with_translation(u, u[:3])),
            ("the translation is R v, but it must be J_l v\nJ_l = I + (1 - cos t)/t^2 hat(w) + (t - sin t)/t^3 hat(w)^2",
             lambda: _se3_with_translation(u, ref[:3, :3] @ u[:3])),
            ("J_l's two coefficients are swapped\nJ_l = I + (1 - cos t)/t^2 hat(w) + (t - sin t)/t^3 hat(w)^2",
             lambda: _se3_with_translation(u, _swapped_v(u[3:]) @ u[:3])),
            ("J_l's hat(w) term has the wrong sign (you used J_l^T)\nJ_l = I + (1 - cos t)/t^2 hat(w) + "
             "(t - sin t)/t^3 hat(w)^2, with a plus before the hat(w) term",  # J_l(w)^T v = J_l(-w) v
             lambda: _se3_with_translation(u, lie.se3_exp(np.concatenate([u[:3], -u[3:]]))[:3, 3])),
            ("the rotation block is transposed (R^T instead of R)", lambda: rotation_transposed(ref)),
        ], atol=1e-9, nan_hint=NEAR_ZERO_HINT, extra=not_se3)
    for w in _tiny_rotation_vectors(generator, hidden):
        u = np.concatenate([generator.normal(scale=3.0, size=3), w])
        _check_tiny_twist(name, as_array(call(u), name, (4, 4)), u)
    ok(f"{name}: agrees with the library for twists [v; w] from rest to angles near pi", hidden)


def _dead_reckon_with(taus, steps, left=False):
    """A mistake's poses from the identity: ``T_{t+1} = T_t exp(tau_t u_t^)`` (``left``: ``exp(tau_t u_t^) T_t``)."""
    poses = [np.eye(4)]
    for tau, u in zip(taus, steps):
        step = lie.se3_exp(tau * u)
        poses.append(step @ poses[-1] if left else poses[-1] @ step)
    return np.array(poses)


def _drive(generator, T, hidden):
    """Time stamps (T,) and twists (T, 6) of a random drive (hidden: irregular steps, a stop)."""
    time_stamps = 100.0 + np.cumsum(generator.uniform(0.02 if hidden else 0.08, 0.12, T))
    samples = np.concatenate([generator.normal([8, 0, 0], [1, 0.3, 0.1], (T, 3)),
                              generator.normal([0, 0, 0.1], [0.05, 0.05, 0.3], (T, 3))], axis=1)
    if hidden:
        samples[T // 3: T // 2] = 0.0  # the car stops
    return time_stamps, samples


def _dead_reckon_variants(time_stamps, samples, lag, ref):
    T, taus, lagged = len(time_stamps), np.diff(time_stamps), motion.select_twists(samples, lag)
    return [
        ("you multiplied on the left, exp(tau u^) T_t\nthe IMU measures body-frame velocities, so "
         "T_{t+1} = T_t exp(tau_t u_{t+lag}^) (multiply on the right)",
         lambda: _dead_reckon_with(taus, lagged, left=True)),
        ("wrong twist order: u = [v; w] (linear first)",
         lambda: motion.dead_reckon(time_stamps, samples[:, [3, 4, 5, 0, 1, 2]], lag=lag)),
        (f"the lag was ignored: with lag {lag:+d} the step t -> t+1 uses u_(t{lag:+d})\n"
         "lag 0 is the course's convention, u_t, the sample at the start of the interval",
         lambda: motion.dead_reckon(time_stamps, samples)),
        (f"the lag has the wrong sign: use u_(t{lag:+d}), not u_(t{-lag:+d})\nlag +1 is the sample at the end "
         "of the interval, u_(t+1)", lambda: motion.dead_reckon(time_stamps, samples, lag=-lag)),
        ("past an end the index wraps around: clip it\nt + lag must stay in 0 .. T-1 (the first or last sample "
         "is used again), as np.clip does; a negative index counts from the end in numpy",
         lambda: _dead_reckon_with(taus, samples[(np.arange(T - 1) + lag) % T])),  # twists[(t + lag) % T]
        ("the twist must be scaled by the time step tau_t = t_{t+1} - t_t\nuse exp(tau_t u^)",
         lambda: _dead_reckon_with(np.ones(T - 1), lagged)),
        ("use each step's own tau_t = t_{t+1} - t_t, not one constant step\nthe time stamps are not uniform",
         lambda: motion.dead_reckon(time_stamps[0] + np.mean(np.diff(time_stamps)) * np.arange(T), samples,
                                    lag=lag)),
        ("the poses are inverted (imu_T_world): visla-edu stores world_T_imu", lambda: lie.se3_inv(ref)),
    ]


@exercise_check
def check_dead_reckon(dead_reckon, hidden=False):
    """Exercise 04: ``dead_reckon(time_stamps (T,), twists (T, 6), lag=0) -> world_T_imu (T, 4, 4)`` from the identity.

    ``T_{t+1} = T_t exp(tau_t u_{t+lag}^)`` (time stamps in s, body twists ``[v; w]``), ``t + lag``
    clipped to ``0 .. T-1`` (:func:`visla_edu.motion.select_twists`); compares with
    :func:`visla_edu.motion.dead_reckon` (``atol=1e-8``) for lags 0 and +1 (hidden: also -1 and +2,
    irregular steps and a stop). Hides it, ``motion.select_twists`` and ``motion.predict_pose``.
    """
    name = "dead_reckon"
    T = 45 if hidden else 30
    time_stamps, samples = _drive(rng(hidden), T, hidden)
    call = student(dead_reckon, name, hide=[motion.dead_reckon, motion.select_twists, motion.predict_pose])
    lags = (0, 1, -1, 2) if hidden else (0, 1)
    for lag in lags:
        try:
            out = call(time_stamps, samples, lag)
        except AssertionError as err:
            if "positional argument" in str(err):
                raise fail(name, "dead_reckon needs a third argument, the lag",
                           "the signature is dead_reckon(time_stamps, twists, lag=0)") from None
            raise
        got = as_array(out, name, (T, 4, 4))
        ref = motion.dead_reckon(time_stamps, samples, lag=lag)
        compare(name, got, ref, f"on a random {T}-step drive with lag {lag:+d}",
                _dead_reckon_variants(time_stamps, samples, lag, ref), atol=1e-8)
    ok(f"{name}: the {T}-pose trajectory agrees with motion.dead_reckon at the lags {list(lags)}", hidden)


# --------------------------------------------------------------------------- the logarithm


def _log_with_angle(R, angle):
    """A mistake's log: the axis from ``s = vee(R - R^T) / 2``, the angle ``angle(|s|)`` (zeros if ``s = 0``)."""
    s = 0.5 * lie.vee(R - R.T)
    norm = np.linalg.norm(s)
    return np.zeros(3) if norm == 0 else angle(norm) / norm * s


def _log_cases(generator, hidden):
    """Rotation vectors with angles 0 to 3 rad, and tiny ones where arccos loses its digits."""
    angles = [0.0, 1e-9, 3e-8, 2e-6, 1e-4, 0.05, 0.5, 1.2, 2.0, 2.6, 3.0]
    tiny = [1e-9, 1e-7, 1e-5]
    if hidden:
        angles = [0.0, 3e-9, 2e-7, 5e-5, 0.0999, 0.1001, 0.8, 1.6, 2.3, 2.9]
        tiny = [3e-9, 4e-8, 2e-6]
    return [a * unit(generator) for a in angles], [a * unit(generator) for a in tiny]


def _log_variants(R, ref):
    return [
        ("the angle from arccos loses its digits near 0: use atan2\nat a small angle (tr R - 1)/2 = cos t is "
         "about 1 - t^2/2 and rounds away t: take t = atan2(|s|, (tr R - 1)/2) with s = vee(R - R^T)/2",
         lambda: _log_with_angle(R, lambda _: np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))),
        ("arcsin gives angles up to pi/2 only: use atan2\nt = atan2(|s|, (tr R - 1)/2) with s = vee(R - R^T)/2 "
         "covers 0 to pi", lambda: _log_with_angle(R, lambda norm: np.arcsin(min(norm, 1.0)))),
        ("you returned -w: the log of R^T\nthe axis is vee(R - R^T) / 2 = sin(t) a, not vee(R^T - R)",
         lambda: -ref),
        ("twice the rotation vector: s = vee(R - R^T) / 2\nvee(R - R^T) is 2 sin(t) a", lambda: 2 * ref),
        ("half the rotation vector: s = vee(R - R^T) / 2 = sin(t) a\nw = t / sin(t) s", lambda: 0.5 * ref),
    ]


@exercise_check
def check_so3_log(so3_log, hidden=False):
    """Exercise 01: ``so3_log(R (3, 3)) -> w (3,)``, ``so3_exp(w) == R``, ``|w|`` in [0, pi], accurate at small angles.

    Compares with :func:`visla_edu.lie.so3_log` for angles 0 to 3 rad (``atol=1e-12``; near pi the
    library needs another formula), then at 3 tiny angles (``atol=1e-15``), where an ``arccos``
    angle is off by about ``eps / t`` and ``atan2`` of the antisymmetric part is not. Hides
    ``lie.so3_log``, ``lie.se3_log`` and the library's sin(t)/t; ``lie.vee`` and ``lie.hat`` stay
    (``scipy.linalg.logm`` cannot be hidden: the exercise text asks for the formula).
    """
    name = "so3_log"
    cases, tiny = _log_cases(rng(hidden), hidden)
    call = student(so3_log, name, hide=[lie.so3_log, lie.se3_log, lie._near_pi_log, lie._sin_over_theta])
    nan_hint = ("at the identity\nthere the angle and s are 0 and t / sin(t) is 0 / 0: return zeros, or use the "
                "series t / sin(t) ~ 1 + t^2/6 below a small angle")
    for w, atol in [(w, 1e-12) for w in cases] + [(w, 1e-15) for w in tiny]:
        R = lie.so3_exp(w)
        out = call(R)
        if np.shape(out) == (3, 3):
            raise fail(name, "return the rotation vector (3,), not a matrix",
                       "so3_log returns w = vee(log R), with so3_exp(w) == R")
        ref = lie.so3_log(R)
        compare(name, as_array(out, name, (3,), "rotation vector"), ref,
                f"for the rotation by {np.linalg.norm(w):.3g} rad about {fmt(w / max(np.linalg.norm(w), 1e-300))}",
                _log_variants(R, ref), rtol=0, atol=atol, nan_hint=nan_hint)
    ok(f"{name}: agrees with the library from 0 to 3 rad, to full precision at 1e-9 rad", hidden)
