"""``policy=lerobot policy.path=…``: any LeRobot pretrained policy with its pre/post processors.

Our observation (images by camera name, ``qpos`` by move group, prompt) is mapped to the
policy's feature keys as our datasets name them (:mod:`molmo_lerobot.features`): each image
feature ``observation.images.<key>`` takes the camera named in ``cameras`` (default: the camera
recorded as that feature), ``observation.state`` is the concatenation of the ``state`` move
groups (default: the episode's, in the robot's order), ``observation.environment_state`` (a
checkpoint trained on it: privileged, see :mod:`molmo_lerobot.features`) is the observation's
``environment_state``, which the rollout then adds, and the prompt goes under ``task``. The
action vector is split into move groups in ``action_groups`` order (default: the episode's). With
``convention: molmospaces`` the state takes MolmoSpaces' joint units (the Robotiq gripper as its
two driver angles) and the action's gripper is their 0 … 255 command.

The policy gets what ``lerobot-eval`` hands it for one env (a batch of one): each image as a
``(1, C, H, W)`` float32 tensor in [0, 1] at the size the env renders it (``resize: none``, the
default: the policy's own pre-processor decides; ``pad``/``stretch`` resize to the checkpoint's
declared size, only when asked), the state as ``(1, D)`` float32, the task as ``[prompt]``; then
its own pre-processor, ``select_action``, post-processor. An env suite names the feature each of
its cameras is in LeRobot's env (``EpisodeContext.extra["camera_features"]``: PushT's ``image`` is
``observation.image``). :meth:`LeRobotPolicy.reset` seeds torch's RNG (LeRobot's ``set_seed``)
with the episode's seed, so a sampling policy (diffusion) draws the same noise for an episode in
any worker and on resume.

``mode: step`` (the default: ``lerobot-eval``'s actions) calls ``select_action`` every step
(LeRobot's own action queue, observation history and temporal ensembling); ``mode: chunk``
returns the whole predicted chunk, which our rollout runs open loop (renders only at chunk ends:
the same actions for a policy whose ``select_action`` plays out its chunk, like ACT without
ensembling; not for one that keeps an observation history, like diffusion). Loading refuses a
checkpoint whose weights did not actually end up in the model (some LeRobot policies silently
keep random weights).
"""

from __future__ import annotations

import copy
import os
import tempfile
from collections import deque
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BeforeValidator, Field

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.features import (
    ENV_STATE,
    ENV_STATE_KEY,
    IMAGE_PREFIX,
    STATE,
    camera_of,
    concat,
    env_state_vector,
    split,
)
from molmo_lerobot.hookspecs import hookimpl
from molmo_lerobot.options import problem as options_problem
from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyOptions, PolicyType
from molmo_lerobot.policies.convention import get_convention
from molmo_lerobot.policies.image_ops import resize_with_pad


class WeightsNotLoadedError(MolmoError, RuntimeError):
    """A checkpoint's weights are not the ones in the model (missing, renamed or random)."""


def _checkpoint_path(path: Any) -> Any:
    problem = path_problem(path)
    if problem:
        raise options_problem(problem)
    return path


class LeRobotOptions(PolicyOptions):
    """``policy=lerobot``'s options (conf/policy/lerobot.yaml documents them)."""

    name: str = "lerobot"
    #: local directory or Hub repo id (save_pretrained layout); no default: every run names its checkpoint
    path: Annotated[str, BeforeValidator(_checkpoint_path)] = Field(default=None, validate_default=True)
    device: str = "auto"
    mode: Literal["step", "chunk"] = "step"
    n_action_steps: int | None = Field(default=None, ge=1)
    cameras: dict[str, str] = Field(default_factory=dict)
    state: list[str] | None = None
    state_key: str = STATE
    action_groups: list[str] | None = None
    task_key: str = "task"
    resize: Literal["none", "pad", "stretch"] = "none"
    verify_weights: bool = True
    max_unmatched_fraction: float = Field(default=0.01, ge=0.0, le=1.0)


