"""Writing files safely: a leaf module (imports only the standard library).

:func:`atomic_write` opens a temporary file in the target's folder and, when the ``with``
block ends without an error, renames it over the target with :func:`os.replace` (atomic on
POSIX and Windows within one file system). A reader therefore sees the old file or the whole
new one, never a half-written file, and a failed write leaves the old file untouched.

>>> from visla_edu._files import atomic_write
>>> with atomic_write("trajectory.txt") as f:    # doctest: +SKIP
...     f.write("1 0 0 0 0 1 0 0 0 0 1 0\\n")
"""

import contextlib
import os
import secrets
from pathlib import Path

__all__ = ["atomic_write"]


@contextlib.contextmanager
def atomic_write(path, mode="w", encoding="utf-8"):
    """Context manager: a file object whose content replaces ``path`` only if the block succeeds.

    Parameters
    ----------
    path : str or os.PathLike
        The target file. Its folder must exist (a missing folder is a ``FileNotFoundError``
        naming it).
    mode : {"w", "wb"}
        Text or binary.
    encoding : str
        For text mode.

    Yields
    ------
    file object
        Open on a temporary file ``.<name>.<pid>.<random>.tmp`` in the target's folder, created
        with the permissions a plain ``open`` would give.

    Raises
    ------
    FileNotFoundError
        The target's folder does not exist.
    ValueError
        ``mode`` is not ``"w"`` or ``"wb"``, or ``path`` is a folder.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write: mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path).expanduser()
    folder = path.parent.resolve()
    if not folder.is_dir():
        raise FileNotFoundError(f"{path}: folder {folder} does not exist; create it or choose another path")
    if path.is_dir():
        raise ValueError(f"{path} is a folder, not a file: give a file name")
    tmp = folder / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    # O_EXCL: never reuse someone else's file; 0o666 & ~umask, the permissions open() would give
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else encoding) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
