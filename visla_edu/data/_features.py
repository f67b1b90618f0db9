"""The ``features`` key of a course file (:mod:`visla_edu.data`), streamed into the sparse Dataset layout.

Decoded in chunks straight from the zip member, checked (finite; each observation all -1 or none, ``uL``
deciding; at most :data:`MAX_OBSERVATIONS`) and collected frame-major. A C-order array is decoded in chunks
of landmark rows of one plane; a Fortran-order one (the bytes of a C-order ``(T, M, 4)`` array) in chunks of
whole frames. The memory is one chunk plus the observations.
"""

import numpy as np

from visla_edu.dataset import frame_major_order

__all__ = ["features_streamed", "features_in_memory", "MAX_OBSERVATIONS"]

#: Bytes of the dense features decoded at a time (tests shrink it to exercise chunking).
_CHUNK_BYTES = 8 * 2**20
#: Most observations a file may hold: 50 times dataset 10's (about 400,000); the sparse
#: arrays of this many take about 1.3 GB.
MAX_OBSERVATIONS = 20_000_000
_PLANES = ("uL", "vL", "uR", "vR")


def features_streamed(fp, header, path):
    """Sparse ``(frame_ptr (T+1,), obs_ids (N,), obs_z (N, 4))``, frame-major, decoded chunk by chunk.

    ``fp`` is the ``features`` zip member positioned after its ``.npy`` header, ``header`` its
    checked :class:`~visla_edu.data._zip.NpyHeader` (``(4, M, T)``, float or signed integer).
    """
    _, M, T = header.shape
    stream, collect = ((_stream_frame_chunks, _collect_frame_blocks) if header.fortran_order
                       else (_stream_chunks, _collect_observations))
    try:
        sparse = collect(stream(fp, header.dtype, M, T, path), T, path)
    except ValueError:
        _drain(fp)  # a damaged archive shows only at the end (CRC): report that instead
        raise
    if fp.read(1):
        raise ValueError(f"{path}: key 'features' has extra bytes after its {header.shape} array data")
    return sparse


def _drain(fp, block=2**22):
    """Read a zip member to its end, so zipfile checks its CRC (raises BadZipFile)."""
    while fp.read(block):
        pass


def features_in_memory(dense, path):
    """:func:`features_streamed` for the whole dense array ``(4, M, T)``, scanned as a C-order file is streamed."""
    _, M, T = dense.shape
    return _collect_observations(_array_chunks(dense, M, T), T, path)


