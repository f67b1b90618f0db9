"""The primer's linear Kalman filter (visla_edu.course.kalman) against independent formulas."""

import numpy as np
import pytest

from visla_edu.course import kalman


def _random_covariance(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def test_update_is_the_product_of_gaussians_in_information_form():
    rng = np.random.default_rng(0)
    n, m = 4, 2
    mean, P = rng.normal(size=n), _random_covariance(rng, n)
    H, R, z = rng.normal(size=(m, n)), _random_covariance(rng, m), rng.normal(size=m)
    got_mean, got_P = kalman.update(mean, P, z - H @ mean, H, R)
    info = np.linalg.inv(P) + H.T @ np.linalg.solve(R, H)  # posterior information matrix
    want_P = np.linalg.inv(info)
    want_mean = want_P @ (np.linalg.solve(P, mean) + H.T @ np.linalg.solve(R, z))
    assert np.allclose(got_P, want_P) and np.allclose(got_mean, want_mean)
    assert np.allclose(got_P, got_P.T)


@pytest.mark.parametrize("case", [(0.0, 4.0, 1.0, 1.0), (10.0, 1.0, 12.5, 4.0), (1.0, 0.0, 5.0, 2.0),
                                  (1.0, 3.0, 5.0, 0.0)])
def test_scalar_update_matches_the_matrix_update_and_bayes(case):
    m, var, z, r = case
    mean, variance = kalman.update_1d(m, var, z, r)
    if var > 0 and r > 0:
        assert np.isclose(1 / variance, 1 / var + 1 / r)  # information adds
        assert np.isclose(mean / variance, m / var + z / r)
        got_mean, got_P = kalman.update([m], [[var]], [z - m], [[1.0]], [[r]])
        assert np.isclose(got_mean[0], mean) and np.isclose(got_P[0, 0], variance)
    else:  # a certain prior keeps its mean; a perfect sensor takes the measurement
        assert (mean, variance) == ((m, 0.0) if var == 0 else (z, 0.0))


def test_predict_matches_the_covariance_of_propagated_samples():
    rng = np.random.default_rng(1)
    mean, P = np.array([1.0, -2.0]), _random_covariance(rng, 2)
    F, Q = np.array([[1.0, 0.5], [0.0, 1.0]]), 0.1 * _random_covariance(rng, 2)
    x = rng.multivariate_normal(mean, P, size=200_000) @ F.T + rng.multivariate_normal(np.zeros(2), Q, size=200_000)
    got_mean, got_P = kalman.predict(mean, P, F, Q)
    assert np.allclose(got_mean, F @ mean)
    assert np.allclose(got_P, np.cov(x.T), rtol=0.02, atol=0.02)


def test_bad_inputs_name_the_problem():
    with pytest.raises(ValueError, match="H must have shape"):
        kalman.update(np.zeros(2), np.eye(2), np.zeros(1), np.zeros((2, 2)), np.eye(1))
    with pytest.raises(ValueError, match="not positive definite"):
        kalman.update(np.zeros(2), np.eye(2), np.zeros(1), np.zeros((1, 2)), -np.eye(1))
    with pytest.raises(ValueError, match=r"predict: F: expected shape \(2, 2\)"):
        kalman.predict(np.zeros(2), np.eye(2), np.eye(3), np.eye(2))
    with pytest.raises(ValueError, match="variances must be >= 0"):
        kalman.update_1d(0.0, -1.0, 0.0, 1.0)
