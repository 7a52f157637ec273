"""Archive packing and the refusals of unsafe or corrupt archives."""

from __future__ import annotations

import tarfile

import pytest

from molmo_lerobot.resources import CorruptArchiveError, ResourceManager, UnsafeArchiveError, pack
from molmo_lerobot.resources.archive import pack_archive, safe_extract, tree_entries

DEPTH = "../" * 7  # from <cache>/.molmo/objects/evil/1/tmp/x-*/ up to tmp_path


def test_pack_is_deterministic_and_roundtrips(src_tree, tmp_path, read_tree):
    entries = tree_entries(src_tree)
    a = pack_archive(src_tree, list(entries), tmp_path / "a.tar.zst")
    b = pack_archive(src_tree, list(entries), tmp_path / "b.tar.zst")
    assert a == b
    names = safe_extract(tmp_path / "a.tar.zst", tmp_path / "out", "a")
    assert set(names) == set(entries)
    assert read_tree(tmp_path / "out") == read_tree(src_tree)
    assert (tmp_path / "out" / "mug_02" / "same.xml").is_symlink()


def test_pack_refuses_link_leaving_tree(src_tree, tmp_path):
    (src_tree / "escape").symlink_to(tmp_path)
    with pytest.raises(Exception, match="points outside"):
        pack(src_tree, tmp_path / "remote", "objects/x@1")


def _outside_untouched(tmp_path):
    cache = tmp_path / "cache"
    stray = [p for p in tmp_path.rglob("*") if "evil" in p.name and cache not in p.parents and "remote" not in p.parts]
    assert stray == []


@pytest.mark.parametrize(
    "members, match",
    [
        ([("ok.txt", b"ok", tarfile.REGTYPE, ""), (DEPTH + "evil.txt", b"x", tarfile.REGTYPE, "")], r"'\.\.'"),
        ([("/tmp/evil_abs.txt", b"x", tarfile.REGTYPE, "")], "absolute path"),
        ([("link", None, tarfile.SYMTYPE, DEPTH), ("link/evil.txt", b"x", tarfile.REGTYPE, "")], "symlink .* outside"),
        ([("link", None, tarfile.SYMTYPE, "/etc")], "symlink .* outside"),
        ([("hard", None, tarfile.LNKTYPE, DEPTH + "evil_target")], "hard link .* outside"),
        ([("dev", None, tarfile.CHRTYPE, "")], "device"),
    ],
    ids=["traversal", "absolute", "symlink-escape", "symlink-absolute", "hardlink-escape", "device"],
)
def test_unsafe_archives_are_refused(members, match, craft_version, tar_member, tmp_path):
    remote = craft_version([tar_member(*member) for member in members])
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", remote, progress=False)
    with pytest.raises(UnsafeArchiveError, match=match) as err:
        mgr.install("objects/evil@1")
    assert "evil-1-00000.tar.zst" in str(err.value) and "\n" not in str(err.value)
    _outside_untouched(tmp_path)
    assert not (tmp_path / "evil.txt").exists()
    assert not mgr.is_complete("objects/evil@1")
    assert list((tmp_path / "cache" / "objects" / "evil" / "1").rglob("*")) == []  # nothing moved into place
    assert not (tmp_path / "install" / "objects").exists()


def test_corrupted_archive_is_refused_before_extraction(craft_version, tar_member, tmp_path):
    remote = craft_version([tar_member("ok.txt", b"ok")], corrupt=True)
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", remote, progress=False)
    with pytest.raises(CorruptArchiveError, match=r"sha256 .* refusing to extract"):
        mgr.install("objects/evil@1")
    assert list((tmp_path / "cache" / "objects").rglob("*.txt")) == []
    tmp_left = tmp_path / "cache" / ".molmo" / "objects" / "evil" / "1" / "tmp"
    assert not tmp_left.exists() or list(tmp_left.iterdir()) == []


def test_archive_contents_must_match_index(craft_version, tar_member, tmp_path):
    remote = craft_version([tar_member("ok.txt", b"ok"), tar_member("surprise.txt", b"!")])
    mgr = ResourceManager(tmp_path / "cache", None, remote, progress=False)
    with pytest.raises(CorruptArchiveError, match="differ from the index"):
        mgr.install("objects/evil@1")


def test_undecodable_archive_is_a_clear_error(tmp_path):
    (tmp_path / "junk.tar.zst").write_bytes(b"not zstd at all")
    with pytest.raises(CorruptArchiveError, match="junk: cannot be read"):
        safe_extract(tmp_path / "junk.tar.zst", tmp_path / "out", "junk")
