"""Verifying what is installed: every file of a version's done archives against its index (size,
sha256, read-only), nothing beside them, every link inside the version, and each install link."""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath

from molmo_lerobot import fileio
from molmo_lerobot.resources.archive import sha256_file
from molmo_lerobot.resources.index import PathIndex
from molmo_lerobot.resources.layout import Layout
from molmo_lerobot.resources.spec import VersionPlace


def version_problems(place: VersionPlace, layout: Layout, index: PathIndex, complete: bool) -> list[str]:
    """Compare the real tree (walked without following links) with the index of the done archives
    (``complete``: the version is marked complete)."""
    spec, manifest = place.spec, layout.manifest
    done = layout.done()
    problems = []
    if complete and not set(manifest["archives"]) <= done:
        problems.append(f"{spec}: marked complete but archives are missing")
    vdir = place.version_dir
    tree = fileio.walk(vdir) if vdir.is_dir() and not vdir.is_symlink() else {}
    expected: dict[str, tuple[str, list]] = {}
    for archive in sorted(done & set(manifest["archives"])):
        expected.update((rel, (archive, want)) for rel, want in index.files(archive).items())
    dirs = {p for rel in expected for p in PurePosixPath(rel).parents if str(p) != "."}
    for rel, (archive, want) in sorted(expected.items()):
        got, what = tree.get(rel), f"{spec}: {rel} (archive {archive})"
        if want[0] == "->":
            if got != ("l", want[1]):
                problems.append(f"{what} is not the link to {want[1]!r}")
        elif want[0] is None:  # MolmoSpaces' index: no size or checksum to compare
            if got is None:
                problems.append(f"{what} is missing")
            elif got[0] == "f" and (vdir / rel).stat().st_mode & 0o222:
                problems.append(f"{what} is writable")
        elif got is None or got[0] != "f":
            problems.append(f"{what} is missing")
        elif got[1] != want[0] or sha256_file(vdir / rel) != want[1]:
            problems.append(f"{what} differs from the manifest")
        elif (vdir / rel).stat().st_mode & 0o222:
            problems.append(f"{what} is writable")
    for rel, got in sorted(tree.items()):
        if rel not in expected and not (got == ("d",) and PurePosixPath(rel) in dirs) and not layout.own_file(rel):
            problems.append(f"{spec}: {rel} is not in the index of any installed archive")
        if got[0] == "l" and not fileio.resolves_inside(vdir, rel):
            problems.append(f"{spec}: link {rel} -> {got[1]!r} resolves to {os.path.realpath(vdir / rel)}, "
                            f"outside {vdir}")
    return problems


def link_problems(place: VersionPlace, mode: str) -> list[str]:
    """The install link of a linked version: present, and (``mode`` ``dir``) pointing at the version dir."""
    link = place.link_path
    if not link.exists():
        return [f"{place.spec}: install link {link} is missing or dangling"]
    if mode == "dir" and Path(os.path.realpath(link)) != place.version_dir:
        return [f"{place.spec}: {link} does not point at {place.version_dir}"]
    return []
