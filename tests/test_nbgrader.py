"""The real nbgrader grades the course: full marks, zero for the blank release, nothing for gaming.

In a temporary course directory this builds the assignment from ``solutions/``, runs
``nbgrader generate_assignment`` and ``nbgrader autograde`` (as a teacher would, through
``python -m nbgrader`` with an ``nbgrader_config.py`` in the course directory) and reads the
gradebook:

* the solutions get every point of the metadata;
* the untouched student release (``visla_edu/course/notebooks/``) gets zero;
* answers that call the library's own function (under its module name, an alias, a class
  method, or through a function that survives the checks' reload) get zero for those cells,
  and so do answer cells that replace the checks, the checks' machinery or a library function;
* nbgrader's own release of the solutions matches the student edition cell by cell (stubs aside).

To keep the runtime small the graded assignment holds each notebook's set-up cell and its
exercise and graded cells only (the demonstrations are executed by nbval on ``solutions/``),
the gamed submissions cover one notebook per hiding mechanism, and two copies of the course
(the solutions and the gamed answers; the blank release) are autograded side by side.
"""

import os
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import nbformat
import pytest

pytest.importorskip("nbgrader", reason="nbgrader is in the dev extra: pip install -e '.[dev]'")

from nbgrader.api import Gradebook  # noqa: E402

from visla_edu.course import release  # noqa: E402
from visla_edu.course import STUDENT_NOTEBOOKS  # noqa: E402

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
SOLUTIONS = ROOT / "solutions"
STUDENT = STUDENT_NOTEBOOKS
#: The graded notebooks (the notation page, a reference page without exercises, is not part of the assignment).
NAMES = sorted(p.stem for p in SOLUTIONS.glob("*.ipynb")
               if not release.is_reference_page(nbformat.read(str(p), as_version=4)))
ASSIGNMENT = "visla"

#: Gamed submissions: student -> (notebook, {answer cell grade id: its source}).
GAMED = {
    "calls_library": ("01_se3_kinematics", {
        "hat": "def hat(w):\n    return lie.hat(w)",
        "so3_exp": ("from visla_edu.lie import so3_exp as library_so3_exp\n\n\n"
                    "def so3_exp(w):\n    return library_so3_exp(w)"),
        "se3_exp": "def se3_exp(u):\n    return motion.predict_pose(np.eye(4), u, 1.0)",
    }),
    "tampers": ("01_se3_kinematics", {
        "hat": "def hat(w):\n    return np.zeros((3, 3))\n\n\nchecks.check_hat = lambda f, hidden=False: None",
        "so3_exp": ("import visla_edu.course.checks as c\n\n\ndef so3_exp(w):\n    return np.eye(3)\n\n\n"
                    "c.check_so3_exp = lambda f, hidden=False: print('\u2713 so3_exp')"),
        "se3_exp": ("import visla_edu.course.checks._core\n\n\ndef se3_exp(u):\n    return np.eye(4)\n\n\n"
                    "visla_edu.course.checks._core.compare = lambda *args, **kwargs: None"),
        "so3_log": "def so3_log(R):\n    return np.zeros(3)\n\n\nlie.so3_log = so3_log",
    }),
    "calls_method": ("02_stereo_camera", {
        "stereo_matrix": "def stereo_matrix(K, b):\n    return camera.stereo_matrix(K, b)",
        "project": ("def project(Ks, cam_T_imu, world_T_imu, p_world):\n"
                    "    K = np.array([[Ks[0, 0], 0, Ks[0, 2]], [0, Ks[1, 1], Ks[1, 2]], [0, 0, 1]])\n"
                    "    rig = StereoCamera(K, -Ks[2, 3] / Ks[0, 0], lie.se3_inv(cam_T_imu))\n"
                    "    return rig.predict(world_T_imu, p_world)"),
    }),
    "calls_reference": ("03_jacobians", {
        "numerical_jacobian": ("def numerical_jacobian(f, x, eps=1e-6):\n"
                               "    return checks.reference_numerical_jacobian(f, x, eps)"),
    }),
}


def _read(path):
    return nbformat.read(str(path), as_version=4)


def _write(nb, path):
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, str(path))


def _meta(cell):
    return cell.metadata.get("nbgrader", {})


def _exercises_only(nb):
    """The set-up cell (first code cell) and every nbgrader cell, in order."""
    first_code = next(i for i, c in enumerate(nb.cells) if c.cell_type == "code")
    nb.cells = [c for i, c in enumerate(nb.cells) if i == first_code or _meta(c)]
    return nb


def _points(name):
    """Check grade id -> points of one solution notebook (from its metadata)."""
    return {_meta(c)["grade_id"]: _meta(c)["points"] for c in _read(SOLUTIONS / f"{name}.ipynb").cells
            if _meta(c).get("grade")}


def _gamed_notebook(name, answers):
    nb = _exercises_only(_read(SOLUTIONS / f"{name}.ipynb"))
    for cell in nb.cells:
        if _meta(cell).get("grade_id") in answers:
            cell.source = answers[_meta(cell)["grade_id"]]
    return nb


def _nbgrader(course, *args):
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "nbgrader", *args], cwd=course, capture_output=True, text=True,
                          timeout=900, env=os.environ | {"PATH": _path_with_this_python()})
    assert done.returncode == 0, f"nbgrader {' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"
    return time.perf_counter() - started


