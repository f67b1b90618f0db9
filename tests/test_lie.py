"""Tests for visla_edu.lie: hat/vee, SO(3)/SE(3) exp/log, inverse, adjoint, curly-hat, odot.

Conventions under test (README, "Conventions"): twist ``u = [v; w]`` (linear first),
``twist_hat(u) = [[hat(w), v], [0, 0]]``, right perturbation ``T = mu exp(delta^)``,
``F = exp(-tau curlyhat(u)) = Ad(exp(-tau u^))``, ``s^odot = [[I, -s^], [0, 0]]``.

Accuracy target: 1e-9 everywhere (relative to the size of the quantity for tiny
rotations), including near the identity, around ``SMALL_ANGLE`` and near pi.
"""

import os

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from visla_edu import lie
from fdiff import fd_jacobian  # tests/fdiff.py

TOL = 1e-9
PI = np.pi

# Angle regimes (rad).
NEAR_ZERO = [0.0, 1e-12, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3]
AT_SWITCH = [
    0.099,
    np.nextafter(lie.SMALL_ANGLE, 0.0),
    lie.SMALL_ANGLE,
    np.nextafter(lie.SMALL_ANGLE, 1.0),
    0.1,
    0.101,
]
GENERIC = [0.3, 1.0, 2.0, 2.9]
# pi - 0.1 is where so3_log switches to the symmetric part of R.
NEAR_PI = [PI - 0.1 - 1e-9, PI - 0.1, PI - 0.1 + 1e-9, PI - 1e-3, PI - 1e-4, PI - 1e-6,
           PI - 1e-9, PI - 1e-12]
BELOW_PI = NEAR_ZERO + AT_SWITCH + GENERIC + NEAR_PI
ALL_ANGLES = BELOW_PI + [PI]

# Hypothesis: moderate example counts, no example database written into the tree.
PROPERTY = settings(
    max_examples=int(os.environ.get("VISLA_HYPOTHESIS_EXAMPLES", "60")),
    deadline=None,
    database=None,
)


# ----------------------------------------------------------------------------- helpers


def unit(rng, shape=()):
    """Random unit 3-vectors of the given leading shape."""
    a = rng.normal(size=tuple(shape) + (3,))
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def axes(rng, n=6):
    """Coordinate axes, a few special diagonals and random axes."""
    special = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [1, 1, 0], [1, -1, 1], [0, -2, 1]]
    special = [np.asarray(a, float) / np.linalg.norm(a) for a in special]
    return special + list(unit(rng, (n,)))


