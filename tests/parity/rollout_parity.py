"""Our side of the rollout comparison (tests/parity/test_rollout_parity.py): an episode run by
``molmo-eval``'s own loop (``runner.rollout.rollout``) with a policy replaying given actions, the
actions the comparison replays, and episodes rewritten as MolmoSpaces writes its files
(:func:`their_format`).

Actions are in MolmoSpaces' convention (``arm`` 7 joint targets, ``gripper`` 0 … 255, one row of 8 per
step); ours reads them through ``policy.convention=molmospaces``. Three kinds, none depending on
floating-point noise of the run that replays them: ``fixed`` (a closed-form sweep of every joint about
``init_qpos`` and the gripper closing and opening), ``random`` (a seeded random walk of the joint
targets and random gripper commands), ``expert`` (our scripted expert's actions, recorded once by our
loop and then replayed on both sides).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot.benchmark.molmospaces import TASK_CLS
from molmo_lerobot.context import RunContext
from molmo_lerobot.policies.base import EpisodeContext, Policy
from molmo_lerobot.policies.convention import GRIPPER_CLOSED_CMD, get_convention
from molmo_lerobot.recording import EpisodeInfo, Recorder
from molmo_lerobot.runner.episode import EpisodeSession, load_run_benchmark
from molmo_lerobot.runner.plan import EpisodePlanner
from molmo_lerobot.runner.rollout import rollout

CONVENTION = get_convention("molmospaces")


def state(data: Any) -> np.ndarray:
    """What is compared per step: every joint position (arm, gripper, objects' free joints, articulated
    joints) and velocity."""
    return np.concatenate([data.qpos, data.qvel])


def fixed_actions(init_arm: np.ndarray, steps: int) -> np.ndarray:
    """Every joint swept about its start by up to 0.25 rad (its own phase); the gripper closes for 20
    steps, then opens for 20, from step 10."""
    t = np.arange(steps)[:, None]
    arm = init_arm[None] + 0.25 * np.sin(2 * np.pi * t / 40.0 + np.arange(7)[None] * 0.7)
    gripper = np.where(((t - 10) // 20) % 2 == 0, GRIPPER_CLOSED_CMD, 0.0) * (t >= 10)
    return np.hstack([arm, gripper])


def random_actions(init_arm: np.ndarray, steps: int, seed: int) -> np.ndarray:
    """A seeded random walk of the arm targets (steps of N(0, 0.03) rad, kept within 0.6 rad of the
    start) and a uniform random gripper command each step."""
    rng = np.random.default_rng(seed)
    arm = init_arm[None] + np.clip(np.cumsum(rng.normal(0.0, 0.03, (steps, 7)), axis=0), -0.6, 0.6)
    return np.hstack([arm, rng.uniform(0.0, GRIPPER_CLOSED_CMD, (steps, 1))])


class Replay(Policy):
    """Replays rows of MolmoSpaces-convention actions through the convention adapter's mapping."""

    needs_images = False

    def __init__(self, actions: np.ndarray) -> None:
        self.actions, self.t = actions, 0

    def reset(self, ctx: EpisodeContext) -> None:
        self.t = 0

    def act(self, obs) -> dict[str, np.ndarray]:
        a = self.actions[self.t]
        self.t += 1
        return CONVENTION.action({"arm": a[:7], "gripper": a[7:8]})


class StateRecorder(Recorder):
    """The state at the start and after every step, the success flag after every step; with ``actions``
    the policy's actions too (MolmoSpaces' convention)."""

    wants_images = False

    def __init__(self, env: Any) -> None:
        self.env, self.states, self.success, self.actions = env, [], [], []

    def start_episode(self, info: EpisodeInfo) -> None:
        self.states.append(state(self.env.data))

    def record_step(self, obs, action, reward, success, done) -> None:
        self.states.append(state(self.env.data))
        self.success.append(bool(success))
        self.actions.append(np.concatenate([action["arm"], np.asarray(action["gripper"]) * GRIPPER_CLOSED_CMD]))

    def end_episode(self, result) -> None:
        pass


@dataclass
class Episode:
    """One episode, run by our loop: what their side needs to run it too, and what ours saw."""

    spec: dict
    metadata: dict
    mjb: Path | None
    actions: np.ndarray
    states: np.ndarray
    success: list[bool]
    final: bool


def _context(benchmark: str | Path, horizon: int | None, config: dict | None = None):
    ctx = RunContext.build({"seed": 0, "horizon": horizon, "timing": {"sleep": True}, **(config or {})})
    bench = load_run_benchmark(benchmark, ctx.plugins)
    return ctx.for_benchmark(bench), bench


