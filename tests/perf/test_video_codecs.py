"""Recorded-video codecs on real renders (``pytest -m perf -s tests/perf/test_video_codecs.py``).

Renders both cameras of one scripted pick_v1 episode, then streams the frames through
:class:`CameraStreamEncoder` once per ``video`` setting and reports, per setting: CPU per
frame (both cameras, encoding plus pixel statistics, all threads), bytes per frame, PSNR
against the renders, and the time to decode one random frame (what a training data loader
pays, with PyAV). Also reports LeRobot's own per-frame image statistics
(``RunningQuantileStats``, what its streaming encoder does) against :class:`PixelStats`.
Figures are printed and appended to ``runs/perf.jsonl``; nothing is asserted about speed.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import av
import numpy as np
import pytest
from lerobot.datasets.compute_stats import RunningQuantileStats

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.export.video import CameraStreamEncoder, PixelStats, VideoSettings
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.factory import make_policy
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import episode_seed, resolve_horizon
from molmo_lerobot.sim.env import Timing

pytestmark = pytest.mark.perf
SETTINGS = [{"vcodec": "h264"}, {"vcodec": "libsvtav1"}, {"vcodec": "h264", "crf": 23},
            {"vcodec": "libsvtav1", "g": 30}]


def _render_episode() -> dict[str, np.ndarray]:
    """Both cameras at every policy step of pick_v1 episode 0, driven by the scripted expert."""
    run = RunContext.build()
    plugins = run.plugins
    spec = load_benchmark(data_path("benchmarks") / "pick_v1", plugins).episodes[0]
    timing = Timing()
    task_type = plugins.task_type(spec.task_name)
    horizon = resolve_horizon(None, spec.task, task_type.default_horizon_sec, timing.policy_dt_ms)
    env = build_env(spec, timing, run)
    seed = episode_seed(0, spec.model_dump(mode="json"))
    env.reset(seed)
    task = task_type.create(spec, env)
    policy = make_policy(plugins, {"name": "scripted"})
    policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=seed, prompt=spec.language.task_description,
                                move_groups=env.move_groups, policy_dt_s=timing.policy_dt_s,
                                env=env, catalog=run.catalog, expert=run.plugins.expert(task_type.name)))
    task.setup()
    frames: dict[str, list[np.ndarray]] = {cam: [] for cam in env.camera_names}
    queue: list[dict] = []
    for _ in range(horizon):
        obs = env.observe(images=True)
        for cam, img in obs["images"].items():
            frames[cam].append(img.copy())
        if not queue:
            out = policy.act(obs)
            arm, grip = np.atleast_2d(out["arm"]), np.atleast_2d(out["gripper"])
            queue = [{"arm": arm[t], "gripper": grip[t]} for t in range(len(arm))]
        env.step(queue.pop(0))
    env.close()
    return {cam: np.stack(f) for cam, f in frames.items()}


def _random_access_ms(path: Path, n: int, rng: np.random.Generator) -> float:
    """Mean time to open the file, seek to a random frame and decode it (PyAV)."""
    picks = rng.integers(0, n, size=20)
    t0 = time.perf_counter()
    for i in picks:
        with av.open(str(path)) as c:
            stream = c.streams.video[0]
            target = int(i) / float(stream.average_rate)
            c.seek(int(target / stream.time_base), stream=stream, backward=True)
            for frame in c.decode(stream):
                if frame.time >= target - 1e-6:
                    break
    return (time.perf_counter() - t0) / len(picks) * 1000


def test_video_codecs(tmp_path):
    frames = _render_episode()
    n = len(next(iter(frames.values())))
    rng = np.random.default_rng(0)
    rows = []
    for block in SETTINGS:
        enc = CameraStreamEncoder(15, VideoSettings.from_config(block).encoder_config(), n + 1, 1)
        enc.start_episode(list(frames), tmp_path)
        c0 = time.process_time()
        for i in range(n):
            for cam in frames:
                enc.feed_frame(cam, frames[cam][i])
        results = enc.finish_episode()
        cpu_ms = (time.process_time() - c0) / n * 1000
        size = psnr = access = 0.0
        for cam, (path, _) in results.items():
            with av.open(str(path)) as c:
                decoded = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)])
            assert decoded.shape == frames[cam].shape
            mse = float(((decoded.astype(np.float64) - frames[cam]) ** 2).mean())
            psnr += 10 * np.log10(255**2 / mse) / len(results)
            size += path.stat().st_size / n / 1024
            access += _random_access_ms(path, n, rng) / len(results)
        rows.append({"video": block, "cpu_ms_per_frame": round(cpu_ms, 2), "kb_per_frame": round(size, 2),
                     "psnr_db": round(psnr, 2), "random_frame_ms": round(access, 2)})

    sample = frames[next(iter(frames))][: min(n, 100)]
    mine, theirs = PixelStats(), RunningQuantileStats()
    t0 = time.process_time()
    for img in sample:
        mine.update(img)
    t1 = time.process_time()
    for img in sample:
        theirs.update(img.reshape(-1, 3))
    t2 = time.process_time()
    figures = {"benchmark": "video_codecs", "frames": n, "cameras": len(frames), "codecs": rows,
               "pixel_stats_ms": round((t1 - t0) / len(sample) * 1000, 3),
               "lerobot_running_stats_ms": round((t2 - t1) / len(sample) * 1000, 3)}
    line = json.dumps(figures)
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")
