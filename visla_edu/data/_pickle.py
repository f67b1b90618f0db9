"""A dict of numpy arrays from a pickled ``.npy`` file, read without running any code from it.

The 2025+ course files are ``np.save(path, dict)``: an ``.npy`` header declaring a 0-d object array, then a
pickle of it, which ``np.load(path, allow_pickle=True)`` would unpickle with every installed class available
(a crafted file could run ``os.system``). Here the header is parsed as numpy's reader does (a Python literal,
never evaluated) and :class:`ArrayUnpickler` resolves only the globals numpy's own pickles of plain arrays use
(``numpy.ndarray``, ``numpy.dtype`` and ``numpy(._)core``'s ``_reconstruct``, ``scalar`` and ``_frombuffer``),
each through a wrapper below that checks its arguments. Python's containers (dict, list, tuple, str, bytes,
numbers, None) need no global; anything else is refused before it is looked up.
"""

import pickle
import re

import numpy as np

from visla_edu._files import check_input_file, format_bytes
from visla_edu.data._zip import read_npy_header

__all__ = ["ArrayUnpickler", "read_pickled_dict", "MAX_PICKLE_BYTES"]

#: Largest file read (a pickle is read whole, not streamed): 2 GiB, 1.5 times dataset 10's dense
#: features as float64.
MAX_PICKLE_BYTES = 2 * 2**30
#: dtype specs a pickled plain array may use: booleans, (un)signed integers, floats, objects.
_DTYPE_SPEC = re.compile(r"^(b1|[iu][1248]|f[248]|O[48])$")


class _NdarrayMarker:
    """Stands for ``numpy.ndarray`` inside the pickle: only ``_reconstruct`` accepts it."""

    __slots__ = ()


_NDARRAY = _NdarrayMarker()


def _reconstruct(cls, shape, typecode):
    """numpy's ``_reconstruct(ndarray, (0,), b'b')``: an empty array for ``__setstate__`` to fill."""
    if cls is not _NDARRAY or tuple(shape) != (0,) or typecode != b"b":
        raise pickle.UnpicklingError(f"unexpected array reconstruction {shape!r}, {typecode!r}")
    return np.empty(0, dtype=np.int8)


def _dtype(spec, align=False, copy=True):
    """``numpy.dtype(spec)`` for booleans, integers, floats and objects only (no structured or void dtypes)."""
    if not isinstance(spec, str) or not _DTYPE_SPEC.match(spec) or align not in (False, 0):
        raise pickle.UnpicklingError(f"dtype {spec!r} is not a plain number or object dtype")
    return np.dtype(spec)


def _scalar(dtype, data):
    """numpy's ``scalar(dtype, bytes)`` for numeric dtypes."""
    if not isinstance(dtype, np.dtype) or dtype.kind not in "biuf" or not isinstance(data, bytes) \
            or len(data) != dtype.itemsize:
        raise pickle.UnpicklingError("unexpected numpy scalar")
    return np.frombuffer(data, dtype=dtype)[0].copy()


def _frombuffer(buffer, dtype, shape, order):
    """numpy's ``_frombuffer`` (pickle protocol 5, an in-band buffer) for numeric dtypes."""
    if not isinstance(dtype, np.dtype) or dtype.kind not in "biuf" or order not in ("C", "F"):
        raise pickle.UnpicklingError("unexpected array buffer")
    return np.frombuffer(buffer, dtype=dtype).reshape(shape, order=order).copy()


_ALLOWED = {("numpy", "ndarray"): _NDARRAY, ("numpy", "dtype"): _dtype}
for _core in ("numpy.core", "numpy._core"):  # numpy 1 and 2
    _ALLOWED.update({(f"{_core}.multiarray", "_reconstruct"): _reconstruct, (f"{_core}.multiarray", "scalar"): _scalar,
                     (f"{_core}.numeric", "_frombuffer"): _frombuffer})


class ArrayUnpickler(pickle.Unpickler):
    """An unpickler that builds numpy arrays and Python containers, and nothing else (see the module)."""

    def find_class(self, module, name):
        """The wrapper of an allowed global; ``UnpicklingError`` for every other one (never imported)."""
        allowed = _ALLOWED.get((module, name))
        if allowed is None:
            raise pickle.UnpicklingError(f"it refers to {module}.{name}, which a file of plain arrays never needs "
                                         "(a pickle that names it could run code)")
        return allowed

    def persistent_load(self, pid):
        """Persistent ids are refused (a file of arrays has none)."""
        raise pickle.UnpicklingError("it uses persistent ids, which a file of plain arrays never needs")


def read_pickled_dict(path):
    """``(absolute path, dict)`` stored by ``np.save(path, dict)``, read with :class:`ArrayUnpickler`.

    Refused (``ValueError``: nothing from the file was run): over :data:`MAX_PICKLE_BYTES`, not a
    0-d object ``.npy``, a pickle damaged or naming anything but plain arrays, or not a dict with
    string keys.
    """
    path = check_input_file(path, "course file")
    size = path.stat().st_size
    if size > MAX_PICKLE_BYTES:
        raise ValueError(f"{path}: {format_bytes(size)}, more than the {format_bytes(MAX_PICKLE_BYTES)} visla-edu "
                         "reads from a pickled .npy course file (it is read whole); nothing was read")
    with open(path, "rb") as fp:
        _check_header(fp, path)
        try:
            stored = ArrayUnpickler(fp).load()
        except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError, KeyError,
                MemoryError, OverflowError) as exc:
            raise ValueError(f"{path}: refused to read its pickled contents: {exc} ({type(exc).__name__}); nothing "
                             "from the file was run. Write the course dict with np.save from plain numpy arrays"
                             ) from None
    return path, _as_dict(stored, path)


def _check_header(fp, path):
    """Read the magic string and header: a 0-d (or 1-element) object array, else ValueError."""
    try:
        shape, _, dtype = read_npy_header(fp)
    except Exception as exc:  # noqa: BLE001 - numpy parses untrusted bytes (literal_eval...)
        raise ValueError(f"{path}: not a readable .npy file ({type(exc).__name__}: {exc}); the 2025+ course files "
                         "are written with np.save(path, dict)") from None
    if not dtype.hasobject or shape not in ((), (1,)):
        raise ValueError(f"{path}: an .npy file of a {shape} {dtype} array, but a 2025+ course file holds one dict "
                         "(np.save(path, dict): a 0-d object array)")


def _as_dict(stored, path):
    """The dict inside the unpickled 0-d object array, with string keys."""
    if not isinstance(stored, np.ndarray) or stored.dtype != object or stored.size != 1:
        raise ValueError(f"{path}: its pickle holds a {type(stored).__name__}, not the 0-d object array of a dict "
                         "that np.save(path, dict) writes")
    contents = stored.reshape(-1)[0]
    if not isinstance(contents, dict):
        raise ValueError(f"{path}: holds a {type(contents).__name__}, but a 2025+ course file holds a dict of arrays "
                         "(v_t, w_t, timestamps, features, K_l, K_r, extL_T_imu, extR_T_imu)")
    bad = [k for k in contents if not isinstance(k, str)]
    if bad:
        raise ValueError(f"{path}: the dict's keys must be strings, got {bad[:3]!r}")
    return contents
