"""Atomic file writes and result directories: complete or absent, never half-written."""

from __future__ import annotations

import os
import stat

import pytest

from clothlab.atomic import atomic_directory, atomic_write_bytes, atomic_write_text
from clothlab.errors import ResultExistsError


def hidden(directory):
    return sorted(p.name for p in directory.iterdir() if p.name.startswith("."))


def test_write_text_creates_and_replaces(tmp_path):
    path = tmp_path / "sub" / "a.txt"
    assert atomic_write_text(path, "first\n") == path
    assert path.read_text() == "first\n"
    atomic_write_text(path, "second ü\r\n")
    assert path.read_bytes() == "second ü\r\n".encode()
    assert hidden(path.parent) == []


def test_written_file_has_normal_permissions(tmp_path):
    path = atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    mask = os.umask(0o022)
    os.umask(mask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask


def test_failed_write_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "c.txt"
    path.write_text("old")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_text(path, "new")
    assert path.read_text() == "old"
    assert hidden(tmp_path) == []


def test_directory_created_on_success(tmp_path):
    dest = tmp_path / "fits" / "run"
    with atomic_directory(dest) as work:
        assert work.parent == dest.parent and work.name.startswith(".")
        assert not dest.exists()
        (work / "params.json").write_text("{}")
    assert (dest / "params.json").read_text() == "{}"
    assert hidden(dest.parent) == []


def test_existing_directory_refused_before_any_work(tmp_path):
    dest = tmp_path / "run"
    dest.mkdir()
    (dest / "keep").write_text("old")
    ran = []
    with pytest.raises(ResultExistsError, match="--force") as info:
        with atomic_directory(dest):
            ran.append(True)
    assert not ran
    assert str(dest) in str(info.value)
    assert (dest / "keep").read_text() == "old"
    assert hidden(tmp_path) == []


def test_force_replaces_only_after_completion(tmp_path):
    dest = tmp_path / "run"
    dest.mkdir()
    (dest / "old").write_text("old")
    with atomic_directory(dest, force=True) as work:
        assert (dest / "old").read_text() == "old"  # still there while the new result is built
        (work / "new").write_text("new")
    assert sorted(p.name for p in dest.iterdir()) == ["new"]
    assert hidden(tmp_path) == []


@pytest.mark.parametrize("existing", [False, True])
def test_exception_leaves_old_result_and_no_temp_dirs(tmp_path, existing):
    dest = tmp_path / "run"
    if existing:
        dest.mkdir()
        (dest / "old").write_text("old")
    with pytest.raises(RuntimeError, match="fit diverged"):
        with atomic_directory(dest, force=True) as work:
            (work / "partial").write_text("half")
            raise RuntimeError("fit diverged")
    if existing:
        assert sorted(p.name for p in dest.iterdir()) == ["old"]
        assert (dest / "old").read_text() == "old"
    else:
        assert not dest.exists()
    assert hidden(tmp_path) == []


def test_directory_appearing_during_work_is_not_clobbered(tmp_path):
    dest = tmp_path / "run"
    with pytest.raises(ResultExistsError):
        with atomic_directory(dest) as work:
            (work / "new").write_text("new")
            dest.mkdir()
            (dest / "other").write_text("someone else's")
    assert sorted(p.name for p in dest.iterdir()) == ["other"]
    assert hidden(tmp_path) == []
