"""Horizons of episodes that carry none: MolmoSpaces' table, and one warning naming the file."""

from __future__ import annotations

from pathlib import Path

from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.episode_files import warn_default_horizons


def test_default_table_is_molmospaces():
    plugins = Plugins()
    table = {name: plugins.task_type(name).default_horizon_sec
             for name in ("pick", "pick_and_place", "pick_and_place_next_to", "pick_and_place_color", "open", "close")}
    assert table == {"pick": 20.0, "pick_and_place": 40.0, "pick_and_place_next_to": 40.0,
                     "pick_and_place_color": 40.0, "open": 30.0, "close": 30.0}


def test_episodes_on_default_horizons_get_one_warning_naming_the_file(capsys):
    described = [{"task_type": "pick", "horizon": 303, "horizon_source": "default"},
                 {"task_type": "pick", "horizon": 303, "horizon_source": "task_horizon_sec"},
                 {"task_type": "open", "horizon": 455, "horizon_source": "default"}]
    warn_default_horizons(Path("/data/ms/benchmark.json"), described, 66.0)
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("molmo-eval: warning: /data/ms/benchmark.json: 2 episodes carry no task.task_horizon_sec; "
                          "running MolmoSpaces' default horizons (open 30 s = 455 steps, pick 20 s = 303 steps)")
    assert "horizon=<steps> or horizons.<task>=<seconds>" in err
    warn_default_horizons(Path("x"), described[1:2], 66.0)
    assert capsys.readouterr().err == ""
