"""Cluster bootstrap of medians: resample whole clusters, vectorised over the resamples.

Clusters are the values that share an error (the pairs of one landmark, or of landmarks anchored
at the same frames). Every resample's median comes from one histogram of ``_BINS`` equal-count
bins: a sparse (bins x clusters) count matrix times the multiplicities ``W`` (M, B).
"""

import numpy as np
from scipy import sparse

__all__ = ["cluster_resamples", "resampled_medians"]

#: Equal-count bins of the grouped median (between the 2% and 98% quantiles).
_BINS = 192
_LOW_QUANTILE, _HIGH_QUANTILE = 0.02, 0.98


def cluster_resamples(num_clusters, resamples, seed):
    """Multiplicities (M, B), float32, of ``num_clusters`` M clusters in ``resamples`` B resamples.

    Exact counts; each column sums to M; the same ``seed`` gives the same resamples.
    """
    rng = np.random.default_rng(seed)
    index = np.int64 if resamples * num_clusters >= 2**31 else np.int32
    draws = rng.integers(0, num_clusters, size=(resamples, num_clusters), dtype=index)
    flat = (draws * index(resamples) + np.arange(resamples, dtype=index)[:, None]).ravel()  # (M, B) layout
    counts = np.bincount(flat, minlength=resamples * num_clusters)
    return counts.reshape(num_clusters, resamples).astype(np.float32)


def resampled_medians(values, cluster, weights):
    """Medians (B,) of finite ``values`` (P,), each weighted by ``weights[cluster]`` (M, B), in every resample.

    ``cluster`` (P,) int, ``0 <= cluster < M``. Exact up to the interpolation within one bin (about
    0.5% of the values); clamped to the 2% and 98% quantiles.
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
