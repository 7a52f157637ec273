"""The typed ``molmo-eval`` run config, validated once before any work; its defaults, stated once.

Hydra composes the config (groups, overrides, interpolations, sweeps); :meth:`RunConfig.of`
validates the composed result and lists every problem, one line each naming its key, so a
run with nonsense options (``limit=0``, ``horizon=-5``, ``seed=abc``, ``timing.policy_dt_ms=0``,
``+timing.mode=hold``) stops before anything is written. The run reads the typed object or
its validated plain form (:meth:`RunConfig.plain`, what :class:`~molmo_lerobot.context.RunContext`
and the workers receive).

A pydantic model rather than a dataclass schema in Hydra's ConfigStore: OmegaConf stops at
the first wrongly typed value with its own multi-line message and checks no ranges, so the
range and cross-field checks (timing ratios, camera options, the work one episode may ask
for) would stay a second pass; here one pass reports everything. The core's own sections
are closed (an unknown key is a problem); ``policy``, ``benchmark`` and ``executor`` (config
groups plugins extend) and the top level (``+key=value`` for a plugin's own key) stay open.
``policy``'s shared keys are typed here (:class:`~molmo_lerobot.policies.base.PolicyOptions`), the
rest by the model its plugin declares once the run has resolved the plugin
(:func:`molmo_lerobot.policies.factory.policy_options`). Missing keys take the fields' defaults:
the only place they are stated (``conf/eval.yaml`` lists them as Hydra's ``molmo_run_defaults``
node, :func:`molmo_lerobot.config.run_defaults`).

:func:`episode_work_problem` bounds the physics steps one episode may ask for (a horizon
of 1e12 seconds or a 0.1 µs physics step would otherwise run until the watchdog).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Annotated, Any
from xml.etree import ElementTree

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    ValidationError,
    model_validator,
)

from molmo_lerobot.benchmark.schema import MAX_TASK_HORIZON_SEC
from molmo_lerobot.cameras.options import camera_option_problems
from molmo_lerobot.options import OptionsError, problem_lines, section_model
from molmo_lerobot.options import is_int as _is_int
from molmo_lerobot.options import is_number as _is_number
from molmo_lerobot.options import optional as _optional
from molmo_lerobot.options import problem as _problem
from molmo_lerobot.options import rule as _rule
from molmo_lerobot.policies.base import OpenPolicyOptions
from molmo_lerobot.robots.base import parse_base_size
from molmo_lerobot.sim.env import CONTROL_MODES, TASK_RULES, Timing

#: Most policy steps an episode may run (``horizon=``): about two hours at 66 ms per step.
MAX_HORIZON_STEPS = 100_000
#: Most physics steps (``mj_step``) one episode may ask for: horizon x ctrl ticks x substeps.
MAX_PHYSICS_STEPS = 2_000_000
#: Bounds of the run's other numeric options (past them a run only wastes the machine or never ends)
MAX_EPISODE_RETRIES = 10
MAX_WORKER_THREADS = 1024
MAX_EPISODE_TIMEOUT_S = 7 * 24 * 3600
MAX_VIDEO_CRF = 63  # libsvtav1's range (0-63); h264/hevc stop at 51 and the encoder says so


class RunConfigError(OptionsError):
    """The run config is invalid; ``problems`` holds one line per problem."""


def _workers(value: Any) -> Any:
    if not _is_int(value):
        raise _problem(f"{{key}}: expected a positive integer, got {value!r}")
    if value < 1:
        raise _problem(f"{{key}} must be at least 1, got {value}")
    return value


Flag = Annotated[bool, _rule(lambda v: isinstance(v, bool), "{key}: expected true or false, got {got}")]
Seconds = Annotated[int | float, _rule(lambda v: _is_number(v) and v > 0,
                                       "{key}: expected a positive number of seconds, got {got}")]
TimeoutSeconds = Annotated[int | float, _rule(lambda v: _is_number(v) and 0 < v <= MAX_EPISODE_TIMEOUT_S,
                                              "{key}: expected a positive number of seconds (at most "
                                              f"{MAX_EPISODE_TIMEOUT_S:,}: a week), got {{got}}")]
Millis = Annotated[int | float, _rule(lambda v: _is_number(v) and v > 0,
                                      "{key}: expected a positive number of milliseconds, got {got}")]
TaskSeconds = Annotated[int | float, _rule(lambda v: _is_number(v) and 0 < v <= MAX_TASK_HORIZON_SEC,
                                           "{key}: expected a positive number of seconds, got {got} "
                                           f"(at most {MAX_TASK_HORIZON_SEC:g})")]


class _Section(BaseModel):
    """A closed section of the run config: known keys, strict types."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)


