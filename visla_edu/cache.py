"""A small user cache of JSON files, keyed by the content of numpy arrays.

Results that take a while to compute from a dataset (its calibration,
:func:`visla_edu.diagnostics.calibrate`) are kept between runs in a user cache folder
(:func:`cache_dir`), one JSON file per entry named by :func:`content_hash` of the arrays and a
version. Entries are written atomically (:func:`save_json`); a missing or corrupt one reads as none
(:func:`load_json`) and a folder that cannot be written is skipped: the cache never fails a run.
"""

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from visla_edu._files import atomic_write, expand_user

__all__ = ["ENV_VAR", "cache_dir", "content_hash", "load_json", "save_json"]

#: Environment variable naming the cache folder.
ENV_VAR = "VISLA_EDU_CACHE"


def cache_dir():
    """The user cache folder of visla-edu (not created here).

    Returns
    -------
    pathlib.Path
        ``$VISLA_EDU_CACHE`` if set and not empty, else ``$XDG_CACHE_HOME/visla-edu``, else
        ``~/.cache/visla-edu``.

    Raises
    ------
    ValueError
        The folder starts with ``~user`` of no user, or ``~`` without a home folder
        (:func:`visla_edu._files.expand_user`); callers then skip the cache.
    """
    explicit = os.environ.get(ENV_VAR, "").strip()
    if explicit:
        return expand_user(explicit)
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    return expand_user(xdg or "~/.cache") / "visla-edu"


def content_hash(arrays, version):
    """Hex digest (BLAKE2b, 32 bytes: 64 characters) of named arrays and a version string.

    Each array enters with its name, dtype, shape and bytes (C order): equal content gives the same
    key whatever the memory layout, any changed value, shape or type a new one.

    Parameters
    ----------
    arrays : dict
        Name -> array_like (scalars too).
    version : str
        Bump it whenever what is cached changes meaning.

    Returns
    -------
    str
    """
    digest = hashlib.blake2b(digest_size=32)
    digest.update(str(version).encode())
    for name in sorted(arrays):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"|{name}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def load_json(path):
    """The JSON object stored at ``path``, or None when it is missing, unreadable or not a JSON object.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    dict or None
    """
    try:
        with open(path, encoding="utf-8") as handle:
            value = json.load(handle)
    except (OSError, ValueError):  # missing, unreadable, not UTF-8, not JSON
        return None
    return value if isinstance(value, dict) else None


def save_json(path, value):
    """Write ``value`` as JSON to ``path`` atomically (:func:`visla_edu._files.atomic_write`), creating the folder.

    Parameters
    ----------
    path : str or pathlib.Path
    value : dict
        JSON-serialisable.

    Returns
    -------
    bool
        True when the file was written; False (and nothing written) when the folder or file cannot
        be written, or ``value`` is not JSON (NaN, infinity, other objects).
    """
    path = Path(path)
    try:
        text = json.dumps(value, allow_nan=False, indent=1)
    except (TypeError, ValueError):  # NaN, infinity or objects JSON cannot hold
        return False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path) as handle:
            handle.write(text)
    except (OSError, ValueError):  # not writable, no space, a folder in the way
        return False
    return True