def rel(a, b):
    """Relative error ``|a - b| / |b|`` (Frobenius), exact comparison when ``b == 0``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    nb = np.linalg.norm(b)
    err = np.linalg.norm(a - b)
    return err / nb if nb > 0 else (0.0 if err == 0 else np.inf)


def maxabs(a, b):
    return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))))


def assert_in_se3(T, tol=1e-12):
    R = T[..., :3, :3]
    Rt_R = np.swapaxes(R, -1, -2) @ R
    assert maxabs(Rt_R, np.broadcast_to(np.eye(3), Rt_R.shape)) < tol
    assert maxabs(np.linalg.det(R), 1.0) < tol
    assert np.array_equal(T[..., 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], T.shape[:-2] + (4,)))




def random_pose(rng, angle=None, scale=5.0):
    w = unit(rng) * (rng.uniform(0, PI) if angle is None else angle)
    return lie.se3_exp(np.r_[rng.normal(size=3) * scale, w])


# ----------------------------------------------------------------------------- hat / vee


def test_hat_layout_and_cross_product():
    np.testing.assert_array_equal(
        lie.hat([1.0, 2.0, 3.0]), [[0, -3, 2], [3, 0, -1], [-2, 1, 0]]
    )
    rng = np.random.default_rng(1)
    w, x = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    W = lie.hat(w)
    assert maxabs(np.einsum("nij,nj->ni", W, x), np.cross(w, x)) < 1e-14
    assert maxabs(W, -np.swapaxes(W, -1, -2)) == 0.0


def test_hat_vee_round_trip_3x3():
    rng = np.random.default_rng(2)
    w = rng.normal(size=(20, 3)) * 10
    np.testing.assert_array_equal(lie.vee(lie.hat(w)), w)
    A = rng.normal(size=(20, 3, 3))
    S = A - np.swapaxes(A, -1, -2)
    np.testing.assert_array_equal(lie.hat(lie.vee(S)), S)


def test_twist_hat_layout_linear_first():
    u = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])  # v = [1, 2, 3], w = [4, 5, 6]
    U = lie.twist_hat(u)
    np.testing.assert_array_equal(U[:3, :3], lie.hat([4.0, 5.0, 6.0]))
    np.testing.assert_array_equal(U[:3, 3], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(U[3], np.zeros(4))


def test_twist_hat_vee_round_trip_4x4():
    rng = np.random.default_rng(3)
    u = rng.normal(size=(2, 5, 6))
    np.testing.assert_array_equal(lie.twist_vee(lie.twist_hat(u)), u)
    np.testing.assert_array_equal(lie.vee(lie.twist_hat(u)), u)  # vee dispatches on 4x4
    U = lie.twist_hat(u)
    np.testing.assert_array_equal(lie.twist_hat(lie.vee(U)), U)


def test_twist_order_pure_translation_and_pure_rotation():
    """Linear part first: [v; 0] translates by v, [0; w] only rotates."""
    v = np.array([1.0, -2.0, 0.5])
    T = lie.se3_exp(np.r_[v, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(T[:3, :3], np.eye(3))
    np.testing.assert_array_equal(T[:3, 3], v)
    T = lie.se3_exp([0.0, 0.0, 0.0, 0.0, 0.0, PI / 2])
    np.testing.assert_array_equal(T[:3, 3], np.zeros(3))
    assert maxabs(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]]) < 1e-15


def test_exp_of_zero_is_identity_exactly():
    np.testing.assert_array_equal(lie.so3_exp(np.zeros(3)), np.eye(3))
    np.testing.assert_array_equal(lie.se3_exp(np.zeros(6)), np.eye(4))
    np.testing.assert_array_equal(lie.so3_log(np.eye(3)), np.zeros(3))
    np.testing.assert_array_equal(lie.se3_log(np.eye(4)), np.zeros(6))


# ----------------------------------------------------------------------------- SO(3)


@pytest.mark.parametrize("theta", ALL_ANGLES)
def test_so3_exp_matches_expm_and_scipy(theta):
    rng = np.random.default_rng(10)
    for a in axes(rng):
        w = theta * a
        R = lie.so3_exp(w)
        assert maxabs(R, expm(lie.hat(w))) < 1e-13
        assert maxabs(R, Rotation.from_rotvec(w).as_matrix()) < 1e-13
        assert_in_se3(np.block([[R, np.zeros((3, 1))], [np.zeros((1, 3)), 1.0]]), tol=1e-14)


@pytest.mark.parametrize("theta", BELOW_PI)
def test_so3_log_inverts_exp(theta):
    """log(exp(w)) == w, relative to |w| (exact at 0); R also built independently by scipy."""
    rng = np.random.default_rng(11)
    for a in axes(rng):
        w = theta * a
        for R in (lie.so3_exp(w), Rotation.from_rotvec(w).as_matrix()):
            w_log = lie.so3_log(R)
            if theta == 0.0:
                np.testing.assert_array_equal(w_log, np.zeros(3))
            else:
                assert rel(w_log, w) < TOL, (theta, a, w_log)


@pytest.mark.parametrize(
    "axis", [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, -1, 1], [-3, 2, 0.5], [0, -1, 1e-3]]
)
def test_so3_log_at_exactly_pi(axis):
    """At pi the axis sign is ambiguous: |log| == pi, log == +-pi a and exp(log R) == R."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    R_exact = 2.0 * np.outer(a, a) - np.eye(3)  # rotation by pi, built without so3_exp
    for R in (R_exact, lie.so3_exp(PI * a), Rotation.from_rotvec(PI * a).as_matrix()):
        w = lie.so3_log(R)
        assert abs(np.linalg.norm(w) - PI) < 1e-12
        assert min(maxabs(w, PI * a), maxabs(w, -PI * a)) < TOL
        assert maxabs(lie.so3_exp(w), R) < 1e-12


