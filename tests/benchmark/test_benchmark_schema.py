"""The pydantic schema reads MolmoSpaces episodes of every task type unchanged."""

from __future__ import annotations

import copy
import json
import math

import pytest
from pydantic import ValidationError

from molmo_lerobot.benchmark import molmospaces, schema
from molmo_lerobot.benchmark.schema import EpisodeSpec
from molmo_lerobot.benchmark.task_specs import DoorOpeningTaskSpec, NavToObjTaskSpec, parse_episode, task_spec_model
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.tasks.open_close import OpenCloseTaskSpec
from molmo_lerobot.tasks.pick import PickTaskSpec
from molmo_lerobot.tasks.pick_and_place import (
    PickAndPlaceColorTaskSpec,
    PickAndPlaceNextToTaskSpec,
    PickAndPlaceTaskSpec,
)


@pytest.fixture(scope="module")
def plugins():
    return Plugins()


@pytest.fixture
def mixed(data):
    return json.loads((data / "mixed_tasks" / "benchmark.json").read_text())


def test_every_molmospaces_task_type_gets_its_typed_spec(mixed, plugins):
    eps = [parse_episode(e, plugins) for e in mixed]
    assert [type(e.task) for e in eps] == [
        PickTaskSpec, PickAndPlaceTaskSpec, PickAndPlaceNextToTaskSpec,
        PickAndPlaceColorTaskSpec, OpenCloseTaskSpec, OpenCloseTaskSpec,
        DoorOpeningTaskSpec, NavToObjTaskSpec,
    ]
    pick, pnp, next_to, color, opening, closing, door, nav = eps
    # schema defaults are MolmoSpaces' eval defaults
    assert pick.task.succ_pos_threshold == 0.01 and pick.task.task_horizon_sec is None
    assert (pnp.task.receptacle_supported_weight_frac, pnp.task.max_place_receptacle_pos_displacement) == (0.5, 0.15)
    assert math.isclose(pnp.task.max_place_receptacle_rot_displacement, math.radians(60))
    assert pnp.task.task_horizon_sec == 40.0
    assert (next_to.task.min_surface_to_surface_gap, next_to.task.max_surface_to_surface_gap) == (0.0, 0.04)
    assert color.task.object_colors["place_receptacle/0/Bowl_27"] == [0.1, 0.3, 0.9, 1.0]
    assert opening.task.task_success_threshold == 0.2 and door.task.door_openness_threshold == 0.67
    assert nav.task.succ_pos_threshold == 1.5 and nav.task.pickup_obj_start_pose is None
    # open and close share one class (legacy "mujoco_thor." prefix too); task_type tells them apart
    assert (opening.task_name, closing.task_name) == ("open", "close")
    assert closing.task.task_cls.startswith("mujoco_thor.") and closing.task.joint_start_position == [1.2]
    assert pick.task_name == "molmo_spaces.tasks.pick_task.PickTask"
    assert door.robot.robot_name == "rby1" and pick.robot.init_qpos["base"] == []


def test_camera_kinds_and_inferred_type(mixed):
    pick = EpisodeSpec.model_validate(mixed[2])
    wrist, front = pick.cameras
    assert isinstance(wrist, schema.RobotMountedCameraSpec)
    assert wrist.camera_quaternion == [-0.006, -0.001, 0.986, 0.169]
    assert isinstance(front, schema.ExocentricCameraSpec) and front.record_depth and front.forward == [-0.8, 0.0, -0.6]
    nav = EpisodeSpec.model_validate(mixed[7])  # no "type" key: a camera without a world position is robot-mounted
    assert isinstance(nav.cameras[0], schema.RobotMountedCameraSpec) and not nav.cameras[0].record_depth
    assert pick.camera("front_camera") is front
    with pytest.raises(KeyError, match="no camera 'left'"):
        pick.camera("left")


def test_extra_fields_survive_and_dump_round_trips(mixed, plugins):
    raw = copy.deepcopy(mixed[0])
    raw["custom_note"] = {"by": "me"}
    raw["task"]["carry_forward_rel_pos_threshold"] = 0.005
    ep = parse_episode(raw, plugins)
    assert ep.custom_note == {"by": "me"} and ep.task.carry_forward_rel_pos_threshold == 0.005
    dumped = ep.model_dump(mode="json")
    assert parse_episode(json.loads(json.dumps(dumped)), plugins) == ep
    assert dumped["img_resolution"] == [624, 352] and ep.img_resolution == (624, 352)


def test_unknown_task_class_parses_generically(mixed, plugins):
    raw = copy.deepcopy(mixed[0])
    raw["task"]["task_cls"] = "acme.tasks.StackTask"
    raw["task"].pop("task_type", None)
    ep = parse_episode(raw, plugins)
    assert type(ep.task) is schema.GenericTaskSpec and ep.task.pickup_obj_name.startswith("bowl_")
    raw["task"]["task_type"] = "pick"  # an unknown class that declares a known type is typed by it
    assert type(parse_episode(raw, plugins).task) is PickTaskSpec


def _errors(raw):
    with pytest.raises(ValidationError) as info:
        parse_episode(raw, Plugins())
    return {tuple(e["loc"]): e["msg"] for e in info.value.errors()}


@pytest.mark.parametrize(
    ("path", "value", "loc", "msg"),
    [
        (("task", "robot_base_pose"), [1, 2, 3, 1, 0, 0], ("task", "pick", "robot_base_pose"),
         "expected 7 values, got 6"),
        (("cameras", 0, "camera_offset"), [0.1, 0.2], ("cameras", 0, "robot_mounted", "camera_offset"),
         "expected 3 values, got 2"),
        (("cameras", 0, "camera_quaternion"), [0, 0, 0, 0], ("cameras", 0, "robot_mounted", "camera_quaternion"),
         "quaternion (qw, qx, qy, qz) must not be all zero"),
        (("scene_modifications", "object_poses", "pillow_1c5c1394_1_0_0"), [1, 2, 3, float("nan"), 0, 0, 0],
         ("scene_modifications", "object_poses", "pillow_1c5c1394_1_0_0"), "values must be finite"),
        (("img_resolution",), [224], ("img_resolution",), "expected 2 values (width, height), got 1"),
        (("task", "succ_pos_threshold"), -0.1, ("task", "pick", "succ_pos_threshold"), "greater than or equal to 0"),
    ],
)
def test_bad_vectors_and_values_are_rejected(mixed, path, value, loc, msg):
    raw = copy.deepcopy(mixed[0])
    target = raw
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    errors = _errors(raw)
    assert loc in errors and msg in errors[loc], errors


def test_molmospaces_names():
    assert molmospaces.task_aliases("pick") == (
        "molmo_spaces.tasks.pick_task.PickTask", "mujoco_thor.tasks.pick_task.PickTask")
    assert "molmo_spaces.tasks.opening_tasks.OpeningTask" in molmospaces.task_aliases("open")
    assert molmospaces.task_aliases("close") == ()  # reached through task_type, not by alias
    assert molmospaces.task_name_for("molmo_spaces.tasks.opening_tasks.OpeningTask", "close") == "close"
    assert molmospaces.task_name_for("molmo_spaces.tasks.opening_tasks.OpeningTask") == "open"
    assert molmospaces.known_task_name("mujoco_thor.tasks.nav_task.NavToObjTask") == "nav_to_obj"
    typed = {name for name in molmospaces.TASK_CLS
             if task_spec_model(Plugins(), {"task_cls": name})[1] is not schema.GenericTaskSpec}
    assert set(molmospaces.TASK_CLS) == typed  # every MolmoSpaces task type has its spec model
