"""molmo-compare: exact McNemar test, Newcombe paired CI, pairing and refusal rules."""

from __future__ import annotations

import itertools
import json
import math

import pytest

from molmo_lerobot.cli.compare import main
from molmo_lerobot.results import EpisodeResult, summarize
from molmo_lerobot.runner.compare import (
    CompareError,
    compare_runs,
    load_run,
    mcnemar_exact,
    paired_diff_ci,
    paired_stats,
)

SHA = "ab" * 32


def _write_run(path, outcomes, sha=SHA, policy="p", seed=0, task=lambda i: "pick", errors=(), header=None,
               horizon=lambda i: 10, task_cls="x.Pick"):
    """A finished run directory with ``outcomes[i] = (success, success_once)`` per episode index."""
    path.mkdir(parents=True)
    rows = [{"episode_index": i, "house_index": i // 2, "task_cls": task_cls, "success": s, "success_once": o,
             "steps": 10, "seed": 1000 * seed + i, "error": "RuntimeError: boom" if i in errors else None,
             "task_type": task(i), "horizon": horizon(i)} for i, (s, o) in outcomes.items()]
    (path / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    summary = summarize([EpisodeResult.from_dict(r) for r in rows],
                        benchmark={"name": "b", "sha256": sha, "n_episodes": 99}, policy={"name": policy}, seed=seed,
                        **(header or {}))
    (path / "results.json").write_text(summary.to_json())
    return path


def test_mcnemar_exact_reference_values():
    assert mcnemar_exact(1, 7) == 2 * (1 + 8) / 2**8  # Bentur et al. 2009 table: p = 0.0703
    assert math.isclose(mcnemar_exact(6, 16), 0.052479, abs_tol=1e-6)  # Cavo et al. 2012 table
    assert mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(5, 5) == 1.0
    assert mcnemar_exact(3, 9) == mcnemar_exact(9, 3)
    assert mcnemar_exact(0, 30) == 2 / 2**30


def test_newcombe_paired_ci_reference_value():
    # Cavo et al. 2012 (Fagerland, Lydersen & Laake 2014): A-B = -0.0621, 95% CI -0.1186 to -0.0046;
    # we report B-A, so the interval flips sign.
    lo, hi = paired_diff_ci(59, 6, 16, 80)
    assert math.isclose(lo, 0.0046, abs_tol=5e-5) and math.isclose(hi, 0.1186, abs_tol=5e-5)


def test_newcombe_ci_contains_estimate_and_stays_in_range_for_all_small_tables():
    for cells in itertools.product(range(4), repeat=4):
        if sum(cells) == 0:
            continue
        _both, only_a, only_b, _neither = cells
        n = sum(cells)
        lo, hi = paired_diff_ci(*cells)
        diff = (only_b - only_a) / n
        assert -1.0 <= lo < hi <= 1.0 and lo <= diff <= hi, cells


def test_paired_stats_table():
    s = paired_stats([(True, True), (True, False), (False, True), (False, True), (False, False)])
    assert (s.n, s.both, s.only_a, s.only_b, s.neither) == (5, 1, 1, 2, 1)
    assert s.rate_a == pytest.approx(0.4) and s.rate_b == pytest.approx(0.6) and s.diff == pytest.approx(0.2)
    assert s.p_value == 1.0


def test_compare_pairs_shared_episodes_with_per_task_table(tmp_path):
    a = _write_run(tmp_path / "a", {i: (i < 8, i < 9) for i in range(12)}, policy="expert",
                   task=lambda i: "pick" if i < 6 else "open", errors={7})
    b = _write_run(tmp_path / "b", {i: (i < 2, i < 2) for i in range(2, 14)}, policy="rand",
                   task=lambda i: "pick" if i < 6 else "open")
    rep = compare_runs(load_run(a), load_run(b))
    assert rep["n_shared"] == 10 and rep["only_in"] == {"a": [0, 1], "b": [12, 13]}
    o = rep["overall"]
    # shared 2..11: A succeeds on 2..6 (7 is an error: a failure), B on none
    assert (o["both"], o["only_a"], o["only_b"], o["neither"]) == (0, 5, 0, 5)
    assert o["diff"] == pytest.approx(-0.5) and o["p_value"] == pytest.approx(2 / 32)
    assert rep["per_task"]["pick"]["n"] == 4 and rep["per_task"]["open"]["n"] == 6
    assert rep["per_task"]["open"]["only_a"] == 1  # episode 6
    assert rep["runs"]["a"]["n_errors"] == 1
    assert any("only in A" in n for n in rep["notes"])
    once = compare_runs(load_run(a), load_run(b), metric="success_once")
    assert once["overall"]["only_a"] == 6  # episode 8 succeeded at some step; 7 is still an error


def test_compare_refuses_different_benchmarks_and_unfinished_runs(tmp_path):
    a = _write_run(tmp_path / "a", {0: (True, True)})
    b = _write_run(tmp_path / "b", {0: (True, True)}, sha="cd" * 32)
    with pytest.raises(CompareError, match=r"refusing to compare.*sha256 abababababab.*sha256 cdcdcdcdcdcd"):
        compare_runs(load_run(a), load_run(b))
    (b / "results.json").unlink()
    with pytest.raises(CompareError, match=r"no results.json.*resume=true"):
        load_run(b)
    c = _write_run(tmp_path / "c", {5: (True, True)})
    with pytest.raises(CompareError, match="share no episodes"):
        compare_runs(load_run(a), load_run(c))
    record = json.loads((c / "episodes.jsonl").read_text())
    (c / "episodes.jsonl").write_text(json.dumps({k: v for k, v in record.items() if k != "success_once"}) + "\n")
    with pytest.raises(CompareError, match=r"episodes.jsonl:1: corrupt episode record \(field 'success_once' is "
                                           r"missing\)$"):
        load_run(c)


def test_cli_text_and_json(tmp_path, capsys):
    a = _write_run(tmp_path / "a", {i: (i % 2 == 0, True) for i in range(6)}, seed=0)
    b = _write_run(tmp_path / "b", {i: (True, True) for i in range(6)}, seed=1)
    assert main([str(a), str(b)]) == 0
    text = capsys.readouterr().out
    assert "B - A: +0.500" in text and "McNemar exact" in text and "pick" in text
    assert "different episode seeds" in text
    assert main([str(a), str(b), "--json", "--metric", "success_once"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["metric"] == "success_once" and rep["overall"]["diff"] == 0.0
    other = json.loads((b / "results.json").read_text())
    (b / "results.json").write_text(json.dumps({**other, "benchmark": {"name": "b", "sha256": "ef" * 32}}))
    assert main([str(a), str(b)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("molmo-compare: error: refusing to compare") and err.count("\n") == 1


TRIAL = {"timing": {"policy_dt_ms": 66.0, "ctrl_dt_ms": 2.0, "sim_dt_ms": 2.0}, "horizon": None,
         "render_profile": {"name": "v2", "shadows": None, "exposure": 1.0, "overrides": {}},
         "eval_options": {"horizons": {}, "custom_object": {"path": None}, "camera": {"randomization": 0}},
         "thresholds": {"pick": {"succ_pos_threshold": 0.01, "horizon_steps": [303]}},
         "versions": {"molmo-lerobot": "0.1.0", "mujoco": "3.3.0"},
         "config": {"workers": 2, "episode_timeout_s": 900, "output_dir": "x"}}


def _changed(path: str, value):
    """A copy of TRIAL with the dotted ``path`` set to ``value``."""
    header = json.loads(json.dumps(TRIAL))
    *parents, last = path.split(".")
    node = header
    for key in parents:
        node = node[key]
    node[last] = value
    return header


@pytest.mark.parametrize(
    ("path", "value", "needle"),
    [
        ("timing.sim_dt_ms", 1.0, "timing.sim_dt_ms 2.0 vs 1.0"),
        ("horizon", 50, "horizon null vs 50"),
        ("eval_options.horizons", {"pick": 5}, "eval_options.horizons.pick (unset) vs 5"),
        ("eval_options.camera.randomization", 2, "eval_options.camera.randomization 0 vs 2"),
        # the key and both values are named, however long the options are
        ("eval_options.custom_object.path", "/data/objects/" + "x" * 90 + ".xml",
         f'eval_options.custom_object.path null vs "/data/objects/{"x" * 90}.xml"'),
        ("thresholds.pick.succ_pos_threshold", 0.05, "thresholds.pick.succ_pos_threshold 0.01 vs 0.05"),
        # issue 36: the look is part of the trial (a profile, or an environment override of it)
        ("render_profile.name", "v3", 'render_profile.name "v2" vs "v3"'),
        ("render_profile.overrides.MOLMO_SCENE_SHADOWS", "0",
         "render_profile.overrides.MOLMO_SCENE_SHADOWS (unset) vs"),
    ],
)
def test_compare_refuses_runs_of_different_trials(tmp_path, path, value, needle):
    """Issue 11.10: runs with different horizons, timing or eval options were paired without a word."""
    a = _write_run(tmp_path / "a", {i: (True, True) for i in range(4)}, header=TRIAL)
    b = _write_run(tmp_path / "b", {i: (False, True) for i in range(4)}, header=_changed(path, value))
    with pytest.raises(CompareError, match=r"refusing to compare.*ran different trials") as info:
        compare_runs(load_run(a), load_run(b))
    assert needle in str(info.value) and "--allow-different-trials" in str(info.value)
    rep = compare_runs(load_run(a), load_run(b), allow_different_trials=True)
    assert any("ran different trials (compared anyway)" in n and needle in n for n in rep["notes"])


def test_compare_refuses_different_per_episode_horizons_and_flags_the_rest(tmp_path, capsys):
    a = _write_run(tmp_path / "a", {i: (True, True) for i in range(4)}, header=TRIAL)
    b = _write_run(tmp_path / "b", {i: (True, True) for i in range(4)}, header=TRIAL, horizon=lambda i: 10 + (i == 2))
    with pytest.raises(CompareError, match=r"horizon of 1 shared episodes \(episode 2: 10 vs 11 steps\)"):
        compare_runs(load_run(a), load_run(b))
    assert main([str(a), str(b)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert main([str(a), str(b), "--allow-different-trials"]) == 0
    assert "note: the runs ran different trials (compared anyway): horizon of 1" in capsys.readouterr().out
    # flagged, not refused: versions and config keys that are not part of the trial's definition
    c = _write_run(tmp_path / "c", {i: (True, True) for i in range(4)},
                   header={**_changed("versions.mujoco", "3.4.0"),
                           "config": {"workers": 8, "episode_timeout_s": 5, "output_dir": "y"}})
    notes = compare_runs(load_run(a), load_run(c))["notes"]
    assert "versions differ: mujoco 3.3.0 vs 3.4.0" in notes
    assert "config differs: episode_timeout_s 900 vs 5" in notes  # workers and output_dir do not matter
    # a run that does not record a trial field cannot be checked on it: say so
    d = _write_run(tmp_path / "d", {i: (True, True) for i in range(4)})
    notes = compare_runs(load_run(a), load_run(d))["notes"]
    assert any("not checked: timing, horizon, eval_options" in n for n in notes)


def test_errored_episodes_without_a_task_type_stay_in_their_task(tmp_path):
    """Issue 11.2: errored records (task_type null) were a separate "task" named by their task_cls."""
    cls = "molmo_lerobot.tasks.pick.PickTask"
    a = _write_run(tmp_path / "a", {i: (i < 4, i < 4) for i in range(8)}, task_cls=cls, errors={6, 7},
                   task=lambda i: None if i >= 6 else "pick")
    b = _write_run(tmp_path / "b", {i: (True, True) for i in range(8)}, task_cls=cls,
                   task=lambda i: None if i >= 6 else "pick")  # older records: resolved from task_cls
    rep = compare_runs(load_run(a), load_run(b))
    assert list(rep["per_task"]) == ["pick"] and rep["per_task"]["pick"]["n"] == 8
    assert rep["per_task"]["pick"]["rate_a"] == 0.5


@pytest.mark.slow
def test_compare_two_real_runs(small_bench, tmp_path, eval_config, capsys):
    run_evaluation = pytest.importorskip("molmo_lerobot.runner.evaluate").run_evaluation
    run_evaluation(eval_config(small_bench, tmp_path / "random", "policy=random", "workers=2"))  # same trial
    run_evaluation(eval_config(small_bench, tmp_path / "scripted", "policy=scripted", "workers=2"))
    assert main([str(tmp_path / "random"), str(tmp_path / "scripted"), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["n_shared"] == 8 and rep["overall"]["diff"] > 0.5
    assert rep["overall"]["p_value"] < 0.05 and rep["overall"]["ci95"][0] > 0


def test_deeply_nested_run_files_are_one_line(tmp_path, capsys):
    a = _write_run(tmp_path / "a", {0: (True, True)})
    b = _write_run(tmp_path / "b", {0: (True, True)})
    (b / "results.json").write_text("[" * 100_000 + "]" * 100_000)
    assert main([str(a), str(b)]) == 2
    assert capsys.readouterr().err == f"molmo-compare: error: {b / 'results.json'}: JSON nested too deeply\n"


@pytest.mark.parametrize(("path", "value"), [("timing", {**TRIAL["timing"], "control": "hold"}), ("mujoco", "3.5.0")])
def test_control_mode_and_mujoco_version_are_part_of_the_trial(tmp_path, path, value):
    """timing.control (hold | ramp) and the MuJoCo version change the dynamics: never paired silently."""
    a = _write_run(tmp_path / "a", {i: (True, True) for i in range(4)}, header={**TRIAL, "mujoco": "4.0.0"})
    b = _write_run(tmp_path / "b", {i: (True, True) for i in range(4)},
                   header={**TRIAL, "mujoco": "4.0.0", path: value})
    with pytest.raises(CompareError, match="ran different trials") as info:
        compare_runs(load_run(a), load_run(b))
    assert path in str(info.value)


def test_compare_refuses_runs_of_different_robots_naming_both(tmp_path):
    droid = {"name": "franka_droid", "version": "molmo-lerobot 0.1.0", "sha256": "1" * 64}
    fr3 = {"name": "franka_droid_fr3", "version": "molmo-lerobot 0.1.0", "sha256": "2" * 64}
    a = _write_run(tmp_path / "a", {0: (True, True)}, header={"robots": [droid]})
    b = _write_run(tmp_path / "b", {0: (False, False)}, sha="cd" * 32, header={"robots": [fr3]})
    with pytest.raises(CompareError) as refused:
        compare_runs(load_run(a), load_run(b))
    assert str(refused.value) == (f"refusing to compare: {a} ran robot franka_droid (sha256 111111111111…) but {b} ran "
                                  "robot franka_droid_fr3 (sha256 222222222222…); a paired comparison needs the same "
                                  "robot")
    # the same robot's model built otherwise (MolmoSpaces' own model installed) is another robot too
    c = _write_run(tmp_path / "c", {0: (False, False)}, header={"robots": [{**droid, "sha256": "3" * 64}]})
    with pytest.raises(CompareError, match=r"ran robot franka_droid \(sha256 333333333333…\)"):
        compare_runs(load_run(a), load_run(c))
    d = _write_run(tmp_path / "d", {0: (False, False)}, header={"robots": [{**droid, "version": "x 2"}]})
    assert compare_runs(load_run(a), load_run(d))["n_shared"] == 1  # same model, other release: comparable


def test_compare_names_the_options_that_made_the_episodes_differ(tmp_path):
    config = {"benchmark": {"name": "libero_object", "suite": "libero", "image_size": 64}, "seed": 0, "horizon": 300}
    a = _write_run(tmp_path / "a", {0: (True, True)}, header={"config": config})
    b = _write_run(tmp_path / "b", {0: (True, True)}, sha="cd" * 32, header={"config": {**config, "horizon": 200}})
    with pytest.raises(CompareError) as refused:
        compare_runs(load_run(a), load_run(b))
    assert str(refused.value) == (f"refusing to compare: {a} and {b} evaluated different episodes of 'b': horizon 300 "
                                  f"vs 200 (benchmark sha256 {'ab' * 6}… vs {'cd' * 6}…); a paired comparison needs "
                                  "the same episodes")


@pytest.mark.slow
def test_a_benchmark_run_with_another_robot_names_it_and_is_not_compared(tmp_path):
    """``robot.name=franka_droid_fr3`` plays pick_v2's franka_droid episodes with the FR3 arm (MolmoSpaces'
    robot_config switch); results.json names each robot, and molmo-compare refuses the pair naming both."""
    from eval_runs import evaluate

    common = ["benchmark=pick_v2", "policy=random", "workers=1", "horizon=2", "limit=1", "progress=false"]
    droid = evaluate(*common, f"output_dir={tmp_path / 'droid'}")
    fr3 = evaluate(*common, "robot.name=franka_droid_fr3", f"output_dir={tmp_path / 'fr3'}")
    assert [r["name"] for r in droid.summary["robots"]] == ["franka_droid"] and fr3.episodes[0].error is None
    assert [r["name"] for r in fr3.summary["per_task"]["pick"]["robots"]] == ["franka_droid_fr3"]
    assert droid.summary["benchmark"]["sha256"] == fr3.summary["benchmark"]["sha256"]  # the same episodes
    with pytest.raises(CompareError, match=r"ran robot franka_droid \(sha256 \w{12}…\) but .* ran robot "
                                           r"franka_droid_fr3 \(sha256 \w{12}…\); a paired comparison needs the same"):
        compare_runs(load_run(tmp_path / "droid"), load_run(tmp_path / "fr3"))
