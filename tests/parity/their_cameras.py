"""Helpers run in MolmoSpaces' venv (tests/parity/theirs.py): their camera systems placed in a scene.

Each case carries the poses our scene gives the bodies their cameras hang off (``robot_0/fr3_link0``,
``robot_0/gripper/base`` with its ``gripper/wrist_camera`` mount); a small MJCF here puts bodies of
those names at those poses, and their own ``CameraManager`` places the cameras on it. Their env's
visibility check (a segmentation render) is the one thing substituted: ``camera_oracle`` answers
for both sides. Every camera comes back as its world pose (position, forward, up) and fov.
"""

from __future__ import annotations

from types import SimpleNamespace

import camera_oracle
import mujoco
import numpy as np


class _Env:
    """What their camera code asks of a ``CPUMujocoEnv``: model, data, camera manager, visibility."""

    def __init__(self, case: dict) -> None:
        from molmo_spaces.env.camera_manager import CameraManager

        spec = mujoco.MjSpec()
        spec.worldbody.add_body(name="robot_0/fr3_link0", pos=case["link0_pos"], quat=case["link0_quat"])
        gripper = spec.worldbody.add_body(name="robot_0/gripper/base", pos=case["gripper_pos"],
                                          quat=case["gripper_quat"])
        gripper.add_camera(name="robot_0/gripper/wrist_camera", pos=case["mount_pos"], quat=case["mount_quat"],
                           fovy=case["mount_fovy"])
        self.current_model = spec.compile()
        self.current_data = mujoco.MjData(self.current_model)
        mujoco.mj_forward(self.current_model, self.current_data)
        self.camera_manager = CameraManager()
        self.oracle = case["oracle"]
        self.checks = 0

    def check_visibility(self, camera_name: str, *bodies: str):
        self.checks += 1
        seen = camera_oracle.fractions(self.camera_manager.registry[camera_name].pos, bodies, self.oracle)
        return seen if len(bodies) > 1 else seen[bodies[0]]


def _poses(env: _Env) -> dict:
    out = {}
    for name, cam in env.camera_manager.registry.cameras.items():
        if hasattr(cam, "_last_reference_pose"):  # a mounted camera: its pose from its (noised) offset now;
            cam._last_reference_pose = None  # theirs recomputes it only once its body has moved
        cam.update_pose(env)
        out[name] = {"pos": np.asarray(cam.pos, float).tolist(), "forward": np.asarray(cam.forward, float).tolist(),
                     "up": np.asarray(cam.up, float).tolist(), "fov": float(cam.fov)}
    return out


def _identity(episode: dict) -> SimpleNamespace:
    """The fields derive_episode_camera_seed reads, as their EpisodeSpec holds them (their
    benchmark_schema module is not imported: molmo_spaces.evaluation pulls in wandb)."""
    source = episode.get("source")
    return SimpleNamespace(scene_dataset=episode["scene_dataset"], data_split=episode.get("data_split", "val"),
                           house_index=episode["house_index"], seed=episode.get("seed"),
                           source=SimpleNamespace(**source) if source else None)


def eval_cameras(inputs: dict) -> dict:
    """FrankaEvalCameraSystem at each case's level: their JSON eval path (json_eval_task_sampler's
    setup_cameras) from the episode to the placed cameras."""
    from molmo_spaces.configs.camera_configs import FrankaEvalCameraSystem
    from molmo_spaces.utils.eval_camera_randomization_utils import (
        apply_camera_randomization_level,
        derive_episode_camera_seed,
        setup_eval_cameras,
    )
    from molmo_spaces.utils.task_relevant_objects_and_workspace_utils import (
        compute_workspace_center_from_object_poses,
        get_task_relevant_objects,
    )

    results = []
    for case in inputs["cases"]:
        episode = case["episode"]
        objects = episode.get("task_relevant_objects") or get_task_relevant_objects(episode["task"])
        centre = compute_workspace_center_from_object_poses(
            objects, episode["scene_modifications"]["object_poses"], np.asarray(case["tcp"]))
        seed = derive_episode_camera_seed(_identity(episode))
        env = _Env({**case, "oracle": {**case["oracle"], "centre": centre.tolist()}})
        system = apply_camera_randomization_level(FrankaEvalCameraSystem(), case["level"])
        error = None
        try:
            setup_eval_cameras(env, system, [*objects, "robot_0/gripper/base"], centre, seed)
        except Exception as exc:  # CameraPlacementError: compared with ours
            error = f"{type(exc).__name__}: {exc}"
        results.append({"seed": seed, "centre": centre.tolist(), "checks": env.checks, "error": error,
                        "cameras": _poses(env)})
    return {"results": results}


def eval_ranges(inputs: dict) -> dict:
    """Their interpolated ranges (apply_camera_randomization_level) at each level."""
    from molmo_spaces.configs.camera_configs import FrankaEvalCameraSystem
    from molmo_spaces.utils.eval_camera_randomization_utils import apply_camera_randomization_level

    out = []
    for level in inputs["levels"]:
        system = apply_camera_randomization_level(FrankaEvalCameraSystem(), level)
        cams = {c.name: c.model_dump() for c in system.cameras}
        out.append({"wrist": {k: cams["wrist_camera"][k] for k in ("fov", "fov_noise_degrees", "pos_noise_range",
                                                                    "orientation_noise_degrees")},
                    "exo": {k: cams["exo_camera_1"][k] for k in (
                        "fov", "azimuth_range", "distance_range", "height_range", "workspace_center_weight",
                        "lookat_noise_range", "fov_range", "max_placement_attempts")}})
    return {"ranges": out}


def droid_cameras(inputs: dict) -> dict:
    """FrankaDroidCameraSystem and FrankaRandomizedDroidCameraSystem through their CameraManager;
    the randomized one draws from numpy's global generator, seeded per case."""
    from molmo_spaces.configs.camera_configs import FrankaDroidCameraSystem, FrankaRandomizedDroidCameraSystem

    results = []
    for case in inputs["cases"]:
        env = _Env({**case, "oracle": {**case["oracle"], "centre": case["centre"]}})
        error = None
        try:
            if case["system"] == "fixed":
                env.camera_manager.setup_cameras(env, FrankaDroidCameraSystem())
            else:
                np.random.seed(case["seed"])
                must_see = {"__task_objects__": case["objects"], "__gripper__": ["robot_0/gripper/base"]}
                env.camera_manager.setup_cameras(env, FrankaRandomizedDroidCameraSystem(),
                                                 workspace_center=np.asarray(case["centre"]),
                                                 visibility_resolver=must_see.get)
        except Exception as exc:  # RuntimeError when no draw sees everything: compared with ours
            error = f"{type(exc).__name__}: {exc}"
        results.append({"checks": env.checks, "error": error, "cameras": _poses(env)})
    return {"results": results}
