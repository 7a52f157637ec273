"""ALOHA's env server: run with the ALOHA venv's Python (``python -m molmo_lerobot.suites.aloha_server``), spoken to
through :mod:`~molmo_lerobot.suites.pipe` by :class:`~molmo_lerobot.suites.aloha.AlohaSuite`.

It makes gym-aloha's env as LeRobot's ``AlohaEnv`` config does (``gym.make("gym_aloha/<task>",
obs_type="pixels_agent_pos", render_mode="rgb_array", max_episode_steps=400)``), one per task, kept across
episodes, reset with the episode's seed, and steps it with the policy's float32 action. gym-aloha's task draws
three 480 × 640 cameras at every reset and step (``top``, ``angle``, ``front_close``) though only ``top`` is
observed; here only ``top`` is drawn, and only at the steps whose frame is asked for (``images``): drawing reads the
physics and writes none of it, so the states, rewards and the frames drawn are gym-aloha's own (the parity test
compares them with LeRobot's env bit for bit). A step is ~0.28 s with the three frames here, ~0.1 s with one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from molmo_lerobot.suites.pipe import serve_env_server

#: LeRobot's ``AlohaEnv.gym_kwargs`` (besides ``render_mode="rgb_array"``)
OBS_TYPE, MAX_EPISODE_STEPS = "pixels_agent_pos", 400
#: the camera a policy sees (LeRobot's ``observation.images.top``)
CAMERA = "top"


class _Frames:
    """Stands in for a dm-control ``Physics.render`` on one env: draws the observed camera when frames are wanted,
    blank frames of the asked size otherwise (the cameras nobody observes, the steps nobody looks at)."""

    def __init__(self, physics: Any) -> None:
        self.draw, self.wanted = physics.render, True

    def __call__(self, height: int = 240, width: int = 320, camera_id: int | str = -1, **kwargs: Any) -> np.ndarray:
        if self.wanted and camera_id == CAMERA:
            return self.draw(height=height, width=width, camera_id=camera_id, **kwargs)
        return np.zeros((height, width, 3), dtype=np.uint8)


class AlohaServer:
    """The request handlers; state: one gym-aloha env per task, the current one."""

    def __init__(self) -> None:
        import gym_aloha  # noqa: F401  (registers gym_aloha/*)

        self._envs: dict[str, tuple[Any, _Frames]] = {}
        self._env: tuple[Any, _Frames] | None = None

    def _make(self, task: str) -> tuple[Any, _Frames]:
        import gymnasium as gym

        if task not in self._envs:
            env = gym.make(f"gym_aloha/{task}", disable_env_checker=True, obs_type=OBS_TYPE, render_mode="rgb_array",
                           max_episode_steps=MAX_EPISODE_STEPS)
            aloha: Any = env.unwrapped  # gym_aloha's AlohaEnv over a dm-control environment
            physics = aloha._env.physics
            frames = _Frames(physics)
            physics.render = frames
            self._envs[task] = (env, frames)
        return self._envs[task]

    def tasks(self, task: str) -> dict[str, Any]:
        """The benchmark's one task and its instruction (gym-aloha's ``task``, what ``lerobot-eval`` prompts with)."""
        env, _ = self._make(task)
        return {"tasks": [{"task_id": 0, "task": task, "instruction": str(env.unwrapped.task)}]}

    def reset(self, task: str, seed: int) -> dict[str, Any]:
        """Start an episode; its first observation."""
        self._env = self._make(task)
        env, frames = self._env
        frames.wanted = True
        obs, _ = env.reset(seed=int(seed))
        return {"observation": self._observation(obs, True)}

    def step(self, action: Any, images: bool = True) -> dict[str, Any]:
        """One control step: the new observation, reward, success and termination; without ``images`` the frame
        is not drawn and the observation has the state only."""
        if self._env is None:
            raise RuntimeError("step before reset")
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (14,):
            raise ValueError(f"action: expected shape (14,), got {action.shape}")
        env, frames = self._env
        frames.wanted = images
        obs, reward, terminated, _truncated, info = env.step(action)
        return {"observation": self._observation(obs, images), "reward": float(reward),
                "success": bool(info["is_success"]), "terminated": bool(terminated)}

    @staticmethod
    def _observation(obs: dict[str, Any], images: bool) -> dict[str, Any]:
        out = {"observation.images.top": np.ascontiguousarray(obs["pixels"][CAMERA])} if images else {}
        out["observation.state"] = np.asarray(obs["agent_pos"], dtype=np.float32)
        return out

    def close_envs(self) -> dict[str, Any]:
        for env, _ in self._envs.values():
            env.close()
        self._envs.clear()
        self._env = None
        return {"ok": True}


def main() -> None:
    serve_env_server(AlohaServer)


if __name__ == "__main__":
    main()
