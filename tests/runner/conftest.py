"""Fixtures for runner tests: a misbehaving test policy installed as a real plugin distribution.

``faulty_policy`` writes ``molmo_test_policies`` (module + ``*.dist-info`` with an entry point in
the ``molmo_lerobot`` group + a Hydra ``policy/faulty.yaml``) into a temp dir, puts it on
``sys.path`` and ``PYTHONPATH`` (spawned workers inherit ``sys.path``; Ray workers the
environment), so every run context built afterwards finds it. ``policy=faulty`` then holds the
arm still and misbehaves in the episodes named by ``policy.faults={episode_index: kind}``:

* ``sigkill`` — the worker SIGKILLs itself at the first ``act`` of that episode, every attempt;
* ``sigkill_once`` — the same, on the first attempt only (a marker file in ``policy.marker_dir``);
* ``hang`` — ``act`` never returns; ``hang_once`` — the same, on the first attempt only;
* ``raise`` — ``act`` raises ``RuntimeError``;
* ``keyboard_interrupt`` / ``system_exit`` — ``act`` raises ``KeyboardInterrupt`` / calls ``sys.exit(7)``;
* ``nan`` / ``wrong_shape`` — ``act`` returns a non-finite / wrongly shaped arm action.
* ``disk_full_until_fixed`` / ``sigkill_until_fixed`` — ``act`` raises ``OSError(ENOSPC)`` / the worker
  SIGKILLs itself, until ``<marker_dir>/fixed`` exists (the machine was repaired; a resume runs it again).

``policy.act_sleep_s`` slows every ``act``; every attempt appends the worker's pid to
``<marker_dir>/pids-<episode_index>`` at reset (so a test can ``kill -9`` it from outside), and its
parent's (with ``forkserver``, the fork server it came from) to ``parents-<episode_index>``;
``policy.fail_init=true`` makes the policy constructor raise; ``+policy.kill_starts=N`` makes the
first N workers that start after a ``sigkill*`` fault fired SIGKILL themselves while starting.

The distribution also provides a recorder: with ``+trace_dir=D`` every finished episode writes
``D/trace-<episode_index>``, a SHA-256 of every action and joint position of the episode;
``+trace_fail_finalize=true`` makes its run-level ``finalize`` (the export step) raise; while
``D/disk-full`` exists, writing a trace raises ``OSError(ENOSPC)`` (a full disk); on resume it
reports the episodes without a trace file as ``missing`` (they run again).
"""

from __future__ import annotations

import functools
import json
import os
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest

