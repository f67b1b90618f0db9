"""``visla-edu student DIR``: a student's folder that never loses work (issue 22).

It copies the student edition into DIR, and run again (after an update of the package) adds
only what is new and keeps every file already there, saying which. Its errors are one line
(exit 2), and an interrupted copy leaves no partial notebook.
"""

import os
import tempfile

import pytest

import fuzzgen as fz  # tests/fuzzgen.py
from visla_edu.course import STUDENT_NOTEBOOKS, manifest, student

NAMES = sorted(p.name for p in STUDENT_NOTEBOOKS.glob("*.ipynb"))


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_the_student_edition_is_discovered_not_listed():
    files = student.course_files()
    assert [name for name in files if name.endswith(".ipynb")] == NAMES and len(NAMES) >= 2
    assert files["README.md"] == student.STUDENT_README
    assert manifest.MANIFEST_NAME not in files


def test_a_student_folder_gets_the_edition_and_a_readme(tmp_path, capsys):
    folder = tmp_path / "new" / "alice"
    outcome = fz.cli_run(["student", folder], capsys, measure=False)
    fz.assert_ok(outcome)
    assert sorted(p.name for p in folder.iterdir()) == sorted([*NAMES, "README.md"])
    for name in NAMES:
        assert (folder / name).read_bytes() == (STUDENT_NOTEBOOKS / name).read_bytes()
    readme = (folder / "README.md").read_text(encoding="utf-8")
    assert "jupyter lab" in readme and "VISLA_EDU_DATA" in readme and "visla-edu student ." in readme
    assert outcome.out.splitlines()[0] == f"student folder {folder}: {len(NAMES) + 1} added, 0 kept (never overwritten)"
    assert f"  added  {NAMES[0]}" in outcome.out.splitlines()


def _newer_edition(tmp_path):
    """The student edition of a newer package: one notebook changed, a new notebook, a new page."""
    edition = tmp_path / "edition"
    edition.mkdir()
    for name in NAMES:
        (edition / name).write_bytes((STUDENT_NOTEBOOKS / name).read_bytes())
    (edition / NAMES[1]).write_bytes((STUDENT_NOTEBOOKS / NAMES[1]).read_bytes().replace(b"the", b"The", 1))
    (edition / "99_new.ipynb").write_bytes((STUDENT_NOTEBOOKS / NAMES[0]).read_bytes())
    (edition / "pages").mkdir()
    (edition / "pages" / "notation.md").write_text("# Notation\n", encoding="utf-8")
    (edition / manifest.MANIFEST_NAME).write_text("{}", encoding="utf-8")
    return edition


def test_run_again_after_an_update_adds_the_new_and_keeps_the_answered(tmp_path, capsys, monkeypatch):
    folder = tmp_path / "alice"
    fz.assert_ok(fz.cli_run(["student", folder], capsys, measure=False))
    answered = folder / NAMES[0]
    answered.write_text(answered.read_text(encoding="utf-8").replace("raise NotImplementedError", "pass  # mine", 1),
                        encoding="utf-8")
    mine = answered.read_bytes()
    monkeypatch.setattr(student, "STUDENT_NOTEBOOKS", _newer_edition(tmp_path))
    outcome = fz.cli_run(["student", folder], capsys, measure=False)
    fz.assert_ok(outcome)
    lines = outcome.out.splitlines()
    assert lines[0] == f"student folder {folder}: 2 added, {len(NAMES) + 1} kept (never overwritten)"
    assert "  added  99_new.ipynb" in lines and "  added  pages/notation.md" in lines
    assert any(line.startswith(f"  kept   {NAMES[0]} (differs from this edition's") for line in lines)
    # an older edition the student never touched is kept too
    assert any(line.startswith(f"  kept   {NAMES[1]} (differs from this edition's") for line in lines)
    assert f"  kept   {NAMES[2]} (as this edition has it)" in lines
    assert answered.read_bytes() == mine
    assert (folder / NAMES[1]).read_bytes() == (STUDENT_NOTEBOOKS / NAMES[1]).read_bytes()
    assert (folder / "pages" / "notation.md").is_file() and not (folder / manifest.MANIFEST_NAME).exists()


def _a_file(tmp_path):
    (tmp_path / "alice").write_text("x")
    return tmp_path / "alice"


def _under_a_file(tmp_path):
    (tmp_path / "file").write_text("x")
    return tmp_path / "file" / "alice"


@pytest.mark.parametrize("make, pattern", [
    (_a_file, r"alice: is a regular file, not a folder; give the name of a folder"),
    (_under_a_file, r"file/alice: cannot create this folder: a part of its path is a file"),
], ids=["file", "under-a-file"])
def test_a_folder_that_is_a_file_is_one_line(tmp_path, capsys, make, pattern):
    target = make(tmp_path)
    before = _snapshot(tmp_path)
    fz.assert_one_line(fz.cli_run(["student", target], capsys, measure=False), 2, pattern)
    assert _snapshot(tmp_path) == before


def test_a_folder_that_refuses_files_is_one_line(tmp_path, capsys, monkeypatch):
    """Permissions do not tell (root, read-only mounts): a probe file is created first."""
    def refuse(*args, **kwargs):
        raise OSError(30, "Read-only file system")

    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refuse)
    fz.assert_one_line(fz.cli_run(["student", tmp_path], capsys, measure=False), 2,
                       r"cannot create files in this folder \(Read-only file system\); choose a folder")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs a non-root POSIX user")
def test_a_read_only_parent_is_one_line(tmp_path, capsys):
    tmp_path.chmod(0o500)
    try:
        fz.assert_one_line(fz.cli_run(["student", tmp_path / "alice"], capsys, measure=False), 2,
                           r"alice: cannot create this folder \(Permission denied\)")
    finally:
        tmp_path.chmod(0o700)


def test_the_edition_itself_is_refused(capsys):
    fz.assert_one_line(fz.cli_run(["student", STUDENT_NOTEBOOKS], capsys, measure=False), 2,
                       r"is the course's own student edition")


def test_an_interrupted_copy_leaves_no_partial_notebook(tmp_path, monkeypatch):
    folder = tmp_path / "alice"
    monkeypatch.setattr(os, "fsync", lambda fd: (_ for _ in ()).throw(KeyboardInterrupt))
    with pytest.raises(KeyboardInterrupt):
        student.make_student_folder(folder)
    assert list(folder.iterdir()) == []  # no notebook, no temporary file
    monkeypatch.undo()
    assert len(student.make_student_folder(folder).added) == len(NAMES) + 1
