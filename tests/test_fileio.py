"""``atomic_write`` / ``atomic_open``: complete new content or the old one, fsynced file and directory."""

from __future__ import annotations

import os
import stat

import pytest

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_open, atomic_write


def test_writes_text_and_bytes_with_the_usual_permissions(tmp_path):
    umask = os.umask(0o022)
    try:
        assert atomic_write(tmp_path / "a.json", '{"x": 1}\n').read_text() == '{"x": 1}\n'
        atomic_write(tmp_path / "b.bin", b"\x00\x01")
    finally:
        os.umask(umask)
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert stat.S_IMODE((tmp_path / "a.json").stat().st_mode) == 0o644  # not mkstemp's 0600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.bin"]


def test_a_failed_write_keeps_the_old_content_and_leaves_no_temp_file(tmp_path):
    path = tmp_path / "results.json"
    atomic_write(path, "old")
    with pytest.raises(RuntimeError), atomic_open(path) as f:
        f.write("half of the new")
        raise RuntimeError("disk full")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["results.json"]


def test_the_file_and_its_directory_are_fsynced(tmp_path, monkeypatch):
    synced: list[str] = []
    real = os.fsync
    monkeypatch.setattr(fileio.os, "fsync", lambda fd: (synced.append(os.readlink(f"/proc/self/fd/{fd}")), real(fd)))
    atomic_write(tmp_path / "sub" / "x.txt", "x", parents=True)
    assert synced[0].startswith(str(tmp_path / "sub" / ".x.txt.")) and synced[1] == str(tmp_path / "sub")
