"""Tests of the course notebooks.

* ``solutions/`` is the single source and the student edition (``visla_edu/course/notebooks/``,
  :data:`visla_edu.course.STUDENT_NOTEBOOKS`) is generated from it: regenerating must reproduce
  it byte for byte, with its release manifest.
* Both are stored without outputs, each file under 1 MB.
* The solutions are well formed for nbgrader (unique grade ids, balanced markers, a graded
  check after every exercise, every check exists in ``visla_edu.course.checks`` and is called through a
  fresh copy of the checks, hidden tests in every notebook).
* Every student notebook runs top to bottom with errors only where an exercise is still a
  stub: in the stub cell itself or in the graded check right after it.

The solution notebooks themselves are executed by nbval (``python -m pytest --nbval-lax
solutions/``), so they are not executed a second time here. The notebooks read the course
data from ``VISLA_EDU_DATA`` (inherited by the kernel) and skip real-data cells without it.
"""

import re
from pathlib import Path

import nbformat
import pytest

from visla_edu.course import checks, release
from visla_edu.course import STUDENT_NOTEBOOKS, manifest

ROOT = Path(__file__).resolve().parents[1]
SOLUTIONS = ROOT / "solutions"
STUDENT = STUDENT_NOTEBOOKS
NAMES = sorted(p.name for p in SOLUTIONS.glob("*.ipynb"))
#: Reference pages (the notation page): no exercises, no code; exempt from the per-lesson checks.
REFERENCE_PAGES = [n for n in NAMES if release.is_reference_page(nbformat.read(str(SOLUTIONS / n), as_version=4))]
LESSONS = [n for n in NAMES if n not in REFERENCE_PAGES]
MAX_BYTES = 1_000_000
#: Seconds one notebook may take (the course budget is 5 minutes for all of them).
CELL_TIMEOUT = 600


def _read(path):
    return nbformat.read(str(path), as_version=4)


def _nbgrader(cell):
    return cell.metadata.get("nbgrader", {})


def _is_graded(cell):
    return bool(_nbgrader(cell).get("grade", False))


def _is_stub(cell):
    return cell.cell_type == "code" and "raise NotImplementedError" in cell.source


def test_there_are_notebooks():
    assert NAMES, f"no solution notebooks in {SOLUTIONS}"
    assert "01_se3_kinematics.ipynb" in NAMES


# --------------------------------------------------------------------------- (a) drift


def test_student_notebooks_in_sync():
    drifted = release.check_in_sync(SOLUTIONS, STUDENT)
    assert not drifted, (f"{STUDENT} is out of date for {drifted}: run `visla-edu release` "
                         "(never edit the student edition by hand)")


def test_regenerating_reproduces_student_notebooks_byte_for_byte(tmp_path):
    release.make_student_notebooks(SOLUTIONS, tmp_path)
    for name in NAMES:
        assert (tmp_path / name).read_bytes() == (STUDENT / name).read_bytes(), name
    assert (tmp_path / manifest.MANIFEST_NAME).read_bytes() == (STUDENT / manifest.MANIFEST_NAME).read_bytes()
    assert sorted(p.name for p in STUDENT.glob("*.ipynb")) == NAMES


def test_generation_is_deterministic(tmp_path):
    release.make_student_notebooks(SOLUTIONS, tmp_path / "a")
    release.make_student_notebooks(SOLUTIONS, tmp_path / "b")
    for name in NAMES:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert release.make_student_notebooks(SOLUTIONS, tmp_path / "a") == []  # nothing to rewrite


# --------------------------------------------------------------------------- (d) storage


@pytest.mark.parametrize("folder", [SOLUTIONS, STUDENT], ids=["solutions", "notebooks"])
@pytest.mark.parametrize("name", NAMES)
def test_stored_without_outputs_and_small(folder, name):
    path = folder / name
    assert path.stat().st_size < MAX_BYTES, f"{path} is {path.stat().st_size} bytes"
    nb = _read(path)
    nbformat.validate(nb)
    for index, cell in enumerate(nb.cells):
        if cell.cell_type == "code":
            assert cell.outputs == [], f"{path} cell {index} has outputs: run `python -m visla_edu.course.release --clean-sources`"
            assert cell.execution_count is None, f"{path} cell {index} has an execution count"
    assert nb.metadata["kernelspec"]["name"] == "python3"


# --------------------------------------------------------------------------- structure


