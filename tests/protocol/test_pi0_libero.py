"""``policy=pi0_libero`` against a stand-in for openpi's ``serve_policy`` with a LIBERO policy (no simulator): the
request has exactly the keys, dtypes and shapes openpi's LIBERO client sends (its ``examples/libero`` client and
``LiberoInputs``), built from a LIBERO suite observation, and the answer's 7-D actions become the chunk."""

from __future__ import annotations

import numpy as np
import pytest
from droid_server import FakeDroidServer

from molmo_lerobot.config import compose
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.image_ops import resize_with_pad_pil
from molmo_lerobot.suites.libero import policy_observation
from molmo_pi0.plugin import make_pi0_policy

LIBERO_KEYS = {"observation/image", "observation/wrist_image", "observation/state", "prompt"}


def check_libero(request: dict) -> None:
    assert set(request) == LIBERO_KEYS, sorted(request)
    for key in ("observation/image", "observation/wrist_image"):
        img = request[key]
        assert isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.shape == (224, 224, 3), (key, img)
    state = request["observation/state"]
    assert state.shape == (8,) and np.isfinite(state).all(), state
    assert isinstance(request["prompt"], str) and request["prompt"]


class FakeLiberoServer(FakeDroidServer):
    """Answers (H, 7) actions (``LiberoOutputs``), action ``t`` = ``t`` on every axis; keeps the requests."""

    def __init__(self, horizon: int = 10) -> None:
        super().__init__(horizon=horizon)
        self.received: list[dict] = []
        self.check = self._check

    def _check(self, request: dict) -> None:
        check_libero(request)
        self.received.append(request)

    def answer(self, request: dict) -> np.ndarray:
        return np.repeat(np.arange(self.horizon, dtype=np.float32)[:, None], 7, axis=1)


def ctx(move_groups=None) -> EpisodeContext:
    return EpisodeContext(spec=None, episode_index=0, seed=0, prompt="Pick up the alphabet soup",
                          move_groups=move_groups or {"eef": 7}, policy_dt_s=0.05)


def libero_obs(size: int = 256) -> dict:
    """A LIBERO suite observation as the suite session gives it to a policy."""
    rng = np.random.default_rng(3)
    raw = {"observation.images.image": rng.integers(0, 255, (size, size, 3), dtype=np.uint8),
           "observation.images.image2": rng.integers(0, 255, (size, size, 3), dtype=np.uint8),
           "observation.state": rng.normal(size=8).astype(np.float32), "task": "Pick up the alphabet soup"}
    return policy_observation(raw, 0)


def pi0_libero(port, **over):
    return make_pi0_policy({**compose(["policy=pi0_libero"])["policy"], "port": port, "timeout_s": 5, **over})


def test_libero_request_and_chunk_follow_openpis_libero_client():
    obs = libero_obs()
    with FakeLiberoServer().running() as srv:
        policy = pi0_libero(srv.port)
        policy.reset(ctx())
        chunk = policy.act(obs)
        policy.close()
    assert srv.errors == [] and len(srv.received) == 1
    request = srv.received[0]
    assert np.array_equal(request["observation/image"], resize_with_pad_pil(obs["images"]["image"], 224, 224))
    assert np.array_equal(request["observation/wrist_image"], resize_with_pad_pil(obs["images"]["image2"], 224, 224))
    assert not np.array_equal(request["observation/image"], request["observation/wrist_image"])
    assert np.array_equal(request["observation/state"], obs["qpos"]["eef"].astype(np.float64))
    assert request["prompt"] == "Pick up the alphabet soup"  # as written, as openpi's client sends it
    assert list(chunk) == ["eef"] and chunk["eef"].shape == (5, 7)  # openpi's replan_steps
    assert np.array_equal(chunk["eef"][:, 0], np.arange(5.0))


def test_pi0_libero_refuses_what_it_cannot_play():
    with FakeLiberoServer().running() as srv:
        policy = pi0_libero(srv.port)
        with pytest.raises(ValueError, match=r"policy=pi0_libero plays LIBERO episodes .* move groups are"):
            policy.reset(ctx({"arm": 7, "gripper": 1}))
        policy.reset(ctx())
        with pytest.raises(ValueError, match=r"needs a LIBERO observation .* got cameras \['exo', 'wrist'\]"):
            policy.act({"images": {"exo": np.zeros((8, 8, 3), np.uint8), "wrist": np.zeros((8, 8, 3), np.uint8)},
                        "qpos": {"arm": np.zeros(7)}})
        policy.close()
    with pytest.raises(ValueError, match=r"runs with policy=lerobot policy\.path"):
        pi0_libero(1, path="/tmp/some-checkpoint")
