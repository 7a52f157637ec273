"""A broken third-party plugin is reported, never fatal; asking for it names it and its error."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace
from typing import ClassVar

import pytest
from pydantic import ValidationError

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.benchmark.validate import validate_benchmark
from molmo_lerobot.cli.plugins import format_table
from molmo_lerobot.config import ConfigError
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import ENTRY_POINT_GROUP, BuiltinHookError, PluginConflict, PluginError, Plugins
from molmo_lerobot.robots.base import RobotType
from molmo_lerobot.run_config import RunConfig

DATA = Path(__file__).resolve().parent / "data" / "molmospaces"
#: what episode overrides see of a run with the default config
NO_RUN = SimpleNamespace(config=RunConfig())
#: ``brokenbots``' ``duckbot``: a robot that is not a RobotType
DUCKBOT_ERROR = ("molmo_robots() gave robot 'duckbot' as a types.SimpleNamespace, "
                 "not a molmo_lerobot.robots.base.RobotType (subclass it)")


class Bot(RobotType):
    """A robot's names only (never built)."""

    move_groups: ClassVar[dict[str, int]] = {"arm": 6}

    def __init__(self, name: str, aliases: tuple[str, ...] = ()) -> None:
        self.name, self.aliases = name, aliases

    def spec(self):
        raise NotImplementedError("a test robot has no model")

    def add_to(self, world, base_pose, base_size=None):
        raise NotImplementedError("a test robot has no model")

    def bind(self, model):
        raise NotImplementedError("a test robot has no model")


@pytest.fixture
def broken_dist(tmp_path: Path) -> Path:
    """A distribution ``brokenbots`` with a plugin that fails to import, one whose hook raises, one that works
    and one whose robot is not a RobotType."""
    info = tmp_path / "brokenbots-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: brokenbots\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nur5 = brokenbots_ur5\nkuka = brokenbots_kuka\ngoodbot = brokenbots_good\n"
        "duckbot = brokenbots_duck\n")
    (tmp_path / "brokenbots_ur5.py").write_text('raise RuntimeError("ur5 driver missing")\n')
    (tmp_path / "brokenbots_kuka.py").write_text(textwrap.dedent("""
        from molmo_lerobot import hookspecs

        @hookspecs.hookimpl
        def molmo_robots():
            raise RuntimeError("kuka meshes not found")
    """))
    (tmp_path / "brokenbots_good.py").write_text(textwrap.dedent("""
        from molmo_lerobot import hookspecs
        from molmo_lerobot.robots.base import RobotType

        class GoodBot(RobotType):
            name, aliases, move_groups = "goodbot", ("gb",), {"arm": 6}

            def spec(self):
                raise NotImplementedError

            def add_to(self, world, base_pose, base_size=None):
                raise NotImplementedError

            def bind(self, model):
                raise NotImplementedError

        @hookspecs.hookimpl
        def molmo_robots():
            return [GoodBot()]
    """))
    (tmp_path / "brokenbots_duck.py").write_text(textwrap.dedent("""
        from types import SimpleNamespace
        from molmo_lerobot import hookspecs

        @hookspecs.hookimpl
        def molmo_robots():
            return [SimpleNamespace(name="duckbot", move_groups={"arm": 6})]
    """))
    return tmp_path


def _with_broken(broken_dist: Path, monkeypatch) -> Plugins:
    """The installed plugins plus ``brokenbots``, found on ``sys.path`` like any installed distribution."""
    monkeypatch.syspath_prepend(str(broken_dist))
    plugins = Plugins()
    assert {"ur5", "kuka", "goodbot"} <= {r.name for r in plugins.records}
    return plugins


def test_broken_plugins_are_recorded_and_the_rest_works(broken_dist, monkeypatch):
    plugins = _with_broken(broken_dist, monkeypatch)
    rec = {r.name: r for r in plugins.records}
    assert (rec["ur5"].status, rec["ur5"].error) == ("error", "RuntimeError: ur5 driver missing")
    assert rec["ur5"].distribution == "brokenbots" and rec["ur5"].version == "0.1"
    assert plugins.robot("gb").name == "goodbot"
    assert plugins.robot("franka_droid").name == "franka_droid"  # built-ins unaffected (Robotiq, never the Panda)
    assert rec["kuka"].status == "error"
    assert "molmo_robots() failed: RuntimeError: kuka meshes not found" in rec["kuka"].error


