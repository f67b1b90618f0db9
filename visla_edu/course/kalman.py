"""The linear Kalman filter of the primer notebook (00b): one scalar update, predict, update.

The textbook version, on a plain vector, of the course's filters (:mod:`visla_edu.filters`,
:mod:`visla_edu.ekf`, on SE(3) and a map of landmarks); ``solutions/00b_kalman_primer.ipynb``
uses it after its exercises, and their checks as the reference. For ``x ~ N(mean, P)``:

* prediction through ``x' = F x + w``, ``w ~ N(0, Q)``:  ``mean' = F mean``, ``P' = F P F^T + Q``;
* update with ``z = H x + v``, ``v ~ N(0, R)``: innovation ``r = z - H mean``,
  ``S = H P H^T + R``, gain ``K = P H^T S^-1``, ``mean += K r``, ``P = (I - K H) P``.

The EKF uses the same update with ``r = z - h(mean)`` and ``H`` the Jacobian of ``h`` at the
mean, hence :func:`update` takes the innovation. Outside :mod:`visla_edu.course.checks` so that
the function objects stay the same when a graded cell reloads the checks (as
:mod:`visla_edu.course.numdiff`).
"""

import numpy as np
from scipy import linalg

__all__ = ["update_1d", "predict", "update"]


def update_1d(mean, variance, z, noise_variance):
    """Kalman update of a scalar state measured directly: ``z = x + v``, ``v ~ N(0, noise_variance)``.

    Parameters
    ----------
    mean, variance : float
        Prior ``x ~ N(mean, variance)``.
    z : float
    noise_variance : float
        ``r``.

    Returns
    -------
    (float, float)
        ``mean + K (z - mean)`` and ``(1 - K) variance``, with ``K = variance / (variance + r)``.
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

    Parameters
    ----------
    mean : array_like, shape (n,)
    P, F, Q : array_like, shape (n, n)
        Covariance of the state, transition matrix, covariance of the process noise.
    """
    mean = np.atleast_1d(np.asarray(mean, dtype=float))
    n = mean.shape[0]
    P, F, Q = _square(P, n, "predict: P"), _square(F, n, "predict: F"), _square(Q, n, "predict: Q")
    return F @ mean, F @ P @ F.T + Q


def update(mean, P, innovation, H, R):
    """Kalman update given the innovation ``r = z - H mean`` (EKF: ``z - h(mean)``, ``H`` the Jacobian).

    Returns the posterior mean (n,) and covariance (n, n) of the module docstring's update, ``K``
    solved with a Cholesky factor of ``S`` (never inverted), the covariance symmetrised.

    Parameters
    ----------
    mean : array_like, shape (n,)
    P : array_like, shape (n, n)
    innovation : array_like, shape (m,)
    H : array_like, shape (m, n)
    R : array_like, shape (m, m)
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
