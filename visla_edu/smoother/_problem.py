"""The least-squares problem a smoother solves: observations, landmarks, pose variables, priors.

A :class:`Problem` covers the frames ``first_frame .. last_frame``; the poses of ``first_var .. last_frame`` are
variables (block rows ``0 .. n - 1`` of the reduced system), the earlier ones are held. The batch smoother has
``first_frame = 0, first_var = 1`` (the first pose defines the world frame); the sliding window has its window as
variables and, in ``"fix"`` mode, older frames held. Observations are stored landmark-major (by landmark, then
frame), so each landmark's variable frames form one run of block rows ``span_lo .. span_hi``; ``slot`` places each
observation in that run (frames of the run without an observation get zero slots). Observations and landmarks
leave the problem by clearing ``active`` / ``landmark_active``; the structure stays.
"""

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from visla_edu.codes import OBS_IGNORED, OBS_NO_DEPTH, OBS_USED
from visla_edu.dataset import repeated_frames, stale_copies

__all__ = ["PosePrior", "Problem", "build_problem", "observation_status", "far_landmarks", "triangulate_landmarks",
           "rig_camera"]


@dataclass
class PosePrior:
    """Prior on pose ``frame``, whitened residual ``U log(mean^{-1} T)``, ``U = sqrt_information`` (6, 6)."""

    frame: int
    mean: np.ndarray
    sqrt_information: np.ndarray


@dataclass
class Problem:
    """Data and structure of one least-squares problem (module docstring): N observations, L local landmarks.

    Attributes
    ----------
    Ks, cam_T_imu, sigma_pixel, loss, loss_scale, min_depth, min_disparity
        Stereo matrix (4, 4) and ``inv(imu_T_cam)`` (4, 4); the rest from :class:`~visla_edu.smoother.SmootherConfig`.
    motion_from, step_inv, motion_sqrt_information : int, ndarray (K, 4, 4), ndarray (K, 6)
        The motion factors: the steps ``motion_from .. last_frame - 1``, their ``exp(-tau_t u_t^)`` and the diagonals
        of ``W_t^{-1/2}``.
    obs_frame, obs_landmark, obs_source, active : ndarray, shape (N,)
        Each observation's frame, local landmark (``0 .. L-1``), index in the dataset's arrays, whether used (bool);
        its pixels ``obs_z`` (N, 4).
    landmark_ids, landmark_active, landmark_start : ndarray, shape (L,), (L,), (L + 1,)
        Dataset id of each local landmark; whether it is in the problem; landmark ``j`` owns observations
        ``landmark_start[j] : landmark_start[j + 1]``.
    landmark_prior : (ndarray, ndarray, ndarray) or None
        Per landmark ``m^T Lambda m - 2 m^T eta + c``: ``Lambda`` (L, 3, 3), ``eta`` (L, 3), ``c`` (L,); observations
        from held poses folded in (their weighted squared errors, linearised, so the prior's cost is never negative).
    slot, span_lo, span_hi, span_start : ndarray of int, shape (N,), (L,), (L,), (L,)
        Row of each observation in the Schur correction rows (-1 at held frames); each landmark's run of block rows
        and its first slot (``span_hi < span_lo``: none).
    frame_sum : scipy.sparse.csr_matrix, shape (n, N)
        Sums per-observation pose terms into their block rows.
    dropped_in_steps, fsu_b : int, float
        Landmarks the solver dropped because a step would bring them behind a camera; a landmark at depth ``d`` has
        disparity ``fsu b / d`` (left pixels).
    """

    Ks: np.ndarray
    cam_T_imu: np.ndarray
    sigma_pixel: float
    loss: str
    loss_scale: float
    min_depth: float
    min_disparity: float
    first_frame: int
    first_var: int
    last_frame: int
    motion_from: int
    step_inv: np.ndarray
    motion_sqrt_information: np.ndarray
    obs_frame: np.ndarray
    obs_landmark: np.ndarray
    obs_z: np.ndarray
    obs_source: np.ndarray
    landmark_ids: np.ndarray
    landmark_start: np.ndarray
    active: np.ndarray
    landmark_active: np.ndarray
    prior: PosePrior = None
    landmark_prior: tuple = None
    slot: np.ndarray = None
    span_lo: np.ndarray = None
    span_hi: np.ndarray = None
    span_start: np.ndarray = None
    num_slots: int = 0
    frame_sum: object = None
    dropped_in_steps: int = 0
    fsu_b: float = None

    @property
    def num_vars(self):
        """n, the number of pose variables."""
        return self.last_frame - self.first_var + 1

    @property
    def num_landmarks(self):
        """L, the number of local landmarks (active or not)."""
        return len(self.landmark_ids)

    def obs_var(self):
        """Block row of each observation's pose, -1 at held frames, shape (N,)."""
        var = self.obs_frame - self.first_var
        return np.where(var >= 0, var, -1)


