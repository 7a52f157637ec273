"""The README's examples work as written: the plugin snippet installs and runs, the policy mapping composes."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def _section(title: str) -> str:
    text = README.read_text()
    start = text.index(f"## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end > 0 else None]


def _blocks(section: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced code block."""
    return re.findall(r"```(\w+)\n(.*?)```", section, flags=re.S)


@pytest.mark.skipif(not __import__("importlib").util.find_spec("hatchling"), reason="building offline needs hatchling")
def test_plugin_snippet_installs_and_runs_as_copied(tmp_path):
    project = tmp_path / "my-plugin"
    toml_body = None
    for lang, body in _blocks(_section("Writing a plugin")):
        first, _, _rest = body.partition("\n")
        name = first.lstrip("# ").strip()
        if lang == "toml":
            toml_body = body
            continue
        path = project / name  # e.g. my_package/plugin.py, my_package/conf/policy/my_policy.yaml
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(body)
    assert toml_body is not None and (project / "my_package" / "plugin.py").is_file()
    (project / "pyproject.toml").write_text(
        '[build-system]\nrequires = ["hatchling"]\nbuild-backend = "hatchling.build"\n\n'
        '[project]\nname = "my-plugin"\nversion = "0.1.0"\n\n'
        '[tool.hatch.build.targets.wheel]\npackages = ["my_package"]\n\n' + toml_body)
    site = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                           "--no-index", "--target", str(site), str(project)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (site / "my_package" / "conf" / "policy" / "my_policy.yaml").is_file()
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(site), "MUJOCO_GL": "egl"}
    proc = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", "policy=my_policy", "benchmark=pick_v1",
                           "limit=1", "horizon=3", "workers=1", "progress=false", f"output_dir={out}"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    assert results["policy"]["name"] == "my_policy" and results["n_errors"] == 0


def test_policy_interface_mapping_example_composes():
    from molmo_lerobot.config import compose

    bash = next(body for lang, body in _blocks(_section("Policy interface")) if lang == "bash")
    args = shlex.split(bash.replace("\\\n", " "))
    assert args[0] == "molmo-eval"
    cfg = compose(args[1:])
    assert dict(cfg.policy.cameras) == {"exterior": "observation.images.front", "wrist": "observation.images.wrist_cam"}
    assert list(cfg.policy.state) == ["arm", "gripper"] and list(cfg.policy.action_groups) == ["arm", "gripper"]


def test_policy_interface_facts_match_the_code():
    """The numbers the README states: rate, dataset fps, Franka move groups and names, benchmark cameras."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.export.merge import dataset_fps
    from molmo_lerobot.paths import data_path
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.sim.env import Timing

    text = _section("Policy interface")
    timing = Timing()
    assert f"`timing.policy_dt_ms` = {timing.policy_dt_ms:g} ms" in text
    assert f"= {timing.ctrl_ticks} ticks" in text and f"= {dataset_fps(timing.policy_dt_ms)};" in text
    plugins = Plugins()
    franka = plugins.robot("franka")
    assert dict(franka.move_groups) == {"arm": 7, "gripper": 1}
    assert franka.joint_names["arm"][0] == "panda_joint1" and franka.joint_names["gripper"] == ["panda_gripper"]
    for name in ("pick_v1", "open_v1"):
        spec = load_benchmark(data_path("benchmarks") / name, plugins).episodes[0]
        assert [c.name for c in spec.cameras] == ["exterior", "wrist"] and list(spec.img_resolution) == [224, 224]


def _quickstart() -> list[list[str]]:
    (_lang, body), = [b for b in _blocks(_section("Quickstart")) if b[0] == "bash"]
    return [shlex.split(line, comments=True) for line in body.splitlines() if line.strip()]


def test_quickstart_is_six_lines_eval_record_load_train_eval():
    lines = _quickstart()
    assert len(lines) == 6 and lines[0] == ["source", ".venv/bin/activate"]
    assert [line[0] for line in lines[1:]] == ["molmo-eval", "molmo-eval", "python", "lerobot-train", "molmo-eval"]
    record, train, evaluate = lines[2], lines[4], lines[5]
    assert "record=true" in record and "--dataset.root=runs/quick-expert/dataset" in train
    out = next(a.split("=", 1)[1] for a in train if a.startswith("--output_dir="))
    assert f"policy.path={out}/checkpoints/last/pretrained_model" in evaluate


@pytest.mark.slow  # imports LeRobot's policies (a minute on 2 loaded cores)
def test_quickstart_commands_are_valid_as_written():
    """Each molmo-eval line is a valid run config; every lerobot-train flag is one LeRobot knows."""
    import draccus
    import lerobot.policies  # noqa: F401  (registers the policy types, as lerobot-train's imports do)
    from lerobot.configs.train import TrainPipelineConfig

    from molmo_lerobot.config import compose
    from molmo_lerobot.run_config import RunConfig

    lines = _quickstart()
    for line in lines:
        if line[0] == "molmo-eval":
            RunConfig.of(compose(line[1:]))
    train = next(line for line in lines if line[0] == "lerobot-train")
    cfg = draccus.parse(config_class=TrainPipelineConfig, args=train[1:])
    assert cfg.policy.type == "act" and cfg.policy.device == "cpu" and cfg.steps == 20
