"""Parity-venv helper: MolmoSpaces' ``PI_Policy`` on a pi_policy_scenario, as their rollout steps it.

Their policy is built from their own ``PiPolicyConfig`` (what ``PiPolicyEvalConfig`` uses) with only
``inputs["config"]`` changed; the openpi websocket client it would connect is replaced by an object
answering the scenario's chunks in order, and the task by one giving the scenario's prompt. The loop is
their ``run_single_rollout``'s: ``get_action_chunk(obs) or [get_action(obs)]``, each action applied
for one step. Runs in their venv: imports only numpy and molmo_spaces.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np


def eval_config_default(cls_name: str, field: str):
    """A field's default in their evaluation_configs.py, read from the source: importing the module pulls
    in their data-generation pipeline (wandb and more) that the parity venv leaves out."""
    origin = importlib.util.find_spec("molmo_spaces").submodule_search_locations[0]
    tree = ast.parse((Path(origin) / "evaluation" / "configs" / "evaluation_configs.py").read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls_name)
    node = next(n for n in cls.body if isinstance(n, ast.AnnAssign) and n.target.id == field)
    return ast.literal_eval(node.value)


def main(inputs: dict) -> dict:
    """Every case in ``inputs["cases"]`` ({name: PiPolicyConfig changes}) on the same observations,
    answered with ``chunks_<name>``; outputs keyed ``<name>.<what>``."""
    out = {}
    for name, config in inputs["cases"].items():
        out.update({f"{name}.{k}": v for k, v in run_case(inputs, inputs[f"chunks_{name}"], config).items()})
    out["end_on_success"] = eval_config_default("PiPolicyEvalConfig", "end_on_success")
    return out


def run_case(inputs: dict, chunks: np.ndarray, config: dict) -> dict:
    from molmo_spaces.configs.policy_configs_baselines import PiPolicyConfig
    from molmo_spaces.policy.learned_policy.pi_policy import PI_Policy

    prompt = inputs["prompt"]
    steps = len(inputs["qpos_arm"])
    policy = PI_Policy(SimpleNamespace(policy_config=PiPolicyConfig(**config), task_type="pick"))
    policy.task = SimpleNamespace(get_task_description=lambda: prompt)
    requests: list[dict] = []

    class Server:  # stands in for openpi_client's WebsocketClientPolicy
        def infer(self, model_input: dict) -> dict:
            requests.append(model_input)
            return {"actions": chunks[len(requests) - 1]}

    policy.reset()
    policy.model = Server()

    def observation(t: int) -> dict:
        obs = {c: inputs[f"image_{c}"][t] for c in inputs["cameras"]}
        obs["qpos"] = {"arm": inputs["qpos_arm"][t].tolist(), "gripper": inputs["qpos_gripper"][t].tolist()}
        return obs

    arm, gripper, t = [], [], 0
    while t < steps:
        chunk = policy.get_action_chunk(observation(t)) or [policy.get_action(observation(t))]
        for action in chunk[: steps - t]:
            arm.append(np.asarray(action["arm"], np.float64))
            gripper.append(np.asarray(action["gripper"], np.float64))
            t += 1
    return {
        "arm": np.stack(arm), "gripper": np.stack(gripper),
        "req_exterior": np.stack([r["observation/exterior_image_1_left"] for r in requests]),
        "req_wrist": np.stack([r["observation/wrist_image_left"] for r in requests]),
        "req_joints": np.stack([r["observation/joint_position"] for r in requests]).astype(np.float64),
        "req_gripper": np.stack([r["observation/gripper_position"] for r in requests]).astype(np.float64),
        "prompts": [r["prompt"] for r in requests],
        "chunk_size": policy.chunk_size, "grasping_threshold": policy.grasping_threshold,
        "grasping_type": policy.grasping_type,
    }
