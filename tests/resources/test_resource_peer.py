"""Interop with the real molmospaces-resources client (the peer), run from its own virtualenv.

The peer installs from our stand-in bucket and ours uses what it left; ours installs and the
peer finds everything in place (fetching nothing). The venv is ``$MOLMO_MSR_PYTHON`` or
``/tmp/msr-venv`` (made here with ``pip install molmospaces-resources`` if missing).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from molmo_lerobot.resources import ResourceManager
from molmo_lerobot.resources import molmospaces as ms

try:
    from ms_remotes import BucketStandin, publish_bucket
except ImportError:
    from tests.resources.ms_remotes import BucketStandin, publish_bucket

pytestmark = pytest.mark.slow

VENV = Path(os.environ.get("MOLMO_MSR_VENV", "/tmp/msr-venv"))
VERSIONS = {"objects": {"thor": "1"}, "scenes": {"ithor": "1"}, "robots": {"franka_droid": "1"}}

PEER = r"""
import json, sys
from pathlib import Path
from molmospaces_resources import R2RemoteStorage, ResourceManager
args = json.loads(sys.argv[1])
mgr = ResourceManager(R2RemoteStorage(args["url"]), args["versions"], Path(args["install"]), Path(args["cache"]),
                      force_install=True)
mgr.setup()
for data_type, source, pkgs in args.get("packages", []):
    mgr.install_packages(data_type, {source: pkgs})
out = {}
for data_type, source, rel in args.get("read", []):
    out[f"{data_type}/{source}/{rel}"] = (mgr.symlink_path(data_type, source) / rel).read_text()
for data_type, source, path in args.get("find", []):
    out[f"find {data_type}/{source}/{path}"] = mgr.find_archives(data_type, source, [path])
print(json.dumps(out))
"""


def _peer_python() -> Path:
    python = VENV / "bin" / "python"
    if not python.exists():
        try:
            subprocess.run([sys.executable, "-m", "venv", str(VENV)], check=True, capture_output=True, timeout=120)
            subprocess.run([str(python), "-m", "pip", "install", "-q", "molmospaces-resources"], check=True,
                           capture_output=True, timeout=600)
        except (subprocess.SubprocessError, OSError) as exc:
            pytest.skip(f"cannot make a venv with molmospaces-resources at {VENV}: {exc}")
    probe = subprocess.run([str(python), "-c", "import molmospaces_resources"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"molmospaces-resources does not import in {VENV}: {probe.stderr.strip().splitlines()[-1:]}")
    return python


def _peer(python, url, cache, install, **extra) -> dict:
    args = {"url": url, "versions": VERSIONS, "cache": str(cache), "install": str(install), **extra}
    out = subprocess.run([str(python), "-c", PEER, json.dumps(args)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _trees(root: Path) -> dict[str, Path]:
    trees = {}
    for data_type, sources in VERSIONS.items():
        for source in sources:
            tree = root / data_type / source
            for i in range(3):
                (tree / f"item_{i}" / "parts").mkdir(parents=True)
                (tree / f"item_{i}" / f"item_{i}.xml").write_text(f"<mujoco model='{source}_{i}'/>\n")
                (tree / f"item_{i}" / "parts" / "p.bin").write_bytes(os.urandom(1000 + i))
            trees[f"{data_type}/{source}"] = tree
    return trees


def test_peer_and_ours_use_each_others_installs(tmp_path):
    python = _peer_python()
    trees = _trees(tmp_path / "src")
    with BucketStandin(tmp_path / "bucket") as bucket:
        groups = {}
        for key, tree in trees.items():
            data_type, source = key.split("/")
            groups[key] = publish_bucket(tree, bucket.root, data_type, source, "1")
        scene_pkg = sorted(groups["scenes/ithor"])[0]

        # 1. the peer installs (thor + robot eager, ithor on demand: one package); ours uses it as-is
        got = _peer(python, bucket.url, tmp_path / "cA", tmp_path / "iA", packages=[["scenes", "ithor", [scene_pkg]]])
        assert got == {}
        peer_gets = sum(bucket.archive_gets().values())
        assert peer_gets == len(groups["objects/thor"]) + len(groups["robots/franka_droid"]) + 1
        ours = ResourceManager(tmp_path / "cA", tmp_path / "iA", bucket.url, progress=False)
        assert ours.installed() == {t: {s: ["1"] for s in src} for t, src in VERSIONS.items()}
        assert ours.linked() == VERSIONS
        assert ours.verify() == []
        assert ours.is_complete("objects/thor@1") and not ours.is_complete("scenes/ithor@1")
        item = tmp_path / "iA" / "objects" / "thor" / "item_1" / "item_1.xml"
        assert item.read_text() == "<mujoco model='thor_1'/>\n"
        files = ours.ensure_uid("scenes/ithor@1", "item_2")  # on demand, through our index of their tries
        assert sum(bucket.archive_gets().values()) == peer_gets + 1
        assert (tmp_path / "iA" / "scenes" / "ithor" / "item_2" / "item_2.xml").is_symlink() and files
        assert ours.verify() == []
        # … and the peer still finds everything installed, and reads what ours added
        got = _peer(python, bucket.url, tmp_path / "cA", tmp_path / "iA",
                    read=[["scenes", "ithor", "item_2/item_2.xml"]], find=[["scenes", "ithor", "item_2/item_2.xml"]])
        assert got["scenes/ithor/item_2/item_2.xml"] == "<mujoco model='ithor_2'/>\n"
        assert sum(bucket.archive_gets().values()) == peer_gets + 1

        # 2. ours installs; the peer sets up over it and fetches nothing
        before = sum(bucket.archive_gets().values())
        mine = ResourceManager(tmp_path / "cB", tmp_path / "iB", bucket.url, progress=False)
        for data_type, sources in VERSIONS.items():
            for source, version in sources.items():
                mine.install(f"{data_type}/{source}@{version}", on_demand=not ms.behaviour(data_type, source)[1])
        mine.ensure_uid("scenes/ithor@1", "item_0")
        mine_gets = sum(bucket.archive_gets().values()) - before
        got = _peer(python, bucket.url, tmp_path / "cB", tmp_path / "iB",
                    packages=[["scenes", "ithor", [sorted(groups["scenes/ithor"])[0]]]],
                    read=[["objects", "thor", "item_0/item_0.xml"], ["robots", "franka_droid", "item_1/item_1.xml"],
                          ["scenes", "ithor", "item_0/item_0.xml"]])
        assert sum(bucket.archive_gets().values()) - before == mine_gets  # the peer downloaded nothing
        assert got == {"objects/thor/item_0/item_0.xml": "<mujoco model='thor_0'/>\n",
                       "robots/franka_droid/item_1/item_1.xml": "<mujoco model='franka_droid_1'/>\n",
                       "scenes/ithor/item_0/item_0.xml": "<mujoco model='ithor_0'/>\n"}
        assert mine.verify() == []
