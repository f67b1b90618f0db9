"""Shared fixtures. Course data is found through the environment variable VISLA_EDU_DATA.

The suite never writes to the user's cache folder: the calibration cache
(``VISLA_EDU_CACHE``, see :mod:`visla_edu.cache`) points at a temporary folder for the whole
session (which the notebook kernels and subprocesses inherit), and at each test's own
``tmp_path`` while that test runs.
"""

import os
import shutil
import tempfile
from pathlib import Path

import pytest

DATA_ENV = "VISLA_EDU_DATA"
CACHE_ENV = "VISLA_EDU_CACHE"
_session_cache = {}


def pytest_configure(config):
    """Point the calibration cache at a fresh temporary folder for the session."""
    _session_cache["previous"] = os.environ.get(CACHE_ENV)
    _session_cache["folder"] = tempfile.mkdtemp(prefix="visla-edu-test-cache-")
    os.environ[CACHE_ENV] = _session_cache["folder"]


def pytest_unconfigure(config):
    """Remove the session's cache folder and restore the variable."""
    folder = _session_cache.pop("folder", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
    previous = _session_cache.pop("previous", None)
    if previous is None:
        os.environ.pop(CACHE_ENV, None)
    else:
        os.environ[CACHE_ENV] = previous


@pytest.fixture(autouse=True)
def _private_calibration_cache(tmp_path, monkeypatch):
    """Each test caches calibrations in its own temporary folder."""
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "visla-edu-cache"))


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