def pick_device(requested: str) -> str:
    import torch

    if requested != "auto":
        if requested.startswith("cuda") and not torch.cuda.is_available():
            raise ValueError(f"policy.device={requested!r} but CUDA is not available on this machine")
        return requested
    if torch.cuda.is_available():
        return "cuda"
    if getattr(torch.backends, "mps", None) is not None and torch.backends.mps.is_available():
        return "mps"
    return "cpu"


def _model_file(path: str) -> str:
    if os.path.isdir(path):
        return str(Path(path) / "model.safetensors")
    from huggingface_hub import hf_hub_download

    return hf_hub_download(repo_id=path, filename="model.safetensors", local_files_only=True)


def verify_weights_loaded(model: Any, model_file: str, max_unmatched_fraction: float = 0.01) -> dict[str, int]:
    """Check that the model's tensors are the checkpoint's.

    Tensors are matched by name (allowing added/removed leading prefixes such as ``model.``).
    Any matched tensor whose value differs means the load failed; more than
    ``max_unmatched_fraction`` of the elements without a counterpart in the file means the
    checkpoint does not belong to this model. Raises :class:`WeightsNotLoadedError`.
    """
    import torch
    from safetensors import safe_open

    if not os.path.isfile(model_file):
        raise WeightsNotLoadedError(f"{model_file}: no such weights file")
    with safe_open(model_file, framework="pt", device="cpu") as f:
        by_suffix: dict[str, str | None] = {}
        for key in f.keys():  # noqa: SIM118 - a safetensors handle has keys() but is not iterable
            for suffix in _suffixes(key):
                by_suffix[suffix] = None if suffix in by_suffix and by_suffix[suffix] != key else key
        state = model.state_dict()
        seen_storage: dict[int, bool] = {}
        total = unmatched = 0
        unmatched_names: list[str] = []
        differing: list[str] = []
        for name, tensor in state.items():
            total += tensor.numel()
            key = next((by_suffix[s] for s in _suffixes(name) if by_suffix.get(s)), None)
            ptr = tensor.data_ptr() if tensor.numel() else -1
            if key is None:
                if not seen_storage.get(ptr):  # tied weights are saved once, under one name
                    unmatched += tensor.numel()
                    unmatched_names.append(name)
                continue
            stored = f.get_tensor(key)
            if stored.shape != tensor.shape or not torch.equal(stored.to(tensor.dtype), tensor.detach().cpu()):
                differing.append(name)
            else:
                seen_storage[ptr] = True
    if differing:
        raise WeightsNotLoadedError(
            f"{model_file}: {len(differing)} of {len(state)} tensors differ from the checkpoint "
            f"(e.g. {', '.join(differing[:3])}); the weights did not load"
        )
    if total and unmatched / total > max_unmatched_fraction:
        raise WeightsNotLoadedError(
            f"{model_file}: {unmatched / total:.1%} of the model's parameters have no counterpart in the "
            f"checkpoint (e.g. {', '.join(unmatched_names[:3])}); the weights did not load"
        )
    return {"tensors": len(state), "unmatched_tensors": len(unmatched_names)}


def _suffixes(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[i:]) for i in range(min(3, len(parts) - 1) + 1)]


#: LeRobot policy types whose ``select_action`` is ``predict_action_chunk`` plus an action queue,
#: so a batched forward with per-client queues reproduces it. Their processors keep no state
#: across calls: pi0 / pi0.5's relative-action step caches the state only from its preprocessing
#: to the postprocessing of the same call, which :meth:`LeRobotPolicy.act_batch` runs back to
#: back for the whole batch. (pi0 / pi0.5 draw flow-matching noise per batch item, so their
#: batched actions equal in-process ones in distribution, not bit for bit; no weights here.)
BATCHABLE_TYPES = frozenset({"act", "pi0", "pi05"})


