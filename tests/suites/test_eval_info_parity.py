"""``eval_info.json``: ``molmo-eval``'s against ``lerobot-eval``'s on the same PushT episodes.

Theirs is ``lerobot-eval``'s own ``eval_main`` (LeRobot 0.6.1) with ``--env.type=pusht --seed=<S>
--env.episode_length=<H> --eval.n_episodes=<N> --eval.batch_size=1``: it builds the env, runs
``eval_policy_all`` and writes ``eval_info.json``. Only the policy is ours: ``make_policy`` gives a
``PreTrainedPolicy`` that plays molmo-eval's ``policy=random`` (the same class, reset with the seed
``lerobot-eval`` gives episode ``k``, ``S + k``; its chunks played one action per ``select_action``), and
the policy's own pre/post-processors are empty (it reads raw targets). Ours is ``molmo-eval policy=random
benchmark=pusht`` over the same seeds and horizon (``-m slow``; the default run plays the same episodes as
its workers do, without worker processes, and builds the document as the run does). Both documents are
compared: ``pc_success``,
``avg_sum_reward``, ``avg_max_reward``, ``n_episodes`` per group and overall, each task's group, id and
per-episode rows; times and video paths excepted (``lerobot-eval`` writes videos, molmo-eval none).
"""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from molmo_lerobot.benchmark_kinds import run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.export.eval_info import EVAL_INFO_FILE, eval_info
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.random_policy import RandomPolicy
from molmo_lerobot.results import summarize
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.suites import pusht
from molmo_lerobot.suites.benchmark import suite_plan

pytest.importorskip("gym_pusht")

SEED, EPISODES, HORIZON = 1000, 3, 40
#: rewards to the last bit but one: gym_pusht's coverage varies there from run to run (test_pusht_parity.py)
ATOL = 1e-12


