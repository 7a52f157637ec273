"""What a resume keeps: the recorded limit, the recording options, the code, the robots, one record per episode;
and what does not block a fresh run (a directory whose run finished no episode)."""

from __future__ import annotations

import json
from importlib import metadata

import pytest

from molmo_lerobot.errors import RunError
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.results import RunFileError, read_episodes
from molmo_lerobot.runner.evaluate import run_evaluation


def _common(faulty_policy) -> list[str]:
    return ["policy=faulty", "workers=1", "horizon=2", f"policy.marker_dir={faulty_policy.marker_dir}"]


def test_resume_without_a_limit_keeps_the_recorded_one_and_says_so(faulty_policy, small_bench, tmp_path, eval_config,
                                                                   capsys, fork_servers):
    out = tmp_path / "run"
    run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "limit=1"), fork_servers)
    (out / "results.json").unlink()  # killed before scoring
    capsys.readouterr()
    resumed = run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "resume=true"), fork_servers)
    assert resumed.summary["n_episodes"] == 1 and json.loads((out / "run.json").read_text())["limit"] == 1
    assert (f"molmo-eval: resume {out}: 1 of 1 episodes recorded stand, running the other 0 (limit=1 as recorded, "
            "of 8 in the benchmark)") in capsys.readouterr().err


def test_resume_refuses_other_code_naming_the_key(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    out = tmp_path / "run"
    run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "limit=1"), fork_servers)
    run = json.loads((out / "run.json").read_text())
    assert run["code"]["version"] and run["code"]["commit"]  # this checkout is a git repository
    run["code"]["commit"] = "0" * 40
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(RunError, match=r"its code differs from this run's \(code.commit: \"0000") as exc:
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "resume=true"), fork_servers)
    assert len(str(exc.value).splitlines()) == 1
    with pytest.raises(RunError, match=r": policy.act_sleep_s differs from the run's \(0.0 in run.json, 0.5 given\)"):
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "resume=true", "policy.act_sleep_s=0.5"),
                       fork_servers)


def test_the_robot_that_ran_is_recorded_and_a_resume_with_another_is_refused(faulty_policy, small_bench, tmp_path,
                                                                             eval_config, fork_servers):
    out = tmp_path / "run"
    res = run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "limit=1"), fork_servers)
    robot = {"name": "franka", "version": f"molmo-lerobot {metadata.version('molmo-lerobot')}",
             "sha256": Plugins().robot("franka").model_sha256()}
    run = json.loads((out / "run.json").read_text())
    assert run["robots"] == res.summary["robots"] == [robot]
    assert [row["robots"] for row in res.summary["per_task"].values()] == [[robot]]
    assert res.episodes[0].extra["robot"] == "franka"
    (out / "results.json").unlink()
    run["robots"] = [{**robot, "sha256": "0" * 64}]  # the run had another model of the robot
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(RunError) as refused:
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "resume=true"), fork_servers)
    assert str(refused.value) == (f"cannot resume {out}: it ran robot franka (sha256 000000000000…), this run would "
                                  f"run robot franka (sha256 {robot['sha256'][:12]}…); finish it with its robots, or "
                                  "start a new output_dir")


def test_a_run_directory_that_finished_no_episode_does_not_block_a_fresh_run(faulty_policy, small_bench, tmp_path,
                                                                             eval_config, capsys, fork_servers):
    out = tmp_path / "run"
    run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "limit=1"), fork_servers)
    (out / "results.json").unlink()  # as a run that died before its first episode finished leaves it
    (out / "episodes.jsonl").write_text("")
    capsys.readouterr()
    res = run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "limit=2", "seed=5"), fork_servers)
    assert res.summary["n_episodes"] == 2 and json.loads((out / "run.json").read_text())["seed"] == 5
    assert f"molmo-eval: output_dir {out} holds a run that finished no episode; this run replaces it" in (
        capsys.readouterr().err)
    (out / "results.json").unlink()  # two episodes finished: kept, so a fresh run is refused
    with pytest.raises(RunError, match="already holds a run; pass resume=true"):
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy), "limit=2"), fork_servers)


@pytest.mark.slow
def test_a_recorded_run_resumes_only_with_its_recording_options(faulty_policy, small_bench, tmp_path, eval_config):
    out = tmp_path / "run"
    common = [*_common(faulty_policy), "record=true", "video.vcodec=h264"]
    run_evaluation(eval_config(small_bench, out, *common, "limit=1"))
    for change, line in [
        (["video.vcodec=libsvtav1"], f"cannot resume {out}: its recording option video.vcodec differs from this "
                                     'run\'s ("h264" vs "libsvtav1"); one dataset has one set of recording options: '
                                     "resume with video.vcodec=h264, or start a new output_dir"),
        (["record_environment_state=true"], "its recording option record_environment_state differs"),
        (["record_min_frames=0"], "its recording option record_min_frames differs"),
        (["record=false"], "with record=false: it was started with record=true and its dataset/ would lack"),
    ]:
        args = [*common, "limit=2", "resume=true", *change]
        with pytest.raises(RunError) as exc:
            run_evaluation(eval_config(small_bench, out, *args))
        assert line in str(exc.value) and len(str(exc.value).splitlines()) == 1
    assert (out / "results.json").exists(), "a refused resume leaves the finished run alone"
    assert run_evaluation(eval_config(small_bench, out, *common, "limit=2", "resume=true")).summary["n_episodes"] == 2


def test_a_duplicated_episode_record_is_refused_naming_the_line(tmp_path):
    record = {"episode_index": 3, "house_index": 1, "task_cls": "pick", "success": False, "success_once": False,
              "steps": 2, "seed": 5, "error": None}
    other = {**record, "episode_index": 4}
    path = tmp_path / "episodes.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in (record, other, {**record, "success": True})))
    with pytest.raises(RunFileError, match=rf"^{path}:3: episode 3 is recorded twice \(also line 1\)$"):
        read_episodes(path)
