"""The linear Kalman filter of the primer notebook (00b) and its checks' reference: update_1d, predict, update.

For ``x ~ N(mean, P)``:

* prediction through ``x' = F x + w``, ``w ~ N(0, Q)``:  ``mean' = F mean``, ``P' = F P F^T + Q``;
* update with ``z = H x + v``, ``v ~ N(0, R)``: innovation ``r = z - H mean``,
  ``S = H P H^T + R``, gain ``K = P H^T S^-1``, ``mean += K r``, ``P = (I - K H) P``.

:func:`update` takes the innovation, so the EKF's ``r = z - h(mean)`` fits too. Outside
:mod:`visla_edu.course.checks` for the same reason as :mod:`visla_edu.course.numdiff`.
"""

import numpy as np
from scipy import linalg

__all__ = ["update_1d", "predict", "update"]


def update_1d(mean, variance, z, noise_variance):
    """Kalman update of a scalar state measured directly: ``z = x + v``, ``v ~ N(0, noise_variance)``.

    Returns ``(mean + K (z - mean), (1 - K) variance)`` (floats), ``K = variance / (variance + noise_variance)``.
    """
    variance, noise_variance = float(variance), float(noise_variance)
    if variance < 0 or noise_variance < 0 or variance + noise_variance <= 0:
        raise ValueError(f"update_1d: variances must be >= 0 and not both 0, got variance {variance}, "
                         f"noise_variance {noise_variance}")
    gain = variance / (variance + noise_variance)
    return float(mean) + gain * (float(z) - float(mean)), (1.0 - gain) * variance


def _square(M, n, what):
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.shape != (n, n):
        raise ValueError(f"{what}: expected shape ({n}, {n}), got {M.shape}")
    return M


def predict(mean, P, F, Q):
    """Prediction of a linear Gaussian state: ``(F mean, F P F^T + Q)``, shapes (n,) and (n, n).

    ``mean`` has shape (n,); ``P, F, Q`` shape (n, n) (state covariance, transition, process noise).
    """
    mean = np.atleast_1d(np.asarray(mean, dtype=float))
    n = mean.shape[0]
    P, F, Q = _square(P, n, "predict: P"), _square(F, n, "predict: F"), _square(Q, n, "predict: Q")
    return F @ mean, F @ P @ F.T + Q


def update(mean, P, innovation, H, R):
    """Kalman update given the innovation ``r = z - H mean`` (EKF: ``z - h(mean)``, ``H`` the Jacobian).

    Shapes: ``mean`` (n,), ``P`` (n, n), ``innovation`` (m,), ``H`` (m, n), ``R`` (m, m); returns the
    posterior mean (n,) and symmetrised covariance (n, n); ValueError if ``S`` is not positive definite.
    """
    mean = np.atleast_1d(np.asarray(mean, dtype=float))
    innovation = np.atleast_1d(np.asarray(innovation, dtype=float))
    n, m = mean.shape[0], innovation.shape[0]
    P, R = _square(P, n, "update: P"), _square(R, m, "update: R")
    H = np.atleast_2d(np.asarray(H, dtype=float))
    if H.shape != (m, n):
        raise ValueError(f"update: H must have shape ({m}, {n}) for {m} measurements of {n} states, got {H.shape}")
    S = H @ P @ H.T + R
    try:
        factor = linalg.cho_factor(S)
    except linalg.LinAlgError:
        raise ValueError("update: the innovation covariance H P H^T + R is not positive definite; "
                         "check that R is a covariance (positive variances)") from None
    gain = linalg.cho_solve(factor, H @ P).T  # K = P H^T S^-1 (S and P symmetric)
    P_new = P - gain @ H @ P
    return mean + gain @ innovation, 0.5 * (P_new + P_new.T)
