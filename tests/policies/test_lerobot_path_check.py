"""A bad ``policy.path`` is refused before any run directory or worker: a missing path, a directory that is not a
LeRobot ``save_pretrained`` checkpoint (no ``config.json``)."""

from __future__ import annotations

from eval_runs import refusal


def test_a_bad_policy_path_is_refused_before_any_run_directory(tmp_path):
    out = tmp_path / "run"
    common = ["policy=lerobot", "benchmark=pusht", "limit=1", f"output_dir={out}"]
    assert refusal(*common, "policy.path=/nonexistent/ckpt") == ["policy.path='/nonexistent/ckpt': no such directory"]
    empty = tmp_path / "checkpoints" / "last"
    empty.mkdir(parents=True)
    assert refusal(*common, f"policy.path={empty}") == [
        f"policy.path={str(empty)!r}: no config.json in that directory (not a LeRobot save_pretrained checkpoint)"]
    assert refusal(*common) == ["policy.path: missing; give policy.path=<a save_pretrained directory or a Hub repo id>"]
    assert not out.exists()
