"""LeRobot's own ALOHA evaluation, for the ALOHA parity tests: run with the ALOHA venv's Python.

``python lerobot_aloha_reference.py '<json>'`` with ``{"task", "horizon", "env": {"policy", "seed", "episodes"} |
null, "runs": [{"checkpoint", "seed", "episodes"}, ...]}`` builds the env as ``lerobot-eval --env.type=aloha
--env.task=<task> --env.episode_length=<horizon> --eval.batch_size=1`` does (``make_env`` over LeRobot's
``AlohaEnv`` config, its env processors). ``env``: plays ``episodes`` rollouts of a :data:`POLICIES` policy with
``lerobot_eval.rollout``, rollout ``k`` seeded ``seed + k`` (``eval_policy``'s seeding); per episode its success
(any step's ``is_success`` up to the first done), steps, every step's reward, and the 14-D state, a digest of the
top image and the task shown at every step. ``runs``: each checkpoint's episodes through ``eval_policy``
(``lerobot_policy_reference.py``). Prints one JSON line.

The policies are plain numpy (the test imports them from here): an action is a function of (episode seed, step).
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

#: gym-aloha's start pose per arm (six joints, gripper normalised): the policies move about it
_POSE = np.asarray([0.0, -0.96, 1.16, 0.0, -0.3, 0.0, 0.5] * 2)


def random_action(seed: int, step: int) -> np.ndarray:
    """A seeded uniform random 14-D joint target within 0.4 of the start pose (float32, as a policy's tensor)."""
    return (_POSE + np.random.default_rng([seed, step]).uniform(-0.4, 0.4, 14)).astype(np.float32)


def replay_action(seed: int, step: int) -> np.ndarray:
    """A fixed open-loop sweep (the same for every episode): the arms reach down and sideways, the grippers close
    and reopen."""
    t = float(step)
    wave = np.asarray([0.4 * np.sin(0.05 * t), 0.3 * np.sin(0.03 * t), -0.3 * np.sin(0.03 * t), 0.2 * np.sin(0.07 * t),
                       0.4 * np.sin(0.04 * t), 0.3 * np.cos(0.06 * t), 0.5 * np.cos(0.1 * t)])
    return (_POSE + np.concatenate([wave, -wave])).astype(np.float32)


POLICIES = {"random": random_action, "replay": replay_action}


def env_episodes(cfg: Any, env: Any, policy: str, seed: int, episodes: int) -> list[dict[str, Any]]:
    import torch
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
    from lerobot.scripts.lerobot_eval import rollout

    class Recorded(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.seed, self.shown = 0, []

        def reset(self) -> None:
            self.shown = []

        def select_action(self, obs: dict) -> torch.Tensor:
            img = (obs["observation.images.top"][0] * 255).round().to(torch.uint8).permute(1, 2, 0).contiguous()
            self.shown.append({"state": obs["observation.state"][0].tolist(), "task": obs["task"][0],
                               "image": hashlib.sha256(img.numpy().tobytes()).hexdigest()})
            return torch.from_numpy(POLICIES[policy](self.seed, len(self.shown) - 1))[None]

    env_pre, env_post = cfg.get_env_processors()
    pre = PolicyProcessorPipeline(steps=[])
    post = PolicyProcessorPipeline(steps=[], to_transition=policy_action_to_transition,
                                   to_output=transition_to_policy_action)
    rec, out = Recorded(), []
    for k in range(episodes):
        rec.seed = seed + k
        data = rollout(env, rec, env_pre, env_post, pre, post, seeds=[seed + k])
        first = int(torch.argmax(data["done"][0].to(int)))
        out.append({"success": bool(data["success"][0][: first + 1].any()), "steps": first + 1,
                    "rewards": data["reward"][0][: first + 1].tolist(), "shown": rec.shown})
    return out


def main(args: dict[str, Any]) -> None:
    from lerobot.envs.configs import AlohaEnv

    sys.path.insert(0, str(Path(__file__).parent))
    from lerobot_policy_reference import lerobot_eval_episodes, make_lerobot_env

    cfg = AlohaEnv(task=args["task"], episode_length=args["horizon"])
    env = make_lerobot_env(cfg)
    run = args.get("env")
    out = {"env": env_episodes(cfg, env, run["policy"], run["seed"], run["episodes"]) if run else None,
           "runs": [lerobot_eval_episodes(cfg, env, Path(r["checkpoint"]), r["seed"], r["episodes"])
                    for r in args.get("runs", [])]}
    env.close()
    print(json.dumps(out))


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
