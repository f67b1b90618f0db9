"""``visla-edu release`` never overwrites a student notebook edited by hand (issue 22).

``release`` writes a manifest of what it wrote (:mod:`visla_edu.course.manifest`); a notebook
that no longer has its digest (an answered exercise) stops the release, which names it and
changes nothing (no notebook, no manifest, no points table) unless ``--force``.
"""

import re
import shutil

import nbformat
import pytest

import fuzzgen as fz  # tests/fuzzgen.py
from visla_edu.course import release
from visla_edu.course import STUDENT_NOTEBOOKS, manifest

SOLUTIONS = STUDENT_NOTEBOOKS.parents[2] / "solutions"


def _solution(path, answer):
    cell = nbformat.v4.new_code_cell(f"def f():\n    ### BEGIN SOLUTION\n    return {answer}\n    ### END SOLUTION")
    cell.metadata["nbgrader"] = {"grade": False, "grade_id": "f", "locked": False, "schema_version": 3,
                                 "solution": True, "task": False}
    nbformat.write(nbformat.v4.new_notebook(cells=[cell]), path)


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture
def course(tmp_path):
    """A small course (two solution notebooks, a guide with a points table), released once."""
    src, dst = tmp_path / "solutions", tmp_path / "notebooks"
    src.mkdir()
    for name in ("a", "b"):
        _solution(src / f"{name}.ipynb", 1)
    (tmp_path / "TEACHING.md").write_text(f"{release.POINTS_BEGIN}\nold\n{release.POINTS_END}\n", encoding="utf-8")
    assert [p.name for p in release.make_student_notebooks(src, dst)] == ["a.ipynb", "b.ipynb"]
    return src, dst


def _answer(path):
    """Answer the stub of a student notebook, as a student would."""
    text = path.read_text(encoding="utf-8")
    assert "raise NotImplementedError" in text
    path.write_text(text.replace('raise NotImplementedError(\\"f: write your solution here\\")', "return 1"),
                    encoding="utf-8")
    assert "return 1" in path.read_text(encoding="utf-8")


def test_release_records_what_it_wrote(course):
    _, dst = course
    recorded = manifest.read_manifest(dst)
    assert recorded == {name: manifest.digest((dst / name).read_bytes()) for name in ("a.ipynb", "b.ipynb")}
    assert manifest.edited_files(dst, ["a.ipynb", "b.ipynb", "new.ipynb"]) == []


def test_release_refuses_an_answered_notebook_and_changes_nothing(course, tmp_path, capsys):
    src, dst = course
    _answer(dst / "a.ipynb")
    for name in ("a", "b"):  # the teacher changed both solutions: b is due for a rewrite too
        _solution(src / f"{name}.ipynb", 2)
    before, guide = _snapshot(dst), (tmp_path / "TEACHING.md").read_bytes()
    line = fz.assert_one_line(fz.cli_run(["release", "--src", src, "--dst", dst], capsys, measure=False), 2,
                              r"notebooks: a\.ipynb differs from what release last wrote there .*nothing was written"
                              r".*--force")
    assert "b.ipynb" not in line
    assert _snapshot(dst) == before and (tmp_path / "TEACHING.md").read_bytes() == guide
    assert release.check_in_sync(src, dst) == ["a.ipynb", "b.ipynb", manifest.MANIFEST_NAME]  # --check reports


def test_release_force_replaces_the_edited_notebook(course, capsys):
    src, dst = course
    _answer(dst / "a.ipynb")
    fz.assert_ok(fz.cli_run(["release", "--src", src, "--dst", dst, "--force"], capsys, measure=False))
    assert "return 1" not in (dst / "a.ipynb").read_text(encoding="utf-8")
    assert release.check_in_sync(src, dst) == []


def test_release_replaces_its_own_stale_output(course):
    """A notebook exactly as release wrote it is no one's work: a newer release replaces it."""
    src, dst = course
    _solution(src / "b.ipynb", 2)
    assert [p.name for p in release.make_student_notebooks(src, dst)] == ["b.ipynb"]
    assert release.check_in_sync(src, dst) == []


def test_release_refuses_a_notebook_it_never_wrote(course):
    """Without a manifest entry (a folder of an older release, a file put there by hand), nothing is replaced."""
    src, dst = course
    (dst / manifest.MANIFEST_NAME).unlink()
    assert release.check_in_sync(src, dst) == [manifest.MANIFEST_NAME]
    assert release.make_student_notebooks(src, dst) == []  # identical notebooks: nothing to replace, manifest back
    _solution(src / "a.ipynb", 2)
    (dst / manifest.MANIFEST_NAME).unlink()
    with pytest.raises(ValueError, match=r"a\.ipynb differs"):
        release.make_student_notebooks(src, dst)


def test_a_damaged_manifest_is_named(course):
    src, dst = course
    _solution(src / "a.ipynb", 2)
    (dst / manifest.MANIFEST_NAME).write_text("{not json", encoding="utf-8")
    with pytest.raises(ValueError, match=r"\.release\.json: not a release manifest \(JSONDecodeError.*--force"):
        release.make_student_notebooks(src, dst)
    assert [p.name for p in release.make_student_notebooks(src, dst, force=True)] == ["a.ipynb"]
    assert release.check_in_sync(src, dst) == []


def test_python_m_release_refuses_too(course, capsys):
    src, dst = course
    _answer(dst / "b.ipynb")
    _solution(src / "b.ipynb", 2)
    assert release.main(["--src", str(src), "--dst", str(dst)]) == 2
    assert "b.ipynb differs" in capsys.readouterr().err
    assert release.main(["--src", str(src), "--dst", str(dst), "--force"]) == 0


def test_an_answered_course_notebook_survives_release(tmp_path, capsys):
    """The issue's case: a copy of the student edition with one exercise answered, released over."""
    dst = tmp_path / "notebooks"
    shutil.copytree(STUDENT_NOTEBOOKS, dst)
    stub = re.compile(r'raise NotImplementedError\(\\"\w+: write your solution here\\"\)')
    answered = next(p for p in sorted(dst.glob("*.ipynb")) if stub.search(p.read_text(encoding="utf-8")))
    answered.write_text(stub.sub("return 42  # my answer", answered.read_text(encoding="utf-8"), count=1),
                        encoding="utf-8")
    before = _snapshot(dst)
    fz.assert_one_line(fz.cli_run(["release", "--src", SOLUTIONS, "--dst", dst], capsys, measure=False), 2,
                       rf"{answered.name} differs from what release last wrote there")
    assert _snapshot(dst) == before
    outcome = fz.cli_run(["release", "--src", SOLUTIONS, "--dst", dst, "--check"], capsys, measure=False)
    assert outcome.code == 1 and f"drifted: {answered.name}" in outcome.out and _snapshot(dst) == before


def test_release_reads_the_checkouts_solutions_by_default(capsys):
    """``visla-edu release --check`` with no ``--src`` finds ``solutions/`` beside the package and
    the checked-in student edition in sync with it (the defaults of a source checkout)."""
    assert release.SOLUTIONS == SOLUTIONS and SOLUTIONS.is_dir()
    outcome = fz.cli_run(["release", "--check"], capsys, measure=False)
    assert outcome.code == 0, outcome.out + outcome.err
