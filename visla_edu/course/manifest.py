"""What ``visla-edu release`` last wrote into a folder: ``.release.json``, one sha256 per file.

Written beside the student notebooks (:func:`visla_edu.course.release.make_student_notebooks`) and
committed; release refuses (unless forced) to replace a file whose digest is not the recorded one.
Format: ``{"about": "...", "sha256": {file name: 64 hexadecimal digits}}``, sorted keys, two-space
indentation, final newline (same bytes for same notebooks: the in-sync test checks it); digests are of
the UTF-8 bytes.
"""

import hashlib
import json
from pathlib import Path

from visla_edu._files import atomic_write

__all__ = ["MANIFEST_NAME", "digest", "manifest_text", "read_manifest", "write_manifest", "edited_files"]

#: The manifest's file name, in the folder of the notebooks it describes (hidden: not for students).
MANIFEST_NAME = ".release.json"

_ABOUT = ("sha256 of each file `visla-edu release` wrote in this folder; release refuses to overwrite a file whose "
          "content no longer has its digest (edited by hand) unless --force")


def digest(data):
    """The sha256 of ``data``, bytes or str (encoded as UTF-8: the bytes release writes), as 64 hexadecimal digits."""
    return hashlib.sha256(data.encode("utf-8") if isinstance(data, str) else data).hexdigest()


def manifest_text(texts):
    """The manifest (str, the module docstring's format) of files with contents ``texts``: file name -> text."""
    body = {"about": _ABOUT, "sha256": {name: digest(text) for name, text in sorted(texts.items())}}
    return json.dumps(body, indent=2, sort_keys=True) + "\n"


def read_manifest(folder):
    """The digests recorded in ``folder``'s manifest: file name -> sha256, ``{}`` without a manifest.

    ValueError if the manifest is not valid JSON or lacks its ``sha256`` table.
    """
    path = Path(folder) / MANIFEST_NAME
    if not path.is_file():
        return {}
    try:
        table = json.loads(path.read_text(encoding="utf-8"))["sha256"]
    except (ValueError, KeyError, TypeError) as err:
        table, problem = None, f"{type(err).__name__}: {err}"
    else:
        problem = "its 'sha256' entry is not a table of file names and digests"
    if not isinstance(table, dict) or not all(isinstance(v, str) for v in table.values()):
        raise ValueError(f"{path}: not a release manifest ({problem}); check the notebooks beside it by hand "
                         "(git diff), then run release with --force, which rewrites it")
    return table


def write_manifest(folder, texts):
    """Write ``folder``'s manifest for ``texts`` (file name -> text), atomically, if it changes; True if it did."""
    path = Path(folder) / MANIFEST_NAME
    text = manifest_text(texts)
    if path.is_file() and path.read_bytes() == text.encode("utf-8"):
        return False
    with atomic_write(path, "wb") as f:
        f.write(text.encode("utf-8"))
    return True


def edited_files(folder, names):
    """The files among ``names`` in ``folder`` that release did not write as they are now, in that order.

    Existing non-regular files, or digests not the manifest's (or unlisted); a missing file is never edited.
    ValueError for a damaged manifest.
    """
    folder = Path(folder)
    recorded = read_manifest(folder)
    edited = []
    for name in names:
        path = folder / name
        if not (path.exists() or path.is_symlink()):
            continue
        if not path.is_file() or digest(path.read_bytes()) != recorded.get(name):
            edited.append(name)
    return edited
