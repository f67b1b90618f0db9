"""A student's own working folder, ``visla-edu student DIR``: course files that are never overwritten.

Students work in a folder of their own (TEACHING.md, section 1), not in a clone, where ``visla-edu
release`` regenerates the notebooks beside the solutions. :func:`make_student_folder` copies into
it the student edition the package carries and a short ``README.md``, keeping any file already
there as it is (the student's answers, or an older edition): after an upgrade it only adds what
is new. Each file is written atomically and only under a name nothing has
(:func:`visla_edu._files.atomic_write` with ``replace=False``): an interruption leaves no half
notebook, and a file that appears while copying is not replaced either.

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

    Attributes
    ----------
    added : tuple of str
        Files copied now (paths relative to ``folder``, with ``/``), as the other two.
    kept, kept_different : tuple of str
        Files that were there already, with the same content as this edition's, or with another
        (the student's work, or an older edition), left as they are.
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

    Every regular file of ``source`` and its subfolders, whatever its name, except hidden names
    (``.release.json``, ``.ipynb_checkpoints/``...) and ``__pycache__``; ``README.md`` is
    :data:`visla_edu.course.STUDENT_README` unless the edition has a file of that name.

    Parameters
    ----------
    source : str or os.PathLike, optional
        The student edition (default :data:`visla_edu.course.STUDENT_NOTEBOOKS`); a
        FileNotFoundError if it holds no notebook (a broken installation).
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

    A file already in ``folder`` (or anything else under its name: a folder, a link) is never
    replaced; the :class:`FolderUpdate` returned says what was added and kept.

    Parameters
    ----------
    folder : str or os.PathLike
        The student's folder (``~`` expanded); created, with its parents, if missing.
    source : str or os.PathLike, optional
        The student edition (:func:`course_files`).

    Raises
    ------
    NotADirectoryError, PermissionError
        ``folder``, or a folder on its path, is a file; ``folder`` cannot be created or written in.
    ValueError, FileNotFoundError
        ``folder`` is the student edition itself; the student edition is missing.
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
