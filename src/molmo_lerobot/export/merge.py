"""Merge worker shards into ``output_dir/dataset`` with LeRobot's aggregation, plus the eval records.

Sources are the previous merged dataset (a resumed run) and every finished shard, oldest
first. Each benchmark episode is stored at most once (a retried episode can sit in two
shards) and only if its final result has no error. The merged dataset is built in a
work directory (``.dataset-merge-<session>/``), checked (episode count, lengths,
``next.success`` at each episode's last frame against the results) and only then swapped
into place, so a failed merge never leaves a dataset that looks complete. A merge killed
inside the swap (the previous dataset moved away, the new one not yet in place) is finished
by the next merge or resume (:func:`recover_dataset`); no work directory outlives a merge.

Layout added to the LeRobot dataset root:

Dataset episodes follow benchmark order (each worker shard holds consecutive episodes, so the
merge only copies and concatenates, never re-encodes), and every frame carries ``eval.episode_index``, but in an
env suite's recording, whose schema is the suite's published datasets' (:mod:`molmo_lerobot.dataset_layout`).

* ``meta/eval/episodes.jsonl``: one record per attempted episode: ``episode_index`` (the
  dataset episode, or null when not stored, with ``not_recorded``), ``benchmark_episode_index``,
  house, task, prompt, success, success_once, steps, seed, error, policy, benchmark + sha256, and
  ``frames`` (the stored frames: fewer than ``steps`` when an expert's recording ended at its
  success hold);
* ``meta/eval/info.json``: benchmark, policy, timing, exact fps, torn shards;
* ``results.json`` (the run summary) and ``README.md`` (card with the score table).

These files name no absolute path of this machine (:func:`molmo_lerobot.export.portable.portable`).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot import fileio
from molmo_lerobot.errors import ExportError
from molmo_lerobot.export.card import make_card
from molmo_lerobot.export.frames import EVAL_EPISODE_INDEX
from molmo_lerobot.export.portable import portable
from molmo_lerobot.export.shards import SHARDS_DIR, Shard, list_shards, new_session
from molmo_lerobot.results import RESULTS_FILE, EpisodeResult, RunSummary

if TYPE_CHECKING:
    from molmo_lerobot.dataset_layout import DatasetLayout

log = logging.getLogger(__name__)

DATASET_DIR = "dataset"
EVAL_EPISODES = "meta/eval/episodes.jsonl"
EVAL_INFO = "meta/eval/info.json"
MERGE_PREFIX = ".dataset-merge-"  # + session: a merge's work directory
PREVIOUS = "previous"  # in the work directory: the dataset being replaced, during the swap


def dataset_fps(policy_dt_ms: float) -> int:
    """LeRobot stores integer fps; the exact policy rate goes into ``meta/eval/info.json``."""
    return max(1, round(1000.0 / float(policy_dt_ms)))


@dataclass
class MergedDataset:
    """What the merge writes of a run's dataset: its repo id, the run's policy and benchmark, the policy
    rate, the recording session (it names the merge's work directory) and whether it goes to the Hub
    (the card says so). :class:`~molmo_lerobot.export.recorder.LeRobotRecorderFactory` is one."""

    repo_id: str
    policy_dt_ms: float
    benchmark: str
    policy: str
    push: bool = False
    session: str = field(default_factory=new_session)
    #: an env suite's fixed schema (its LeRobot datasets', which the card describes); None: each shard's schema
    #: follows its first step
    layout: DatasetLayout | None = None

    @property
    def fps(self) -> int:
        """The dataset's declared fps: the policy rate, or the suite layout's own (LIBERO's datasets say 10)."""
        return self.layout.fps if self.layout is not None else dataset_fps(self.policy_dt_ms)


@dataclass
class _Source:
    root: Path
    episodes: list[dict[str, Any]]  # per local episode: {"episode_index": benchmark index, "success": …}


def read_eval_records(dataset_root: Path) -> list[dict[str, Any]]:
    """The ``meta/eval/episodes.jsonl`` records of a merged dataset."""
    path = Path(dataset_root) / EVAL_EPISODES
    out = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        try:
            out.append(json.loads(line))
        except ValueError as exc:
            raise ExportError(f"{path}:{n}: not a JSON record ({exc})") from None
    return out


def _previous_source(dataset: Path) -> _Source | None:
    fileio.refuse_link(dataset)  # a planted link would bring (and then drop) a dataset from elsewhere
    if not (dataset / "meta/info.json").exists() or not (dataset / EVAL_EPISODES).exists():
        return None
    stored = sorted((r for r in read_eval_records(dataset) if r.get("episode_index") is not None),
                    key=lambda r: r["episode_index"])
    eps = [{"episode_index": r["benchmark_episode_index"], "success": r["success"],
            "frames": r.get("frames", r["steps"])} for r in stored]
    return _Source(dataset, eps)


def _choose(sources: list[_Source], by_index: dict[int, EpisodeResult]) -> dict[int, tuple[int, int]]:
    """benchmark index → (source, local episode): the last copy whose success matches the result."""
    best: dict[int, tuple[bool, int, int]] = {}
    for si, src in enumerate(sources):
        for li, ep in enumerate(src.episodes):
            r = by_index.get(int(ep["episode_index"]))
            if r is None or r.error is not None:
                continue
            key = (bool(ep.get("success")) == r.success, si, li)
            if r.episode_index not in best or key > best[r.episode_index]:
                best[r.episode_index] = key
    return {i: (k[1], k[2]) for i, k in best.items()}


def _segments(order: list[int], chosen: dict[int, tuple[int, int]]) -> list[tuple[int, list[int]]]:
    """Split the benchmark ``order`` into runs stored consecutively in one source: [(source, local episodes)].

    Shards hold consecutive episodes, so every run is a whole shard (copied, never re-encoded);
    only a source with episodes not chosen (a resumed run's previous dataset, a shard whose
    episode was chosen from a retry) needs cutting into a subset.
    """
    segments: list[tuple[int, list[int]]] = []
    for b in order:
        si, li = chosen[b]
        if segments and segments[-1][0] == si and segments[-1][1][-1] < li:
            segments[-1][1].append(li)
        else:
            segments.append((si, [li]))
    return segments


def recover_dataset(output_dir: Path) -> None:
    """Finish what a killed merge left: a swap stopped between its two renames (``dataset`` moved
    to ``<work>/previous``, the checked new one still at ``<work>/dataset``) is completed, and every
    ``.dataset-merge-*`` work directory is removed."""
    final = Path(output_dir) / DATASET_DIR
    for work in sorted(Path(output_dir).glob(f"{MERGE_PREFIX}*")):
        previous, new = work / PREVIOUS, work / DATASET_DIR
        if previous.is_dir() and not final.exists():
            kept = new if new.is_dir() else previous  # the new one was checked before the swap began
            log.warning("completing a dataset merge that was killed mid-swap: %s -> %s", kept, final)
            fileio.replace(kept, final, root=output_dir)
        fileio.rmtree(work, root=output_dir, ignore_errors=True)


def _sources(output_dir: Path) -> tuple[list[_Source], list[Shard]]:
    """The copies a merge chooses from (the previous dataset, then every finished shard) and all shards."""
    recover_dataset(output_dir)
    shards = list_shards(output_dir)
    sources = [s for s in [_previous_source(output_dir / DATASET_DIR)] if s is not None]
    sources += [_Source(s.root, s.episodes) for s in shards if s.complete and s.episodes]
    return sources, shards


def stored_episodes(output_dir: Path, results: list[EpisodeResult]) -> set[int]:
    """The episodes of ``results`` that a merge of ``output_dir`` now would store."""
    sources, _ = _sources(Path(output_dir))
    return set(_choose(sources, {r.episode_index: r for r in results}))


def merge_shards(output_dir: Path, results: list[EpisodeResult], summary: RunSummary,
                 dataset: MergedDataset) -> Path | None:
    """Build ``output_dir/dataset`` from the shards; returns its root, or None when nothing was recorded."""
    output_dir = Path(output_dir)
    sources, shards = _sources(output_dir)
    torn = [s.root.name for s in shards if not s.complete]
    for name in torn:
        log.warning("skipping dataset shard %s: its worker did not finish it (killed or crashed); "
                    "its episodes are not stored in the dataset", name)
    work = output_dir / f"{MERGE_PREFIX}{dataset.session}"
    try:
        tmp = _build(work, sources, shards, torn, results, summary, dataset)
    except BaseException:
        fileio.rmtree(work, root=output_dir, ignore_errors=True)
        raise
    if tmp is None:
        fileio.rmtree(work, root=output_dir, ignore_errors=True)
        return None
    final = output_dir / DATASET_DIR
    _swap_into_place(tmp, final, work)
    fileio.rmtree(output_dir / SHARDS_DIR, root=output_dir, ignore_errors=True)
    fileio.rmtree(work, root=output_dir, ignore_errors=True)
    return final


def _build(work: Path, sources: list[_Source], shards: list[Shard], torn: list[str], results: list[EpisodeResult],
           summary: RunSummary, dataset: MergedDataset) -> Path | None:
    """The merged, checked dataset at ``work/dataset``; None when no episode is to be stored."""
    from lerobot.datasets.aggregate import aggregate_datasets
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    output_dir = work.parent
    discarded = {int(d["episode_index"]): d["reason"] for s in shards for d in s.discarded}
    by_index = {r.episode_index: r for r in results}
    chosen = _choose(sources, by_index)

    order = sorted(chosen)  # dataset episodes follow benchmark order, whatever the number of workers
    dataset_index = {b: i for i, b in enumerate(order)}
    fileio.make_dirs(work, root=output_dir)  # LeRobot writes the subsets and the merged dataset in here
    roots: list[Path] = []
    for k, (si, keep) in enumerate(_segments(order, chosen)):
        src = sources[si]
        roots.append(src.root if len(keep) == len(src.episodes)
                     else _subset(src, keep, work / f"subset-{k}", dataset.repo_id))

    if not roots:
        log.warning("record=true but no episode finished without error: no dataset written")
        return None

    tmp = work / DATASET_DIR
    try:
        aggregate_datasets([dataset.repo_id] * len(roots), dataset.repo_id, roots=roots, aggr_root=tmp)
    except Exception as exc:
        raise ExportError(f"merging {len(roots)} dataset shards under {output_dir / SHARDS_DIR} failed: "
                          f"{type(exc).__name__}: {exc}") from exc
    restat(tmp)
    frames = {b: sources[si].episodes[li].get("frames", by_index[b].steps) for b, (si, li) in chosen.items()}
    records = portable(_eval_records(results, dataset_index, frames, discarded, summary, dataset), output_dir)
    fileio.atomic_write(tmp / EVAL_EPISODES, "".join(json.dumps(r) + "\n" for r in records), root=tmp)
    info = {
        "benchmark": summary.document().get("benchmark"), "policy": dataset.policy, "repo_id": dataset.repo_id,
        "policy_dt_ms": dataset.policy_dt_ms, "fps_exact": 1000.0 / dataset.policy_dt_ms, "fps": dataset.fps,
        "n_attempted": len(results), "n_recorded": len(dataset_index), "torn_shards": torn,
        "session": dataset.session,
    }
    shared = RunSummary.from_document(portable(summary.document(), output_dir))  # no path of this machine
    fileio.atomic_write(tmp / EVAL_INFO, json.dumps(portable(info, output_dir), indent=2) + "\n", root=tmp)
    fileio.atomic_write(tmp / RESULTS_FILE, shared.to_json(), root=tmp)
    meta = LeRobotDatasetMetadata(dataset.repo_id, root=tmp)
    check_dataset(tmp, results)
    card = make_card(meta.info, shared, dataset.repo_id, records, on_hub=dataset.push, layout=dataset.layout)
    fileio.atomic_write(tmp / "README.md", str(card), root=tmp)
    return tmp


def restat(root: Path) -> None:
    """Rewrite ``meta/stats.json`` of the merged dataset at ``root`` from its merged data.

    LeRobot's ``aggregate_datasets`` aggregates each source's ``stats.json`` as it was before the
    merge re-indexed ``index``, ``episode_index`` and ``task_index`` (every shard's start at 0), and
    ``delete_episodes`` (a resumed run's subset) copies each episode's stats unchanged. The numeric
    features are computed here as LeRobot computes a dataset's stats (``compute_episode_stats`` per
    episode, then ``aggregate_stats``, as its ``recompute_stats``, but the bookkeeping columns
    included); image and video statistics, which no re-indexing changes, are kept.
    """
    import numpy as np
    import pyarrow.dataset as pads
    from lerobot.datasets.compute_stats import aggregate_stats, compute_episode_stats
    from lerobot.datasets.io_utils import load_stats
    from lerobot.datasets.utils import serialize_dict

    features = json.loads((root / "meta/info.json").read_text())["features"]
    numeric = {k: v for k, v in features.items() if v["dtype"] not in ("image", "video", "string")}
    frames = pads.dataset(str(root / "data"), format="parquet").to_table(columns=list(numeric)).to_pandas()
    per_episode = []
    for _, episode in frames.groupby("episode_index", sort=True):
        columns = {k: episode[k].to_numpy() for k in numeric}
        per_episode.append(compute_episode_stats(
            {k: np.stack(v) if v.dtype == object else v for k, v in columns.items()}, numeric))
    stats = {**(load_stats(root) or {}), **aggregate_stats(per_episode)}
    fileio.atomic_write(root / "meta/stats.json", json.dumps(serialize_dict(stats), indent=4) + "\n", root=root)


def _subset(src: _Source, keep: list[int], out: Path, repo_id: str) -> Path:
    """A copy of ``src`` with only the ``keep`` episodes (LeRobot's delete_episodes)."""
    from lerobot.datasets.dataset_tools import delete_episodes
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset(repo_id, root=src.root, video_backend="pyav")
    drop = [i for i in range(len(src.episodes)) if i not in set(keep)]
    delete_episodes(ds, drop, output_dir=out, repo_id=repo_id)
    return out


def _eval_records(results: list[EpisodeResult], dataset_index: dict[int, int], frames: dict[int, int],
                  discarded: dict[int, str], summary: RunSummary,
                  dataset: MergedDataset) -> list[dict[str, Any]]:
    bench = summary.benchmark.model_dump() if summary.benchmark else {}
    records = []
    for r in sorted(results, key=lambda r: r.episode_index):
        idx = dataset_index.get(r.episode_index)
        if idx is not None:
            why = None
        elif r.error is not None:
            why = "episode error"
        elif r.output_errors:
            why = f"output failed: {r.output_errors[0]}"
        else:
            why = discarded.get(r.episode_index, "not in any finished shard (its worker was killed or crashed)")
        records.append({
            "episode_index": idx, "benchmark_episode_index": r.episode_index, "house_index": r.house_index,
            "task_cls": r.task_cls, "task_type": r.task_type, "prompt": r.prompt, "success": r.success,
            "success_once": r.success_once, "steps": r.steps, "seed": r.seed, "error": r.error,
            "policy": dataset.policy, "benchmark": bench.get("name", dataset.benchmark),
            "benchmark_sha256": bench.get("sha256"), "not_recorded": why, "frames": frames.get(r.episode_index),
        })
    return records


def check_dataset(root: Path, results: list[EpisodeResult]) -> None:
    """Raise :class:`ExportError` unless the stored episodes agree with the eval records and results: their
    lengths, and where the schema has them (not a suite's fixed layout) ``eval.episode_index`` and the final
    ``next.done``/``next.success``."""
    import pyarrow.dataset as pads

    by_index = {r.episode_index: r for r in results}
    stored = {r["episode_index"]: r for r in read_eval_records(root) if r["episode_index"] is not None}
    data = pads.dataset(str(root / "data"), format="parquet")
    flags = EVAL_EPISODE_INDEX in data.schema.names
    frames = data.to_table(columns=["episode_index", "frame_index",
                                    *(["next.success", "next.done", EVAL_EPISODE_INDEX] if flags else [])]
                           ).to_pandas()
    if set(frames["episode_index"].unique()) != set(stored):
        raise ExportError(f"{root}: data holds episodes {sorted(frames['episode_index'].unique())[:10]}…, "
                          f"meta/eval/episodes.jsonl maps {sorted(stored)[:10]}…")
    for ep, g in frames.groupby("episode_index"):
        rec = stored[int(ep)]
        res = by_index[rec["benchmark_episode_index"]]
        length = rec.get("frames", res.steps)
        if not flags:
            if len(g) != length or length != res.steps:
                raise ExportError(f"{root}: dataset episode {ep} (benchmark episode {res.episode_index}) has "
                                  f"{len(g)} frames; the records say {length} frames of {res.steps} steps")
            continue
        last = g.loc[g["frame_index"].idxmax()]
        if set(g[EVAL_EPISODE_INDEX]) != {res.episode_index}:
            raise ExportError(f"{root}: dataset episode {ep} holds {EVAL_EPISODE_INDEX} "
                              f"{sorted(set(g[EVAL_EPISODE_INDEX]))[:5]}, expected {res.episode_index}")
        held = length < res.steps  # an expert's recording ends at its success hold, its rollout goes on
        if (len(g) != length or length > res.steps or not bool(last["next.done"])
                or (bool(last["next.success"]) != res.success if not held else not g["next.success"].any())):
            raise ExportError(
                f"{root}: dataset episode {ep} (benchmark episode {res.episode_index}) has {len(g)} frames, "
                f"final next.success={bool(last['next.success'])}; the records say {length} frames of "
                f"{res.steps} steps, success={res.success}")


def _swap_into_place(tmp: Path, final: Path, work: Path) -> None:
    """Two renames; one killed between them is completed by :func:`recover_dataset`."""
    old = work / PREVIOUS
    if final.exists():
        fileio.replace(final, old, root=work.parent)
    fileio.replace(tmp, final, root=work.parent)
    fileio.rmtree(old, root=work.parent, ignore_errors=True)
