"""Camera poses against MolmoSpaces' own code: the fixed and randomized DROID systems and the eval
system (``--use_eval_cameras --camera_rand_level``) at several levels and episodes (seeds).

Scenes are franka_droid variants of the shipped pick and pick-and-place episodes (a table, objects,
the arm), built by us; their side gets the poses of the bodies its cameras hang off
(tests/parity/their_cameras.py). Visibility is the one thing both sides take from a common stand-in
(tests/parity/camera_oracle.py), so the redraw loops are compared draw for draw.
"""

from __future__ import annotations

import json

import camera_oracle
import mujoco
import numpy as np
import pytest
from droid_variants import droid_episode

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.cameras import droid, franka_mounts
from molmo_lerobot.cameras.franka_eval import episode_camera_seed, exo_ranges, workspace_centre, wrist_noise
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim import env as sim_env
from molmo_lerobot.sim.env import Timing

pytestmark = pytest.mark.parity

LEVELS = (0, 10, 25, 40, 50, 75, 100)
POS_TOL, DIR_TOL, FOV_TOL = 2e-6, 2e-6, 1e-5  # their cameras hold float32 poses
#: visibility stand-ins: every azimuth seen; about half; a third, gripper only from 0.3 m up
ORACLES = ({"lobes": 1, "phase": 0.0, "cut": -2.0, "rise": -9.0},
           {"lobes": 2, "phase": 0.7, "cut": 0.0, "rise": -9.0},
           {"lobes": 3, "phase": 2.0, "cut": 0.5, "rise": 0.3})


def _episodes() -> list[dict]:
    """Six episodes: three picks, three pick-and-places (two task objects), some with a recorded
    source (its file and trajectory key enter MolmoSpaces' camera seed), one without a seed."""
    out = []
    for bench, ks in (("pick_v1", (0, 3, 7)), ("pick_and_place_v1", (0, 2, 5))):
        rows = json.loads((data_path("benchmarks") / bench / "benchmark.json").read_text())
        for k in ks:
            ep = droid_episode(rows[k])
            if k % 2 == 0:
                ep["source"] = {"h5_file": f"/data/{bench}/house_{ep['house_index']}.h5", "traj_key": f"traj_{k}"}
            out.append(ep)
    out[-1]["seed"] = None
    return out


class _Visibility:
    """Env.visible_fractions replaced by the stand-in, counting the checks."""

    def __init__(self, oracle: dict) -> None:
        self.oracle, self.checks = oracle, 0

    def __call__(self, env, camera: str, bodies):
        self.checks += 1
        c = env.model.camera(camera).id
        return camera_oracle.fractions(env.model.cam_pos[c], bodies, self.oracle)


def _scene(env) -> dict:
    """What their side needs of our reset scene: the poses their cameras hang off, and the TCP."""
    m, d = env.model, env.data
    link0, gripper, mount = m.body("robot_0/fr3_link0").id, m.body("robot_0/gripper/base").id, \
        m.camera("robot_0/gripper/wrist_camera").id
    return {"link0_pos": d.xpos[link0].tolist(), "link0_quat": d.xquat[link0].tolist(),
            "gripper_pos": d.xpos[gripper].tolist(), "gripper_quat": d.xquat[gripper].tolist(),
            "mount_pos": m.cam_pos[mount].tolist(), "mount_quat": m.cam_quat[mount].tolist(),
            "mount_fovy": float(m.cam_fovy[mount]), "tcp": d.site_xpos[env.robot.tcp_site].tolist()}


def _world(env, name: str) -> dict:
    c = env.model.camera(name).id
    rot = env.data.cam_xmat[c].reshape(3, 3)
    return {"pos": env.data.cam_xpos[c].tolist(), "forward": (-rot[:, 2]).tolist(), "up": rot[:, 1].tolist(),
            "fov": float(env.model.cam_fovy[c])}


def _build(raw: dict, camera: dict | None, monkeypatch, oracle: dict | None = None):
    """Our env for ``raw`` under the run's ``camera`` options, placed with the stand-in's answers."""
    sim_env._MODEL_CACHE.clear()  # the stand-in is not part of the cache key
    seen = _Visibility(oracle or {**ORACLES[0], "centre": [0.0, 0.0, 0.0]})  # sees everything
    monkeypatch.setattr(sim_env.Env, "visible_fractions", lambda env, cam, bodies: seen(env, cam, bodies))
    try:
        run = RunContext.build()
        env = build_env(parse_episode(raw, run.plugins), Timing(), run, camera)
    except ValueError as exc:
        return None, seen.checks, str(exc)
    env.reset(0)
    return env, seen.checks, None


