"""Checks of notebook 00 (know your data): reading the course's dense feature array."""

import numpy as np

from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, ok, rng, student
from visla_edu.dataset import Dataset

__all__ = ["check_observations_at", "check_track_spans"]


def _random_dense(generator, M=40, T=25):
    """A small dense course array (4, M, T): contiguous tracks, -1 elsewhere, some unseen."""
    features = np.full((4, M, T), -1.0)
    for i in range(M):
        if i % 7 == 3:
            continue  # never observed
        start = int(generator.integers(0, T))
        stop = int(min(T, start + generator.integers(1, 10)))
        n = stop - start
        uL = generator.uniform(10, 1300, n)
        v = generator.uniform(10, 480, n)
        features[:, i, start:stop] = np.stack([uL, v, uL - generator.uniform(1, 60, n), v])
    features[:, :, 5] = -1.0  # one frame without any observation
    return features


def _dense_cases(hidden):
    """Dense arrays to test on: one visible; hidden: other sizes, a single landmark, one frame."""
    generator = rng(hidden)
    if not hidden:
        return [_random_dense(generator)]
    return [_random_dense(generator, M=60, T=30), _random_dense(generator, M=1, T=8),
            _random_dense(generator, M=12, T=6)[:, :, :1]]


def _observations_reference(features, t):
    ids = np.nonzero(features[0, :, t] != -1)[0]
    return ids, features[:, ids, t].T


def _check_frame(call, name, features, t):
    out = call(features, t)
    if not isinstance(out, tuple) or len(out) != 2:
        raise fail(name, f"must return a tuple (ids, z), got {type(out).__name__}")
    ids_ref, z_ref = _observations_reference(features, t)
    if np.ndim(out[0]) == 1 and len(out[0]) == features.shape[1] != len(ids_ref):
        raise fail(name, f"returned all {len(out[0])} landmarks; keep only the observed ones",
                   f"at frame {t}: keep the landmarks with features[0, i, t] != -1")
    where = f"at frame {t}, where {len(ids_ref)} landmarks are observed"
    if not len(ids_ref):
        where += ": an empty frame gives ids of shape (0,) and z of shape (0, 4)"
    try:
        ids = as_array(out[0], name, ids_ref.shape, "ids")
        if not np.array_equal(ids, ids_ref):
            raise fail(name, f"wrong landmark ids at frame {t}",
                       f"got {ids.astype(int).tolist()}, expected {ids_ref.tolist()} "
                       "(landmark indices along axis 1, increasing)")
        z = as_array(out[1], name, z_ref.shape, "pixels z")
    except AssertionError as err:
        if f"at frame {t}" in str(err):
            raise
        raise fail("", str(err), where) from None
    compare(name, z, z_ref, f"at frame {t}", [
        ("the columns are in the wrong order: rows are [uL, vL, uR, vR]\nz[i] = features[:, i, t]",
         lambda: z_ref[:, [0, 2, 1, 3]]),
    ])


@exercise_check
def check_observations_at(observations_at, hidden=False):
    """Exercise 00: ``observations_at(features (4, M, T), t) -> (ids (k,), z (k, 4))`` from dense features.

    At every frame of random dense course arrays (:mod:`visla_edu.data`; unseen landmarks, an empty
    frame among them): a tuple, ``ids`` the landmarks with ``features[0, i, t] != -1``, increasing,
    and ``z[j] = features[:, ids[j], t]``. Hides :meth:`visla_edu.dataset.Dataset.observations`.
    """
    name = "observations_at"
    call = student(observations_at, name, hide=[Dataset.observations])
    frames = 0
    for features in _dense_cases(hidden):
        for t in range(features.shape[2]):
            _check_frame(call, name, features, t)
        frames += features.shape[2]
    ok(f"{name}: ids and pixels agree with the dataset on {frames} frames, including an empty one", hidden)


def _spans_reference(features):
    seen = features[0] != -1  # (M, T)
    spans = np.full((features.shape[1], 2), -1, dtype=int)
    any_seen = seen.any(axis=1)
    spans[any_seen, 0] = np.argmax(seen[any_seen], axis=1)
    spans[any_seen, 1] = features.shape[2] - 1 - np.argmax(seen[any_seen, ::-1], axis=1)
    return spans


def _check_spans(call, name, features):
    ref = _spans_reference(features)
    got = as_array(call(features), name, ref.shape)
    seen = ref[:, 0] >= 0
    never = ~seen
    if seen.sum() and np.array_equal(got[seen], ref[seen]) and not np.array_equal(got[never], ref[never]):
        raise fail(name, "landmarks that are never observed must get [-1, -1]",
                   f"e.g. landmark {int(np.nonzero(never)[0][0])}; np.argmax of an all-False row returns 0")
    last_plus_one = ref.copy()
    last_plus_one[seen, 1] += 1
    compare(name, got, ref, f"on a random dense array of shape {features.shape}", [
        ("the last frame is off by one\nreturn the index of the last observed frame (inclusive), "
         "not one past it", lambda: last_plus_one),
        ("the two columns are swapped: [first, last]", lambda: ref[:, ::-1]),
    ], atol=0)
    return int(seen.sum()), int(never.sum())


@exercise_check
def check_track_spans(track_spans, hidden=False):
    """Exercise 00: ``track_spans(features (4, M, T)) -> (M, 2)`` first and last frame, -1 if never seen.

    On the arrays of :func:`check_observations_at`, must equal ``[first, last]`` (inclusive) of
    every landmark, ``[-1, -1]`` if never seen. Hides :meth:`visla_edu.dataset.Dataset.track_spans`.
    """
    name = "track_spans"
    call = student(track_spans, name, hide=[Dataset.track_spans])
    counts = [_check_spans(call, name, features) for features in _dense_cases(hidden)]
    seen, never = counts[0]
    ok(f"{name}: first/last frames agree for {seen} tracks and {never} unseen landmarks", hidden)
