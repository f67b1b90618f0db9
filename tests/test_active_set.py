"""Tests of the joint state's bookkeeping (visla_edu.filters.ActiveSet) against the explicit forms:
augmenting is the linearised covariance of the extended state, retiring is deleting rows and
columns, and the slots always match the landmarks they hold."""

import numpy as np
import pytest

from visla_edu.ekf import slot_columns
from visla_edu.filters import ActiveSet

M = 20  # landmark ids of the imagined dataset


def _spd(n, rng):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def _state_with(ids, rng):
    """An active set holding ``ids`` with a random positive definite covariance."""
    state = ActiveSet(M, np.zeros((6, 6)))
    state.enter(np.asarray(ids))
    state.Sigma = _spd(state.dim, rng)
    return state


def _assert_slots_consistent(state):
    assert state.dim == 6 + 3 * len(state.active_ids)
    np.testing.assert_array_equal(state.slot_of[state.active_ids], np.arange(len(state.active_ids)))
    outside = np.setdiff1d(np.arange(M), state.active_ids)
    assert np.all(state.slot_of[outside] == -1)


def test_slot_columns_follow_the_pose():
    np.testing.assert_array_equal(slot_columns([0, 2]), [[6, 7, 8], [12, 13, 14]])
    assert slot_columns(np.zeros(0, dtype=int)).shape == (0, 3)


def test_enter_appends_zero_slots_in_order():
    rng = np.random.default_rng(0)
    state = _state_with([4, 9], rng)
    before = state.Sigma.copy()
    state.enter(np.array([7, 1, 15]))
    np.testing.assert_array_equal(state.active_ids, [4, 9, 7, 1, 15])
    _assert_slots_consistent(state)
    np.testing.assert_array_equal(state.Sigma[:12, :12], before)
    np.testing.assert_array_equal(state.Sigma[12:], 0.0)
    np.testing.assert_array_equal(state.Sigma[:, 12:], 0.0)