def lerobot_eval_info(out: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """``lerobot-eval``'s ``eval_info.json`` for the episodes, written by its ``eval_main``."""
    import torch
    from lerobot.configs.default import EvalConfig
    from lerobot.configs.eval import EvalPipelineConfig
    from lerobot.envs.configs import PushtEnv
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.pretrained import PreTrainedPolicy
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
    from lerobot.scripts import lerobot_eval

    class MolmoRandom(PreTrainedPolicy):
        """molmo-eval's ``policy=random`` inside ``lerobot-eval``: reset with episode ``k``'s seed."""

        config_class, name = ACTConfig, "molmo_random"

        def __init__(self, config: ACTConfig) -> None:
            super().__init__(config)
            self.anchor = torch.nn.Parameter(torch.zeros(1))  # lerobot-eval reads the policy's device from one
            self.episodes, self.policy, self.queue = 0, RandomPolicy({}), deque()

        def reset(self) -> None:  # lerobot-eval resets the policy, then the env with seed start_seed + k
            self.policy.reset(EpisodeContext(spec=None, episode_index=self.episodes, seed=SEED + self.episodes,
                                             prompt="", move_groups={pusht.MOVE_GROUP: pusht.ACTION_DIM},
                                             policy_dt_s=1 / pusht.CONTROL_HZ,
                                             extra={"action_bounds": {pusht.MOVE_GROUP: pusht.WORKSPACE}}))
            self.episodes += 1
            self.queue.clear()

        def select_action(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
            if not self.queue:
                obs = {"qpos": {pusht.MOVE_GROUP: batch["observation.state"][0].numpy()}}
                self.queue.extend(self.policy.act(obs)[pusht.MOVE_GROUP])
            return torch.from_numpy(np.asarray(self.queue.popleft(), dtype=np.float32))[None]

        def get_optim_params(self) -> dict:
            return {}

        def forward(self, batch):
            raise NotImplementedError

        def predict_action_chunk(self, batch):
            raise NotImplementedError

    def empty_processors(**_: Any) -> tuple[PolicyProcessorPipeline, PolicyProcessorPipeline]:
        return (PolicyProcessorPipeline(steps=[]),
                PolicyProcessorPipeline(steps=[], to_transition=policy_action_to_transition,
                                        to_output=transition_to_policy_action))

    monkeypatch.setattr(lerobot_eval, "make_policy", lambda cfg, **_: MolmoRandom(cfg))
    monkeypatch.setattr(lerobot_eval, "make_pre_post_processors", empty_processors)
    cfg = EvalPipelineConfig(env=PushtEnv(episode_length=HORIZON), eval=EvalConfig(n_episodes=EPISODES, batch_size=1),
                             policy=ACTConfig(device="cpu"), output_dir=out, seed=SEED)
    lerobot_eval.eval_main(cfg)
    return json.loads((out / EVAL_INFO_FILE).read_text())


def molmo_eval_info(out: Path, whole_run: bool) -> tuple[dict[str, Any], dict[str, Any]]:
    """Ours: ``molmo-eval``'s ``eval_info.json`` and ``results.json`` (``whole_run``), or, cheaper, the same
    episodes played as its workers play them (``SuiteSession`` + the rollout loop, no worker processes) and
    both documents built from their results as the run builds them."""
    overrides = ["policy=random", "benchmark=pusht", f"seed={SEED}", f"horizon={HORIZON}",
                 f"benchmark.episodes_per_task={EPISODES}"]
    if whole_run:
        run_evaluation(compose([*overrides, "workers=1", "progress=false", f"output_dir={out}"]))
        return json.loads((out / EVAL_INFO_FILE).read_text()), json.loads((out / "results.json").read_text())
    config = RunConfig.of(compose(overrides))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    sessions, policy, results = run_kind(Plugins(), config).sessions_of(config), RandomPolicy({}), []
    try:
        for i, episode in enumerate(bench.episodes):
            session = sessions.open(suite_plan(i, bench.suite, episode, True), policy,
                                    end_on_success=config.end_on_success)
            results.append(rollout(session, policy, [], "random"))
    finally:
        sessions.close()
    summary = summarize(results, benchmark={"name": bench.name}, wall_time_s=1.0)
    return eval_info(summary, results), summary.document()


def _same_block(ours: dict[str, Any], theirs: dict[str, Any], where: str) -> None:
    timed = {"eval_s", "eval_ep_s"}
    assert set(ours) == set(theirs), where
    assert ours["n_episodes"] == theirs["n_episodes"] == EPISODES, where
    assert ours["pc_success"] == theirs["pc_success"], where
    for key in ("avg_sum_reward", "avg_max_reward"):
        assert ours[key] == pytest.approx(theirs[key], rel=0, abs=ATOL), f"{where}: {key}"
    assert ours["predicted_video_paths"] == theirs["predicted_video_paths"] == [], where
    assert ours["video_paths"] == [] and all(isinstance(ours[k], float) for k in timed & set(ours)), where


@pytest.mark.parametrize("whole_run", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["episodes", "molmo_eval"])
def test_eval_info_equals_lerobot_evals_on_the_same_episodes(tmp_path, monkeypatch, whole_run):
    theirs = lerobot_eval_info(tmp_path / "lerobot", monkeypatch)
    ours, results = molmo_eval_info(tmp_path / "molmo", whole_run)
    assert set(ours) == set(theirs) == {"per_task", "per_group", "overall"}
    (their_task,), (our_task,) = theirs["per_task"], ours["per_task"]
    assert set(our_task) == {*their_task, "task"} and our_task["task"] == "pusht/PushT-v0"
    assert (our_task["task_group"], our_task["task_id"]) == (their_task["task_group"], their_task["task_id"]) \
        == ("pusht", 0)
    mine, yours = our_task["metrics"], their_task["metrics"]
    assert set(mine) == set(yours) and mine["successes"] == yours["successes"]
    for key in ("sum_rewards", "max_rewards"):
        assert np.allclose(mine[key], yours[key], rtol=0, atol=ATOL), key
    assert max(yours["max_rewards"]) > 0  # the episodes push the block: the rewards are not all zero
    assert list(ours["per_group"]) == list(theirs["per_group"]) == ["pusht"]
    _same_block(ours["per_group"]["pusht"], theirs["per_group"]["pusht"], "per_group")
    _same_block(ours["overall"], theirs["overall"], "overall")
    # results.json reports the same rewards
    for block in (results, results["per_task"]["pusht/PushT-v0"]):
        assert block["avg_max_reward"] == pytest.approx(theirs["overall"]["avg_max_reward"], rel=0, abs=ATOL)
        assert block["avg_sum_reward"] == pytest.approx(theirs["overall"]["avg_sum_reward"], rel=0, abs=ATOL)
    assert results["per_task"]["pusht/PushT-v0"]["instructions"] == [""]  # lerobot-eval's PushT task is empty
