"""MolmoSpaces' own data used unchanged: scene datasets, thor/objaverse libraries, user libraries
and scenes, validation of their files and the up-front check of a run that cannot simulate."""

from __future__ import annotations

import json
import shutil

import mujoco
import numpy as np
import pytest
from standin import OBJAVERSE_UID, pick_episode, top_down_grasps
from user_library import UID, user_pick_episode, write_user_library

from molmo_lerobot.assets import (
    AssetCatalog,
    AssetError,
    BuiltinAssetLibrary,
    GraspError,
)
from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.cli import bench as bench_cli
from molmo_lerobot.config import compose
from molmo_lerobot.context import RunContext
from molmo_lerobot.errors import RunError
from molmo_lerobot.molmospaces import layout
from molmo_lerobot.molmospaces.user import (
    register_user_asset_library,
    register_user_grasp_library,
)
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.evaluate import run_evaluation


def _write_bench(path, episodes):
    path.mkdir(parents=True, exist_ok=True)
    (path / "benchmark.json").write_text(json.dumps(episodes))
    return path


def _run(tmp_path, bench, *extra):
    return run_evaluation(compose(["policy=scripted", "workers=1", f"benchmark.path={bench}",
                                   f"output_dir={tmp_path / 'run'}", "progress=false", *extra]))


# Layout ------------------------------------------------------------------------------------------


def test_scene_paths_follow_molmospaces(tmp_path):
    assert layout.scene_xml(tmp_path, "ithor", "val", 15) == tmp_path / "scenes/ithor/FloorPlan15_physics.xml"
    assert layout.scene_xml(tmp_path, "ithor", "test", 228) == tmp_path / "scenes/ithor/FloorPlan228_physics.xml"
    with pytest.raises(layout.SceneLookupError, match="FloorPlan1 belongs to split 'train', not data_split 'val'"):
        layout.scene_xml(tmp_path, "ithor", "val", 1)
    assert layout.scene_xml(tmp_path, "procthor-10k", "val", 3).name == "val_3_ceiling.xml"
    assert (layout.scene_xml(tmp_path, "procthor-10k", "train", 3, "base")
            == tmp_path / "scenes/procthor-10k-train/train_3.xml")
    assert layout.scene_xml(tmp_path, "procthor-100k-debug", "val", 1).parent.name == "procthor-objaverse-val"
    assert layout.scene_xml(tmp_path, "procthor-objaverse-debug", "train", 1).parent.name == "procthor-objaverse-debug"
    assert layout.scene_xml(tmp_path, "holodeck-objaverse", "val", 1194).parent.name == "holodeck-objaverse-val"
    # metadata beside the scene, with MolmoSpaces' fallbacks
    xml = tmp_path / "FloorPlan2_physics.xml"
    (tmp_path / "FloorPlan2_metadata.json").write_text('{"objects": {"a": {"asset_id": "A"}}}')
    assert layout.read_scene_metadata(xml)["objects"]["a"]["asset_id"] == "A"
    (tmp_path / "val_3_metadata.json").write_text('{"objects": {}}')
    assert layout.metadata_path(tmp_path / "val_3_ceiling.xml") == tmp_path / "val_3_metadata.json"


