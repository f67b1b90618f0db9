"""visla_edu._files: atomic writes and the checks of input files and output paths."""

import os
import stat

import pytest

from visla_edu import _files


def test_atomic_write_replaces_and_keeps_permissions(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    target.chmod(0o640)
    with _files.atomic_write(target, "w") as f:
        f.write("new ü")
    assert target.read_text(encoding="utf-8") == "new ü" and stat.S_IMODE(target.stat().st_mode) == 0o640
    assert os.listdir(tmp_path) == ["a.txt"]


def test_atomic_write_of_a_new_file_follows_the_umask(tmp_path):
    previous = os.umask(0o027)
    try:
        with _files.atomic_write(tmp_path / "b.bin", "wb") as f:
            f.write(b"\x00\x01")
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "b.bin").stat().st_mode) == 0o640


def test_a_failure_inside_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="midway"), _files.atomic_write(target, "w") as f:
        f.write("half of the new")
        raise RuntimeError("midway")
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["a.txt"]


def test_output_path_checks(tmp_path):
    source = tmp_path / "in.npz"
    source.write_bytes(b"x")
    assert _files.check_output_path(tmp_path / "out.npz", (".npz",), "--out", [source]) == tmp_path / "out.npz"
    with pytest.raises(ValueError, match=r"--out .*in.npz: is the input file"):
        _files.check_output_path(tmp_path / "." / "in.npz", (".npz",), "--out", [source])
    with pytest.raises(ValueError, match=r"must end in .png, .pdf or .svg; e.g. --plot .*map.png"):
        _files.check_output_path(tmp_path / "map.jpg2", (".png", ".pdf", ".svg"), "--plot")
    with pytest.raises(IsADirectoryError, match=r"is a directory; give a file name"):
        _files.check_output_path(tmp_path, (".npz",), "--out")
    with pytest.raises(FileNotFoundError, match=r"does not exist; create it first"):
        _files.check_output_path(tmp_path / "a" / "b.npz", (".npz",), "--out")


def test_input_file_kinds(tmp_path):
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "link").symlink_to(tmp_path / "gone")
    assert _files.file_kind(tmp_path / "pipe") == "a FIFO (named pipe)"
    with pytest.raises(ValueError, match=r"is a FIFO \(named pipe\), not a regular file"):
        _files.check_input_file(tmp_path / "pipe")
    with pytest.raises(FileNotFoundError, match=r"a broken symbolic link \(it points to"):
        _files.check_input_file(tmp_path / "link")
    with pytest.raises(IsADirectoryError):
        _files.check_input_file(tmp_path)
    with pytest.raises(FileNotFoundError, match=r"course file .*nothing: not found"):
        _files.check_input_file(tmp_path / "nothing", "course file")


def test_format_bytes():
    assert [_files.format_bytes(n) for n in (512, 3 * 2**20 + 2**19, 7 * 2**40)] == ["512 B", "3.5 MiB", "7.0 TiB"]


def test_a_folder_that_refuses_new_files_is_found_before_any_work(tmp_path, monkeypatch):
    """Permissions do not tell (root, /proc, read-only mounts): a probe file is created and removed."""
    import tempfile

    def refuse(*args, **kwargs):
        raise OSError(30, "Read-only file system")

    assert _files.check_output_path(tmp_path / "out.npz", (".npz",), "--out") == tmp_path / "out.npz"
    assert os.listdir(tmp_path) == []  # the probe leaves nothing behind
    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refuse)
    with pytest.raises(PermissionError, match=r"--out .*out.npz: cannot create a file in .* \(Read-only file system\)"):
        _files.check_output_path(tmp_path / "out.npz", (".npz",), "--out")


def test_expand_user_names_an_unknown_user(monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path))
    assert _files.expand_user("~/a.npz") == tmp_path / "a.npz" and _files.expand_user("b/c") == _files.Path("b/c")
    with pytest.raises(ValueError, match=r"~visla-edu-no-such-user-4711/a.npz: cannot expand "
                                         r"'~visla-edu-no-such-user-4711': no such user"):
        _files.expand_user("~visla-edu-no-such-user-4711/a.npz")
    with pytest.raises(ValueError, match="cannot expand"):  # every check of a path uses it
        _files.check_output_path("~visla-edu-no-such-user-4711/a.npz", (".npz",), "--out")


def test_atomic_write_without_replace_keeps_a_file_that_appears_meanwhile(tmp_path):
    target = tmp_path / "a.ipynb"
    with pytest.raises(FileExistsError, match="exists already; not replaced"):
        with _files.atomic_write(target, "wb", replace=False) as f:
            f.write(b"course")
            target.write_bytes(b"student")  # the student's save, while the copy is written
    assert target.read_bytes() == b"student" and os.listdir(tmp_path) == ["a.ipynb"]


def test_atomic_write_without_replace_and_without_hard_links(tmp_path, monkeypatch):
    def no_links(src, dst):
        raise OSError(1, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    with _files.atomic_write(tmp_path / "new.ipynb", "wb", replace=False) as f:
        f.write(b"course")
    assert (tmp_path / "new.ipynb").read_bytes() == b"course"
    with pytest.raises(FileExistsError):
        with _files.atomic_write(tmp_path / "new.ipynb", "wb", replace=False) as f:
            f.write(b"again")
    assert (tmp_path / "new.ipynb").read_bytes() == b"course" and os.listdir(tmp_path) == ["new.ipynb"]
