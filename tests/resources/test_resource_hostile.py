"""Hostile and malformed versions (issue 11 items 1, 7 and 12): links across archives of a
version, extraction bombs, manifests and indexes with wrong field types."""

from __future__ import annotations

import gzip
import json
import os
import subprocess
import sys
import tarfile

import pytest

from molmo_lerobot.cli.resources import main
from molmo_lerobot.resources import LocalRemote, ResourceError, ResourceManager, UnsafeArchiveError, pack
from molmo_lerobot.resources.archive import safe_extract

SPEC = "objects/evil@1"


def _mgr(tmp_path, remote, workers=1):
    return ResourceManager(tmp_path / "cache", tmp_path / "install", remote, workers=workers, progress=False)


def _nothing_complete(tmp_path):
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install")
    assert not mgr.is_complete(SPEC)
    assert not (tmp_path / "install" / "objects" / "evil").exists()


# -- item 1: write-anywhere through links from other archives of the version ------------------------------------
@pytest.mark.parametrize("index_check", [True, False], ids=["index-checked", "filesystem-checks-only"])
@pytest.mark.parametrize("workers", [1, 4])
def test_three_archive_link_attack_writes_nothing_outside(craft_archives, tar_member, tmp_path, monkeypatch,
                                                          workers, index_check):
    """a0 ``l1 -> .``; a1 ``l1/…/l1/esc -> ../…/..`` (12 levels); a2 ``esc/<abs path>/PWNED.txt``.

    The index check refuses ``l1/…`` below the link ``l1`` up front; with it switched off the
    no-follow placement alone must still stop the attack.
    """
    if not index_check:
        monkeypatch.setattr("molmo_lerobot.resources.manager.check_index", lambda entries, archives, where: entries)
    target = tmp_path / "outside"
    target.mkdir()
    vdir = tmp_path / "cache" / "objects" / "evil" / "1"
    if len(vdir.parts) - 1 > 12:
        pytest.skip(f"{vdir} is deeper than the attack's 12 levels")
    deep = "/".join(["l1"] * 12) + "/esc"
    remote = craft_archives({
        "a0.tar.zst": [tar_member("l1", None, tarfile.SYMTYPE, ".")],
        "a1.tar.zst": [tar_member(deep, None, tarfile.SYMTYPE, "/".join([".."] * 12))],
        "a2.tar.zst": [tar_member(f"esc{target}/PWNED.txt", b"pwned")],
    })
    with pytest.raises(ResourceError) as err:
        _mgr(tmp_path, remote, workers).install(SPEC)
    assert "\n" not in str(err.value)
    assert not (target / "PWNED.txt").exists()
    stray = [p for p in tmp_path.rglob("PWNED.txt") if "remote" not in p.parts and vdir not in p.parents]
    assert stray == []  # a2 may land harmlessly inside the version dir; never anywhere else
    _nothing_complete(tmp_path)


@pytest.mark.parametrize("workers", [1, 4])
def test_link_made_to_escape_by_another_archive_is_refused(craft_archives, tar_member, tmp_path, workers):
    """Each link passes the textual check, but ``up -> l1/..`` leaves the version once ``l1 -> .`` exists."""
    remote = craft_archives({
        "a0.tar.zst": [tar_member("l1", None, tarfile.SYMTYPE, ".")],
        "a1.tar.zst": [tar_member("up", None, tarfile.SYMTYPE, "l1/.."), tar_member("a1.txt", b"a1")],
        "a2.tar.zst": [tar_member("ok.txt", b"ok")],
    })
    mgr = _mgr(tmp_path, remote, workers)
    with pytest.raises(UnsafeArchiveError, match=r"link 'up' -> 'l1/\.\.' resolves to .* outside"):
        mgr.install(SPEC)
    vdir = mgr.version_dir(SPEC)
    links = [p for p in vdir.rglob("*") if p.is_symlink()]
    assert all(os.path.realpath(p).startswith(str(vdir)) for p in links), links
    _nothing_complete(tmp_path)


def test_extraction_never_follows_a_link_in_its_own_archive(tar_member, tmp_path):
    import io

    import zstandard

    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for info, data in [tar_member("l1", None, tarfile.SYMTYPE, "."), tar_member("l1/x.txt", b"x")]:
            tar.addfile(info, io.BytesIO(data) if data is not None else None)
    (tmp_path / "a.tar.zst").write_bytes(zstandard.ZstdCompressor().compress(buf.getvalue()))
    with pytest.raises(UnsafeArchiveError, match=r"l1 is a symlink; refusing to write 'l1/x.txt' through it"):
        safe_extract(tmp_path / "a.tar.zst", tmp_path / "out", "a")
    assert not (tmp_path / "out" / "x.txt").exists()