def test_the_notation_page_is_the_reference_page_and_has_no_code():
    assert REFERENCE_PAGES == ["notation.ipynb"]
    for folder in (SOLUTIONS, STUDENT):
        nb = _read(folder / "notation.ipynb")
        assert all(c.cell_type == "markdown" for c in nb.cells), folder
        assert not any(_nbgrader(c) for c in nb.cells), folder


@pytest.mark.parametrize("name", LESSONS)
def test_solution_notebook_structure(name):
    nb = _read(SOLUTIONS / name)
    ids = [_nbgrader(c)["grade_id"] for c in nb.cells if _nbgrader(c)]
    assert len(ids) == len(set(ids)), f"{name}: duplicate grade ids {ids}"
    previous = None
    exercises = hidden = 0
    for index, cell in enumerate(nb.cells):
        meta = _nbgrader(cell)
        has_markers = release.BEGIN_SOLUTION in cell.source
        if has_markers:
            assert meta.get("solution"), f"{name} cell {index}: solution markers without nbgrader solution metadata"
            assert cell.source.count(release.BEGIN_SOLUTION) == cell.source.count(release.END_SOLUTION)
            exercises += 1
        if meta.get("solution"):
            assert not meta.get("locked"), f"{name} cell {index}: a solution cell must not be locked"
        if _is_graded(cell):
            assert meta.get("locked") and meta.get("points", 0) > 0, f"{name} cell {index}: graded cells are locked"
            assert previous is not None and release.BEGIN_SOLUTION in previous.source, (
                f"{name} cell {index}: a graded check must follow its exercise cell")
            _check_graded_cell(cell.source, f"{name} cell {index}")
            hidden += release.BEGIN_HIDDEN in cell.source
        if cell.cell_type == "code":
            previous = cell
    assert 2 <= exercises <= 4, f"{name}: {exercises} exercises (the course has 2-4 per notebook)"
    assert hidden >= 1, f"{name}: no graded cell has hidden tests ({release.BEGIN_HIDDEN})"


def _check_graded_cell(source, where):
    """A graded cell loads the checks fresh and calls them only through that fresh copy."""
    lines = [line for line in source.split("\n") if line.strip() and not line.startswith("###")]
    assert lines[0].startswith("import importlib, visla_edu.course.checks"), f"{where}: starts with {lines[0]!r}"
    assert lines[1] == "_checks = importlib.reload(visla_edu.course.checks)", f"{where}: no fresh checks: {lines[1]!r}"
    for line in lines[2:]:
        assert re.fullmatch(r"_checks\.check_\w+\(\w+(, hidden=True)?\)", line), (
            f"{where}: a graded cell only calls the fresh checks: {line!r}")
    called = re.findall(r"_checks\.(check_\w+)\(", source)
    assert called, f"{where}: a graded cell calls a visla_edu.course.checks function"
    for fn in called:
        assert fn in checks.__all__, f"{where}: checks.{fn} does not exist"


@pytest.mark.parametrize("name", LESSONS)
def test_student_notebook_has_stubs_and_no_solutions(name):
    nb = _read(STUDENT / name)
    text = "\n".join(c.source for c in nb.cells)
    assert release.BEGIN_SOLUTION not in text and release.BEGIN_HIDDEN not in text
    assert release.BEGIN_ANSWERS not in text, f"{name}: answers to the questions left in the student notebook"
    stubs = [c for c in nb.cells if _is_stub(c)]
    assert stubs, f"{name}: no exercise stubs"
    for cell in stubs:
        assert _nbgrader(cell).get("solution"), f"{name}: stub outside a solution cell"


# --------------------------------------------------------------------------- (c) execution


def _execute(path):
    from nbclient import NotebookClient

    nb = _read(path)
    client = NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3", allow_errors=True,
                            resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    return nb


def _errors(cell):
    return [o for o in cell.get("outputs", []) if o.output_type == "error"]


@pytest.mark.parametrize("name", NAMES)
def test_student_notebook_fails_only_at_stubs(name):
    nb = _execute(STUDENT / name)
    previous_code = None
    unexpected, silent_checks = [], []
    for index, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        after_stub = previous_code is not None and _is_stub(previous_code)
        errors = _errors(cell)
        for err in errors:
            allowed = (_is_stub(cell) and err.ename == "NotImplementedError") or (
                _is_graded(cell) and after_stub and err.ename in ("NotImplementedError", "AssertionError"))
            if not allowed:
                unexpected.append(f"cell {index} ({err.ename}: {err.evalue})\n{cell.source[:300]}")
        if _is_graded(cell) and after_stub and not errors:
            silent_checks.append(f"cell {index}: {cell.source[:120]}")
        previous_code = cell
    assert not unexpected, f"{name}: errors outside the exercises:\n" + "\n\n".join(unexpected)
    assert not silent_checks, f"{name}: these checks passed although the exercise is a stub:\n" + "\n".join(
        silent_checks)


