"""Files visla-edu reads and writes: atomic writes, and checks of input and output paths.

A leaf module (imports only the standard library). Every file the package writes goes through
:func:`atomic_write`. :func:`check_output_path` and :func:`check_input_file` turn the usual path
mistakes into one-line errors that name the path and what to do, before any work starts; they
raise built-in types with that message as the only argument, so ``str(err)`` is the whole message.
"""

import contextlib
import errno
import os
import secrets
import stat
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "check_output_path", "check_input_file", "same_file", "file_kind", "format_bytes",
           "expand_user"]

#: Bytes the temporary file's name adds to the target's: ``.`` + ``.<pid>.<8 hex>.tmp``.
_TMP_EXTRA = 1 + 1 + 10 + 1 + 8 + 4
#: ``stat`` test -> what to call a path that is not a regular file.
_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def expand_user(path):
    """``Path(path)`` with a leading ``~`` or ``~user`` expanded, as :meth:`pathlib.Path.expanduser`.

    Where ``expanduser`` raises a ``RuntimeError`` (``~user`` of no user, ``~`` without a home
    folder), which would read as a bug, this raises a ValueError naming the path.
    """
    try:
        return Path(path).expanduser()
    except RuntimeError:
        head = Path(path).parts[0]
        raise ValueError(f"{path}: cannot expand {head!r}: no such user or home folder on this system; "
                         "give the full path (e.g. /home/NAME/...) instead") from None


@contextlib.contextmanager
def atomic_write(path, mode="w", encoding="utf-8", replace=True):
    """Context manager: a file object whose content replaces ``path`` only if the block succeeds.

    ``mode`` is ``"w"`` (text, in ``encoding``) or ``"wb"``; write to the yielded file, do not close
    it. The bytes go to ``.<name>.<pid>.<random>.tmp`` in the target's folder, are flushed and
    fsynced, then renamed over ``path`` with :func:`os.replace` (atomic within one file system): a
    reader sees the old file or the whole new one. If the body raises, the temporary file is removed
    and ``path`` keeps its content (a kill leaves at most the hidden temporary file). A replaced file
    keeps its permission bits; a new one gets those a plain ``open`` would give.

    ``replace=False`` never replaces an existing file: the finished temporary file is hard-linked to
    ``path`` (:func:`os.link` fails if ``path`` exists, even if it appeared while writing; without
    hard links, ``path`` is checked just before the rename), else a FileExistsError leaves ``path``
    as it was. A missing folder is a FileNotFoundError naming it; another ``mode``, or ``path`` a
    folder, a ValueError.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write: mode must be 'w' or 'wb', got {mode!r}")
    path = expand_user(path)
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
        if not replace:
            _link_new(tmp, path)
            return
        with contextlib.suppress(FileNotFoundError):
            os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def _link_new(tmp, path):
    """Give the finished ``tmp`` the name ``path`` only if nothing has it (``atomic_write(..., replace=False)``)."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(errno.EEXIST, "exists already; not replaced", str(path)) from None
    except OSError:  # no hard links here (FAT, some network shares): check, then rename
        if os.path.lexists(path):
            raise FileExistsError(errno.EEXIST, "exists already; not replaced", str(path)) from None
        os.replace(tmp, path)


def format_bytes(n):
    """``n`` bytes as a short text in binary units (up to TiB), one decimal: ``"512 B"``, ``"3.2 MiB"``."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n} B"


def file_kind(path):
    """What ``path`` is, for messages: ``"a regular file"``, ``"a directory"``, ``"a FIFO (named pipe)"``, ...

    Symbolic links are followed; also the other names of ``_KINDS``, ``"missing"`` (nothing there, or
    a component of the path is not a folder) and ``"a broken symbolic link"``. Other ``os.stat``
    errors propagate (e.g. ``PermissionError`` on the way).
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "a broken symbolic link" if os.path.islink(path) else "missing"
    except NotADirectoryError:
        return "missing"
    return next((name for test, name in _KINDS if test(mode)), "a regular file")


