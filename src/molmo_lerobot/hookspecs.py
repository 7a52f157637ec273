"""The hook specifications every molmo_lerobot plugin implements (one file, one docstring per hook).

A plugin is a module (or object) named by an entry point in the group ``molmo_lerobot``.
It implements any subset of these hooks with ``@molmo_lerobot.hookimpl``. Our built-in
task types, robots, camera systems, scene datasets, asset and grasp libraries and policies
are plugins too and register through the very same entry points (see ``pyproject.toml``).

Each ``molmo_*`` provider hook returns a list of descriptors; the registries in
:mod:`molmo_lerobot.plugins` index them by name (and alias). Two plugins providing one name
clash: ``molmo-plugins`` lists it and a run resolving that name fails naming both, unless
its config pins one (``plugins.prefer.<kind>.<name>=<plugin>``).

Hooks are called through pluggy one implementation at a time, in pluggy's order (the most
recently registered first, ``tryfirst`` / ``trylast`` respected; ``specname`` works). An
implementation that raises marks its plugin broken (listed by ``molmo-plugins``, skipped
everywhere else); hook wrappers are not supported. Hooks that take the run config
(``molmo_recorders``, ``molmo_episode_overrides``) reject it by raising ``ValueError``
(e.g. :class:`ConfigError`): that is reported as the run's (or the episode's) error instead.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pluggy

from molmo_lerobot.errors import MolmoError

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetLibraryType, GraspLibraryType
    from molmo_lerobot.benchmark.generators import BenchmarkGenerator
    from molmo_lerobot.benchmark.packs import BenchmarkDir
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.cameras.base import CameraSystem
    from molmo_lerobot.dataset_layout import DatasetLayout
    from molmo_lerobot.executor_types import ExecutorType
    from molmo_lerobot.policies.base import PolicyType
    from molmo_lerobot.recording import RecorderFactory
    from molmo_lerobot.robots.base import RobotType
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.sim.scenes import SceneDataset
    from molmo_lerobot.tasks.base import TaskType

PROJECT = "molmo_lerobot"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


class ConfigError(MolmoError, ValueError):
    """A command-line override or config value is invalid; the message says which.

    Raise it from a hook that takes the run config to reject that config in one line.
    """


@hookspec
def molmo_task_types() -> list[TaskType]:
    """Task types this plugin provides.

    Each :class:`~molmo_lerobot.tasks.base.TaskType` has a short ``name`` (``"pick"``) and
    ``aliases`` (e.g. MolmoSpaces' dotted ``task_cls`` paths) so that benchmark files
    written for MolmoSpaces resolve to it unchanged, and its ``spec_model``: the pydantic
    model (a :class:`~molmo_lerobot.benchmark.schema.BaseTaskSpec` subclass) that loading a
    benchmark validates its episodes' ``task`` with, so a new task type brings its own fields.
    """


@hookspec
def molmo_robots() -> list[RobotType]:
    """Robots this plugin provides, keyed by ``name`` and ``aliases`` (episode ``robot.robot_name``)."""


@hookspec
def molmo_camera_systems() -> list[CameraSystem]:
    """Camera systems: how an episode's camera specs become MuJoCo cameras (and their randomization)."""


@hookspec
def molmo_scene_datasets() -> list[SceneDataset]:
    """Scene datasets: what an episode's ``scene_dataset`` + ``house_index`` build with MjSpec."""


@hookspec
def molmo_asset_libraries() -> list[AssetLibraryType]:
    """Asset library types: every run's asset catalog holds the libraries of each.

    An :class:`~molmo_lerobot.assets.catalog.AssetLibraryType` has a ``name`` (``aliases``),
    a lookup ``priority`` and ``make(settings, catalog)``: its libraries for a run, made from
    the run's MolmoSpaces settings (e.g. MolmoSpaces' ``thor`` over its assets dir, or one
    library per ``asset_libraries`` entry of the config).
    """


@hookspec
def molmo_grasp_libraries() -> list[GraspLibraryType]:
    """Grasp library types beyond the grasps an asset library ships with (MolmoSpaces' ``droid``).

    A :class:`~molmo_lerobot.assets.catalog.GraspLibraryType` is an asset library type's
    counterpart; ``make(settings, catalog)`` gives ``(grasp library, asset library name)`` pairs.
    """


@hookspec
def molmo_policies() -> list[PolicyType]:
    """Policies, keyed by ``name`` as used on the command line (``policy=<name>``)."""


@hookspec
def molmo_experts() -> list[PolicyType]:
    """Scripted experts, each a :class:`~molmo_lerobot.policies.base.PolicyType` whose ``name`` is
    the task type it serves (``aliases``: further task types). ``policy=scripted`` plays the
    expert of each episode's task type; task plugins never import their experts.
    """


@hookspec
def molmo_benchmarks() -> list[BenchmarkDir]:
    """Benchmarks this plugin ships, each a :class:`~molmo_lerobot.benchmark.packs.BenchmarkDir`
    (``name`` → directory); :func:`~molmo_lerobot.benchmark.packs.benchmark_pack` lists every
    benchmark directory of a folder. ``molmo-eval benchmark=<name>``, ``molmo-bench validate <name>``
    and the Gymnasium id ``molmo_lerobot/<name>`` (once ``gym_env.register_benchmarks()`` ran) then find them.
    """


@hookspec
def molmo_generators() -> list[BenchmarkGenerator]:
    """Benchmark generators, keyed by ``name`` as used by ``molmo-bench generate <name>``.

    A :class:`~molmo_lerobot.benchmark.generators.BenchmarkGenerator` has a ``description``, the
    ``tasks`` it takes (``--task``; the first is the default) and ``generate(task, n_houses,
    episodes_per_house, seed, name)``: the episodes (JSON-ready, validated before anything is written)
    and the benchmark's metadata, fully determined by the arguments.
    """


@hookspec
def molmo_executors() -> list[ExecutorType]:
    """Executors, keyed by ``name`` as used on the command line (``executor=<name>``).

    An :class:`~molmo_lerobot.executor_types.ExecutorType` has an ``options`` pydantic model (its
    ``executor.<key>`` options and their defaults, checked before a run writes anything; Hydra's
    ``executor/<name>`` config node is made from it) and ``factory(workers, options, timeout_s, retries,
    fork_servers)``: the run's executor (a :class:`~molmo_lerobot.runner.supervisor.Supervisor`).
    """


@hookspec
def molmo_benchmark_kinds() -> list[Any]:
    """Benchmark kinds this plugin provides, each a :class:`~molmo_lerobot.benchmark_kinds.BenchmarkKind` (typed
    ``Any`` here: that module's types name the plugin set, which imports this one). Each claims
    benchmark names (``molmo-eval benchmark=<name>``, ``molmo-bench list``/``validate``) and gives their typed
    options, their episode plan and, in each worker, the session that plays a plan. A run's benchmark is the
    first kind's, in pluggy's call order, that claims its name (as a ``firstresult`` hook: mark yours
    ``tryfirst`` to take a name from another); our episode files are the ``trylast`` kind ``episodes``. LIBERO
    and PushT (:mod:`molmo_lerobot.suites.plugin`) are kinds.
    """


@hookspec
def molmo_config_dirs() -> list[str]:
    """Directories holding Hydra config groups (``policy/<name>.yaml`` …) to add to the search path.

    A third-party policy plugin returns the directory of its own ``policy/<name>.yaml`` so
    that ``molmo-eval policy=<name>`` finds it without touching this repository (a policy with no
    yaml anywhere gets ``{name: <name>}``).
    """


@hookspec
def molmo_recorders(config: RunConfig, dataset_layout: DatasetLayout | None) -> list[RecorderFactory]:
    """Recorder factories (:class:`~molmo_lerobot.recording.RecorderFactory`) for this run.

    Called once in the main process with the run config, validated and frozen
    (:class:`~molmo_lerobot.run_config.RunConfig`: typed sections, defaults filled in; a plugin's own
    top-level key ``+my_key=…`` is ``getattr(config, "my_key", None)``) and the
    :class:`~molmo_lerobot.dataset_layout.DatasetLayout` the run's benchmark kind records in (an env
    suite's published datasets'; None: a dataset's schema follows its first step); return an
    empty list unless the config asks for your recording, and raise :class:`ConfigError` if
    it asks for it wrongly (the run then fails with your message). Each factory is pickled to every
    worker and makes one recorder there that sees every step of the one rollout loop.
    """


@hookspec
def molmo_episode_overrides(episode: EpisodeSpec, config: RunConfig, context: Any) -> EpisodeSpec | None:
    """Edit an episode before it runs (MolmoSpaces' robot eval overrides).

    Called once per episode with the validated spec, the run config (the validated, frozen
    :class:`~molmo_lerobot.run_config.RunConfig`, as :func:`molmo_recorders` gets it) and the run's
    :class:`~molmo_lerobot.context.RunContext` (its asset catalog, settings; take only the
    arguments you need). Return a new
    :class:`EpisodeSpec` (e.g. ``episode.model_copy(update=...)``) to replace it, or
    ``None`` to leave it alone. Implementations run in pluggy's call order and each sees
    the previous one's result. Raise ``ValueError`` when your override cannot apply to this
    episode (that episode is recorded as an error with your message). They must be
    deterministic: the same episode and config always give the same result.
    """
