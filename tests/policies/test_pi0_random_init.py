"""A random-init LeRobot PI0 (molmo_pi0.random_init, size ``small``) is a real ``policy=pi0
policy.path=…`` checkpoint: served by ``molmo-serve``, two clients' requests run as one batch of 2
and each gets a chunk of DROID actions. Needs ``molmo-pi0[inprocess]`` (transformers)."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

pytest.importorskip("transformers")
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.remote import RemotePolicy
from molmo_lerobot.serving.server import build_server, serve_in_thread
from molmo_pi0.random_init import DIMS_FILE, SIZES, read_dims, save_random_pi0

PROMPT = "pick up the white cup"


def ctx(i: int) -> EpisodeContext:
    return EpisodeContext(spec=None, episode_index=i, seed=i, prompt=PROMPT,  # type: ignore[arg-type]
                          move_groups={"arm": 7, "gripper": 1}, policy_dt_s=0.066)


def obs(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    return {"images": {cam: rng.integers(0, 255, (224, 224, 3), dtype=np.uint8) for cam in ("exterior", "wrist")},
            "qpos": {"arm": rng.uniform(-1, 1, 7), "gripper": np.zeros(1)}, "prompt": PROMPT}


def test_random_pi0_answers_a_served_batch_of_two(tmp_path):
    from lerobot.policies.pi0 import modeling_pi0

    path = save_random_pi0(tmp_path / "pi0", size="small")
    assert read_dims(path) == ("pi0", SIZES["small"])
    assert modeling_pi0.get_gemma_config("gemma_2b").width == 2048  # LeRobot's own sizes again after the build
    assert json.loads((path / "config.json").read_text())["type"] == "pi0"
    pre = json.loads((path / "policy_preprocessor.json").read_text())
    step = next(s for s in pre["steps"] if s["registry_name"] == "tokenizer_processor")
    assert step["config"]["tokenizer_name"] == str(path / "tokenizer")  # the stand-in, in a tokenizer repo's layout
    assert (path / "tokenizer" / "tokenizer.json").is_file() and (path / DIMS_FILE).is_file()

    server = build_server(Plugins(), {"name": "pi0", "path": str(path), "device": "cpu"}, port=0, max_batch=2,
                          batch_timeout_ms=5000)
    with serve_in_thread(server, start_timeout_s=120) as srv:
        clients = [RemotePolicy({"name": "remote", "port": srv.port, "timeout_s": 120}) for _ in range(2)]
        for i, client in enumerate(clients):
            client.reset(ctx(i))
        answers: list = [None, None]

        def act(i: int) -> None:
            answers[i] = clients[i].act(obs(i))

        threads = [threading.Thread(target=act, args=(i,)) for i in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        stats = srv.stats()
        for client in clients:
            client.close()
    assert stats["batch_sizes"] == {"2": 1}
    for answer in answers:
        assert answer["arm"].shape == (8, 7) and answer["gripper"].shape == (8, 1)  # open_loop_horizon 8 of 50
        assert np.isfinite(answer["arm"]).all() and set(np.unique(answer["gripper"])) <= {0.0, 1.0}
    assert not np.array_equal(answers[0]["arm"], answers[1]["arm"])  # each client its own item of the batch