#: Wrong answers that their check rejects, and the first cell that uses the answer after the check:
#: (notebook, grade id of the exercise, the wrong answer, id of the last cell to run).
_REJECTED_ANSWERS = [
    ("03_jacobians.ipynb", "numerical_jacobian",  # transposed: a (4, 3) Jacobian came back (3, 4)
     "def numerical_jacobian(f, x, eps=1e-6):\n    x = np.asarray(x, dtype=float)\n"
     "    return np.stack([(np.asarray(f(x + eps * e)) - np.asarray(f(x - eps * e))) / (2 * eps)"
     " for e in np.eye(x.size)])", "03-11"),
    ("05_landmark_mapping.ipynb", "landmark_update",  # world_T_imu where its inverse belongs
     "def landmark_update(m, Sigma, z, world_T_imu, Ks, cam_T_imu, noise_var):\n"
     "    q = cam_T_imu @ world_T_imu @ np.r_[m, 1.0]\n"
     "    H = Ks @ camera.projection_jacobian(q) @ cam_T_imu @ world_T_imu[:, :3]\n"
     "    K = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + noise_var * np.eye(4))\n"
     "    return m + K @ (z - Ks @ camera.projection(q)), (np.eye(3) - K @ H) @ Sigma", "05-12"),
    ("09_active_set.ipynb", "dense_covariance_bytes",  # the stride ignored
     "def dense_covariance_bytes(num_landmarks, stride=1):\n    return (6 + 3 * num_landmarks) ** 2 * 8", "09-08"),
]


@pytest.mark.parametrize("name, grade_id, wrong, last", _REJECTED_ANSWERS,
                         ids=[case[1] for case in _REJECTED_ANSWERS])
def test_an_answer_its_check_rejects_is_not_used_by_the_cells_after_it(name, grade_id, wrong, last):
    """The later cells fall back on the library (and say so) instead of running a rejected answer."""
    nb = _read(STUDENT / name)
    ids = [cell.get("id") for cell in nb.cells]
    nb.cells = nb.cells[:ids.index(last) + 1]
    for cell in nb.cells:
        if _nbgrader(cell).get("grade_id") == grade_id:
            cell.source = wrong
    from nbclient import NotebookClient

    NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3", allow_errors=True,
                   resources={"metadata": {"path": str(STUDENT)}}).execute()
    at = next(i for i, c in enumerate(nb.cells) if _nbgrader(c).get("grade_id") == f"check_{grade_id}")
    assert [e.ename for e in _errors(nb.cells[at])] == ["AssertionError"], f"{grade_id}: the check accepted it"
    after = [c for c in nb.cells[at + 1:] if c.cell_type == "code"]
    assert not any(_errors(c) for c in after), f"{name}: {[e.evalue for c in after for e in _errors(c)]}"
    printed = "".join(o.get("text", "") for c in after for o in c.outputs if o.output_type == "stream")
    assert f"using the library's {grade_id}" in printed, printed


# --------------------------------------------------------------------------- release.py units


def test_stub_keeps_signature_and_indentation():
    source = ('def f(x):\n    """Doc."""\n    ### BEGIN SOLUTION\n    y = x + 1\n    return y\n'
              '    ### END SOLUTION\n\nprint("after")')
    out = release.stub_source(source, what="f")
    assert out == ('def f(x):\n    """Doc."""\n    raise NotImplementedError("f: write your solution here")\n'
                   '\nprint("after")')


def test_stub_names_the_students_function_not_the_grade_id():
    source = ('class Filter:\n    def predict(self, x):\n        ### BEGIN SOLUTION\n        return x\n'
              '        ### END SOLUTION\n')
    out = release.stub_source(source, what="capstone_predict")
    assert 'raise NotImplementedError("predict: write your solution here")' in out
    top_level = "def f(x):\n    return x\n\n### BEGIN SOLUTION\ny = 2\n### END SOLUTION\n"
    assert 'NotImplementedError("grade-id: write' in release.stub_source(top_level, what="grade-id")


