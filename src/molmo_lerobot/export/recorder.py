"""``record=true``: every worker writes its rollouts with LeRobot's own writer; the main process merges.

:class:`LeRobotRecorderFactory` is built from the run config in the main process and
pickled to the workers. Each worker's :class:`LeRobotRecorder` streams frames into a
LeRobot v3 dataset shard (``streaming_encoding=True``: video is encoded while the episode
runs, by :mod:`molmo_lerobot.export.video` with the run's ``video`` settings), saves an
episode only if it finished without error, and finalizes its shard when the worker closes.
An expert's episode (:attr:`EpisodeInfo.expert`) is recorded up to ``record_hold_steps`` after
its first success, but at least ``record_min_frames`` frames (100: the action chunk of LeRobot's
ACT and SmolVLA, so no demonstration is shorter than the chunk a policy trained on it predicts); the
rollout itself, and so the score, runs on to the horizon either way.
An env-suite run (``benchmark=libero_object``, ``pusht``) records in the suite's fixed schema instead, that of the
suite's LeRobot datasets (:mod:`molmo_lerobot.dataset_layout`), so that its dataset merges with theirs.
``finalize`` then merges the shards into ``output_dir/dataset`` with
``lerobot.datasets.aggregate.aggregate_datasets``, writes the eval records, the dataset card
and ``results.json`` into it, and pushes to the Hub when ``push=true``.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot import fileio
from molmo_lerobot.export.frames import FrameLayout
from molmo_lerobot.export.merge import MergedDataset, merge_shards, stored_episodes
from molmo_lerobot.export.shards import SHARDS_DIR, shard_name, write_marker
from molmo_lerobot.export.video import RecordingDataset, VideoSettings
from molmo_lerobot.hookspecs import ConfigError
from molmo_lerobot.recording import EpisodeInfo, Recorder, RecorderFactory
from molmo_lerobot.results import EpisodeResult, Push, RunSummary
from molmo_lerobot.run_config import RunConfig

if TYPE_CHECKING:
    from molmo_lerobot.dataset_layout import DatasetLayout

log = logging.getLogger(__name__)


class RecordConfigError(ConfigError):
    """``record`` / ``push`` / ``hub`` settings are invalid; the message names the key."""


def validate_repo_id(repo_id: str) -> str:
    """A Hub dataset id ``<namespace>/<name>``: a valid namespace id, and valid by the Hub's own rules."""
    from huggingface_hub.utils import HFValidationError
    from huggingface_hub.utils import validate_repo_id as hf_validate

    from molmo_lerobot.namespaces import parse_dataset_id

    try:
        namespace, _ = parse_dataset_id(repo_id)
        hf_validate(repo_id)
    except (ValueError, HFValidationError) as exc:
        raise RecordConfigError(f"hub.repo_id {repo_id!r} is not a valid dataset id: {exc}") from None
    if namespace is None:
        raise RecordConfigError(f"hub.repo_id {repo_id!r} must be <namespace>/<name>")
    return repo_id