def _rows_per_chunk(row_items, itemsize):
    return max(1, _CHUNK_BYTES // max(1, row_items * itemsize))


def _stream_chunks(fp, dtype, M, T, path):
    """Yield ``(plane, first_row, block)``, block (rows, T) of ``features[plane]``, in file order."""
    step = _rows_per_chunk(T, dtype.itemsize)
    for plane in range(4):
        for first in range(0, M, step):
            rows = min(step, M - first)
            raw = _read_exact(fp, rows * T * dtype.itemsize, path)
            yield plane, first, np.frombuffer(raw, dtype=dtype).reshape(rows, T)


def _stream_frame_chunks(fp, dtype, M, T, path):
    """Fortran order: yield ``(first_frame, block)``, block (frames, M, 4) = ``features[:, :, frames]`` moved."""
    step = _rows_per_chunk(4 * M, dtype.itemsize)
    for first in range(0, T, step):
        frames = min(step, T - first)
        raw = _read_exact(fp, frames * M * 4 * dtype.itemsize, path)
        yield first, np.frombuffer(raw, dtype=dtype).reshape(frames, M, 4)


def _array_chunks(features, M, T):
    """Like :func:`_stream_chunks` for an array already in memory."""
    step = _rows_per_chunk(T, features.dtype.itemsize)
    for plane in range(4):
        for first in range(0, M, step):
            yield plane, first, features[plane, first:first + step]


def _read_exact(fp, size, path):
    """``size`` bytes of the zip member ``fp`` (whose ``read`` returns fewer only at its end)."""
    data = fp.read(size)
    if len(data) < size:
        raise ValueError(f"{path}: key 'features' is truncated: its array data ends {size - len(data)} bytes early")
    return data


def _collect_observations(chunks, T, path):
    """Frame-major ``(frame_ptr, obs_ids, obs_z)`` from blocks; ``uL`` decides what is observed."""
    found, z = [], None
    for plane, first, block in chunks:
        _check_finite_block(block, plane, first, path)
        if plane == 0:
            rows, frames = np.nonzero(block != -1)
            found.append((rows + first, frames, block[rows, frames]))
            _check_count(sum(len(f[0]) for f in found), path)
            continue
        if z is None:
            ids, frames, z = _start_observations(found)
        lo, hi = np.searchsorted(ids, [first, first + len(block)])
        values = block[ids[lo:hi] - first, frames[lo:hi]]
        _check_complete(block, plane, first, ids[lo:hi], frames[lo:hi], values, path)
        z[lo:hi, plane] = values
    if z is None:
        ids, frames, z = _start_observations(found)
    order, frame_ptr = frame_major_order(ids, frames, T)
    return frame_ptr, ids[order], z[order]


def _collect_frame_blocks(chunks, T, path):
    """Like :func:`_collect_observations` for Fortran-order blocks ``(first_frame, (frames, M, 4))``."""
    found = []
    for first, block in chunks:
        for plane in range(4):
            _check_finite_block(block[:, :, plane].T, plane, 0, path, first_frame=first)
        observed = block[:, :, 0] != -1
        for plane in range(1, 4):
            partial = (block[:, :, plane] == -1) == observed
            if partial.any():
                t, m = (int(i) for i in np.argwhere(partial)[0])
                raise ValueError(_partial_message(path, plane, m, first + t, block[t, m, plane], observed[t, m]))
        t, m = np.nonzero(observed)
        _check_count(sum(len(f[0]) for f in found) + len(m), path)
        found.append((m, t + first, block[t, m]))
    ids, frames, z = _concatenate(found, (4,))
    order, frame_ptr = frame_major_order(ids, frames, T)
    return frame_ptr, ids[order], z[order]


def _check_count(count, path):
    if count > MAX_OBSERVATIONS:
        raise ValueError(f"{path}: key 'features' holds more than {MAX_OBSERVATIONS} observations (entries other than "
                         "-1), fifty times the largest course file; is 'not observed' marked with -1?")


def _start_observations(found):
    """Concatenate plane-0 findings: landmark ids (sorted), frames, and z with uL filled."""
    ids, frames, uL = _concatenate(found, ())
    z = np.empty((len(ids), 4))
    z[:, 0] = uL
    return ids, frames, z


def _concatenate(found, value_shape):
    """The ``(ids, frames, values)`` found, each concatenated: int64 ids and frames, float values."""
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, *value_shape)))
    return (np.concatenate(parts) for parts in zip(empty, *found))


def _check_finite_block(block, plane, first, path, first_frame=0):
    """No NaN or inf in ``block`` = ``features[plane, first:first + rows, first_frame:...]``."""
    bad = ~np.isfinite(block)
    if bad.any():
        row, frame = (int(i) for i in np.argwhere(bad)[0])
        landmark, frame_index = first + row, first_frame + frame
        hint = ("; the course marks 'not observed' with -1 in all four: features = np.nan_to_num(features, nan=-1)"
                if np.isnan(block[row, frame]) else "")
        raise ValueError(
            f"{path}: key 'features' has a non-finite value {block[row, frame]} at index "
            f"({plane}, {landmark}, {frame_index}) ({_PLANES[plane]} of landmark {landmark} at frame {frame_index})"
            f"{hint}"
        )


def _check_complete(block, plane, first, ids, frames, values, path):
    """Each observation has all four pixels or none (all -1)."""
    if np.count_nonzero(block == -1) == block.size - len(values) and not np.any(values == -1):
        return
    observed = np.zeros(block.shape, dtype=bool)
    observed[ids - first, frames] = True
    row, frame = (int(i) for i in np.argwhere((block == -1) == observed)[0])
    raise ValueError(_partial_message(path, plane, first + row, frame, block[row, frame], observed[row, frame]))


def _partial_message(path, plane, landmark, frame, value, observed):
    state = "observed (uL != -1)" if observed else "not observed (uL = -1)"
    return (
        f"{path}: key 'features': landmark {landmark} at frame {frame} is partly observed: it is {state} "
        f"but {_PLANES[plane]} = features[{plane}, {landmark}, {frame}] = {value}; "
        f"all four of [uL, vL, uR, vR] must be -1 (not observed) or none of them"
    )
