"""LeRobot's own LIBERO evaluation, for the parity test: run with the LIBERO venv's Python.

``python lerobot_libero_reference.py '<json>'`` with ``{"suite", "task_id", "episodes", "seed", "horizon",
"policy", "size", "hard_reset"}`` builds the env exactly as ``lerobot-eval --env.type=libero --env.task=<suite>
--env.task_ids=[<task_id>] --env.episode_length=<horizon> --env.hard_reset=<hard_reset> --eval.batch_size=1``
does (``make_env`` over LeRobot's ``LiberoEnv`` config, its env processors) and plays ``episodes`` rollouts
with ``lerobot_eval.rollout``, seeding rollout ``k`` with ``seed + k`` as ``eval_policy`` does. The policy
(``parity_policies.py``) records what it is shown. Prints one JSON line: per episode, success (any step's
``is_success`` up to the first done, ``eval_policy``'s rule), steps (``select_action`` calls), the 8-D
states seen and a digest of both camera images at every step.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import torch
from lerobot.envs.configs import LiberoEnv as LiberoEnvConfig
from lerobot.envs.factory import make_env
from lerobot.processor import PolicyProcessorPipeline
from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
from lerobot.scripts.lerobot_eval import rollout

sys.path.insert(0, str(Path(__file__).parent))
from parity_policies import POLICIES


class Recorded(torch.nn.Module):
    """A policy of ``parity_policies`` as LeRobot's rollout calls it, remembering what it saw."""

    def __init__(self, act) -> None:
        super().__init__()
        self.act, self.seed, self.step = act, 0, 0
        self.states: list[list[float]] = []
        self.images: list[dict[str, str]] = []

    def reset(self) -> None:
        self.step, self.states, self.images = 0, [], []

    def select_action(self, obs: dict) -> torch.Tensor:
        self.states.append(obs["observation.state"][0].tolist())
        digests = {}
        for key in ("observation.images.image", "observation.images.image2"):
            img = (obs[key][0] * 255).round().to(torch.uint8).permute(1, 2, 0).contiguous().numpy()
            digests[key] = hashlib.sha256(img.tobytes()).hexdigest()
        self.images.append(digests)
        action = self.act(self.seed, self.step)
        self.step += 1
        return torch.from_numpy(action)[None]


def main(args: dict) -> None:
    cfg = LiberoEnvConfig(task=args["suite"], task_ids=[args["task_id"]], episode_length=args["horizon"],
                          observation_height=args["size"], observation_width=args["size"],
                          hard_reset=args.get("hard_reset", True))
    envs = make_env(cfg, n_envs=1)
    env = envs[args["suite"]][args["task_id"]]
    env_pre, env_post = cfg.get_env_processors()
    pre = PolicyProcessorPipeline(steps=[])
    post = PolicyProcessorPipeline(steps=[], to_transition=policy_action_to_transition,
                                   to_output=transition_to_policy_action)
    policy = Recorded(POLICIES[args["policy"]])
    out = []
    for k in range(args["episodes"]):
        policy.seed = args["seed"] + k
        data = rollout(env, policy, env_pre, env_post, pre, post, seeds=[args["seed"] + k])
        done = data["done"][0].to(int)
        first = int(torch.argmax(done))
        out.append({"success": bool(data["success"][0][: first + 1].any()), "steps": policy.step,
                    "done_at": first + 1, "states": policy.states, "images": policy.images})
    env.close()
    print(json.dumps({"episodes": out, "max_steps": dict(sorted(__import__(
        "lerobot.envs.libero", fromlist=["TASK_SUITE_MAX_STEPS"]).TASK_SUITE_MAX_STEPS.items()))}))


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