@pytest.mark.parametrize("theta", [PI - 1e-12, PI - 1e-9, PI - 1e-6, PI - 1e-3])
def test_so3_log_near_pi_keeps_the_sign(theta):
    """Just below pi the axis sign is determined: log must not flip to -w."""
    rng = np.random.default_rng(12)
    for a in axes(rng):
        assert maxabs(lie.so3_log(lie.so3_exp(theta * a)), theta * a) < TOL
        assert maxabs(lie.so3_log(lie.so3_exp(-theta * a)), -theta * a) < TOL


@pytest.mark.filterwarnings("error")
def test_log_of_batch_mixing_identity_and_pi_is_silent_and_exact():
    """Regression: the near-pi branch used to be evaluated for every entry, so the identity
    gave 0/0 (RuntimeWarning) in a batch that also held a rotation by pi."""
    w = np.array([[0.0, 0.0, 0.0], [PI, 0.0, 0.0], [0.0, 0.0, 1e-3], [0.0, PI - 1e-9, 0.0]])
    np.testing.assert_array_equal(lie.so3_log(lie.so3_exp(w)), w)
    u = np.concatenate([np.ones((4, 3)), w], axis=-1)
    assert maxabs(lie.se3_log(lie.se3_exp(u)), u) < 1e-14


@pytest.mark.parametrize("theta", AT_SWITCH)
def test_series_switch_is_seamless(theta):
    """Both sides of SMALL_ANGLE agree with expm to ~1e-14: the series are long enough and
    the closed forms have not yet lost digits (a tighter bound than TOL on purpose)."""
    rng = np.random.default_rng(14)
    for a in axes(rng, 20):
        u = np.r_[rng.normal(size=3), theta * a]
        T = expm(lie.twist_hat(u))
        assert maxabs(lie.so3_exp(u[3:]), T[:3, :3]) < 1e-15
        assert maxabs(lie.se3_exp(u), T) < 1e-14
        assert rel(lie.so3_log(T[:3, :3]), u[3:]) < 1e-14
        assert rel(lie.se3_log(T), u) < 1e-12


def test_so3_log_angle_range_for_large_rotation_vectors():
    """log returns the equivalent rotation vector with angle in [0, pi]."""
    rng = np.random.default_rng(13)
    for theta in [PI + 1e-6, 4.0, 2 * PI - 1e-3, 2 * PI, 7.0, 20.0]:
        for a in axes(rng, 3):
            R = lie.so3_exp(theta * a)
            w = lie.so3_log(R)
            assert np.linalg.norm(w) <= PI + 1e-12
            assert maxabs(lie.so3_exp(w), R) < 1e-12


def test_so3_log_tolerates_slightly_non_orthogonal_input():
    """Accumulated products drift off SO(3) by ~1e-15; trace may exceed 3 or go below -1."""
    for R in (np.eye(3) * (1 + 1e-15), lie.so3_exp([PI, 0, 0]) * (1 + 1e-15)):
        w = lie.so3_log(R)
        assert np.all(np.isfinite(w))
        assert maxabs(lie.so3_exp(w), R) < 1e-12


# ----------------------------------------------------------------------------- SE(3)


@pytest.mark.parametrize("theta", ALL_ANGLES)
def test_se3_exp_matches_expm(theta):
    rng = np.random.default_rng(20)
    for a in axes(rng):
        u = np.r_[rng.normal(size=3) * 3, theta * a]
        T = lie.se3_exp(u)
        ref = expm(lie.twist_hat(u))
        assert maxabs(T, ref) < 1e-12 * max(1.0, np.abs(ref).max())
        assert_in_se3(T, tol=1e-14)


@pytest.mark.parametrize("theta", BELOW_PI)
def test_se3_log_inverts_exp(theta):
    rng = np.random.default_rng(21)
    for a in axes(rng):
        for scale in (1e-6, 1.0, 100.0):
            u = np.r_[rng.normal(size=3) * scale, theta * a]
            for T in (lie.se3_exp(u), expm(lie.twist_hat(u))):
                u_log = lie.se3_log(T)
                assert rel(u_log, u) < TOL, (theta, scale, u_log - u)
                assert rel(u_log[:3], u[:3]) < TOL  # linear part alone
                if theta == 0.0:
                    np.testing.assert_array_equal(u_log[3:], np.zeros(3))
                else:
                    assert rel(u_log[3:], u[3:]) < TOL  # angular part, relative to |w|


