"""Semantic checks against installed plugins: every problem named by file, episode and field."""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.benchmark.validate import validate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins


def _load_edited(data, tmp_path, edit):
    episodes = json.loads((data / "pick_list" / "benchmark.json").read_text())
    edit(episodes)
    d = tmp_path / "b"
    d.mkdir()
    (d / "benchmark.json").write_text(json.dumps(episodes))
    return load_benchmark(d, Plugins())


def _texts(bench, plugins):
    return [str(p) for p in validate_benchmark(bench, plugins, RunContext.build())]


def test_molmospaces_files_in_both_layouts_validate(data, fake_plugins):
    for layout in ("pick_list", "pick_legacy"):
        assert validate_benchmark(load_benchmark(data / layout, Plugins()), fake_plugins, RunContext.build()) == []


def test_unknown_task_class_suggests_the_close_one(data, tmp_path, fake_plugins):
    bench = _load_edited(data, tmp_path,
                         lambda eps: eps[2]["task"].update(task_cls="molmo_spaces.tasks.pick_task.PickTsk"))
    (problem,) = validate_benchmark(bench, fake_plugins, RunContext.build())
    assert (problem.episode_index, problem.field) == (2, "task.task_cls")
    assert problem.message.startswith("unknown task 'molmo_spaces.tasks.pick_task.PickTsk'; "
                                      "did you mean 'molmo_spaces.tasks.pick_task.PickTask'")


def test_mobile_robot_episodes_fail_cleanly(data, fake_plugins):
    problems = validate_benchmark(load_benchmark(data / "mixed_tasks", Plugins()), fake_plugins, RunContext.build())
    robot = [p for p in problems if p.field == "robot.robot_name"]
    assert [(p.episode_index, p.message.split(" (")[0]) for p in robot] == [
        (6, "no robot plugin provides 'rby1'"), (7, "no robot plugin provides 'rby1'")]
    tasks = {p.episode_index: p.message.split(";")[0].split(" (")[0] for p in problems if p.field.startswith("task.")}
    assert tasks == {
        1: "unknown task 'molmo_spaces.tasks.pick_and_place_task.PickAndPlaceTask'",
        2: "unknown task 'molmo_spaces.tasks.pick_and_place_next_to_task.PickAndPlaceNextToTask'",
        3: "unknown task 'molmo_spaces.tasks.pick_and_place_color_task.PickAndPlaceColorTask'",
        4: "unknown task 'open'", 5: "unknown task 'close'",
        6: "unknown task 'molmo_spaces.tasks.opening_tasks.DoorOpeningTask'",
        7: "unknown task 'molmo_spaces.tasks.nav_task.NavToObjTask'",
    }
    assert {p.field for p in problems if p.episode_index == 5} >= {"task.task_type", "scene_dataset"}
    # MolmoSpaces' Franka gripper state (two finger joints) does not fit our one-value gripper
    assert any(p.episode_index == 0 and p.field == "robot.init_qpos.gripper" and p.message == "expected 1 values, got 2"
               for p in problems)


@pytest.mark.parametrize(
    ("edit", "field", "message"),
    [  # "warning: " marks what MolmoSpaces accepts but cannot run here as it stands
        (lambda ep: ep["robot"]["init_qpos"].update(arm=[0.0] * 6), "robot.init_qpos.arm",
         "warning: expected 7 values, got 6"),
        (lambda ep: ep["robot"]["init_qpos"].update(base=[0.0, 0.0, 0.0]), "robot.init_qpos.base",
         "warning: robot 'franka' has no move group 'base' (move groups: arm, gripper)"),
        (lambda ep: ep.update(scene_dataset="procthor-objaverse"), "scene_dataset",
         "no scene dataset plugin provides 'procthor-objaverse' (available: procedural_tabletop)"),
        (lambda ep: ep["cameras"][1].update(name="wrist_camera"), "cameras[1].name",
         "duplicate camera name 'wrist_camera' (also cameras[0])"),
        (lambda ep: ep["cameras"][0].update(name="cam/x") or ep["cameras"][1].update(name="cam_x"), "cameras[1].name",
         "cameras 'cam/x' (cameras[0]) and 'cam_x' would both be recorded as 'observation.images.cam_x'; rename one"),
        (lambda ep: ep.update(cameras=[]), "source.camera_system_class",
         "warning: no camera system plugin provides 'FrankaDroidCameraSystem' (available: none); "
         "install a plugin that provides it, or set camera.system= for the run"),
        (lambda ep: ep["cameras"][0].update(fov=0.0), "cameras[0].fov",
         "field of view must be in (0, 180) degrees, got 0.0"),
        (lambda ep: ep["language"].update(task_description="  "), "language.task_description",
         "empty task description"),
    ],
)
def test_each_problem_names_index_and_field(data, tmp_path, fake_plugins, edit, field, message):
    bench = _load_edited(data, tmp_path, lambda eps: edit(eps[1]))
    prefix = "warning: " if message.startswith("warning: ") else ""
    assert _texts(bench, fake_plugins) == [
        f"{prefix}{tmp_path / 'b' / 'benchmark.json'}: episode 1: field {field}: {message.removeprefix(prefix)}"]


def test_all_episodes_are_checked(data, tmp_path, fake_plugins):
    def edit(eps):
        eps[0]["robot"]["robot_name"] = "ur5e"
        eps[3]["robot"]["init_qpos"]["arm"] = [0.0] * 8

    problems = validate_benchmark(_load_edited(data, tmp_path, edit), fake_plugins, RunContext.build())
    assert [(p.episode_index, p.field) for p in problems] == [(0, "robot.robot_name"), (3, "robot.init_qpos.arm")]


def test_installed_plugins_accept_the_molmospaces_pick_files(data):
    plugins = Plugins()
    if any(r.status != "ok" for r in plugins.records if r.name in ("pick", "franka", "tabletop")):
        pytest.fail("built-in plugins failed to load: " + "; ".join(f"{r.name}: {r.error}" for r in plugins.broken()))
    for layout in ("pick_list", "pick_legacy"):
        problems = validate_benchmark(load_benchmark(data / layout, plugins), plugins, RunContext.build())
        assert [str(p) for p in problems] == []
