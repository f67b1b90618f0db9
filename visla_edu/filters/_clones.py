"""The joint filter's clone window: when its tracks are used, and how their rows reach the state.

:class:`CloneWindow` is the part of :class:`visla_edu.filters.JointSlam` that runs when
``msckf_window > 0``: each frame it clones the pose, updates with the landmarks in the state,
buffers the other observations, and uses the tracks that ended or outlived the window (the math
is :mod:`visla_edu.filters._tracks`):

* a track that ended (its landmark is not seen at this frame) gives its null-space rows;
* a track seen for the whole window enters the state as a landmark (delayed entry) while there
  is room (``max_slam_landmarks``), else it gives its null-space rows and starts again.

All the rows of a frame make one EKF update on the pose and the clones (through their
correlations, on everything), then the oldest clones beyond the window are marginalised.
"""

import numpy as np

from visla_edu import ekf
from visla_edu.codes import OBS_DELAYED, OBS_USED
from visla_edu.filters import _tracks

__all__ = ["CloneWindow"]


class CloneWindow:
    """Mixin of :class:`visla_edu.filters.JointSlam` for ``window > 0`` (see the module docstring).

    Uses the host's ``state``, ``form``, ``camera``, ``buffer``, ``clone_T``, ``window``,
    ``track_counts``, ``noise_var``, ``config`` and its landmark arrays.
    """

    def _update_with_clones(self, ids, z, status, z_pred):
        """One frame with clones: returns ``(nis, dof)`` of its updates.

        The tracks are used first (their rows do not involve this frame's observations of the
        landmarks in the state), then those observations update the state as without clones; a
        landmark that enters now is not updated again with the observation it entered with.
        """
        self._retire_finished()
        self.state.clone_pose(self.t)
        self.clone_T = np.concatenate([self.clone_T, self.world_T_imu[None]])
        usable = self._usable(ids, z, status)
        known = usable & (self.state.slot_of[ids] >= 0)
        pending = usable & ~known
        self.buffer.add(ids[pending], z[pending], self.t)
        status[pending] = OBS_DELAYED
        nis, dof = self._use_tracks(ids[usable | self._frame_stale])  # a stale copy does not end its track
        prediction = self._gate_known(ids, z, status, z_pred, known)
        use = status == OBS_USED
        if np.any(use):
            nis += self._joint_update(ids[use], z[use], tuple(a[use[known]] for a in prediction))
            self.updates[ids[use]] += 1
            dof += 4 * int(use.sum())
        self._trim_window()
        return (nis if dof else np.nan), dof

    def _trim_window(self):
        """Marginalise the clones beyond the window and forget the observations made from them."""
        while len(self.state.clone_frames) > self.window:
            self.state.drop_clone(0)
            self.clone_T = self.clone_T[1:]
        self.buffer.forget_before(self.state.clone_frames[0])

    def _use_tracks(self, seen):
        """Use the tracks that ended or outlived the window; ``(nis, dof)`` of their update."""
        buffered = self.buffer.landmarks()
        if len(buffered) == 0:
            return 0.0, 0
        observed = np.isin(buffered, seen) & (self.t < self.dataset.num_frames - 1)  # the last frame ends them all
        full = len(self.state.clone_frames) > self.window
        oldest = observed & full & (self.buffer.first_frame(buffered) <= self.state.clone_frames[0])
        room = max(0, self.config.max_slam_landmarks - len(self.state.active_ids))
        long_ids = buffered[oldest]
        tracks = self._tracks_of(np.concatenate([long_ids[:room], buffered[~observed], long_ids[room:]]))
        if tracks is None:
            return 0.0, 0
        entering = np.isin(tracks[0], long_ids[:room])
        rows = [self._enter_from_track(*_select(tracks, [b])) for b in np.nonzero(entering)[0]]
        if not np.all(entering):
            rows.append(self._track_rows(*_select(tracks, np.nonzero(~entering)[0])))
        rows = [r for r in rows if r is not None]
        if not rows:
            return 0.0, 0
        return self._update_rows(np.vstack([h for h, _ in rows]), np.concatenate([r for _, r in rows]))

    def _update_columns(self):
        """State columns the track rows act on: the pose, then every clone, shape (6 + 6 n_clones,)."""
        clones = self.state.clone_columns(np.arange(len(self.state.clone_frames))).ravel()
        return np.concatenate([np.arange(ekf.POSE_DIM), clones])

    def _tracks_of(self, lms):
        """Pop the observations of ``lms``; the usable tracks as ``(lms, clone_index, z, owner, p_world)``, or None.

        Usable: at least :data:`~visla_edu.filters._tracks.MIN_TRACK_OBSERVATIONS` observations and
        a point in front of every camera (sorted by track); a shorter track with such a point is
        only put on the map.
        """
        if len(lms) == 0:
            return None
        frames, z, owner = self.buffer.pop(lms)
        clone_index = np.searchsorted(self.state.clone_frames, frames)
        p_world, ok = _tracks.triangulate_tracks(self.camera, self.clone_T[clone_index], z, owner, len(lms),
                                                 np.sqrt(self.noise_var))
        enough = np.bincount(owner, minlength=len(lms)) >= _tracks.MIN_TRACK_OBSERVATIONS
        short = ~enough & ok  # too short to update anything, but placed on the map
        if np.any(short):
            keep, remap = short[owner], np.cumsum(short) - 1
            _, _, H_point = _tracks.track_systems(self.camera, self.form, self.clone_T[clone_index[keep]], z[keep],
                                                  remap[owner[keep]], p_world[short])
            information = _tracks.segment_sum(np.swapaxes(H_point, 1, 2) @ H_point, remap[owner[keep]], int(short.sum()))
            self.landmarks[lms[short]] = p_world[short]
            self.landmark_cov[lms[short]] = self.noise_var * np.linalg.pinv(information, hermitian=True)
        self.track_counts["tracks_short"] += int(np.sum(~enough))
        self.track_counts["tracks_failed"] += int(np.sum(enough & ~ok))
        use = enough & ok
        if not np.any(use):
            return None
        keep, remap = use[owner], np.cumsum(use) - 1
        return lms[use], clone_index[keep], z[keep], remap[owner[keep]], p_world[use]

    def _track_rows(self, lms, clone_index, z, owner, p_world):
        """Null-space rows ``(H (m, 6 + 6 n_clones), r (m,))`` of the tracks (:meth:`_tracks_of`) that pass the gate."""
        r, H_clone, H_point = _tracks.track_systems(self.camera, self.form, self.clone_T[clone_index], z, owner,
                                                    p_world)
        counts = np.bincount(owner)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        H_rows, r_rows = [], []
        for n in np.unique(counts):
            group = np.nonzero(counts == n)[0]
            obs = (starts[group][:, None] + np.arange(n)).ravel()
            H, rr = self._group_rows(r[obs], H_clone[obs], H_point[obs], clone_index[obs], lms[group], p_world[group],
                                     len(group), n)
            H_rows += H
            r_rows += rr
        return (np.vstack(H_rows), np.concatenate(r_rows)) if H_rows else None

    def _group_rows(self, r, H_clone, H_point, clone_index, lms, p_world, B, n):
        """Gate ``B`` tracks of ``n`` observations each; lists of their rows over the update columns."""
        Q2T, _, R1 = _tracks.project_out_point(r.reshape(B, n, 4), H_point.reshape(B, n, 4, 3))
        r_o = np.einsum("bmi,bi->bm", Q2T, r.reshape(B, 4 * n))
        H_o = np.einsum("bmjk,bjkl->bmjl", Q2T.reshape(B, 4 * n - 3, n, 4), H_clone.reshape(B, n, 4, 6))
        cols = self.state.clone_columns(clone_index.reshape(B, n)).reshape(B, 6 * n)
        Sigma_sub = self.state.Sigma[cols[:, :, None], cols[:, None, :]]
        inside, _ = _tracks.gate_tracks(r_o, H_o.reshape(B, 4 * n - 3, 6 * n), Sigma_sub, self.noise_var,
                                        self.config.track_gate_probability)
        self._count_tracks(inside, n)
        covs = self.noise_var * np.linalg.inv(np.swapaxes(R1, 1, 2) @ R1)
        self.landmarks[lms], self.landmark_cov[lms] = p_world, covs
        keep = np.nonzero(inside)[0]
        m, width = 4 * n - 3, 6 + 6 * len(self.state.clone_frames)
        H = np.zeros((len(keep), width, m))  # transposed, so that the clone columns index one axis
        cols = (6 + 6 * clone_index.reshape(B, n)[keep][:, :, None] + np.arange(6)).reshape(len(keep), 6 * n)
        H[np.arange(len(keep))[:, None], cols] = np.swapaxes(H_o[keep].reshape(len(keep), m, 6 * n), 1, 2)
        return list(np.swapaxes(H, 1, 2)), list(r_o[keep])

    def _count_tracks(self, inside, n):
        """Add ``inside`` (a mask over tracks of ``n`` observations each) to :attr:`track_counts`."""
        used, gated = int(inside.sum()), int((~inside).sum())
        self.track_counts["tracks_used"] += used
        self.track_counts["tracks_gated"] += gated
        self.track_counts["observations_used"] += n * used
        self.track_counts["observations_gated"] += n * gated

    def _enter_from_track(self, lms, clone_index, z, owner, p_world):
        """Delayed entry of the one landmark of ``lms`` from its track; its null-space rows, or None (refused)."""
        lm = int(lms[0])
        r, H_clone, H_point = _tracks.track_systems(self.camera, self.form, self.clone_T[clone_index], z, owner,
                                                    p_world)
        n = len(z)
        H = np.zeros((4 * n, 6 + 6 * len(self.state.clone_frames)))
        H[:, :6] = self.form.delayed_pose_jacobian(H_point, p_world[owner]).reshape(4 * n, 6)
        for j in range(n):
            H[4 * j:4 * j + 4, 6 + 6 * clone_index[j]: 12 + 6 * clone_index[j]] = H_clone[j]
        Q2T, Q1T, R1 = _tracks.project_out_point(r[None], H_point[None])
        r_o, H_o = Q2T[0] @ r.ravel(), Q2T[0] @ H
        U = self._update_columns()
        inside, _ = _tracks.gate_tracks(r_o[None], H_o[None], self.state.Sigma[np.ix_(U, U)][None], self.noise_var,
                                        self.config.track_gate_probability)
        self._count_tracks(inside, n)
        if not inside[0]:
            return None
        H1 = Q1T[0] @ H
        H1_Sigma = H1 @ self.state.Sigma[U]  # (3, D)
        _, cross, block = _tracks.delayed_entry(Q1T[0] @ r.ravel(), R1[0], H1_Sigma, H1_Sigma[:, U] @ H1.T,
                                                   self.noise_var)
        at = self.state.landmark_end
        self.state.enter(np.array([lm]))
        self.state.augment_delayed(np.array([lm]), np.insert(cross, [at] * 3, 0.0, axis=1), block)
        self.landmarks[lm] = p_world[0]  # the robust fit; its Q1 rows are ~0 at the inliers
        self.updates[lm] = 0
        self.track_counts["entered"] += 1
        return H_o, r_o

    def _update_rows(self, H, r):
        """One EKF update with the stacked track rows (over :meth:`_update_columns`); ``(nis, dof)`` of all the rows.

        More rows than columns are compressed orthonormally (``H = Q R``, the same update); the part
        of ``r`` outside ``Q``'s columns, where ``S`` is ``noise_var I``, is added to the NIS.
        """
        rows, outside = len(r), 0.0
        if len(r) > H.shape[1]:
            Q, H = np.linalg.qr(H)
            compressed = Q.T @ r
            outside = max(0.0, float(r @ r - compressed @ compressed)) / self.noise_var
            r = compressed
        U = self._update_columns()
        Sigma_Ht = self.state.Sigma[:, U] @ H.T
        S = H @ Sigma_Ht[U] + self.noise_var * np.eye(len(r))
        try:
            delta, nis = self.state.update(Sigma_Ht, S, r)
        except np.linalg.LinAlgError as err:
            raise self._diverged(err, f" (track update, {len(r)} rows)") from err
        self._retract(delta)
        return nis + outside, rows


def _select(tracks, picked):
    """The tracks ``picked`` (indices) of a :meth:`CloneWindow._tracks_of` tuple, renumbered."""
    lms, clone_index, z, owner, p_world = tracks
    picked = np.asarray(picked, dtype=np.int64)
    keep = np.isin(owner, picked)
    renumber = np.full(len(lms), -1)
    renumber[picked] = np.arange(len(picked))
    return lms[picked], clone_index[keep], z[keep], renumber[owner[keep]], p_world[picked]