def test_a_plugin_giving_an_item_not_of_its_kinds_base_class_is_broken(broken_dist, monkeypatch):
    plugins = _with_broken(broken_dist, monkeypatch)
    rec = {r.name: r for r in plugins.records}
    assert plugins.broken()  # collects
    assert (rec["duckbot"].status, rec["duckbot"].error) == ("error", DUCKBOT_ERROR)
    assert rec["duckbot"].provides == [] and plugins.robot("goodbot").name == "goodbot"
    with pytest.raises(PluginError) as info:
        plugins.robot("duckbot")
    assert f"plugin 'duckbot' from brokenbots failed to load: {DUCKBOT_ERROR}" in str(info.value)


def test_a_builtin_plugin_giving_an_item_not_of_its_kinds_base_class_raises(monkeypatch):
    import molmo_lerobot.tasks.pick as pick

    @hookimpl
    def molmo_task_types():
        return [SimpleNamespace(name="pick")]

    monkeypatch.setattr(pick, "molmo_task_types", molmo_task_types)
    with pytest.raises(BuiltinHookError) as info:
        Plugins().task_type("pick")
    assert str(info.value) == ("the built-in plugin 'pick' (molmo-lerobot 0.1.0): molmo_task_types() gave task 'pick' "
                               "as a types.SimpleNamespace, not a molmo_lerobot.tasks.base.TaskType (subclass it)")


@pytest.mark.parametrize(
    ("name", "needle"),
    [
        ("ur5", "plugin 'ur5' from brokenbots failed to load: RuntimeError: ur5 driver missing"),
        ("kuka", "plugin 'kuka' from brokenbots failed to load: "
                 "molmo_robots() failed: RuntimeError: kuka meshes not found"),
    ],
)
def test_asking_for_the_broken_plugin_names_it(broken_dist, monkeypatch, name, needle):
    plugins = _with_broken(broken_dist, monkeypatch)
    with pytest.raises(PluginError) as info:
        plugins.robot(name)
    assert str(info.value).startswith(f"unknown robot {name!r}") and needle in str(info.value)


def test_validation_is_unaffected_by_broken_plugins(broken_dist, monkeypatch):
    bench = load_benchmark(DATA / "pick_list", Plugins())
    clean = [str(p) for p in validate_benchmark(bench, Plugins(), RunContext.build())]
    broken = _with_broken(broken_dist, monkeypatch)
    assert [str(p) for p in validate_benchmark(bench, broken, RunContext.build())] == clean == []


def test_validation_names_the_broken_plugin_a_benchmark_needs(broken_dist, monkeypatch, tmp_path):
    import json

    episodes = json.loads((DATA / "pick_list" / "benchmark.json").read_text())
    episodes[0]["robot"]["robot_name"] = "ur5"
    d = tmp_path / "b"
    d.mkdir()
    (d / "benchmark.json").write_text(json.dumps(episodes))
    (problem,) = validate_benchmark(load_benchmark(d, Plugins()), _with_broken(broken_dist, monkeypatch),
                                    RunContext.build())
    assert (problem.episode_index, problem.field) == (0, "robot.robot_name")
    assert problem.message.startswith("no robot plugin provides 'ur5'")
    assert problem.message.endswith("; plugin 'ur5' from brokenbots failed to load: RuntimeError: ur5 driver missing")


def _molmo_plugins(broken_dist: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(broken_dist), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.plugins", *args],
                          capture_output=True, text=True, env=env, timeout=300)


def test_molmo_plugins_lists_broken_plugins_and_exits_0(broken_dist):
    res = _molmo_plugins(broken_dist, "--hooks")
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stdout + res.stderr
    table = res.stdout.split("\n\n")[0].splitlines()
    rows = {line.split()[0]: line for line in table}
    assert rows["ur5"].split()[1:4] == ["-", "brokenbots", "0.1"]
    assert rows["ur5"].endswith("error: RuntimeError: ur5 driver missing")
    assert rows["kuka"].endswith("error: molmo_robots() failed: RuntimeError: kuka meshes not found")
    assert rows["goodbot"].split()[1:5] == ["robot", "brokenbots", "0.1", "ok"]
    assert rows["franka"].split()[1:2] == ["robot"] and rows["franka"].endswith("ok")
    assert "goodbot (brokenbots_good)\n  hooks:    molmo_robots\n  provides: robot:goodbot" in res.stdout
    assert rows["duckbot"].endswith(f"error: {DUCKBOT_ERROR}")
    assert "plugins failed to load" in res.stderr


