"""The ``features`` key of a course file, streamed into the sparse layout of the Dataset.

``features`` is a dense ``(4, M, T)`` array of pixels ``[uL, vL, uR, vR]``, all four -1 where
landmark m is not seen at frame t. Dataset 10's is 1.3 GB, of which about 1% is observations,
so it is decoded in chunks of landmark rows straight from the zip member (never held whole),
checked (finite, each observation complete) and collected into frame-major sparse arrays
(:func:`visla_edu.dataset.frame_major_order`).
"""

import numpy as np

from visla_edu.data._format import check_extras
from visla_edu.dataset import frame_major_order

__all__ = ["features_streamed", "features_in_memory"]

#: Bytes of the dense features decoded at a time (tests shrink it to exercise chunking).
_CHUNK_BYTES = 8 * 2**20
_PLANES = ("uL", "vL", "uR", "vR")


def features_streamed(fp, arrays, T, path):
    """Sparse features decoded chunk by chunk from an open ``.npy`` stream.

    Parameters
    ----------
    fp : file-like
        The ``features`` member of the archive, opened for reading at its start.
    arrays : dict
        The file's other (already checked) arrays; their ground-truth keys are checked
        against M here.
    T : int
        Number of frames (from ``time_stamps``).
    path : pathlib.Path
        The file, for messages.

    Returns
    -------
    tuple or None
        ``(frame_ptr (T+1,), obs_ids (N,), obs_z (N, 4), M)``, or None when the array is in
        Fortran order or an unusual ``.npy`` version (then use :func:`features_in_memory`).
    """
    header = _read_npy_header(fp, path)
    if header is None or header[1]:
        return None
    M = _check_features_header(header[0], header[2], T, path)
    check_extras(arrays, T, M, path)
    try:
        sparse = _collect_observations(_stream_chunks(fp, header[2], M, T, path), T, path)
    except ValueError:
        _drain(fp)  # a damaged archive shows only at the end (CRC): report that instead
        raise
    if fp.read(1):
        raise ValueError(f"{path}: key 'features' has extra bytes after its {header[0]} array data")
    return sparse + (M,)


def _drain(fp, block=2**22):
    """Read a zip member to its end, so zipfile checks its CRC (raises BadZipFile)."""
    while fp.read(block):
        pass



def features_in_memory(dense, arrays, T, path):
    """Like :func:`features_streamed` for the whole dense array ``(4, M, T)`` already read."""
    M = _check_features_header(dense.shape, dense.dtype, T, path)
    check_extras(arrays, T, M, path)
    return _collect_observations(_array_chunks(dense, M, T), T, path) + (M,)


def _read_npy_header(fp, path):
    """``(shape, fortran_order, dtype)`` of an ``.npy`` stream, or None for versions 3+."""
    try:
        version = np.lib.format.read_magic(fp)
        if version == (1, 0):
            return np.lib.format.read_array_header_1_0(fp)
        if version == (2, 0):
            return np.lib.format.read_array_header_2_0(fp)
        return None
    except (ValueError, TypeError, EOFError, OSError, UnicodeError) as exc:
        raise ValueError(f"{path}: key 'features' is not a readable numpy array ({exc})") from None


def _check_features_header(shape, dtype, T, path):
    """Check the shape and dtype of ``features``; return M."""
    if len(shape) != 3 or shape[0] != 4 or shape[2] != T:
        raise ValueError(f"{path}: key 'features' expected shape (4, M, T) with T = {T} from time_stamps, got {shape}")
    if dtype.kind not in "fiu":
        raise ValueError(f"{path}: key 'features' must hold real numbers, got dtype {dtype}")
    return shape[1]


def _rows_per_chunk(T, itemsize):
    return max(1, _CHUNK_BYTES // max(1, T * itemsize))


def _stream_chunks(fp, dtype, M, T, path):
    """Yield ``(plane, first_row, block)`` with block (rows, T) of ``features[plane]``, in file order."""
    step = _rows_per_chunk(T, dtype.itemsize)
    for plane in range(4):
        for first in range(0, M, step):
            rows = min(step, M - first)
            raw = _read_exact(fp, rows * T * dtype.itemsize, path)
            yield plane, first, np.frombuffer(raw, dtype=dtype).reshape(rows, T)


def _array_chunks(features, M, T):
    """Like :func:`_stream_chunks` for an array already in memory."""
    step = _rows_per_chunk(T, features.dtype.itemsize)
    for plane in range(4):
        for first in range(0, M, step):
            yield plane, first, features[plane, first:first + step]


def _read_exact(fp, size, path):
    parts, remaining = [], size
    while remaining:
        part = fp.read(remaining)
        if not part:
            raise ValueError(f"{path}: key 'features' is truncated: its array data ends {remaining} bytes early")
        parts.append(part)
        remaining -= len(part)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def _collect_observations(chunks, T, path):
    """Sparse frame-major observations ``(frame_ptr, obs_ids, obs_z)`` from feature blocks.

    Plane 0 (``uL``) decides which entries are observations; planes 1-3 must be -1
    exactly where ``uL`` is -1, and their values are taken at the observed entries.
    """
    found, z = [], None
    for plane, first, block in chunks:
        _check_finite_block(block, plane, first, path)
        if plane == 0:
            rows, frames = np.nonzero(block != -1)
            found.append((rows + first, frames, block[rows, frames]))
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


def _start_observations(found):
    """Concatenate plane-0 findings: landmark ids (sorted), frames, and z with uL filled."""
    ids = np.concatenate([f[0] for f in found]) if found else np.zeros(0, dtype=np.int64)
    frames = np.concatenate([f[1] for f in found]) if found else np.zeros(0, dtype=np.int64)
    z = np.empty((len(ids), 4))
    z[:, 0] = np.concatenate([f[2] for f in found]) if found else 0.0
    return ids.astype(np.int64), frames.astype(np.int64), z


def _check_finite_block(block, plane, first, path):
    bad = ~np.isfinite(block)
    if bad.any():
        row, frame = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"{path}: key 'features' has a non-finite value {block[row, frame]} at index "
            f"({plane}, {first + row}, {frame}) ({_PLANES[plane]} of landmark {first + row} at frame {frame})"
        )


def _check_complete(block, plane, first, ids, frames, values, path):
    """Each observation has all four pixels or none (all -1)."""
    if np.count_nonzero(block == -1) == block.size - len(values) and not np.any(values == -1):
        return
    observed = np.zeros(block.shape, dtype=bool)
    observed[ids - first, frames] = True
    row, frame = (int(i) for i in np.argwhere((block == -1) == observed)[0])
    landmark = first + row
    state = "observed (uL != -1)" if observed[row, frame] else "not observed (uL = -1)"
    raise ValueError(
        f"{path}: key 'features': landmark {landmark} at frame {frame} is partly observed: it is {state} "
        f"but {_PLANES[plane]} = features[{plane}, {landmark}, {frame}] = {block[row, frame]}; "
        f"all four of [uL, vL, uR, vR] must be -1 (not observed) or none of them"
    )
