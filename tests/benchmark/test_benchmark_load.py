"""Loading both layouts, the content hash, and one clear line per problem."""

from __future__ import annotations

import copy
import json
import shutil

import pytest

from molmo_lerobot.benchmark.load import BenchmarkError, load_benchmark
from molmo_lerobot.plugins import Plugins

#: the installed plugins, whose spec models type each episode's task
PLUGINS = Plugins()


def _problems(path) -> list[str]:
    with pytest.raises(BenchmarkError) as info:
        load_benchmark(path, PLUGINS)
    return [str(p) for p in info.value.problems]


def _write_list(tmp_path, episodes, name="b"):
    d = tmp_path / name
    d.mkdir()
    (d / "benchmark.json").write_text(json.dumps(episodes, indent=2))
    return d


@pytest.fixture
def episodes(data):
    return json.loads((data / "pick_list" / "benchmark.json").read_text())


def test_both_layouts_load_to_the_same_benchmark(data):
    listed = load_benchmark(data / "pick_list", PLUGINS)
    legacy = load_benchmark(data / "pick_legacy", PLUGINS)
    assert len(listed) == len(legacy) == 4
    assert listed.episodes == legacy.episodes
    assert listed.sha256 == legacy.sha256 and len(listed.sha256) == 64
    assert (listed.name, legacy.name) == ("pick_list", "pick_legacy")
    assert listed.metadata.num_episodes == 4 and listed.metadata.house_counts == {12: 2, 3: 2}
    assert [ep.house_index for ep in legacy.episodes] == [12, 12, 3, 3]  # MolmoSpaces' order: sorted names
    assert legacy.origins[2].file.endswith("house_3/episode_00000000.json")
    assert listed.where(3).endswith("pick_list/benchmark.json: episode 3")


def test_single_files_load(data, tmp_path):
    single = load_benchmark(data / "pick_list" / "benchmark.json", PLUGINS)
    assert single.name == "pick_list" and single.metadata.num_houses == 2
    one = load_benchmark(data / "pick_legacy" / "house_3" / "episode_00000001.json", PLUGINS)
    assert len(one) == 1 and one.episodes[0].task.pickup_obj_name == "builtin_red_block"


def test_hash_ignores_key_order_whitespace_and_defaults(episodes, tmp_path):
    base = load_benchmark(_write_list(tmp_path, episodes, "a"), PLUGINS).sha256
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "benchmark.json").write_text(json.dumps(episodes, sort_keys=True, separators=(",", ":")))
    assert load_benchmark(tmp_path / "c", PLUGINS).sha256 == base
    no_default = copy.deepcopy(episodes)
    del no_default[0]["task"]["succ_pos_threshold"]  # 0.01 is the default
    no_default[0]["img_resolution"] = [224.0, 224]
    assert load_benchmark(_write_list(tmp_path, no_default, "d"), PLUGINS).sha256 == base


@pytest.mark.parametrize(
    "edit",
    [
        lambda eps: eps[1]["task"].__setitem__("succ_pos_threshold", 0.02),
        lambda eps: eps.reverse(),
        lambda eps: eps[3]["language"].__setitem__("task_description", "Pick up the block"),
        lambda eps: eps.pop(),
    ],
)
def test_hash_changes_with_content(episodes, tmp_path, edit):
    base = load_benchmark(_write_list(tmp_path, episodes, "a"), PLUGINS).sha256
    changed = copy.deepcopy(episodes)
    edit(changed)
    assert load_benchmark(_write_list(tmp_path, changed, "b"), PLUGINS).sha256 != base


def test_malformed_json_reports_line_and_column(tmp_path):
    d = tmp_path / "bad"
    d.mkdir()
    (d / "benchmark.json").write_text('[\n  {"house_index": 1,\n  }\n]')
    (problem,) = _problems(d)
    assert problem.startswith(f"{d / 'benchmark.json'}: invalid JSON at line 3, column 3:")


def test_every_bad_episode_is_reported_with_file_index_and_field(episodes, tmp_path):
    bad = copy.deepcopy(episodes)
    bad[0]["task"]["robot_base_pose"] = [0, 0, 0, 1, 0, 0]
    del bad[2]["language"]
    bad[3]["cameras"][0]["camera_offset"] = [0.1]
    bad[3]["cameras"][1]["type"] = "fisheye"
    d = _write_list(tmp_path, bad)
    f = d / "benchmark.json"
    assert _problems(d) == [
        f"{f}: episode 0: field task.robot_base_pose: expected 7 values, got 6",
        f"{f}: episode 2: field language: missing",
        f"{f}: episode 3: field cameras[0].camera_offset: expected 3 values, got 1",
        f"{f}: episode 3: field cameras[1].type: unknown camera type 'fisheye' "
        "(expected 'robot_mounted' or 'exocentric')",
    ]


def test_wrong_types_show_the_value(episodes, tmp_path):
    bad = copy.deepcopy(episodes)
    bad[1]["house_index"] = "twelve"
    bad[1]["robot"]["init_qpos"]["arm"][2] = "x"
    f = _write_list(tmp_path, bad) / "benchmark.json"
    problems = _problems(f.parent)
    assert f"{f}: episode 1: field house_index: Input should be a valid integer (got \"twelve\")" in problems
    assert any(p.startswith(f"{f}: episode 1: field robot.init_qpos.arm[2]: ") for p in problems)


def test_legacy_layout_names_the_bad_file_and_keeps_indices(data, tmp_path):
    d = tmp_path / "legacy"
    shutil.copytree(data / "pick_legacy", d)
    (d / "house_12" / "episode_00000001.json").write_text("{ nope")
    ep3 = d / "house_3" / "episode_00000001.json"
    raw = json.loads(ep3.read_text())
    raw["task"]["pickup_obj_start_pose"] = [0.5, 0.0, 0.8]
    ep3.write_text(json.dumps(raw))
    (d / "house_x").mkdir()
    assert _problems(d) == [
        f"{d / 'house_12' / 'episode_00000001.json'}: invalid JSON at line 1, column 3: "
        "Expecting property name enclosed in double quotes",
        f"{d / 'house_x'}: directory name is not house_<integer>",
        f"{ep3}: episode 3: field task.pickup_obj_start_pose: expected 7 values, got 3",
    ]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ('{"episodes": []}', None),  # a single object that is no episode: reported as episode fields
        ("[1, []]", "expected an episode object, got a number"),
        ('"text"', "expected a list of episode objects, got a string"),
        ("[]", "benchmark has no episodes"),
    ],
)
def test_wrong_top_level_shapes(tmp_path, content, message):
    f = tmp_path / "x.json"
    f.write_text(content)
    problems = _problems(f)
    if message:
        assert any(message in p for p in problems), problems
    else:
        assert f"{f}: episode 0: field house_index: missing" in problems


def test_missing_and_empty_paths(tmp_path):
    assert _problems(tmp_path / "nope") == [f"{tmp_path / 'nope'}: no such benchmark file or directory"]
    (tmp_path / "empty").mkdir()
    (problem,) = _problems(tmp_path / "empty")
    assert "no benchmark.json and no house_<id>/episode_<n>.json files" in problem


def test_bad_metadata_is_reported(data, tmp_path):
    d = tmp_path / "m"
    shutil.copytree(data / "pick_list", d)
    (d / "benchmark_metadata.json").write_text('{"num_episodes": "many"}')
    (problem,) = _problems(d)
    assert problem.startswith(f"{d / 'benchmark_metadata.json'}: field num_episodes: Input should be a valid integer")