#: the largest difference seen per quantity (reported by the tests)
DEVIATION = {"pos": 0.0, "forward": 0.0, "up": 0.0, "fov": 0.0}


def _same_pose(ours: dict, theirs: dict, what: str) -> list[str]:
    bad = []
    for key in DEVIATION:
        DEVIATION[key] = max(DEVIATION[key], float(np.max(np.abs(np.subtract(ours[key], theirs[key])))))
    for key, tol in (("pos", POS_TOL), ("forward", DIR_TOL), ("up", DIR_TOL)):
        if not np.allclose(ours[key], theirs[key], atol=tol, rtol=0):
            bad.append(f"{what} {key}: ours {np.round(ours[key], 6).tolist()} "
                       f"theirs {np.round(theirs[key], 6).tolist()}")
    if abs(ours["fov"] - theirs["fov"]) > FOV_TOL:
        bad.append(f"{what} fov: ours {ours['fov']} theirs {theirs['fov']}")
    return bad


@pytest.fixture(scope="module")
def scenes():
    """Each episode's reset scene (the fixed system: cameras do not move the robot or objects)."""
    out = []
    for raw in _episodes():
        run = RunContext.build()
        env = build_env(parse_episode(raw, run.plugins), Timing(), run, None)
        env.reset(0)
        out.append((raw, _scene(env), env))
    yield out
    for _, _, env in out:
        env.close()


def test_eval_ranges_at_every_level_equal_theirs(theirs):
    levels = [0, 5, 10, 17.5, 25, 40, 50, 60, 75, 90, 100]
    for level, got in zip(levels, theirs.run("their_cameras:eval_ranges", {"levels": levels})["ranges"], strict=True):
        w, e = wrist_noise(level), exo_ranges(level)
        assert got["wrist"]["fov"] == 52.0 and got["exo"]["fov"] == 71.0
        assert got["exo"]["max_placement_attempts"] == 50
        np.testing.assert_allclose(got["wrist"]["fov_noise_degrees"], w.fov, atol=1e-12)
        np.testing.assert_allclose(got["wrist"]["pos_noise_range"], w.pos, atol=1e-12)
        np.testing.assert_allclose(got["wrist"]["orientation_noise_degrees"], w.rot_deg, atol=1e-12)
        for theirs_key, ours in (("azimuth_range", e.azimuth), ("distance_range", e.distance),
                                 ("height_range", e.height), ("lookat_noise_range", e.lookat_noise),
                                 ("fov_range", e.fov), ("workspace_center_weight", e.lookat_weight)):
            np.testing.assert_allclose(got["exo"][theirs_key], ours, atol=1e-12, err_msg=f"{theirs_key} at {level}")


def test_eval_system_places_the_cameras_theirs_does(theirs, scenes, monkeypatch):
    DEVIATION.update(dict.fromkeys(DEVIATION, 0.0))
    cases, ours = [], []
    plugins = Plugins()
    for i, (raw, scene, _) in enumerate(scenes):
        spec = parse_episode(raw, plugins)
        for level in LEVELS:
            oracle = ORACLES[(i + level) % len(ORACLES)]
            centre = workspace_centre(spec, scene["tcp"]).tolist()
            env, checks, error = _build(raw, {"eval": True, "rand_level": level}, monkeypatch,
                                        {**oracle, "centre": centre})
            cams = {n: _world(env, n) for n in ("wrist_camera", "exo_camera_1")} if env else {}
            if env:
                env.close()
            ours.append({"seed": episode_camera_seed(spec), "centre": centre, "checks": checks, "error": error,
                         "cameras": cams, "what": f"episode {i} level {level}"})
            cases.append({**scene, "episode": raw, "level": level, "oracle": oracle})
    got = theirs.run("their_cameras:eval_cameras", {"cases": cases})["results"]
    bad, failed, agreed = [], 0, 0
    for o, t in zip(ours, got, strict=True):
        what, problems = o["what"], []
        if o["seed"] != t["seed"]:
            problems.append(f"{what}: seed ours {o['seed']} theirs {t['seed']}")
        if not np.allclose(o["centre"], t["centre"], atol=1e-12):
            problems.append(f"{what}: workspace centre ours {o['centre']} theirs {t['centre']}")
        if o["checks"] != t["checks"] or (o["error"] is None) != (t["error"] is None):
            problems.append(f"{what}: {o['checks']} visibility checks ({o['error']}) vs theirs "
                            f"{t['checks']} ({t['error']})")
        elif o["error"]:
            failed += 1
        else:
            for name in ("wrist_camera", "exo_camera_1"):
                problems += _same_pose(o["cameras"][name], t["cameras"][name], f"{what} {name}")
        agreed += not problems
        bad += problems
    print(f"\neval cameras: {len(ours)} cases ({len(scenes)} episodes x {len(LEVELS)} levels), {agreed} agreed "
          f"({failed} of them: placement fails on both sides), {sum(o['checks'] for o in ours)} visibility checks; "
          f"largest differences {DEVIATION}")
    assert not bad, "\n".join(bad)
    assert 0 < failed < len(ours) // 2  # the stand-ins make some placements hopeless, most not


