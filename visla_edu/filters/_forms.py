"""The two error forms of the joint filter: the right perturbation and the invariant error.

Both run the same EKF on the same state layout (``[pose (6); slot 0 (3); ...]``, see
:class:`~visla_edu.filters.ActiveSet`); they differ in what the state's error *means*, and so
in four places: the covariance prediction, the pose Jacobian, how a correction is applied,
and how a new landmark inherits the pose's uncertainty.

* :class:`RightForm`, the form notebooks 06-08 derive: ``T = mu exp(hat(delta))`` (body
  frame), ``m = mu_m + delta_m``. Its unobservable directions (moving the whole world) depend
  on the estimate, so each update, linearised at a slightly different estimate, gains
  information the data never gave: the classic overconfidence of EKF-SLAM (Huang, Mourikis
  and Roumeliotis 2008). On a 1100-frame simulated drive its pose NEES averages in the
  hundreds where 6 is consistent.
* :class:`InvariantForm`, the invariant EKF (Barrau and Bonnabel 2017): ``T = exp(hat(xi)) mu``
  (world frame, ``xi = [p; theta]``) and ``m_j = exp(hat(theta)) mu_j + e_j``. The
  unobservable directions are the same whatever the estimate, the transition is the identity,
  and the filter stays consistent (pose NEES about 4-6 on the same drives).

Results are reported in the library's convention either way: the pose covariance of the right
perturbation ``[v; w]`` and the landmark covariance of ``m - mu_m``.
"""

import numpy as np

from visla_edu import ekf, lie, motion

__all__ = ["RightForm", "InvariantForm", "ERROR_FORMS"]


class RightForm:
    """The right perturbation ``T = mu exp(hat(delta))``, ``m = mu_m + delta_m`` (notebooks 06-08).

    A namespace of static methods (the class itself is used, never an instance); the joint
    filter calls them on its state ``[pose (6); landmarks (3 each, in slot order)]``.

    Attributes
    ----------
    name : str
        ``"right"``, the value of ``FilterConfig.slam_error`` that selects it.
    """

    name = "right"

    @staticmethod
    def predict(Sigma, world_T_imu, p_active, F, W):
        """``Sigma_pp <- F Sigma_pp F^T + W``, ``Sigma_pl <- F Sigma_pl`` (in place).

        :func:`visla_edu.motion.predict_joint_covariance` (which also keeps ``Sigma``
        symmetric).

        Parameters
        ----------
        Sigma : ndarray, shape (6 + 3n, 6 + 3n)
            The joint covariance, modified in place.
        world_T_imu : ndarray, shape (4, 4)
            Unused here.
        p_active : ndarray, shape (n, 3)
            Unused here.
        F : ndarray, shape (6, 6)
            :func:`visla_edu.motion.pose_transition` of the step.
        W : ndarray, shape (6, 6)
            The step's motion noise.
        """
        motion.predict_joint_covariance(Sigma, F, W)

    @staticmethod
    def pose_jacobian(J_landmark, J_pose):
        """The camera's right-perturbation pose Jacobian, unchanged, (k, 4, 6).

        Parameters
        ----------
        J_landmark : ndarray, shape (k, 4, 3)
            Unused here.
        J_pose : ndarray, shape (k, 4, 6)
            From :meth:`visla_edu.camera.StereoCamera.predict_with_jacobians`.

        Returns
        -------
        ndarray, shape (k, 4, 6)
            ``J_pose`` itself.
        """
        return J_pose

    @staticmethod
    def retract(world_T_imu, p_active, delta):
        """``mu exp(hat(delta_pose))`` and ``mu_m + delta_m``.

        Parameters
        ----------
        world_T_imu : ndarray, shape (4, 4)
        p_active : ndarray, shape (n, 3)
            Means of the landmarks in the state, in slot order.
        delta : ndarray, shape (6 + 3n,)
            The correction ``[delta_pose (6); delta_m (3 each)]``.

        Returns
        -------
        world_T_imu : ndarray, shape (4, 4)
            ``world_T_imu @ se3_exp(delta[:6])``.
        p_active : ndarray, shape (n, 3)
            ``p_active + delta[6:].reshape(-1, 3)``.
        """
        return world_T_imu @ lie.se3_exp(delta[:6]), p_active + delta[6:].reshape(-1, 3)

    @staticmethod
    def clone_jacobian(J_landmark, J_pose, p_world):
        """Jacobian of an observation made from a cloned pose with respect to that clone's error, (N, 4, 6).

        A clone's error means what the pose's does (here the right perturbation), so it is the
        camera's ``J_pose``.

        Parameters
        ----------
        J_landmark : ndarray, shape (N, 4, 3)
            Unused here.
        J_pose : ndarray, shape (N, 4, 6)
            The right-perturbation pose Jacobian at the clone's mean.
        p_world : ndarray, shape (N, 3)
            Unused here.

        Returns
        -------
        ndarray, shape (N, 4, 6)
        """
        return J_pose

    @staticmethod
    def delayed_pose_jacobian(J_landmark, p_world):
        """Jacobian of a past observation of a landmark entering now with respect to the current pose, (N, 4, 6).

        The right form's landmark error ``m - mu_m`` does not involve the pose: zero.

        Parameters
        ----------
        J_landmark : ndarray, shape (N, 4, 3)
        p_world : ndarray, shape (N, 3)

        Returns
        -------
        ndarray, shape (N, 4, 6)
        """
        return np.zeros(J_landmark.shape[:-1] + (6,))

    @staticmethod
    def retract_clone(clone_T, delta):
        """``clone_T exp(hat(delta))`` for each clone: clone_T (n, 4, 4), delta (n, 6)."""
        return clone_T @ lie.se3_exp(delta)

    @staticmethod
    def landmark_sensitivity(G_pose):
        """``G_pose`` of :func:`visla_edu.ekf.initialize_landmarks` (the body-frame error), (k, 3, 6).

        Parameters
        ----------
        G_pose : ndarray, shape (k, 3, 6)

        Returns
        -------
        ndarray, shape (k, 3, 6)
            ``G_pose`` itself.
        """
        return G_pose

    @staticmethod
    def pose_cov(Sigma_pose, world_T_imu):
        """The state's pose block is already the right-perturbation covariance.

        Parameters
        ----------
        Sigma_pose : ndarray, shape (6, 6)
        world_T_imu : ndarray, shape (4, 4)
            Unused here.

        Returns
        -------
        ndarray, shape (6, 6)
            ``Sigma_pose`` itself.
        """
        return Sigma_pose

    @staticmethod
    def landmark_covs(Sigma, cols, means):
        """Marginal covariances of the slots with columns ``cols`` (k, 3), (k, 3, 3).

        Parameters
        ----------
        Sigma : ndarray, shape (6 + 3n, 6 + 3n)
        cols : ndarray of int, shape (k, 3)
            State columns of each landmark.
        means : ndarray, shape (k, 3)
            Unused here.

        Returns
        -------
        ndarray, shape (k, 3, 3)
            The diagonal blocks ``Sigma[cols_i, cols_i]``.
        """
        return Sigma[cols[:, :, None], cols[:, None, :]]


