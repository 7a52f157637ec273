"""molmo-eval fails fast with one clear line (and no traceback) on bad configuration."""

import json

import pytest

from molmo_lerobot.cli.eval import main


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
def test_bad_config_is_one_clear_line(args, needle, capsys, tmp_path):
    assert main([*args, f"output_dir={tmp_path / 'out'}"]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not (tmp_path / "out" / "results.json").exists()


def test_malformed_benchmark_names_the_file(tmp_path, capsys):
    bench = tmp_path / "bad"
    bench.mkdir()
    (bench / "benchmark.json").write_text('[{"house_index": 1,}]')
    assert main([f"benchmark.path={bench}", f"output_dir={tmp_path / 'out'}"]) == 2
    err = capsys.readouterr().err
    assert str(bench / "benchmark.json") in err and "line 1" in err and "Traceback" not in err


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
def test_unparsable_override_is_one_line_that_says_how_to_quote(override, needle, capsys):
    assert main([override]) == 2
    assert capsys.readouterr().err == f"molmo-eval: error: {needle}\n"


def test_quoted_unicode_value_parses(capsys):
    assert main(["--cfg", 'output_dir="/tmp/ü"']) == 0
    assert "output_dir: /tmp/ü" in capsys.readouterr().out


def test_existing_output_dir_is_not_overwritten(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text(json.dumps({"success_rate": 1.0}))
    assert main(["limit=1", f"output_dir={out}"]) == 2
    assert "already holds a run" in capsys.readouterr().err
    assert json.loads((out / "results.json").read_text()) == {"success_rate": 1.0}


def test_print_config(capsys):
    assert main(["--cfg", "policy=random", "workers=3"]) == 0
    out = capsys.readouterr().out
    assert "name: random" in out and "workers: 3" in out


def test_override_errors_keep_hydras_hint(capsys, tmp_path):
    assert main(["policy=random", "policy.camerass.exterior=x", f"output_dir={tmp_path / 'out'}"]) == 2
    err = capsys.readouterr().err
    assert "Could not override 'policy.camerass.exterior'.\nTo append to your config use " \
           "+policy.camerass.exterior=x" in err and "Traceback" not in err


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
def test_documented_maps_take_new_keys_without_plus(args, needle, capsys):
    assert main(["--cfg", *args]) == 0
    assert needle in capsys.readouterr().out
