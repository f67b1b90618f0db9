"""Track-reprojection evidence for the extrinsic axes and the IMU lag (works on sparse drives).

Each landmark's first observation with disparity above :data:`MIN_DISPARITY` (its anchor), ``p_a``
in the left camera at frame ``a``, is paired with its observations 1 to :data:`MAX_GAP` frames
later (:func:`track_pairs`). The IMU's dead-reckoned motion with a candidate lag, through a
candidate ``imu_T_cam = C X``, predicts the point at frame ``b``::

    q = cam_T_imu  inv(S_a S_(a+1) ... S_(b-1))  imu_T_cam  p_a,    S_t = exp(tau_t u[t + lag]^)

A candidate's score is the median over all pairs of the left-image error ``|(u, v)(q) - (uL, vL)_b|``.
It is chosen only when every competitor is worse with :data:`CONFIDENCE` confidence: the lower
``1 - CONFIDENCE`` quantile of its median minus the best one's, in a seeded bootstrap
(:mod:`._bootstrap`) over blocks of :data:`BLOCK` anchor frames, is above zero; otherwise the
verdict is "not enough evidence" and the caller keeps its default.
"""

from dataclasses import asdict, dataclass

import numpy as np

from visla_edu import lie
from visla_edu.dataset import stale_copies
from visla_edu.diagnostics._bootstrap import cluster_resamples, resampled_medians
from visla_edu.diagnostics._vo import LAGS, corrections_of, imu_step_twists

__all__ = ["TrackChoice", "TrackEvidence", "TrackScorer", "track_pairs", "reprojection_errors", "MIN_DISPARITY",
           "MAX_GAP", "RESAMPLES", "BLOCK", "CONFIDENCE", "MIN_LANDMARKS", "MIN_GROUPS"]

#: The anchor observation needs a disparity above this (px) for a usable depth.
MIN_DISPARITY = 2.0
#: Later observations up to this many frames after the anchor are scored.
MAX_GAP = 5
#: Bootstrap resamples.
RESAMPLES = 300
#: Landmarks anchored within a block of this many frames are resampled together.
BLOCK = 2 * MAX_GAP
#: Seed of the bootstrap: the same data give the same verdicts.
SEED = 0
#: A candidate must beat every competitor with this confidence.
CONFIDENCE = 0.95
#: Fewer landmarks, or blocks of anchor frames, with scored pairs than this: not enough
#: evidence, no bootstrap.
MIN_LANDMARKS = 20
MIN_GROUPS = 10
#: Error given to a point predicted behind the camera (px): always in the upper tail.
_BEHIND = 1e6
NOT_ENOUGH = "not enough evidence"


@dataclass
class TrackChoice:
    """The verdict on one setting (the extrinsic correction or the lag).

    Attributes
    ----------
    chosen, best : str or int or None
        The candidate chosen (None without enough evidence), and the one with the smallest median
        error (None without pairs).
    verdict : str
        ``"chosen"`` or ``"not enough evidence: ..."`` with the reason.
    margins : dict
        Competitor (its name, or its lag as ``"+1"``) -> ``[difference, lower]``: its median minus
        the best one's (px) and the lower ``1 - CONFIDENCE`` bootstrap quantile of it.
    """

    chosen: object
    best: object
    verdict: str
    margins: dict


