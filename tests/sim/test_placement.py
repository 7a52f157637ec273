"""Robot placement as MolmoSpaces builds it: mount body at robot_base_pose, base_size pedestal, arm on top."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from molmo_lerobot.benchmark.schema import EpisodeSpec
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.plugins import Plugins

DATA = Path(__file__).resolve().parents[1] / "data" / "molmospaces"


def ithor_pick(**robot) -> EpisodeSpec:
    """The pick episode of tests/data/molmospaces/mixed_tasks (MolmoSpaces' geometry: the base pose on
    the floor, the object on a counter at 0.82 m), with ``robot`` fields added."""
    raw = next(e for e in json.loads((DATA / "mixed_tasks" / "benchmark.json").read_text())
               if e["task"]["task_cls"].endswith("PickTask"))
    raw["robot"].update(robot)
    return parse_episode(raw, Plugins())


def placed(spec: EpisodeSpec):
    """The robot alone, placed as the episode says and at its initial joint positions."""
    robot = Plugins().robot(spec.robot.robot_name)
    world = mujoco.MjSpec()
    robot.place(world, spec)
    model = world.compile()
    data = mujoco.MjData(model)
    handle = robot.bind(model)
    for group, values in spec.robot.init_qpos.items():
        if group in robot.move_groups:
            handle.set_qpos(data, group, robot.init_qpos(group, values))
    mujoco.mj_forward(model, data)
    return model, data, handle


def test_franka_droid_stands_on_their_pedestal_above_the_object():
    """Must-show: on MolmoSpaces' iTHOR-style pick geometry the arm's root is at base z + 0.58 m and
    the gripper starts above the object (without the pedestal it started 0.28 m below it)."""
    spec = ithor_pick()
    base, obj = spec.task.robot_base_pose, spec.task.pickup_obj_start_pose
    model, data, handle = placed(spec)
    root = data.xpos[model.body("robot_0/fr3_link0").id]
    assert np.allclose(data.xpos[model.body("robot_0/base").id], base[:3])
    assert root == pytest.approx(np.add(base[:3], [0.0, 0.0, 0.58]))
    pedestal = model.geom("robot_0/base/pedestal").id
    assert model.geom_size[pedestal] == pytest.approx([0.25, 0.25, 0.29])
    assert data.geom_xpos[pedestal] == pytest.approx(np.add(base[:3], [0.0, 0.0, 0.29]))
    tcp = data.site_xpos[handle.tcp_site]
    assert tcp[2] - obj[2] > 0.2
    # the same episode without a pedestal: the old placement, gripper below the counter top
    model, data, handle = placed(ithor_pick(base_size=None))
    assert data.xpos[model.body("robot_0/fr3_link0").id][2] == pytest.approx(base[2])
    assert data.site_xpos[handle.tcp_site][2] < obj[2]


def test_base_size_per_episode_and_per_run():
    tall = placed(ithor_pick(base_size=[0.4, 0.4, 0.75]))
    assert tall[1].xpos[tall[0].body("robot_0/fr3_link0").id][2] == pytest.approx(0.07 + 0.75)
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.overrides import molmo_episode_overrides

    def with_base_size(episode, value):
        run = RunContext.build({"robot": {"base_size": value}})
        return molmo_episode_overrides(episode, run.config, run)

    spec = with_base_size(ithor_pick(), [0.3, 0.3, 0.2])
    assert spec.robot.model_extra["base_size"] == [0.3, 0.3, 0.2]
    assert with_base_size(ithor_pick(), "default") is None
    none = with_base_size(ithor_pick(base_size=[0.4, 0.4, 0.75]), None)
    model, data, _ = placed(none)
    assert data.xpos[model.body("robot_0/fr3_link0").id][2] == pytest.approx(0.07)
    assert "robot_0/base/pedestal" not in {model.geom(i).name for i in range(model.ngeom)}


def test_franka_keeps_no_pedestal_unless_asked():
    """The Panda of the published v1 benchmarks stands at the base pose itself."""
    franka = Plugins().robot("franka")
    assert franka.default_base_size is None
    world = mujoco.MjSpec()
    franka.add_to(world, [0.1, 0.0, 0.7, 1, 0, 0, 0])
    model = world.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert data.xpos[model.body("robot/panda0_link0").id] == pytest.approx([0.1, 0.0, 0.7])
    world = mujoco.MjSpec()
    franka.add_to(world, [0.1, 0.0, 0.1, 1, 0, 0, 0], (0.5, 0.5, 0.6))
    model = world.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert data.xpos[model.body("robot/panda0_link0").id] == pytest.approx([0.1, 0.0, 0.7])


@pytest.mark.parametrize("bad", [[0.5, 0.5], [0.5, 0.5, -1.0], "tall", [True, True, True]])
def test_a_bad_base_size_is_one_clear_error(bad):
    from molmo_lerobot.benchmark.load import Benchmark, Origin
    from molmo_lerobot.benchmark.validate import validate_benchmark
    from molmo_lerobot.context import RunContext

    spec = ithor_pick(base_size=bad)
    bench = Benchmark("b", [spec], None, "", Path("b.json"), [Origin("b.json")])
    run = RunContext.build()
    problems = [p for p in validate_benchmark(bench, run.plugins, run) if p.field == "robot.base_size"]
    assert len(problems) == 1 and not problems[0].warning
    assert str(problems[0]).startswith("b.json: episode 0: field robot.base_size: base_size must be null or three")
    with pytest.raises(ValueError, match="base_size must be null or three positive sizes"):
        Plugins().robot("franka_droid").base_size(spec.robot)
