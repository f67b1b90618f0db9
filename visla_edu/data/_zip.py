"""The archive layer of the ``.npz`` reader: zip members and ``.npy`` headers, read before any data.

:func:`member_infos` lists the members and :func:`read_header` reads each ``.npy`` header and checks the size
it declares against the zip directory's uncompressed size, so a header that declares a huge array, or a member
whose entry inflates far beyond it, is refused from the headers alone; the caller bounds the declared shapes
(:func:`visla_edu.data._format.check_course_headers`) before reading.
"""

import io
import math
import zipfile
import zlib
from dataclasses import dataclass

import numpy as np

from visla_edu._files import format_bytes

__all__ = ["ZIP_ERRORS", "NpyHeader", "member_infos", "read_header", "read_member", "read_npy_header"]

#: Errors of ``zipfile`` and ``zlib`` that mean the archive is damaged.
ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError)

#: Largest ``.npy`` header read (numpy's own default limit).
_MAX_HEADER_BYTES = 10_000

#: zip flag bit 0: the member is encrypted.
_ENCRYPTED = 0x1


@dataclass(frozen=True)
class NpyHeader:
    """What an ``.npy`` member declares, read from its header without its data.

    ``data_offset`` is the bytes of magic and header before the data.
    """

    shape: tuple
    dtype: np.dtype
    fortran_order: bool
    data_offset: int

    @property
    def ndim(self):
        """Number of dimensions."""
        return len(self.shape)

    @property
    def nbytes(self):
        """Bytes of array data the header declares."""
        return math.prod(self.shape) * self.dtype.itemsize


def member_infos(zf, path):
    """Key -> ``ZipInfo`` of every member, in the archive's order (``np.savez`` stores key ``k`` as ``k.npy``).

    Folder entries are skipped; a member not ending in ``.npy`` keeps its whole name as key. Refused:
    a key twice (e.g. a second ``K.npy`` appended: which one wins would be an accident of the
    reader), an encrypted member, an unknown compression.
    """
    members, seen = {}, {}
    for index, info in enumerate(zf.infolist()):
        if info.is_dir():
            continue
        key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
        if key in members:
            raise ValueError(
                f"{path}: key '{key}' appears twice in the archive (members {seen[key][1]!r} at entry "
                f"{seen[key][0]} and {info.filename!r} at entry {index}); the file was appended to or "
                "assembled by hand. Re-create it with numpy.savez so that each key is stored once.")
        if info.flag_bits & _ENCRYPTED:
            raise ValueError(f"{path}: key '{key}' is encrypted; store the course file without a password")
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2,
                                      zipfile.ZIP_LZMA):
            raise ValueError(f"{path}: key '{key}' uses zip compression method {info.compress_type}, which "
                             "numpy cannot write and Python cannot read; re-create it with numpy.savez_compressed")
        members[key], seen[key] = info, (index, info.filename)
    return members


def read_header(zf, info, key, path):
    """The :class:`NpyHeader` of one member, checked against its zip entry; decompresses only the header.

    Refused: not ``.npy``, a version other than 1.0 or 2.0, an object dtype (pickle), a negative
    dimension, or a declared size other than the entry's uncompressed size (damaged or forged).
    ``zipfile.BadZipFile`` and ``zlib.error`` (the archive itself damaged) pass to the caller.
    """
    with zf.open(info) as fp:
        header = _parse_header(fp, key, path)
    declared = header.data_offset + header.nbytes
    if info.file_size != declared:
        raise ValueError(_size_mismatch(header, info.file_size, declared, key, path))
    return header


def read_npy_header(fp, version_note=""):
    """``(shape, fortran_order, dtype)`` of the ``.npy`` header at ``fp``, as numpy reads it (at most 10,000 bytes).

    A version other than 1.0 or 2.0 is a ValueError, ``version_note`` ending its message.
    """
    version = np.lib.format.read_magic(fp)
    if version not in ((1, 0), (2, 0)):
        raise ValueError(f".npy format version {version[0]}.{version[1]}{version_note}")
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    return read(fp, max_header_size=_MAX_HEADER_BYTES)


def _parse_header(fp, key, path):
    try:
        shape, fortran_order, dtype = read_npy_header(fp, "; numpy writes plain arrays as 1.0 or 2.0 (3.0 only "
                                                          "for structured dtypes with non-Latin-1 field names)")
        offset = fp.tell()
    except (zipfile.BadZipFile, zlib.error):
        raise  # the archive itself is damaged: the caller says so
    except Exception as exc:  # noqa: BLE001 - numpy parses untrusted bytes (tokenize, literal_eval...)
        raise ValueError(f"{path}: key '{key}' is not a readable numpy array ({type(exc).__name__}: {exc})") from None
    if dtype.hasobject:
        raise ValueError(f"{path}: key '{key}' is not a readable numpy array (dtype {dtype} holds Python "
                         "objects, which need pickle; loading pickles is refused)")
    if any(n < 0 for n in shape):
        raise ValueError(f"{path}: key '{key}' is not a readable numpy array (its header declares shape {shape})")
    return NpyHeader(tuple(int(n) for n in shape), dtype, bool(fortran_order), offset)


def _size_mismatch(header, actual, declared, key, path):
    what = f"a {header.shape} {header.dtype} array ({format_bytes(header.nbytes)})"
    if actual > declared:
        return (f"{path}: key '{key}': its zip entry inflates to {format_bytes(actual)} but its .npy header "
                f"declares {what}; the member is damaged or forged (nothing was read). Re-download the file.")
    return (f"{path}: key '{key}': its .npy header declares {what} but its zip entry holds only "
            f"{format_bytes(actual)}; the member is truncated or forged (nothing was read). Re-download the file.")


def read_member(zf, info, key, path):
    """One whole member as an array (size already checked, pickles refused; a CRC mismatch raises ``BadZipFile``)."""
    raw = zf.read(info)
    try:
        return np.lib.format.read_array(io.BytesIO(raw), allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - numpy parses untrusted bytes
        raise ValueError(f"{path}: key '{key}' is not a readable numpy array ({type(exc).__name__}: {exc})") from None