def test_scene_loads_with_its_physics_metadata_and_modifications(assets, tmp_path):
    root, houses = assets
    from molmo_lerobot.benchmark.task_specs import parse_episode
    from molmo_lerobot.runner.episode_env import build_env
    from molmo_lerobot.sim.env import PHYSICS_OPTIONS, Timing

    house = houses[0]  # iTHOR FloorPlan15
    ep = pick_episode(house)
    ep["scene_modifications"]["added_objects"] = {"place_receptacle/0/Bowl_27": "objects/thor/Kitchen/Bowl_27.xml",
                                                  "extra": str(root / "objects/thor/Kitchen/Mug_2.xml")}
    ep["scene_modifications"]["object_poses"]["place_receptacle/0/Bowl_27"] = [0.6, -2.2, 0.8, 1, 0, 0, 0]
    ep["scene_modifications"]["removed_objects"] = ["not_in_this_scene", "Mug_1_15_0_0"]
    del ep["scene_modifications"]["object_poses"]["Mug_1_15_0_0"]
    ep["task"]["pickup_obj_name"] = "place_receptacle/0/Bowl_27"
    run = RunContext.build()
    plugins = run.plugins
    spec = parse_episode(ep, plugins)
    env = build_env(spec, Timing(), run)
    m = env.model
    names = {m.body(i).name for i in range(m.nbody)}
    assert {"place_receptacle/0/Bowl_27", "extra", "table_1_0_0"} <= names and "Mug_1_15_0_0" not in names
    assert m.opt.timestep == 0.002 and m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    env.reset(0)
    np.testing.assert_allclose(env.body_pose("place_receptacle/0/Bowl_27")[:3], [0.6, -2.2, 0.8])
    meta = plugins.scene_dataset("ithor").episode_metadata(spec, run)["objects"]
    assert meta["place_receptacle/0/Bowl_27"]["asset_id"] == "Bowl_27" and meta["Mug_1_15_0_0"]["asset_id"] == "Mug_1"
    # user scene: its XML says timestep 5 ms and the run says 2 ms; a run may override its options
    write_user_library(tmp_path)
    run = RunContext.build({"scene_xml_paths": [str(tmp_path / "scene.xml")],
                            "molmospaces": {"physics_options": {"integrator": "rk4", "cone": "pyramidal"}}})
    env = build_env(parse_episode(user_pick_episode(), run.plugins), Timing(), run)
    assert env.model.opt.timestep == 0.002 and env.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert env.model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL and PHYSICS_OPTIONS["cone"] != env.model.opt.cone


def test_user_scenes_of_one_house_index_in_two_runs_build_each_their_own(tmp_path):
    """The compiled-model cache keys a MolmoSpaces house by its scene file too: two runs in one process
    whose ``scene_xml_paths[0]`` differ get each their own scene (the first's was reused before)."""
    from molmo_lerobot.benchmark.task_specs import parse_episode
    from molmo_lerobot.runner.episode_env import build_env
    from molmo_lerobot.sim.env import Timing

    tables = []
    for name, x in (("a", 0.3), ("b", 0.4)):
        write_user_library(tmp_path / name)
        scene = tmp_path / name / "scene.xml"
        scene.write_text(scene.read_text().replace('name="table" pos="0.3 0 0"', f'name="table" pos="{x} 0 0"'))
        run = RunContext.build({"scene_xml_paths": [str(scene)]})
        env = build_env(parse_episode(user_pick_episode(), run.plugins), Timing(), run)
        tables.append(float(env.model.body("table").pos[0]))
        env.close()
    assert tables == [0.3, 0.4]


# Libraries ---------------------------------------------------------------------------------------


def test_thor_and_objaverse_libraries_and_droid_grasps(assets, tmp_path):
    root, _ = assets
    cat = RunContext.build().catalog
    loc = cat.locate_uid("Mug_1")
    assert (loc.library, loc.mjcf_path) == ("thor", root / "objects/thor/Kitchen/Mug_1.xml")
    assert cat.locate_uid(OBJAVERSE_UID).library == "objaverse"
    assert cat.install_uid("Mug_1").mjcf_path.is_file()
    doc = cat.annotation(OBJAVERSE_UID)  # MolmoSpaces' LMDB: arrays included
    assert doc["category"] == "cup" and doc["clip_img_features"].shape == (3, 4)
    np.testing.assert_allclose(cat.get_grasps("Mug_1", robot="franka_droid"), top_down_grasps())
    assert cat.count_grasps(OBJAVERSE_UID, robot="franka") == 4  # droid grasps serve another robot
    assert [g.name for g in cat._grasp_sources("Mug_1", "franka")] == ["droid"]
    assert [g.name for g in cat._grasp_sources(OBJAVERSE_UID, "franka_droid")] == ["droid_objaverse"]
    # a user grasp library registered for the thor library goes before droid (MolmoSpaces' priority)
    mine = tmp_path / "thor_grasps"
    (mine / "Mug_1").mkdir(parents=True)
    np.savez(mine / "Mug_1" / "g.npz", transforms=top_down_grasps()[:1])
    (mine / "grasps_index.json").write_text(json.dumps({"grasp_paths": {"droid": {"Mug_1": "Mug_1/g.npz"}}}))
    register_user_grasp_library(cat, "better", mine, "thor")
    assert [g.name for g in cat._grasp_sources("Mug_1", "franka_droid")] == ["better/droid", "droid"]
    assert cat.count_grasps("Mug_1", robot="franka_droid") == 1
    with pytest.raises(AssetError,
                       match=r"not installed under .*objaverse.*molmo-resources install objects/objaverse@"):
        cat.library("objaverse").install("f" * 32)


