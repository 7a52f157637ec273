"""Camera video for record=true: settings, exact pixel statistics, and the streaming encoder."""

from __future__ import annotations

import os
import subprocess
import sys

import av
import numpy as np
import pytest
from lerobot.datasets.compute_stats import RunningQuantileStats

from molmo_lerobot.export.video import (
    CameraStreamEncoder,
    PixelStats,
    VideoConfigError,
    VideoSettings,
    pick_auto_codec,
)

KEYS = ["observation.images.exo", "observation.images.wrist"]


def _frames(n: int, h: int = 48, w: int = 64, seed: int = 0) -> list[np.ndarray]:
    """Smooth gradients plus noise: compressible, yet every channel spreads over many values."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    out = []
    for t in range(n):
        base = np.stack([(xx * 3 + t) % 256, (yy * 4 + 2 * t) % 256, (xx + yy + 5 * t) % 256], axis=-1)
        out.append(np.clip(base + rng.integers(-8, 9, base.shape), 0, 255).astype(np.uint8))
    return out


def test_pixel_stats_are_exact_and_agree_with_lerobots_running_stats():
    frames = _frames(7)
    stats = PixelStats()
    lerobot = RunningQuantileStats()
    for f in frames:
        stats.update(f)
        lerobot.update(f.reshape(-1, 3))
    got = stats.statistics()
    pixels = np.concatenate([f.reshape(-1, 3) for f in frames]).astype(np.float64)
    assert got["count"].tolist() == [len(pixels)]
    np.testing.assert_array_equal(got["min"], pixels.min(0))
    np.testing.assert_array_equal(got["max"], pixels.max(0))
    np.testing.assert_allclose(got["mean"], pixels.mean(0), rtol=1e-12)
    np.testing.assert_allclose(got["std"], pixels.std(0), rtol=1e-9)
    for q in (0.01, 0.1, 0.5, 0.9, 0.99):
        np.testing.assert_allclose(got[f"q{int(q * 100):02d}"], np.quantile(pixels, q, axis=0), atol=1e-9)
    ref = lerobot.get_statistics()
    assert set(got) == set(ref)  # the same keys LeRobot's writer stores
    for key in ("min", "max", "mean", "std"):
        np.testing.assert_allclose(got[key], ref[key], rtol=1e-4, atol=1e-3)
    for key in ("q01", "q10", "q50", "q90", "q99"):  # LeRobot's are histogram estimates
        np.testing.assert_allclose(got[key], ref[key], atol=1.0)


def test_pixel_stats_need_two_pixels():
    with pytest.raises(ValueError, match="at least 2"):
        PixelStats().statistics()


@pytest.mark.parametrize("vcodec", ["h264", "libsvtav1"])
def test_encoder_writes_every_frame_and_returns_stats(tmp_path, vcodec):
    settings = VideoSettings.from_config({"vcodec": vcodec})
    enc = CameraStreamEncoder(15, settings.encoder_config(), queue_maxsize=2, encoder_threads=1)
    frames = {k: _frames(20, seed=i) for i, k in enumerate(KEYS)}
    enc.start_episode(KEYS, tmp_path)
    for t in range(20):
        for k in KEYS:
            enc.feed_frame(k, frames[k][t])  # a queue of 2: the producer waits, nothing is dropped
    results = enc.finish_episode()
    assert set(results) == set(KEYS)
    for k, (path, stats) in results.items():
        with av.open(str(path)) as c:
            stream = c.streams.video[0]
            decoded = [f.to_ndarray(format="rgb24") for f in c.decode(stream)]
            assert stream.codec.canonical_name == {"h264": "h264", "libsvtav1": "av1"}[vcodec]
        assert len(decoded) == 20 and decoded[0].shape == (48, 64, 3)
        err = np.abs(decoded[7].astype(int) - frames[k][7].astype(int)).mean()
        assert err < 12, f"{k}: mean abs error {err:.1f}"
        assert stats["count"].tolist() == [20 * 48 * 64]


def test_cancel_removes_the_partial_video(tmp_path):
    enc = CameraStreamEncoder(15, VideoSettings().encoder_config(), queue_maxsize=8, encoder_threads=1)
    enc.start_episode(KEYS, tmp_path)
    for f in _frames(5):
        enc.feed_frame(KEYS[0], f)
    enc.cancel_episode()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError, match="no active episode"):
        enc.finish_episode()
    enc.close()


def test_bad_frames_and_encoder_failures_are_reported(tmp_path):
    enc = CameraStreamEncoder(15, VideoSettings(vcodec="h264").encoder_config(), queue_maxsize=4, encoder_threads=1)
    enc.start_episode(KEYS[:1], tmp_path)
    with pytest.raises(ValueError, match="uint8"):
        enc.feed_frame(KEYS[0], np.zeros((48, 64, 3), np.float32))
    with pytest.raises(RuntimeError, match="no episode started"):
        enc.feed_frame(KEYS[1], _frames(1)[0])
    enc.feed_frame(KEYS[0], np.zeros((47, 63, 3), np.uint8))  # x264 needs even sizes for yuv420p: it refuses
    with pytest.raises(RuntimeError, match="video encoding failed"):
        enc.finish_episode()
    assert list(tmp_path.iterdir()) == []  # nothing half-written is left for the writer to pick up


@pytest.mark.skipif(__import__("torch").cuda.is_available(), reason="an NVIDIA GPU can run NVENC")
def test_a_codec_this_machine_cannot_run_fails_before_the_run():
    # PyAV ships NVENC, so LeRobot accepts it (and vcodec=auto may pick it); without a GPU it cannot open
    with pytest.raises(VideoConfigError, match="video: vcodec='h264_nvenc'"):  # refused by the probe or LeRobot
        VideoSettings.from_config({"vcodec": "h264_nvenc"})


def test_auto_picks_nvenc_where_it_encodes_else_the_cpu_default():
    assert pick_auto_codec(lambda codec: codec == "h264_nvenc") == "h264_nvenc"
    assert pick_auto_codec(lambda codec: False) == "libsvtav1"
    tried = []
    pick_auto_codec(lambda codec: tried.append(codec) or False)
    assert tried == ["h264_nvenc"]
    # on this machine: NVENC only where it encodes (a GPU with NVENC: not an H100 or A100), else AV1
    settings = VideoSettings.from_config({"vcodec": "auto", "g": 4})
    nvenc = VideoSettings(vcodec="h264_nvenc").encodes()
    assert settings.vcodec == ("h264_nvenc" if nvenc else "libsvtav1") and settings.g == 4
    if not __import__("torch").cuda.is_available():
        assert settings.vcodec == "libsvtav1"


def test_settings_defaults_follow_the_codec():
    h264 = VideoSettings.from_config({"vcodec": "h264"}).encoder_config()
    assert (h264.vcodec, h264.crf, h264.preset, h264.g) == ("h264", 18, "veryfast", 2)
    av1 = VideoSettings.from_config({"vcodec": "libsvtav1", "g": 8}).encoder_config()
    assert (av1.vcodec, av1.crf, av1.preset, av1.g) == ("libsvtav1", 30, 12, 8)
    assert VideoSettings.from_config({"vcodec": "h264", "crf": 25}).encoder_config().crf == 25



@pytest.mark.parametrize("block, match", [
    ({"vcodec": "divx"}, "video: vcodec='divx'"),
    ({"g": 0}, "video.g: expected a positive integer"),
    ({"encoder_threads": "two"}, "video.encoder_threads"),
    ({"codec": "h264"}, r"video: unknown key\(s\) \['codec'\]"),
    ({"vcodec": "libsvtav1", "preset": "veryfast"}, "video: vcodec='libsvtav1'"),
])
def test_bad_settings_name_the_key(block, match):
    with pytest.raises(VideoConfigError, match=match):
        VideoSettings.from_config(block)


_SCHEDULING_CHECK = """
import numpy as np, os, tempfile, time
from pathlib import Path
from molmo_lerobot.export.video import CameraStreamEncoder, VideoSettings
def policies():
    return {os.sched_getscheduler(int(t)) for t in os.listdir("/proc/self/task")}