def test_se3_log_at_exactly_pi():
    rng = np.random.default_rng(22)
    for a in axes(rng):
        T = lie.se3_exp(np.r_[rng.normal(size=3) * 3, PI * a])
        u = lie.se3_log(T)
        assert abs(np.linalg.norm(u[3:]) - PI) < 1e-12
        assert maxabs(lie.se3_exp(u), T) < 1e-12


def test_se3_exp_log_on_arbitrary_poses():
    """exp(log(T)) == T for poses whose rotation vector is longer than pi."""
    rng = np.random.default_rng(23)
    for theta in [3.5, 5.0, 2 * PI, 11.0]:
        for a in axes(rng, 3):
            T = lie.se3_exp(np.r_[rng.normal(size=3) * 10, theta * a])
            assert maxabs(lie.se3_exp(lie.se3_log(T)), T) < 1e-12 * 10


def test_se3_inv():
    rng = np.random.default_rng(24)
    for theta in [0.0, 1e-9, 0.1, 1.0, PI - 1e-9, PI]:
        T = random_pose(rng, theta, scale=50.0)
        Ti = lie.se3_inv(T)
        assert maxabs(Ti @ T, np.eye(4)) < 1e-13
        assert maxabs(T @ Ti, np.eye(4)) < 1e-13
        assert maxabs(Ti, np.linalg.inv(T)) < 1e-12
        assert_in_se3(Ti, tol=1e-14)


def test_group_axioms():
    rng = np.random.default_rng(25)
    for _ in range(30):
        a, b = rng.normal(size=(2, 6)) * 2
        Ta, Tb = lie.se3_exp(a), lie.se3_exp(b)
        assert_in_se3(Ta @ Tb)
        assert maxabs(lie.se3_exp(a) @ lie.se3_exp(-a), np.eye(4)) < 1e-12
        assert maxabs(lie.se3_exp(-a), lie.se3_inv(Ta)) < 1e-12
        # one-parameter subgroup: exp(s u) exp(t u) == exp((s + t) u)
        s, t = rng.uniform(-2, 2, size=2)
        assert maxabs(lie.se3_exp(s * a) @ lie.se3_exp(t * a), lie.se3_exp((s + t) * a)) < 1e-11
        # log(T^-1) == -log(T) away from pi
        if np.linalg.norm(a[3:]) < PI - 1e-3:
            assert rel(lie.se3_log(lie.se3_inv(Ta)), -a) < TOL


# ----------------------------------------------------------------------------- adjoint, curly hat, odot


def test_adjoint_layout():
    rng = np.random.default_rng(30)
    T = random_pose(rng)
    R, p = T[:3, :3], T[:3, 3]
    Ad = lie.adjoint(T)
    np.testing.assert_array_equal(Ad[:3, :3], R)
    np.testing.assert_array_equal(Ad[3:, 3:], R)
    np.testing.assert_array_equal(Ad[3:, :3], np.zeros((3, 3)))
    assert maxabs(Ad[:3, 3:], lie.hat(p) @ R) == 0.0


def test_adjoint_identities():
    rng = np.random.default_rng(31)
    for theta in [0.0, 1e-9, 0.1, 1.0, 3.0, PI]:
        T = random_pose(rng, theta)
        T2 = random_pose(rng)
        u = rng.normal(size=6)
        Ad = lie.adjoint(T)
        lhs = T @ lie.twist_hat(u) @ lie.se3_inv(T)
        assert maxabs(lhs, lie.twist_hat(Ad @ u)) < 1e-12 * max(1, np.abs(lhs).max())
        assert maxabs(lie.adjoint(T @ T2), Ad @ lie.adjoint(T2)) < 1e-12
        assert maxabs(lie.adjoint(lie.se3_inv(T)), np.linalg.inv(Ad)) < 1e-12
        # conjugation is exact on the group: T exp(d) T^-1 == exp(Ad d)
        d = rng.normal(size=6) * 0.5
        assert maxabs(T @ lie.se3_exp(d) @ lie.se3_inv(T), lie.se3_exp(Ad @ d)) < 1e-12 * 10
        assert rel(lie.se3_log(T @ lie.se3_exp(d) @ lie.se3_inv(T)), Ad @ d) < TOL


