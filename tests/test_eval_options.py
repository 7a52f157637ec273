"""Eval-time options: custom object swap, camera overrides and randomization, per-task horizons,
episode overrides from plugins, and robots no plugin provides."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.config import compose
from molmo_lerobot.context import RunContext
from molmo_lerobot.errors import RunError
from molmo_lerobot.overrides import OverrideError
from molmo_lerobot.overrides import molmo_episode_overrides as _override
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfigError
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.sim.env import Timing

CUSTOM_MJCF = """<mujoco><worldbody><body name="thing"><freejoint/>
<geom type="box" size="0.025 0.025 0.04" rgba="0.1 0.8 0.2 1" mass="0.1"/></body></worldbody></mujoco>"""


@pytest.fixture(scope="module")
def episode():
    return load_benchmark(data_path("benchmarks") / "pick_v1", Plugins()).episodes[0]


@pytest.fixture
def custom_mjcf(tmp_path):
    path = tmp_path / "thing.xml"
    path.write_text(CUSTOM_MJCF)
    return path


def molmo_episode_overrides(episode, config):
    """The built-in overrides under a run context of ``config`` (partial: the rest are RunConfig's defaults)."""
    context = RunContext.build(config)
    return _override(episode, context.config, context)


def _rows(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines()]


def test_custom_object_replaces_the_target_keeping_its_pose(episode, custom_mjcf):
    old = episode.task.pickup_obj_name
    old_pose = episode.scene_modifications.object_poses[old]
    new = molmo_episode_overrides(episode, {"custom_object": {"path": str(custom_mjcf), "name": "thing",
                                                              "description": "pick up the green box"}})
    assert new.task.pickup_obj_name == "thing" and old in new.scene_modifications.removed_objects
    pose = new.scene_modifications.object_poses["thing"]
    assert pose[:2] == old_pose[:2] and pose[3:] == old_pose[3:]
    assert new.language.task_description == "pick up the green box"
    env = build_env(new, Timing(), RunContext.build())
    env.reset(0)
    mujoco_body = env.body_pose("thing")
    table_top = Plugins().scene_dataset(new.scene_dataset).metadata(new.house_index)["table_height"]
    assert mujoco_body[2] == pytest.approx(table_top + 0.04, abs=2e-3)  # resting on the table, not in it
    with pytest.raises(ValueError, match=f"no body '{old}'"):
        env.body_id(old)
    env.close()


def test_custom_object_errors_are_clear(episode, tmp_path):
    with pytest.raises(RunConfigError, match=r"custom_object.path: no MJCF file"):  # refused before any episode
        molmo_episode_overrides(episode, {"custom_object": {"path": str(tmp_path / "missing.xml")}})
    with pytest.raises(RunConfigError, match=r"camera.randomization: expected a level 0-3 \(0: off\), got 5"):
        molmo_episode_overrides(episode, {"camera": {"randomization": 5}})
    with pytest.raises(OverrideError, match=r"camera.overrides: no camera 'nope'"):
        molmo_episode_overrides(episode, {"camera": {"overrides": {"nope": {"fov": 10}}}})


def test_camera_randomization_is_seeded_by_the_episode(episode):
    a = molmo_episode_overrides(episode, {"camera": {"randomization": 2}})
    b = molmo_episode_overrides(episode, {"camera": {"randomization": 2}})
    assert a.cameras == b.cameras  # same episode -> same cameras, in any run or worker
    assert [c.fov for c in a.cameras] != [c.fov for c in episode.cameras]
    exo0, exo2 = episode.cameras[0], a.cameras[0]
    assert 0 < np.linalg.norm(np.subtract(exo2.pos, exo0.pos)) <= 0.04 * np.sqrt(3) + 1e-9
    assert molmo_episode_overrides(episode, {"camera": {"randomization": 0}}) is None
    env0, env2 = build_env(episode, Timing(), RunContext.build()), build_env(a, Timing(), RunContext.build())
    env0.reset(0)
    env2.reset(0)
    assert not np.array_equal(env0.render(exo0.name), env2.render(exo0.name))
    env0.close()
    env2.close()


def test_options_change_the_run_and_are_recorded(tmp_path, custom_mjcf, fork_servers):
    out = tmp_path / "run"
    res = run_evaluation(compose([
        "policy=random", "workers=1", "limit=2", f"output_dir={out}", "progress=false",
        f"custom_object.path={custom_mjcf}", "custom_object.name=thing", "camera.randomization=1",
        "+camera.overrides.exterior.fov=50", "+horizons.pick=1.0"]), fork_servers)
    assert res.summary["n_errors"] == 0
    results = json.loads((out / "results.json").read_text())
    opts = results["eval_options"]
    assert opts["custom_object"]["path"] == str(custom_mjcf) and opts["camera"]["randomization"] == 1
    assert opts["horizons"] == {"pick": 1.0}
    assert results["thresholds"]["pick"]["horizon_steps"] == [15]  # 1 s at 66 ms
    assert all(r["steps"] == 15 for r in _rows(out))


def test_an_override_that_cannot_apply_fails_only_its_episodes(tmp_path, custom_mjcf, fork_servers):
    res = run_evaluation(compose(["policy=random", "benchmark=open_v1", "workers=1", "limit=2", "horizon=2",
                                  f"custom_object.path={custom_mjcf}", f"output_dir={tmp_path / 'run'}",
                                  "progress=false"]), fork_servers)
    assert res.summary["n_episodes"] == 2 and res.summary["n_errors"] == 2
    assert all("episode override failed: OverrideError: custom_object:" in r["error"]
               for r in _rows(tmp_path / "run"))


class _RobotOverride:
    """A robot eval override as a third-party plugin would ship it."""

    @hookimpl
    def molmo_episode_overrides(self, episode, config):
        init = dict(episode.robot.init_qpos, gripper=[1.0])
        return episode.model_copy(update={
            "robot": episode.robot.model_copy(update={"init_qpos": init}),
            "language": episode.language.model_copy(update={"task_description": "overridden"})})


def test_plugin_episode_overrides_apply(tmp_path, in_process_plugins, fork_servers):
    in_process_plugins(_RobotOverride(), "robot_override")
    run_evaluation(compose(["policy=random", "workers=1", "limit=1", "horizon=2", f"output_dir={tmp_path}",
                            "progress=false"]), fork_servers)
    assert [r["prompt"] for r in _rows(tmp_path)] == ["overridden"]


def test_runs_that_cannot_simulate_fail_up_front(tmp_path, monkeypatch, fork_servers):
    """MolmoSpaces episodes whose scenes (and mobile robots) are missing here: one line, before any worker."""
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(tmp_path / "no_assets"))
    bench = Path(__file__).parent / "data" / "molmospaces" / "mixed_tasks"
    with pytest.raises(RunError, match=r"^cannot simulate 8 of 8 episodes: .*mixed_tasks/benchmark.json: "
                                       r"episodes 0, 1: "
                                       r"field scene_dataset: scene 'procthor-objaverse' val house 2115: "
                                       r".*no_assets/scenes/procthor-objaverse-val/val_2115_ceiling.xml not found"):
        run_evaluation(compose(["policy=random", "workers=1", f"benchmark.path={bench}", "horizon=2",
                                f"output_dir={tmp_path / 'run'}", "progress=false"]), fork_servers)
    assert not (tmp_path / "run").exists()

