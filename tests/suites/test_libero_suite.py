"""The LIBERO suite's parts that need no LIBERO: episode plans, the state convention, the pipe protocol."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest
import torch
from lerobot.processor.env_processor import LiberoProcessorStep

from molmo_lerobot.suites.libero import MAX_STEPS, LiberoEpisode, LiberoSuite, plan_episodes
from molmo_lerobot.suites.libero_server import axis_angle
from molmo_lerobot.suites.pipe import SuiteError, SuiteProcess, SuiteProcessError

TASKS = [{"task_id": 0, "instruction": "pick up the soup", "init_states": 50},
         {"task_id": 3, "instruction": "pick up the milk", "init_states": 2}]


def test_episodes_follow_lerobot_evals_order_seeds_and_step_limits():
    eps = plan_episodes("libero_goal", TASKS, 3, seed=100)
    assert [(e.task_id, e.init_state_index, e.seed) for e in eps] == [
        (0, 0, 100), (0, 1, 101), (0, 2, 102), (3, 0, 100), (3, 1, 101), (3, 0, 102)]  # init states wrap
    assert {e.horizon for e in eps} == {MAX_STEPS["libero_goal"]} == {300}
    assert eps[3].instruction == "pick up the milk"
    assert {e.horizon for e in plan_episodes("libero_10", TASKS, 1, horizon=12)} == {12}
    with pytest.raises(ValueError, match="unknown LIBERO suite 'libero_100'"):
        plan_episodes("libero_100", TASKS, 1)


def test_episode_digest_is_its_content():
    e = LiberoEpisode("libero_object", 1, 2, 3, 280, "pick")
    assert e.digest == LiberoEpisode("libero_object", 1, 2, 3, 280, "pick").digest
    fields = [("libero_spatial", 1, 2, 3, 280, "pick"), ("libero_object", 0, 2, 3, 280, "pick"),
              ("libero_object", 1, 0, 3, 280, "pick"), ("libero_object", 1, 2, 0, 280, "pick"),
              ("libero_object", 1, 2, 3, 20, "pick"), ("libero_object", 1, 2, 3, 280, "place")]
    changed = [LiberoEpisode(*f) for f in fields]
    assert len({e.digest, *(c.digest for c in changed)}) == 7


def test_axis_angle_has_lerobots_bits():
    """The 8-D state's orientation as LeRobot's LIBERO processor computes it, bit for bit (identity included)."""
    rng = np.random.default_rng(0)
    quats = [q / np.linalg.norm(q) for q in rng.normal(size=(500, 4))] + [np.array([0.0, 0.0, 0.0, 1.0])]
    ours = np.stack([axis_angle(q) for q in quats])
    theirs = LiberoProcessorStep()._quat2axisangle(torch.from_numpy(np.stack(quats)))
    assert ours.dtype == np.float32 and np.array_equal(ours, theirs.numpy())


def test_pipe_round_trip_errors_and_a_chatty_server(tmp_path):
    """Replies carry numpy arrays; a failing request is one SuiteError and the server keeps serving; what the
    server's code prints does not corrupt the frames."""
    (tmp_path / "echo_server.py").write_text(textwrap.dedent("""
        import numpy as np
        from molmo_lerobot.suites.pipe import serve

        def double(x):
            print("noise on stdout")
            return {"y": np.asarray(x) * 2}

        def fail():
            raise KeyError("no such task")

        serve({"double": double, "fail": fail})
    """))
    with SuiteProcess(sys.executable, "echo_server", pythonpath=[tmp_path]) as proc:
        assert np.array_equal(proc.request("double", x=np.arange(3.0))["y"], [0.0, 2.0, 4.0])
        with pytest.raises(SuiteError, match=r"fail: KeyError: 'no such task'"):
            proc.request("fail")
        with pytest.raises(SuiteError, match="unknown op 'nope'"):
            proc.request("nope")
        assert proc.request("double", x=np.ones(2, dtype=np.uint8))["y"].tolist() == [2, 2]


def test_a_missing_venv_is_one_clear_error(tmp_path):
    with pytest.raises(SuiteProcessError, match=r"no interpreter at .*run `make \.libero-venv`.*MOLMO_LIBERO_VENV"):
        LiberoSuite(tmp_path)