def test_table_format():
    from molmo_lerobot.plugins import PluginRecord

    table = format_table([PluginRecord("a", "m", "dist", "1.0", kinds=["robot", "task"]),
                          PluginRecord("bb", "n", "d", "2", status="error", error="ImportError: no")])
    assert table.splitlines() == [
        "NAME  KIND        DISTRIBUTION  VERSION  STATUS",
        "a     robot,task  dist          1.0      ok",
        "bb    -           d             2        error: ImportError: no",
    ]
    assert format_table([]).startswith("no plugins installed")



# Dispatch through pluggy -------------------------------------------------------------------
def _bare(*plugins_and_names) -> Plugins:
    plugins = Plugins(entry_points=[])
    for plugin, name in plugins_and_names:
        plugins.add(plugin, name)
    return plugins


def test_specname_implementations_are_used():
    class Bots:
        @hookimpl(specname="molmo_robots")
        def provide_bots(self):
            return [Bot("specbot", aliases=("sb",))]

    plugins = _bare((Bots(), "bots"))
    assert plugins.robot("sb").name == "specbot"
    assert plugins.records[0].kinds == ["robot"] and plugins.records[0].provides == ["robot:specbot"]


def test_hooks_run_in_pluggys_order_with_tryfirst_and_trylast():
    def override(tag, **opts):
        class Override:
            @hookimpl(**opts)
            def molmo_episode_overrides(self, episode, config):
                return [*episode, tag]
        return Override()

    plugins = _bare((override("last", trylast=True), "a"), (override("first", tryfirst=True), "b"),
                    (override("early"), "c"), (override("late"), "d"))
    # pluggy: tryfirst, then the most recently registered first, then trylast
    assert plugins.apply_episode_overrides([], NO_RUN) == ["first", "late", "early", "last"]


def test_a_hook_with_an_unknown_name_or_a_wrapper_marks_the_plugin_broken():
    class Typo:
        @hookimpl
        def molmo_robot(self):
            return []

    class Wrapper:
        @hookimpl(wrapper=True)
        def molmo_robots(self):
            return (yield)

    plugins = _bare((Typo(), "typo"), (Wrapper(), "wrapper"))
    rec = {r.name: r for r in plugins.records}
    assert "unknown hook molmo_robot()" in rec["typo"].error
    assert "hook wrappers are not supported" in rec["wrapper"].error
    assert plugins.names("robot") == []


class _GoodRecorder:
    @hookimpl
    def molmo_recorders(self, config):
        return ["good-factory"]


def test_a_broken_recorder_plugin_is_skipped_and_marked_broken(capsys):
    class Broken:
        @hookimpl
        def molmo_recorders(self, config):
            raise AttributeError("module 'lerobot' has no attribute 'OldApi'")

    class Exits:
        @hookimpl
        def molmo_recorders(self, config):
            raise SystemExit(3)

    plugins = _bare((_GoodRecorder(), "good"), (Broken(), "broken"), (Exits(), "exits"))
    assert plugins.recorder_factories(RunConfig(record=True)) == ["good-factory"]
    rec = {r.name: r for r in plugins.records}
    assert rec["broken"].error == "molmo_recorders() failed: AttributeError: module 'lerobot' has no attribute 'OldApi'"
    assert rec["exits"].error == "molmo_recorders() failed: SystemExit: 3"
    assert rec["good"].status == "ok"
    err = capsys.readouterr().err
    assert "plugin 'broken' ((in-process) -) is broken and was skipped" in err
    assert plugins.recorder_factories(RunConfig()) == ["good-factory"]  # skipped from then on


