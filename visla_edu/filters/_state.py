"""The joint state's bookkeeping: one covariance over the pose and the landmarks in the state.

:class:`ActiveSet` owns the joint EKF's covariance (in the manner of OpenVINS's ``StateHelper``)
and which slot holds which landmark; the filters build the Jacobians, the innovations and the
retraction of the means, and decide *when* to do each. ``tests/test_structure.py`` holds that
nothing else writes :attr:`ActiveSet.Sigma`.

The state is ``[pose perturbation (6); slot 0 (3); slot 1 (3); ...; clone 0 (6); clone 1 (6);
...]``: slot ``s`` occupies the columns :func:`visla_edu.ekf.slot_columns` gives (``6 + 3 s ..
6 + 3 s + 2``), and after the ``n`` landmark slots come the *clones*, copies of past poses that
the multi-frame track updates need (:mod:`visla_edu.filters._tracks`), oldest first: clone ``k``
occupies ``6 + 3 n + 6 k .. 6 + 3 n + 6 k + 5`` (:meth:`ActiveSet.clone_columns`).
"""

import numpy as np

from visla_edu import ekf
from visla_edu.ekf import POSE_DIM, slot_columns

__all__ = ["ActiveSet"]


class ActiveSet:
    """Covariance of ``[pose; landmarks in the state]`` and the landmark of each slot.

    ``num_landmarks`` is ``M``, the dataset's number of landmark ids; ``pose_cov`` (6, 6) the first
    pose's covariance (``ValueError`` for another shape).

    Attributes
    ----------
    Sigma : ndarray, shape (D, D), D = 6 + 3 n (+ 6 per clone)
        The joint covariance. Read it; only this class's methods change it.
    active_ids, slot_of : ndarray of int, shapes (n,) and (M,)
        Landmark id in each slot, in slot order, and the slot of each landmark id, -1 when it is not
        in the state.
    clone_frames : list of int
        The frame of each clone, oldest first (empty unless the filter clones poses).
    """

    def __init__(self, num_landmarks, pose_cov):
        self.Sigma = np.array(pose_cov, dtype=float)
        if self.Sigma.shape != (POSE_DIM, POSE_DIM):
            raise ValueError(f"ActiveSet: pose_cov must have shape (6, 6), got {self.Sigma.shape}")
        self.active_ids = np.zeros(0, dtype=np.int64)
        self.slot_of = np.full(num_landmarks, -1)
        self.clone_frames = []

    @classmethod
    def dense(cls, num_landmarks, ids, pose_cov, placeholder_variance):
        """Every landmark of ``ids`` in the state from the start (the textbook filter), uncorrelated.

        ``placeholder_variance`` on their diagonal until :meth:`augment` fills their rows at the
        first observation (exact: a landmark never observed is uncorrelated with everything).
        """
        state = cls(num_landmarks, pose_cov)
        state.enter(ids)
        diagonal = np.arange(POSE_DIM, state.dim)
        state.Sigma[diagonal, diagonal] = placeholder_variance
        return state

    @property
    def dim(self):
        """``D = 6 + 3 n``, the dimension of the state."""
        return self.Sigma.shape[0]

    @property
    def pose_cov(self):
        """The pose block of the joint covariance, (6, 6) (a view)."""
        return self.Sigma[:POSE_DIM, :POSE_DIM]

    @property
    def landmark_end(self):
        """``6 + 3 n``: the first column after the landmark slots (where the clones start)."""
        return POSE_DIM + 3 * len(self.active_ids)

    def clone_columns(self, k):
        """State columns of clone ``k`` (0 = the oldest), shape (6,) (or (len(k), 6) for an array)."""
        return self.landmark_end + 6 * np.asarray(k, dtype=np.int64)[..., None] + np.arange(6)

    def columns(self, ids):
        """State columns of landmarks ``ids`` (all in the state), shape (k, 3)."""
        return slot_columns(self.slot_of[ids])

    def marginals(self, ids):
        """Marginal covariances of landmarks ``ids`` (all in the state), shape (k, 3, 3)."""
        cols = self.columns(ids)
        return self.Sigma[cols[:, :, None], cols[:, None, :]]

    def pose_cross(self, ids):
        """Cross-covariances ``Sigma_pose,landmark`` of landmarks ``ids``, shape (k, 6, 3)."""
        return np.swapaxes(self.Sigma[:POSE_DIM][:, self.columns(ids)], 0, 1)

    def propagate(self, form, world_T_imu, p_active, F, W):
        """The covariance prediction in place: ``form.predict`` (:mod:`visla_edu.filters._forms`) on :attr:`Sigma`."""
        form.predict(self.Sigma, world_T_imu, p_active, F, W)

    def update(self, Sigma_Ht, S, innovation):
        """:func:`visla_edu.ekf.gain_update` on :attr:`Sigma` (one EKF gain step): ``(delta, nis)``."""
        return ekf.gain_update(self.Sigma, Sigma_Ht, S, innovation)

    def correct(self, ids, z, noise_var, prediction, rows):
        """:func:`visla_edu.ekf.joint_correction` on the slots of landmarks ``ids``: ``(delta, nis)``."""
        return ekf.joint_correction(self.Sigma, self.slot_of[ids], z, noise_var, prediction, rows)

    def landmark_covs(self, form, ids, means):
        """Marginal covariances (k, 3, 3) of ``m - mu_m`` of landmarks ``ids``, means (k, 3): ``form.landmark_covs``."""
        return form.landmark_covs(self.Sigma, self.columns(ids), means)

    def enter(self, ids):
        """Append one slot per landmark of ``ids`` after the last landmark slot, before the clones.

        Its rows and columns are zero until :meth:`augment` or :meth:`augment_delayed` fills them.
        """
        ids = np.asarray(ids, dtype=np.int64)
        self.Sigma = _insert_zeros(self.Sigma, self.landmark_end, 3 * len(ids))
        self.slot_of[ids] = len(self.active_ids) + np.arange(len(ids))
        self.active_ids = np.concatenate([self.active_ids, ids])

    def augment(self, ids, G_pose, C_new):
        """Fill the rows of new landmarks placed from the current pose (:func:`visla_edu.ekf.initialize_landmarks`).

        ``Sigma_new,x = G_pose Sigma_pose,x`` for every state entry ``x``, and
        ``Sigma_new,new = G_pose Sigma_pp G_pose^T + C_new`` (``C_new`` block diagonal). ``ids``
        (k,) are already in the state (:meth:`enter`), never updated since; ``G_pose`` (k, 3, 6),
        zero for the uncorrelated textbook shortcut; ``C_new`` (k, 3, 3).
        """
        k = len(ids)
        cols = self.columns(ids).ravel()
        G = G_pose.reshape(3 * k, POSE_DIM)
        cross = G @ self.Sigma[:POSE_DIM]  # (3k, D)
        self.Sigma[cols] = cross
        self.Sigma[:, cols] = cross.T
        block = G @ self.pose_cov @ G.T
        block.reshape(k, 3, k, 3)[np.arange(k), :, np.arange(k), :] += C_new
        self.Sigma[np.ix_(cols, cols)] = block

    def augment_delayed(self, ids, cross, block):
        """Fill the rows of new landmarks whose covariance is already known (delayed initialisation).

        ``ids`` (k,) as in :meth:`augment`; ``cross`` (3k, D) is ``Sigma_new,x`` for every state
        entry ``x`` (the new rows' own columns are ignored), ``block`` (3k, 3k) ``Sigma_new,new``.
        """
        cols = self.columns(ids).ravel()
        self.Sigma[cols] = cross
        self.Sigma[:, cols] = cross.T
        self.Sigma[np.ix_(cols, cols)] = 0.5 * (block + block.T)

    def clone_pose(self, frame):
        """Append a clone of the current pose (rows and columns copying the pose's), for ``frame``."""
        D = self.dim
        rows = np.concatenate([np.arange(D), np.arange(POSE_DIM)])
        self.Sigma = self.Sigma[np.ix_(rows, rows)]
        self.clone_frames.append(int(frame))

    def drop_clone(self, k=0):
        """Marginalise clone ``k`` (delete its rows and columns)."""
        self.Sigma = _delete(self.Sigma, self.clone_columns(k))
        del self.clone_frames[k]

    def retire(self, ids):
        """Marginalise landmarks ``ids`` (k,) out of the state: delete their rows and columns; later slots move down.

        Returns their marginal covariances (k, 3, 3) at the moment they leave.
        """
        covs = self.marginals(ids)
        leaving = np.zeros(len(self.active_ids), dtype=bool)
        leaving[self.slot_of[ids]] = True
        keep_slots = np.nonzero(~leaving)[0]
        self.Sigma = _delete(self.Sigma, slot_columns(np.nonzero(leaving)[0]).ravel())
        self.slot_of[ids] = -1
        self.active_ids = self.active_ids[keep_slots]
        self.slot_of[self.active_ids] = np.arange(len(self.active_ids))
        return covs


def _insert_zeros(Sigma, at, count):
    """``Sigma`` with ``count`` zero rows and columns inserted before index ``at``."""
    D = Sigma.shape[0]
    out = np.zeros((D + count, D + count))
    if at == D:  # appending (no clones after the landmarks): one block copy
        out[:D, :D] = Sigma
        return out
    old = np.concatenate([np.arange(at), np.arange(at + count, D + count)])
    out[np.ix_(old, old)] = Sigma
    return out


def _delete(Sigma, cols):
    """``Sigma`` without the rows and columns ``cols``."""
    keep = np.setdiff1d(np.arange(Sigma.shape[0]), np.asarray(cols).ravel())
    return Sigma.take(keep, axis=0).take(keep, axis=1)