def test_markdown_stub_and_hidden_tests():
    assert release.stub_source("Why?\n### BEGIN SOLUTION\nBecause.\n### END SOLUTION", "markdown") == \
        "Why?\nYOUR ANSWER HERE"
    source = "check(f)\n### BEGIN HIDDEN TESTS\nassert f(1) == 2\n### END HIDDEN TESTS\n"
    assert release.strip_hidden_tests(source) == "check(f)"


def test_hidden_tests_in_the_middle_keep_the_end_of_the_cell():
    hidden = "### BEGIN HIDDEN TESTS\nassert f(1) == 2\n### END HIDDEN TESTS"
    assert release.strip_hidden_tests(f"check(f)\n{hidden}\nprint(f(3))\n\n") == "check(f)\nprint(f(3))\n\n"
    assert release.strip_hidden_tests(f"check(f)\n\n{hidden}\n\n") == "check(f)"  # at the end: blanks go


def test_answers_to_questions_are_replaced_in_markdown_only():
    nb = nbformat.v4.new_notebook()
    answers = f"**Answers**\n{release.BEGIN_ANSWERS}\n1. Because.\n{release.END_ANSWERS}\nEnd."
    nb.cells = [nbformat.v4.new_markdown_cell(answers), nbformat.v4.new_code_cell(f"# {release.BEGIN_ANSWERS}")]
    out = release.student_notebook(nb)
    assert out.cells[0].source == "**Answers**\nYOUR ANSWER HERE\nEnd."
    assert out.cells[1].source == nb.cells[1].source
    nb.cells[0].source = f"{release.BEGIN_ANSWERS}\n1. Because."
    with pytest.raises(ValueError, match="never closed"):
        release.student_notebook(nb, "demo.ipynb")


@pytest.mark.parametrize("source", [
    "### BEGIN SOLUTION\nx = 1",
    "x = 1\n### END SOLUTION",
    "### BEGIN SOLUTION\n### BEGIN SOLUTION\n### END SOLUTION",
])
def test_unbalanced_markers_are_reported(source):
    with pytest.raises(ValueError, match="cell 3"):
        release.stub_source(source, where="demo.ipynb cell 3")


def test_student_notebook_strips_outputs_and_keeps_metadata():
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("def g():\n    ### BEGIN SOLUTION\n    return 1\n    ### END SOLUTION")
    cell.metadata["nbgrader"] = {"grade": False, "grade_id": "g", "locked": False, "schema_version": 3,
                                 "solution": True, "task": False}
    cell.metadata["execution"] = {"iopub.status.busy": "2024-01-01"}
    cell.outputs = [nbformat.v4.new_output("stream", text="hi")]
    cell.execution_count = 3
    nb.cells = [cell]
    out = release.student_notebook(nb)
    assert out.cells[0].outputs == [] and out.cells[0].execution_count is None
    assert "execution" not in out.cells[0].metadata
    assert out.cells[0].metadata["nbgrader"]["grade_id"] == "g"
    assert 'raise NotImplementedError("g: write your solution here")' in out.cells[0].source
    assert nb.cells[0].outputs, "the input notebook is not modified"


def test_check_in_sync_reports_drift(tmp_path):
    release.make_student_notebooks(SOLUTIONS, tmp_path)
    assert release.check_in_sync(SOLUTIONS, tmp_path) == []
    first = tmp_path / NAMES[0]
    first.write_text(first.read_text(encoding="utf-8").replace("NotImplementedError", "NotImplemented"),
                     encoding="utf-8")
    (tmp_path / "zz_orphan.ipynb").write_text("{}", encoding="utf-8")
    (tmp_path / NAMES[-1]).unlink()
    assert release.check_in_sync(SOLUTIONS, tmp_path) == [NAMES[0], NAMES[-1], "zz_orphan.ipynb"]
    assert release.main(["--src", str(SOLUTIONS), "--dst", str(tmp_path), "--check"]) == 1


def test_command_line_writes_notebooks(tmp_path, capsys):
    assert release.main(["--src", str(SOLUTIONS), "--dst", str(tmp_path / "out")]) == 0
    assert sorted(p.name for p in (tmp_path / "out").glob("*.ipynb")) == NAMES
    assert release.main(["--src", str(SOLUTIONS), "--dst", str(tmp_path / "out"), "--check"]) == 0
    assert release.main(["--src", str(tmp_path / "missing"), "--dst", str(tmp_path / "out")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_command_line_refuses_check_with_clean_sources(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        release.main(["--src", str(SOLUTIONS), "--dst", str(tmp_path), "--check", "--clean-sources"])
    assert info.value.code == 2
    assert "--check and --clean-sources cannot be combined" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing written