def test_curly_hat_layout_and_lie_bracket():
    rng = np.random.default_rng(32)
    u, x = rng.normal(size=(2, 6))
    C = lie.curly_hat(u)
    np.testing.assert_array_equal(C[:3, :3], lie.hat(u[3:]))
    np.testing.assert_array_equal(C[:3, 3:], lie.hat(u[:3]))
    np.testing.assert_array_equal(C[3:, 3:], lie.hat(u[3:]))
    np.testing.assert_array_equal(C[3:, :3], np.zeros((3, 3)))
    U, X = lie.twist_hat(u), lie.twist_hat(x)
    assert maxabs(lie.twist_hat(C @ x), U @ X - X @ U) < 1e-14


@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-6, 1e-3, 0.099, 0.1, 0.101, 1.0, 2.5, PI - 1e-9, PI])
def test_expm_curly_hat_is_adjoint_of_exp(theta):
    rng = np.random.default_rng(33)
    for a in axes(rng, 3):
        u = np.r_[rng.normal(size=3) * 2, theta * a]
        assert maxabs(expm(lie.curly_hat(u)), lie.adjoint(lie.se3_exp(u))) < 1e-12 * 10


@pytest.mark.parametrize("tau", [1e-3, 0.01, 0.1])
def test_motion_model_F_closed_form(tau):
    """F = exp(-tau curlyhat(u)) = Ad(exp(-tau u^)), and it is the Jacobian of the
    right-perturbation error: mu exp(d) exp(tau u^) = (mu exp(tau u^)) exp((F d)^)."""
    rng = np.random.default_rng(34)
    for _ in range(5):
        u = np.r_[rng.normal(size=3) * 10, rng.normal(size=3)]  # m/s, rad/s
        F = lie.adjoint(lie.se3_exp(-tau * u))
        assert maxabs(F, expm(-tau * lie.curly_hat(u))) < 1e-12 * max(1, np.abs(F).max())
        mu = random_pose(rng)
        step = lie.se3_exp(tau * u)
        mu_next_inv = lie.se3_inv(mu @ step)

        def delta_next(d):
            return lie.se3_log(mu_next_inv @ mu @ lie.se3_exp(d) @ step)

        assert maxabs(fd_jacobian(delta_next, np.zeros(6), 1e-3), F) < TOL
        d = rng.normal(size=6) * 0.1
        assert rel(delta_next(d), F @ d) < TOL  # exact, not only to first order


def test_odot_layout_and_identity():
    rng = np.random.default_rng(35)
    s = np.r_[rng.normal(size=3), 1.0]
    O = lie.odot(s)
    assert O.shape == (4, 6)
    np.testing.assert_array_equal(O[:3, :3], np.eye(3))
    np.testing.assert_array_equal(O[:3, 3:], -lie.hat(s[:3]))
    np.testing.assert_array_equal(O[3], np.zeros(6))
    for s4 in [1.0, 0.0, 2.5, -0.3]:
        for _ in range(10):
            s = np.r_[rng.normal(size=3) * 20, s4]
            u = rng.normal(size=6)
            assert maxabs(lie.twist_hat(u) @ s, lie.odot(s) @ u) < 1e-13


# ----------------------------------------------------------------------------- Jacobians via finite differences


def test_exp_derivatives_at_identity_are_the_generators():
    J = fd_jacobian(lie.se3_exp, np.zeros(6), 1e-3)  # (4, 4, 6)
    for i in range(6):
        assert maxabs(J[..., i], lie.twist_hat(np.eye(6)[i])) < 1e-12
    J = fd_jacobian(lie.so3_exp, np.zeros(3), 1e-3)
    for i in range(3):
        assert maxabs(J[..., i], lie.hat(np.eye(3)[i])) < 1e-12


def test_exp_derivative_along_a_twist():
    """d/dt exp(t u^) = exp(t u^) u^ = u^ exp(t u^) (the IMU kinematics)."""
    rng = np.random.default_rng(40)
    for t in [0.0, 0.3, 1.0]:
        u = rng.normal(size=6)
        T = lie.se3_exp(t * u)
        dT = fd_jacobian(lambda s: lie.se3_exp(s[0] * u), np.array([t]), 1e-3)[..., 0]
        assert maxabs(dT, T @ lie.twist_hat(u)) < TOL
        assert maxabs(dT, lie.twist_hat(u) @ T) < TOL