def save_model(model: mujoco.MjModel, path: Path) -> None:
    """The episode's compiled model as MJB (textures and meshes make it 100+ MB: a file, not an
    input), body sleeping off (their loop turns it on itself)."""
    m = copy.copy(model)
    m.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    mujoco.mj_saveModel(m, str(path), None)


def run(benchmark: str | Path, index: int, policy: Policy | str, horizon: int | None,
        actions: np.ndarray | None = None, mjb: Path | None = None, config: dict | None = None) -> Episode:
    """Episode ``index`` of ``benchmark`` (a name or a path) through our rollout loop for ``horizon`` steps
    (None: the episode's own), body sleeping on as in their loop; ``policy`` is ``"scripted"`` or a Policy.
    With ``mjb`` the compiled model is saved there; ``config`` adds to the run config (``scene_xml_paths``)."""
    from molmo_lerobot.policies.factory import make_policy
    from molmo_lerobot.runner.episode_env import build_env

    run, bench = _context(benchmark, horizon, config)
    plan = EpisodePlanner(run, bench).plan(index)
    spec = plan.episode(run.plugins)
    task_type = run.plugins.task_type(plan.task_type)
    env = build_env(spec, run.timing, run, run.config.camera.model_dump())
    try:
        env.reset(plan.seed)
        task = task_type.create(spec, env)
        if mjb is not None:
            save_model(env.model, mjb)
        expert = policy == "scripted"
        pol = make_policy(run.plugins, {"name": "scripted"}) if expert else policy
        session = EpisodeSession.start(plan, spec, env, task, run, policy=pol)
        rec = StateRecorder(env)
        rec.start_episode(session.recorder_info(expert=expert, extra={}))
        result = rollout(session, pol, [rec], "replay")
        return Episode(spec=raw_episode(bench, index, task_type.name), metadata=their_metadata(env), mjb=mjb,
                       actions=np.array(rec.actions) if actions is None else actions,
                       states=np.array(rec.states), success=rec.success, final=result.success)
    finally:
        env.close()


def raw_episode(bench: Any, index: int, task_type: str) -> dict:
    """Episode ``index`` as its file has it (what their ``EpisodeSpec`` reads), made runnable by their
    JSON eval: ``task_cls`` in MolmoSpaces' spelling (our pick and pick-and-place files name our classes,
    ``molmo_lerobot.tasks.pick.PickTask``, which their eval cannot import), for pick a
    ``pickup_obj_goal_pose``, for next-to the referral names ``pickup_name`` / ``place_name``, and a
    ``joint_start_position`` given as a number as a one-value list.
    docs/parity.md, "Our files in their eval"."""
    origin = bench.origins[index]
    raw = json.loads(Path(origin.file).read_text())
    raw = raw[origin.position] if origin.position is not None else raw
    raw["task"]["task_cls"] = TASK_CLS[task_type][0]
    if task_type == "pick" and raw["task"].get("pickup_obj_goal_pose") is None:
        # their PickTask.get_info (called after every step) reads it; no success rule does. Their pick
        # sampler puts it 5 cm above the start pose; our pick files do not carry it
        goal = list(raw["task"]["pickup_obj_start_pose"])
        goal[2] += 0.05
        raw["task"]["pickup_obj_goal_pose"] = goal
    names = raw.get("language", {}).get("referral_expressions", {})
    if task_type == "pick_and_place_next_to":  # their next-to task reads these two names at reset
        names.setdefault("pickup_name", names.get("pickup_obj_name"))
        names.setdefault("place_name", names.get("place_receptacle_name"))
    start = raw["task"].get("joint_start_position")
    if isinstance(start, int | float):  # their sampler reads joint_start_position[0]; ours takes a number too
        raw["task"]["joint_start_position"] = [start]
    return raw


def their_metadata(env: Any) -> dict:
    """The episode's scene metadata with the ``is_static`` flag their scene metadata gives every object
    (their loop reads it at reset to list the movable objects): true unless the body has a free joint."""
    meta = copy.deepcopy(env.scene_metadata)
    m = env.model
    for name, obj in meta.get("objects", {}).items():
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        free = bid >= 0 and m.body_jntnum[bid] == 1 and m.jnt_type[m.body_jntadr[bid]] == mujoco.mjtJoint.mjJNT_FREE
        obj.setdefault("is_static", not free)
    return meta


def init_arm(benchmark: str | Path, index: int, config: dict | None = None) -> np.ndarray:
    """The episode's arm start (its ``init_qpos``)."""
    _, bench = _context(benchmark, None, config)
    return np.asarray(bench.episodes[index].robot.init_qpos["arm"], dtype=np.float64)


