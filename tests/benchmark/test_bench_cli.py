"""``molmo-bench validate`` / ``generate``: a summary, or every problem and exit 1, never a traceback."""

from __future__ import annotations

import json
import subprocess
import sys
import types

import pytest

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.generators import BenchmarkGenerator
from molmo_lerobot.cli import bench
from molmo_lerobot.cli.bench import main
from molmo_lerobot.plugins import Plugins


def test_validate_prints_a_summary(data, capsys):
    assert main(["validate", "--schema-only", str(data / "pick_legacy")]) == 0
    out = capsys.readouterr().out
    assert "pick_legacy" in out and "4 over 2 houses" in out
    assert "tasks      pick (4)" in out and "wrist_camera (4)" in out
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.plugins import Plugins

    assert f"sha256     {load_benchmark(data / 'pick_list', Plugins()).sha256}" in out


def test_validate_reports_every_problem(tmp_path, data, capsys):
    episodes = json.loads((data / "pick_list" / "benchmark.json").read_text())
    episodes[1]["task"]["robot_base_pose"] = [0, 0, 0]
    episodes[2]["robot"].pop("robot_name")
    (tmp_path / "benchmark.json").write_text(json.dumps(episodes))
    assert main(["validate", str(tmp_path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-3:] == [
        f"{tmp_path / 'benchmark.json'}: episode 1: field task.robot_base_pose: expected 7 values, got 3",
        f"{tmp_path / 'benchmark.json'}: episode 2: field robot.robot_name: missing",
        "molmo-bench: 2 problems in 2 episodes",
    ]


def test_validate_subprocess_has_no_traceback(tmp_path):
    (tmp_path / "benchmark.json").write_text('[{"house_index": 3, "task": {"task_cls": "x.y.Z",]')
    res = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.bench", "validate", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "invalid JSON at line 1, column 50" in res.stderr and "Traceback" not in res.stderr


def test_validate_unknown_task_with_installed_plugins(tmp_path, data, capsys):
    episodes = json.loads((data / "pick_list" / "benchmark.json").read_text())
    episodes[0]["task"]["task_cls"] = "x.y.Z"
    (tmp_path / "benchmark.json").write_text(json.dumps(episodes))
    assert main(["validate", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'benchmark.json'}: episode 0: field task.task_cls: unknown task 'x.y.Z'" in err


def _stand_in(name, tasks, calls, episodes):
    """A generator returning the fixture ``episodes`` (the real ones build scenes), recording its calls."""

    def generate(task, n_houses, episodes_per_house, seed, bench):
        calls.append((task, n_houses, episodes_per_house, seed, bench))
        return episodes[: n_houses * episodes_per_house], {"name": bench, "num_episodes": n_houses * episodes_per_house}

    return BenchmarkGenerator(name, f"the {name} stand-in", tasks, generate)


@pytest.fixture
def fake_generator(monkeypatch, data):
    """A stand-in ``content.tabletop.generate`` plugin module whose ``v1`` returns the fixture episodes."""
    episodes = json.loads((data / "pick_list" / "benchmark.json").read_text())
    calls = []

    def write_benchmark(out_dir, eps, metadata):
        (out_dir / "benchmark.json").write_text(json.dumps(eps))
        (out_dir / "benchmark_metadata.json").write_text(json.dumps(metadata))

    module = types.ModuleType("molmo_lerobot.content.tabletop.generate")
    module.molmo_generators = hookimpl(lambda: [_stand_in("v1", ("pick",), calls, episodes)])
    module.write_benchmark = write_benchmark
    monkeypatch.setitem(sys.modules, "molmo_lerobot.content.tabletop.generate", module)
    return types.SimpleNamespace(calls=calls, episodes=episodes)


def test_a_generator_plugin_is_listed_and_run(tmp_path, data, monkeypatch, capsys):
    episodes = json.loads((data / "pick_list" / "benchmark.json").read_text())
    calls = []

    class Tiny:
        @hookimpl
        def molmo_generators(self):
            return [_stand_in("tiny", ("pick", "lift"), calls, episodes)]

    class WithTiny(Plugins):
        def __init__(self):
            super().__init__()
            self.add(Tiny(), "tiny")

    monkeypatch.setattr(bench, "Plugins", WithTiny)
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    assert "tiny: the tiny stand-in (--task pick, lift)" in " ".join(capsys.readouterr().out.split())
    out = tmp_path / "tiny"
    assert main(["generate", "tiny", "--houses", "1", "--episodes-per-house", "2", "--seed", "5", "--name", "tiny",
                 "--out", str(out)]) == 0
    assert calls == [("pick", 1, 2, 5, "tiny")]
    assert json.loads((out / "benchmark.json").read_text()) == episodes[:2]
    assert main(["generate", "tiyn", "--houses", "1", "--episodes-per-house", "1", "--name", "x",
                 "--out", str(tmp_path / "x")]) == 2
    assert "unknown generator 'tiyn'; did you mean 'tiny'?" in capsys.readouterr().err


def test_generate_writes_and_summarizes(tmp_path, fake_generator, capsys):
    out = tmp_path / "pick_small"
    args = ["generate", "--task", "pick", "--houses", "2", "--episodes-per-house", "2", "--seed", "3",
            "--name", "pick_small", "--out", str(out)]
    assert main(args) == 0
    assert fake_generator.calls == [("pick", 2, 2, 3, "pick_small")]
    assert "benchmark  pick_small" in capsys.readouterr().out
    assert json.loads((out / "benchmark.json").read_text()) == fake_generator.episodes[:4]
    assert main(args) == 2 and "exists (use --force" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pick_small"]  # no temporary directories left


def test_generate_never_leaves_partial_output(tmp_path, fake_generator, capsys):
    fake_generator.episodes[1]["task"]["robot_base_pose"] = [0.0]
    out = tmp_path / "broken"
    assert main(["generate", "--houses", "1", "--episodes-per-house", "2", "--name", "broken", "--out", str(out)]) == 1
    assert "<generated>: episode 1: field task.robot_base_pose: expected 7 values, got 1" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    assert main(["generate", "--task", "stack", "--houses", "1", "--episodes-per-house", "1", "--name", "x",
                 "--out", str(out)]) == 2
    assert "generator 'v1' makes 'pick' episodes only, not --task 'stack'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_generate_with_the_real_generator_is_deterministic(tmp_path, capsys):
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.benchmark.validate import validate_benchmark
    from molmo_lerobot.context import RunContext

    ctx = RunContext.build()

    def run(name, seed):
        args = ["generate", "--task", "pick", "--houses", "2", "--episodes-per-house", "2", "--seed", str(seed),
                "--name", "tiny", "--out", str(tmp_path / name)]
        assert main(args) == 0, capsys.readouterr().err
        return load_benchmark(tmp_path / name, ctx.plugins)

    a, b, c = run("a", 0), run("b", 0), run("c", 1)
    assert a.sha256 == b.sha256 != c.sha256
    assert a.name == "tiny" and len(a) == 4 and len({ep.house_index for ep in a.episodes}) == 2
    assert validate_benchmark(a, ctx.plugins, ctx) == []


def test_validate_finds_what_molmo_eval_finds_from_any_directory(data, tmp_path, monkeypatch, capsys):
    """A shipped name (as ``molmo-eval benchmark=pick_v2``) and a path relative to the current directory."""
    monkeypatch.chdir(tmp_path)  # not the repository root
    assert main(["validate", "--schema-only", "pick_v2"]) == 0
    assert "benchmark  pick_v2" in capsys.readouterr().out
    (tmp_path / "mine").symlink_to(data / "pick_legacy")
    assert main(["validate", "--schema-only", "mine"]) == 0
    assert main(["validate", "--schema-only", "no_such_benchmark"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("molmo-bench: error: unknown benchmark 'no_such_benchmark': neither a "
                                               "path nor a registered benchmark (close_v1, ")


def test_validate_exits_as_molmo_eval_does_on_an_invalid_benchmark(tmp_path):
    """molmo-eval refuses an invalid benchmark with exit 2 before any run directory: so does validate."""
    from eval_runs import refusal

    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "benchmark.json").write_text("[]")
    assert refusal(f"benchmark.path={tmp_path / 'bad'}", f"output_dir={tmp_path / 'run'}", "workers=1")
    assert main(["validate", "--schema-only", str(tmp_path / "bad")]) == 2
    assert not (tmp_path / "run").exists()