def test_placement_never_writes_through_a_link_on_disk(src_tree, tmp_path):
    """A link already in the version dir (tampering, another tool) cannot redirect the move into place."""
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", tmp_path / "remote", progress=False)
    outside = tmp_path / "outside"
    outside.mkdir()
    vdir = mgr.version_dir("objects/lib@1")
    vdir.mkdir(parents=True)
    (vdir / "apple_01").symlink_to(outside)
    with pytest.raises(UnsafeArchiveError, match="apple_01 is a symlink; refusing to write"):
        mgr.install("objects/lib@1")
    assert list(outside.iterdir()) == []
    assert not mgr.is_complete("objects/lib@1")


def test_verify_catches_an_escaping_tree(src_tree, tmp_path, capsys):
    """The tree the attack leaves (a link out of the version, files reached through links) is reported."""
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", tmp_path / "remote", progress=False)
    mgr.install("objects/lib@1")
    vdir = mgr.version_dir("objects/lib@1")
    outside = tmp_path / "outside"
    os.chmod(vdir, 0o755)
    os.rename(vdir / "mug_02", outside)  # same files, now reached through a link leaving the version
    (vdir / "mug_02").symlink_to(os.path.relpath(outside, vdir))
    (vdir / "esc").symlink_to("../" * 12)
    assert main(["verify", "--cache-dir", str(tmp_path / "cache"), "--install-dir", str(tmp_path / "install")]) == 1
    out = capsys.readouterr().out
    assert "link mug_02 -> " in out and "link esc -> " in out and "outside" in out
    assert "mug_02/mug_02.xml (archive" in out and "missing" in out
    assert "esc is not in the index" in out


# -- item 7: extraction stops at the indexed size, once --------------------------------------------------------
class _CountingRemote(LocalRemote):
    downloads: list[str]

    def download(self, rel, dest):
        self.downloads.append(rel)
        super().download(rel, dest)


def _counting(remote_dir):
    remote = _CountingRemote(remote_dir)
    remote.downloads = []
    return remote


def test_member_larger_than_its_index_stops_before_writing_and_is_not_retried(craft_archives, tar_member, tmp_path):
    big = bytes(64 << 20)  # 64 MiB of zeros: a ~2 KB archive
    remote_dir = craft_archives(
        {"bomb.tar.zst": [tar_member("bomb.bin", big)]},
        edit_index=lambda idx: idx["bomb.tar.zst"]["bomb.bin"].__setitem__(0, 2),
    )
    assert (remote_dir / "objects/evil/1/archives/bomb.tar.zst").stat().st_size < 65536
    remote = _counting(remote_dir)
    with pytest.raises(UnsafeArchiveError, match=r"bomb.bin' has size 67108864, but its indexed size is 2"):
        _mgr(tmp_path, remote).install(SPEC)
    assert [d for d in remote.downloads if "/archives/" in d] == ["objects/evil/1/archives/bomb.tar.zst"]
    written = sum(p.stat().st_size for p in (tmp_path / "cache").rglob("*") if p.is_file())
    assert written < 1 << 20, written
    _nothing_complete(tmp_path)


def test_unindexed_member_is_refused_before_writing(craft_archives, tar_member, tmp_path):
    remote_dir = craft_archives(
        {"a.tar.zst": [tar_member("ok.txt", b"ok"), tar_member("extra.bin", bytes(8 << 20))]},
        edit_index=lambda idx: idx["a.tar.zst"].pop("extra.bin"),
    )
    with pytest.raises(ResourceError, match=r"'extra.bin' is not in the index"):
        _mgr(tmp_path, remote_dir).install(SPEC)
    assert not any(p.name == "extra.bin" for p in (tmp_path / "cache").rglob("*"))


def test_stream_past_the_index_allowance_is_refused(craft_archives, tar_member, tmp_path):
    info, data = tar_member("ok.txt", b"ok")
    info.pax_headers = {"comment": "x" * (4 << 20)}  # a 4 MiB header: bytes the index never allowed
    remote_dir = craft_archives({"a.tar.zst": [(info, data)]})
    with pytest.raises(UnsafeArchiveError, match=r"past its limit of .* bytes"):
        _mgr(tmp_path, remote_dir).install(SPEC)