def test_a_failing_builtin_recorder_fails_the_run_in_one_line(monkeypatch):
    """The project's own recorder is never skipped as a broken plugin: that dropped a run's recording
    silently (exit 0, no dataset/, run.json saying record: true)."""
    from molmo_lerobot.errors import RunError
    from molmo_lerobot.export.recorder import LeRobotRecorderFactory

    def fail(cfg, layout=None):
        raise OSError(errno.ENAMETOOLONG, "File name too long", "/store/" + "x" * 300)

    monkeypatch.setattr(LeRobotRecorderFactory, "from_config", staticmethod(fail))
    plugins = Plugins()
    with pytest.raises(RunError) as err:  # BuiltinHookError: molmo-eval's one line, exit 2
        plugins.recorder_factories(RunConfig(record=True))
    assert str(err.value).startswith("molmo_recorders() of the built-in plugin 'lerobot_export' (molmo-lerobot ")
    assert "failed: OSError: [Errno 36] File name too long" in str(err.value) and "\n" not in str(err.value)
    assert plugins.broken() == [] and len(plugins.recorder_factories(RunConfig())) == 1  # still there: only the glance


def test_a_recorder_rejecting_the_config_fails_the_run_with_its_message():
    class Picky:
        @hookimpl
        def molmo_recorders(self, config):
            raise ValueError("picky.fps must be positive")

    plugins = _bare((_GoodRecorder(), "good"), (Picky(), "picky"))
    with pytest.raises(ConfigError, match=r"picky.fps must be positive"):
        plugins.recorder_factories(RunConfig())
    assert plugins.broken() == []


def test_the_run_config_hooks_get_the_validated_frozen_run_config():
    """``molmo_recorders`` and ``molmo_episode_overrides`` get the run's :class:`RunConfig` itself (typed,
    defaults filled in, a plugin's own top-level key an attribute), not a plain dict of it."""
    seen = {}

    class Both:
        @hookimpl
        def molmo_recorders(self, config):
            seen["recorders"] = config
            return []

        @hookimpl
        def molmo_episode_overrides(self, episode, config):
            seen["overrides"] = config
            return None

    config = RunConfig.of({"policy": {"name": "random"}, "record": True, "my_key": 3})
    plugins = _bare((Both(), "both"))
    plugins.recorder_factories(config)
    plugins.apply_episode_overrides([], SimpleNamespace(config=config))
    assert seen["recorders"] is config and seen["overrides"] is config
    assert config.record and config.policy.name == "random" and config.my_key == 3 and config.horizon is None
    with pytest.raises(ValidationError, match="frozen"):
        config.record = False


def test_a_broken_override_plugin_is_skipped_but_an_inapplicable_override_fails_the_episode(capsys):
    class Tag:
        @hookimpl
        def molmo_episode_overrides(self, episode, config):
            return [*episode, "tag"]

    class Broken:
        @hookimpl
        def molmo_episode_overrides(self, episode, config):
            raise KeyError("camera")

    plugins = _bare((Tag(), "tag"), (Broken(), "broken"))
    assert plugins.apply_episode_overrides([], NO_RUN) == ["tag"]
    assert plugins.apply_episode_overrides(["x"], NO_RUN) == ["x", "tag"]
    assert {r.name: r.status for r in plugins.records} == {"tag": "ok", "broken": "error"}
    assert "plugin 'broken'" in capsys.readouterr().err

    class Inapplicable:
        @hookimpl
        def molmo_episode_overrides(self, episode, config):
            raise ValueError("custom_object: no target object")

    plugins = _bare((Tag(), "tag"), (Inapplicable(), "inapplicable"))
    with pytest.raises(ValueError, match="no target object"):
        plugins.apply_episode_overrides([], NO_RUN)
    assert plugins.broken() == []


# Name clashes ------------------------------------------------------------------------------
IMPOSTOR = textwrap.dedent("""
    import os
    from pathlib import Path

    from molmo_lerobot import hookimpl
    from molmo_lerobot.robots.franka import Franka


    class Impostor(Franka):
        \"\"\"The built-in Franka under the same name; leaves a mark wherever it is built.\"\"\"

        def add_to(self, world, base_pose):
            marker = os.environ.get("IMPOSTOR_MARKER")
            if marker:
                with open(marker, "a") as f:
                    f.write(f"{os.getpid()}\\n")
            super().add_to(world, base_pose)


    @hookimpl
    def molmo_robots():
        return [Impostor()]
""")