class _OpenSection(BaseModel):
    """A section a plugin's config may add keys to (kept as given)."""

    model_config = ConfigDict(strict=True, extra="allow", frozen=True)


class TimingConfig(_Section):
    """How a policy step advances the simulation (:class:`~molmo_lerobot.sim.env.Timing`)."""

    #: one policy step
    policy_dt_ms: Millis = 66.0
    #: one controller tick
    ctrl_dt_ms: Millis = 2.0
    #: one physics step (sets model.opt.timestep)
    sim_dt_ms: Millis = 2.0
    #: hold: a step's targets applied at once and held (MolmoSpaces); ramp: moved in over the ticks
    control: Annotated[str, _rule(lambda v: v in CONTROL_MODES,
                                  f"timing: control must be one of {', '.join(CONTROL_MODES)}, got {{got}}")] = "hold"
    #: MuJoCo body sleeping from the reset state on, as MolmoSpaces' rollouts; null: as the benchmark's
    #: scene datasets say (MolmoSpaces' scenes: on; ours: off, as a sleeping body's contacts leave
    #: data.contact, docs/parity.md). run.json records the value the run used
    sleep: Annotated[bool | None, _rule(lambda v: v is None or isinstance(v, bool),
                                        "timing: sleep must be true, false or null (the benchmark's scenes "
                                        "decide), got {got}")] = None

    @model_validator(mode="after")
    def _steps_divide(self) -> TimingConfig:
        try:
            Timing(**self.model_dump(exclude={"sleep"}))
        except ValueError as exc:
            raise _problem(str(exc)) from None
        return self


class CameraConfig(_Section):
    """Which camera system each episode runs with, set up how (:mod:`molmo_lerobot.cameras.options`)."""

    #: {camera_name: {field: value}}, e.g. {exterior: {fov: 60}}
    overrides: dict[str, dict[str, Any]] = {}
    #: camera system for episodes without cameras (default: source.camera_system_class, else the robot's:
    #: franka_droid -> FrankaDroidCameraSystem); FrankaRandomizedDroidCameraSystem; FrankaEvalCameraSystem
    #: replaces every episode's cameras (= camera.eval=true)
    system: str | None = None
    #: MolmoSpaces' --use_eval_cameras: their FrankaEvalCameraSystem replaces the recorded cameras
    eval: bool = False
    #: MolmoSpaces' --camera_rand_level 0-100 (with eval=true): 0 calibrated rig, 100 exterior camera
    #: anywhere around the scene, up to 1.5 m further, fov 64-78; seeded per episode as theirs
    rand_level: int | float = 0
    #: 0 off; 1-3: our own small jitter of the episode's recorded cameras (not MolmoSpaces')
    randomization: int = 0

    @model_validator(mode="before")
    @classmethod
    def _options(cls, data: Any) -> Any:
        problems = camera_option_problems(data)
        if problems:
            raise _problem("\n".join(problems))
        return data


def _base_size(value: Any) -> Any:
    if value != "default":
        try:
            parse_base_size(value)
        except ValueError as exc:
            raise _problem(f"robot.{exc} (or default)") from None
    return value


class RobotConfig(_Section):
    #: run every episode with this robot instead of the one its spec names (``robot.robot_name``), as
    #: MolmoSpaces' eval config's ``robot_config`` does; null: each episode's own
    name: Annotated[str | None, _rule(_optional(lambda v: isinstance(v, str) and v != ""),
                                      "{key}: expected a robot's name (molmo-plugins lists them) or null, "
                                      "got {got}")] = None
    #: the robot's pedestal, as MolmoSpaces' robot configs: [x, y, z] metres, null for none; default:
    #: the episode's robot.base_size, else the robot's (franka_droid [0.5, 0.5, 0.58], franka none)
    base_size: Annotated[str | list[int | float] | None, BeforeValidator(_base_size)] = "default"


