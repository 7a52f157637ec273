"""Camera video for ``record=true``: encoder settings, and the streaming encoder LeRobot's writer drives.

LeRobot's ``DatasetWriter`` streams each camera's frames into an encoder through five calls
(``start_episode``, ``feed_frame``, ``finish_episode``, ``cancel_episode``, ``close``) and
gets that encoder from ``LeRobotDataset._build_streaming_encoder``. :class:`RecordingDataset`
overrides that factory with :class:`CameraStreamEncoder`; the writer, the parquet and
metadata files, the per-episode mp4 concatenation and the stats aggregation stay LeRobot's.

The encoder differs from LeRobot's own ``StreamingVideoEncoder`` in two ways:

* image statistics are exact per-channel histograms of the uint8 frames (:class:`PixelStats`,
  ``np.bincount``), where LeRobot updates a 5000-bin float histogram with ``np.histogram``
  on every frame: 5.2 ms against 0.5 ms per 224x224 camera frame
  (``tests/perf/test_video_codecs.py``);
* a full frame queue makes the rollout wait instead of dropping the frame, so a recording
  never has holes.

:class:`VideoSettings` is the ``video`` block of the run config (codec, quality, GOP, preset,
threads) turned into LeRobot's ``RGBEncoderConfig``; codec options are LeRobot's.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import queue
import shutil
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import numpy as np
from lerobot.configs.video import RGBEncoderConfig
from lerobot.datasets.compute_stats import DEFAULT_QUANTILES
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from molmo_lerobot.hookspecs import ConfigError

#: h264 quality and speed when the config leaves them null: crf 18 matches the picture quality
#: of LeRobot's default AV1 (crf 30, preset 12) on our 224x224 renders (42.0 dB PSNR both) with
#: files 28 % larger and a third of the encoding CPU (1.8 against 5.4 ms per frame of two
#: cameras, ``tests/perf/test_video_codecs.py``). AV1 stays the default: LeRobot's
#: ``aggregate_datasets`` merges only datasets whose ``video.codec`` agree, and LeRobot records AV1.
#: Other codecs get LeRobot's own defaults.
H264_DEFAULTS: dict[str, Any] = {"crf": 18, "preset": "veryfast"}

#: ``vcodec=auto``: the first of these that encodes a test frame here (NVENC needs an NVIDIA GPU
#: with its driver), else the CPU default. LeRobot's own ``auto`` picks any hardware encoder
#: FFmpeg was built with, runnable or not.
AUTO_CODECS = ("h264_nvenc",)
CPU_DEFAULT_CODEC = "libsvtav1"


#: SVT-AV1 prints its configuration banner (a dozen lines) to stderr for every stream it opens,
#: reading ``SVT_LOG`` once, at its first encoder: errors only, unless the user set it.
os.environ.setdefault("SVT_LOG", "1")


_CAP_SYS_NICE = 23
_CAPABILITY_VERSION_3 = 0x20080522


class _CapHeader(ctypes.Structure):
    _fields_ = (("version", ctypes.c_uint32), ("pid", ctypes.c_int))


class _CapData(ctypes.Structure):
    _fields_ = (("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32), ("inheritable", ctypes.c_uint32))


def forgo_realtime() -> None:
    """Drop ``CAP_SYS_NICE`` from the calling thread, and so from the threads it starts (Linux keeps
    capabilities per thread). SVT-AV1 (LeRobot's default codec), run as root, switches the thread that
    starts an encoder and every thread it starts to real-time ``SCHED_FIFO`` at top priority: a
    recording worker then starves the run's supervisor and every other process on its cores. Without
    the capability its request fails and the encoder runs at ordinary priority. No-op elsewhere."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        header, data = _CapHeader(_CAPABILITY_VERSION_3, 0), (_CapData * 2)()
        if libc.capget(ctypes.byref(header), data) != 0 or not data[0].effective & (1 << _CAP_SYS_NICE):
            return
        data[0].effective &= ~(1 << _CAP_SYS_NICE)
        data[0].permitted &= ~(1 << _CAP_SYS_NICE)
        libc.capset(ctypes.byref(header), data)


class VideoConfigError(ConfigError):
    """The ``video`` block is invalid; the message names the key."""


@dataclass(frozen=True)
class VideoSettings:
    """How camera streams are encoded: the run config's ``video`` block."""

    vcodec: str = "libsvtav1"
    crf: int | float | None = None
    g: int | None = 2
    preset: int | str | None = None
    encoder_threads: int | None = 1

    @classmethod
    def from_config(cls, block: dict[str, Any] | None) -> VideoSettings:
        """Read and check ``video.*`` (unknown keys and codec options the encoder refuses are errors)."""
        block = dict(block or {})
        unknown = sorted(set(block) - set(cls.__dataclass_fields__))
        if unknown:
            raise VideoConfigError(f"video: unknown key(s) {unknown}; known: {sorted(cls.__dataclass_fields__)}")
        for key in ("g", "encoder_threads"):
            value = block.get(key)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise VideoConfigError(f"video.{key}: expected a positive integer or null, got {value!r}")
        if block.get("vcodec") == "auto":
            block["vcodec"] = pick_auto_codec(lambda vcodec: cls(**{**block, "vcodec": vcodec}).encodes())
        settings = cls(**block)
        settings.probe()
        return settings

    def encodes(self) -> bool:
        """Whether these settings encode a test frame on this machine."""
        try:
            self.probe()
        except VideoConfigError:
            return False
        return True

    def encoder_config(self) -> RGBEncoderConfig:
        """LeRobot's ``RGBEncoderConfig`` for these settings (raises :class:`VideoConfigError`)."""
        kwargs: dict[str, Any] = {"vcodec": self.vcodec, "g": self.g}
        if self.vcodec == "h264":
            kwargs |= H264_DEFAULTS
        kwargs |= {k: v for k in ("crf", "preset") if (v := getattr(self, k)) is not None}
        try:
            return RGBEncoderConfig(**kwargs)
        except (ValueError, TypeError) as exc:
            given = " ".join(f"{k}={v!r}" for k, v in kwargs.items())
            raise VideoConfigError(f"video: {given}: {exc}") from None


    def probe(self) -> None:
        """Encode one small frame in memory, so a codec that is compiled in but cannot run here
        (``h264_nvenc`` without an NVIDIA GPU, which ``auto`` may pick) fails before the run."""
        config = self.encoder_config()  # LeRobot checks codec name, pixel format and options
        frame = av.VideoFrame.from_ndarray(np.zeros((64, 64, 3), np.uint8), format="rgb24")
        try:
            _in_encoder_thread(lambda: self._encode_one(config, frame))
        except Exception as exc:
            raise VideoConfigError(f"video: vcodec={self.vcodec!r} (encoder {config.vcodec}) cannot encode on "
                                   f"this machine: {exc}") from None

    def _encode_one(self, config: RGBEncoderConfig, frame: Any) -> None:
        with av.open(io.BytesIO(), "w", format="mp4") as container:
            stream = add_video_stream(container, config, self.encoder_threads, 15, 64, 64)
            container.mux(stream.encode(frame))
            container.mux(stream.encode())


def _in_encoder_thread(work: Any) -> None:
    """Run ``work()`` in a thread of its own that cannot become real-time (:func:`forgo_realtime`);
    re-raise what it raised."""
    failure: list[BaseException] = []

    def run() -> None:
        forgo_realtime()
        try:
            work()
        except BaseException as exc:
            failure.append(exc)

    thread = threading.Thread(target=run, name="encode-probe", daemon=True)
    thread.start()
    thread.join()
    if failure:
        raise failure[0]


def pick_auto_codec(encodes: Callable[[str], bool]) -> str:
    """``vcodec=auto``: the first of :data:`AUTO_CODECS` that ``encodes``, else :data:`CPU_DEFAULT_CODEC`."""
    return next((codec for codec in AUTO_CODECS if encodes(codec)), CPU_DEFAULT_CODEC)


def add_video_stream(container: Any, config: RGBEncoderConfig, threads: int | None, fps: int,
                     height: int, width: int) -> Any:
    """A video stream on an open PyAV output ``container``, with LeRobot's codec options for ``config``."""
    stream = container.add_stream(config.vcodec, fps, options=config.get_codec_options(threads, as_strings=True))
    stream.pix_fmt, stream.width, stream.height = config.pix_fmt, width, height
    stream.time_base = Fraction(1, fps)
    return stream


class PixelStats:
    """Exact per-channel statistics of uint8 images, from a 256-bin histogram per channel.

    :meth:`statistics` returns what LeRobot's streaming encoder hands its writer: ``min``,
    ``max``, ``mean``, ``std`` (population), ``count`` (pixels) and the quantiles, each of
    shape ``(channels,)`` in 0–255 units. Quantiles equal ``np.quantile`` (linear) over all pixels.
    """

    def __init__(self, channels: int = 3, quantiles: tuple[float, ...] | None = None) -> None:
        self.channels = channels
        self.quantiles = tuple(DEFAULT_QUANTILES if quantiles is None else quantiles)
        self.hist = np.zeros((channels, 256), dtype=np.int64)
        self._offsets = np.arange(channels, dtype=np.uint16) * 256

    def update(self, image: np.ndarray) -> None:
        """Count one ``(H, W, channels)`` uint8 image."""
        flat = image.reshape(-1, self.channels).astype(np.uint16)
        flat += self._offsets  # channel c counts into bins [256 c, 256 c + 256)
        self.hist += np.bincount(flat.ravel(), minlength=256 * self.channels).reshape(self.channels, 256)

    @property
    def count(self) -> int:
        return int(self.hist[0].sum())

    def statistics(self) -> dict[str, np.ndarray]:
        n = self.count
        if n < 2:
            raise ValueError("statistics need at least 2 pixels")
        values = np.arange(256, dtype=np.float64)
        cum = np.cumsum(self.hist, axis=1)
        mean = self.hist @ values / n
        var = np.maximum(self.hist @ values**2 / n - mean**2, 0.0)
        stats = {
            "min": np.array([np.flatnonzero(h)[0] for h in self.hist], dtype=np.float64),
            "max": np.array([np.flatnonzero(h)[-1] for h in self.hist], dtype=np.float64),
            "mean": mean, "std": np.sqrt(var), "count": np.array([n]),
        }
        for q in self.quantiles:
            pos = q * (n - 1)
            lo = int(np.floor(pos))
            hi = min(lo + 1, n - 1)
            v_lo = np.array([np.searchsorted(c, lo, side="right") for c in cum], dtype=np.float64)
            v_hi = np.array([np.searchsorted(c, hi, side="right") for c in cum], dtype=np.float64)
            stats[f"q{int(q * 100):02d}"] = v_lo + (pos - lo) * (v_hi - v_lo)
        return stats


class _CameraStream(threading.Thread):
    """Encodes one camera's frames from a queue into an mp4 and counts their pixels."""

    def __init__(self, path: Path, fps: int, encoder: RGBEncoderConfig, threads: int | None, maxsize: int) -> None:
        super().__init__(name=f"encode-{path.stem}", daemon=True)
        self.path, self.fps, self.encoder, self.threads = path, fps, encoder, threads
        self.frames: queue.Queue = queue.Queue(maxsize=maxsize)
        self.stats = PixelStats()
        self.encoded = 0
        self.error: BaseException | None = None
        self.cancelled = False

    def run(self) -> None:
        forgo_realtime()
        container: Any = None  # PyAV's output container and video stream, opened on the first frame
        stream: Any = None
        while (frame := self.frames.get()) is not None:
            if self.error is not None or self.cancelled:
                continue  # keep draining so a producer blocked on put() is released
            try:
                if container is None:
                    container = av.open(str(self.path), "w")
                    stream = add_video_stream(container, self.encoder, self.threads, self.fps, *frame.shape[:2])
                video_frame = av.VideoFrame.from_ndarray(frame, format="rgb24")
                video_frame.pts = self.encoded
                container.mux(stream.encode(video_frame))
                self.stats.update(frame)
                self.encoded += 1
            except BaseException as exc:  # reported by finish_episode(); the queue keeps draining
                self.error = exc
        try:
            if container is not None:
                if self.error is None and not self.cancelled:
                    container.mux(stream.encode())
                container.close()
        except BaseException as exc:
            self.error = self.error or exc


class CameraStreamEncoder:
    """LeRobot's streaming-encoder interface: one encoding thread per camera, per episode.

    ``feed_frame`` hands a copy of the frame to the camera's thread and waits when that
    camera's queue is full; ``finish_episode`` returns ``{video_key: (mp4_path, stats)}``
    as LeRobot's writer expects and raises if any frame failed to encode.
    """

    def __init__(self, fps: int, rgb_encoder: RGBEncoderConfig, queue_maxsize: int,
                 encoder_threads: int | None) -> None:
        self.fps = int(fps)
        self.encoder = rgb_encoder
        self.queue_maxsize = max(1, int(queue_maxsize))
        self.encoder_threads = encoder_threads
        self._streams: dict[str, _CameraStream] = {}
        self._fed: dict[str, int] = {}

    def start_episode(self, video_keys: list[str], temp_dir: Path, depth_video_keys: list[str] | None = None) -> None:
        if depth_video_keys:
            raise ValueError(f"depth video is not recorded (features {depth_video_keys})")
        self.cancel_episode()
        for key in video_keys:
            # LeRobot moves the file out and removes its directory once the episode is saved
            path = Path(tempfile.mkdtemp(dir=temp_dir)) / f"{key.replace('/', '_')}_streaming.mp4"
            stream = _CameraStream(path, self.fps, self.encoder, self.encoder_threads, self.queue_maxsize)
            stream.start()
            self._streams[key] = stream
            self._fed[key] = 0

    def feed_frame(self, video_key: str, image: np.ndarray) -> None:
        stream = self._streams.get(video_key)
        if stream is None:
            raise RuntimeError(f"{video_key}: no episode started for this camera")
        if stream.error is not None:
            raise RuntimeError(f"{video_key}: video encoding failed: {stream.error!r}") from stream.error
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"{video_key}: expected uint8 (H, W, 3) frames, got {image.dtype} {image.shape}")
        stream.frames.put(image.copy())  # blocks while the encoder catches up: no frame is dropped
        self._fed[video_key] += 1

    def finish_episode(self) -> dict[str, tuple[Path, dict[str, np.ndarray] | None]]:
        if not self._streams:
            raise RuntimeError("no active episode to finish")
        streams, fed = self._streams, self._fed
        self._streams, self._fed = {}, {}
        for stream in streams.values():
            stream.frames.put(None)
        for stream in streams.values():
            stream.join()
        results: dict[str, tuple[Path, dict[str, np.ndarray] | None]] = {}
        failed = [f"{key}: {s.error!r}" for key, s in streams.items() if s.error is not None]
        failed += [f"{key}: encoded {s.encoded} of {fed[key]} frames" for key, s in streams.items()
                   if s.error is None and s.encoded != fed[key]]
        if failed:
            for stream in streams.values():
                shutil.rmtree(stream.path.parent, ignore_errors=True)
            raise RuntimeError("video encoding failed: " + "; ".join(failed))
        for key, stream in streams.items():
            results[key] = (stream.path, stream.stats.statistics() if stream.encoded >= 2 else None)
        return results

    def cancel_episode(self) -> None:
        streams, self._streams, self._fed = self._streams, {}, {}
        for stream in streams.values():
            stream.cancelled = True
            stream.frames.put(None)
        for stream in streams.values():
            stream.join()
            shutil.rmtree(stream.path.parent, ignore_errors=True)

    def close(self) -> None:
        self.cancel_episode()


class RecordingDataset(LeRobotDataset):
    """``LeRobotDataset`` whose streaming encoder is :class:`CameraStreamEncoder`."""

    @staticmethod
    def _build_streaming_encoder(fps, rgb_encoder, depth_encoder, encoder_queue_maxsize, encoder_threads):
        return CameraStreamEncoder(fps, rgb_encoder or RGBEncoderConfig(), encoder_queue_maxsize, encoder_threads)