def write_dist(root: Path, dist: str, modules: dict[str, str], entry_points: dict[str, str]) -> Path:
    """A distribution ``dist`` (modules + ``*.dist-info`` with ``molmo_lerobot`` entry points) under ``root``."""
    root.mkdir(parents=True, exist_ok=True)
    info = root / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\n" + "".join(f"{k} = {v}\n" for k, v in entry_points.items()))
    for name, text in modules.items():
        (root / f"{name}.py").write_text(text)
    return root


@pytest.fixture
def impostor_dist(tmp_path: Path) -> Path:
    """``impostor-bots``: entry point ``impostor_franka`` providing a robot named ``franka`` (like the built-in)."""
    return write_dist(tmp_path / "impostor", "impostor-bots", {"impostor_bots": IMPOSTOR},
                      {"impostor_franka": "impostor_bots"})


def test_a_clashing_name_fails_naming_both_providers(impostor_dist, monkeypatch):
    monkeypatch.syspath_prepend(str(impostor_dist))
    plugins = Plugins()
    clashes = plugins.clashes()
    assert [r.name for r in clashes[("robot", "franka")]] == ["franka", "impostor_franka"]
    assert ("robot", "franka_panda") in clashes  # the aliases clash too
    for name in ("franka", "franka_panda"):
        with pytest.raises(PluginConflict) as info:
            plugins.robot(name)
        msg = str(info.value)
        assert "\n" not in msg
        assert f"robot {name!r} is provided by plugin 'franka' (molmo-lerobot " in msg
        assert "and plugin 'impostor_franka' (impostor-bots 0.1)" in msg
        assert f"plugins.prefer.robot.{name}=<plugin>" in msg
    assert plugins.policy("random").name == "random"  # names without a clash are unaffected


@pytest.mark.parametrize("pin", ["impostor_franka", "impostor-bots", "impostor-bots:impostor_franka"])
def test_a_pinned_provider_resolves_the_clash(impostor_dist, monkeypatch, pin):
    monkeypatch.syspath_prepend(str(impostor_dist))
    plugins = Plugins()
    plugins.set_preferences({"robot": {"franka": pin}})
    assert type(plugins.robot("franka")).__name__ == "Impostor"
    assert type(plugins.robot("franka_panda")).__name__ == "Impostor"  # pinned by its primary name
    assert type(plugins.resolve("robot", "franka", prefer={"robot": {"franka": "franka"}})).__name__ == "Franka"
    plugins.set_preferences({})
    with pytest.raises(PluginConflict):
        plugins.robot("franka")


@pytest.mark.parametrize(
    ("prefer", "needle"),
    [
        ({"robots": {"franka": "franka"}}, "plugins.prefer.robots: unknown kind"),
        ({"robot": {"frank": "franka"}}, "plugins.prefer.robot.frank: unknown robot 'frank'; did you mean 'franka'"),
        ({"robot": {"franka": "kuka"}}, "plugins.prefer.robot.franka='kuka': no such provider of robot 'franka'"),
    ],
)
def test_bad_pins_are_one_clear_line(impostor_dist, monkeypatch, prefer, needle):
    monkeypatch.syspath_prepend(str(impostor_dist))
    with pytest.raises(PluginError) as info:
        Plugins().set_preferences(prefer)
    assert str(info.value).startswith(needle)


def test_molmo_plugins_lists_the_clash(impostor_dist):
    res = _molmo_plugins(impostor_dist, "--hooks")
    assert res.returncode == 0, res.stderr
    assert "CLASHES" in res.stdout
    line = next(ln for ln in res.stdout.splitlines() if ln.strip().startswith("robot 'franka' (and aliases "))
    assert "franka_panda" in line and len([ln for ln in res.stdout.splitlines() if "impostor_franka' (" in ln]) == 1
    assert "'franka' (molmo-lerobot " in line and "'impostor_franka' (impostor-bots 0.1)" in line
    assert "provides: robot:franka (clash)" in res.stdout


# Plugins that exit at import ---------------------------------------------------------------
@pytest.fixture
def exiting_dist(tmp_path: Path) -> Path:
    """``exitbots``: ``exit7`` calls ``sys.exit(7)`` at import, ``ctrlc`` raises KeyboardInterrupt."""
    return write_dist(tmp_path / "exiting", "exitbots",
                      {"exitbots_exit7": "import sys\nsys.exit(7)\n",
                       "exitbots_ctrlc": "raise KeyboardInterrupt\n"},
                      {"exit7": "exitbots_exit7", "ctrlc": "exitbots_ctrlc"})