class LeRobotPolicy(Policy):
    """A LeRobot ``PreTrainedPolicy`` with its processors, behind our Policy interface.

    Served (``molmo-serve``), each client gets a :meth:`fork`: the model and processors are
    shared, the action queue is the fork's own, and :meth:`act_batch` stacks the clients'
    observations into one forward pass and splits the chunks (types in
    :data:`BATCHABLE_TYPES`, without ACT's temporal ensembling).
    """

    def __init__(self, cfg: Mapping[str, Any]) -> None:
        self.cfg = validate_group("policy", LeRobotOptions, cfg)
        self.convention = get_convention(self.cfg.convention)
        self.device = pick_device(self.cfg.device)
        self.policy, self.preprocessor, self.postprocessor = self._load()
        features = self.policy.config.input_features
        from lerobot.configs.types import FeatureType

        self.image_features = {k: tuple(f.shape) for k, f in features.items() if f.type is FeatureType.VISUAL}
        self.state_dim = features[self.cfg.state_key].shape[0] if self.cfg.state_key in features else None
        self.needs_images = bool(self.image_features)
        self.env_state_dim = features[ENV_STATE].shape[0] if ENV_STATE in features else None
        self.needs_environment_state = self.env_state_dim is not None
        config = self.policy.config
        self.batched = config.type in BATCHABLE_TYPES and getattr(config, "temporal_ensemble_coeff", None) is None
        self._groups: dict[str, int] = {}
        self._camera_features: dict[str, str] = {}
        self._prompt = ""
        self._queue: deque[np.ndarray] | None = None  # a fork's own action queue (None: LeRobot's queue)

    def _load(self) -> tuple[Any, Any, Any]:
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        path = self.cfg.path
        try:
            with _temporary_files_removed():
                config = PreTrainedConfig.from_pretrained(path)
        except Exception as exc:
            raise ValueError(f"policy.path={path!r}: not a LeRobot pretrained policy "
                             f"({type(exc).__name__}: {exc})") from None
        config.device = self.device
        if self.cfg.n_action_steps is not None and hasattr(config, "n_action_steps"):
            config.n_action_steps = self.cfg.n_action_steps
        policy = get_policy_class(config.type).from_pretrained(path, config=config)
        policy.to(self.device)
        policy.eval()
        if self.cfg.verify_weights:
            verify_weights_loaded(policy, _model_file(path), self.cfg.max_unmatched_fraction)
        pre, post = make_pre_post_processors(
            config,
            pretrained_path=path,
            preprocessor_overrides={"device_processor": {"device": self.device}},
        )
        return policy, pre, post

    # Policy interface ------------------------------------------------------------------
    def reset(self, ctx: EpisodeContext) -> None:
        from lerobot.utils.random_utils import set_seed

        set_seed(ctx.seed % 2**32)  # as lerobot-eval seeds its run (numpy takes seeds in [0, 2**32))
        if self._queue is not None:  # a fork: its own queue only (shared processors of these types are stateless)
            self._queue.clear()
        else:
            self.policy.reset()
            for pipeline in (self.preprocessor, self.postprocessor):
                pipeline.reset()
        self._groups = dict(ctx.move_groups)
        self._camera_features = dict(ctx.extra.get("camera_features", {}))
        self._prompt = ctx.prompt

    def fork(self) -> LeRobotPolicy | None:
        """A client of the same model with its own action queue (batchable types only)."""
        if not self.batched:
            return None
        twin = copy.copy(self)
        twin._groups, twin._camera_features, twin._prompt, twin._queue = {}, {}, "", deque()
        return twin

    @classmethod
    def act_batch(cls, policies: list[Policy], observations: list[Observation]) -> list[Action | Exception]:
        """One forward for every client whose queue is empty; see the class docstring."""
        forks: list[LeRobotPolicy] = policies  # type: ignore[assignment]
        results: list[Any] = [None] * len(forks)
        todo: list[int] = []
        for i, p in enumerate(forks):
            if p._queue is None:
                results[i] = TypeError("act_batch needs forks of a LeRobotPolicy (LeRobotPolicy.fork)")
            elif p.cfg.mode == "step" and p._queue:
                results[i] = p._to_action(p._queue.popleft()[None])
            else:
                todo.append(i)
        chunks = cls.predict_batch([forks[i] for i in todo], [observations[i] for i in todo])
        for i, actions in zip(todo, chunks, strict=True):
            p = forks[i]
            if isinstance(actions, Exception):
                results[i] = actions
                continue
            try:
                if p.cfg.mode == "step":
                    p._queue.extend(actions)  # type: ignore[union-attr]
                    results[i] = p._to_action(p._queue.popleft()[None])  # type: ignore[union-attr]
                else:
                    results[i] = p._to_action(actions)
            except Exception as exc:
                results[i] = exc
        return results

    @staticmethod
    def predict_batch(policies: list[LeRobotPolicy], observations: list[Observation]) -> list[np.ndarray | Exception]:
        """Each observation's unnormalized chunk (H, A) from one forward of the first policy's model
        (instances of one model: forks); a bad observation gets its exception, the others still run."""
        import torch

        results: list[Any] = [None] * len(policies)
        todo: list[tuple[int, dict[str, Any]]] = []
        for i, (p, obs) in enumerate(zip(policies, observations, strict=True)):
            try:
                todo.append((i, p._batch(obs)))
            except Exception as exc:  # a bad observation fails its own request only
                results[i] = exc
        if todo:
            lead = policies[todo[0][0]]
            batch = {key: (torch.cat([b[key] for _, b in todo]) if torch.is_tensor(value)
                           else [item for _, b in todo for item in b[key]])
                     for key, value in todo[0][1].items()}
            with torch.inference_mode():
                chunk = lead.policy.predict_action_chunk(lead.preprocessor(batch))
                n = getattr(lead.policy.config, "n_action_steps", None)
                chunk = lead.postprocessor(chunk[:, :n] if n else chunk)
            for (i, _), actions in zip(todo, chunk.detach().to("cpu", torch.float32).numpy(), strict=True):
                results[i] = actions
        return results

    def act(self, obs: Observation) -> Action:
        if self._queue is not None:
            result = self.act_batch([self], [obs])[0]
            if isinstance(result, Exception):
                raise result
            return result
        return self._to_action(self.predict(obs))

    def _to_action(self, actions: np.ndarray) -> Action:
        """(H, A) unnormalized actions -> our action (step mode) or chunk, split into move groups."""
        groups = self.cfg.action_groups or list(self._groups)
        dims = {g: self._groups.get(g, 0) for g in groups}
        if sum(dims.values()) != actions.shape[-1]:
            raise ValueError(
                f"policy {self.cfg.path!r} outputs {actions.shape[-1]} action values but move groups "
                f"{dims} need {sum(dims.values())} (set policy.action_groups)"
            )
        out = split(actions, dims)
        return self.convention.action({g: a[0] for g, a in out.items()} if self.cfg.mode == "step" else out)

    def predict(self, obs: Observation) -> np.ndarray:
        """Unnormalized actions (H, A): H = 1 in step mode, the executed chunk in chunk mode."""
        import torch

        batch = self._batch(obs)
        with torch.inference_mode():
            batch = self.preprocessor(batch)
            if self.cfg.mode == "step":
                action = self.policy.select_action(batch)
            else:
                action = self.policy.predict_action_chunk(batch)
                n = getattr(self.policy.config, "n_action_steps", None)
                action = action[:, :n] if n else action
            action = self.postprocessor(action)
        arr = action.detach().to("cpu", torch.float32).numpy()
        return arr.reshape(-1, arr.shape[-1])

    def _batch(self, obs: Observation) -> dict[str, Any]:
        """``obs`` as ``lerobot-eval`` hands a policy one env's observation: a batch of one (see the module)."""
        import torch

        view = self.convention.observation(obs)
        images = self.convention.images(view)
        batch: dict[str, Any] = {}
        for key, (_c, h, w) in self.image_features.items():
            camera = self._camera(key, images)
            img = np.asarray(images[camera])
            if self.cfg.resize != "none" and img.shape[:2] != (h, w):
                img = resize_with_pad(img, h, w) if self.cfg.resize == "pad" else _stretch(img, h, w)
            # as LeRobot's preprocess_observation: channels first, contiguous, float in [0, 1]
            chw = torch.from_numpy(np.ascontiguousarray(img.transpose(2, 0, 1)))
            batch[key] = chw[None].float().div_(255.0)
        if self.state_dim is not None:
            qpos = view.get("qpos") or {}
            groups = self.cfg.state if self.cfg.state is not None else list(self._groups)
            missing = [g for g in groups if g not in qpos]
            if missing:
                raise KeyError(f"policy.state names move groups {missing} absent from the observation ({sorted(qpos)})")
            state = concat(qpos, groups, self.cfg.state_key)
            if state.shape[0] != self.state_dim:
                raise ValueError(
                    f"{self.cfg.state_key} needs {self.state_dim} values, move groups {groups} give {state.shape[0]}"
                )
            batch[self.cfg.state_key] = torch.from_numpy(state)[None]
        if self.env_state_dim is not None:
            if obs.get(ENV_STATE_KEY) is None:
                raise KeyError(f"policy feature {ENV_STATE!r}: the observation has no {ENV_STATE_KEY!r} "
                               "(the episode's task defines none)")
            batch[ENV_STATE] = torch.from_numpy(env_state_vector(obs[ENV_STATE_KEY], self.env_state_dim))[None]
        batch[self.cfg.task_key] = [obs.get("prompt", self._prompt) or self._prompt]
        return batch

    def _camera(self, feature: str, images: Mapping[str, Any]) -> str:
        """The camera image ``feature`` takes: ``policy.cameras``, else the env's own name for it
        (``camera_features``), else the camera recorded as it."""
        short = feature.removeprefix(IMAGE_PREFIX)
        named = [cam for cam, k in self.cfg.cameras.items() if k in (feature, short)]
        named += [cam for cam, k in self._camera_features.items() if k == feature]
        camera = next(iter(named), None) or camera_of(feature, images) or short
        if camera not in images:
            raise KeyError(
                f"policy feature {feature!r} wants camera {camera!r}, observation has {sorted(images)} "
                f"(map it with policy.cameras.<camera>={feature})"
            )
        return camera

    def close(self) -> None:
        self.policy = self.preprocessor = self.postprocessor = None
        try:
            import torch

            if torch.cuda.is_available():
                torch.cuda.empty_cache()
        except ImportError:
            pass


