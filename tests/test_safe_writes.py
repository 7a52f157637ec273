"""Issue 24, defect 3: no write escapes a run directory (or a resource cache / install dir) through a
symbolic link planted inside it; the root itself may be a link. Every write goes through
:mod:`molmo_lerobot.fileio`, and a scan of ``src/`` keeps it that way."""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import export_synthetic as S  # the synthetic rollouts of tests/export
import pytest

from molmo_lerobot import fileio
from molmo_lerobot.errors import INFRASTRUCTURE, error_kind
from molmo_lerobot.fileio import UnsafePathError, atomic_write

SRC = Path(__file__).parents[1] / "src" / "molmo_lerobot"


def _tree(path: Path) -> list[str]:
    """Everything below ``path`` (not following links), to show that nothing was written there."""
    return sorted(str(p.relative_to(path)) for p in path.rglob("*"))


@pytest.fixture
def outside(tmp_path):
    d = tmp_path / "outside"
    d.mkdir()
    return d


# -- the write path itself ---------------------------------------------------------------------------------------
def test_a_link_below_the_root_is_refused_for_every_kind_of_write(tmp_path, outside):
    root = tmp_path / "run"
    (root / "sub").mkdir(parents=True)
    (root / "linked").symlink_to(outside)
    (outside / "keep.txt").write_text("keep")
    for write in (lambda: atomic_write(root / "linked" / "a.json", "{}", root=root),
                  lambda: fileio.make_dirs(root / "linked" / "d", root=root),
                  lambda: fileio.open_fd(root / "linked" / "w.log", os.O_WRONLY | os.O_CREAT, root=root),
                  lambda: fileio.symlink("x", root / "linked" / "l", root=root),
                  lambda: fileio.replace(root / "sub", root / "linked" / "sub", root=root),
                  lambda: fileio.rmtree(root / "linked" / "keep.txt", root=root)):
        with pytest.raises(UnsafePathError) as err:
            write()
        assert str(err.value).startswith(f"{root}: linked is a symlink; refusing to write 'linked/")
        assert str(err.value).endswith("' through it") and "\n" not in str(err.value)
    fileio.remove(root / "linked" / "keep.txt", root=root)  # a removal through a link is a no-op
    assert _tree(outside) == ["keep.txt"]


def test_a_dangling_link_as_the_file_is_never_created_through(tmp_path, outside):
    root = tmp_path / "run"
    root.mkdir()
    (root / "w0g0.log").symlink_to(outside / "created.log")
    with pytest.raises(UnsafePathError, match=r"w0g0.log is a symlink"):
        fileio.open_fd(root / "w0g0.log", os.O_WRONLY | os.O_CREAT | os.O_APPEND, root=root)
    atomic_write(root / "w0g0.log", "x", root=root)  # an atomic replace swaps the link itself
    assert not (root / "w0g0.log").is_symlink() and _tree(outside) == []


def test_a_linked_root_is_allowed(tmp_path):
    real = tmp_path / "elsewhere"
    real.mkdir()
    root = tmp_path / "run"
    root.symlink_to(real)
    atomic_write(root / "thumbnails" / "000000.jpg", b"jpg", root=root)
    os.close(fileio.open_fd(root / "logs" / "w0g0.log", os.O_WRONLY | os.O_CREAT, root=root))
    assert _tree(real) == ["logs", "logs/w0g0.log", "thumbnails", "thumbnails/000000.jpg"]


# -- run directory ------------------------------------------------------------------------------------------------
def test_thumbnails_never_go_through_a_linked_thumbnails_dir(tmp_path, outside):
    from molmo_lerobot.export.glance import GlanceRecorderFactory

    run = tmp_path / "run"
    run.mkdir()
    (run / "thumbnails").symlink_to(outside)
    rec = GlanceRecorderFactory(width=16).make("w0g0", run)
    with pytest.raises(UnsafePathError, match=f"{run}: thumbnails is a symlink; refusing to write "
                                              "'thumbnails/000000.jpg'"):
        S.run_episode(rec, 0, 3, success_from=None)
    assert _tree(outside) == []


_REDIRECT = ("import sys; from molmo_lerobot.runner.progress import redirect_worker_output; "
             "print(redirect_worker_output(sys.argv[1], 'w0g0'), file=sys.__stdout__)")


