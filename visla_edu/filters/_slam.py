"""Joint SLAM: the EKF over the pose and the landmarks, on the active set or dense.

By default only the *active set* (landmarks being tracked) is in the state: a landmark enters at
its first usable observation, which it consumes (covariance and cross-covariance through
``G_pose``, :meth:`~visla_edu.filters.ActiveSet.augment`), and is marginalised after its last one.
With ``dense=True`` it is the textbook filter over all landmarks from the start. Both give the
same trajectory: a landmark not yet observed is uncorrelated with everything (its rows are filled
at its first observation exactly as the active set appends them), and marginalising a Gaussian in
covariance form is deleting rows and columns. The maps differ: in the dense filter a retired
landmark keeps moving through its correlation with the pose, in the active set it keeps the
estimate it had when it left.

:class:`JointSlam` decides when to gate, update, enter, place again (``reinit_gated_landmarks``)
and retire; the error form (``FilterConfig.slam_error``, :mod:`visla_edu.filters._forms`) says
what the state's error means. With clones (``FilterConfig.msckf_window > 0``; not dense) a
landmark enters the state only when its track outlives the window (:mod:`visla_edu.filters._clones`).
"""

import numpy as np

from visla_edu import ekf
from visla_edu.codes import OBS_GATED, OBS_USED
from visla_edu.filters import _tracks
from visla_edu.filters._base import FilterBase
from visla_edu.filters._clones import CloneWindow
from visla_edu.filters._forms import ERROR_FORMS
from visla_edu.filters._state import ActiveSet

__all__ = ["JointSlam", "DENSE_PLACEHOLDER_VARIANCE", "MAX_DENSE_BYTES"]

#: Variance on the diagonal of a landmark the dense filter has not observed yet (its mean is
#: not set either); replaced by the real prior at the first observation.
DENSE_PLACEHOLDER_VARIANCE = 1e6

#: The dense reference refuses covariances larger than this (bytes); use a landmark stride.
MAX_DENSE_BYTES = 4 * 2**30