class InvariantForm:
    """The invariant error ``T = exp(hat(xi)) mu``, ``m_j = exp(hat(theta)) mu_j + e_j``.

    ``xi = [p; theta]`` is in the world frame. A namespace of static methods with the same
    signatures as :class:`RightForm`'s; :meth:`pose_cov` and :meth:`landmark_covs` convert back
    to the library's convention (the right perturbation ``[v; w]`` of the pose, ``m - mu_m``).

    Attributes
    ----------
    name : str
        ``"invariant"``, the value of ``FilterConfig.slam_error`` that selects it.
    """

    name = "invariant"

    @staticmethod
    def predict(Sigma, world_T_imu, p_active, F, W):
        """``Sigma <- Sigma + B B^T`` (:func:`visla_edu.motion.predict_invariant_covariance`); F is the identity here.

        Parameters
        ----------
        Sigma : ndarray, shape (6 + 3n, 6 + 3n)
            The joint covariance, modified in place.
        world_T_imu : ndarray, shape (4, 4)
            The pose mean after the step.
        p_active : ndarray, shape (n, 3)
            Landmark means in slot order; non-finite entries count as 0 (the dense filter's
            placeholders get no noise).
        F : ndarray, shape (6, 6)
            Ignored.
        W : ndarray, shape (6, 6)
            The step's motion noise.

        Clones (columns after the landmarks) get no noise: a clone's world-frame error does not
        change when the current pose moves.
        """
        end = 6 + 3 * len(p_active)
        motion.predict_invariant_covariance(Sigma[:end, :end], world_T_imu, p_active, W)

    @staticmethod
    def pose_jacobian(J_landmark, J_pose):
        """``[-J_landmark, 0]`` (:func:`visla_edu.ekf.invariant_pose_jacobian`), (k, 4, 6).

        Parameters
        ----------
        J_landmark : ndarray, shape (k, 4, 3)
        J_pose : ndarray, shape (k, 4, 6)
            Unused here.

        Returns
        -------
        ndarray, shape (k, 4, 6)
            Columns 0-2 (for ``p``) ``-J_landmark``, columns 3-5 (for ``theta``) zero.
        """
        return ekf.invariant_pose_jacobian(J_landmark)

    @staticmethod
    def retract(world_T_imu, p_active, delta):
        """:func:`visla_edu.ekf.invariant_retract`.

        ``mu <- exp(hat(xi)) mu`` and ``mu_j <- R_xi mu_j + J_l(theta) e_j``.

        Parameters
        ----------
        world_T_imu : ndarray, shape (4, 4)
        p_active : ndarray, shape (n, 3)
        delta : ndarray, shape (6 + 3n,)
            ``[xi (6); e_0 (3); e_1 (3); ...]``.

        Returns
        -------
        world_T_imu : ndarray, shape (4, 4)
        p_active : ndarray, shape (n, 3)
        """
        return ekf.invariant_retract(world_T_imu, p_active, delta)

    @staticmethod
    def clone_jacobian(J_landmark, J_pose, p_world):
        """Jacobian of an observation made from a clone with respect to the clone's error, (N, 4, 6).

        With ``T = exp(hat(xi)) mu`` and a point ``m`` not in the state, the camera sees
        ``inv(T) m ~ inv(mu) (m - p - theta x m)``: ``[-J_landmark, J_landmark hat(m)]``.

        Parameters
        ----------
        J_landmark : ndarray, shape (N, 4, 3)
            ``dz/dm`` at the clone's mean.
        J_pose : ndarray, shape (N, 4, 6)
            Unused here.
        p_world : ndarray, shape (N, 3)
            ``m``.

        Returns
        -------
        ndarray, shape (N, 4, 6)
        """
        return np.concatenate([-J_landmark, J_landmark @ lie.hat(p_world)], axis=-1)

    @staticmethod
    def delayed_pose_jacobian(J_landmark, p_world):
        """Jacobian of a past observation of a landmark entering now with respect to the current pose, (N, 4, 6).

        The landmark's invariant error is taken relative to the current pose's rotation error,
        ``m = exp(hat(theta)) mu_m + e``, so every observation of it depends on ``theta`` through
        ``-J_landmark hat(mu_m)`` (and on ``e`` through ``J_landmark``).

        Parameters
        ----------
        J_landmark : ndarray, shape (N, 4, 3)
        p_world : ndarray, shape (N, 3)
            ``mu_m``.

        Returns
        -------
        ndarray, shape (N, 4, 6)
            Columns 0-2 zero, 3-5 ``-J_landmark hat(mu_m)``.
        """
        return np.concatenate([np.zeros_like(J_landmark), -J_landmark @ lie.hat(p_world)], axis=-1)

    @staticmethod
    def retract_clone(clone_T, delta):
        """``exp(hat(delta)) clone_T`` for each clone: clone_T (n, 4, 4), delta (n, 6)."""
        return lie.se3_exp(delta) @ clone_T

    @staticmethod
    def landmark_sensitivity(G_pose):
        """``[I, 0]``: a landmark placed at ``mu p_imu`` has ``e = p + R dp_imu``, (k, 3, 6).

        With ``T = exp(hat(xi)) mu`` the new point is ``exp(hat(theta)) mu p_imu + p`` to first
        order, so its invariant error takes the pose's translation error ``p`` and nothing of
        ``theta``; the pixels add ``R dp_imu`` (the triangulation covariance in the world frame).

        Parameters
        ----------
        G_pose : ndarray, shape (k, 3, 6)
            Only its length ``k`` is used.

        Returns
        -------
        ndarray, shape (k, 3, 6)
            ``[I, 0]`` for each new landmark.
        """
        G = np.zeros((len(G_pose), 3, 6))
        G[:, :, :3] = np.eye(3)
        return G

    @staticmethod
    def pose_cov(Sigma_pose, world_T_imu):
        """The right-perturbation covariance ``Ad(inv(mu)) Sigma_xi Ad(inv(mu))^T`` (``delta = Ad(inv(mu)) xi``).

        Parameters
        ----------
        Sigma_pose : ndarray, shape (6, 6)
            Covariance of ``xi``.
        world_T_imu : ndarray, shape (4, 4)
            ``mu``.

        Returns
        -------
        ndarray, shape (6, 6)
        """
        A = lie.adjoint(lie.se3_inv(world_T_imu))
        return A @ Sigma_pose @ A.T

    @staticmethod
    def landmark_covs(Sigma, cols, means):
        """Covariances of ``m - mu_m = e - hat(mu_m) theta`` for the slots with columns ``cols``, (k, 3, 3).

        ``A Sigma_theta A^T + A Sigma_theta,e + (A Sigma_theta,e)^T + Sigma_e`` with
        ``A = -hat(mu_m)``, symmetrised.

        Parameters
        ----------
        Sigma : ndarray, shape (6 + 3n, 6 + 3n)
        cols : ndarray of int, shape (k, 3)
            State columns of each landmark's ``e``.
        means : ndarray, shape (k, 3)
            The landmark means ``mu_m``.

        Returns
        -------
        ndarray, shape (k, 3, 3)
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
