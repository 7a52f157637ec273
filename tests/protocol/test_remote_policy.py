"""policy=remote (issue 13 item 6): any served policy plugin over the wire, native observations.

Serving ``random`` and evaluating with ``policy=remote`` gives the in-process outcomes; the
actions are bit-identical; molmo-serve refuses a policy that needs the simulator and prints
its usage for --help.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
from droid_server import FakeDroidServer

from molmo_lerobot.cli.bench import main as bench_main
from molmo_lerobot.cli.serve import main as serve_main
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.random_policy import RandomPolicy
from molmo_lerobot.policies.remote import RemotePolicy
from molmo_lerobot.protocol.client import PolicyClientError
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.serving.server import build_server, serve_in_thread

HORIZON = 30
CTX = EpisodeContext(spec=None, episode_index=3, seed=1234, prompt="pick the mug",  # type: ignore[arg-type]
                     move_groups={"arm": 7, "gripper": 1}, policy_dt_s=0.066)


def remote(port, **over) -> RemotePolicy:
    return RemotePolicy({"name": "remote", "port": port, "timeout_s": 5, "connect_timeout_s": 5, **over})


def test_remote_actions_are_the_in_process_actions():
    rng = np.random.default_rng(0)
    with serve_in_thread(build_server(Plugins(), {"name": "random", "scale": 0.3}, port=0)) as srv:
        far = remote(srv.port)
        assert far.served == "random" and far.needs_images is False
        near = RandomPolicy({"scale": 0.3})
        for episode in range(2):
            ctx = EpisodeContext(**{**CTX.__dict__, "seed": CTX.seed + episode})
            far.reset(ctx)
            near.reset(ctx)
            for step in range(5):
                obs = {"qpos": {"arm": rng.normal(size=7), "gripper": np.array([0.1])},
                       "qvel": {"arm": np.zeros(7), "gripper": np.zeros(1)}, "tcp_pose": np.zeros(7),
                       "prompt": ctx.prompt, "step": step}
                a, b = far.act(obs), near.act(obs)
                assert sorted(a) == ["arm", "gripper"]
                for g in a:
                    np.testing.assert_array_equal(a[g], b[g])
        far.close()


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "remote_e2e"
    assert bench_main(["generate", "--task", "pick", "--houses", "2", "--episodes-per-house", "2",
                       "--name", "remote_e2e", "--out", str(out)]) == 0
    return out


def evaluate(bench_dir, out_dir, *overrides):
    cfg = compose([f"benchmark.path={bench_dir}", f"horizon={HORIZON}", f"output_dir={out_dir}", "progress=false",
                   "seed=7", *overrides])
    return run_evaluation(cfg)


def outcome(e) -> tuple:
    return (e.episode_index, e.success, e.success_once, e.steps, e.seed, e.error)


def test_served_random_gives_the_in_process_outcomes(bench_dir, tmp_path):
    local = evaluate(bench_dir, tmp_path / "local", "policy=random", "workers=1", "limit=2")
    with serve_in_thread(build_server(Plugins(), {"name": "random"}, port=0)) as srv:
        served = evaluate(bench_dir, tmp_path / "served", "policy=remote", f"policy.port={srv.port}", "workers=2",
                          "limit=2")
        assert srv.served == 2 * -(-HORIZON // 8)  # chunks of 8 run open loop: one request per chunk
    assert served.summary["n_errors"] == 0 and len(served.episodes) == 2
    assert [outcome(e) for e in served.episodes] == [outcome(e) for e in local.episodes]


def test_molmo_serve_refuses_a_policy_that_needs_the_simulator(capsys):
    assert serve_main(["policy=scripted", "port=0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'scripted' reads the simulator" in err[0]


def test_molmo_serve_help_prints_usage_and_exits_0(capsys):
    assert serve_main(["--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("molmo-serve") and "usage: molmo-serve policy=P" in out and "max_batch" in out


def test_remote_refuses_a_server_that_is_not_molmo_serve():
    with (FakeDroidServer().running() as srv,
          pytest.raises(ValueError, match=r"is not a molmo-serve server.*policy=pi0")):
        remote(srv.port)


def test_connection_lost_mid_episode_fails_the_episode_then_recovers():
    with serve_in_thread(build_server(Plugins(), {"name": "random"}, port=0, idle_timeout_s=0.3)) as srv:
        far = remote(srv.port)
        far.reset(CTX)
        obs = {"qpos": {"arm": np.zeros(7), "gripper": np.zeros(1)}}
        far.act(obs)
        threading.Event().wait(0.8)  # the server drops the idle connection
        with pytest.raises(PolicyClientError, match="dropped the connection mid-episode"):
            far.act(obs)
        far.reset(CTX)  # the next episode reconnects
        assert far.act(obs)["arm"].shape == (8, 7)


def test_a_host_name_that_does_not_resolve_fails_at_once():
    """Not after policy.connect_timeout_s (60 s) of retries: a retry cannot make the name resolve."""
    import time

    from molmo_lerobot.protocol.client import PolicyClient

    client = PolicyClient("no.such.host", 8000, connect_timeout_s=60.0)
    t0 = time.monotonic()
    with pytest.raises(PolicyClientError, match=r"no.such.host:8000: its host name does not resolve .*policy.host"):
        client.connect()
    assert time.monotonic() - t0 < 5.0