def episode(benchmark: str | Path, index: int, kind: str, steps: int, mjb: Path,
            config: dict | None = None) -> Episode:
    """Ours on one case: ``kind`` ``fixed`` / ``random`` replay ``steps`` actions; ``expert`` runs the
    scripted expert over the episode's horizon and records its actions (their side replays them: the
    gripper as ``255 g``, which our convention maps back to ``g`` within a rounding). The model goes to
    ``mjb``; ``config`` as :func:`run`'s."""
    if kind == "expert":  # the expert's own run: its states, and its actions for their side to replay
        return run(benchmark, index, "scripted", None, mjb=mjb, config=config)
    arm = init_arm(benchmark, index, config)
    actions = fixed_actions(arm, steps) if kind == "fixed" else random_actions(arm, steps, seed=index)
    return run(benchmark, index, Replay(actions), len(actions), actions, mjb, config)


#: what MolmoSpaces' files carry that ours do not: the robot start of their ``FrankaRobotConfig`` (no base
#: joints, the gripper open at their driver angles), the cameras their DROID camera system records (the
#: wrist camera on ``gripper/base``, the exterior one on ``fr3_link0``) and its image size
#: (tests/data/molmospaces/mixed_tasks holds episodes written so)
THEIR_GRIPPER_OPEN = [0.00296, 0.00296]
THEIR_CAMERAS = [
    {"name": "wrist_camera", "type": "robot_mounted", "reference_body_names": ["robot_0/gripper/base"],
     "camera_offset": [0.031, 0.074, 0.022], "lookat_offset": [0.0, 0.0, 0.08],
     "camera_quaternion": [-0.006, -0.001, 0.986, 0.169], "fov": 56.74},
    {"name": "exo_camera_1", "type": "robot_mounted", "reference_body_names": ["robot_0/fr3_link0"],
     "camera_offset": [0.1, 0.57, 0.66], "lookat_offset": [0.0, 0.0, 0.08],
     "camera_quaternion": [-0.363, -0.124, 0.426, 0.819], "fov": 71.0}]
THEIR_RESOLUTION = [624, 352]


def their_format(cases: list[tuple[str, int]], root: Path) -> tuple[Path, dict]:
    """Episodes ``(benchmark, index)`` of our files rewritten as MolmoSpaces writes its own, each on a user
    scene in their layout built here: house ``k`` is ``root/scenes/house_<k>.xml`` with
    ``house_<k>_metadata.json`` beside it, the source episode's house as its scene dataset builds it,
    written as MJCF; episode ``k`` (``root/benchmark/benchmark.json``) names it (``scene_dataset: user``,
    house ``k``) and has :func:`raw_episode`'s task, their robot start, cameras and image size. Returns the
    benchmark dir and the run config that finds the scenes (``scene_xml_paths``)."""
    from molmo_lerobot.sim.env import PHYSICS_OPTIONS

    (root / "scenes").mkdir(parents=True)
    (root / "benchmark").mkdir()
    episodes, scenes = [], []
    for k, (benchmark, index) in enumerate(cases):
        run, bench = _context(benchmark, None)
        plan = EpisodePlanner(run, bench).plan(index)
        spec = plan.episode(run.plugins)
        dataset = run.plugins.scene_dataset(spec.scene_dataset)
        world = dataset.build_episode(spec, run)
        dataset.modify(world, spec, run)
        for option, value in dataset.physics_options(PHYSICS_OPTIONS, run).items():
            setattr(world.option, option, value)
        scene = root / "scenes" / f"house_{k}.xml"
        scene.write_text(world.to_xml())
        (root / "scenes" / f"house_{k}_metadata.json").write_text(json.dumps(dataset.episode_metadata(spec, run)))
        scenes.append(str(scene))
        raw = raw_episode(bench, index, run.plugins.task_type(plan.task_type).name)
        raw.update(scene_dataset="user", house_index=k, data_split="val", cameras=THEIR_CAMERAS,
                   img_resolution=THEIR_RESOLUTION)
        raw["robot"]["init_qpos"] = {"base": [], "arm": raw["robot"]["init_qpos"]["arm"], "gripper": THEIR_GRIPPER_OPEN}
        episodes.append(raw)
    (root / "benchmark" / "benchmark.json").write_text(json.dumps(episodes, indent=1))
    return root / "benchmark", {"scene_xml_paths": scenes}


def arm_xml() -> str:
    """Our franka_droid arm's MJCF, for their robot directory (their kinematics solvers load it)."""
    from molmo_lerobot.robots.franka_droid import load_droid_spec

    return load_droid_spec().to_xml()