@dataclass
class LeRobotRecorderFactory(MergedDataset, RecorderFactory):
    """Picklable recipe: per-worker shard writers plus the merge/publish step (the dataset it merges:
    :class:`~molmo_lerobot.export.merge.MergedDataset`)."""

    private: bool = False
    #: finalize a worker's shard after this many episodes (a killed worker or a failed save loses
    #: its open shard's episodes from the dataset, never from the results), or before an episode
    #: that does not follow the previous one in benchmark order: the supervisor gives each worker
    #: consecutive stretches, so shards concatenate in benchmark order without re-encoding, and
    #: the merge (about a second per shard) sees a few shards, not one per episode
    shard_episodes: int = 8
    video: VideoSettings = field(default_factory=VideoSettings)
    #: an expert's recording ends this many steps after its first success (None: the whole rollout)
    hold_steps: int | None = RunConfig.model_fields["record_hold_steps"].default
    #: ``dataset_id=ns/sub/name``: the merged dataset is also copied into the dataset store (``store_root``),
    #: and ``push=true`` uploads it there with its namespaces (``remote``: ``hf://<owner>``)
    dataset_id: str | None = None
    store_root: str | None = None
    remote: str | None = None
    #: ... but an expert's recording keeps at least this many frames (the horizon permitting)
    min_frames: int = RunConfig.model_fields["record_min_frames"].default

    @classmethod
    def from_config(cls, run: RunConfig, layout: DatasetLayout | None = None) -> LeRobotRecorderFactory:
        """Build from the run config (``record``, ``push``, ``hub``, ``video``, ``timing`` …); ``layout``: the fixed
        schema the run's benchmark kind records in (an env suite's datasets'), None: each recording's first step
        decides it."""
        bench, policy = run.benchmark.name, run.policy.name
        repo_id = run.hub.repo_id
        dataset_id, store_root, remote = _store_target(run)
        if run.push and not repo_id and dataset_id is None:
            raise RecordConfigError("push=true needs hub.repo_id=<namespace>/<name>")
        if repo_id:
            validate_repo_id(repo_id)
        else:
            repo_id = f"local/{_slug(bench)}-{_slug(policy)}"
        policy_dt_ms = 1000.0 / layout.step_hz if layout is not None else float(run.timing.policy_dt_ms)
        return cls(repo_id=repo_id, policy_dt_ms=policy_dt_ms, benchmark=bench,
                   policy=policy, push=run.push, private=run.hub.private,
                   video=VideoSettings.from_config(run.video.model_dump()), hold_steps=run.record_hold_steps,
                   dataset_id=dataset_id, store_root=store_root, remote=remote, min_frames=run.record_min_frames,
                   layout=layout)

    def make(self, worker_id: str, output_dir: Path) -> LeRobotRecorder:
        return LeRobotRecorder(self, worker_id, Path(output_dir))

    def finalize(self, output_dir: Path, results: list[EpisodeResult], summary: RunSummary) -> Push | None:
        """Merge the shards into ``output_dir/dataset``; push it when ``push=true``.

        Returns the push outcome (``results.json``'s ``push``): a failed push keeps every local
        file and makes ``molmo-eval`` exit non-zero."""
        from molmo_lerobot.export.hub import push_dataset

        quiet_libraries()
        root = merge_shards(Path(output_dir), results, summary, self)
        if self.dataset_id is not None:
            return self._store(Path(output_dir), root, summary)
        if not self.push:
            return None
        error = (push_dataset(root, self.repo_id, private=self.private) if root is not None
                 else "no episode finished without error, so there is no dataset to push")
        return Push(repo_id=self.repo_id, ok=error is None, error=error)

    def _store(self, output_dir: Path, root: Path | None, summary: RunSummary) -> Push | None:
        """Copy the dataset into the store as ``dataset_id`` (the run directory keeps its own: ``resume`` and
        the report read it there), then, with ``push=true``, upload it with its namespace chain."""
        from molmo_lerobot.namespaces import DatasetStore, upload_dataset

        store, dataset_id = DatasetStore(self.store_root), self.dataset_id
        assert dataset_id is not None  # finalize() stores only with one
        if root is None:
            raise RuntimeError(f"dataset_id {self.dataset_id!r}: no episode finished without error, so there is "
                               "no dataset to store")
        bench = summary.benchmark
        store.add_dataset(dataset_id, root, {
            "benchmark": {"name": bench and bench.name, "sha256": bench and bench.sha256}, "policy": self.policy,
            "success_rate": summary.success_rate, "n_success": summary.n_success,
            "n_episodes": summary.n_episodes, "run_id": output_dir.resolve().name,
            "started_at": summary.started_at, "lerobot_repo_id": self.repo_id}, run_dir=output_dir)
        if not self.push:
            return None
        target = f"{self.remote}/{self.dataset_id}"
        try:
            upload_dataset(dataset_id, store=store, remote=self.remote, private=self.private)
            error = None
        except Exception as exc:  # a push must never cost the local results
            from molmo_lerobot.export.hub import failure_line

            error = failure_line(exc)
            log.warning("push of %s to %s failed; local files are intact: %s", self.dataset_id, target, error)
        return Push(repo_id=target, ok=error is None, error=error)

    def missing(self, output_dir: Path, results: list[EpisodeResult]) -> set[int]:
        """Resume: the episodes that finished without error but are neither in ``output_dir/dataset``
        nor in a finished shard (their worker was killed before it finished its shard, or saving
        failed); the resume runs them again so that the dataset holds every such episode."""
        stored = stored_episodes(Path(output_dir), results)
        return {r.episode_index for r in results if r.error is None and r.episode_index not in stored}


