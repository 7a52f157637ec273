"""Workers cap torch/BLAS threads (``worker_threads``), so W workers do not run W x cores threads."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytest.importorskip("torch")


def _threads_in_fresh_process(code: str, env_threads: str | None = None) -> int:
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    if env_threads:
        env["OMP_NUM_THREADS"] = env_threads
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    return int(out.stdout.strip().splitlines()[-1])


# before torch's import is also what a worker does (the last test): the default run keeps the other order
@pytest.mark.parametrize("torch_first", [pytest.param(False, marks=pytest.mark.slow), True],
                         ids=["before-torch", "after-torch"])
def test_cap_threads_sets_torch_threads_before_or_after_its_import(torch_first):
    code = ("import torch; torch.set_num_threads(3)\n" if torch_first else "") + (
        "from molmo_lerobot.cpu_threads import cap_threads\ncap_threads(1)\n"
        "import torch\nprint(torch.get_num_threads())")
    assert _threads_in_fresh_process(code) == 1


def test_null_leaves_the_default():
    code = ("from molmo_lerobot.cpu_threads import cap_threads\ncap_threads(None)\n"
            "import torch\nprint(torch.get_num_threads())")
    assert _threads_in_fresh_process(code, env_threads="2") == 2


def test_a_worker_loading_a_torch_policy_runs_it_with_the_cap(tmp_path):
    """What a spawned worker does: build the policy (it imports torch), then run with the cap."""
    from test_lerobot_policy import save_tiny_act

    act = save_tiny_act(tmp_path / "act", image_hw=(32, 32))
    code = (
        "from molmo_lerobot.config import compose\n"
        "from molmo_lerobot.run_config import RunConfig\n"
        "from molmo_lerobot.runner.worker import EpisodeWorker, WorkerJob\n"
        f"cfg = RunConfig.of(compose(['policy=lerobot', 'policy.path={act}', 'policy.device=cpu', "
        "'worker_threads=1']))\n"
        f"job = WorkerJob(config=cfg, policy=cfg.policy.given(), output_dir={str(tmp_path)!r}, "
        "benchmark_name='b', benchmark_sha256='0')\n"
        "EpisodeWorker(job, 'w0')\n"
        "import torch\nprint(torch.get_num_threads())")
    assert _threads_in_fresh_process(code, env_threads="2") == 1
