"""molmo-eval fails fast with one clear line (and no traceback) on bad configuration."""

import json

import pytest
from omegaconf import OmegaConf

from eval_runs import molmo_eval, refusal
from molmo_lerobot.config import compose


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["policy=scriptd"], "unknown policy 'scriptd'; did you mean 'scripted'?"),
        (["benchmark=nope"], "unknown benchmark 'nope'"),
        (["wokers=3"], "Could not override 'wokers'"),
        (["executor=slurm"], "unknown executor 'slurm'"),
        (["executor.start_method=fork"], "executor.start_method: expected one of ['forkserver', 'spawn'], got 'fork'"),
        (["executor.egl_devices=0"], "executor.egl_devices: expected a list of device indices or null, got 0"),
        (["workers=0"], "workers must be at least 1, got 0"),
        (["+horizons.pick=soon"], "horizons.pick: expected a positive number of seconds, got 'soon'"),
        (["+horizons.pick=-2"], "horizons.pick: expected a positive number of seconds, got -2"),
        (["push=true", "hub.repo_id=bad/na//me"], "hub.repo_id 'bad/na//me' is not a valid dataset id"),
        (["push=true"], "push=true needs hub.repo_id=<namespace>/<name>"),
        (["record=true", "video.vcodec=divx"], "video: vcodec='divx'"),
        (["record=true", "video.g=0"], "video.g: expected a positive integer or null, got 0"),
    ],
)
def test_bad_config_is_one_clear_line(args, needle, tmp_path):
    assert needle in "\n".join(refusal(*args, f"output_dir={tmp_path / 'out'}"))
    assert not (tmp_path / "out" / "results.json").exists()


def test_malformed_benchmark_names_the_file(tmp_path):
    bench = tmp_path / "bad"
    bench.mkdir()
    (bench / "benchmark.json").write_text('[{"house_index": 1,}]')
    [line] = refusal(f"benchmark.path={bench}", f"output_dir={tmp_path / 'out'}")
    assert str(bench / "benchmark.json") in line and "line 1" in line


@pytest.mark.parametrize(
    ("override", "needle"),
    [
        ("output_dir=/tmp/ü", """cannot parse override 'output_dir=/tmp/ü': 'ü' is allowed only in a quoted value; """
                              """quote it, e.g. molmo-eval 'output_dir="/tmp/ü"'"""),
        ("wörkers=2", "cannot parse override 'wörkers=2': 'ö' is not allowed there (grammar: "
                      "https://hydra.cc/docs/advanced/override_grammar/basic)"),
        ("limit=[1,", "cannot parse override 'limit=[1,': no viable alternative at input '[1,' "
                      "(grammar: https://hydra.cc/docs/advanced/override_grammar/basic)"),
    ],
)
def test_unparsable_override_is_one_line_that_says_how_to_quote(override, needle):
    assert refusal(override) == [needle]


def test_the_cli_prints_one_error_line_per_problem_and_exits_2(tmp_path):
    """The console script's own parsing (Hydra's, of its command line) and a run's refusal alike."""
    proc = molmo_eval("output_dir=/tmp/ü")
    assert (proc.returncode, proc.stderr) == (2, "molmo-eval: error: cannot parse override 'output_dir=/tmp/ü': "
                                                 "'ü' is allowed only in a quoted value; quote it, e.g. "
                                                 """molmo-eval 'output_dir="/tmp/ü"'\n""")
    proc = molmo_eval("limit=0", "seed=x", f"output_dir={tmp_path / 'out'}")
    assert proc.returncode == 2 and proc.stdout == "" and not (tmp_path / "out").exists()
    assert [line.split(": ")[:3] for line in proc.stderr.splitlines()] == [
        ["molmo-eval", "error", "limit"], ["molmo-eval", "error", "seed"]]


def test_quoted_unicode_value_parses():
    assert compose(['output_dir="/tmp/ü"']).output_dir == "/tmp/ü"


def test_existing_output_dir_is_not_overwritten(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text(json.dumps({"success_rate": 1.0}))
    assert "already holds a run" in "\n".join(refusal("limit=1", f"output_dir={out}"))
    assert json.loads((out / "results.json").read_text()) == {"success_rate": 1.0}


def test_cfg_alone_prints_the_job_config():
    proc = molmo_eval("--cfg", "policy=random", "workers=3")
    assert proc.returncode == 0, proc.stderr
    assert "name: random" in proc.stdout and "workers: 3" in proc.stdout and "hydra:" not in proc.stdout


def test_override_errors_keep_hydras_hint(tmp_path):
    assert "Could not override 'policy.camerass.exterior'.\nTo append to your config use " \
           "+policy.camerass.exterior=x" in "\n".join(refusal("policy=random", "policy.camerass.exterior=x",
                                                             f"output_dir={tmp_path / 'out'}"))


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["horizons.pick=15"], "horizons:\n  pick: 15"),
        (["camera.overrides.exterior.fov=50"], "overrides:\n    exterior:\n      fov: 50"),
        (["plugins.prefer.robot.franka=franka"], "prefer:\n    robot:\n      franka: franka"),
        (["policy=lerobot", "policy.cameras.exterior=observation.images.front"],
         "cameras:\n    exterior: observation.images.front"),
    ],
)
def test_documented_maps_take_new_keys_without_plus(args, needle):
    assert needle in OmegaConf.to_yaml(compose(args))