def _store_target(run: RunConfig) -> tuple[str | None, str | None, str | None]:
    """``(dataset_id, store root, remote)`` of a ``dataset_id=`` run, checked before any output: a valid id
    that is free in the store (or this run's own recording, on ``resume``), and a remote to push to."""
    from molmo_lerobot.namespaces import DatasetStore, HubRemote, NamespaceError

    dataset_id = run.dataset_id
    if dataset_id is None:
        return None, None, None
    store = DatasetStore()
    remote = run.hub.remote or os.environ.get("MOLMO_DATASETS_REMOTE")
    if run.hub.repo_id:
        raise RecordConfigError(f"dataset_id {dataset_id!r} and hub.repo_id both say where the dataset goes; "
                                "set one (dataset_id pushes to hub.remote)")
    try:
        store.check_new_dataset(dataset_id, run.output_dir if run.resume else None)
        if run.push:
            if not remote:
                raise NamespaceError(f"dataset_id {dataset_id!r} with push=true needs hub.remote=hf://<user or org> "
                                     "(or $MOLMO_DATASETS_REMOTE)")
            HubRemote.from_remote(remote)
    except NamespaceError as exc:
        raise RecordConfigError(str(exc)) from None
    return dataset_id, str(store.root), remote


def quiet_libraries() -> None:
    """FFmpeg prints errors only (LeRobot's video helpers reinstate FFmpeg's stderr logger at
    INFO: codec banners for every episode), and ``datasets`` draws no per-episode progress
    bars under the run's own."""
    import av
    import datasets

    av.logging.set_libav_level(av.logging.ERROR)
    datasets.disable_progress_bars()


def _slug(text: str) -> str:
    return re.sub(r"[^-\w.]+", "-", text).strip("-.") or "x"


