"""``load``: one entry point for course names, file paths and simulated drives."""

import os
from pathlib import Path

from visla_edu.data._groundtruth import attach_registered_ground_truth
from visla_edu.data._npz import load_npz
from visla_edu.data._registry import COURSE_NAMES, ENV_VAR, SIMULATED, resolve_dir
from visla_edu.data._standin import load_dataset10

__all__ = ["load"]


def load(name_or_path, data_dir=None):
    """Load a course file or a simulated drive as a :class:`~visla_edu.dataset.Dataset`.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A course name (``"03"``, ``"0022"``, ``"0020"``, ``"10"``: the file ``<data dir>/<name>.npz``),
        ``"sim"``, ``"sim-small"`` or ``"sim-tiny"`` (simulated with seed 0), or a path to
        an ``.npz`` file in either course format or written by :func:`~visla_edu.data.save`.
        ``"10"`` falls back to a stand-in when ``10.npz`` is absent: simulated stereo
        tracks on dataset 10's real IMU drive (``10_imu_only.npz`` + ``03.npz``'s rig).
    data_dir : str or os.PathLike, optional
        Folder of the course files, see :func:`~visla_edu.data.data_dir`.

    Returns
    -------
    Dataset
        Time-major arrays, sparse observations; ``source`` is the absolute file path and
        ``label`` describes known files (recognised by sha256). A drive whose KITTI ground
        truth the registry names (``"0020"``) gets it as ``ground_truth`` when its poses file
        is beside the npz (:func:`~visla_edu.data.attach_registered_ground_truth`).

    Raises
    ------
    FileNotFoundError
        The file is not there (the message says where it looked).
    ValueError
        The file is not a valid course file (the message names key, expected and actual).
    """
    if isinstance(name_or_path, os.PathLike) or _looks_like_path(name_or_path):
        return attach_registered_ground_truth(load_npz(_find_file(name_or_path, data_dir)))
    name = _check_name(name_or_path)
    if name in SIMULATED:
        from visla_edu import simulate  # lazy: simulation is optional for loading files

        return simulate.simulate_drive(preset=SIMULATED[name], seed=0)
    directory, how = resolve_dir(data_dir)
    if name == "10":
        return load_dataset10(directory, how)
    path = directory / f"{name}.npz"
    if not path.is_file():
        raise FileNotFoundError(_not_found_message(f"{name}.npz", directory, how))
    return attach_registered_ground_truth(load_npz(path))


def _looks_like_path(value):
    return isinstance(value, str) and (value.endswith(".npz") or "/" in value or os.sep in value)


def _check_name(value):
    if not isinstance(value, str):
        raise TypeError(f"load: expected a dataset name or a path, got {type(value).__name__} {value!r}")
    if not value.strip():
        raise ValueError("load: empty dataset name; use e.g. '03', '0022', '0020', '10' or 'sim'")
    return value.strip()


def _not_found_message(filename, directory, how):
    known = ", ".join(repr(n) for n in (*COURSE_NAMES, *SIMULATED))
    return (
        f"course file {filename} not found in {directory} (the data directory from {how}). "
        f"Set {ENV_VAR} to the folder with the course files or pass data_dir=...; "
        f"known names: {known}."
    )


def _find_file(path, data_dir):
    """An existing file given as a path: as given, else relative to the data directory."""
    given = Path(path).expanduser()
    if given.is_file():
        return given.resolve()
    directory, how = resolve_dir(data_dir)
    if not given.is_absolute() and (directory / given).is_file():
        return (directory / given).resolve()
    where = f"{given.resolve()}" if given.is_absolute() else f"{given.resolve()} nor in {directory} ({how})"
    raise FileNotFoundError(
        f"no data file {str(path)!r}: not found at {where}. "
        f"Set {ENV_VAR} to the folder with the course files or pass an existing path."
    )
