"""A worker's allocator: few arenas whatever its threads, free pages handed back (``molmo_lerobot.allocator``)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")

#: eight threads alive at once, each allocating outside Python's small-object allocator; prints the arena count
_THREADS_ALLOCATE = textwrap.dedent("""
    import ctypes, threading
    libc = ctypes.CDLL(None)
    libc.malloc.restype = ctypes.c_void_p
    libc.open_memstream.restype = ctypes.c_void_p
    libc.fclose.argtypes = [ctypes.c_void_p]
    libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
    together = threading.Barrier(8)
    def allocate():
        together.wait()
        libc.malloc(50_000)
        together.wait()
    threads = [threading.Thread(target=allocate) for _ in range(8)]
    for t in threads: t.start()
    for t in threads: t.join()
    buf, size = ctypes.c_char_p(), ctypes.c_size_t()
    stream = libc.open_memstream(ctypes.byref(buf), ctypes.byref(size))
    libc.malloc_info(0, stream)
    libc.fclose(stream)
    print(ctypes.string_at(buf, size.value).decode().count("<heap nr="))
""")


def _arenas(prelude: str, env: dict[str, str] | None = None) -> int:
    import os

    out = subprocess.run([sys.executable, "-c", prelude + _THREADS_ALLOCATE], capture_output=True, text=True,
                         check=True, env={**os.environ, **(env or {})})
    return int(out.stdout.split()[-1])


def test_a_worker_process_shares_two_arenas_among_its_threads():
    """The fork server imports worker_env first: every worker forked from it, and the server, are bounded."""
    assert _arenas("") > 2  # glibc's default: an arena per thread, up to eight per core
    assert _arenas("import molmo_lerobot.runner.worker_env\n") <= 2


def test_a_process_started_with_child_env_is_bounded_too():
    from molmo_lerobot.allocator import child_env

    assert _arenas("", child_env()) <= 2


def test_release_free_memory_returns_freed_pages():
    """300 MB freed below a chunk still in use stays resident until released."""
    code = textwrap.dedent("""
        import ctypes
        from molmo_lerobot.allocator import release_free_memory
        libc = ctypes.CDLL(None)
        libc.malloc.restype = ctypes.c_void_p
        libc.free.argtypes = [ctypes.c_void_p]
        def rss_mb():
            return int(open("/proc/self/statm").read().split()[1]) * 4096 >> 20
        chunks = [libc.malloc(100_000) for _ in range(3000)]
        for c in chunks:
            ctypes.memset(c, 1, 100_000)
        for c in chunks[:-1]:
            libc.free(c)
        before = rss_mb()
        release_free_memory()
        print(before, rss_mb())
    """)
    before, after = map(int, subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                            check=True).stdout.split())
    assert before - after > 200, (before, after)


def test_the_libero_env_server_starts_with_the_bound(tmp_path, monkeypatch):
    from molmo_lerobot.allocator import child_env
    from molmo_lerobot.suites import libero, pipe

    started: dict[str, str] = {}

    class Started(Exception):
        pass

    def popen(*args, env, **kwargs):
        started.update(env)
        raise Started  # no process: only its environment is looked at

    monkeypatch.setattr(pipe.subprocess, "Popen", popen)
    (tmp_path / "bin").mkdir()
    (tmp_path / "bin" / "python").touch()
    (tmp_path / "libero-config").mkdir()
    (tmp_path / "libero-config" / "config.yaml").touch()
    with pytest.raises(Started):
        libero.LiberoSuite(venv=tmp_path)
    assert started.items() >= child_env().items()


def test_a_worker_releases_free_memory_after_each_episode(tmp_path, monkeypatch):
    from molmo_lerobot.benchmark.load import Benchmark, Origin
    from molmo_lerobot.benchmark.task_specs import parse_episode
    from molmo_lerobot.content.tabletop.generate import generate_benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.runner import worker as worker_module
    from molmo_lerobot.runner.plan import EpisodePlanner

    config = {"horizon": 2}
    raw = generate_benchmark("pick", 1, 1, 11, "test")[0][0]
    bench = Benchmark("t", [parse_episode(raw, Plugins())], None, "", tmp_path, [Origin("t.json")])
    plan = EpisodePlanner(RunContext.build(config), bench).plan(0)
    job = worker_module.WorkerJob(config=RunConfig.of(config), policy={"name": "random"}, output_dir=str(tmp_path),
                                  benchmark_name="t", benchmark_sha256="0" * 64)
    worker = worker_module.EpisodeWorker(job, "w0")
    released: list[int] = []
    monkeypatch.setattr(worker_module, "release_free_memory", lambda: released.append(1))
    try:
        for episodes in (1, 2):
            assert worker.run(plan).error is None
            assert len(released) == episodes
    finally:
        worker.close()
