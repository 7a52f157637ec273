"""Options that could only fail per episode (or waste the machine) are refused up front, one line each."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from eval_runs import refusal
from molmo_lerobot.config import compose
from molmo_lerobot.run_config import config_problems


def _problems(*overrides: str) -> list[str]:
    return config_problems(OmegaConf.to_container(compose(list(overrides)), resolve=True))


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["camera.randomization=7"], "camera.randomization: expected a level 0-3 (0: off), got 7"),
        (["+camera.overrides.exterior.fov=nan"], "camera.overrides.exterior.fov: expected finite numbers, got nan"),
        (["+camera.overrides.exterior.fov=-10"],
         "camera.overrides.exterior.fov: expected a field of view in (0, 180) degrees, got -10"),
        (["+camera.overrides.exterior.fov=1e9"],
         "camera.overrides.exterior.fov: expected a field of view in (0, 180) degrees, got 1000000000.0"),
        (["robot.base_size=[1e9,1e9,1e9]"], "robot.base_size must be null or three positive sizes in metres"),
        (["custom_object.path=/etc/passwd"], "custom_object.path: /etc/passwd is not an MJCF file (not XML"),
        (["+policy.serve=true", "+policy.serve_max_batch=abc"],
         "policy.serve_max_batch: expected an integer in 1..4096 (or null: the number of workers), got 'abc'"),
        (["+policy.serve=true", "+policy.serve_transport=shm", "executor=ray"],
         "policy.serve_transport=shm needs executor=local"),
        (["+policy.serve_transport=pipe"], "policy.serve_transport: expected one of auto, shm, websocket, got 'pipe'"),
        (["episode_retries=1000"], "episode_retries: expected an integer in 0..10, got 1000"),
        (["worker_threads=100000"], "worker_threads: expected an integer in 1..1024"),
        (["episode_timeout_s=1e12"], "episode_timeout_s: expected a positive number of seconds (at most 604,800"),
        (["video.crf=1000"], "video.crf: expected a number in 0..63 or null, got 1000"),
        (["output_dir="], "output_dir: expected a path"),
    ],
)
def test_out_of_range_options_are_one_line_naming_the_key(args, line):
    problems = _problems(*args)
    assert len(problems) == 1 and problems[0].startswith(line), problems


def test_a_custom_object_must_be_an_mjcf_model(tmp_path):
    body = tmp_path / "box.xml"
    body.write_text('<mujoco><worldbody><body name="b"><freejoint/><geom size=".02 .02 .02" type="box"/></body>'
                    "</worldbody></mujoco>")
    assert _problems(f"custom_object.path={body}") == []
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><body><geom type='nosuch'/></body></worldbody></mujoco>")
    assert _problems(f"custom_object.path={tmp_path / 'broken.xml'}")[0].startswith(
        f"custom_object.path: {tmp_path / 'broken.xml'} is not an MJCF model MuJoCo loads")
    assert _problems(f"custom_object.path={tmp_path / 'none.xml'}") == [
        f"custom_object.path: no MJCF file at {tmp_path / 'none.xml'}"]


def test_plugin_checked_options_are_one_line_naming_the_key():
    """The policy's own options (its ``PolicyType.options`` model), camera systems and task types need the plugins."""
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.runner.evaluate import plugin_option_problems

    def problems(*overrides: str) -> list[str]:
        return plugin_option_problems(RunContext.build(RunConfig.of(compose(list(overrides)))))

    assert problems("policy=random") == [] and problems() == []
    assert problems("policy=random", "+policy.scale=nan") == ["policy.scale: expected a number in 0..3.14159, got nan"]
    assert problems("policy=random", "+policy.chunk=1000000000") == [
        "policy.chunk: expected an integer in 1..10000, got 1000000000"]
    assert problems("+policy.chunk=0") == ["policy.chunk: expected an integer in 1..10000, got 0"]
    assert problems("camera.system=NoSuch")[0].startswith("camera.system: unknown camera 'NoSuch' (available: ")
    assert problems("+horizons.pikc=10") == ["horizons.pikc: no task type 'pikc'; did you mean horizons.pick?"]


@pytest.mark.parametrize("args", [["+policy.serve=true", "+policy.serve_max_batch=abc"], ["horizons.pikc=10"]])
def test_a_run_refuses_them_before_any_run_directory(args, tmp_path):
    out = tmp_path / "out"
    assert len(refusal(*args, "policy=random", "limit=1", f"output_dir={out}")) == 1
    assert not out.exists()
