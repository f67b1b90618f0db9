"""A small user cache of JSON files, keyed by the content of numpy arrays.

Slow results of a dataset (its calibration, :func:`visla_edu.diagnostics.calibrate`) are kept
between runs in :func:`cache_dir`, one JSON file per entry named by :func:`content_hash` of the
arrays and a version. Entries are written atomically (:func:`save_json`); a missing or corrupt one
reads as none (:func:`load_json`) and a folder that cannot be written is skipped: the cache never
fails a run.
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
    """The user cache folder of visla-edu, a :class:`pathlib.Path` (not created here).

    ``$VISLA_EDU_CACHE`` if set and not empty, else ``$XDG_CACHE_HOME/visla-edu``, else
    ``~/.cache/visla-edu``. ValueError for ``~user`` of no user or ``~`` without a home folder
    (:func:`visla_edu._files.expand_user`); callers then skip the cache.
    """
    explicit = os.environ.get(ENV_VAR, "").strip()
    if explicit:
        return expand_user(explicit)
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    return expand_user(xdg or "~/.cache") / "visla-edu"


def content_hash(arrays, version):
    """Hex digest (BLAKE2b, 32 bytes: 64 characters) of named arrays and a version string.

    ``arrays``: name -> array_like (scalars too); ``version``: bump it whenever what is cached changes
    meaning. Each array enters with its name, dtype, shape and bytes (C order): equal content gives the
    same key whatever the memory layout, any changed value, shape or type a new one.
    """
    digest = hashlib.blake2b(digest_size=32)
    digest.update(str(version).encode())
    for name in sorted(arrays):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"|{name}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def load_json(path):
    """The JSON object (a dict) stored at ``path``, or None when it is missing, unreadable or not an object."""
    try:
        with open(path, encoding="utf-8") as handle:
            value = json.load(handle)
    except (OSError, ValueError):  # missing, unreadable, not UTF-8, not JSON
        return None
    return value if isinstance(value, dict) else None


def save_json(path, value):
    """Write the dict ``value`` as JSON to ``path`` atomically, creating the folder.

    Through :func:`visla_edu._files.atomic_write`. True when written; False (and nothing written) when
    the folder or file cannot be written, or ``value`` is not JSON (NaN, infinity, other objects).
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