def _path_with_this_python():
    """PATH with this interpreter's scripts first: nbgrader's gradebook runs the ``alembic`` script."""
    return os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])


def _build_course(course, students):
    """A course directory with the assignment's source and the submissions of ``students``."""
    (course / "nbgrader_config.py").write_text(
        "c = get_config()  # noqa: F821\n"
        "c.CourseDirectory.course_id = 'visla-edu'\n"
        "c.Execute.timeout = 300\n", encoding="utf-8")
    submitted = course / "submitted"
    for name in NAMES:
        solution = _exercises_only(_read(SOLUTIONS / f"{name}.ipynb"))
        _write(solution, course / "source" / ASSIGNMENT / f"{name}.ipynb")
        if "solutions" in students:
            _write(solution, submitted / "solutions" / ASSIGNMENT / f"{name}.ipynb")
        if "blank" in students:
            blank = _exercises_only(_read(STUDENT / f"{name}.ipynb"))
            _write(blank, submitted / "blank" / ASSIGNMENT / f"{name}.ipynb")
    for student in set(students) & set(GAMED):
        name, answers = GAMED[student]
        _write(_gamed_notebook(name, answers), submitted / student / ASSIGNMENT / f"{name}.ipynb")


def _autograde(course):
    """Seconds taken by ``nbgrader autograde`` of every submission in ``course``."""
    return _nbgrader(course, "autograde", ASSIGNMENT, "--force")


def _scores(course, students):
    """Student -> notebook -> grade id -> score, and the assignment's maximum, from the gradebook."""
    scores = {}
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("PATH", _path_with_this_python())
        with Gradebook(f"sqlite:///{course / 'gradebook.db'}", "visla-edu") as gradebook:
            for student in students:
                submission = gradebook.find_submission(ASSIGNMENT, student)
                scores[student] = {nb.name: {g.name: g.score for g in nb.grades} for nb in submission.notebooks}
                scores[student]["(max)"] = submission.max_score
    return scores


#: Two course directories, autograded side by side (nbgrader runs one notebook at a time).
GROUPS = (("solutions", *GAMED), ("blank",))


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """Build the courses, generate the assignment, autograde every submission: (course, scores)."""
    courses = [tmp_path_factory.mktemp(f"course{i}") for i in range(len(GROUPS))]
    for course, students in zip(courses, GROUPS):
        _build_course(course, students)
    seconds = {"generate_assignment": _nbgrader(courses[0], "generate_assignment", ASSIGNMENT, "--force")}
    for other in courses[1:]:  # the same assignment: its gradebook records the graded cells
        shutil.copy(courses[0] / "gradebook.db", other / "gradebook.db")
    with ThreadPoolExecutor(len(courses)) as pool:
        seconds["autograde"] = list(pool.map(_autograde, courses))
    print(f"nbgrader seconds: {seconds}")
    scores = {}
    for course, students in zip(courses, GROUPS):
        scores.update(_scores(course, students))
    return courses[0], scores


def test_solutions_get_every_point(graded):
    _, scores = graded
    expected = {name: _points(name) for name in NAMES}
    got = {name: scores["solutions"][name] for name in NAMES}
    assert got == expected
    total = sum(sum(points.values()) for points in expected.values())
    assert scores["solutions"]["(max)"] == total
    assert sum(sum(points.values()) for points in got.values()) == total


def test_blank_release_gets_zero(graded):
    _, scores = graded
    for name in NAMES:
        assert set(scores["blank"][name]) == set(_points(name)), name
        assert sum(scores["blank"][name].values()) == 0, (name, scores["blank"][name])


@pytest.mark.parametrize("student", list(GAMED))
def test_gamed_answers_get_no_points(graded, student):
    _, scores = graded
    name, answers = GAMED[student]
    points = _points(name)
    expected = {grade_id: (0 if grade_id.removeprefix("check_") in answers else value)
                for grade_id, value in points.items()}
    assert scores[student][name] == expected
    for other in NAMES:
        if other != name:  # notebooks not submitted score zero
            assert sum(scores[student][other].values()) == 0


def test_nbgrader_release_matches_the_student_notebooks(graded):
    """nbgrader's release and the student edition agree on the set-up, exercise and graded cells."""
    course, _ = graded
    for name in NAMES:
        ours = _exercises_only(_read(STUDENT / f"{name}.ipynb")).cells
        theirs = _read(course / "release" / ASSIGNMENT / f"{name}.ipynb").cells
        assert [c.cell_type for c in theirs] == [c.cell_type for c in ours], name
        for index, (mine, nbg) in enumerate(zip(ours, theirs)):
            where = f"{name} cell {index}"
            assert _meta(mine).get("grade_id") == _meta(nbg).get("grade_id"), where
            if _meta(mine).get("solution"):  # both replaced the solution by a stub
                stub = "raise NotImplementedError" if mine.cell_type == "code" else "YOUR ANSWER HERE"
                assert stub in mine.source and stub in nbg.source, where
                assert release.BEGIN_SOLUTION not in nbg.source, where
            else:
                assert mine.source.strip() == nbg.source.strip(), where