class JointSlam(CloneWindow, FilterBase):
    """Joint EKF over ``[pose; landmarks]``, active set by default, textbook form if ``dense``.

    ``dataset``, ``camera``, ``config`` as :class:`~visla_edu.filters.FilterBase`; ``dense`` keeps
    every (strided) landmark in the state from the first frame (``ValueError`` if its covariance
    would exceed :data:`MAX_DENSE_BYTES`).

    Attributes
    ----------
    state : ActiveSet
        The joint covariance (in the error form's coordinates) and each landmark's slot in it.
    form : RightForm or InvariantForm
        The error form (``config.slam_error``).
    updates : ndarray of int, shape (M,)
        Observations of each landmark used by an update since it entered the state.
    window : int
        Clones kept (``config.msckf_window``; 0 when dense): 0 is the joint EKF without clones.
    clone_T : ndarray, shape (n_clones, 4, 4)
        The clones' means, oldest first (their frames: ``state.clone_frames``).
    track_counts : dict of str -> int
        Multi-frame track updates so far: ``tracks_used``, ``tracks_gated`` (refused whole),
        ``tracks_short`` (fewer than :data:`~visla_edu.filters._tracks.MIN_TRACK_OBSERVATIONS`
        observations in the window), ``tracks_failed`` (no point in front of every camera),
        ``entered`` (into the state), and the tracks' ``observations_used``, ``observations_gated``.
    """

    def __init__(self, dataset, camera, config, dense=False):
        super().__init__(dataset, camera, config)
        self.dense = dense
        self.window = 0 if dense else config.msckf_window
        self.buffer = _tracks.TrackBuffer()
        self.clone_T = np.zeros((0, 4, 4))
        self.track_counts = dict.fromkeys(("tracks_used", "tracks_gated", "tracks_short", "tracks_failed", "entered",
                                           "observations_used", "observations_gated"), 0)
        self.form = ERROR_FORMS[config.slam_error]
        self.updates = np.zeros(dataset.num_landmarks, dtype=np.int64)
        pose_cov = config.initial_pose_sigma**2 * np.eye(6)
        M = dataset.num_landmarks
        if dense:
            ids = np.arange(0, M, config.landmark_stride)
            D = ekf.POSE_DIM + 3 * len(ids)
            if D * D * 8 > MAX_DENSE_BYTES:
                raise ValueError(
                    f"dense SLAM on {dataset.name}: a {D}x{D} covariance needs {D * D * 8 / 2**30:.1f} GiB "
                    f"(limit {MAX_DENSE_BYTES / 2**30:.0f} GiB); use landmark_stride or the active set")
            self.state = ActiveSet.dense(M, ids, pose_cov, DENSE_PLACEHOLDER_VARIANCE)
        else:
            self.state = ActiveSet(M, pose_cov)

    @property
    def pose_cov(self):
        """Covariance of the right perturbation ``[v; w]`` of the pose, (6, 6)."""
        return self.form.pose_cov(self.state.pose_cov, self.world_T_imu)

    def _predict_covariance(self, F, W):
        self.state.propagate(self.form, self.world_T_imu, self.landmarks[self.state.active_ids], F, W)

    def _update(self, ids, z, status, z_pred):
        if self.window:
            return self._update_with_clones(ids, z, status, z_pred)
        if not self.dense:
            self._retire_finished()
        usable = self._usable(ids, z, status)
        known = self._known(ids, usable)
        prediction = self._gate_known(ids, z, status, z_pred, known)
        use = status == OBS_USED
        again = self._to_place_again(ids, status)
        nis = np.nan
        if np.any(use):
            keep = use[known]  # the gate's predictions of the observations in use
            nis = self._joint_update(ids[use], z[use], tuple(a[keep] for a in prediction))
            self.updates[ids[use]] += 1
        self._forget(ids[again])
        new, G_pose, C_new = self._new_landmarks(ids, z, status, (usable & ~known) | again)
        if np.any(new):
            self._enter(ids[new], G_pose, C_new)
        return nis, 4 * int(use.sum())

    def _to_place_again(self, ids, status):
        """Gated observations of landmarks no update has used yet (``reinit_gated_landmarks``)."""
        if not self.config.reinit_gated_landmarks:
            return np.zeros(len(ids), dtype=bool)
        return (status == OBS_GATED) & (self.updates[ids] == 0)

    def _forget(self, lm):
        """Drop landmarks ``lm`` from the state without keeping them (they are placed again)."""
        if len(lm) == 0:
            return
        if not self.dense:
            self.state.retire(lm)
        self.landmarks[lm] = np.nan

    def _retire_finished(self):
        """Marginalise the landmarks whose track ended before this frame; keep their covariances."""
        active = self.state.active_ids
        leaving = active[self.last_frame[active] < self.t]
        if len(leaving):
            self.landmark_cov[leaving] = self._landmark_covs(leaving)
            self.state.retire(leaving)

    def _landmark_covs(self, lm):
        """Marginal covariances of ``m - mu_m`` of landmarks ``lm`` in the state, (k, 3, 3)."""
        return self.state.landmark_covs(self.form, lm, self.landmarks[lm])

    def _gate_known(self, ids, z, status, z_pred, known):
        """Predict and gate the observations of landmarks in the state (``known`` mask); fills ``z_pred``, ``status``.

        Returns ``(z_pred (k, 4), J_landmark (k, 4, 3), J_pose (k, 4, 6))``, ``J_pose`` in the error
        form's coordinates; None when there are none.
        """
        if not np.any(known):
            return None
        lm = ids[known]
        pred, J_landmark, J_pose = self.camera.predict_with_jacobians(self.world_T_imu, self.landmarks[lm])
        J_pose = self.form.pose_jacobian(J_landmark, J_pose)
        z_pred[known] = pred
        S = ekf.innovation_covariances(J_pose, J_landmark, self.state.pose_cov, self.state.pose_cross(lm),
                                       self.state.marginals(lm), self.noise_var)
        inside, _ = self._gate(S, z[known] - pred, pred)
        self._mark_gated(status, known, inside)
        return pred, J_landmark, J_pose

    def _joint_update(self, lm, z, prediction):
        """The joint EKF update with the observations of landmarks ``lm``; returns the NIS."""
        try:
            delta, nis = self.state.correct(lm, z, self.noise_var, prediction, self.camera.stereo_rows)
        except np.linalg.LinAlgError as err:
            raise self._diverged(err, f" ({len(lm)} observations)") from err
        self._retract(delta)
        return nis

    def _retract(self, delta):
        """Apply a correction of the whole state: pose, landmarks (in slot order) and clones."""
        active = self.state.active_ids
        end = self.state.landmark_end
        self.world_T_imu, self.landmarks[active] = self.form.retract(self.world_T_imu, self.landmarks[active],
                                                                     delta[:end])
        if len(self.clone_T):
            self.clone_T = self.form.retract_clone(self.clone_T, delta[end:].reshape(-1, 6))

    def _enter(self, new_ids, G_pose, C_new):
        """New landmarks into the state (slots appended unless dense), correlated unless the shortcut is on."""
        if not self.dense:
            self.state.enter(new_ids)
        self.updates[new_ids] = 0
        G = self.form.landmark_sensitivity(G_pose)
        if not self.config.landmark_cross_covariance:  # the textbook shortcut, for comparison
            G = np.zeros_like(G)
        self.state.augment(new_ids, G, C_new)

    def _active(self):
        ids = self.state.active_ids
        active = ids[np.isfinite(self.landmarks[ids, 0]) & (self.last_frame[ids] >= self.t)]
        return active, self._landmark_covs(active)

    def landmark_estimates(self):
        """Landmark means (M, 3) and marginal covariances (M, 3, 3), NaN if never initialised.

        Landmarks still in the state (dense: every initialised one) report their current estimate.
        """
        cov = self.landmark_cov.copy()
        ids = self.state.active_ids
        in_state = ids[np.isfinite(self.landmarks[ids, 0])]
        cov[in_state] = self._landmark_covs(in_state)
        return self.landmarks.copy(), cov