def test_metadata_from_the_json_source_when_no_lmdb(assets, tmp_path, monkeypatch):
    root, _ = assets
    copy = tmp_path / "assets"
    shutil.copytree(root, copy, symlinks=True)
    shutil.rmtree(copy / ".lmdb")
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(copy))
    assert RunContext.build().catalog.annotation("Mug_2")["description_short"]["two_words"] == "small mug"
    assert any((tmp_path / "home" / "molmospaces" / "metadata").glob("*.lmdb"))


def test_user_libraries_in_molmospaces_format(assets, tmp_path):
    lib = write_user_library(tmp_path)
    cat = AssetCatalog()
    cat.register_library(BuiltinAssetLibrary())
    register_user_asset_library(cat, "custom_assets", lib)
    (g,) = register_user_grasp_library(cat, "custom_grasps", lib, "custom_assets")
    assert g.name == "custom_grasps/droid" and cat.grasp_libraries[0][0] is g
    assert cat.locate_uid(UID).mjcf_path == lib / UID / f"{UID}.xml"
    assert cat.annotation(UID)["boundingBox"]["z"] == pytest.approx(0.06)
    np.testing.assert_allclose(cat.get_grasps(UID, robot="franka"), top_down_grasps())  # droid grasps serve franka
    with pytest.raises(AssetError, match="already registered"):
        register_user_asset_library(cat, "custom_assets", lib)
    with pytest.raises(AssetError, match="name of a MolmoSpaces object source"):
        register_user_asset_library(cat, "thor", lib)
    with pytest.raises(AssetError, match="no asset library named 'nope'"):
        register_user_grasp_library(cat, "g2", lib, "nope")


@pytest.mark.parametrize(("edit", "error", "message"), [
    (lambda a, g: a[UID].update(object_path="../../outside.xml"), AssetError,
     r"assets_index.json: field blue_block.object_path: '../../outside.xml' points outside the library"),
    (lambda a, g: a[UID].update(metadata_path="blue_block/missing.json"), AssetError,
     r"assets_index.json: field blue_block.metadata_path: .*missing.json not found"),
    (lambda a, g: g["grasp_paths"]["droid"].update(blue_block="/etc/passwd"), GraspError,
     r"grasps_index.json: field grasp_paths.droid.blue_block: '/etc/passwd' points outside the library"),
    (lambda a, g: g.update(grasp_paths=["droid"]), GraspError,
     r"grasps_index.json: field grasp_paths: expected \{robot: \{uid: ...\}\}"),
])
def test_bad_library_indexes_name_file_and_field(assets, tmp_path, edit, error, message):
    lib = write_user_library(tmp_path)
    a = json.loads((lib / "assets_index.json").read_text())
    g = json.loads((lib / "grasps_index.json").read_text())
    edit(a, g)
    (lib / "assets_index.json").write_text(json.dumps(a))
    (lib / "grasps_index.json").write_text(json.dumps(g))
    cat = AssetCatalog()
    with pytest.raises(error, match=message):
        register_user_asset_library(cat, "custom_assets", lib)
        register_user_grasp_library(cat, "custom_grasps", lib, "custom_assets")


def test_malformed_grasps_index_in_a_run_is_one_line(assets, tmp_path):
    from eval_runs import refusal

    lib = write_user_library(tmp_path)
    (lib / "grasps_index.json").write_text("{not json")
    bench = _write_bench(tmp_path / "b", [user_pick_episode()])
    [err] = refusal(f"benchmark.path={bench}", "workers=1", f"output_dir={tmp_path / 'run'}", "progress=false",
                    f"scene_xml_paths=[{tmp_path / 'scene.xml'}]", f"+asset_libraries.custom_assets={lib}",
                    f"+grasp_libraries.custom_grasps={{path: {lib}, asset_library: custom_assets}}")
    assert "grasp_libraries.custom_grasps:" in err and "grasps_index.json: invalid JSON" in err
    assert not (tmp_path / "run" / "results.json").exists()


