"""Tests of visla_edu.cache: the folder, the content key, atomic JSON files that never fail a run."""

import os

import numpy as np
import pytest

from visla_edu import cache


def test_cache_dir_precedence(tmp_path, monkeypatch):
    monkeypatch.setenv("VISLA_EDU_CACHE", str(tmp_path / "explicit"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "explicit"
    monkeypatch.setenv("VISLA_EDU_CACHE", "  ")  # empty counts as unset
    assert cache.cache_dir() == tmp_path / "xdg" / "visla-edu"
    monkeypatch.delenv("VISLA_EDU_CACHE")
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache.cache_dir() == tmp_path / "home" / ".cache" / "visla-edu"


def test_a_cache_folder_of_an_unknown_user_is_skipped(tmp_path, monkeypatch):
    """VISLA_EDU_CACHE=~nosuchuser/...: cache_dir names it; calibrate runs without the cache, creates nothing."""
    from visla_edu import diagnostics, simulate

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("VISLA_EDU_CACHE", "~visla-edu-no-such-user-4711/cache")
    with pytest.raises(ValueError, match=r"cannot expand '~visla-edu-no-such-user-4711': no such user"):
        cache.cache_dir()
    calibration = diagnostics.calibrate(simulate.simulate_drive("tiny", seed=0))
    assert calibration.source == "computed" and not list(tmp_path.iterdir())


def test_content_hash_follows_values_shapes_types_and_version():
    a = np.arange(12.0).reshape(3, 4)
    key = cache.content_hash({"a": a, "b": 0.5}, "v1")
    assert len(key) == 64 and key == cache.content_hash({"b": 0.5, "a": np.asfortranarray(a)}, "v1")
    changed = a.copy()
    changed[2, 3] = np.nextafter(changed[2, 3], np.inf)
    others = [cache.content_hash({"a": changed, "b": 0.5}, "v1"),
              cache.content_hash({"a": a.reshape(4, 3), "b": 0.5}, "v1"),
              cache.content_hash({"a": a.astype(np.float32), "b": 0.5}, "v1"),
              cache.content_hash({"a": a, "b": 0.5}, "v2"),
              cache.content_hash({"a2": a, "b": 0.5}, "v1")]
    assert len(set(others + [key])) == len(others) + 1


def test_save_and_load_round_trip_leave_no_temporary_files(tmp_path):
    path = tmp_path / "deep" / "entry.json"
    assert cache.save_json(path, {"x": [1.0, 2.0], "name": "n"})
    assert cache.load_json(path) == {"x": [1.0, 2.0], "name": "n"}
    assert cache.save_json(path, {"x": 3})  # replaced in one step
    assert cache.load_json(path) == {"x": 3}
    assert sorted(p.name for p in path.parent.iterdir()) == ["entry.json"]


@pytest.mark.parametrize("text", ["{broken", "[1, 2]", "", "\udcff"])
def test_corrupt_or_missing_files_read_as_nothing(tmp_path, text):
    path = tmp_path / "entry.json"
    assert cache.load_json(path) is None
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    assert cache.load_json(path) is None


def test_failures_to_write_return_false(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert cache.save_json(blocker / "sub" / "entry.json", {"x": 1}) is False
    # values JSON cannot hold (NaN is not JSON, objects are not serialisable): nothing written
    assert cache.save_json(tmp_path / "nan.json", {"x": float("nan")}) is False
    assert cache.save_json(tmp_path / "obj.json", {"x": object()}) is False
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs a non-root POSIX user")
def test_read_only_folder_returns_false(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        assert cache.save_json(folder / "entry.json", {"x": 1}) is False
        assert list(folder.iterdir()) == []
    finally:
        folder.chmod(0o700)