def check_input_file(path, what="data file"):
    """``path`` as an absolute Path (symbolic links resolved) if it is a readable regular file, else a clear error.

    The message starts with ``what``: FileNotFoundError (nothing there, or a broken symbolic link),
    IsADirectoryError, PermissionError (not readable), or ValueError for a FIFO, socket or device
    (visla-edu seeks in its inputs).
    """
    path = expand_user(path)
    kind = file_kind(path)
    if kind == "missing":
        raise FileNotFoundError(f"{what} {path}: not found")
    if kind == "a broken symbolic link":
        raise FileNotFoundError(f"{what} {path}: a broken symbolic link (it points to {os.readlink(path)!r}, "
                                "which does not exist)")
    if kind == "a directory":
        raise IsADirectoryError(f"{what} {path}: is a directory, not a file; pass the .npz file inside it")
    if kind != "a regular file":
        raise ValueError(f"{what} {path}: is {kind}, not a regular file; save the data to a file on disk "
                         "and pass that (visla-edu reads its inputs with random access)")
    if not os.access(path, os.R_OK):
        raise PermissionError(f"{what} {path}: permission denied (this user cannot read it); "
                              "check its permissions (ls -l) or copy it somewhere readable")
    return path.resolve()


def same_file(a, b):
    """Whether paths ``a`` and ``b`` (``~`` expanded) name the same file, through links, ``..`` or hard links.

    :func:`os.path.samefile` when both can be stat'ed, else whether both resolve to the same path.
    """
    a, b = expand_user(a), expand_user(b)
    with contextlib.suppress(OSError):
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def check_output_path(path, suffixes, option, inputs=(), others=()):
    """Check an output path before any work (suffix, folder, kind, no input); return the absolute path to write.

    ``suffixes``: the allowed ones, lower case with the dot (``(".npz",)``), the first suggested;
    ``option``: how the user gave the path (``"--out"``), it starts the message. The output may be none
    of ``inputs`` (the files the command reads, even through a link or a relative path) nor of
    ``others`` (``(option, path)`` of the command's other outputs). The folder is resolved, the name
    kept as given. Errors: ValueError (wrong suffix, an existing FIFO or device, a name too long for
    the folder, an input or another output), IsADirectoryError (``path`` is a folder),
    FileNotFoundError or NotADirectoryError (no such folder), PermissionError (not writable).
    """
    given = expand_user(path)
    kind = file_kind(given)
    if kind == "a directory":
        raise IsADirectoryError(f"{option} {path}: is a directory; give a file name, "
                                f"e.g. {option} {given / ('result' + suffixes[0])}")
    if given.suffix.lower() not in suffixes:
        example = given.with_suffix(suffixes[0]) if given.suffix else given.with_name(given.name + suffixes[0])
        raise ValueError(f"{option} {path}: the file name must end in {_choices(suffixes)}; e.g. {option} {example}")
    if kind not in ("missing", "a regular file", "a broken symbolic link"):
        raise ValueError(f"{option} {path}: is {kind}; visla-edu writes a regular file, give another name")
    folder = _writable_folder(given, option, path)
    target = folder / given.name
    longest = os.pathconf(folder, "PC_NAME_MAX") - _TMP_EXTRA
    if len(given.name.encode()) > longest:
        raise ValueError(f"{option} {path}: the file name is {len(given.name.encode())} bytes long, more than the "
                         f"{longest} this folder allows (with room for the temporary file); choose a shorter name")
    for source in inputs:
        if same_file(target, source):
            raise ValueError(f"{option} {path}: is the input file {Path(source).resolve()}; writing there would "
                             "destroy it: choose another name")
    for other_option, other in others:
        if other is not None and (same_file(target, other) or target == expand_user(other).resolve()):
            raise ValueError(f"{option} {path}: is also the {other_option} file; give them different names")
    return target


def _choices(suffixes):
    return suffixes[0] if len(suffixes) == 1 else f"{', '.join(suffixes[:-1])} or {suffixes[-1]}"


def _writable_folder(given, option, shown):
    """The resolved folder of ``given``, checked to exist, be a folder and be writable."""
    folder = given.parent.resolve()
    kind = file_kind(folder)
    if kind == "missing":
        raise FileNotFoundError(f"{option} {shown}: the folder {folder} does not exist; create it first "
                                f"(mkdir -p {folder})")
    if kind != "a directory":
        raise NotADirectoryError(f"{option} {shown}: {folder} is {kind}, not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"{option} {shown}: the folder {folder} is not writable by this user; "
                              "choose another folder")
    _probe_write(folder, option, shown)
    return folder


def _probe_write(folder, option, shown):
    """Create and remove a small file in ``folder``: permissions alone do not tell (root, /proc, read-only mounts)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".visla-edu-probe-"):
            pass
    except OSError as err:
        raise PermissionError(f"{option} {shown}: cannot create a file in {folder} ({err.strerror or err}); "
                              "choose another folder") from None