def test_point_derivative_is_odot():
    """d/dd exp(d^) s at d = 0 equals odot(s)."""
    rng = np.random.default_rng(41)
    s = np.r_[rng.normal(size=3) * 5, 1.0]
    J = fd_jacobian(lambda d: lie.se3_exp(d) @ s, np.zeros(6), 1e-3)
    assert maxabs(J, lie.odot(s)) < TOL * 10


def _so3_right_jacobian_inverse(w):
    theta = np.linalg.norm(w)
    W = lie.hat(w)
    if theta < 0.05:
        k = 1 / 12 + theta**2 / 720 + theta**4 / 30240
    else:
        k = 1 / theta**2 - (1 + np.cos(theta)) / (2 * theta * np.sin(theta))
    return np.eye(3) + 0.5 * W + k * W @ W


@pytest.mark.parametrize("theta", [0.0, 1e-9, 1e-4, 0.05, 0.1, 0.5, 2.0, PI - 0.1, PI - 0.05, PI - 0.01])
def test_so3_log_derivative_is_inverse_right_jacobian(theta):
    """d/de log(exp(w) exp(e)) at 0 = J_r(w)^-1; crosses both switches of so3_log."""
    rng = np.random.default_rng(42)
    h = min(1e-3, (PI - theta) / 10) if theta > 1 else 1e-3
    for a in axes(rng, 2):
        w = theta * a
        R = lie.so3_exp(w)
        J = fd_jacobian(lambda e: lie.so3_log(R @ lie.so3_exp(e)), np.zeros(3), h)
        assert maxabs(J, _so3_right_jacobian_inverse(w)) < TOL * 10


@pytest.mark.parametrize("theta", [0.0, 1e-7, 0.05, 0.0999, 0.1001, 0.7, 2.5])
def test_so3_left_jacobian_matches_finite_differences(theta):
    """exp((w + d)^) ~ exp((J_l(w) d)^) exp(w^), on both sides of the series switch; and J_l(w) v is
    the translation of se3_exp([v; w]) (the V of the closed form)."""
    rng = np.random.default_rng(43)
    for a in unit(rng, (3,)):
        w = theta * a
        R = lie.so3_exp(w)
        fd = fd_jacobian(lambda d: lie.so3_log(lie.so3_exp(w + d) @ R.T), np.zeros(3), 1e-5)
        J_l = lie.so3_left_jacobian(w)
        assert maxabs(J_l, fd) < 1e-9
        v = rng.normal(size=3)
        assert maxabs(J_l @ v, lie.se3_exp(np.r_[v, w])[:3, 3]) < 1e-12
    # batched input: one Jacobian per rotation vector
    W = unit(rng, (4,)) * np.array([0.0, 0.05, 0.7, 2.5])[:, None]
    assert maxabs(lie.so3_left_jacobian(W), np.stack([lie.so3_left_jacobian(w) for w in W])) == 0.0


# ----------------------------------------------------------------------------- batches and errors


# Every batch of two or more mixes the identity with a rotation by pi (the two branches
# of so3_log that are hardest to combine), then cycles through the other regimes.
MIXED_ANGLES = [0.0, PI, 1e-12, PI - 1e-9, lie.SMALL_ANGLE, 0.099, 1.0, PI - 0.1, 1e-3, 2.9]


def _mixed_rotvecs(rng, n):
    return unit(rng, (n,)) * np.resize(MIXED_ANGLES, n)[:, None]


def _inputs(name, rng, lead):
    n = int(np.prod(lead))
    w = _mixed_rotvecs(rng, n)
    u = np.concatenate([rng.normal(size=(n, 3)) * 3, w], axis=-1)
    A = rng.normal(size=(n, 3, 3))
    data = {
        "hat": w,
        "vee": A - np.swapaxes(A, -1, -2),
        "vee4": lie.twist_hat(u),
        "so3_exp": w,
        "so3_log": lie.so3_exp(w),
        "twist_hat": u,
        "twist_vee": lie.twist_hat(u),
        "se3_exp": u,
        "se3_log": lie.se3_exp(u),
        "se3_inv": lie.se3_exp(u),
        "adjoint": lie.se3_exp(u),
        "curly_hat": u,
        "odot": np.concatenate([rng.normal(size=(n, 3)), rng.normal(size=(n, 1))], axis=-1),
    }[name]
    return data.reshape(tuple(lead) + data.shape[1:])