def _stretch(img: np.ndarray, h: int, w: int) -> np.ndarray:
    import cv2

    return cv2.resize(np.ascontiguousarray(img, dtype=np.uint8), (w, h), interpolation=cv2.INTER_AREA)


#: the policy config file of a LeRobot ``save_pretrained`` directory
CONFIG_NAME = "config.json"


@contextmanager
def _temporary_files_removed() -> Iterator[None]:
    """Temporary files made inside go to a directory of ours, removed after: LeRobot's
    ``PreTrainedConfig.from_pretrained`` writes the config it parses to a ``NamedTemporaryFile(delete=False)``
    and never removes it (a file in ``/tmp`` per policy load: per worker, per served policy)."""
    with tempfile.TemporaryDirectory(prefix="molmo-lerobot-load-") as own:
        before, tempfile.tempdir = tempfile.tempdir, own
        try:
            yield
        finally:
            tempfile.tempdir = before


def path_problem(path: Any) -> str | None:
    """What is wrong with ``policy.path`` that shows without loading it (``None``: nothing): none given, a
    local path that is no directory, a directory without LeRobot's ``config.json``. A Hub repo id
    (``owner/name``, not a local directory) is left to loading."""
    if not isinstance(path, str) or path in ("", "???"):
        return "policy.path: missing; give policy.path=<a save_pretrained directory or a Hub repo id>"
    if os.path.isdir(path):
        if not os.path.isfile(os.path.join(path, CONFIG_NAME)):
            return (f"policy.path={path!r}: no {CONFIG_NAME} in that directory (not a LeRobot save_pretrained "
                    "checkpoint)")
        return None
    if path.startswith((".", "/", "~")) or path.count("/") != 1:
        return f"policy.path={path!r}: no such directory"
    return None


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType("lerobot", LeRobotPolicy, "any LeRobot pretrained policy (policy.path=…)",
                       conventions=True, preload=("torch", "lerobot.policies.factory"), options=LeRobotOptions)]