@pytest.mark.parametrize("plant", ["logs dir", "dangling log file"])
def test_worker_logs_never_go_through_a_link(tmp_path, outside, plant):
    run = tmp_path / "run"
    run.mkdir()
    if plant == "logs dir":
        (run / "logs").symlink_to(outside)
    else:
        (run / "logs").mkdir()
        (run / "logs" / "w0g0.log").symlink_to(outside / "target.log")
    env = {k: v for k, v in os.environ.items() if k != "MOLMO_DEBUG"}
    proc = subprocess.run([sys.executable, "-c", _REDIRECT, str(run)], capture_output=True, text=True, env=env,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "None"  # output stays on the console
    assert "molmo-eval: warning: worker output stays on the console:" in proc.stderr
    shown = "logs is a symlink; refusing to write 'logs/w0g0.log'" if plant == "logs dir" else \
        "logs/w0g0.log is a symlink; refusing to write through it"
    assert f"{run}: {shown}" in proc.stderr
    assert _tree(outside) == []


def test_dataset_shards_are_never_written_through_a_link(tmp_path, outside):
    from molmo_lerobot.export.recorder import LeRobotRecorderFactory

    run = tmp_path / "run"
    run.mkdir()
    (run / "dataset_shards").symlink_to(outside)
    factory = LeRobotRecorderFactory(repo_id="local/synth", policy_dt_ms=66.0, benchmark="synth_v1", policy="x")
    rec = factory.make("w0g0", run)
    with pytest.raises(UnsafePathError, match="dataset_shards is a symlink"):
        S.run_episode(rec, 0, 3, success_from=None)
    assert _tree(outside) == []


def test_a_linked_dataset_dir_is_refused_at_merge(tmp_path, outside):
    """A planted ``dataset`` link would have its episodes merged in and the link silently replaced."""
    from molmo_lerobot.export.recorder import LeRobotRecorderFactory

    run = tmp_path / "run"
    run.mkdir()
    (outside / "meta").mkdir()
    (outside / "meta" / "info.json").write_text("{}")
    (run / "dataset").symlink_to(outside)
    factory = LeRobotRecorderFactory(repo_id="local/synth", policy_dt_ms=66.0, benchmark="synth_v1", policy="x")
    result = S.run_episode(S.NullRecorder(), 0, 3, success_from=None)
    with pytest.raises(UnsafePathError, match=f"{run / 'dataset'} is a symlink; refusing"):
        factory.finalize(run, [result], S.summary_for([result]))
    assert (run / "dataset").is_symlink() and _tree(outside) == ["meta", "meta/info.json"]


def test_a_resumed_run_with_planted_links_writes_nothing_outside_and_keeps_its_results(tmp_path, outside, fork_servers):
    """The run dir is itself a link (allowed); ``thumbnails`` and ``logs/w0g0.log`` planted inside it
    are refused, and the run still writes its results, every episode accounted for."""
    from molmo_lerobot.config import compose
    from molmo_lerobot.runner.evaluate import run_evaluation

    real = tmp_path / "real_run"
    real.mkdir()
    run = tmp_path / "run"
    run.symlink_to(real)
    args = ["policy=random", "horizon=2", "workers=1", f"output_dir={run}", "progress=false"]
    run_evaluation(compose([*args, "limit=1"]), fork_servers)
    assert (real / "results.json").is_file() and (real / "thumbnails" / "000000.jpg").is_file()
    shutil.rmtree(real / "thumbnails")
    (real / "thumbnails").symlink_to(outside / "thumbs", target_is_directory=True)
    (outside / "thumbs").mkdir()
    (real / "logs" / "w0g0.log").unlink()
    (real / "logs" / "w0g0.log").symlink_to(outside / "w0g0.log")
    run_evaluation(compose([*args, "limit=2", "resume=true"]), fork_servers)
    assert _tree(outside) == ["thumbs"]
    results = json.loads((real / "results.json").read_text())
    episodes = [json.loads(line) for line in (real / "episodes.jsonl").read_text().splitlines()]
    assert results["n_episodes"] == 2 and [e["episode_index"] for e in episodes] == [0, 1]
    assert episodes[0]["error"] is None  # the first run's episode is kept as it was


# -- resource cache and install dir -------------------------------------------------------------------------------
def _install(tmp_path, src_tree, cache, install):
    from molmo_lerobot.resources import LocalRemote, ResourceManager, pack

    remote = LocalRemote(tmp_path / "remote")
    pack(src_tree, remote, "objects/fruit@1", link="file", uid_depth=0)
    return ResourceManager(cache, install, remote, progress=False).install("objects/fruit@1")


@pytest.mark.parametrize("plant", ["cache/.molmo", "cache/objects", "inst/objects"])
def test_resource_writes_never_go_through_a_link_below_the_cache_or_install_dir(tmp_path, outside, plant):
    from molmo_lerobot.resources import ResourceError

    src_tree = tmp_path / "src"
    (src_tree / "apple_01").mkdir(parents=True)
    (src_tree / "apple_01" / "apple_01.xml").write_text("<mujoco/>\n")
    (tmp_path / plant).parent.mkdir(parents=True, exist_ok=True)
    (tmp_path / plant).symlink_to(outside)
    with pytest.raises((UnsafePathError, ResourceError)) as err:
        _install(tmp_path, src_tree, tmp_path / "cache", tmp_path / "inst")
    assert f"{Path(plant).name} is a symlink; refusing to write" in str(err.value) and "\n" not in str(err.value)
    assert _tree(outside) == []


def test_linked_cache_and_install_roots_are_allowed(tmp_path):
    src_tree = tmp_path / "src"
    (src_tree / "apple_01").mkdir(parents=True)
    (src_tree / "apple_01" / "apple_01.xml").write_text("<mujoco/>\n")
    for name in ("cache", "inst"):
        (tmp_path / f"real_{name}").mkdir()
        (tmp_path / name).symlink_to(tmp_path / f"real_{name}")
    got = _install(tmp_path, src_tree, tmp_path / "cache", tmp_path / "inst")
    assert (got.path / "apple_01" / "apple_01.xml").read_text() == "<mujoco/>\n"
    assert (tmp_path / "real_cache" / "objects" / "fruit" / "1" / "apple_01" / "apple_01.xml").is_file()
    assert (tmp_path / "real_inst" / "objects" / "fruit" / "apple_01" / "apple_01.xml").is_symlink()


# -- our cache dir ($MOLMO_LEROBOT_HOME): LIBERO's computed grasps and downscaled textures -----------------------------
@pytest.mark.parametrize("plant", ["grasps", "grasps/libero-v1", "grasps/libero-v1/franka"])
def test_libero_grasps_are_never_cached_through_a_link(tmp_path, outside, monkeypatch, plant):
    """Issue 39, defect 1: a grasp file computed on first use went through a link planted in the cache dir."""
    import numpy as np

    from molmo_lerobot.content.libero import grasps

    home = tmp_path / "home"
    (home / plant).parent.mkdir(parents=True)
    (home / plant).symlink_to(outside)
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(home))
    monkeypatch.setattr(grasps, "compute_grasps", lambda uid, robot: np.eye(4)[None])  # the write is under test
    with pytest.raises(UnsafePathError) as err:
        grasps.LiberoGraspLibrary().path("libero_ketchup", "franka")
    assert str(err.value) == (f"{home}: {plant} is a symlink; refusing to write "
                              "'grasps/libero-v1/franka/libero_ketchup.npz' through it")
    assert error_kind(err.value) == INFRASTRUCTURE, "an episode it ends is rerun by resume once the link is gone"
    assert _tree(outside) == []