BATCH_FUNCS = ["hat", "vee", "vee4", "so3_exp", "so3_log", "twist_hat", "twist_vee",
               "se3_exp", "se3_log", "se3_inv", "adjoint", "curly_hat", "odot"]


@pytest.mark.filterwarnings("error")  # mixed batches must not warn (e.g. 0/0 in an unused branch)
@pytest.mark.parametrize("lead", [(5,), (2, 3), (1,), (0,)])
@pytest.mark.parametrize("name", BATCH_FUNCS)
def test_batch_equals_loop(name, lead):
    rng = np.random.default_rng(50)
    f = getattr(lie, name.rstrip("4"))
    x = _inputs(name, rng, lead)
    out = f(x)
    single = f(x.reshape((-1,) + x.shape[len(lead):])[0]) if x.size else None
    if single is not None:
        assert out.shape == tuple(lead) + single.shape
    else:
        assert out.shape[: len(lead)] == tuple(lead)
    for idx in np.ndindex(*lead):
        assert maxabs(out[idx], f(x[idx])) < 1e-14, idx


@pytest.mark.parametrize(
    "name, bad",
    [
        ("hat", np.zeros(2)), ("hat", np.zeros((3, 2))), ("hat", 1.0),
        ("vee", np.zeros((3, 4))), ("vee", np.zeros(3)), ("vee", np.zeros((2, 2))),
        ("so3_exp", np.zeros(4)), ("so3_exp", np.zeros((2, 6))),
        ("so3_log", np.zeros(3)), ("so3_log", np.eye(4)),
        ("twist_hat", np.zeros(3)), ("twist_hat", np.zeros((6, 2))),
        ("twist_vee", np.zeros((3, 3))),
        ("se3_exp", np.zeros(3)), ("se3_exp", np.eye(4)),
        ("se3_log", np.eye(3)), ("se3_log", np.zeros(6)),
        ("se3_inv", np.eye(3)), ("adjoint", np.eye(6)),
        ("curly_hat", np.zeros(4)), ("odot", np.zeros(3)), ("odot", np.zeros(6)),
    ],
)
def test_wrong_shapes_raise_clear_value_error(name, bad):
    with pytest.raises(ValueError, match=name) as info:
        getattr(lie, name)(bad)
    assert str(np.shape(bad)) in str(info.value)


# ----------------------------------------------------------------------------- hypothesis properties

finite = dict(allow_nan=False, allow_infinity=False)
axis_st = st.lists(st.floats(-1, 1, **finite), min_size=3, max_size=3).map(np.array).filter(
    lambda a: np.linalg.norm(a) > 1e-3
).map(lambda a: a / np.linalg.norm(a))
angle_below_pi = st.one_of(
    st.just(0.0),
    st.floats(-12, -1).map(lambda e: 10.0**e),  # tiny angles, log-uniform
    st.floats(1e-12, PI - 1e-7),
    st.floats(1e-12, 1e-1).map(lambda d: PI - d),  # near pi
)
vec3 = st.lists(st.floats(-100, 100, **finite), min_size=3, max_size=3).map(np.array)
twist = st.lists(st.floats(-5, 5, **finite), min_size=6, max_size=6).map(np.array)


@PROPERTY
@given(axis_st, angle_below_pi)
def test_prop_so3_round_trip(a, theta):
    w = theta * a
    R = lie.so3_exp(w)
    w_log = lie.so3_log(R)
    assert np.linalg.norm(w_log - w) <= TOL * theta
    assert maxabs(lie.so3_exp(w_log), R) < 1e-12


@PROPERTY
@given(vec3, axis_st, angle_below_pi)
def test_prop_se3_round_trip(v, a, theta):
    u = np.r_[v, theta * a]
    T = lie.se3_exp(u)
    u_log = lie.se3_log(T)
    assert np.linalg.norm(u_log - u) <= TOL * np.linalg.norm(u)
    assert np.linalg.norm(u_log[3:] - u[3:]) <= TOL * theta
    assert maxabs(lie.se3_exp(u_log), T) <= 1e-12 * max(1.0, np.abs(T).max())