def build_problem(obs_frame, obs_landmark_ids, obs_z, obs_source, *, camera, config, frames, motion,
                  prior=None, landmark_prior=None):
    """Assemble a :class:`Problem` and its structure from observations in any order.

    Per observation: ``obs_frame``, ``obs_landmark_ids`` (dataset ids, each pair once), ``obs_z`` (4,), ``obs_source``;
    ``frames = (first_frame, first_var, last_frame)``, ``motion = (motion_from, step_inv, motion_sqrt_information)``;
    ``landmark_prior`` indexed by dataset id (``Lambda`` (M, 3, 3), ``eta`` (M, 3), ``c`` (M,)).
    """
    obs_frame, obs_landmark_ids = np.asarray(obs_frame, np.int64), np.asarray(obs_landmark_ids, np.int64)
    order = np.lexsort((obs_frame, obs_landmark_ids))
    landmark_ids, obs_landmark = np.unique(obs_landmark_ids[order], return_inverse=True)
    first_frame, first_var, last_frame = frames
    motion_from, step_inv, sqrt_info = motion
    problem = Problem(
        Ks=camera.Ks, cam_T_imu=camera.cam_T_imu, fsu_b=camera.fsu_b, sigma_pixel=float(config.sigma_pixel),
        loss=config.loss, loss_scale=float(config.loss_scale), min_depth=float(config.min_depth),
        min_disparity=float(config.min_disparity), first_frame=first_frame, first_var=first_var,
        last_frame=last_frame, motion_from=motion_from, step_inv=step_inv, motion_sqrt_information=sqrt_info,
        obs_frame=obs_frame[order], obs_landmark=obs_landmark, obs_z=np.asarray(obs_z, dtype=float)[order],
        obs_source=np.asarray(obs_source)[order], landmark_ids=landmark_ids,
        landmark_start=np.searchsorted(obs_landmark, np.arange(len(landmark_ids) + 1)),
        active=np.ones(len(order), dtype=bool), landmark_active=np.ones(len(landmark_ids), dtype=bool), prior=prior,
    )
    if landmark_prior is not None:
        problem.landmark_prior = tuple(part[landmark_ids] for part in landmark_prior)
    _build_structure(problem)
    return problem


def _build_structure(problem):
    """Slots of the Schur correction rows and the frame-sum matrix (see :class:`Problem`)."""
    var = problem.obs_var()
    first, last = problem.landmark_start[:-1], problem.landmark_start[1:] - 1
    lo = np.maximum(problem.obs_frame[first] - problem.first_var, 0)
    hi = var[last]  # -1 when the landmark's last observation is at a held frame
    count = np.maximum(hi - lo + 1, 0)
    problem.span_lo, problem.span_hi = lo, lo + count - 1
    problem.span_start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    problem.num_slots = int(count.sum())
    on_var = var >= 0
    problem.slot = np.where(on_var, problem.span_start[problem.obs_landmark] + var - lo[problem.obs_landmark], -1)
    cols = np.flatnonzero(on_var)
    problem.frame_sum = sparse.csr_matrix((np.ones(len(cols)), (var[cols], cols)),
                                          shape=(problem.num_vars, len(var)))


def observation_status(dataset, config, frames=None):
    """Which dataset observations a smoother may use: an ``OBS_*`` code each (:mod:`visla_edu.codes`), (N,) int8.

    ``OBS_NO_DEPTH`` for a non-positive disparity, ``OBS_IGNORED`` in a repeated frame (``config.skip_repeated_frames``)
    and for a stale copy (``config.skip_stale_copies``, :func:`visla_edu.dataset.stale_copies`), else ``OBS_USED``.
    """
    frames = dataset.observation_frames() if frames is None else frames
    status = np.full(dataset.num_observations, OBS_USED, dtype=np.int8)
    status[dataset.disparity() <= 0] = OBS_NO_DEPTH
    if config.skip_repeated_frames:
        status[np.isin(frames, repeated_frames(dataset))] = OBS_IGNORED
    if config.skip_stale_copies:
        status[stale_copies(dataset)] = OBS_IGNORED
    return status


def far_landmarks(dataset, usable, min_disparity):
    """Landmarks with ``usable`` (N,) observations, all with ``uL - uR < min_disparity`` px: (M,) bool."""
    disparity = np.where(usable, dataset.disparity(), -np.inf)
    best = np.full(dataset.num_landmarks, -np.inf)
    np.maximum.at(best, dataset.obs_ids, disparity)
    return np.isfinite(best) & (best < min_disparity)


def triangulate_landmarks(dataset, camera, world_T_imu, usable, landmarks=None):
    """Initial landmark positions (M, 3): the given ones where finite, else from the best observation.

    ``landmarks`` (M, 3), optional: e.g. the EKF's map, NaN where it never initialised one (another shape: ValueError).
    The best observation is a landmark's ``usable`` (N,) one with the largest disparity (the best-conditioned depth),
    triangulated at that frame's pose ``world_T_imu`` (T, 4, 4). NaN where neither exists.
    """
    M = dataset.num_landmarks
    out = np.full((M, 3), np.nan) if landmarks is None else np.array(landmarks, dtype=float, copy=True)
    if out.shape != (M, 3):
        raise ValueError(f"initial landmarks must have shape ({M}, 3) for {dataset.name}, got {out.shape}")
    disparity = np.where(usable, dataset.disparity(), -np.inf)
    order = np.lexsort((-disparity, dataset.obs_ids))  # per landmark, largest disparity first
    first = order[np.r_[True, dataset.obs_ids[order][1:] != dataset.obs_ids[order][:-1]]]
    first = first[np.isfinite(disparity[first])]
    need = first[~np.all(np.isfinite(out[dataset.obs_ids[first]]), axis=1)]
    if len(need):
        p_cam = camera.triangulate(dataset.obs_z[need])
        world_T_cam = world_T_imu[dataset.observation_frames()[need]] @ camera.imu_T_cam
        out[dataset.obs_ids[need]] = np.einsum("nij,nj->ni", world_T_cam[:, :3, :3], p_cam) + world_T_cam[:, :3, 3]
    return out


def rig_camera(dataset, imu_T_cam=None):
    """:meth:`~visla_edu.dataset.Dataset.stereo_camera`: the rig, ``imu_T_cam`` (4, 4) replaced if given."""
    return dataset.stereo_camera(imu_T_cam)
