"""Shared fixtures. Course data is found through the environment variable VISLA_EDU_DATA."""

import os
from pathlib import Path

import pytest

DATA_ENV = "VISLA_EDU_DATA"


def _course_dir():
    """The folder named by VISLA_EDU_DATA, or None when unset."""
    value = os.environ.get(DATA_ENV, "").strip()
    return Path(value).expanduser().resolve() if value else None


def _require_course_file(name):
    """Path of course file ``<name>.npz``; skip the calling test when it is absent."""
    directory = _course_dir()
    filename = name if name.endswith(".npz") else f"{name}.npz"
    if directory is None or not (directory / filename).is_file():
        shown = directory if directory is not None else "(unset)"
        pytest.skip(
            f"course file {filename} not found in {DATA_ENV}={shown}; "
            f"set {DATA_ENV} to the folder with the course files"
        )
    return directory / filename


@pytest.fixture(scope="session")
def data_dir():
    """The course data folder from VISLA_EDU_DATA (the test is skipped when unset)."""
    directory = _course_dir()
    if directory is None or not directory.is_dir():
        pytest.skip(f"{DATA_ENV} is not set to an existing folder; set it to the folder with the course files")
    return directory


@pytest.fixture(scope="session")
def require_data():
    """``require_data("03")`` returns the path of ``03.npz`` or skips the test with the reason."""
    return _require_course_file
