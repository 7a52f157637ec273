"""Shared pytest fixtures, and the one place that puts the tests' helper folders on ``sys.path``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

#: Folders whose helper modules tests elsewhere import by name: ``hub_standin``, ``eval_runs`` (here),
#: ``droid_variants`` (tasks/), ``save_tiny_act`` of ``test_lerobot_policy`` (policies/), ``rby1_standin``
#: (sim/), ``droid_server`` (protocol/), ``export_synthetic`` (export/), ``tiny_policies`` and ``standin_dataset``
#: (suites/). Module names are unique across tests/.
TESTS = Path(__file__).resolve().parent
sys.path[:0] = [str(TESTS / sub) for sub in ("", "tasks", "policies", "sim", "protocol", "export", "suites")
                if str(TESTS / sub) not in sys.path]

from hub_standin import HubStandin, pinned_client_factory  # noqa: E402

#: Test files that start Ray clusters on this machine: a parallel run (``make test``: pytest-xdist) plays them in
#: one process, one after the other, since ``executor.address=auto`` joins any cluster it finds running here.
RAY_FILES = frozenset({"tests/runner/test_ray_executor.py", "tests/runner/test_ray_node_servers.py"})


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` (the Makefile's), the files of :data:`RAY_FILES` counted as one file."""
    from xdist.scheduler import LoadFileScheduling

    if config.getoption("dist") != "loadfile":
        return None

    class RayFilesTogether(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return "ray clusters" if scope in RAY_FILES else scope

    return RayFilesTogether(config, log)


@pytest.fixture(scope="session")
def run():
    """A run context of the default config, shared by the session (tests that need other settings
    build their own)."""
    from molmo_lerobot.context import RunContext

    return RunContext.build()


@pytest.fixture(scope="session")
def fork_servers():
    """The session's :class:`~molmo_lerobot.runner.forkserver.ForkServerPool`: a run given it
    (``run_evaluation(cfg, fork_servers)``) forks its workers from the server of an earlier run of the
    same preload and environment instead of starting one (seconds of imports; LeRobot's for a recording).
    The environment pytest sets per test phase (``PYTEST_CURRENT_TEST``) does not count: no worker reads it."""
    from molmo_lerobot.runner.forkserver import ForkServerPool

    with ForkServerPool(keep=4, ignored_env=["PYTEST_CURRENT_TEST"]) as pool:
        yield pool


@pytest.fixture(scope="session")
def pick_recording(tmp_path_factory, fork_servers):
    """One recorded multi-worker run, shared by the tests that read a recording of the defaults:
    ``molmo-eval policy=scripted benchmark=pick_v1 workers=2 limit=4 horizon=30 record=true``.

    Returns ``(output_dir, result, shards)``, ``shards`` the number of dataset shards the run merged."""
    import lerobot.datasets.aggregate as aggregate

    from molmo_lerobot.config import compose
    from molmo_lerobot.runner.evaluate import run_evaluation

    merged: list[int] = []
    inner = aggregate.aggregate_datasets
    out = tmp_path_factory.mktemp("pick_recording") / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(aggregate, "aggregate_datasets",
                   lambda repo_ids, *a, **k: merged.append(len(repo_ids)) or inner(repo_ids, *a, **k))
        res = run_evaluation(compose(["policy=scripted", "benchmark=pick_v1", "workers=2", "limit=4", "horizon=30",
                                      "record=true", "progress=false", f"output_dir={out}"]), fork_servers)
    assert len(merged) == 1, merged
    return out, res, merged[0]


@pytest.fixture(scope="session")
def droid_recording(tmp_path_factory, fork_servers):
    """One recorded franka_droid run with the DROID cameras (``cameras: []``), shared by the tests that read
    one: ``policy=pi0_droid`` over openpi's protocol against a fake DROID server (gripper commands 0 … 1 over
    15 steps), the first two pick_v1 episodes, 30 steps each.

    Returns ``(benchmark dir, output_dir, result, server)``."""
    import json

    from droid_server import FakeDroidServer
    from droid_variants import droid_episode

    from molmo_lerobot.config import compose
    from molmo_lerobot.paths import data_path
    from molmo_lerobot.runner.evaluate import run_evaluation

    tmp = tmp_path_factory.mktemp("droid_recording")
    bench, out = tmp / "droid_pick", tmp / "run"
    bench.mkdir()
    episodes = json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[:2]
    (bench / "benchmark.json").write_text(json.dumps([droid_episode(e) for e in episodes]))
    with FakeDroidServer(horizon=15, velocity=0.0).running() as srv:
        res = run_evaluation(compose(["policy=pi0_droid", "policy.open_loop_horizon=null", f"policy.port={srv.port}",
                                      "workers=1", f"benchmark.path={bench}", "horizon=30", "record=true",
                                      f"output_dir={out}", "progress=false"]), fork_servers)
    return bench, out, res, srv


@pytest.fixture
def hub_standin(tmp_path_factory, monkeypatch):
    """A running local stand-in of the Hugging Face Hub; ``huggingface_hub`` is pointed at it.

    Sets ``HF_ENDPOINT``, disables Xet and offline mode, moves the hub cache to a temp dir
    (both the environment and the already-imported ``huggingface_hub.constants``), and pins
    the client's HTTP session to the stand-in, so nothing reaches the network.
    """
    import huggingface_hub.constants as hfc
    import huggingface_hub.hf_api as hf_api
    from huggingface_hub import set_client_factory
    from huggingface_hub.utils._http import default_client_factory

    with HubStandin(tmp_path_factory.mktemp("hub_standin")) as hub:
        cache = tmp_path_factory.mktemp("hf_cache")
        for key, value in {"HF_ENDPOINT": hub.endpoint, "HF_HUB_DISABLE_XET": "1", "HF_HUB_OFFLINE": "0",
                           "HF_HUB_CACHE": str(cache), "HF_HUB_DISABLE_TELEMETRY": "1"}.items():
            monkeypatch.setenv(key, value)
        monkeypatch.setattr(hfc, "ENDPOINT", hub.endpoint)
        monkeypatch.setattr(hf_api.api, "endpoint", hub.endpoint)  # the client behind huggingface_hub.upload_file & co
        monkeypatch.setattr(hfc, "HUGGINGFACE_CO_URL_TEMPLATE",
                            hub.endpoint + "/{repo_id}/resolve/{revision}/{filename}")
        monkeypatch.setattr(hfc, "HF_HUB_DISABLE_XET", True)
        monkeypatch.setattr(hfc, "HF_HUB_OFFLINE", False)
        monkeypatch.setattr(hfc, "HF_HUB_CACHE", str(cache))
        set_client_factory(pinned_client_factory(hub.endpoint))
        try:
            yield hub
        finally:
            set_client_factory(default_client_factory)


@pytest.fixture
def in_process_plugins(monkeypatch):
    """``in_process_plugins(plugin, name)``: every run context built in this process (``RunContext.build``)
    gets ``plugin`` as if it were installed; spawned workers do not."""
    from molmo_lerobot import context
    from molmo_lerobot.plugins import Plugins

    added: list[tuple[object, str]] = []

    class WithInProcess(Plugins):
        def __init__(self) -> None:
            super().__init__()
            for plugin, name in added:
                self.add(plugin, name)

    monkeypatch.setattr(context, "Plugins", WithInProcess)
    return lambda plugin, name: added.append((plugin, name))
