"""Cluster bootstrap of medians: resample whole clusters, vectorised over the resamples.

Values that share an error (the pairs of one landmark share its triangulation error, those of
landmarks anchored at the same frames the IMU's noise) are not independent; clusters of them
are. Resampling clusters with replacement (``B`` times, seeded) gives each cluster a
multiplicity ``W[m, b]``; resample ``b``'s median of the values is the weighted median with
the weights of the values' clusters.

A weighted median per resample by sorting costs ``B`` passes over all pairs. Here the pairs
are binned once into ``G`` equal-count bins between the 2% and 98% quantiles (plus one bin
below and one above); a sparse (bins x clusters) count matrix times ``W`` gives every
resample's weighted histogram at once, and the median is interpolated linearly within the bin
where the cumulative weight reaches half. With 192 bins the interpolation error is far below
the resampling spread.
"""

import numpy as np
from scipy import sparse

__all__ = ["cluster_resamples", "resampled_medians"]

#: Equal-count bins of the grouped median (between the 2% and 98% quantiles).
_BINS = 192
_LOW_QUANTILE, _HIGH_QUANTILE = 0.02, 0.98


def cluster_resamples(num_clusters, resamples, seed):
    """Multiplicities of each cluster in ``resamples`` bootstrap resamples.

    Parameters
    ----------
    num_clusters : int
        M, clusters (e.g. groups of landmarks) to resample with replacement, M at a time.
    resamples : int
        B.
    seed : int
        Seed of the generator: the same seed gives the same resamples.

    Returns
    -------
    ndarray of float32, shape (M, B)
        Counts (exact in float32); each column sums to M.
    """
    rng = np.random.default_rng(seed)
    index = np.int64 if resamples * num_clusters >= 2**31 else np.int32
    draws = rng.integers(0, num_clusters, size=(resamples, num_clusters), dtype=index)
    flat = (draws * index(resamples) + np.arange(resamples, dtype=index)[:, None]).ravel()  # (M, B) layout
    counts = np.bincount(flat, minlength=resamples * num_clusters)
    return counts.reshape(num_clusters, resamples).astype(np.float32)


def resampled_medians(values, cluster, weights):
    """Median of ``values`` in every resample, the pairs weighted by their cluster's multiplicity.

    Parameters
    ----------
    values : ndarray, shape (P,)
        Finite values of the pairs.
    cluster : ndarray of int, shape (P,)
        Cluster of each pair, ``0 <= cluster < M``.
    weights : ndarray, shape (M, B)
        Multiplicities from :func:`cluster_resamples`.

    Returns
    -------
    ndarray, shape (B,)
        Grouped-data medians (exact up to the linear interpolation within one bin of about
        0.5% of the pairs; clamped to the 2% and 98% quantiles).
    """
    edges = np.quantile(values, np.linspace(_LOW_QUANTILE, _HIGH_QUANTILE, _BINS + 1))
    bins = np.searchsorted(edges, values, side="right")  # 0 below, 1.._BINS inside, _BINS + 1 above
    counts = sparse.csr_matrix((np.ones(len(values), dtype=weights.dtype), (bins, cluster)),
                               shape=(_BINS + 2, weights.shape[0]))
    histogram = counts @ weights  # (bins, B)
    cumulative = np.cumsum(histogram, axis=0)
    half = 0.5 * cumulative[-1]
    j = np.argmax(cumulative >= half, axis=0)  # first bin reaching half the weight
    before = np.where(j > 0, cumulative[np.maximum(j - 1, 0), np.arange(len(j))], 0.0)
    inside = histogram[j, np.arange(len(j))]
    fraction = np.clip((half - before) / np.where(inside > 0, inside, 1.0), 0.0, 1.0)
    lower = edges[np.clip(j - 1, 0, _BINS)]
    upper = edges[np.clip(j, 0, _BINS)]
    return lower + fraction * (upper - lower)