# Runs --------------------------------------------------------------------------------------------


def test_expert_scores_on_ithor_and_procthor_layouts(assets, tmp_path):
    _, houses = assets
    chosen = [h for h in houses if (h.dataset, h.index) in (("ithor", 15), ("procthor-10k", 3))]
    res = _run(tmp_path, _write_bench(tmp_path / "b", [pick_episode(h) for h in chosen]))
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == 2, [e.error for e in res.episodes]


def test_expert_scores_on_franka_droid_with_molmospaces_init_qpos(assets, tmp_path):
    """Their robot name and gripper init (driver radians, open); droid grasps are this robot's own."""
    _, houses = assets
    ep = pick_episode(houses[2], robot="franka_droid", gripper=[0.00296, 0.00296])
    res = _run(tmp_path, _write_bench(tmp_path / "b", [ep]))
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == 1, [e.error for e in res.episodes]


@pytest.mark.slow
def test_expert_scores_on_every_standin_scene(assets, tmp_path):
    _, houses = assets
    res = _run(tmp_path, _write_bench(tmp_path / "b", [pick_episode(h) for h in houses]))
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == len(houses)


def test_user_scene_and_libraries_from_the_run_config(assets, tmp_path, fork_servers):
    lib = write_user_library(tmp_path)
    bench = _write_bench(tmp_path / "b", [user_pick_episode()])
    scene = f"scene_xml_paths=[{tmp_path / 'scene.xml'}]"
    libs = [f"asset_libraries.custom_assets={lib}",  # open maps: no Hydra '+' needed
            f"grasp_libraries.custom_grasps={{path: {lib}, asset_library: custom_assets}}"]
    res = _run(tmp_path, bench, scene, *libs)
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == 1, [e.error for e in res.episodes]
    # without the grasp library the expert has no grasps for the block: the library's grasps were used
    res = run_evaluation(compose(["policy=scripted", "workers=1", f"benchmark.path={bench}", scene, libs[0],
                                  f"output_dir={tmp_path / 'run2'}", "progress=false"]), fork_servers)
    assert "no grasps for 'blue_block'" in res.episodes[0].error
    assert [g.name for g, _ in RunContext.build().catalog.grasp_libraries if "/" in g.name] == []  # nor in this process


def test_house_index_beyond_scene_xml_paths_fails_up_front(assets, tmp_path):
    write_user_library(tmp_path)
    bench = _write_bench(tmp_path / "b", [user_pick_episode(0), user_pick_episode(3)])
    with pytest.raises(RunError, match=r"house_index 3 is beyond scene_xml_paths \(1 scene configured"):
        _run(tmp_path, bench, f"scene_xml_paths=[{tmp_path / 'scene.xml'}]")
    assert not (tmp_path / "run").exists()


def test_missing_scene_assets_fail_up_front_and_still_validate(assets, tmp_path, monkeypatch, capsys):
    from eval_runs import refusal

    _, houses = assets
    bench = _write_bench(tmp_path / "b", [pick_episode(h) for h in houses[:3]])
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(tmp_path / "empty"))
    [err] = refusal(f"benchmark.path={bench}", "workers=1", f"output_dir={tmp_path / 'run'}", "progress=false")
    assert "cannot simulate 3 of 3 episodes" in err and str(tmp_path / "empty" / "scenes" / "ithor") in err
    assert "molmo-resources install scenes/ithor@" in err
    assert not (tmp_path / "run" / "results.json").exists()
    assert bench_cli.main(["validate", str(bench)]) == 0
    out = capsys.readouterr()
    assert "episodes   3 over 3 houses" in out.out and out.err.count("warning: ") == 3  # one per missing scene


# Validation --------------------------------------------------------------------------------------