@dataclass
class TrackEvidence:
    """Track-reprojection scores of every (correction, lag) candidate and the verdicts.

    Attributes
    ----------
    lags, scores : list of int, dict
        Correction name -> median left-image error (px) per lag of ``lags`` (None without pairs).
    pairs, landmarks, groups : int
        Scored pairs, their landmarks, and the resampling groups.
    resamples : int
        Bootstrap resamples (0 when there was not enough evidence to run it).
    correction, lag : TrackChoice
        Among the corrections (each at its best lag); among the lags of the one the filter uses.
    """

    lags: list
    scores: dict
    pairs: int
    landmarks: int
    groups: int
    resamples: int
    correction: TrackChoice
    lag: TrackChoice = None

    def to_dict(self):
        """JSON-safe dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d):
        """Inverse of :meth:`to_dict`."""
        lag = None if d.get("lag") is None else TrackChoice(**d["lag"])
        return cls(**{**d, "correction": TrackChoice(**d["correction"]), "lag": lag})


def track_pairs(dataset):
    """Anchor and later observations of the scored pairs (stale copies and non-positive disparities left out).

    Returns
    -------
    anchor, later, gap : ndarray of int, shape (P,)
        Indices into the dataset's observations (``obs_ids``, ``obs_z``); frames from the anchor to
        the later observation, ``1..MAX_GAP``.
    """
    frames = dataset.observation_frames()
    order = np.lexsort((frames, dataset.obs_ids))  # landmark by landmark, in time
    ids_sorted, frames_sorted = dataset.obs_ids[order], frames[order]
    same = np.zeros(len(order), dtype=bool)  # the same landmark as the observation before
    same[1:] = ids_sorted[1:] == ids_sorted[:-1]
    stale = stale_copies(dataset)[order]
    disparity = dataset.disparity()[order]
    can_anchor = disparity > MIN_DISPARITY
    # the first anchor-able observation of each landmark (big: none)
    track = np.cumsum(~same) - 1
    big = len(order)
    first_anchor = np.full(int(track[-1]) + 1 if big else 0, big)
    np.minimum.at(first_anchor, track[can_anchor], np.flatnonzero(can_anchor))
    anchor_pos = first_anchor[track]
    gap = frames_sorted - frames_sorted[np.minimum(anchor_pos, big - 1)] if big else np.zeros(0, np.int64)
    keep = (anchor_pos < big) & (gap >= 1) & (gap <= MAX_GAP) & ~stale & (disparity > 0)
    return order[anchor_pos[keep]], order[keep], gap[keep]


def _relative_motions(dataset, lag):
    """``inv(S_a ... S_(a+g-1))`` for gaps ``g = 1..MAX_GAP``, anchors ``a``: (MAX_GAP, T-1, 4, 4), identity past T."""
    steps_inv = lie.se3_inv(lie.se3_exp(imu_step_twists(dataset, lag)))
    n = len(steps_inv)
    out = np.broadcast_to(np.eye(4), (MAX_GAP, n, 4, 4)).copy()
    out[0] = steps_inv
    for g in range(1, min(MAX_GAP, n)):
        out[g, : n - g] = steps_inv[g:] @ out[g - 1, : n - g]
    return out


def _apply(R, t, p):
    """``R p + t`` written out per component: R (..., 3, 3), t (..., 3), p (..., 3) broadcast."""
    return np.stack([R[..., i, 0] * p[..., 0] + R[..., i, 1] * p[..., 1] + R[..., i, 2] * p[..., 2] + t[..., i]
                     for i in range(3)], axis=-1)


def reprojection_errors(dataset, imu_T_cams, lags=LAGS):
    """Left-image errors (px) of every pair for every candidate ``imu_T_cams`` (C, 4, 4) and lag.

    Returns ``errors`` (L, C, P), finite (a point predicted behind the camera gets ``1e6`` px), and
    each pair's anchor frame and landmark id, (P,) each.
    """
    anchor, later, gap = track_pairs(dataset)
    frames = dataset.observation_frames()[anchor]
    imu_T_cams = np.asarray(imu_T_cams, dtype=float)[:, None]  # (C, 1, 4, 4): broadcast over pairs
    cam_T_imus = lie.se3_inv(imu_T_cams)
    p_cam = dataset.camera.triangulate(dataset.obs_z[anchor])
    p_imu = _apply(imu_T_cams[..., :3, :3], imu_T_cams[..., :3, 3], p_cam)  # (C, P, 3)
    K, z_later = dataset.K, dataset.obs_z[later, :2]
    errors = np.empty((len(lags), len(imu_T_cams), len(anchor)))
    for i, lag in enumerate(lags):
        later_T_anchor = _relative_motions(dataset, lag)[gap - 1, frames]  # (P, 4, 4)
        moved = _apply(later_T_anchor[:, :3, :3], later_T_anchor[:, :3, 3], p_imu)
        q = _apply(cam_T_imus[..., :3, :3], cam_T_imus[..., :3, 3], moved)
        depth = q[..., 2]
        inverse_depth = np.where(depth > 0, 1.0 / np.where(depth > 0, depth, 1.0), 0.0)
        du = K[0, 0] * q[..., 0] * inverse_depth + K[0, 2] - z_later[:, 0]
        dv = K[1, 1] * q[..., 1] * inverse_depth + K[1, 2] - z_later[:, 1]
        errors[i] = np.where(depth > 0, np.minimum(np.hypot(du, dv), _BEHIND), _BEHIND)
    return errors, frames, dataset.obs_ids[anchor]


class TrackScorer:
    """The reprojection errors of a drive's track pairs for every candidate, and the choices.

    Parameters
    ----------
    candidates : dict of str to ndarray (4, 4), optional
        Name -> candidate ``imu_T_cam`` (e.g. the readings of a 2025+ file, :mod:`._readings`);
        default :func:`corrections_of` ``dataset.imu_T_cam``.

    Attributes
    ----------
    names : list of str
    errors, scores : ndarray, shapes (len(LAGS), len(names), P) and (len(LAGS), len(names))
        Each pair's error, and each candidate's median (NaN without pairs).
    group : ndarray of int, shape (P,)
        Resampling group of each pair (its anchor frame's block), ``0 <= group < num_groups``.
    num_groups, num_landmarks : int
        Groups and landmarks with scored pairs.
    """

    def __init__(self, dataset, candidates=None):
        candidates = corrections_of(dataset.imu_T_cam) if candidates is None else candidates
        self.names = list(candidates)
        imu_T_cams = np.stack([np.asarray(candidates[name], dtype=float) for name in self.names])
        self.errors, anchor_frame, landmark = reprojection_errors(dataset, imu_T_cams, LAGS)
        blocks, self.group = np.unique(anchor_frame // BLOCK, return_inverse=True)
        self.num_groups, self.num_landmarks = len(blocks), len(np.unique(landmark))
        pairs = self.errors.shape[-1]
        self.scores = np.median(self.errors, axis=-1) if pairs else np.full(self.errors.shape[:2], np.nan)
        self._weights = None
        self._memo = {}

    @property
    def enough(self):
        """Enough landmarks and groups for a verdict (:data:`MIN_LANDMARKS`, :data:`MIN_GROUPS`)."""
        return self.num_landmarks >= MIN_LANDMARKS and self.num_groups >= MIN_GROUPS

    def _medians(self, lag_index, correction_index):
        """Bootstrap medians (RESAMPLES,) of one candidate, computed once."""
        if self._weights is None:
            self._weights = cluster_resamples(self.num_groups, RESAMPLES, SEED)
        key = (lag_index, correction_index)
        if key not in self._memo:
            self._memo[key] = resampled_medians(self.errors[key], self.group, self._weights)
        return self._memo[key]

    def _choice(self, candidates):
        """Verdict among ``candidates``: label -> (lag index, correction index)."""
        scores = {label: self.scores[index] for label, index in candidates.items()}
        if not self.enough:
            best = min(scores, key=scores.get) if self.errors.shape[-1] else None
            return TrackChoice(None, best, f"{NOT_ENOUGH}: {self.num_landmarks} landmarks in {self.num_groups} "
                               f"blocks of {BLOCK} frames with scored pairs (need {MIN_LANDMARKS} and {MIN_GROUPS})",
                               {})
        best = min(scores, key=scores.get)
        best_medians = self._medians(*candidates[best])
        margins = {}
        for label, index in candidates.items():
            if label != best:
                differences = self._medians(*index) - best_medians
                margins[str(label)] = [float(scores[label] - scores[best]),
                                       float(np.quantile(differences, 1 - CONFIDENCE))]
        doubtful = [label for label, (_, lower) in margins.items() if lower <= 0]
        if doubtful:
            return TrackChoice(None, best, f"{NOT_ENOUGH}: {', '.join(doubtful)} not worse with "
                               f"{CONFIDENCE:.0%} confidence", margins)
        return TrackChoice(best, best, "chosen", margins)

    def choose_correction(self):
        """The candidate (a correction, or a reading) whose best lag beats every other candidate's best lag."""
        finite = np.where(np.isfinite(self.scores), self.scores, np.inf)
        return self._choice({name: (int(np.argmin(finite[:, c])), c) for c, name in enumerate(self.names)})

    def best_lag(self, name):
        """The lag with the smallest median error for candidate ``name`` (0 without enough evidence)."""
        return LAGS[int(np.argmin(self.scores[:, self.names.index(name)]))] if self.enough else 0

    def choose_lag(self, correction):
        """The lag that beats every other lag, all with candidate ``correction``."""
        c = self.names.index(correction)
        choice = self._choice({lag: (i, c) for i, lag in enumerate(LAGS)})
        choice.margins = {f"{int(k):+d}": v for k, v in choice.margins.items()}
        return choice

    def evidence(self, correction_choice, lag_choice):
        """The :class:`TrackEvidence` with both verdicts."""
        scores = {name: [None if not np.isfinite(s) else float(s) for s in self.scores[:, c]]
                  for c, name in enumerate(self.names)}
        return TrackEvidence(list(LAGS), scores, int(self.errors.shape[-1]), self.num_landmarks, self.num_groups,
                             RESAMPLES if self._weights is not None else 0, correction_choice, lag_choice)
