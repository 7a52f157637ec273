"""End to end: ``policy=pi0`` (remote) through run_evaluation against an openpi-style DROID server.

One connection per worker; chunk length read from the response; a server that sends NaN,
a wrong shape or never answers makes per-episode errors with the reason, and the run finishes.
"""

from __future__ import annotations

import json

import pytest
from droid_server import FakeDroidServer

from molmo_lerobot.cli.bench import main as bench_main
from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation

HORIZON = 20


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "pi0_e2e"
    assert bench_main(["generate", "--task", "pick", "--houses", "2", "--episodes-per-house", "2",
                       "--name", "pi0_e2e", "--out", str(out)]) == 0
    return out


def evaluate(bench_dir, out_dir, port, *extra):
    cfg = compose(["policy=pi0", f"policy.port={port}", "workers=2", f"benchmark.path={bench_dir}",
                   f"horizon={HORIZON}", f"output_dir={out_dir}", "progress=false", *extra])
    return run_evaluation(cfg)


def test_pi0_remote_completes_episodes_with_two_workers(bench_dir, tmp_path):
    with FakeDroidServer(horizon=10, velocity=0.05).running() as srv:
        res = evaluate(bench_dir, tmp_path / "run", srv.port)
    assert srv.errors == []
    assert res.summary["n_episodes"] == 4 and res.summary["n_errors"] == 0
    assert all(e.error is None and e.steps == HORIZON for e in res.episodes)
    assert srv.connections == 2  # one connection per worker, kept across episodes
    assert srv.requests == 4 * 3  # the default preset (MolmoSpaces'): 8 of each 10 actions, open loop
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert results["policy"]["name"] == "pi0" and results["n_errors"] == 0
    assert results["policy"]["convention"] == "molmospaces" and results["eval_options"]["end_on_success"] is True


# each answer's error is checked on the policy in tests/protocol/test_pi0_remote.py; through a run, one stays
# in the default run (a server that never answers: the worker must not hang)
@pytest.mark.parametrize("mode, reason", [
    pytest.param("nan", "non-finite value at step 1", marks=pytest.mark.slow),
    pytest.param("bad_shape", "'actions' has shape (10, 5), expected (H, 8)", marks=pytest.mark.slow),
    ("silent", "sent no inference response within 1 s"),
])
def test_bad_server_answers_become_episode_errors(bench_dir, tmp_path, mode, reason):
    with FakeDroidServer(mode=mode).running() as srv:
        res = evaluate(bench_dir, tmp_path / "run", srv.port, "policy.timeout_s=1", "limit=2")
    assert res.summary["n_episodes"] == 2 and res.summary["n_errors"] == 2
    assert all(reason in e.error for e in res.episodes), [e.error for e in res.episodes]
    lines = (tmp_path / "run" / "episodes.jsonl").read_text().splitlines()
    assert len(lines) == 2 and all(reason in json.loads(ln)["error"] for ln in lines)