def _every_task(houses):
    """One MolmoSpaces-format episode per task type on the stand-in scenes."""
    base = pick_episode(houses[0])
    t = base["task"]
    pose = t["pickup_obj_start_pose"]
    rec = {"place_receptacle_name": "place_receptacle/0/Bowl_27",
           "place_receptacle_start_pose": [0.6, -2.2, 0.8, 1, 0, 0, 0]}
    tasks = {
        "molmo_spaces.tasks.pick_task.PickTask": {},
        "molmo_spaces.tasks.pick_and_place_task.PickAndPlaceTask": rec,
        "molmo_spaces.tasks.pick_and_place_next_to_task.PickAndPlaceNextToTask": {
            **rec, "min_surface_to_surface_gap": None, "max_surface_to_surface_gap": None},
        "molmo_spaces.tasks.pick_and_place_color_task.PickAndPlaceColorTask": {
            **rec, "object_colors": {"place_receptacle/0/Bowl_27": [1, 0, 0, 1]}},
        "molmo_spaces.tasks.opening_tasks.OpeningTask": {"joint_name": "door_joint", "joint_start_position": [0.0],
                                                         "task_type": "open"},
        "molmo_spaces.tasks.opening_tasks.DoorOpeningTask": {"door_body_name": "door_1"},
        "molmo_spaces.tasks.nav_task.NavToObjTask": {"succ_pos_threshold": 1.5},
    }
    out = []
    for cls, extra in tasks.items():
        ep = json.loads(json.dumps(base))
        ep["task"] = {"task_cls": cls, "robot_base_pose": t["robot_base_pose"], "pickup_obj_name": t["pickup_obj_name"],
                      "pickup_obj_start_pose": pose, **extra}
        if "Place" in cls:
            ep["scene_modifications"]["added_objects"] = {
                "place_receptacle/0/Bowl_27": "objects/thor/Kitchen/Bowl_27.xml"}
        if "Door" in cls or "Nav" in cls:
            ep["robot"] = {"robot_name": "rby1", "init_qpos": {"base": [0.0, 0.0, 0.0]}}
        out.append(ep)
    close = json.loads(json.dumps(out[4]))
    close["task"]["task_type"] = "close"
    out.append(close)
    out.append(dict(json.loads(json.dumps(out[0])), cameras=[]))  # cameras: [] (camera system from the run)
    return out


def test_every_task_type_in_both_layouts_is_valid(assets, tmp_path, capsys):
    _, houses = assets
    episodes = _every_task(houses)
    lists = _write_bench(tmp_path / "list", episodes)
    legacy = tmp_path / "legacy"
    for i, ep in enumerate(episodes):  # legacy layout, any integer in the file name (episode_7.json)
        d = legacy / f"house_{ep['house_index']}"
        d.mkdir(parents=True, exist_ok=True)
        (d / f"episode_{i}.json").write_text(json.dumps(ep))
    for path in (lists, legacy):
        assert bench_cli.main(["validate", str(path)]) == 0
        out = capsys.readouterr()
        assert f"episodes   {len(episodes)} over 1 houses" in out.out
        assert "problem" not in out.err
    assert len(load_benchmark(legacy, Plugins()).episodes) == len(episodes)


def test_install_uid_fetches_objaverse_objects_and_grasps_through_the_resource_manager(tmp_path):
    from standin import object_xml, save_npz

    from molmo_lerobot.resources import pack

    uids = ("a" * 32, "b" * 32)
    objects, grasps = tmp_path / "objects_src", tmp_path / "grasps_src"
    for uid in uids:
        (objects / uid).mkdir(parents=True)
        (objects / uid / f"{uid}.xml").write_text(object_xml(uid, "1 1 1 1"))
        save_npz(grasps / uid / f"{uid}_grasps_filtered.npz", top_down_grasps())
    remote = tmp_path / "remote"
    pack(objects, remote, f"objects/objaverse@{layout.OBJECT_VERSIONS['objaverse']}", max_archive_bytes=1)
    pack(grasps, remote, f"grasps/droid_objaverse@{layout.GRASP_VERSIONS['droid_objaverse']}", max_archive_bytes=1)
    assets = tmp_path / "assets"
    run = RunContext.build({"molmospaces": {"assets_dir": str(assets), "cache_dir": str(tmp_path / "cache"),
                                            "remote": str(remote)}})
    loc = run.catalog.library("objaverse").install(uids[0])
    assert loc.mjcf_path == assets / "objects" / "objaverse" / uids[0] / f"{uids[0]}.xml" and loc.mjcf_path.is_file()
    assert (assets / "grasps" / "droid_objaverse" / uids[0] / f"{uids[0]}_grasps_filtered.npz").is_file()
    assert not (assets / "objects" / "objaverse" / uids[1] / f"{uids[1]}.xml").exists()  # one UID at a time


