"""Body sleeping by default as the benchmark's scene datasets say (issue 37): MolmoSpaces' files
(their scene datasets, user scenes in their format) run with it on as their rollouts do, ours with
it off; ``timing.sleep=true|false`` overrides; ``run.json`` records the value the run used."""

from __future__ import annotations

import json

import mujoco
import pytest
from standin import pick_episode
from user_library import user_pick_episode, write_user_library

from eval_runs import refusal
from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.benchmark.registry import benchmark_dir, benchmark_names
from molmo_lerobot.config import compose
from molmo_lerobot.context import RunContext
from molmo_lerobot.errors import RunError
from molmo_lerobot.run_config import RunConfigError
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.sim.env import sleep_supported

SLEEP = int(getattr(mujoco.mjtEnableBit, "mjENBL_SLEEP", 0))


def _bench(path, episodes):
    path.mkdir(parents=True, exist_ok=True)
    (path / "benchmark.json").write_text(json.dumps(episodes))
    return path


def _ithor(houses):
    return next(h for h in houses if h.dataset == "ithor")


def _run(bench, out, *extra):
    return run_evaluation(compose(["policy=scripted", "workers=1", "horizon=2", f"benchmark.path={bench}",
                                   f"output_dir={out}", "progress=false", *extra]))


def _recorded_sleep(out):
    run, results = (json.loads((out / name).read_text()) for name in ("run.json", "results.json"))
    assert run["timing"] == results["timing"]
    assert results["config"]["timing"]["sleep"] is run["timing"]["sleep"]  # the config as it ran
    return run["timing"]["sleep"]


def test_molmospaces_files_sleep_by_default_and_record_it(assets, tmp_path):
    """Their file runs as their rollouts do (sleep on) with no option given (before issue 37 item 2
    the default was off everywhere); the recorded value is part of the trial."""
    bench, out = _bench(tmp_path / "b", [pick_episode(_ithor(assets[1]))]), tmp_path / "run"
    res = _run(bench, out)
    assert res.summary["n_errors"] == 0, [e.error for e in res.episodes]
    assert _recorded_sleep(out) is True
    # the run's option was null (its scenes decided: true); a resume that gives another is refused naming it
    with pytest.raises(RunError, match=r"timing.sleep differs from the run's \(null in run.json, false given\)"):
        _run(bench, out, "resume=true", "timing.sleep=false")


def test_ours_record_false_and_a_run_recorded_so_before_resumes(tmp_path):
    """Our scenes keep sleep off; run.json says false, as every run before this change recorded, so
    such a run resumes (a null would be refused as other timing)."""
    from molmo_lerobot.benchmark.output import write_benchmark
    from molmo_lerobot.content.tabletop.generate import generate_benchmark

    bench = write_benchmark(tmp_path / "ours", *generate_benchmark("pick", 1, 1, seed=3, name="ours"))
    out = tmp_path / "run"
    _run(bench, out, "limit=1")
    before = {"policy_dt_ms": 66.0, "ctrl_dt_ms": 2.0, "sim_dt_ms": 2.0, "control": "hold", "sleep": False}
    assert json.loads((out / "run.json").read_text())["timing"] == before  # what the old default wrote
    assert _run(bench, out, "resume=true").summary["n_episodes"] == 1
    with pytest.raises(RunError, match=r"timing.sleep differs from the run's \(null in run.json, true given\)"):
        _run(bench, out, "resume=true", "timing.sleep=true")


def test_every_published_benchmark_keeps_sleep_off(run):
    """Their recorded trials stay as they are: no shipped benchmark's scenes sleep."""
    names = [n for n in benchmark_names(run.plugins) if (benchmark_dir(n, run.plugins) / "benchmark.json").exists()]
    assert len(names) >= 20
    for name in names:
        bench = load_benchmark(benchmark_dir(name, run.plugins), run.plugins)
        assert run.for_benchmark(bench).config.timing.sleep is False, name


def test_user_scenes_in_their_format_sleep_and_an_explicit_value_wins(assets, tmp_path):
    write_user_library(tmp_path)
    bench = _bench(tmp_path / "b", [user_pick_episode()])
    for given, decided in ((None, True), (False, False), (True, True)):
        ctx = RunContext.build({"scene_xml_paths": [str(tmp_path / "scene.xml")], "timing": {"sleep": given}})
        ctx = ctx.for_benchmark(load_benchmark(bench, ctx.plugins))
        assert ctx.config.timing.sleep is decided and ctx.timing.sleep is decided


def test_a_benchmark_mixing_sleeping_and_awake_scenes_needs_timing_sleep(assets, tmp_path):
    ours = json.loads((benchmark_dir("pick_v1", RunContext.build().plugins) / "benchmark.json").read_text())[0]
    bench = _bench(tmp_path / "mixed", [pick_episode(_ithor(assets[1])), ours])
    [line] = refusal("policy=scripted", f"benchmark.path={bench}", f"output_dir={tmp_path / 'out'}")
    assert line == (f"timing.sleep: benchmark {bench} mixes scene datasets whose episodes sleep (ithor) with ones "
                    "whose episodes do not (procedural_tabletop); set timing.sleep=true or timing.sleep=false")
    assert not (tmp_path / "out").exists()
    ctx = RunContext.build()
    with pytest.raises(RunConfigError):
        ctx.for_benchmark(load_benchmark(bench, ctx.plugins))
    for given in (True, False):
        ctx = RunContext.build({"timing": {"sleep": given}})
        assert ctx.for_benchmark(load_benchmark(bench, ctx.plugins)).timing.sleep is given


@pytest.mark.skipif(not sleep_supported(), reason="this MuJoCo has no body sleeping (mjENBL_SLEEP)")
def test_the_gymnasium_env_steps_their_files_with_sleep_on(assets, tmp_path):
    """The Gymnasium env (and lerobot-eval through it) decides as molmo-eval does, and its
    simulation gets the decided value."""
    from molmo_lerobot.gym_env import MolmoEnv

    bench = str(_bench(tmp_path / "b", [pick_episode(_ithor(assets[1]))]))
    for timing, on in ((None, True), ({"sleep": False}, False)):
        env = MolmoEnv(bench, timing=timing)
        try:
            assert bool(env._current.env.model.opt.enableflags & SLEEP) is on
        finally:
            env.close()


def test_a_context_nothing_decided_uses_each_episodes_scene_dataset():
    """A session opened from a context no benchmark decided (a script, a hand-built worker job) sleeps as its
    episode's scene dataset says; a given value wins."""
    undecided = RunContext.build()
    assert undecided.timing_for("ithor").sleep is True
    assert undecided.timing_for("procedural_tabletop").sleep is False
    assert RunContext.build({"timing": {"sleep": False}}).timing_for("ithor").sleep is False
    assert RunContext.build({"timing": {"sleep": True}}).timing_for("procedural_tabletop").sleep is True