def _mjcf_file(value: Any) -> Any:
    """``custom_object.path``: a file MuJoCo loads as an MJCF model (checked once, before any episode)."""
    if value is None:
        return value
    if not isinstance(value, str) or not value:
        raise _problem(f"{{key}}: expected the path of an MJCF file (or null), got {value!r}")
    from pathlib import Path

    import mujoco

    path = Path(value).expanduser()
    if not path.is_file():
        raise _problem(f"{{key}}: no MJCF file at {path}")
    try:  # MuJoCo prints its own warnings for a file that is not XML: refuse those first
        root = ElementTree.parse(path).getroot().tag
    except (ElementTree.ParseError, OSError, UnicodeDecodeError) as exc:
        raise _problem(f"{{key}}: {path} is not an MJCF file (not XML: {exc})") from None
    if root != "mujoco":
        raise _problem(f"{{key}}: {path} is not an MJCF file (its root element is <{root}>, not <mujoco>)")
    try:
        mujoco.MjSpec.from_file(str(path)).compile()
    except Exception as exc:  # MuJoCo raises ValueError or its own errors; any is a bad file
        text = str(exc).strip().splitlines()
        raise _problem(f"{{key}}: {path} is not an MJCF model MuJoCo loads ({text[0] if text else type(exc).__name__})"
                       ) from None
    return value


class CustomObjectConfig(_Section):
    #: an MJCF file whose top body has a freejoint
    path: Annotated[str | None, BeforeValidator(_mjcf_file)] = None
    #: the new body name; the task's target is renamed to it
    name: str = "custom_object"
    #: new instruction text (default: keep the episode's)
    description: str | None = None


class MolmoSpacesConfig(_Section):
    """MolmoSpaces' data; :func:`~molmo_lerobot.molmospaces.settings.resolve` checks the values."""

    #: override the scene XML's <option> (e.g. {integrator: implicitfast}); timestep is sim_dt_ms
    physics_options: dict[str, Any] = {}
    #: null: $MLSPACES_ASSETS_DIR, else ~/.cache/molmo_lerobot/molmospaces/assets
    assets_dir: str | None = None
    #: ceiling | base: which ProcTHOR/Holodeck scene file (MolmoSpaces' default: ceiling)
    house_variant: str | None = "ceiling"
    #: with remote: install missing objects per UID through our resource manager
    cache_dir: str | None = None
    remote: str | None = None


class PluginsConfig(_Section):
    #: pin the provider of a name several plugins provide: plugins.prefer.<kind>.<name>=<plugin>
    #: (kind: task|robot|camera|scene|policy; plugin: its name in `molmo-plugins`)
    prefer: dict[str, dict[str, str]] = {}  # checked against the plugins by RunContext.build


class HubConfig(_Section):
    repo_id: str | None = None  # the recorder checks it (push=true)
    private: bool = False
    #: push=true with dataset_id: hf://<user or org> (null: $MOLMO_DATASETS_REMOTE)
    remote: str | None = None  # push=true with dataset_id: hf://<owner>; the recorder checks it


class WandbConfig(_Section):
    #: log scores and the episode table to Weights & Biases
    enable: bool = False
    project: str = "molmo-eval"
    #: W&B team or user (null: your default entity)
    entity: str | None = None


class VideoConfig(_Section):
    """How camera streams are encoded (record=true); the recorder checks the values with the encoder."""

    #: LeRobot's default (AV1: merges with datasets LeRobot records) | h264 (a third of the CPU, 28 % larger
    #: files; merges only with h264 datasets) | hevc | h264_nvenc | auto (h264_nvenc where it encodes a test
    #: frame: an NVIDIA GPU; else libsvtav1)
    vcodec: str = "libsvtav1"
    #: quality, lower is better (null: libsvtav1 30, h264 18; same picture quality)
    crf: Annotated[int | float | None,
                   _rule(_optional(lambda v: _is_number(v) and 0 <= v <= MAX_VIDEO_CRF),
                         f"{{key}}: expected a number in 0..{MAX_VIDEO_CRF} or null, got {{got}}")] = None
    #: keyframe interval; 2 keeps training-time random access cheap (LeRobot's default)
    g: int | None = 2
    #: speed preset (null: libsvtav1 12, h264 veryfast)
    preset: Annotated[int | str | None, _rule(lambda v: v is None or isinstance(v, str) or _is_int(v),
                                              "{key}: expected a preset name, a number or null, got {got}")] = None
    #: codec threads per camera stream (null: the codec decides)
    encoder_threads: int | None = 1