def test_libero_textures_are_never_cached_through_a_link_and_a_linked_cache_dir_is_allowed(tmp_path, outside,
                                                                                          monkeypatch):
    from molmo_lerobot.content.libero.objects import assets_root, texture_file

    src = assets_root() / "textures" / "martin_novak_wood_table.png"
    home = tmp_path / "home"
    home.mkdir()
    (home / "libero_textures").symlink_to(outside)
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(home))
    with pytest.raises(UnsafePathError, match=f"^{home}: libero_textures is a symlink; refusing to write "
                                              "'libero_textures/16/textures/martin_novak_wood_table.png'") as err:
        texture_file(src, size=16)
    assert error_kind(err.value) == INFRASTRUCTURE, "an episode it ends is rerun by resume once the link is gone"
    assert _tree(outside) == []
    (tmp_path / "real_home").mkdir()
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "linked_home"))
    (tmp_path / "linked_home").symlink_to(tmp_path / "real_home")
    assert texture_file(src, size=16) == tmp_path / "linked_home" / "libero_textures" / "16" / "textures" / src.name
    assert _tree(tmp_path / "real_home") == ["libero_textures", "libero_textures/16", "libero_textures/16/textures",
                                             "libero_textures/16/textures/martin_novak_wood_table.png"]


# -- no write bypasses fileio ---------------------------------------------------------------------------------------
_PATH_METHODS = {"write_text", "write_bytes", "touch", "mkdir", "rename", "replace", "unlink", "symlink_to",
                 "hardlink_to", "rmdir"}
_OS = {"replace", "rename", "renames", "symlink", "link", "mkdir", "makedirs", "unlink", "remove", "rmdir",
       "truncate"}
_SHUTIL = {"copy", "copy2", "copyfile", "copytree", "move", "rmtree"}

