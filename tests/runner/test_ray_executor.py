"""Ray executor: same contract and same per-episode outcomes as the local pool."""

from __future__ import annotations

import os

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.errors import RunError
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.evaluate import _make_executor, run_evaluation
from molmo_lerobot.runner.ray_executor import RayExecutor, RayTransport


def test_executor_ray_config_reaches_the_executor():
    cfg = RunConfig.of(compose(["executor=ray", "workers=3", "episode_timeout_s=12",
                                "executor.num_gpus_per_worker=0.5"]))
    plugins = Plugins()
    ex = _make_executor(cfg, plugins)
    assert isinstance(ex, RayExecutor)
    assert (ex.workers, ex.transport.address, ex.transport.include_dashboard) == (3, None, False)
    assert (ex.timeout_s, ex.retries, ex.transport.num_gpus_per_worker) == (12.0, 1, 0.5)
    bad = RunConfig.of({**cfg.plain(), "executor": {"name": "ray", "adress": "auto"}})
    with pytest.raises(RunError, match=r"^executor.adress: executor ray has no such option \(options: address, "):
        _make_executor(bad, plugins)
    with pytest.raises(ValueError, match="workers must be >= 1"):
        RayExecutor(0)


def test_nothing_to_do_starts_no_cluster():
    import ray

    RayExecutor(2).run(None, [], lambda r: None)  # type: ignore[arg-type]
    assert not ray.is_initialized()


@pytest.mark.slow
def test_local_and_ray_give_identical_outcomes_on_8_episodes(small_bench, tmp_path, eval_config, outcomes):
    # horizon 50 sits where the scripted expert succeeds in some episodes and not in others,
    # so any difference in seeding or stepping between executors would show up.
    common = ["policy=scripted", "workers=2", "horizon=50"]
    local = run_evaluation(eval_config(small_bench, tmp_path / "local", *common, "executor=local"))
    ray_run = run_evaluation(eval_config(small_bench, tmp_path / "ray", *common, "executor=ray"))
    assert outcomes(tmp_path / "ray") == outcomes(tmp_path / "local")
    assert len(outcomes(tmp_path / "local")) == 8
    assert 0 < local.summary["n_success"] < 8, "the horizon no longer separates episodes; pick another"
    assert ray_run.summary["executor"] == "ray" and local.summary["executor"] == "local"
    for key in ("success_rate", "success_once_rate", "ci95", "per_task", "benchmark", "thresholds"):
        assert ray_run.summary[key] == local.summary[key], key


@pytest.mark.slow
def test_ray_policy_that_cannot_start_fails_the_run_clearly(faulty_policy, small_bench, tmp_path, eval_config):
    import ray

    from molmo_lerobot.runner.supervisor import WorkerStartError

    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "executor=ray", "workers=1", "horizon=2",
                      "policy.fail_init=true")
    with pytest.raises(WorkerStartError, match="refusing to start"):
        run_evaluation(cfg)
    assert not ray.is_initialized(), "the executor shuts down the cluster it started"
    assert not (tmp_path / "run" / "results.json").exists()


def test_joining_a_missing_cluster_is_a_clear_start_error(faulty_policy, small_bench, tmp_path, eval_config,
                                                          monkeypatch):
    import ray

    from molmo_lerobot.runner.supervisor import WorkerStartError

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "executor=ray", "executor.address=auto",
                      "workers=1", "horizon=2")
    with pytest.raises(WorkerStartError, match="could not join the Ray cluster at 'auto'"):
        run_evaluation(cfg)
    assert not ray.is_initialized()


@pytest.mark.slow
def test_local_and_ray_random_policy_trajectories_are_identical(faulty_policy, small_bench, tmp_path, eval_config,
                                                                outcomes, traces):
    """The random policy's draws come from each episode's seed: local processes and Ray actors give the
    same outcomes and the same trajectories (a hash of every action and joint position) on 8 episodes."""
    runs = {}
    for executor in ("local", "ray"):
        runs[executor] = run_evaluation(eval_config(
            small_bench, tmp_path / executor, "policy=random", "workers=2", "horizon=20", f"executor={executor}",
            f"+trace_dir={tmp_path / f'traces-{executor}'}"))
    assert outcomes(tmp_path / "ray") == outcomes(tmp_path / "local")
    local_traces, ray_traces = traces(tmp_path / "traces-local"), traces(tmp_path / "traces-ray")
    assert sorted(local_traces) == list(range(8)) and ray_traces == local_traces
    assert len(set(local_traces.values())) == 8, "every episode's seed gives its own trajectory"
    assert all(r.error is None for r in runs["ray"].episodes)



def test_a_local_cluster_start_logs_no_token_auth_notice(monkeypatch):
    """Issue 39 (first hour, output): Ray logged that it turned token authentication on (its default for a new
    local cluster) at every run; that notice is dropped, Ray's behaviour and environment untouched."""
    import logging.handlers

    import ray
    from ray._private.authentication import authentication_token_setup as auth

    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", lambda **kwargs: (auth._warn_token_auth_enabled(),
                                                       auth._warn_token_auth_disabled()))
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    seen = logging.handlers.BufferingHandler(100)  # Ray's loggers do not propagate to pytest's
    logging.getLogger(auth.__name__).addHandler(seen)
    try:
        RayTransport().join(1)
    finally:
        logging.getLogger(auth.__name__).removeHandler(seen)
    messages = [r.getMessage() for r in seen.buffer]
    assert not any(m.startswith("Token authentication is enabled") for m in messages), messages
    assert any(m.startswith("Token authentication is disabled") for m in messages)  # other warnings still show
    assert "RAY_AUTH_MODE" not in os.environ