def test_repeated_member_is_refused(craft_archives, tar_member, tmp_path):
    remote_dir = craft_archives({"a.tar.zst": [tar_member("ok.txt", b"ok"), tar_member("ok.txt", b"ok")]})
    with pytest.raises(UnsafeArchiveError, match=r"'ok.txt' appears twice"):
        _mgr(tmp_path, remote_dir).install(SPEC)


# -- item 12: manifests and indexes with wrong field types ------------------------------------------------------
def _set(*path_value):
    *path, value = path_value

    def edit(d):
        for key in path[:-1]:
            d = d[key] if not callable(key) else key(d)
        d[path[-1]] = value

    return edit


def _first(d):
    return d[next(iter(d))]


@pytest.mark.parametrize("edit_manifest, edit_index, match", [
    (_set("archives", []), None, "field archives: Input should be a valid dictionary"),
    (_set("archives", _first, "size", "12"), None,
     r"field archives\.a\.tar\.zst\.size: Input should be a valid integer"),
    (_set("archives", _first, "sha256", 5), None, r"field archives\.a\.tar\.zst\.sha256"),
    (_set("uid_depth", "x"), None, "field uid_depth: Input should be a valid integer"),
    (_set("link", 5), None, "field link: Input should be 'dir' or 'file'"),
    (_set("archives", {"../../x.tar.zst": {"size": 1, "sha256": "0" * 64}}), None, "is not a plain file name"),
    (None, _set("a.tar.zst", "ok.txt", [1, 2, 3]), "is not \\[size, sha256\\]"),
    (None, _set("a.tar.zst", "../ok.txt", [2, "0" * 64]), "is not a clean relative path"),
    (None, _set("a.tar.zst", ["x"]), "must map paths to entries"),
], ids=["archives-list", "size-str", "sha-int", "uid-depth-str", "link-int", "archive-name-traversal",
        "index-entry", "index-path", "index-archive-list"])
def test_wrong_field_types_are_one_line(craft_archives, tar_member, tmp_path, capsys, edit_manifest, edit_index, match):
    remote = craft_archives({"a.tar.zst": [tar_member("ok.txt", b"ok")]}, edit_index=edit_index,
                            edit_manifest=edit_manifest)
    rc = main(["install", SPEC, "--remote", str(remote), "--cache-dir", str(tmp_path / "cache"), "--install-dir",
               str(tmp_path / "install"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1 and err.startswith("molmo-resources: error: "), err
    import re

    assert re.search(match, err), err
    assert "manifest.json" in err or "index.json.gz" in err
    _nothing_complete(tmp_path)


@pytest.mark.parametrize("which, content", [("cache", "[]"), ("cache", '{"objects": {"lib": "1"}}'),
                                            ("install", '{"objects": ["1"]}'), ("install", "{not json")])
def test_bad_local_manifests_are_one_line(src_tree, tmp_path, which, content):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", tmp_path / "remote", progress=False)
    mgr.install("objects/lib@1")
    path = tmp_path / which / ".molmo" / "installed.json"
    path.write_text(content)
    for cmd in (["verify", "--cache-dir", str(tmp_path / "cache"), "--install-dir", str(tmp_path / "install")],
                ["install", "objects/lib@1", "--remote", str(tmp_path / "remote"), "--cache-dir",
                 str(tmp_path / "cache"), "--install-dir", str(tmp_path / "install")]):
        out = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.resources", *cmd], capture_output=True,
                             text=True, timeout=60)
        assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
        assert out.stderr.count("\n") == 1 and str(path) in out.stderr, out.stderr


def test_cached_manifest_edited_to_wrong_types_is_one_line(src_tree, tmp_path, capsys):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", tmp_path / "remote", progress=False)
    mgr.install("objects/lib@1")
    path = tmp_path / "cache" / ".molmo" / "objects" / "lib" / "1" / "manifest.json"
    manifest = json.loads(path.read_text())
    manifest["uid_depth"] = [0]
    path.write_text(json.dumps(manifest))
    assert main(["install", "objects/lib@1", "--remote", str(tmp_path / "remote"), "--cache-dir",
                 str(tmp_path / "cache"), "--install-dir", str(tmp_path / "install")]) == 1
    err = capsys.readouterr().err
    assert "cached manifest" in err and "field uid_depth" in err and err.count("\n") == 1
    idx = tmp_path / "cache" / ".molmo" / "objects" / "lib" / "1" / "index.json.gz"
    assert gzip.decompress(idx.read_bytes())  # untouched
