"""LIBERO's env server: run with the LIBERO venv's Python (``python -m molmo_lerobot.suites.libero_server``),
spoken to through :mod:`~molmo_lerobot.suites.pipe` by :class:`~molmo_lerobot.suites.libero.LiberoSuite`.

It builds LIBERO's own ``OffScreenRenderEnv`` from the task's BDDL file and plays an episode the way
LeRobot's ``LiberoEnv`` does (``lerobot-eval --env.type=libero``): reset with the episode's seed, set the
task's init state, settle for :data:`SETTLE_STEPS` no-op steps, then delta end-effector control; a step
succeeds when LIBERO's goal predicates hold, and the episode terminates then. Observations follow LeRobot's
LIBERO datasets: ``observation.images.image`` (agent view) and ``observation.images.image2`` (wrist), each
turned 180° (LIBERO renders them upside down), and an 8-D ``observation.state``: end-effector position,
its orientation as an axis-angle, the two gripper finger positions.

One env per task is kept and reset per episode; with ``hard_reset`` (LeRobot's default) LIBERO rebuilds
the model at every reset, without it it reuses the compiled model.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from molmo_lerobot.suites.pipe import serve

#: no-op steps after setting the init state, so that objects settle (LeRobot's ``num_steps_wait``)
SETTLE_STEPS = 10
#: the no-op action: no motion, gripper open
NOOP = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0)
#: LIBERO's camera observation → LeRobot's LIBERO dataset feature
CAMERAS = {"agentview_image": "observation.images.image", "robot0_eye_in_hand_image": "observation.images.image2"}
CONTROL_FREQ = 20


def axis_angle(quat_xyzw: np.ndarray) -> np.ndarray:
    """A unit quaternion (x, y, z, w) as a rotation vector (axis × angle), zero for the identity. In float32
    with torch's kernels, as LeRobot computes it for ``lerobot-eval``: numpy's float32 ``arccos`` differs from
    torch's in the last bit for about a third of all angles, and a policy should see the same bits."""
    import torch

    q = torch.as_tensor(np.asarray(quat_xyzw), dtype=torch.float32)
    w = q[3].clamp(-1.0, 1.0)
    sin_half = torch.sqrt(torch.clamp(1.0 - w * w, min=0.0))
    if not sin_half > 1e-10:
        return np.zeros(3, dtype=np.float32)
    return ((q[:3] / sin_half) * (2.0 * torch.acos(w))).numpy()


class LiberoServer:
    """The request handlers; state: the LIBERO benchmark objects, one env per task, the current episode."""

    def __init__(self) -> None:
        if "LIBERO_CONFIG_PATH" not in os.environ:
            raise SystemExit("libero_server: LIBERO_CONFIG_PATH is not set (LiberoSuite sets it)")
        from libero.libero import benchmark

        self._benchmarks = benchmark.get_benchmark_dict()
        self._suites: dict[str, Any] = {}
        self._envs: dict[tuple, Any] = {}
        self._env = None

    def _suite(self, suite: str) -> Any:
        if suite not in self._suites:
            if suite not in self._benchmarks:
                raise ValueError(f"unknown LIBERO suite {suite!r} (known: {', '.join(sorted(self._benchmarks))})")
            self._suites[suite] = self._benchmarks[suite]()
        return self._suites[suite]

    def tasks(self, suite: str) -> dict[str, Any]:
        """The suite's tasks: name, instruction, BDDL file and number of init states."""
        s = self._suite(suite)
        out = []
        for i in range(s.get_num_tasks()):
            task = s.get_task(i)
            out.append({"task_id": i, "name": task.name, "instruction": task.language,
                        "bddl_file": f"{task.problem_folder}/{task.bddl_file}",
                        "init_states": len(s.get_task_init_states(i))})
        return {"suite": suite, "tasks": out}

    def reset(self, suite: str, task_id: int, init_state_index: int, seed: int, width: int, height: int,
              hard_reset: bool = True) -> dict[str, Any]:
        """Start an episode; its first observation."""
        from libero.libero import get_libero_path
        from libero.libero.envs import OffScreenRenderEnv

        s = self._suite(suite)
        key = (suite, task_id, width, height, hard_reset)
        env = self._envs.get(key)
        if env is None:
            for other in self._envs.values():  # one live env (one GL context) per process
                other.close()
            self._envs.clear()
            task = s.get_task(task_id)
            env = OffScreenRenderEnv(bddl_file_name=os.path.join(get_libero_path("bddl_files"), task.problem_folder,
                                                                 task.bddl_file),
                                     camera_heights=height, camera_widths=width, control_freq=CONTROL_FREQ,
                                     hard_reset=hard_reset)
            env.reset()
            self._envs[key] = env
        states = s.get_task_init_states(task_id)
        env.seed(seed)
        env.reset()
        raw = env.set_init_state(states[init_state_index % len(states)])
        for _ in range(SETTLE_STEPS):
            raw, _, _, _ = env.step(list(NOOP))
        for robot in env.robots:
            robot.controller.use_delta = True
        self._env = env
        return {"observation": self._observation(raw)}

    def step(self, action: Any) -> dict[str, Any]:
        """One control step: the new observation, reward, success and termination."""
        if self._env is None:
            raise RuntimeError("step before reset")
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (7,):
            raise ValueError(f"action: expected shape (7,), got {action.shape}")
        raw, reward, done, _ = self._env.step(action)
        success = bool(self._env.check_success())
        return {"observation": self._observation(raw), "reward": float(reward), "success": success,
                "terminated": bool(done) or success}

    @staticmethod
    def _observation(raw: dict[str, Any]) -> dict[str, Any]:
        obs = {key: np.ascontiguousarray(raw[cam][::-1, ::-1]) for cam, key in CAMERAS.items()}
        obs["observation.state"] = np.concatenate([raw["robot0_eef_pos"], axis_angle(raw["robot0_eef_quat"]),
                                                   raw["robot0_gripper_qpos"]]).astype(np.float32)
        return obs

    def close_envs(self) -> dict[str, Any]:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
        self._env = None
        return {"ok": True}


def main() -> None:
    server = LiberoServer()
    try:
        serve({"tasks": server.tasks, "reset": server.reset, "step": server.step, "close_envs": server.close_envs})
    finally:
        server.close_envs()


if __name__ == "__main__":
    main()
