"""Built-in sim policies through the real rollout loop: the scripted expert picks, random does not."""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import plan_spec
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.tasks.base import Task

HORIZON = 100  # the script needs about 60 policy steps; 100 also checks that the hold lasts


@pytest.fixture(scope="module")
def episodes():
    return generate_benchmark("pick", 2, 1, 11, "test")[0]


def _run(raw, policy_name, horizon=HORIZON, config=None):
    run = RunContext.build()
    plugins = run.plugins
    spec = parse_episode(raw, plugins)
    timing = Timing()
    policy = plugins.policy(policy_name).factory({"name": policy_name, **(config or {})})
    env = build_env(spec, timing, run)
    try:
        env.reset(spec.seed)
        task = plugins.task_type(spec.task.task_cls).create(spec, env)
        plan = plan_spec(spec, plugins, seed=spec.seed, horizon=horizon)
        outcome = rollout(EpisodeSession.start(plan, spec, env, task, run, policy=policy), policy, [], policy_name)
        return outcome, env.data.qpos.copy()
    finally:
        env.close()


def test_scripted_picks_two_episodes(episodes):
    for raw in episodes:
        outcome, _ = _run(raw, "scripted")
        assert outcome.success and outcome.success_once, raw["task"]["pickup_obj_name"]


def test_scripted_returns_chunks_without_images(episodes):
    run = RunContext.build()
    plugins = run.plugins
    spec = parse_episode(episodes[0], plugins)
    policy = plugins.policy("scripted").factory({"name": "scripted", "chunk": 5})
    assert policy.needs_images is False
    env = build_env(spec, Timing(), run)
    try:
        env.reset(0)
        policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=0, prompt="", move_groups=env.move_groups,
                                    policy_dt_s=0.066, env=env, catalog=run.catalog, expert=plugins.expert("pick")))
        chunk = policy.act(env.observe(images=False))
        assert chunk["arm"].shape == (5, 7) and chunk["gripper"].shape == (5, 1)
        assert np.all(chunk["gripper"] == 0.0)  # open while approaching
    finally:
        env.close()


def test_scripted_refuses_a_robot_without_a_hand_naming_it(episodes, monkeypatch):
    """No silent fallback to another robot's fingers: a robot stating no hand geometry is refused at reset."""
    from molmo_lerobot.robots.franka import Franka

    run = RunContext.build()
    spec = parse_episode(episodes[0], run.plugins)
    policy = run.plugins.policy("scripted").factory({"name": "scripted"})
    env = build_env(spec, Timing(), run)
    try:
        env.reset(0)
        monkeypatch.setattr(Franka, "hand_geometry", None)
        with pytest.raises(ValueError, match=r"^scripted pick: robot 'franka' has no hand geometry "
                                             r"\(RobotType.hand_geometry\)"):
            policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=0, prompt="", move_groups=env.move_groups,
                                        policy_dt_s=0.066, env=env, catalog=run.catalog,
                                        expert=run.plugins.expert("pick")))
    finally:
        env.close()


def test_each_robot_states_the_hand_its_built_in_grasps_are_computed_for():
    from molmo_lerobot.assets.builtin import HANDS, PANDA_HAND, ROBOTIQ_2F85

    plugins = Plugins()
    hands = {name: plugins.robot(name).hand_geometry for name in ("franka", "franka_droid", "franka_droid_fr3",
                                                                   "mobile_franka", "rby1")}
    assert hands == {"franka": PANDA_HAND, "franka_droid": ROBOTIQ_2F85, "franka_droid_fr3": ROBOTIQ_2F85,
                     "mobile_franka": ROBOTIQ_2F85, "rby1": None}
    for name in ("franka", "franka_droid", "franka_droid_fr3"):
        robot = plugins.robot(name)
        assert HANDS[robot.hand] == robot.hand_geometry, name


def test_scripted_needs_privileged_env(episodes):
    plugins = Plugins()
    spec = parse_episode(episodes[0], plugins)
    policy = plugins.policy("scripted").factory({})
    with pytest.raises(ValueError, match="privileged"):
        policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=0, prompt="", move_groups={"arm": 7, "gripper": 1},
                                    policy_dt_s=0.066))


def test_random_is_seeded_and_fails(episodes):
    a, qa = _run(episodes[0], "random")
    _b, qb = _run(episodes[0], "random")
    assert np.array_equal(qa, qb)  # same episode seed, same rollout
    assert not a.success and not a.success_once


