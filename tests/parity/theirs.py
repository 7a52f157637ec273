"""Run code in MolmoSpaces' own virtual environment and get its result back.

The parity venv (``.parity-venv`` at the repository root, built by ``scripts/parity-venv.sh``; another
location through ``MOLMO_PARITY_VENV``) holds the real ``molmo-spaces`` package and its pinned MuJoCo.
A *helper* is a function ``main(inputs: dict) -> dict`` in a module file next to this one
(``tests/parity/<module>.py``); it runs there, in a fresh interpreter, with nothing of ours on its path.

Inputs and outputs cross as one JSON document plus one ``.npz``: a top-level value that is a numpy
array travels in the npz, everything else in the JSON (so keep it JSON-able).

This file is also the entry point on the other side (``python theirs.py MODULE:FUNC IO_DIR``), so it
imports only the standard library and numpy at the top.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
VENV = Path(os.environ.get("MOLMO_PARITY_VENV", HERE.parents[1] / ".parity-venv"))
REQUIRED_ENV = "MOLMO_PARITY_REQUIRED"  # set by `make parity`: a missing venv fails instead of skipping


class TheirError(RuntimeError):
    """The helper failed on MolmoSpaces' side; the message carries its traceback."""


def python() -> Path | None:
    """The parity venv's interpreter, or None when the venv is not built."""
    exe = VENV / "bin" / "python"
    return exe if exe.exists() else None


def _plain(value):
    """numpy scalars (a bool from a comparison, a float64) as their Python value."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON-able: {type(value).__name__}")


def _write(io_dir: Path, stem: str, payload: dict) -> None:
    arrays = {k: v for k, v in payload.items() if isinstance(v, np.ndarray)}
    rest = {k: v for k, v in payload.items() if k not in arrays}
    (io_dir / f"{stem}.json").write_text(json.dumps(rest, default=_plain))
    np.savez(io_dir / f"{stem}.npz", **arrays)


def _read(io_dir: Path, stem: str) -> dict:
    payload = json.loads((io_dir / f"{stem}.json").read_text())
    with np.load(io_dir / f"{stem}.npz") as npz:
        payload.update({k: npz[k] for k in npz.files})
    return payload


def run(helper: str, inputs: dict | None = None, timeout: float = 600) -> dict:
    """Call ``helper`` (``"module:function"``, module in tests/parity/) in the parity venv.

    Raises FileNotFoundError when the venv is missing (the ``theirs`` fixture skips or fails first)
    and TheirError with the other side's stderr when the helper raises.
    """
    exe = python()
    if exe is None:
        raise FileNotFoundError(f"no parity venv at {VENV} (build it with `make parity`)")
    with tempfile.TemporaryDirectory(prefix="molmo-parity-") as tmp:
        io_dir = Path(tmp)
        _write(io_dir, "in", inputs or {})
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
        env.setdefault("MUJOCO_GL", "egl")
        # MolmoSpaces' resource manager works under these: keep it inside this call's temp dir
        env["MLSPACES_ASSETS_DIR"] = str(io_dir / "mlspaces-assets")
        env["MLSPACES_CACHE_DIR"] = str(io_dir / "mlspaces-cache")
        proc = subprocess.run([str(exe), str(Path(__file__).resolve()), helper, str(io_dir)],
                              cwd=io_dir, env=env, capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0:
            raise TheirError(f"{helper} failed in the parity venv (exit {proc.returncode}):\n{proc.stderr[-6000:]}")
        return _read(io_dir, "out")


def contact_table(model, data) -> np.ndarray:
    """One row per contact of an ``mj_forward``-ed state: geom1, geom2, dist, position (3), normal (3),
    force in the contact frame (3). Both sides compute it; where the tables differ, MuJoCo's collision
    or solver differs between the two versions, whatever the rule says."""
    import mujoco

    rows = np.zeros((data.ncon, 12))
    force = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        mujoco.mj_contactForce(model, data, i, force)
        rows[i] = [c.geom1, c.geom2, c.dist, *c.pos, *c.frame[:3], *force[:3]]
    return rows


def same_contacts(a, b, atol: float = 1e-6, force_rtol: float = 1e-3) -> bool:
    """Whether two :func:`contact_table` s hold the same contacts (any order): geoms, distance, position
    and normal within ``atol``, forces within ``force_rtol`` of their size (at least 1 N)."""
    a, b = np.asarray(a, dtype=np.float64).reshape(-1, 12), np.asarray(b, dtype=np.float64).reshape(-1, 12)
    if a.shape != b.shape:
        return False
    a, b = (t[np.lexsort(np.round(t[:, [5, 4, 3, 1, 0]], 5).T)] for t in (a, b))
    scale = np.maximum(1.0, np.abs(a[:, 9:]))
    return bool(np.allclose(a[:, :9], b[:, :9], rtol=0, atol=atol)
                and np.all(np.abs(a[:, 9:] - b[:, 9:]) <= force_rtol * scale))


def offline() -> None:
    """On their side, before importing their task or sampler modules: MolmoSpaces downloads resources
    (scene archives, object annotations, ThOR material tables) on first use; swap them for empty
    ones. The resource manager is not set up (``get_resource_manager`` returns None), the object
    annotation database is empty, and ThOR's two material tables, read at import by
    ``env/arena/randomization/texture.py``, are ``{}`` under this call's ``MLSPACES_ASSETS_DIR``.
    Code that needs a real resource then fails loudly instead of downloading it."""
    thor = Path(os.environ["MLSPACES_ASSETS_DIR"]) / "objects" / "thor"
    thor.mkdir(parents=True, exist_ok=True)
    for name in ("material-database.json", "material_to_textures.json"):
        (thor / name).write_text("{}")
    import molmo_spaces.molmo_spaces_constants as constants
    import molmo_spaces.utils.object_metadata as object_metadata

    constants.get_resource_manager = lambda *args, **kwargs: None
    object_metadata.get_db = lambda: {}


DOC = HERE.parents[1] / "docs" / "parity.md"


def table_row(key: str) -> dict[str, int]:
    """The numeric cells of the docs/parity.md table row whose first cell is ``key``, by column header:
    tests compare their counts with it, so the published table stays true."""
    header: list[str] = []
    for line in DOC.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else []
        if not cells:
            header = []
        elif not header:
            header = cells
        elif cells[0] == key:
            return {h: int(c) for h, c in zip(header, cells, strict=False) if c.isdigit()}
    raise KeyError(f"{DOC}: no table row starting with {key!r}")


def versions(_inputs: dict) -> dict:
    """A helper: what the parity venv runs (for the report and the harness's own test)."""
    from importlib.metadata import version

    import mujoco

    return {"molmo-spaces": version("molmo-spaces"), "mujoco": mujoco.__version__, "python": sys.version.split()[0]}


def _serve(helper: str, io_dir: Path) -> None:
    """The other side: import the helper module from this directory and run it on the inputs."""
    import importlib

    module, func = helper.split(":")  # the module is found next to this file: sys.path[0]
    result = getattr(importlib.import_module(module), func)(_read(io_dir, "in"))
    _write(io_dir, "out", result)


if __name__ == "__main__":
    _serve(sys.argv[1], Path(sys.argv[2]))
