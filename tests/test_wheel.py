"""The wheel a student installs: the student edition inside, nothing of the solutions.

The wheel is built from a copy of the project (``pip wheel --no-deps``, as a teacher builds it,
solutions and tests included in the copy, so their absence from the wheel is the packaging's
doing), once per session; the checks then read its file list and its notebooks, and run
``visla-edu student`` from the unpacked wheel alone. Building takes a few seconds (pip fetches
the build requirements, setuptools and wheel, from the package index); without an index that
has them the tests are skipped, saying so.
"""

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from visla_edu.course import release
from visla_edu.course import STUDENT_NOTEBOOKS

ROOT = Path(__file__).resolve().parents[1]
EDITION = "visla_edu/course/notebooks/"
#: Marker lines that must not survive into anything a student gets.
MARKERS = (release.BEGIN_SOLUTION, release.END_SOLUTION, release.BEGIN_HIDDEN, release.END_HIDDEN,
           release.BEGIN_ANSWERS, release.END_ANSWERS)
_NOT_COPIED = shutil.ignore_patterns(".git", ".venv", "__pycache__", "*.egg-info", "build", "dist", ".pytest_cache",
                                     ".hypothesis", ".ipynb_checkpoints", "data", "out")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The path of the wheel built from a copy of the project."""
    work = tmp_path_factory.mktemp("wheel")
    shutil.copytree(ROOT, work / "project", ignore=_NOT_COPIED)
    assert (work / "project" / "solutions").is_dir() and (work / "project" / "tests" / "answers.py").is_file()
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(work / "dist"),
                           str(work / "project")], capture_output=True, text=True, timeout=600)
    if done.returncode and "satisfies the requirement setuptools" in done.stdout + done.stderr:
        pytest.skip("pip cannot fetch the build requirements (setuptools, wheel): no package index")
    assert done.returncode == 0, done.stdout + done.stderr
    (built,) = (work / "dist").glob("visla_edu-*.whl")
    return built


@pytest.fixture(scope="module")
def names(wheel):
    with zipfile.ZipFile(wheel) as archive:
        return archive.namelist()


def test_the_wheel_holds_the_student_edition(wheel, names):
    expected = sorted(p.name for p in STUDENT_NOTEBOOKS.iterdir() if p.is_file() and not p.name.startswith("."))
    assert sorted(n[len(EDITION):] for n in names if n.startswith(EDITION)) == expected
    assert any(name.endswith(".ipynb") for name in expected)
    with zipfile.ZipFile(wheel) as archive:
        for name in expected:
            assert archive.read(EDITION + name) == (STUDENT_NOTEBOOKS / name).read_bytes(), name
    assert "visla_edu/course/student_readme.md" in names


def test_the_wheel_holds_nothing_of_the_solutions(names):
    assert not [n for n in names if n.startswith(("solutions/", "tests/")) or "/solutions/" in n or "/tests/" in n]
    assert not [n for n in names if "answers" in n.lower()]
    assert not [n for n in names if n.endswith(".release.json")]  # the teacher's bookkeeping stays home


def _lines(archive, name):
    """The lines a student reads in a file of the wheel: a notebook's cell sources, another file's text."""
    text = archive.read(name).decode("utf-8", errors="replace")
    if not name.endswith(".ipynb"):
        return text.splitlines()
    cells = json.loads(text)["cells"]
    return [line for cell in cells for line in "".join(cell["source"]).splitlines()]


def test_no_marker_line_and_nothing_between_markers_anywhere_in_the_wheel(wheel, names):
    with zipfile.ZipFile(wheel) as archive:
        found = [f"{name}: {line.strip()}" for name in names if not name.endswith((".pyc", ".png"))
                 for line in _lines(archive, name) if line.strip() in MARKERS]
    assert not found, found


def test_an_installed_wheel_makes_a_student_folder(wheel, tmp_path):
    """The unpacked wheel alone (no checkout on the path) gives ``visla-edu student`` everything it copies."""
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as archive:
        archive.extractall(site)
    code = ("import sys, visla_edu; from visla_edu import cli; print(visla_edu.__file__); "
            "sys.exit(cli.main(['student', sys.argv[1]]))")
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path / "alice")], capture_output=True, text=True,
                          cwd=tmp_path, env={"PYTHONPATH": str(site), "PATH": ""}, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == str(site / "visla_edu" / "__init__.py")
    made = sorted(p.name for p in (tmp_path / "alice").iterdir())
    assert made == sorted([*(p.name for p in STUDENT_NOTEBOOKS.glob("*.ipynb")), "README.md"])