def test_one_warning_per_missing_resource_and_user_scenes_from_overrides(assets, tmp_path, capsys):
    _, houses = assets
    ithor = houses[0]
    distinct = [{**pick_episode(ithor), "seed": i} for i in range(3)]  # duplicates are refused by content
    bench = _write_bench(tmp_path / "b", [*distinct, user_pick_episode()])
    assert bench_cli.main(["validate", str(bench), f"molmospaces.assets_dir={tmp_path / 'none'}"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "episodes 0, 1, 2: field scene_dataset" in err[0]
    assert "episode 3: field scene_dataset" in err[1]
    write_user_library(tmp_path)
    assert bench_cli.main(["validate", str(bench), f"scene_xml_paths=[{tmp_path / 'scene.xml'}]"]) == 0
    assert capsys.readouterr().err == ""


def test_objaverse_uid_known_by_metadata_but_not_installed_says_how_to_install(assets, tmp_path, monkeypatch):
    import gzip

    root, _ = assets
    copy = tmp_path / "assets"
    shutil.copytree(root, copy, symlinks=True)
    shutil.rmtree(copy / ".lmdb")
    shutil.rmtree(copy / "objects" / "objaverse" / OBJAVERSE_UID)
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(copy))
    uid = "c" * 32
    with gzip.open(copy / "objects/objathor_metadata/objects_metadata.json.gz", "rt") as fh:
        docs = json.load(fh)
    docs[uid] = {"assetId": uid, "category": "vase"}
    with gzip.open(copy / "objects/objathor_metadata/objects_metadata.json.gz", "wt") as fh:
        json.dump(docs, fh)
    cat = RunContext.build().catalog
    assert cat.locate_uid(uid).mjcf_path == copy / "objects/objaverse" / uid / f"{uid}.xml"
    assert cat.annotation(uid)["category"] == "vase"
    with pytest.raises(AssetError,
                       match=rf"object '{uid}' is not installed .*molmo-resources install objects/objaverse@"):
        cat.install_uid(uid)
    with pytest.raises(AssetError, match="unknown asset UID 'Mug_9'"):
        cat.install_uid("Mug_9")


def test_scenes_installed_on_demand_are_fetched_per_house_before_the_run(assets, tmp_path, monkeypatch):
    from molmo_lerobot.molmospaces.preflight import preflight
    from molmo_lerobot.resources import ResourceManager, pack

    root, houses = assets
    house = next(h for h in houses if (h.dataset, h.index) == ("procthor-10k", 3))
    remote, cache, fresh = tmp_path / "remote", tmp_path / "cache", tmp_path / "fresh"
    pack(root / "scenes" / "procthor-10k-val", remote, "scenes/procthor-10k-val@v1", link="file", max_archive_bytes=1)
    ResourceManager(cache, fresh, remote, progress=False).install("scenes/procthor-10k-val@v1", on_demand=True)
    for data in ("objects", "grasps"):
        (fresh / data).symlink_to(root / data)
    xml = fresh / "scenes" / "procthor-10k-val" / "val_3_ceiling.xml"
    assert not xml.exists()
    cfg = {"molmospaces": {"assets_dir": str(fresh), "cache_dir": str(cache), "remote": str(remote)}}
    run = RunContext.build(cfg)
    bench = load_benchmark(_write_bench(tmp_path / "b", [pick_episode(house)]), run.plugins)
    assert preflight(bench, run, [0]) is None
    assert xml.is_file() and (fresh / "scenes" / "procthor-10k-val" / "val_3_metadata.json").is_file()
    assert not (fresh / "scenes" / "procthor-10k-val" / "val_7_ceiling.xml").exists()  # only the house asked for
    res = _run(tmp_path, tmp_path / "b", f"molmospaces.assets_dir={fresh}")
    assert res.summary["n_success"] == 1 and res.summary["n_errors"] == 0, [e.error for e in res.episodes]