#: (file, start of the call) -> why it may write without fileio's walk.
ALLOWED = {
    ("benchmark/output.py", "out.mkdir("): "a benchmark directory the user names, not a run dir",
    ("cli/bench.py", "out.parent.mkdir("): "molmo-bench's output: a benchmark directory the user names",
    ("cli/bench.py", "shutil.rmtree(out)"): "molmo-bench replaces the benchmark directory the user named",
    ("cli/bench.py", "os.replace(tmp, out)"): "molmo-bench: its fresh mkdtemp dir into the named place",
    ("cli/bench.py", "shutil.rmtree(tmp"): "molmo-bench: removes its own fresh mkdtemp dir",
    ("export/video.py", "shutil.rmtree(stream.path.parent"): "a fresh mkdtemp dir inside LeRobot's own temp "
                                                             "dir of a shard that fileio made",
    ("export/video.py", "av.open(str(self.path), 'w')"): "a new file in a fresh mkdtemp dir inside LeRobot's own "
                                                         "temp dir of a shard that fileio made",
    ("resources/archive.py", "open(out, 'wb')"): "``out`` is a descriptor opened O_NOFOLLOW at a walked dir fd",
    ("runner/forkserver.py", "open(w, 'wb'"): "``w`` is the fork server's pipe to a new worker, not a path",
    ("resources/remotes.py", "shutil.copytree(local_dir, staging)"): "copytree makes the new staging dir "
                                                                     "itself, in a parent fileio made",
    ("namespaces.py", "shutil.copytree(source, staging / 'dataset'"): "copytree makes the new directory itself, "
                                                                      "in a staging dir fileio made in the store",
}


def _raw_writes(tree: ast.AST):
    for n in ast.walk(tree):
        if not isinstance(n, ast.Call):
            continue
        f, kws = n.func, {k.arg for k in n.keywords}
        if kws & {"dir_fd", "src_dir_fd", "dst_dir_fd"}:
            continue  # relative to a directory descriptor from fileio's walk
        base = f.value.id if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) else None
        if (isinstance(f, ast.Name) and f.id == "open") or (isinstance(f, ast.Attribute) and f.attr == "open"
                                                             and base != "os" and "fileobj" not in kws):
            # open(path, "w"), Path.open("a"), av.open(path, "w"): not a descriptor fileio opened
            args = list(n.args)
            if isinstance(f, ast.Attribute) and args and isinstance(args[0], ast.Constant):
                args = [f.value, *args]  # Path.open("w"): the mode comes first
            mode = args[1] if len(args) > 1 else next((k.value for k in n.keywords if k.arg == "mode"), None)
            first = ast.unparse(args[0]) if args else ""
            if (isinstance(mode, ast.Constant) and isinstance(mode.value, str) and set(mode.value) & set("wax+")
                    and not first.startswith(("fileio.", "io.BytesIO("))):
                yield n
        elif isinstance(f, ast.Attribute):
            if base == "os":
                text = ast.unparse(n)
                if f.attr in _OS or (f.attr == "open" and any(x in text for x in ("O_CREAT", "O_WRONLY", "O_RDWR"))):
                    yield n
            elif base == "shutil":
                if f.attr in _SHUTIL:
                    yield n
            elif base not in ("fileio", "str", "dataclasses") and f.attr in _PATH_METHODS:  # dataclasses.replace copies
                if f.attr == "replace" and len(n.args) == 2:
                    continue  # str.replace(old, new); Path.replace takes one argument
                yield n


def test_no_write_bypasses_the_one_write_path():
    """Raw writes (open(..., 'w'), write_text, os.replace, shutil.rmtree, mkdir, ...) live in fileio only."""
    found = set()
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel == "fileio.py":
            continue
        for call in _raw_writes(ast.parse(path.read_text())):
            text = ast.unparse(call)
            key = next((k for k in ALLOWED if k[0] == rel and text.startswith(k[1])), None)
            if key is None:
                pytest.fail(f"{rel}:{call.lineno}: {text[:100]} writes without molmo_lerobot.fileio "
                            "(use fileio.atomic_write/open_fd/make_dirs/replace/rmtree with the run, cache or "
                            "install dir as root, or allow-list it in ALLOWED with the reason)")
            found.add(key)
    assert found == set(ALLOWED), f"allow-list entries that no longer match: {set(ALLOWED) - found}"


def test_the_scan_catches_a_raw_write():
    code = "p.write_text('x')\nopen(f, 'a')\nos.replace(a, b)\nshutil.copyfile(a, b)\nos.open(p, os.O_CREAT)\n"
    code += "path.open('w')\nav.open(str(p), 'w')\n"
    assert len(list(_raw_writes(ast.parse(code)))) == 7
    assert list(_raw_writes(ast.parse("s.replace('a', 'b')\nos.replace(a, b, src_dir_fd=1, dst_dir_fd=2)\n"
                                      "open(p)\nopen(fileio.open_fd(p, 1), 'wb')\ngzip.open(p, 'rt')\n"
                                      "tarfile.open(fileobj=f, mode='w|')\nav.open(io.BytesIO(), 'w')\n"))) == []