class BenchmarkConfig(_OpenSection):
    name: str
    path: str | None = None  # null: the shipped benchmark of this name


class ExecutorConfig(_OpenSection):
    """``executor=<name>``; the executor's options model (``molmo_executors``) checks the other options."""

    name: str


def _policy(value: Any) -> Any:
    if not isinstance(value, Mapping | OpenPolicyOptions):
        raise _problem(f"{{key}}: expected a mapping with a name (policy=<name>), got {value!r}")
    return value


def _dataset_id(value: Any) -> Any:
    from molmo_lerobot.namespaces import NamespaceError, parse_dataset_id

    if value is not None:
        try:
            parse_dataset_id(value)
        except NamespaceError as exc:
            raise _problem(f"{{key}}: {exc}") from None
    return value


class RunConfig(_OpenSection):
    """The run config, typed; fields in the composed config's order (the config groups first).

    Keys plugins add at the top level (``+trace_dir=...``) are kept as given.
    """

    #: the policy plugin's options: the keys every policy shares typed here, the plugin's own kept as given
    #: until its model (``PolicyType.options``) validates them, when the run resolves the plugin
    policy: Annotated[OpenPolicyOptions, BeforeValidator(_policy)] = OpenPolicyOptions(name="scripted")
    benchmark: BenchmarkConfig = BenchmarkConfig(name="pick_v1")
    executor: ExecutorConfig = ExecutorConfig.model_validate(
        {"name": "local", "start_method": "forkserver", "egl_devices": None, "cuda_devices": None})
    #: seconds per task type, e.g. {pick: 15, pick_and_place: 40}
    horizons: Annotated[dict[str, TaskSeconds], _rule(
        lambda v: isinstance(v, Mapping), "{key}: expected a mapping of task type to seconds, got {got}")] = {}
    #: which camera system each episode runs with, set up how
    camera: CameraConfig = CameraConfig()
    plugins: PluginsConfig = PluginsConfig()
    #: MolmoSpaces user asset libraries: {name: dir with assets_index.json}
    asset_libraries: dict[str, Any] = {}  # checked with the MolmoSpaces settings by RunContext.build
    #: MolmoSpaces user grasp libraries: {name: {path: dir with grasps_index.json, asset_library: name}}
    grasp_libraries: dict[str, Any] = {}
    #: MolmoSpaces' own data (scenes ithor, procthor-*, holodeck-*, thor/objaverse objects)
    molmospaces: MolmoSpacesConfig = MolmoSpacesConfig()
    #: worker processes (local) or simulator actors (ray)
    workers: Annotated[int, BeforeValidator(_workers)] = 2
    #: CPU threads for torch/BLAS per worker and in the policy.serve server (null: one per core)
    worker_threads: Annotated[int | None, _rule(
        _optional(lambda v: _is_int(v) and 1 <= v <= MAX_WORKER_THREADS),
        f"{{key}}: expected an integer in 1..{MAX_WORKER_THREADS} (or null for the libraries' default), "
        "got {got}")] = 1
    #: evaluate only the first K (>= 1) episodes; a resume keeps the recorded one unless given a larger one
    limit: Annotated[int | None, _rule(
        _optional(lambda v: _is_int(v) and v >= 1),
        "{key}: expected a positive integer (or null for every episode), got {got}")] = None
    #: exactly these benchmark indices (runner/selection.py); at most one of limit, episodes, sample
    episodes: Annotated[list[int] | None, _rule(
        _optional(lambda v: isinstance(v, list) and v != [] and all(_is_int(i) and i >= 0 for i in v)
                  and len(set(v)) == len(v)),
        "{key}: expected a non-empty list of distinct benchmark indices (>= 0), got {got}")] = None
    #: K episodes spread over the benchmark's (house, task) strata, drawn with ``seed``
    sample: Annotated[int | None, _rule(
        _optional(lambda v: _is_int(v) and v >= 1),
        "{key}: expected a positive number of episodes (or null), got {got}")] = None
    #: run seed; per-episode seeds derive from it and the episode's content
    seed: Annotated[int, _rule(_is_int, "{key}: expected an integer, got {got}")] = 0
    #: default: runs/<benchmark>-<policy>-<timestamp>
    output_dir: Annotated[str | None, _rule(_optional(lambda v: isinstance(v, str) and v.strip() != ""),
                                            "{key}: expected a path (or null for runs/<benchmark>-<policy>-"
                                            "<time>), got {got}")] = None
    #: write output_dir/dataset as a LeRobot v3 dataset
    record: Flag = False
    #: record=true: a scripted expert's recording ends this many steps after its first success (null:
    #: the whole rollout); other policies are recorded in full. Scores are unchanged: the rollout
    #: still runs to the horizon (end_on_success ends it)
    record_hold_steps: Annotated[int | None, _rule(
        _optional(lambda v: _is_int(v) and v >= 0), "{key}: expected a non-negative integer or null, got {got}")] = 10
    #: ... but it keeps at least this many frames (the horizon permitting): the action chunk of
    #: LeRobot's ACT and SmolVLA, which lerobot-doctor's gate asks of each episode
    record_min_frames: Annotated[int, _rule(
        lambda v: _is_int(v) and v >= 0, "{key}: expected a non-negative integer, got {got}")] = 100
    #: record=true: also record the task's observation.environment_state (pick: the object's
    #: pose in the robot base frame): privileged ground truth for state-only policies, not a
    #: camera's view. A policy that reads it gets it either way
    record_environment_state: Flag = False
    #: push the dataset and scores to the Hub (hub.repo_id; with dataset_id: hub.remote)
    push: Flag = False
    #: ns/sub/name: also store the recording in the local dataset store under this id
    #: ($MOLMO_DATASETS_PATH, else $MOLMO_LEROBOT_HOME/datasets; molmo-datasets --help)
    dataset_id: Annotated[str | None, BeforeValidator(_dataset_id)] = None
    #: rerun only the episodes missing from output_dir/episodes.jsonl
    resume: Flag = False
    #: policy steps; else horizons.<task>; else task_horizon_sec; else the task's default
    horizon: Annotated[int | None, _rule(
        _optional(lambda v: _is_int(v) and 1 <= v <= MAX_HORIZON_STEPS),
        f"{{key}}: expected a whole number of policy steps in 1..{MAX_HORIZON_STEPS} (or null), got {{got}}")] = None
    #: wall-clock limit per episode; past it the episode is an error
    episode_timeout_s: TimeoutSeconds = 900
    #: reruns of an episode whose worker died (SIGKILL, segfault) or that failed for the machinery (infrastructure)
    episode_retries: Annotated[int, _rule(lambda v: _is_int(v) and 0 <= v <= MAX_EPISODE_RETRIES,
                                          f"{{key}}: expected an integer in 0..{MAX_EPISODE_RETRIES}, got {{got}}")] = 1
    #: a bar on a terminal; else one line per finished episode
    progress: Flag = True
    #: not a terminal: a line with the running episodes' steps this often
    progress_interval_s: Annotated[int | float | None, _rule(
        _optional(lambda v: _is_number(v) and v > 0), "{key}: expected a positive number of seconds, got {got}")] = 30
    #: how a policy step advances the simulation (part of the trial: molmo-compare checks it)
    timing: TimingConfig = TimingConfig()
    #: swap every episode's target object for this MJCF (keeping its pose)
    custom_object: CustomObjectConfig = CustomObjectConfig()
    #: end an episode at its first success (MolmoSpaces' end_on_success / terminate_upon_success);
    #: Hydra's default is the policy preset's (policy.end_on_success; pi0: true), else false
    end_on_success: Flag = False
    #: molmospaces: success judged as MolmoSpaces' code judges it, quirks included (open: a zero-range
    #: joint at 0 listed first makes their fraction NaN, the episode fails); an episode our corrected
    #: rule would judge otherwise says so in parity_notes. fixed: our corrected rules
    task_rules: Annotated[str, _rule(lambda v: v in TASK_RULES,
                                     f"{{key}}: expected one of {', '.join(TASK_RULES)}, got {{got}}")] = "molmospaces"
    robot: RobotConfig = RobotConfig()
    #: record=true: how camera streams are encoded (LeRobot's RGBEncoderConfig)
    video: VideoConfig = VideoConfig()
    #: scene_dataset "user": house_index i is scene_xml_paths[i] (+ <name>_metadata.json beside it)
    scene_xml_paths: list[str] = []
    hub: HubConfig = HubConfig()
    wandb: WandbConfig = WandbConfig()

    @model_validator(mode="after")
    def _one_selection(self) -> RunConfig:
        given = [k for k in ("limit", "episodes", "sample") if getattr(self, k) is not None]
        if len(given) > 1:
            raise _problem(f"{' and '.join(given)}: give at most one of limit (the first K episodes), episodes "
                           "(these indices) and sample (K spread over houses and tasks)")
        return self

    @model_validator(mode="after")
    def _bounded_work(self) -> RunConfig:
        if self.horizon is not None:
            problem = episode_work_problem(self.horizon, self.timing.model_dump(), "horizon")
            if problem:
                raise _problem(problem)
        return self

    @model_validator(mode="after")
    def _shm_is_local(self) -> RunConfig:
        executor = self.executor.name
        if self.policy.serve and self.policy.serve_transport == "shm" and executor != "local":
            raise _problem(f"policy.serve_transport=shm needs executor=local (workers on the server's machine), "
                           f"not executor={executor}; use policy.serve_transport=websocket or auto")
        return self

    @classmethod
    def of(cls, config: RunConfig | Mapping[str, Any] | None) -> RunConfig:
        """``config`` validated (a composed ``DictConfig`` is resolved first; a ``RunConfig`` is
        returned as is). Raises :class:`RunConfigError` listing every problem."""
        from omegaconf import DictConfig, OmegaConf

        if isinstance(config, RunConfig):
            return config
        data = OmegaConf.to_container(config, resolve=True) if isinstance(config, DictConfig) else config
        try:
            return cls.model_validate(data or {})
        except ValidationError as exc:
            raise RunConfigError(_lines(exc)) from None

    def plain(self) -> dict[str, Any]:
        """The validated config as plain data (a fresh copy): what the run and its workers read, and
        ``run.json`` keeps (``policy`` as given: its plugin's model fills in the rest)."""
        return copy.deepcopy({**self.model_dump(), "policy": self.policy.given()})