def test_fixed_and_randomized_droid_systems_place_the_cameras_theirs_do(theirs, scenes, monkeypatch):
    DEVIATION.update(dict.fromkeys(DEVIATION, 0.0))
    cases, ours = [], []
    for i, (raw, scene, fixed) in enumerate(scenes):
        ours.append({"cameras": {n: _world(fixed, n) for n in ("wrist_camera", "exo_camera_1")}, "checks": 0,
                     "error": None, "what": f"episode {i} fixed"})
        cases.append({**scene, "system": "fixed", "oracle": ORACLES[0], "centre": [0.0, 0.0, 0.0]})
        # randomized: both sides draw from one RandomState(seed) in their order (module docstring of
        # molmo_lerobot.cameras.droid: ours seeds two streams from the episode; theirs uses numpy's
        # global generator): same draws in, same cameras out
        env, _, _ = _build(raw, {"system": "droid_randomized"}, monkeypatch)
        objects = franka_mounts.task_objects(env.spec)
        centre = np.mean([*(env.data.xpos[env.body_id(n)] for n in objects), scene["tcp"]], axis=0)
        oracle = {**ORACLES[1 + i % 2], "centre": centre.tolist()}
        rng = np.random.RandomState(1000 + i)
        wrist = env.model.camera("wrist_camera").id
        mount = env.model.camera("robot_0/gripper/wrist_camera").id
        pos, quat, fov = franka_mounts.noisy_mount(env.model.cam_pos[mount], env.model.cam_quat[mount],
                                                   droid.RANDOM_WRIST_FOV, droid.RANDOM_WRIST_NOISE, rng)
        env.model.cam_pos[wrist], env.model.cam_quat[wrist], env.model.cam_fovy[wrist] = pos, quat, fov
        seen = _Visibility(oracle)
        probe = type("Probe", (), {"model": env.model,
                                   "visible_fractions": lambda self, c, b, seen=seen, env=env: seen(env, c, b)})()
        error = None
        try:
            for cam in droid.RANDOM_EXO_CAMERAS:
                placed = franka_mounts.place_until_seen(probe, cam.name, [*objects, "robot_0/gripper/base"],
                                                        cam.attempts, droid.random_exo_draws(cam, centre, rng), "ours")
                c = env.model.camera(cam.name).id
                env.model.cam_pos[c], env.model.cam_quat[c], env.model.cam_fovy[c] = placed
        except ValueError as exc:
            error = str(exc)
        mujoco.mj_forward(env.model, env.data)
        names = ("wrist_camera", *(c.name for c in droid.RANDOM_EXO_CAMERAS))
        ours.append({"cameras": {n: _world(env, n) for n in names}, "checks": seen.checks, "error": error,
                     "what": f"episode {i} randomized"})
        cases.append({**scene, "system": "randomized", "seed": 1000 + i, "objects": objects,
                      "centre": centre.tolist(), "oracle": oracle})
        env.close()
    got = theirs.run("their_cameras:droid_cameras", {"cases": cases})["results"]
    bad, agreed = [], 0
    for o, t in zip(ours, got, strict=True):
        problems = []
        if o["checks"] != t["checks"] or (o["error"] is None) != (t["error"] is None):
            problems.append(f"{o['what']}: {o['checks']} checks ({o['error']}) vs theirs {t['checks']} ({t['error']})")
        else:
            for name, pose in o["cameras"].items():
                if name in t["cameras"]:
                    problems += _same_pose(pose, t["cameras"][name], f"{o['what']} {name}")
                elif not o["error"]:
                    problems.append(f"{o['what']}: {name} placed by us, not by them")
        agreed += not problems
        bad += problems
    print(f"\nDROID systems: {len(ours)} cases ({len(scenes)} fixed, {len(scenes)} randomized), {agreed} agreed, "
          f"{sum(o['checks'] for o in ours)} visibility checks; largest differences {DEVIATION}")
    assert not bad, "\n".join(bad)
