"""Stale copies, a quirk of the course files, added to a drive (:func:`visla_edu.dataset.stale_copies`)."""

import dataclasses

import numpy as np

__all__ = ["with_stale_copies"]


def with_stale_copies(dataset, share, seed=0):
    """``dataset`` with stale frames: at each, every continuing track repeats its pixels of the frame before.

    As the course files have them (one frame in seven to twelve on ``0020``, ``0022`` and ``03``): at a stale frame
    ``t`` each landmark also seen at ``t - 1`` gets frame ``t - 1``'s pixels, bit for bit; new tracks and the ground
    truth stay as they are. ``share``: probability that a frame ``t >= 1`` is stale, in ``[0, 1]`` (else ValueError);
    ``seed`` seeds the choice of frames. Returns a new Dataset named ``"<name>-stale"``, with ``extra`` empty.
    """
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"with_stale_copies: share must be in [0, 1], got {share!r}")
    z = dataset.obs_z.copy()
    stale = np.random.default_rng(seed).random(dataset.num_frames) < share
    ptr = dataset.frame_ptr
    for t in np.flatnonzero(stale[1:]) + 1:
        _, before, now = np.intersect1d(dataset.obs_ids[ptr[t - 1]:ptr[t]], dataset.obs_ids[ptr[t]:ptr[t + 1]],
                                        return_indices=True)
        z[ptr[t] + now] = z[ptr[t - 1] + before]
    return dataclasses.replace(dataset, obs_z=z, name=f"{dataset.name}-stale", extra={})