settings = VideoSettings.from_config({})  # the probe encodes a frame
enc = CameraStreamEncoder(15, settings.encoder_config(), 30, 1)
enc.start_episode(["observation.images.exo"], Path(tempfile.mkdtemp()))
for _ in range(5):
    enc.feed_frame("observation.images.exo", np.zeros((48, 64, 3), np.uint8))
time.sleep(0.5)
seen = policies()  # with the encoder's threads running
enc.finish_episode()
print(sorted(seen | policies()), os.SCHED_OTHER)
"""


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0 or not os.path.isdir("/proc/self/task"),
                    reason="only root (on Linux) can be switched to real-time scheduling")
def test_recording_as_root_leaves_no_thread_real_time():
    """SVT-AV1 run as root makes the thread that starts an encoder, and its own threads, SCHED_FIFO at
    top priority; a recording worker then starved the supervisor and every process on its cores."""
    # the child starts at ordinary priority whatever this process was left at (an earlier test's
    # encoder, LeRobot's own, may have made it real-time: children inherit the policy)
    out = subprocess.run([sys.executable, "-c", _SCHEDULING_CHECK], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "SVT_LOG": "0"},
                         preexec_fn=lambda: os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0)))
    assert out.returncode == 0, out.stderr[-2000:]
    policies, other = out.stdout.strip().rsplit(" ", 1)
    assert policies == f"[{other}]", f"thread scheduling policies seen: {policies} (SCHED_OTHER is {other})"
