"""One pi0 episode without a simulator, shared by our side and MolmoSpaces' ``PI_Policy``.

The episode is a sequence of native observations (three cameras of different shapes, arm joints,
Robotiq driver angles up to past MolmoSpaces' 0.824033 normalizer, a mixed-case prompt) and the
chunks a fake openpi server answers, in order (gripper outputs on and around the thresholds, below 0
and above 1). Each :data:`CASES` entry pairs a ``PiPolicyConfig`` of theirs with our preset.
:func:`run_ours` plays a case through our ``policy=pi0`` against a server answering those chunks,
stepping as our rollout does; ``pi_policy_theirs.main`` plays the same observations and answers
through their ``PI_Policy`` as their rollout does.
"""

from __future__ import annotations

import contextlib
import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from molmo_lerobot.config import compose
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.convention import MolmoSpacesConvention
from molmo_lerobot.runner.rollout import split_actions

try:
    from protocol.droid_server import FakeDroidServer
except ImportError:  # tests/ imported as a package
    from tests.protocol.droid_server import FakeDroidServer

PROMPT = "Pick up the Red Mug"
CAMERAS = {"exo_camera_1": (90, 160), "wrist_camera": (120, 160), "exo_camera_2": (100, 100)}
DT = 0.066
MOVE_GROUPS = {"arm": 7, "gripper": 1}
DRIVER_CLOSED = 0.8  # franka_droid's public gripper value = mean driver angle / 0.8


@dataclass(frozen=True)
class Case:
    """Their ``PiPolicyConfig`` changes and the ``policy=`` preset (with overrides) that should match them."""

    theirs: dict[str, Any]
    preset: str
    overrides: tuple[str, ...] = ()
    horizon: int = 10  # actions per server answer


CASES = {
    "binary": Case({}, "pi0"),
    "continuous": Case({"grasping_type": "continuous"}, "pi0", ("gripper.binarize=false",)),
    "short_answers": Case({}, "pi0_molmospaces", horizon=4),  # the server answers fewer than chunk_size
    "chunk5_threshold07": Case({"chunk_size": 5, "grasping_threshold": 0.7}, "pi0",
                               ("open_loop_horizon=5", "gripper.threshold=0.7")),
}


def observations(steps: int = 21, seed: int = 0) -> list[dict[str, Any]]:
    """Native observations for ``steps`` policy steps."""
    rng = np.random.default_rng(seed)
    out = []
    for t in range(steps):
        arm, drivers = rng.uniform(-2.0, 2.0, 7), rng.uniform(0.0, 0.9, 2)
        tcp_quat, base_quat = rng.normal(size=4), rng.normal(size=4)
        out.append({
            "images": {c: rng.integers(0, 256, (*hw, 3), dtype=np.uint8) for c, hw in CAMERAS.items()},
            "qpos": {"arm": arm, "gripper": np.array([min(drivers.mean() / DRIVER_CLOSED, 1.0)])},
            "qvel": {"arm": np.zeros(7), "gripper": np.zeros(1)},
            "joint_qpos": {"arm": arm, "gripper": drivers},
            "joint_qvel": {"arm": np.zeros(7), "gripper": np.zeros(2)},
            "tcp_pose": np.concatenate([rng.normal(size=3), tcp_quat / np.linalg.norm(tcp_quat)]),
            "robot_base_pose": np.concatenate([rng.normal(size=3), base_quat / np.linalg.norm(base_quat)]),
            "prompt": PROMPT, "step": t,
        })
    return out


def chunks(horizon: int, steps: int = 21, seed: int = 1) -> np.ndarray:
    """One (horizon, 8) float32 answer per step at most; gripper outputs on, around and past the threshold."""
    rng = np.random.default_rng(seed)
    out = rng.normal(scale=0.8, size=(steps, horizon, 8)).astype(np.float32)
    out[:, :, 7] = rng.choice(np.array([-0.2, 0.0, 0.49, 0.5, 0.51, 0.69, 0.7, 0.71, 1.0, 1.3], np.float32),
                              (steps, horizon))
    return out


def our_config(case: Case) -> dict[str, Any]:
    """The ``policy`` group of ``policy=<preset>`` with the case's overrides, as the CLI composes it."""
    return dict(compose([f"policy={case.preset}", *(f"policy.{o}" for o in case.overrides)])["policy"])


class ScriptedDroidServer(FakeDroidServer):
    """The fake openpi DROID server, answering ``chunks[i]`` to the i-th request and keeping the requests."""

    def __init__(self, chunks: np.ndarray) -> None:
        super().__init__(horizon=chunks.shape[1])
        self.chunks = chunks
        self.seen: list[dict[str, Any]] = []

    def answer(self, request: dict[str, Any]) -> np.ndarray:
        self.seen.append(request)
        return self.chunks[len(self.seen) - 1]


