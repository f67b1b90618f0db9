"""``load``: one entry point for course names, file paths and simulated drives."""

import os
from pathlib import Path

from visla_edu._files import expand_user, file_kind
from visla_edu.data._format2025 import load_course2025
from visla_edu.data._groundtruth import attach_registered_ground_truth
from visla_edu.data._npz import load_npz
from visla_edu.data._registry import (COURSE2025_NAME, COURSE_NAMES, ENV_VAR, REGISTRY, SIMULATED, STANDIN_INPUTS,
                                      course2025_files, ground_truth_files, resolve_dir)
from visla_edu.data._standin import load_dataset10

__all__ = ["load", "input_files"]


def load(name_or_path, data_dir=None):
    """Load a course file or a simulated drive as a :class:`~visla_edu.dataset.Dataset`.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A course name (``"03"``, ``"0022"``, ``"0020"``, ``"0042"``, ``"10"``: ``<data dir>/<name>.npz``;
        ``"datasetNN"``: ``<data dir>/datasetNN/datasetNN.npy``, else ``<data dir>/datasetNN.npy``),
        ``"sim"``, ``"sim-small"`` or ``"sim-tiny"`` (simulated with seed 0), or the path of a file
        in a course format of :mod:`visla_edu.data` (``.npy``: 2025+) or written by
        :func:`~visla_edu.data.save`. ``"10"`` without ``10.npz`` is the stand-in
        (:func:`~visla_edu.data.course_standin10` with seed 0).
    data_dir : str or os.PathLike, optional
        See :func:`~visla_edu.data.data_dir`.

    Returns
    -------
    Dataset
        ``source`` is the absolute file path, ``label`` describes known files (recognised by sha256); a registered
        drive gets its KITTI ground truth beside it (:func:`~visla_edu.data.attach_registered_ground_truth`).

    Raises
    ------
    NotADirectoryError, TypeError, ValueError
        The data directory is not a folder; ``name_or_path`` is neither a string nor a path, or empty.
    """
    if isinstance(name_or_path, os.PathLike) or _looks_like_path(name_or_path):
        return _load_file(_find_file(name_or_path, data_dir))
    name = _check_name(name_or_path)
    if name in SIMULATED:
        from visla_edu import simulate  # lazy: simulation is optional for loading files

        return simulate.simulate_drive(preset=SIMULATED[name], seed=0)
    directory, how = resolve_dir(data_dir)
    _check_data_dir(directory, how)
    if name == "10":
        return load_dataset10(directory, how)
    if COURSE2025_NAME.match(name):
        found = [p for p in course2025_files(name, directory) if os.path.lexists(p)]
        if not found:
            raise FileNotFoundError(_not_found_message(f"{name}/{name}.npy (or {name}.npy)", directory, how))
        return load_course2025(found[0])
    path = directory / f"{name}.npz"
    if not os.path.lexists(path):
        raise FileNotFoundError(_not_found_message(f"{name}.npz", directory, how))
    return attach_registered_ground_truth(load_npz(path))


def _load_file(path):
    """A course file by its suffix: ``.npy`` the 2025+ format, anything else an ``.npz``."""
    if path.suffix.lower() == ".npy":
        return load_course2025(path)
    return attach_registered_ground_truth(load_npz(path))


def input_files(name_or_path, data_dir=None):
    """The existing files (list of pathlib.Path) :func:`load` would read, so that a caller can refuse to overwrite them.

    ``name_or_path`` and ``data_dir`` as in :func:`load`: a relative path counts both as given and under the data
    directory, ``"10"`` adds the stand-in's inputs, ``"datasetNN"`` both places of its ``.npy``; a simulated drive
    or anything else gives none. The candidates that exist come as built (not resolved), then every registered
    KITTI ground-truth file in the folder of each of them.
    """
    if isinstance(name_or_path, os.PathLike) or _looks_like_path(name_or_path):
        given = expand_user(name_or_path)
        directory = resolve_dir(data_dir)[0]
        candidates = [given] if given.is_absolute() else [given, directory / given]
    elif isinstance(name_or_path, str) and name_or_path.strip() in COURSE_NAMES:
        directory = resolve_dir(data_dir)[0]
        name = name_or_path.strip()
        candidates = [directory / f"{name}.npz"] + ([directory / f for f in STANDIN_INPUTS] if name == "10" else [])
    elif isinstance(name_or_path, str) and COURSE2025_NAME.match(name_or_path.strip()):
        candidates = course2025_files(name_or_path.strip(), resolve_dir(data_dir)[0])
    else:
        candidates = []
    files = [c for c in candidates if c.exists()]
    for npz in list(files):
        files.extend(_registered_ground_truth_beside(npz))
    return files


def _registered_ground_truth_beside(npz):
    """Every registered ground-truth file beside ``npz`` (a drive is recognised by content, not name)."""
    return [f for name in REGISTRY for f in ground_truth_files(name, npz.parent) or () if f is not None]


def _looks_like_path(value):
    return isinstance(value, str) and (value.endswith((".npz", ".npy")) or "/" in value or os.sep in value)


def _check_name(value):
    if not isinstance(value, str):
        raise TypeError(f"load: expected a dataset name or a path, got {type(value).__name__} {value!r}")
    if not value.strip():
        raise ValueError("load: empty dataset name; use e.g. '03', '0022', '0020', '10', 'dataset01' or 'sim'")
    return value.strip()


def _not_found_message(filename, directory, how):
    known = ", ".join(repr(n) for n in (*COURSE_NAMES, *SIMULATED)) + ", 'datasetNN' (2025+ files)"
    here = (f" A file {filename} is in the current folder: give it as a path, ./{filename}."
            if Path(filename).is_file() else "")
    return (
        f"course file {filename} not found in {directory} (the data directory from {how}). "
        f"Set {ENV_VAR} to the folder with the course files or pass data_dir=... (--data-dir on the command "
        f"line); known names: {known}.{here}"
    )


def _check_data_dir(directory, how):
    """The data directory, if it exists, must be a folder."""
    kind = file_kind(directory)
    if kind not in ("missing", "a directory"):
        raise NotADirectoryError(f"the data directory {directory} (from {how}) is {kind}, not a folder; "
                                 f"set {ENV_VAR} or --data-dir to the folder with the course files")


def _find_file(path, data_dir):
    """A path as given if anything is there, else relative to the data directory (load_npz checks its kind)."""
    given = expand_user(path)
    if os.path.lexists(given):
        return given
    directory, how = resolve_dir(data_dir)
    if not given.is_absolute() and os.path.lexists(directory / given):
        return directory / given
    where = f"{given.resolve()}" if given.is_absolute() else f"{given.resolve()} nor in {directory} ({how})"
    raise FileNotFoundError(
        f"no data file {str(path)!r}: not found at {where}. "
        f"Set {ENV_VAR} to the folder with the course files or pass an existing path."
    )
