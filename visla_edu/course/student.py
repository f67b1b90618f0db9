"""A student's own working folder, ``visla-edu student DIR``: course files that are never overwritten.

:func:`make_student_folder` copies the packaged student edition and a ``README.md`` into the folder
(TEACHING.md, section 1), keeping any file already there, so an upgrade only adds what is new. Each file
is written atomically under a free name (:func:`visla_edu._files.atomic_write`, ``replace=False``).

>>> from visla_edu.course import student
>>> print(student.make_student_folder("~/visla-course").report())    # doctest: +SKIP
student folder /home/alice/visla-course: 12 added, 0 kept
"""

import dataclasses
import os
import tempfile
from pathlib import Path

from visla_edu._files import atomic_write, expand_user, file_kind, same_file
from visla_edu.course import STUDENT_NOTEBOOKS, STUDENT_README

__all__ = ["README_NAME", "FolderUpdate", "course_files", "make_student_folder"]

#: The student README's name in the student's folder.
README_NAME = "README.md"
#: Names never copied: editor and Python caches (hidden names are never copied either).
_SKIPPED = {"__pycache__"}


@dataclasses.dataclass(frozen=True)
class FolderUpdate:
    """What :func:`make_student_folder` did to a student's folder (``folder``, absolute).

    ``added``, ``kept``, ``kept_different``: tuples of paths relative to ``folder`` (with ``/``): copied now,
    already there with this edition's content, already there with other content (left as they are).
    """

    folder: Path
    added: tuple
    kept: tuple
    kept_different: tuple

    def report(self):
        """The text ``visla-edu student`` prints (str): a summary line, then one line per file."""
        kept = len(self.kept) + len(self.kept_different)
        lines = [f"student folder {self.folder}: {len(self.added)} added, {kept} kept (never overwritten)"]
        lines += [f"  added  {name}" for name in self.added]
        lines += [f"  kept   {name} (differs from this edition's: yours stays; to get this edition's, rename "
                  "yours and run again)" for name in self.kept_different]
        lines += [f"  kept   {name} (as this edition has it)" for name in self.kept]
        lines.append(f"start: cd {self.folder} && jupyter lab   ({README_NAME} there says more)")
        return "\n".join(lines)


def course_files(source=None):
    """The files a student's folder receives: relative name (with ``/``) -> the package file, sorted.

    Every regular file under ``source`` (default :data:`visla_edu.course.STUDENT_NOTEBOOKS`) but hidden names
    and ``__pycache__``; ``README.md`` is :data:`visla_edu.course.STUDENT_README` unless the edition has one.
    FileNotFoundError if ``source`` holds no notebook.
    """
    source = Path(STUDENT_NOTEBOOKS if source is None else source)
    found = {}
    for path in sorted(source.rglob("*")):
        parts = path.relative_to(source).parts
        if path.is_file() and not any(part.startswith(".") or part in _SKIPPED for part in parts):
            found["/".join(parts)] = path
    if not any(name.endswith(".ipynb") for name in found):
        raise FileNotFoundError(f"no student notebooks in {source}: this visla-edu installation is incomplete; "
                                "reinstall it (python -m pip install --force-reinstall ...) from the wheel or "
                                "index your course gives")
    return dict(sorted({README_NAME: STUDENT_README, **found}.items()))


def make_student_folder(folder, source=None):
    """Create or complete a student's folder: copy each course file that is not there yet.

    Anything already under a file's name (a file, folder or link) is never replaced. ``folder`` (``~``
    expanded) is created with its parents; ``source`` as :func:`course_files`. Returns a :class:`FolderUpdate`.

    Raises NotADirectoryError (a file on ``folder``'s path), PermissionError (cannot create or write),
    ValueError (``folder`` is the student edition itself), FileNotFoundError (the edition is missing).
    """
    files = course_files(source)
    target = _student_folder(folder, Path(STUDENT_NOTEBOOKS if source is None else source))
    outcomes = {"added": [], "kept": [], "different": []}
    for name, path in files.items():
        outcomes[_copy_new(path, target / name)].append(name)
    return FolderUpdate(target, *(tuple(outcomes[key]) for key in ("added", "kept", "different")))


def _copy_new(source, target):
    """Copy ``source`` to ``target`` unless something has that name: ``"added"``, ``"kept"`` or ``"different"``."""
    data = source.read_bytes()
    if not os.path.lexists(target):
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            with atomic_write(target, "wb", replace=False) as f:
                f.write(data)
            return "added"
        except FileExistsError:  # it appeared while we wrote: it stays
            pass
    return "kept" if target.is_file() and target.read_bytes() == data else "different"


def _student_folder(folder, source):
    """``folder`` as an absolute path, created if missing, checked to be a folder this user can write in."""
    path = expand_user(folder)
    kind = file_kind(path)
    if kind == "missing":
        _create(path, folder)
    elif kind != "a directory":
        raise NotADirectoryError(f"{folder}: is {kind}, not a folder; give the name of a folder (it is created if "
                                 "missing), e.g. ~/visla-course")
    path = path.resolve()
    if same_file(path, source):
        raise ValueError(f"{folder}: is the course's own student edition ({source}); give a folder of your own, "
                         "e.g. ~/visla-course")
    try:
        with tempfile.NamedTemporaryFile(dir=path, prefix=".visla-edu-probe-"):
            pass
    except OSError as err:
        raise PermissionError(f"{folder}: cannot create files in this folder ({err.strerror or err}); choose a "
                              "folder you can write in, e.g. ~/visla-course") from None
    return path


def _create(path, shown):
    """``mkdir -p path``, its failures as one-line errors naming ``shown``."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(f"{shown}: cannot create this folder: a part of its path is a file, not a folder; "
                                 "choose another folder") from None
    except OSError as err:
        raise PermissionError(f"{shown}: cannot create this folder ({err.strerror or err}); choose a folder you can "
                              "write in, e.g. ~/visla-course") from None
