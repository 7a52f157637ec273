"""Worker start-up: the preloaded fork server, the start-up breakdown, GPU placement (pure functions, on CPU).

The end-to-end check that forkserver and spawn workers give the same outcomes is
``tests/test_eval_e2e.py::test_workers_do_not_change_outcomes`` (a forkserver CLI run against a
spawn run, both full scripted episodes).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.forkserver
import sys
import types

import pytest

from molmo_lerobot.runner.forkserver import BASE_PRELOAD, PreloadedForkServer, inherited_gpu_state, preload_modules
from molmo_lerobot.runner.local import ProcessTransport
from molmo_lerobot.runner.placement import Gpu, Placement, nvidia_gpus, place, slot_of, visible_gpus
from molmo_lerobot.runner.worker import Startup, startup_summary

GPUS = [Gpu(0, "GPU-aaaa-0"), Gpu(1, "GPU-bbbb-1"), Gpu(2, "GPU-cccc-2"), Gpu(3, "GPU-dddd-3")]


# Placement ---------------------------------------------------------------------------------------
def test_visible_gpus_follow_cuda_visible_devices():
    assert visible_gpus(GPUS, {}) == GPUS
    assert visible_gpus(GPUS, {"CUDA_VISIBLE_DEVICES": "2,0"}) == [GPUS[2], GPUS[0]]
    assert visible_gpus(GPUS, {"CUDA_VISIBLE_DEVICES": "GPU-bbbb,GPU-dddd-3"}) == [GPUS[1], GPUS[3]]
    assert visible_gpus(GPUS, {"CUDA_VISIBLE_DEVICES": ""}) == []
    assert visible_gpus(GPUS, {"CUDA_VISIBLE_DEVICES": "-1"}) == []
    assert visible_gpus(GPUS, {"CUDA_VISIBLE_DEVICES": "1,7,2"}) == [GPUS[1]]  # CUDA stops at a bad entry
    assert visible_gpus([], {}) == []


def test_workers_go_round_robin_over_the_gpus():
    egl = [place(k, GPUS, {}, {}, "cuda").egl_device for k in range(6)]
    assert egl == [0, 1, 2, 3, 0, 1]
    assert [place(k, GPUS, {}, {}, "cuda").policy_device for k in range(5)] == [f"cuda:{k % 4}" for k in range(5)]
    # CUDA indexes the visible GPUs; EGL enumerates every GPU, so it gets their physical index
    env = {"CUDA_VISIBLE_DEVICES": "2,3"}
    assert [place(k, GPUS, env, {}, "cuda") for k in range(3)] == [
        Placement(2, "cuda:0"), Placement(3, "cuda:1"), Placement(2, "cuda:0")]


def test_configured_lists_and_the_environment_win():
    ex = {"egl_devices": [3], "cuda_devices": [1, 2]}
    assert [place(k, GPUS, {}, ex, "cuda") for k in range(3)] == [
        Placement(3, "cuda:1"), Placement(3, "cuda:2"), Placement(3, "cuda:1")]
    assert place(1, GPUS, {"MUJOCO_EGL_DEVICE_ID": "0"}, {}, None).egl_device is None  # the user's choice stays
    assert place(1, GPUS, {"MUJOCO_EGL_DEVICE_ID": "0"}, {"egl_devices": [2]}, None).egl_device == 2
    assert place(1, GPUS, {}, {"egl_devices": [], "cuda_devices": []}, "cuda") == Placement(None, None)


def test_policy_device_is_chosen_only_where_it_means_a_gpu_of_several():
    assert place(1, GPUS, {}, {}, "cpu").policy_device is None
    assert place(1, GPUS, {}, {}, "cuda:3").policy_device is None  # explicit: kept
    assert place(1, GPUS, {}, {}, None).policy_device is None  # a policy without a device (served, scripted)
    assert place(1, GPUS, {}, {}, "auto").policy_device == "cuda:1"
    assert place(1, GPUS[:1], {}, {}, "auto").policy_device is None  # one GPU: auto finds it
    assert place(0, GPUS, {}, {"cuda_devices": [2]}, "auto").policy_device == "cuda:2"
    assert place(0, [], {}, {}, "cuda") == Placement(None, None)  # no GPU: nothing chosen, the policy decides


def test_bad_device_lists_name_the_key():
    with pytest.raises(ValueError, match=r"executor.egl_devices: expected a list"):
        place(0, GPUS, {}, {"egl_devices": "0,1"}, None)
    with pytest.raises(ValueError, match=r"executor.cuda_devices: expected a list"):
        place(0, GPUS, {}, {"cuda_devices": [-1]}, "cuda")


def test_gpus_are_read_from_the_driver_in_bus_order(tmp_path):
    for bus, uuid in (("0000:c1:00.0", "GPU-2222"), ("0000:41:00.0", "GPU-1111")):
        (tmp_path / bus).mkdir()
        (tmp_path / bus / "information").write_text(f"Model: \t NVIDIA H100\nGPU UUID: \t {uuid}\n")
    assert nvidia_gpus(tmp_path) == [Gpu(0, "GPU-1111"), Gpu(1, "GPU-2222")]
    assert nvidia_gpus(tmp_path / "absent") == []
    assert [slot_of(w) for w in ("w0g0", "w3g12", "actor")] == [0, 3, 0]


# The fork server ---------------------------------------------------------------------------------
def _report(conn):
    conn.send(sorted(m for m in ("colorsys", "molmo_lerobot.runner.worker_env", "tabnanny") if m in sys.modules))
    conn.close()


def test_fork_server_preloads_its_own_modules_and_leaves_the_global_one_alone():
    before = list(multiprocessing.forkserver._forkserver._preload_modules)
    server = PreloadedForkServer(["molmo_lerobot.runner.worker_env", "colorsys"])
    try:
        server.start()
        parent, child = multiprocessing.get_context("forkserver").Pipe()
        proc = server.process(_report, (child,), name="probe")
        proc.start()
        child.close()
        # imported by the server before the fork (nothing the child unpickles imports colorsys)
        assert parent.recv() == ["colorsys", "molmo_lerobot.runner.worker_env"]
        proc.join(30)
        assert proc.exitcode == 0
    finally:
        server.stop()
    assert server.pid is None
    assert multiprocessing.forkserver._forkserver._preload_modules == before


def _exit_zero():
    pass


def test_a_ctrl_c_while_the_fork_server_imports_neither_ends_it_nor_prints_a_traceback(tmp_path, monkeypatch,
                                                                                      capfd):
    """A Ctrl-C at the terminal during worker start-up reaches the fork server, busy importing the preload: it
    carries on (the supervisor decides when to stop), and the next worker starts."""
    import os
    import signal
    import time

    (tmp_path / "slow_preload.py").write_text(f"import pathlib, time\npathlib.Path({str(tmp_path)!r}, 'importing')"
                                              ".touch()\ntime.sleep(2)\n")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), *sys.path]))  # the server's own sys.path
    server = PreloadedForkServer(["molmo_lerobot.runner.worker_env", "slow_preload"])
    try:
        server.start()
        deadline = time.monotonic() + 60
        while not (tmp_path / "importing").exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        assert (tmp_path / "importing").exists(), "the server never imported the slow module"
        os.kill(server.pid, signal.SIGINT)
        proc = server.process(_exit_zero, (), name="after-ctrl-c")
        proc.start()
        proc.join(30)
        assert proc.exitcode == 0
    finally:
        server.stop()
    assert "KeyboardInterrupt" not in capfd.readouterr().err


def test_preload_lists_keep_order_and_start_with_the_worker_environment():
    modules = preload_modules(["plugin_a", "numpy"], ["torch", "plugin_a"])
    assert modules[:len(BASE_PRELOAD)] == list(BASE_PRELOAD) and modules[0] == "molmo_lerobot.runner.worker_env"
    assert modules[len(BASE_PRELOAD):] == ["plugin_a", "torch"]
    with pytest.raises(ValueError, match=r"executor\.start_method: expected one of"):
        ProcessTransport("fork")


def test_a_worker_refuses_gpu_state_it_did_not_create(monkeypatch):
    cuda = types.SimpleNamespace(is_initialized=lambda: False)
    egl = types.SimpleNamespace(EGL_DISPLAY=None)
    monkeypatch.setitem(sys.modules, "torch", types.SimpleNamespace(cuda=cuda))
    monkeypatch.setitem(sys.modules, "mujoco.egl", egl)
    assert inherited_gpu_state() is None
    cuda.is_initialized = lambda: True
    assert inherited_gpu_state() == "a CUDA context"
    cuda.is_initialized = lambda: False
    egl.EGL_DISPLAY = object()
    assert inherited_gpu_state() == "an EGL display"


def test_startup_report_and_summary():
    startup = Startup(launch_s=0.5)
    with startup.phase("policy_s"):
        pass
    startup.phases.update(first_scene_s=2.0, renderer_s=1.0)
    report = startup.report()
    assert report["ready_s"] == pytest.approx(0.5 + report["policy_s"], abs=1e-3)
    assert report["total_s"] == pytest.approx(report["ready_s"] + 3.0, abs=1e-3)
    summary = startup_summary({"w1g0": {"launch_s": 3.0}, "w0g0": {"launch_s": 1.0, "renderer_s": 1.0}})
    assert list(summary["workers"]) == ["w0g0", "w1g0"]
    assert summary["median"] == {"launch_s": 2.0, "renderer_s": 1.0}


def _library_work(conn):
    import cv2
    import numpy as np
    import torch

    image = np.random.default_rng(0).random((1000, 1000, 3), dtype=np.float32)
    blurred = cv2.GaussianBlur(cv2.resize(image, (1500, 1500)), (9, 9), 0)
    x = torch.ones(300, 300)
    conn.send((blurred.shape, float((x @ x)[0, 0])))


@pytest.mark.slow
def test_thread_pools_of_preloaded_policy_libraries_work_in_a_forked_worker():
    """LeRobot's import leaves the server with idle thread pools (OpenCV's, jemalloc's): a forked worker
    still runs OpenCV's and torch's parallel kernels (a deadlock here would time out)."""
    pytest.importorskip("lerobot")
    server = PreloadedForkServer(["molmo_lerobot.runner.worker_env", "torch", "cv2", "lerobot.policies.factory"])
    try:
        server.start()
        parent, child = multiprocessing.get_context("forkserver").Pipe()
        proc = server.process(_library_work, (child,), name="libraries")
        proc.start()
        child.close()
        assert parent.poll(300), "the forked worker hung in a library's thread pool"
        assert parent.recv() == ((1500, 1500, 3), 300.0)
        proc.join(30)
    finally:
        server.stop()