def test_a_plugin_exiting_at_import_is_listed_broken(exiting_dist, monkeypatch):
    monkeypatch.syspath_prepend(str(exiting_dist))
    plugins = Plugins()
    rec = {r.name: r for r in plugins.records}
    assert (rec["exit7"].status, rec["exit7"].error) == ("error", "SystemExit: 7")
    assert (rec["ctrlc"].status, rec["ctrlc"].error) == ("error", "KeyboardInterrupt")
    with pytest.raises(PluginError) as info:
        plugins.policy("exit7")
    assert "plugin 'exit7' from exitbots failed to load: SystemExit: 7" in str(info.value)
    assert plugins.policy("random").name == "random"


def test_molmo_plugins_and_molmo_eval_survive_a_plugin_exiting_at_import(exiting_dist, tmp_path):
    res = _molmo_plugins(exiting_dist)
    assert res.returncode == 0, res.stderr
    rows = {line.split()[0]: line for line in res.stdout.splitlines() if line.strip()}
    assert rows["exit7"].endswith("error: SystemExit: 7") and rows["ctrlc"].endswith("error: KeyboardInterrupt")
    env = {**os.environ, "PYTHONPATH": str(exiting_dist), "MUJOCO_GL": "egl"}
    res = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", "policy=exit7",
                          f"output_dir={tmp_path / 'out'}"], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith("molmo-eval: error: unknown policy 'exit7'")
    assert "plugin 'exit7' from exitbots failed to load: SystemExit: 7" in res.stderr
    assert "Traceback" not in res.stderr


def test_molmo_bench_validate_reports_a_clash_in_one_line(impostor_dist):
    from molmo_lerobot.paths import data_path

    env = {**os.environ, "PYTHONPATH": str(impostor_dist)}
    res = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.bench", "validate",
                          str(data_path("benchmarks") / "pick_v1")],
                         capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines() == [
        "molmo-bench: error: robot 'franka' is provided by plugin 'franka' (molmo-lerobot 0.1.0) and plugin "
        "'impostor_franka' (impostor-bots 0.1); choose one with plugins.prefer.robot.franka=<plugin>"]


# A policy plugin that ships no Hydra yaml ---------------------------------------------------------
HOLD_STILL = textwrap.dedent("""
    import json, os
    import numpy as np
    from molmo_lerobot import hookimpl
    from molmo_lerobot.policies.base import Policy, PolicyType

    class HoldStill(Policy):
        needs_images = False

        def __init__(self, config):
            with open(os.environ["HOLD_STILL_CONFIG"], "w") as fh:
                json.dump(dict(config), fh)

        def reset(self, ctx):
            self.groups = dict(ctx.move_groups)

        def act(self, obs):
            return {g: np.asarray(obs["qpos"][g], float)[None] for g in self.groups}

    def make(config):
        return HoldStill(config)

    @hookimpl
    def molmo_policies():
        return [PolicyType(name="hold_still", factory=make)]
""")


def test_a_policy_plugin_without_a_yaml_is_chosen_by_name(tmp_path):
    """Friction: `molmo-plugins` listed such a policy but `policy=<name>` said "unknown policy"."""
    dist = write_dist(tmp_path / "dist", "holdstill", {"holdstill": HOLD_STILL}, {"hold_still": "holdstill"})
    seen = tmp_path / "config.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(dist), os.environ.get("PYTHONPATH", "")]),
           "MUJOCO_GL": "egl", "HOLD_STILL_CONFIG": str(seen)}
    res = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", "policy=hold_still", "+policy.speed=2",
                          "limit=1", "workers=1", "horizon=3", "progress=false", f"output_dir={tmp_path / 'out'}"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "pick_v1 · hold_still: success" in res.stdout
    # its own key as given, the keys every policy shares from PolicyOptions (no model of its own declared)
    assert json.loads(seen.read_text()) == {"name": "hold_still", "speed": 2, "device": None, "serve": False,
                                            "serve_max_batch": None, "serve_batch_timeout_ms": 50,
                                            "serve_transport": "auto"}
