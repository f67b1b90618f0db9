"""The two error forms of the joint filter: the right perturbation and the invariant error.

Both run the same EKF on the same state layout (:class:`~visla_edu.filters.ActiveSet`); they
differ in what the state's error *means*, and so in the covariance prediction, the pose
Jacobian, how a correction is applied, and how a new landmark inherits the pose's uncertainty.

* :class:`RightForm`, the form notebooks 06-08 derive (:mod:`visla_edu.lie`): its unobservable
  directions (moving the whole world) depend on the estimate, so each update gains information the
  data never gave, the classic overconfidence of EKF-SLAM (Huang, Mourikis and Roumeliotis 2008).
* :class:`InvariantForm`, the invariant EKF (Barrau and Bonnabel 2017): the unobservable
  directions are the same whatever the estimate, the transition is the identity, and the filter
  stays consistent (notebook 10 compares the NEES of both).

Each form is a namespace of static methods with the same signatures (the class itself is used,
never an instance), documented once here; a method ignores the arguments its form does not need:

* ``Sigma`` (D, D): the joint covariance, ``D = 6 + 3 n`` (then 6 per clone);
* ``world_T_imu`` (4, 4): the pose mean ``mu`` (in ``predict``: after the step);
* ``p_active`` (n, 3): the landmark means in slot order; ``p_world`` (k, 3): the world point of
  each observation;
* ``F``, ``W`` (6, 6): the step's :func:`visla_edu.motion.pose_transition` and motion noise;
* ``J_landmark`` (k, 4, 3), ``J_pose`` (k, 4, 6): the stereo pixels' Jacobians with respect to
  the point and to the pose's right perturbation, at the pose's (or the clone's) mean
  (:meth:`visla_edu.camera.StereoCamera.predict_with_jacobians`);
* ``delta`` (6 + 3 n,): a correction ``[pose (6); landmarks (3 each)]``; for the clones
  ``clone_T`` (n, 4, 4) and ``delta`` (n, 6);
* ``G_pose`` (k, 3, 6): the pose sensitivity of new landmarks
  (:func:`visla_edu.ekf.initialize_landmarks`);
* ``cols`` (k, 3) of int, ``means`` (k, 3): state columns and means of landmarks in the state.

Results are reported in the library's convention either way: the pose covariance of the right
perturbation ``[v; w]`` and the landmark covariance of ``m - mu_m``.
"""

import numpy as np

from visla_edu import ekf, lie, motion

__all__ = ["RightForm", "InvariantForm", "ERROR_FORMS"]


class RightForm:
    """The right perturbation ``T = mu exp(hat(delta))``, ``m = mu_m + delta_m`` (``slam_error="right"``).

    Arguments of its methods: the module docstring.
    """

    name = "right"

    @staticmethod
    def predict(Sigma, world_T_imu, p_active, F, W):
        """``Sigma_pp <- F Sigma_pp F^T + W``, ``Sigma_pl <- F Sigma_pl`` (in place).

        :func:`visla_edu.motion.predict_joint_covariance` (which also keeps ``Sigma`` symmetric).
        """
        motion.predict_joint_covariance(Sigma, F, W)

    @staticmethod
    def pose_jacobian(J_landmark, J_pose):
        """``J_pose`` itself, (k, 4, 6): the camera's Jacobian is already the right perturbation's."""
        return J_pose

    @staticmethod
    def retract(world_T_imu, p_active, delta):
        """``(mu exp(hat(delta[:6])), p_active + delta[6:].reshape(-1, 3))``, shapes (4, 4) and (n, 3)."""
        return world_T_imu @ lie.se3_exp(delta[:6]), p_active + delta[6:].reshape(-1, 3)

    @staticmethod
    def clone_jacobian(J_landmark, J_pose, p_world):
        """Jacobian (N, 4, 6) of an observation made from a clone with respect to that clone's error: ``J_pose``."""
        return J_pose

    @staticmethod
    def delayed_pose_jacobian(J_landmark, p_world):
        """Zero (N, 4, 6): a past observation of a landmark entering now does not depend on the current pose."""
        return np.zeros(J_landmark.shape[:-1] + (6,))

    @staticmethod
    def retract_clone(clone_T, delta):
        """``clone_T exp(hat(delta))`` for each clone: clone_T (n, 4, 4), delta (n, 6)."""
        return clone_T @ lie.se3_exp(delta)

    @staticmethod
    def landmark_sensitivity(G_pose):
        """``G_pose`` itself, (k, 3, 6): :func:`visla_edu.ekf.initialize_landmarks` uses the body-frame error."""
        return G_pose

    @staticmethod
    def pose_cov(Sigma_pose, world_T_imu):
        """``Sigma_pose`` itself, (6, 6): the state's pose block is already the right-perturbation covariance."""
        return Sigma_pose

    @staticmethod
    def landmark_covs(Sigma, cols, means):
        """Marginal covariances (k, 3, 3) of the slots with columns ``cols``: the blocks ``Sigma[cols_i, cols_i]``."""
        return Sigma[cols[:, :, None], cols[:, None, :]]