class LeRobotRecorder(Recorder):
    """One worker's writer: frames stream into the current shard; errors are never saved.

    An expert's recording stops ``hold_steps`` after its first successful step (and not before
    ``min_frames``): a demonstration that idles to the horizon teaches a policy to stand still. The
    last recorded frame is marked ``next.done``; the rollout goes on unrecorded (and unrendered) for
    the episode's score.
    """

    wants_images = True

    def __init__(self, factory: LeRobotRecorderFactory, worker_id: str, output_dir: Path) -> None:
        quiet_libraries()
        self.factory = factory
        self.worker_id = worker_id
        self.shards_dir = output_dir / SHARDS_DIR
        self._ds: Any = None
        self._root: Path | None = None
        self._layout: FrameLayout | DatasetLayout | None = None
        self._seq = 0
        self._saved: list[dict[str, Any]] = []
        self._discarded: list[dict[str, Any]] = []
        self._info: EpisodeInfo | None = None
        self._frames = 0  # recorded this episode
        self._steps = 0  # seen this episode
        self._last: int | None = None  # the last step to record, once the success hold has begun

    # Recorder interface -------------------------------------------------------------
    def start_episode(self, info: EpisodeInfo) -> None:
        previous = self._info
        if self._saved and previous is not None and info.episode_index != previous.episode_index + 1:
            self._close_shard()  # out of benchmark order: the next shard starts here
        self._info, self._frames, self._steps, self._last = info, 0, 0, None

    def wants_images_at(self, step: int, horizon: int) -> bool:
        return self._last is None or step <= self._last

    def record_step(self, obs: dict[str, Any], action: dict[str, Any], reward: float | None,
                    success: bool, done: bool) -> None:
        info = self._info
        if info is None:
            raise RuntimeError("record_step called before start_episode")
        step, self._steps = self._steps, self._steps + 1
        if self._last is not None and step > self._last:
            return  # past the success hold: the rollout goes on for its score only
        if success and self._last is None and info.expert and self.factory.hold_steps is not None:
            self._last = max(step + self.factory.hold_steps, self.factory.min_frames - 1)
        done = done or step == self._last
        if self._frames == 0:
            layout = self.factory.layout or FrameLayout.from_step(info, obs, reward)
            if self._ds is not None and layout != self._layout:
                self._close_shard()  # cameras/joints changed: a dataset holds one schema
            if self._ds is None:
                self._open_shard(layout, info.horizon)
        assert self._layout is not None
        self._ds.add_frame(self._layout.frame(obs, action, reward, success, done, info.prompt or info.task_type, info))
        self._frames += 1

    def end_episode(self, result: EpisodeResult) -> None:
        frames, self._frames = self._frames, 0
        if self._ds is None:
            return
        expected = result.steps if self._last is None else min(result.steps, self._last + 1)
        reason = None
        if result.error is not None:
            reason = "episode error"
        elif frames != expected:
            reason = f"recorded {frames} frames for {expected} steps"
        if reason is not None:
            self._ds.clear_episode_buffer()
            if frames:
                self._discarded.append({"episode_index": result.episode_index, "reason": reason})
                if result.error is None:
                    log.warning("episode %d not recorded: %s", result.episode_index, reason)
            return
        try:
            self._ds.save_episode()
        except Exception:
            self._abandon_shard()  # half-saved: leave it torn (no marker) so it is never merged
            raise
        self._saved.append({"episode_index": result.episode_index, "seed": result.seed,
                            "success": result.success, "steps": result.steps, "frames": frames})
        if len(self._saved) >= self.factory.shard_episodes:
            self._close_shard()

    def close(self) -> None:
        self._close_shard()

    # Shards ----------------------------------------------------------------------------
    def _open_shard(self, layout: FrameLayout | DatasetLayout, horizon: int) -> None:
        fileio.make_dirs(self.shards_dir, root=self.shards_dir.parent)  # LeRobot makes the new shard in it
        root = self.shards_dir / shard_name(self.factory.session, self.worker_id, self._seq)
        while root.exists():  # never reuse a directory, whatever left it there
            self._seq += 1
            root = self.shards_dir / shard_name(self.factory.session, self.worker_id, self._seq)
        self._seq += 1
        video = self.factory.video
        self._ds = RecordingDataset.create(
            repo_id=self.factory.repo_id, fps=self.factory.fps, features=layout.features(), root=root,
            robot_type=layout.robot_type, use_videos=True, streaming_encoding=True, video_backend="pyav",
            rgb_encoder=video.encoder_config(), encoder_threads=video.encoder_threads,
            # room for a whole episode per camera: the encoder may lag behind the rollout
            encoder_queue_maxsize=max(64, int(horizon) + 1),
        )
        self._root, self._layout = root, layout
        self._saved, self._discarded = [], []

    def _close_shard(self) -> None:
        if self._ds is None:
            return
        ds, root = self._ds, self._root
        self._ds = self._root = self._layout = None
        if ds.has_pending_frames():
            ds.clear_episode_buffer()
        ds.finalize()
        assert root is not None
        write_marker(root, {"worker_id": self.worker_id, "session": self.factory.session,
                            "episodes": self._saved, "discarded": self._discarded})
        self._saved, self._discarded = [], []

    def _abandon_shard(self) -> None:
        log.warning("dataset shard %s abandoned after a failed save; its episodes will not be stored", self._root)
        self._ds = self._root = self._layout = None
        self._saved, self._discarded = [], []