def run_ours(case: Case, policy_cfg: dict[str, Any] | None = None) -> dict[str, Any]:
    """Our ``policy=pi0`` on the case: the action applied at every step and the requests sent."""
    from molmo_pi0.plugin import make_pi0_policy

    server = ScriptedDroidServer(chunks(case.horizon))
    arm, gripper = [], []
    cfg = {**(policy_cfg or our_config(case)), "timeout_s": 10, "connect_timeout_s": 5}
    with server.running(), contextlib.closing(make_pi0_policy({**cfg, "port": server.port})) as policy:
        policy.reset(EpisodeContext(spec=None, episode_index=0, seed=0, prompt=PROMPT, move_groups=MOVE_GROUPS,
                                    policy_dt_s=DT))
        queue: list[dict[str, np.ndarray]] = []
        for obs in observations():
            if not queue:
                queue.extend(split_actions(policy.act(obs), MOVE_GROUPS, "pi0"))
            action = queue.pop(0)
            arm.append(np.asarray(action["arm"], np.float64))
            gripper.append(np.asarray(action["gripper"], np.float64))
    assert server.errors == [], server.errors
    return {"arm": np.stack(arm), "gripper": np.stack(gripper), "requests": server.seen}


def their_inputs(cases: dict[str, Case]) -> dict[str, Any]:
    """The observations as MolmoSpaces observations (our convention module) and each case's answers,
    as flat arrays for the parity venv."""
    views = [MolmoSpacesConvention().observation(obs) for obs in observations()]
    return {
        **{f"image_{c}": np.stack([v[c] for v in views]) for c in CAMERAS},
        **{f"chunks_{name}": chunks(case.horizon) for name, case in cases.items()},
        "cameras": list(CAMERAS), "prompt": PROMPT,
        "qpos_arm": np.array([v["qpos"]["arm"] for v in views], np.float32),
        "qpos_gripper": np.array([v["qpos"]["gripper"] for v in views], np.float32),
        "cases": {name: case.theirs for name, case in cases.items()},
    }


def _request(exterior: np.ndarray, wrist: np.ndarray, joints: Any, gripper: Any, prompt: str) -> dict[str, Any]:
    sha = lambda img: hashlib.sha256(np.ascontiguousarray(img, dtype=np.uint8).tobytes()).hexdigest()  # noqa: E731
    return {"exterior_sha256": sha(exterior), "wrist_sha256": sha(wrist),
            "joints": np.asarray(joints, np.float64).tolist(), "gripper": np.asarray(gripper, np.float64).tolist(),
            "prompt": prompt}


def applied(arm: np.ndarray, gripper: np.ndarray, requests: list[dict[str, Any]]) -> dict[str, Any]:
    """What reaches the robot at every step (arm targets, gripper command clipped to [0, 1] as our robots
    clip it) and what went to the server, images as digests: the form both sides are compared in."""
    return {"arm": np.asarray(arm, np.float64).tolist(), "gripper": np.clip(gripper[:, 0], 0.0, 1.0).tolist(),
            "requests": requests}


def applied_ours(ours: dict[str, Any]) -> dict[str, Any]:
    return applied(ours["arm"], ours["gripper"], [
        _request(r["observation/exterior_image_1_left"], r["observation/wrist_image_left"],
                 r["observation/joint_position"], r["observation/gripper_position"], r["prompt"])
        for r in ours["requests"]])


def applied_theirs(out: dict[str, Any], case: str) -> dict[str, Any]:
    """Their PI_Policy's actions (gripper 0 … 255) through our convention module into our units."""
    action = MolmoSpacesConvention().action({"gripper": out[f"{case}.gripper"]})
    return applied(out[f"{case}.arm"], action["gripper"], [
        _request(*args) for args in zip(out[f"{case}.req_exterior"], out[f"{case}.req_wrist"],
                                        out[f"{case}.req_joints"], out[f"{case}.req_gripper"], out[f"{case}.prompts"],
                                        strict=True)])


def differences(ours: dict[str, Any], theirs: dict[str, Any]) -> list[str]:
    """Where two :func:`applied` records differ (empty: they agree), step by step: everything exactly
    but the gripper command, within 1e-12 (their continuous command is the output x 255, ours / 255)."""
    diffs = []
    for t, (a, b) in enumerate(zip(ours["arm"], theirs["arm"], strict=False)):
        if a != b:
            diffs.append(f"step {t}: arm {a} != {b}")
    for t, (a, b) in enumerate(zip(ours["gripper"], theirs["gripper"], strict=False)):
        if abs(a - b) > 1e-12:
            diffs.append(f"step {t}: gripper {a} != {b}")
    if len(ours["arm"]) != len(theirs["arm"]):
        diffs.append(f"steps {len(ours['arm'])} != {len(theirs['arm'])}")
    if len(ours["requests"]) != len(theirs["requests"]):
        diffs.append(f"server requests {len(ours['requests'])} != {len(theirs['requests'])}")
    for i, (a, b) in enumerate(zip(ours["requests"], theirs["requests"], strict=False)):
        diffs += [f"request {i}: {k} {a[k]!r} != {b[k]!r}" for k in a if a[k] != b[k]]
    return diffs