MODULE = textwrap.dedent('''
    """Test-only policies that misbehave on purpose (see tests/runner/conftest.py)."""

    import errno
    import hashlib
    import os
    import signal
    import sys
    import time
    from pathlib import Path

    import numpy as np

    from molmo_lerobot import hookimpl
    from molmo_lerobot.policies.base import Policy, PolicyType
    from molmo_lerobot.recording import Recorder, RecorderFactory


    class FaultyPolicy(Policy):
        needs_images = False

        def __init__(self, cfg):
            if cfg.get("fail_init"):
                raise RuntimeError("faulty policy: refusing to start (fail_init=true)")
            self.faults = {int(k): str(v) for k, v in (cfg.get("faults") or {}).items()}
            self.marker_dir = Path(cfg.get("marker_dir") or ".")
            self.act_sleep_s = float(cfg.get("act_sleep_s") or 0.0)
            self.episode = -1
            kill_starts = int(cfg.get("kill_starts") or 0)
            if kill_starts and any(self.marker_dir.glob("crashed-*")):
                counter = self.marker_dir / "start-kills"
                if len(counter.read_text() if counter.exists() else "") < kill_starts:
                    with open(counter, "a") as f:
                        f.write("x")
                    os.kill(os.getpid(), signal.SIGKILL)

        def reset(self, ctx):
            self.episode = ctx.episode_index
            with open(self.marker_dir / f"pids-{self.episode}", "a") as f:
                f.write(f"{os.getpid()}\\n")
            with open(self.marker_dir / f"parents-{self.episode}", "a") as f:
                f.write(f"{os.getppid()}\\n")

        def act(self, obs):
            kind = self.faults.get(self.episode)
            marker = self.marker_dir / f"crashed-{self.episode}"
            if kind == "sigkill" or (kind == "sigkill_once" and not marker.exists()):
                marker.touch()
                os.kill(os.getpid(), signal.SIGKILL)
            hung = self.marker_dir / f"hung-{self.episode}"
            if kind == "hang" or (kind == "hang_once" and not hung.exists()):
                hung.touch()
                while True:
                    time.sleep(60)
            if kind == "raise":
                raise RuntimeError(f"faulty policy: raising in episode {self.episode}")
            if not (self.marker_dir / "fixed").exists():
                if kind == "disk_full_until_fixed":
                    raise OSError(errno.ENOSPC, "No space left on device", str(self.marker_dir / "scratch"))
                if kind == "sigkill_until_fixed":
                    os.kill(os.getpid(), signal.SIGKILL)
            if kind == "keyboard_interrupt":
                raise KeyboardInterrupt
            if kind == "system_exit":
                sys.exit(7)
            if self.act_sleep_s:
                time.sleep(self.act_sleep_s)
            action = {g: (np.zeros(len(q)) if g == "gripper" else np.array(q, dtype=float))
                      for g, q in obs["qpos"].items()}
            if kind == "nan":
                action["arm"][0] = np.nan
            if kind == "wrong_shape":
                action["arm"] = np.zeros(len(action["arm"]) + 1)
            return action


    def make_faulty(cfg):
        return FaultyPolicy(cfg)


    @hookimpl
    def molmo_policies():
        return [PolicyType("faulty", make_faulty, "holds still; crashes, hangs or errs on request (tests)")]


    @hookimpl
    def molmo_config_dirs():
        return [str(Path(__file__).parent / "conf")]


    class TraceFactory(RecorderFactory):
        def __init__(self, out, fail_finalize=False):
            self.out, self.fail_finalize = Path(out), fail_finalize

        def make(self, worker_id, output_dir):
            return TraceRecorder(self.out)

        def finalize(self, output_dir, results, summary):
            if self.fail_finalize:
                raise OSError("trace export: disk full (trace_fail_finalize=true)")

        def missing(self, output_dir, results):
            return {r.episode_index for r in results
                    if r.error is None and not (self.out / f"trace-{r.episode_index}").exists()}


    class TraceRecorder(Recorder):
        """SHA-256 of every action and joint position of an episode, written when it ends."""

        wants_images = False

        def __init__(self, out):
            self.out, self.digest = out, None

        def start_episode(self, info):
            self.digest = hashlib.sha256()

        def record_step(self, obs, action, reward, success, done):
            for part in (action, obs["qpos"]):
                for key in sorted(part):
                    self.digest.update(np.asarray(part[key], dtype=np.float64).tobytes())

        def end_episode(self, result):
            digest, self.digest = self.digest, None
            if digest is not None and result.error is None:
                path = self.out / f"trace-{result.episode_index}"
                if (self.out / "disk-full").exists():
                    raise OSError(errno.ENOSPC, "No space left on device", str(path))
                self.out.mkdir(parents=True, exist_ok=True)
                path.write_text(digest.hexdigest())


    @hookimpl
    def molmo_recorders(config):
        if not getattr(config, "trace_dir", None):
            return []
        return [TraceFactory(config.trace_dir, bool(getattr(config, "trace_fail_finalize", False)))]
''')

POLICY_YAML = textwrap.dedent("""\
    # Test-only policy (tests/runner/conftest.py): holds still, misbehaves in the episodes of `faults`.
    name: faulty
    faults: {}
    marker_dir: null
    act_sleep_s: 0.0
    fail_init: false
""")


def write_test_distribution(root: Path) -> Path:
    """Write the ``molmo_test_policies`` distribution into ``root`` (a future ``sys.path`` entry)."""
    pkg = root / "molmo_test_policies"
    (pkg / "conf" / "policy").mkdir(parents=True)
    (pkg / "__init__.py").write_text(MODULE)
    (pkg / "conf" / "policy" / "faulty.yaml").write_text(POLICY_YAML)
    info = root / "molmo_test_policies-0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: molmo-test-policies\nVersion: 0.0\n")
    (info / "entry_points.txt").write_text("[molmo_lerobot]\nmolmo_test_policies = molmo_test_policies\n")
    return root


@pytest.fixture(scope="session")
def test_distribution(tmp_path_factory) -> Path:
    """The ``molmo_test_policies`` distribution, written once: every test installing it has the same
    ``sys.path`` and ``PYTHONPATH``, so its runs can share fork servers (the ``fork_servers`` fixture)."""
    return write_test_distribution(tmp_path_factory.mktemp("site"))


@pytest.fixture
def faulty_policy(test_distribution, tmp_path, monkeypatch):
    """Install ``policy=faulty`` for this test; yields its ``marker_dir`` and ``sys.path`` entry."""
    root = test_distribution
    markers = tmp_path / "markers"
    markers.mkdir()
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(root), os.environ.get("PYTHONPATH")) if p))
    sys.modules.pop("molmo_test_policies", None)
    yield SimpleNamespace(marker_dir=markers, site=root)
    sys.modules.pop("molmo_test_policies", None)


@pytest.fixture(scope="session")
def small_bench(tmp_path_factory) -> Path:
    """An 8-episode pick benchmark (4 houses x 2) generated into a temp dir."""
    from molmo_lerobot.benchmark.output import write_benchmark
    from molmo_lerobot.content.tabletop.generate import generate_benchmark

    episodes, metadata = generate_benchmark("pick", 4, 2, seed=7, name="pick_small")
    return write_benchmark(tmp_path_factory.mktemp("bench") / "pick_small", episodes, metadata)