class InvariantForm:
    """The invariant error ``T = exp(hat(xi)) mu``, ``m_j = exp(hat(theta)) mu_j + e_j`` (``slam_error="invariant"``).

    ``xi = [p; theta]`` is in the world frame. :meth:`pose_cov` and :meth:`landmark_covs` convert
    back to the library's convention. Arguments of its methods: the module docstring.
    """

    name = "invariant"

    @staticmethod
    def predict(Sigma, world_T_imu, p_active, F, W):
        """``Sigma <- Sigma + B B^T`` in place (:func:`visla_edu.motion.predict_invariant_covariance`); F is I here.

        Clones (columns after the landmarks) get no noise: a clone's world-frame error does not change
        when the current pose moves.
        """
        end = 6 + 3 * len(p_active)
        motion.predict_invariant_covariance(Sigma[:end, :end], world_T_imu, p_active, W)

    @staticmethod
    def pose_jacobian(J_landmark, J_pose):
        """``[-J_landmark, 0]`` (:func:`visla_edu.ekf.invariant_pose_jacobian`), (k, 4, 6): columns 0-2 for ``p``."""
        return ekf.invariant_pose_jacobian(J_landmark)

    @staticmethod
    def retract(world_T_imu, p_active, delta):
        """``mu <- exp(hat(xi)) mu``, ``mu_j <- R_xi mu_j + J_l(theta) e_j`` (:func:`visla_edu.ekf.invariant_retract`).

        ``delta`` is ``[xi (6); e_0 (3); e_1 (3); ...]``; returns as :meth:`RightForm.retract`.
        """
        return ekf.invariant_retract(world_T_imu, p_active, delta)

    @staticmethod
    def clone_jacobian(J_landmark, J_pose, p_world):
        """``[-J_landmark, J_landmark hat(m)]`` (N, 4, 6): an observation from a clone, by the clone's error.

        With ``T = exp(hat(xi)) mu`` and a point ``m`` (``p_world``) not in the state, the camera
        sees ``inv(T) m ~ inv(mu) (m - p - theta x m)``; ``J_landmark`` is ``dz/dm`` at the clone's
        mean.
        """
        return np.concatenate([-J_landmark, J_landmark @ lie.hat(p_world)], axis=-1)

    @staticmethod
    def delayed_pose_jacobian(J_landmark, p_world):
        """``[0, -J_landmark hat(mu_m)]`` (N, 4, 6): a past observation of a landmark entering now, by the pose.

        Its invariant error is taken relative to the current pose's rotation error, ``m =
        exp(hat(theta)) mu_m + e`` (``mu_m``: ``p_world``), so all its observations depend on
        ``theta``.
        """
        return np.concatenate([np.zeros_like(J_landmark), -J_landmark @ lie.hat(p_world)], axis=-1)

    @staticmethod
    def retract_clone(clone_T, delta):
        """``exp(hat(delta)) clone_T`` for each clone: clone_T (n, 4, 4), delta (n, 6)."""
        return lie.se3_exp(delta) @ clone_T

    @staticmethod
    def landmark_sensitivity(G_pose):
        """``[I, 0]`` for each new landmark, (k, 3, 6) (only ``len(G_pose)`` is used).

        A point placed at ``mu p_imu`` is ``exp(hat(theta)) mu p_imu + p`` to first order, so its
        invariant error ``e = p + R dp_imu`` takes the pose's translation error and nothing of
        ``theta``; the pixels add ``R dp_imu`` (the triangulation covariance, world frame).
        """
        G = np.zeros((len(G_pose), 3, 6))
        G[:, :, :3] = np.eye(3)
        return G

    @staticmethod
    def pose_cov(Sigma_pose, world_T_imu):
        """``Ad(inv(mu)) Sigma_xi Ad(inv(mu))^T`` (6, 6): the right-perturbation covariance.

        ``delta = Ad(inv(mu)) xi``; ``Sigma_pose`` is the covariance of ``xi``.
        """
        A = lie.adjoint(lie.se3_inv(world_T_imu))
        return A @ Sigma_pose @ A.T

    @staticmethod
    def landmark_covs(Sigma, cols, means):
        """Covariances (k, 3, 3) of ``m - mu_m = e - hat(mu_m) theta`` for the slots with columns ``cols``.

        ``A Sigma_theta A^T + A Sigma_theta,e + (A Sigma_theta,e)^T + Sigma_e`` with
        ``A = -hat(mu_m)`` (``mu_m``: ``means``), symmetrised.
        """
        See = Sigma[cols[:, :, None], cols[:, None, :]]
        if len(cols) == 0:
            return See
        A = -lie.hat(means)  # (k, 3, 3), acting on theta
        Ste = np.swapaxes(Sigma[3:6][:, cols], 0, 1)  # (k, 3, 3): cov(theta, e)
        ASte = A @ Ste
        covs = A @ Sigma[3:6, 3:6] @ np.swapaxes(A, 1, 2) + ASte + np.swapaxes(ASte, 1, 2) + See
        return 0.5 * (covs + np.swapaxes(covs, 1, 2))


#: Error form by the name ``FilterConfig.slam_error`` takes.
ERROR_FORMS = {form.name: form for form in (RightForm, InvariantForm)}