def test_augment_is_the_linearised_covariance_of_the_extended_state():
    """New landmarks ``m = m0 + G_pose delta + e``, ``e ~ N(0, C_new)``: the extended covariance is
    ``A Sigma A^T + diag(0, C_new)`` with ``A = [I; G_pose 0]``."""
    rng = np.random.default_rng(1)
    state = _state_with([3, 5, 11], rng)
    Sigma, D = state.Sigma.copy(), state.dim
    new = np.array([0, 17])
    G_pose = rng.normal(size=(2, 3, 6))
    C_new = np.stack([_spd(3, rng) for _ in range(2)])
    state.enter(new)
    state.augment(new, G_pose, C_new)

    A = np.zeros((D + 6, D))
    A[:D] = np.eye(D)
    A[D:, :6] = G_pose.reshape(6, 6)
    expected = A @ Sigma @ A.T
    expected[D:D + 3, D:D + 3] += C_new[0]
    expected[D + 3:, D + 3:] += C_new[1]
    np.testing.assert_allclose(state.Sigma, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(state.marginals(new), C_new + G_pose @ Sigma[:6, :6] @ np.swapaxes(G_pose, 1, 2),
                               rtol=1e-12)
    np.testing.assert_allclose(state.pose_cross(new), np.swapaxes(G_pose @ Sigma[:6, :6], 1, 2), rtol=1e-12)


def test_retire_deletes_rows_and_columns_and_returns_the_marginals():
    rng = np.random.default_rng(2)
    ids = np.array([2, 8, 6, 13, 19])
    state = _state_with(ids, rng)
    Sigma = state.Sigma.copy()
    covs = state.retire(np.array([13, 8]))
    for lm, cov in zip((13, 8), covs):
        cols = slot_columns([list(ids).index(lm)])[0]
        np.testing.assert_array_equal(cov, Sigma[np.ix_(cols, cols)])
    np.testing.assert_array_equal(state.active_ids, [2, 6, 19])
    _assert_slots_consistent(state)
    keep = np.concatenate([np.arange(6), slot_columns([0, 2, 4]).ravel()])
    np.testing.assert_array_equal(state.Sigma, Sigma[np.ix_(keep, keep)])
    # what stays is untouched: marginals of the remaining landmarks are the same as before
    for lm in (2, 6, 19):
        cols = slot_columns([list(ids).index(lm)])[0]
        np.testing.assert_array_equal(state.marginals([lm])[0], Sigma[np.ix_(cols, cols)])


def test_retire_all_leaves_the_pose():
    rng = np.random.default_rng(3)
    state = _state_with([1, 2], rng)
    pose = state.pose_cov.copy()
    state.retire(np.array([1, 2]))
    assert state.dim == 6 and len(state.active_ids) == 0
    np.testing.assert_array_equal(state.pose_cov, pose)
    _assert_slots_consistent(state)


def test_dense_state_holds_every_landmark_with_the_placeholder():
    ids = np.arange(0, M, 3)
    pose = 0.01 * np.eye(6)
    state = ActiveSet.dense(M, ids, pose, placeholder_variance=1e6)
    _assert_slots_consistent(state)
    np.testing.assert_array_equal(state.pose_cov, pose)
    np.testing.assert_array_equal(state.Sigma[6:, 6:], 1e6 * np.eye(3 * len(ids)))
    np.testing.assert_array_equal(state.Sigma[:6, 6:], 0.0)


@pytest.mark.parametrize("shape", [(5, 5), (6,)])
def test_pose_cov_must_be_six_by_six(shape):
    with pytest.raises(ValueError, match=r"pose_cov must have shape \(6, 6\)"):
        ActiveSet(M, np.zeros(shape))


def test_propagate_is_the_forms_prediction_with_static_landmarks():
    """``propagate`` with the right form: ``F Sigma_pp F^T + W`` on the pose, ``F Sigma_pl`` across,
    the landmark block untouched (the explicit ``Phi Sigma Phi^T + Q``)."""
    from visla_edu.filters._forms import RightForm

    rng = np.random.default_rng(3)
    state = _state_with([4, 9], rng)
    F, W = rng.normal(size=(6, 6)), np.diag(rng.uniform(0.1, 1.0, 6))
    Phi = np.eye(state.dim)
    Phi[:6, :6] = F
    Q = np.zeros((state.dim, state.dim))
    Q[:6, :6] = W
    expected = Phi @ state.Sigma @ Phi.T + Q
    state.propagate(RightForm, np.eye(4), np.zeros((2, 3)), F, W)
    np.testing.assert_allclose(state.Sigma, expected, rtol=1e-12, atol=1e-12)


def test_update_is_the_kalman_update_of_the_explicit_form():
    """``update``: ``Sigma - K H Sigma`` and ``delta = K r`` with ``K = Sigma H^T S^-1``."""
    rng = np.random.default_rng(4)
    state = _state_with([1, 2, 3], rng)
    H = rng.normal(size=(4, state.dim))
    Sigma = state.Sigma.copy()
    S = H @ Sigma @ H.T + 2.0 * np.eye(4)
    r = rng.normal(size=4)
    K = Sigma @ H.T @ np.linalg.inv(S)
    delta, nis = state.update(Sigma @ H.T, S, r)
    np.testing.assert_allclose(delta, K @ r, rtol=1e-10)
    np.testing.assert_allclose(state.Sigma, Sigma - K @ H @ Sigma, rtol=1e-9, atol=1e-9)
    assert nis == pytest.approx(r @ np.linalg.solve(S, r), rel=1e-10)


def test_landmark_covs_are_the_slots_diagonal_blocks_in_the_right_form():
    from visla_edu.filters._forms import RightForm

    rng = np.random.default_rng(5)
    state = _state_with([7, 3, 11], rng)
    covs = state.landmark_covs(RightForm, np.array([3, 11]), np.zeros((2, 3)))
    np.testing.assert_array_equal(covs, state.marginals(np.array([3, 11])))


def test_correct_is_the_joint_correction_on_the_slots_of_the_ids():
    """``correct(ids, ...)`` is :func:`visla_edu.ekf.joint_correction` at the slots holding ``ids``."""
    from visla_edu import ekf

    rng = np.random.default_rng(6)
    state = _state_with([5, 8, 13], rng)
    ids = np.array([13, 5])
    z = rng.normal(size=(2, 4))
    prediction = (rng.normal(size=(2, 4)), rng.normal(size=(2, 4, 3)), rng.normal(size=(2, 4, 6)))
    Sigma = state.Sigma.copy()
    delta_ref, nis_ref = ekf.joint_correction(Sigma, np.array([2, 0]), z, 1.5, prediction)
    delta, nis = state.correct(ids, z, 1.5, prediction, ekf.STEREO_ROWS)
    np.testing.assert_array_equal(delta, delta_ref)
    np.testing.assert_array_equal(state.Sigma, Sigma)
    assert nis == nis_ref