def section_keys(path: str) -> tuple[list[str], bool] | None:
    """The keys the schema knows at ``path`` (``""``: the top level) and whether it refuses
    others; ``None`` for a path inside an open section or a free-form map."""
    model = section_model(RunConfig, path)
    return None if model is None else (list(model.model_fields), model.model_config.get("extra") == "forbid")


def _lines(exc: ValidationError) -> list[str]:
    """One line per problem, each naming its key; a section's unknown keys in one line."""
    return problem_lines(exc, RunConfig)


def config_problems(cfg: Mapping[str, Any]) -> list[str]:
    """Every problem of ``cfg`` (a resolved ``conf/eval.yaml``, possibly partial), one line each."""
    try:
        RunConfig.of(cfg)
    except RunConfigError as exc:
        return exc.problems
    return []


def physics_steps(horizon: int, timing: Mapping[str, float]) -> int:
    """``mj_step`` calls an episode of ``horizon`` policy steps makes under ``timing``."""
    per_policy_step = (round(timing["policy_dt_ms"] / timing["ctrl_dt_ms"])
                       * round(timing["ctrl_dt_ms"] / timing["sim_dt_ms"]))
    return horizon * per_policy_step


def episode_work_problem(horizon: int, timing: Mapping[str, float], what: str) -> str | None:
    """Why ``horizon`` policy steps under ``timing`` is too much work for one episode, or ``None``."""
    steps = physics_steps(horizon, timing)
    if horizon <= MAX_HORIZON_STEPS and steps <= MAX_PHYSICS_STEPS:
        return None
    return (f"{what}: {horizon:,} policy steps x {steps // horizon:,} physics steps each = {steps:,} physics steps, "
            f"over the limit of {MAX_PHYSICS_STEPS:,} per episode (at most {MAX_HORIZON_STEPS:,} policy steps); "
            "lower the horizon (horizon=, horizons.<task>=, task_horizon_sec) or raise timing.sim_dt_ms")