@PROPERTY
@given(st.lists(st.floats(-10, 10, **finite), min_size=3, max_size=3).map(np.array))
def test_prop_exp_of_log_for_any_rotation(w):
    R = lie.so3_exp(w)
    w_log = lie.so3_log(R)
    assert np.linalg.norm(w_log) <= PI + 1e-12
    assert maxabs(lie.so3_exp(w_log), R) < 1e-12
    assert maxabs(R, Rotation.from_rotvec(w).as_matrix()) < 1e-12


@PROPERTY
@given(twist, twist)
def test_prop_group_axioms(a, b):
    Ta, Tb = lie.se3_exp(a), lie.se3_exp(b)
    assert_in_se3(Ta)
    assert_in_se3(Ta @ Tb, tol=1e-12)
    assert maxabs(lie.se3_inv(Ta) @ Ta, np.eye(4)) < 1e-12
    assert maxabs(lie.se3_inv(Ta @ Tb), lie.se3_inv(Tb) @ lie.se3_inv(Ta)) < 1e-11
    assert maxabs(lie.se3_exp(-a), lie.se3_inv(Ta)) < 1e-11


@PROPERTY
@given(twist, twist)
def test_prop_adjoint_and_curly_hat(a, u):
    T = lie.se3_exp(a)
    lhs = T @ lie.twist_hat(u) @ lie.se3_inv(T)
    assert maxabs(lhs, lie.twist_hat(lie.adjoint(T) @ u)) < 1e-12 * max(1.0, np.abs(lhs).max())
    Ad = lie.adjoint(lie.se3_exp(u))
    assert maxabs(expm(lie.curly_hat(u)), Ad) < 1e-11 * max(1.0, np.abs(Ad).max())


@PROPERTY
@given(twist, vec3, st.floats(-3, 3, **finite))
def test_prop_odot(u, p, s4):
    s = np.r_[p, s4]
    assert maxabs(lie.twist_hat(u) @ s, lie.odot(s) @ u) < 1e-12


RIGHT_JACOBIAN_FD_REL = 1e-6


# --- SO(3) and SE(3) right Jacobians (moved here from the smoother's tests with the functions) ---


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.05, 0.0999, 0.1001, 0.7, 2.5])
def test_right_jacobian_inverse_matches_finite_differences_of_log(angle):
    rng = np.random.default_rng(1)
    x = rng.normal(size=6)
    x[3:] *= angle / np.linalg.norm(x[3:])
    fd = fd_jacobian(lambda d: lie.se3_log(lie.se3_exp(x) @ lie.se3_exp(d)), np.zeros(6), 1e-5)
    assert rel(lie.se3_right_jacobian_inv(x), fd) < RIGHT_JACOBIAN_FD_REL
    fd_r = fd_jacobian(lambda d: lie.se3_log(lie.se3_inv(lie.se3_exp(x)) @ lie.se3_exp(x + d)), np.zeros(6), 1e-5)
    assert rel(lie.se3_right_jacobian(x), fd_r) < RIGHT_JACOBIAN_FD_REL
    assert np.allclose(lie.se3_right_jacobian(x) @ lie.se3_right_jacobian_inv(x), np.eye(6), atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.0999, 0.1001, 2.5])
def test_so3_right_jacobians_match_finite_differences(angle):
    """``exp((phi + d)^) ~ exp(phi^) exp((J_r d)^)`` and ``log(exp(phi^) exp(d^)) ~ phi + J_r^{-1} d``."""
    phi = np.random.default_rng(5).normal(size=3)
    phi *= angle / np.linalg.norm(phi)
    R = lie.so3_exp(phi)
    fd = fd_jacobian(lambda d: lie.so3_log(R.T @ lie.so3_exp(phi + d)), np.zeros(3), 1e-5)
    assert rel(lie.so3_right_jacobian(phi), fd) < RIGHT_JACOBIAN_FD_REL
    fd_inv = fd_jacobian(lambda d: lie.so3_log(R @ lie.so3_exp(d)), np.zeros(3), 1e-5)
    assert rel(lie.so3_right_jacobian_inv(phi), fd_inv) < RIGHT_JACOBIAN_FD_REL


def test_right_jacobian_rejects_a_wrong_shape():
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        lie.se3_right_jacobian_inv(np.zeros(3))