class _Scripted:
    """A test policy: plays fixed chunks, records what it was given."""

    needs_images = False
    needs_simulator = False

    def __init__(self, chunks):
        self.chunks, self.ctx = list(chunks), None

    def reset(self, ctx):
        self.ctx = ctx

    def act(self, obs):
        return self.chunks.pop(0) if self.chunks else {"gripper": np.zeros(1)}


class _SuccessAt(Task):
    """A task that succeeds exactly at the given (1-based) steps."""

    def __init__(self, steps):
        self.steps, self.n = set(steps), 0

    def setup(self):
        pass

    def success(self):
        self.n += 1
        return self.n in self.steps

    def reward(self):
        return None


def _loop(episodes, policy, task, horizon=12, **kw):
    run = RunContext.build()
    spec = parse_episode(episodes[0], run.plugins)
    env = build_env(spec, Timing(), run)
    try:
        env.reset(0)
        session = EpisodeSession.start(plan_spec(spec, run.plugins, seed=0, horizon=horizon), spec, env, task, run,
                                       policy=policy, **kw)
        return rollout(session, policy, [], "test"), env.robot.targets(env.data, "arm"), env
    finally:
        env.close()


def test_left_out_move_group_holds_its_target(episodes):
    start = parse_episode(episodes[0], Plugins()).robot.init_qpos["arm"]
    out, arm, _ = _loop(episodes, _Scripted([{"gripper": np.ones((4, 1))}]), _SuccessAt([]), horizon=8)
    assert out.steps == 8 and np.allclose(arm, start)


def test_done_ends_the_episode_after_its_step(episodes):
    chunk = {"gripper": np.zeros((4, 1)), "done": [False, True, False, False]}
    out, _, _ = _loop(episodes, _Scripted([chunk]), _SuccessAt([]))
    assert out.steps == 2 and out.extra["ended_by"] == "done" and not out.success


def test_end_on_success(episodes):
    out, _, _ = _loop(episodes, _Scripted([]), _SuccessAt([3]), end_on_success=True)
    assert out.steps == 3 and out.extra["ended_by"] == "success" and out.success and out.success_once
    out, _, _ = _loop(episodes, _Scripted([]), _SuccessAt([3]))
    assert out.steps == 12 and out.extra["ended_by"] == "horizon" and not out.success


def test_success_once_is_sampled_at_chunk_ends(episodes):
    """MolmoSpaces records success once per observation, i.e. after each chunk; the per-step figure is an extra."""
    chunks = [{"gripper": np.zeros((4, 1))} for _ in range(3)]
    out, _, _ = _loop(episodes, _Scripted(chunks), _SuccessAt([2]))  # mid-chunk only
    assert not out.success_once and out.extra["success_any_step"]
    chunks = [{"gripper": np.zeros((4, 1))} for _ in range(3)]
    out, _, _ = _loop(episodes, _Scripted(chunks), _SuccessAt([4]))  # a chunk's last step
    assert out.success_once and out.extra["success_any_step"]


def test_only_privileged_policies_get_the_simulator(tmp_path, episodes):
    """Through the worker: scripted experts see ctx.env, a policy under evaluation gets None."""
    from molmo_lerobot.benchmark.load import Benchmark, Origin
    from molmo_lerobot.runner.plan import EpisodePlanner
    from molmo_lerobot.runner.worker import EpisodeWorker, WorkerJob

    seen = {}
    plugins = Plugins()
    config = {"timing": {"policy_dt_ms": 66.0, "ctrl_dt_ms": 2.0, "sim_dt_ms": 2.0}, "horizon": 2}
    bench = Benchmark("t", [parse_episode(episodes[0], plugins)], None, "", tmp_path, [Origin("t.json")])
    plan = EpisodePlanner(RunContext.build(config), bench).plan(0)
    for name in ("scripted", "random"):
        job = WorkerJob(config=RunConfig.of(config), policy={"name": name}, output_dir=str(tmp_path),
                        benchmark_name="t", benchmark_sha256="0" * 64)
        worker = EpisodeWorker(job, "w0")
        original = worker.policy.reset
        worker.policy.reset = lambda ctx, _o=original, _n=name: (seen.__setitem__(_n, ctx.env), _o(ctx))
        result = worker.run(plan)
        assert result.error is None and result.extra["ended_by"] == "horizon"
        worker.close()
    assert seen["scripted"] is not None and seen["random"] is None
    assert plugins.policy("scripted").factory({}).needs_simulator
    assert not plugins.policy("random").factory({}).needs_simulator