def _eval_config(bench: Path, out: Path, *overrides: str):
    """Composed ``molmo-eval`` config for ``bench`` writing to ``out`` (no progress bar)."""
    from molmo_lerobot.config import compose

    return compose([f"benchmark.path={bench}", f"output_dir={out}", "progress=false", *overrides])


def _outcomes(run_dir: Path) -> list[dict]:
    """The ``episodes.jsonl`` contract fields (plus task type and horizon) of a run, by episode."""
    keys = ("episode_index", "house_index", "task_cls", "success", "success_once", "steps", "seed", "error",
            "task_type", "horizon")
    rows = [json.loads(line) for line in (run_dir / "episodes.jsonl").read_text().splitlines() if line.strip()]
    return [{k: r.get(k) for k in keys} for r in sorted(rows, key=lambda r: r["episode_index"])]


@pytest.fixture
def eval_config():
    """``eval_config(bench, out, *overrides)``: a composed run config (call after ``faulty_policy``)."""
    return _eval_config


@pytest.fixture
def outcomes():
    """``outcomes(run_dir)``: the per-episode outcome fields of a run, sorted by episode."""
    return _outcomes


def _traces(trace_dir: Path) -> dict[int, str]:
    return {int(p.name.split("-")[1]): p.read_text() for p in sorted(trace_dir.glob("trace-*"))}


@pytest.fixture
def traces():
    """``traces(trace_dir)``: ``{episode_index: sha256 of its actions and joint positions}``."""
    return _traces


SUBREAPER = textwrap.dedent(r'''
    """Run molmo-eval as a child of this process, made a child subreaper (Linux): whatever
    molmo-eval leaves behind (orphaned workers, unreaped helpers) becomes our child. Optionally
    send it a signal once files reach a number of lines. Prints one JSON line."""

    import ctypes, json, os, signal, subprocess, sys, time
    from pathlib import Path

    plan = json.loads(sys.argv[1])
    ctypes.CDLL(None).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER

    def children():
        out = []
        for task in Path(f"/proc/{os.getpid()}/task").iterdir():
            out += [int(p) for p in (task / "children").read_text().split()]
        return out

    def state(pid):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:120]
        except OSError:
            return "gone", ""
        return stat.rsplit(")", 1)[1].split()[0], cmd

    # output to files, not pipes: a worker left running would hold a pipe open forever
    logs = {name: open(plan["log_prefix"] + name, "w+") for name in ("stdout", "stderr")}
    proc = subprocess.Popen([sys.executable, "-m", "molmo_lerobot.cli.eval", *plan["args"]], **logs)
    signalled = None
    if plan.get("signal"):
        def ready():
            return all(Path(p).exists() and len(Path(p).read_text().splitlines()) >= n for p, n in plan["when"])
        deadline = time.monotonic() + plan.get("when_timeout_s", 180)
        while proc.poll() is None and not ready() and time.monotonic() < deadline:
            time.sleep(0.05)
        if proc.poll() is None:
            os.kill(proc.pid, plan["signal"])
            signalled = time.monotonic()
    try:
        proc.wait(timeout=plan.get("timeout_s", 300))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    exited = time.monotonic()
    stdout, stderr = (Path(f.name).read_text() for f in logs.values())
    # orphans still running after a grace period (a stopped worker may take a moment to end)
    deadline = time.monotonic() + plan.get("orphan_grace_s", 0.0)
    while time.monotonic() < deadline and any(state(p)[0] not in ("Z", "gone") for p in children()):
        time.sleep(0.1)
    left = {str(p): state(p) for p in children()}
    for pid in left:
        try:
            os.kill(int(pid), signal.SIGKILL)
            os.waitpid(int(pid), 0)
        except (ProcessLookupError, ChildProcessError):
            pass
    print(json.dumps({"rc": proc.returncode, "stdout": stdout, "stderr": stderr, "left": left,
                      "exit_after_signal_s": None if signalled is None else exited - signalled}))
''')


def _run_cli(log_dir: Path, *args: str, signal: int | None = None, when: list[tuple[Path, int]] = (),
             orphan_grace_s: float = 0.0, timeout_s: float = 200) -> dict:
    """Run ``molmo-eval *args`` under a child subreaper; see ``SUBREAPER``. Returns its report:
    ``rc``, ``stdout``, ``stderr``, ``left`` (pid → (state, cmdline) of every process it left
    behind, zombies included) and ``exit_after_signal_s``."""
    import subprocess

    plan = {"args": list(args), "signal": signal, "when": [(str(p), n) for p, n in when],
            "orphan_grace_s": orphan_grace_s, "timeout_s": timeout_s,
            "log_prefix": str(log_dir / "molmo-eval.")}
    env = dict(os.environ, MUJOCO_GL="egl")
    out = subprocess.run([sys.executable, "-c", SUBREAPER, json.dumps(plan)], capture_output=True, text=True,
                         env=env, timeout=timeout_s + 60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture
def run_cli(tmp_path):
    """``run_cli(*args, signal=…, when=[(file, lines)], orphan_grace_s=…)``: molmo-eval under a subreaper."""
    return functools.partial(_run_cli, tmp_path)
