"""Stands for ``libero_server`` (LIBERO itself costs ~30 s an episode here) as a real child process on the suite
pipe: LIBERO's catalogue and observation layout; an episode's states and outcome follow from its task, seed and
actions. A fake LIBERO venv's ``bin/python`` runs it (``standin_venv`` in ``test_suite_process_faults.py``).

``$STANDIN_DIR``: each process writes its pid to ``pids`` there; a ``fault`` file there (``kill|stop SEED STEP``)
makes the process playing step STEP of the episode with seed SEED SIGKILL or SIGSTOP itself, once (the file is
renamed to ``fault.done`` first), and a ``slow_tasks`` file makes the task catalogue take ten minutes.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np

from molmo_lerobot.suites.pipe import serve

TASKS = [{"task_id": i, "name": f"task_{i}", "instruction": f"pick up object {i}", "bddl_file": f"standin/{i}.bddl",
          "init_states": 50} for i in range(4)]


class Standin:
    def __init__(self) -> None:
        self.dir = Path(os.environ["STANDIN_DIR"])
        with open(self.dir / "pids", "a") as f:
            f.write(f"{os.getpid()}\n")

    def tasks(self, suite: str) -> dict:
        if (self.dir / "slow_tasks").exists():  # a catalogue that takes its time: long enough for a Ctrl-C
            (self.dir / "in_tasks").touch()
            time.sleep(600)
        return {"suite": suite, "tasks": TASKS}

    def reset(self, suite: str, task_id: int, init_state_index: int, seed: int, width: int, height: int,
              hard_reset: bool = True) -> dict:
        self.seed, self.t, self.size = seed, 0, width
        self.state = np.full(8, task_id + 0.25 * init_state_index + seed / 7, dtype=np.float32)
        return {"observation": self._obs(True)}

    def step(self, action, images: bool = True) -> dict:
        self.t += 1
        self._fault()
        self.state = (self.state + np.resize(np.asarray(action, dtype=np.float32), 8)).astype(np.float32)
        success = self.seed % 2 == 1 and self.t >= 3  # odd seeds: the goal holds from step 3
        return {"observation": self._obs(images), "reward": float(success), "success": success,
                "terminated": success}

    def close_envs(self) -> dict:
        return {"ok": True}

    def _fault(self) -> None:
        fault = self.dir / "fault"
        if not fault.exists():
            return
        how, seed, step = fault.read_text().split()
        if (int(seed), int(step)) == (self.seed, self.t):
            fault.rename(self.dir / "fault.done")
            os.kill(os.getpid(), signal.SIGKILL if how == "kill" else signal.SIGSTOP)

    def _obs(self, images: bool) -> dict:
        obs = {"observation.state": self.state.copy()}
        if images:
            level = (self.seed * 40 + self.t * 9) % 250
            obs["observation.images.image"] = np.full((self.size, self.size, 3), level, np.uint8)
            obs["observation.images.image2"] = np.full((self.size, self.size, 3), 255 - level, np.uint8)
        return obs


def handlers() -> dict:
    server = Standin()
    return {"tasks": server.tasks, "reset": server.reset, "step": server.step, "close_envs": server.close_envs}


if __name__ == "__main__":
    serve(handlers)
