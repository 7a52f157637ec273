"""Workers play stretches of consecutive episodes (``take_next``), so each worker's dataset shards
are in benchmark order and a recorded run merges a few shards instead of one per episode."""

from __future__ import annotations

import pytest

from molmo_lerobot.runner.supervisor import take_next


def _pending(*positions: int) -> dict[int, str]:
    return {p: f"item{p}" for p in positions}


def test_free_slots_split_the_run_into_stretches():
    pending = _pending(*range(10))
    first = take_next(pending, None, [None])
    pending.pop(first)
    second = take_next(pending, None, [first])
    assert (first, second) == (0, 5)  # the second slot starts in the middle of what the first continues


def test_a_slot_continues_its_stretch_then_takes_the_longest_one_left():
    assert take_next(_pending(3, 4, 8, 9), 2, [7]) == 3
    # its own stretch is done: the longest run left is 12..17, nobody continues it
    assert take_next(_pending(8, 9, 12, 13, 14, 15, 16, 17), 4, [7]) == 12
    # every run is continued by another slot: take the second half of the longest
    assert take_next(_pending(8, 9, 20, 21, 22, 23), 4, [7, 19]) == 22


def test_retried_item_is_continued_by_its_slot():
    # the slot lost position 3 and set last = 2: the retry comes before 4
    assert take_next(_pending(3, 4, 5), 2, [None]) == 3


@pytest.mark.slow  # the default run checks it on the recording tests/export/test_export_e2e.py reads
def test_a_recorded_run_merges_a_few_shards_in_benchmark_order(tmp_path, monkeypatch):
    """6 episodes on 2 workers: each worker's consecutive episodes share a shard."""
    pytest.importorskip("lerobot")
    import lerobot.datasets.aggregate as aggregate

    from molmo_lerobot.config import compose
    from molmo_lerobot.export.merge import read_eval_records
    from molmo_lerobot.runner.evaluate import run_evaluation

    seen: list[int] = []
    inner = aggregate.aggregate_datasets
    monkeypatch.setattr(aggregate, "aggregate_datasets",
                        lambda repo_ids, *a, **k: seen.append(len(repo_ids)) or inner(repo_ids, *a, **k))
    out = tmp_path / "run"
    cfg = compose(["policy=random", "benchmark=pick_v1", "limit=6", "horizon=3", "workers=2", "record=true",
                   f"output_dir={out}", "progress=false"])
    res = run_evaluation(cfg)
    assert res.summary["n_errors"] == 0
    assert seen and seen[0] <= 4  # one shard per episode would be 6
    stored = [r["benchmark_episode_index"] for r in read_eval_records(out / "dataset")]
    assert stored == list(range(6))
