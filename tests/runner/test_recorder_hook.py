"""A plugin's ``molmo_recorders`` factory subscribes to the one rollout loop inside the workers."""

from __future__ import annotations

import json
from pathlib import Path

from molmo_lerobot import hookimpl
from molmo_lerobot.config import compose
from molmo_lerobot.recording import Recorder, RecorderFactory
from molmo_lerobot.runner.evaluate import run_evaluation


class StepCounter(Recorder):
    wants_images = False

    def __init__(self, path: Path) -> None:
        self.path, self.steps, self.episodes, self.current = path, 0, [], 0

    def start_episode(self, info) -> None:
        self.current = 0

    def record_step(self, obs, action, reward, success, done) -> None:
        assert set(action) == {"arm", "gripper"} and "qpos" in obs
        self.current += 1

    def end_episode(self, result) -> None:
        self.episodes.append([result.episode_index, self.current, result.error])

    def close(self) -> None:
        self.path.write_text(json.dumps(self.episodes))


class StepCounterFactory(RecorderFactory):
    def make(self, worker_id, output_dir):
        return StepCounter(Path(output_dir) / f"steps-{worker_id}.json")

    def finalize(self, output_dir, results, summary) -> None:
        (Path(output_dir) / "finalized.json").write_text(json.dumps(summary.n_episodes))


class CounterPlugin:
    @hookimpl
    def molmo_recorders(self, config):
        return [StepCounterFactory()] if getattr(config, "count_steps", False) else []


def test_plugin_recorder_sees_every_step(tmp_path, in_process_plugins, fork_servers):
    in_process_plugins(CounterPlugin(), "step_counter")
    out = tmp_path / "run"
    run_evaluation(compose(["policy=random", "workers=2", "limit=3", "horizon=7", "+count_steps=true",
                            f"output_dir={out}", "progress=false"]), fork_servers)
    seen = sorted(e for f in out.glob("steps-*.json") for e in json.loads(f.read_text()))
    assert seen == [[0, 7, None], [1, 7, None], [2, 7, None]]
    assert json.loads((out / "finalized.json").read_text()) == 3
    assert (out / "report.html").exists()
