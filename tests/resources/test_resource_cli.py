"""``molmo-resources`` end to end, in-process (``main(argv)``) and one real subprocess."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS
from molmo_lerobot.cli.resources import main


def test_pack_install_verify_list(src_tree, tmp_path, capsys, read_tree):
    remote, cache, inst = str(tmp_path / "remote"), str(tmp_path / "cache"), str(tmp_path / "inst")
    assert main(["pack", str(src_tree), "--remote", remote, "--data-type", "objects", "--source", "lib",
                 "--version", "1", "--link", "file"]) == 0
    assert "objects/lib@1" in capsys.readouterr().out
    assert main(["install", "objects/lib@1", "--remote", remote, "--cache-dir", cache, "--install-dir", inst,
                 "--no-progress"]) == 0
    assert "1 archives extracted" in capsys.readouterr().out
    assert read_tree(tmp_path / "inst" / "objects" / "lib") == read_tree(src_tree)
    assert main(["verify", "--cache-dir", cache, "--install-dir", inst]) == 0
    assert "0 problems" in capsys.readouterr().out
    assert main(["list", "--cache-dir", cache, "--install-dir", inst, "--remote", remote, "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert listing == {"cache": {"objects": {"lib": ["1"]}}, "linked": {"objects": {"lib": "1"}},
                       "remote": {"objects": {"lib": ["1"]}}}
    f = tmp_path / "cache" / "objects" / "lib" / "1" / "README.txt"
    f.chmod(0o644)
    f.write_text("changed")
    assert main(["verify", "--cache-dir", cache]) == 1
    assert "README.txt" in capsys.readouterr().out


def test_errors_are_one_line_without_traceback(tmp_path):
    cmd = [sys.executable, "-m", "molmo_lerobot.cli.resources", "install", "objects/none@1", "--remote",
           str(tmp_path / "remote"), "--cache-dir", str(tmp_path / "c"), "--install-dir", str(tmp_path / "i")]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert out.returncode == 1
    assert out.stderr.strip().count("\n") == 0 and "Traceback" not in out.stderr
    assert out.stderr.startswith("molmo-resources: error: remote ") and "objects/none@1" in out.stderr


def test_bad_inputs_name_what_is_wrong(tmp_path, capsys):
    assert main(["install", "objects-none", "--remote", str(tmp_path), "--cache-dir", str(tmp_path / "c"),
                 "--install-dir", str(tmp_path / "i")]) == 1
    assert "invalid resource 'objects-none'" in capsys.readouterr().err
    assert main(["pack", str(tmp_path / "missing"), "--remote", str(tmp_path / "r"), "--data-type", "objects",
                 "--source", "s", "--version", "1"]) == 1
    assert "missing: not a directory" in capsys.readouterr().err


def test_grasps_generate_writes_npz_per_uid(tmp_path, capsys):
    assert main(["grasps", "generate", "--out", str(tmp_path / "g")]) == 0
    files = sorted((tmp_path / "g" / "franka").glob("*.npz"))
    assert [f.stem for f in files] == sorted(BUILTIN_OBJECTS)
    with np.load(files[0]) as npz:
        assert npz["transforms"].ndim == 3 and npz["transforms"].shape[1:] == (4, 4)
    assert main(["grasps", "generate", "--out", str(tmp_path / "g"), "--robot", "ur5"]) == 1
    assert "franka" in capsys.readouterr().err
