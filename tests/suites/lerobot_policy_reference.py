"""LeRobot's own evaluation of a checkpoint, for the policy-parity tests (``test_policy_parity.py``).

:func:`lerobot_eval_episodes` sets up what ``lerobot-eval --policy.path=<checkpoint> --policy.device=cpu
--eval.batch_size=1`` sets up (``eval_main``: ``make_env``, ``make_policy`` with the env's config, the policy's
pre/post-processors with ``eval_main``'s overrides, ``make_env_pre_post_processors``) and plays each episode with
its ``eval_policy`` (``rollout``: ``preprocess_observation`` → env pre-processor → policy pre-processor →
``select_action`` → post-processor → env post-processor), episode ``k`` seeded ``seed + k``. One departure:
``eval_main`` seeds torch's RNG once (``set_seed(seed)``, before it builds the policy); here ``set_seed`` runs
before each episode with its seed, as ``policy=lerobot`` seeds each episode, so a sampling policy (diffusion) draws
the same noise on both sides. Run in the LIBERO venv as ``python lerobot_policy_reference.py '<json>'`` for LIBERO
(``{"suite", "task_id", "size", "horizon", "runs": [{"checkpoint", "seed", "episodes"}, ...]}``: the runs one after
the other on one env, whose init state advances at each reset as in ``lerobot-eval``; prints one JSON line).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any


def make_lerobot_env(env_cfg: Any) -> Any:
    """``make_env(env_cfg, n_envs=1)``'s one vector env (one task)."""
    from lerobot.envs.factory import make_env

    [tasks] = make_env(env_cfg, n_envs=1).values()
    [env] = tasks.values()
    return env


def lerobot_eval_episodes(env_cfg: Any, env: Any, checkpoint: Path, seed: int, episodes: int) -> list[dict[str, Any]]:
    """Per episode on ``env``: ``eval_policy``'s success and seed, its steps and the action handed to the env at each
    step (a single env's rollout steps until its episode is done)."""
    import torch
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.envs.factory import make_env_pre_post_processors
    from lerobot.policies.factory import make_policy, make_pre_post_processors
    from lerobot.scripts.lerobot_eval import eval_policy
    from lerobot.utils.random_utils import set_seed

    policy_cfg = PreTrainedConfig.from_pretrained(checkpoint)  # EvalPipelineConfig's --policy.path
    policy_cfg.pretrained_path = checkpoint
    policy_cfg.device = "cpu"
    policy = make_policy(cfg=policy_cfg, env_cfg=env_cfg, rename_map={})
    policy.eval()
    pre, post = make_pre_post_processors(policy_cfg=policy_cfg, pretrained_path=policy_cfg.pretrained_path,
                                         preprocessor_overrides={"device_processor": {"device": "cpu"},
                                                                 "rename_observations_processor": {"rename_map": {}}})
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=policy_cfg)
    given: list[list[float]] = []
    step = env.step

    def logged_step(action):  # the action rollout hands the env, after every processor
        given.append(action[0].tolist())
        return step(action)

    env.step, out = logged_step, []
    try:
        with torch.no_grad():
            for k in range(episodes):
                set_seed(seed + k)
                given.clear()
                info = eval_policy(env, policy, env_pre, env_post, pre, post, n_episodes=1, start_seed=seed + k)
                [episode] = info["per_episode"]
                out.append({"success": bool(episode["success"]), "seed": int(episode["seed"]), "steps": len(given),
                            "actions": list(given)})
    finally:
        del env.step  # the class's own again
    return out


def main(args: dict[str, Any]) -> None:
    from lerobot.envs.configs import LiberoEnv

    cfg = LiberoEnv(task=args["suite"], task_ids=[args["task_id"]], episode_length=args["horizon"],
                    observation_height=args["size"], observation_width=args["size"])
    env = make_lerobot_env(cfg)
    print(json.dumps([lerobot_eval_episodes(cfg, env, Path(run["checkpoint"]), run["seed"], run["episodes"])
                      for run in args["runs"]]))
    env.close()


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
