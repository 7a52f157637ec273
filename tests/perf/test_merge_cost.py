"""Dataset merge cost (``record=true``): shards of consecutive episodes (the default) against one
shard per episode (the earlier layout), same episodes, from one run. Reports the merge's wall time
and shard count; asserts only that both datasets hold the same episodes in benchmark order.

``pytest -m perf -s tests/perf/test_merge_cost.py``; knobs ``MOLMO_PERF_EPISODES`` (16),
``MOLMO_PERF_WORKERS`` (2), ``MOLMO_PERF_HORIZON`` (10 steps).
"""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip("lerobot")

from molmo_lerobot.config import compose
from molmo_lerobot.export import merge, recorder
from molmo_lerobot.export.merge import read_eval_records
from molmo_lerobot.runner.evaluate import run_evaluation

pytestmark = pytest.mark.perf
EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "16"))
WORKERS = int(os.environ.get("MOLMO_PERF_WORKERS", "2"))
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "10"))


def test_merge_cost_by_shard_layout(tmp_path, monkeypatch):
    timings: dict[str, tuple[float, int]] = {}
    stored = {}
    inner_merge, inner_from_config = merge.merge_shards, recorder.LeRobotRecorderFactory.from_config.__func__
    for layout, per_shard in (("one episode per shard", 1), ("consecutive episodes (default)", None)):
        def from_config(cls, cfg, per_shard=per_shard):
            factory = inner_from_config(cls, cfg)
            if per_shard is not None:
                factory.shard_episodes = per_shard
            return factory

        def timed(output_dir, *args, layout=layout, **kwargs):
            shards = len(list((output_dir / "dataset_shards").iterdir()))
            t = time.perf_counter()
            root = inner_merge(output_dir, *args, **kwargs)
            timings[layout] = (time.perf_counter() - t, shards)
            return root

        monkeypatch.setattr(recorder.LeRobotRecorderFactory, "from_config", classmethod(from_config))
        monkeypatch.setattr(merge, "merge_shards", timed)
        out = tmp_path / str(per_shard)
        cfg = compose(["policy=random", "benchmark=pick_v1", f"limit={EPISODES}", f"horizon={HORIZON}",
                       f"workers={WORKERS}", "record=true", f"output_dir={out}", "progress=false"])
        run_evaluation(cfg)
        stored[layout] = [r["benchmark_episode_index"] for r in read_eval_records(out / "dataset")]
    base = timings["one episode per shard"][0]
    print(f"\nmerge of {EPISODES} recorded episodes x {HORIZON} steps, {WORKERS} workers")
    for layout, (seconds, shards) in timings.items():
        print(f"{layout:>32}: {shards:3d} shards, merge {seconds:6.2f} s, {seconds / base:5.2f} x")
    assert all(s == list(range(EPISODES)) for s in stored.values())
