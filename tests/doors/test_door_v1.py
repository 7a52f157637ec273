"""door_rooms scenes, the door_v1 generator, the door expert and door_v1 end to end (mobile_franka)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.config import compose
from molmo_lerobot.content.doors.generate import generate_benchmark
from molmo_lerobot.content.doors.scenes import DOOR_NAME, HINGE_JOINT, DoorRooms, door_geometry, layout
from molmo_lerobot.content.libero.objects import assets_root
from molmo_lerobot.context import RunContext
from molmo_lerobot.policies.scripted import ScriptedExpert
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.runner.plan import plan_spec, resolve_horizon
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.tasks.door_opening import door_handles, door_hinge

SHIPPED = Path(__file__).resolve().parents[2] / "benchmarks" / "door_v1"


def test_shipped_door_v1_is_what_the_generator_writes():
    episodes, metadata = generate_benchmark(12, 5, 0, "door_v1")
    assert json.loads((SHIPPED / "benchmark.json").read_text()) == episodes
    assert json.loads((SHIPPED / "benchmark_metadata.json").read_text()) == metadata
    assert len(episodes) >= 60 and metadata["num_houses"] >= 10
    assert all(e["task"]["task_horizon_sec"] > 0 and e["robot"]["robot_name"] == "mobile_franka" for e in episodes)
    assert set(metadata["prompt_counts"]) == {"Push the door open", "Pull the door open"}


def test_houses_are_deterministic_and_varied():
    scene = DoorRooms()
    a, b = scene.build(7).to_xml(), scene.build(7).to_xml()
    assert a == b and scene.metadata(7) == scene.metadata(7)
    lays = [layout(h) for h in range(40)]
    assert {lay["leaf_dir"] for lay in lays} == {-1, 1} and {lay["swing_side"] for lay in lays} == {-1, 1}
    assert max(lay["width"] for lay in lays) - min(lay["width"] for lay in lays) > 0.08
    assert str(assets_root()) in a  # LIBERO's textures, read where the distribution installed them


def test_door_has_molmospaces_door_layout():
    """Their Door view: hinge = the joint not named *handle*, handles = the leaves of the door's tree."""
    model = DoorRooms().build(3).compile()
    door = model.body(DOOR_NAME).id
    hinge = door_hinge(model, door)
    assert model.joint(hinge).name == HINGE_JOINT
    lo, hi = model.jnt_range[hinge]
    assert (lo, hi) == pytest.approx((0.0, np.pi / 2))
    assert model.jnt_stiffness[hinge] == 0.0 and model.dof_damping[model.jnt_dofadr[hinge]] > 0  # latch-free
    names = sorted(model.body(b).name for b in door_handles(model, door))
    assert names == ["door/handle_neg", "door/handle_pos"]
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    xs = sorted(float(data.xpos[model.body(n).id][0]) for n in names)
    assert xs[0] < 0 < xs[1]  # one handle on each face
    assert door_geometry(3)["hinge"][1] == pytest.approx(float(data.xanchor[hinge][1]))


def _run_expert(raw: dict) -> tuple[bool, float]:
    run = RunContext.build()
    plugins = run.plugins
    timing = Timing()
    spec = parse_episode(raw, plugins)
    task_type = plugins.task_type(spec.task_name)
    env = build_env(spec, timing, run)
    try:
        env.reset(spec.seed)
        task = task_type.create(spec, env)
        horizon = resolve_horizon(None, spec.task, task_type.default_horizon_sec, timing.policy_dt_ms)
        expert = ScriptedExpert({})
        plan = plan_spec(spec, run.plugins, seed=spec.seed, horizon=horizon)
        session = EpisodeSession.start(plan, spec, env, task, run, policy=expert)
        out = rollout(session, expert, [], "scripted")
        return out.success, task.openness()
    finally:
        env.close()


def _molmospaces_shape(raw: dict) -> dict:
    """As their door sampler writes an episode: their task_type name, no range, reset state,
    threshold or horizon (their defaults apply), a source trajectory, their robot name."""
    task = {k: v for k, v in raw["task"].items() if k in ("task_cls", "robot_base_pose", "door_body_name")}
    return {**raw, "robot": {**raw["robot"], "robot_name": "mobile_franka_droid"},
            "task": {**task, "task_type": "door_open"},
            "source": {"h5_file": "house_0/trajectories_batch_1.h5", "traj_key": "traj_0"}}


@pytest.mark.parametrize("prompt, shape", [("Push the door open", None), ("Pull the door open", _molmospaces_shape)])
def test_expert_opens_the_door_pushing_and_pulling(prompt, shape):
    """A push episode of door_v1, and a pull episode in the shape MolmoSpaces writes, on door_rooms."""
    episodes = json.loads((SHIPPED / "benchmark.json").read_text())
    raw = next(e for e in episodes if e["language"]["task_description"] == prompt)
    success, openness = _run_expert(shape(raw) if shape else raw)
    assert success and openness >= 0.67


@pytest.mark.slow
def test_door_run_records_a_dataset_with_the_base_group(tmp_path):
    """molmo-eval on door_v1 (one episode, recorded): the LeRobot dataset loads with the base group."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out = tmp_path / "run"
    res = run_evaluation(compose(["policy=scripted", "benchmark=door_v1", "workers=1", "limit=1", "record=true",
                                  f"output_dir={out}", "progress=false"]))
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == 1
    ds = LeRobotDataset("local/door", root=out / "dataset", video_backend="pyav")
    for key in ("observation.state", "action"):
        assert ds.meta.features[key]["names"][:3] == ["base_x", "base_y", "base_theta"]
    assert ds[0]["observation.state"].shape == (11,)
    assert {"observation.images.head_camera", "observation.images.wrist_camera"} <= set(ds.meta.features)
