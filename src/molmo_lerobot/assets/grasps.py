"""Grasp libraries: NPZ files of TCP poses ``transforms`` (N, 4, 4) in the object frame.

Layout of a grasp library directory, keyed by robot and UID::

    <root>/<robot>/<uid>.npz                 rigid objects
    <root>/<robot>/<uid>/<joint>.npz         articulated objects, one file per joint

Counting grasps reads the ``.npy`` header inside the NPZ only, never the array.
The built-in library is written by ``molmo-resources grasps generate``; until then its
lookups fall back to computing the analytic grasps, so a fresh clone works. Plugins provide
grasp libraries beyond those shipped with an asset library as :class:`GraspLibraryType` s.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.fileio import atomic_open
from molmo_lerobot.paths import home_dir

KEY = "transforms"


class GraspError(MolmoError, LookupError):
    """No grasps for a UID/robot, or a grasp file is malformed (the message names the file)."""


def _check(transforms: np.ndarray, where: str) -> np.ndarray:
    if transforms.ndim != 3 or transforms.shape[1:] != (4, 4) or transforms.shape[0] == 0:
        raise GraspError(f"{where}: '{KEY}' must have shape (N, 4, 4) with N > 0, got {transforms.shape}")
    if not np.all(np.isfinite(transforms)):
        raise GraspError(f"{where}: '{KEY}' holds non-finite values")
    return transforms


def load_grasp_file(path: str | os.PathLike) -> np.ndarray:
    """The ``transforms`` array of one NPZ file, validated."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            if KEY not in npz.files:
                raise GraspError(f"{path}: no '{KEY}' array (has {sorted(npz.files)})")
            return _check(np.asarray(npz[KEY], dtype=np.float64), str(path))
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise GraspError(f"{path}: not a readable NPZ file ({exc})") from None


def count_grasp_file(path: str | os.PathLike) -> int:
    """Number of grasps in an NPZ file, from the ``.npy`` header only."""
    try:
        with zipfile.ZipFile(path) as zf, zf.open(f"{KEY}.npy") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, _ = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, _, _ = np.lib.format.read_array_header_2_0(fh)
            else:
                raise GraspError(f"{path}: unsupported .npy format version {version}")
    except KeyError:
        raise GraspError(f"{path}: no '{KEY}' array") from None
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise GraspError(f"{path}: not a readable NPZ file ({exc})") from None
    if len(shape) != 3 or shape[1:] != (4, 4):
        raise GraspError(f"{path}: '{KEY}' must have shape (N, 4, 4), got {shape}")
    return int(shape[0])


def save_grasp_file(path: str | os.PathLike, transforms: np.ndarray, *, root: str | os.PathLike | None = None) -> Path:
    """Write ``transforms`` to ``path`` atomically (uncompressed, so counts stay header reads).

    ``root``: the cache (or output) dir ``path`` lies below; no directory from it down may be a
    link (:mod:`molmo_lerobot.fileio`). Without it, ``path``'s missing parents are made.
    """
    path = Path(path)
    transforms = _check(np.asarray(transforms, dtype=np.float64), str(path))
    with atomic_open(path, "wb", root=root, parents=root is None) as fh:
        np.savez(fh, transforms=transforms)  # the array is named KEY
    return path


class GraspLibrary:
    """A directory of grasp files (see the module docstring).

    ``robot`` is ``None`` for libraries keyed by robot (one subdirectory each); libraries made
    for one robot (MolmoSpaces' ``droid``, a user library's ``name/<robot>``) name it.
    """

    robot: str | None = None

    def __init__(self, root: str | os.PathLike, name: str | None = None) -> None:
        self.root = Path(root)
        self.name = name or self.root.name

    def path(self, uid: str, robot: str = "franka", joint: str | None = None) -> Path | None:
        path = self.root / robot / (f"{uid}/{joint}.npz" if joint else f"{uid}.npz")
        return path if path.is_file() else None

    def joints(self, uid: str, robot: str = "franka") -> list[str]:
        """Joints with their own grasp file (articulated objects)."""
        d = self.root / robot / uid
        return sorted(p.stem for p in d.glob("*.npz")) if d.is_dir() else []

    def has(self, uid: str, robot: str = "franka", joint: str | None = None) -> bool:
        return self.path(uid, robot, joint) is not None

    def load(self, uid: str, robot: str = "franka", joint: str | None = None) -> np.ndarray | None:
        path = self.path(uid, robot, joint)
        return None if path is None else load_grasp_file(path)

    def count(self, uid: str, robot: str = "franka", joint: str | None = None) -> int | None:
        path = self.path(uid, robot, joint)
        return None if path is None else count_grasp_file(path)

    def __repr__(self) -> str:
        return f"GraspLibrary({self.name!r}, {str(self.root)!r})"


def builtin_grasp_dir() -> Path:
    """Where ``grasps generate`` writes the built-in grasps (``$MOLMO_LEROBOT_HOME/grasps/builtin``)."""
    return home_dir() / "grasps" / "builtin"


class BuiltinGraspLibrary(GraspLibrary):
    """Grasps of the built-in objects: generated NPZ files, else the analytic grasps computed now
    for the robot's hand (robots in :data:`~molmo_lerobot.assets.builtin.HANDS`)."""

    def __init__(self, root: str | os.PathLike | None = None) -> None:
        super().__init__(root or builtin_grasp_dir(), name="builtin")

    def has(self, uid: str, robot: str = "franka", joint: str | None = None) -> bool:
        from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, HANDS

        return super().has(uid, robot, joint) or (uid in BUILTIN_OBJECTS and robot in HANDS and joint is None)

    def load(self, uid: str, robot: str = "franka", joint: str | None = None) -> np.ndarray | None:
        from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, HANDS, analytic_grasps

        got = super().load(uid, robot, joint)
        if got is not None or joint is not None or robot not in HANDS:
            return got
        return analytic_grasps(BUILTIN_OBJECTS[uid], HANDS[robot]) if uid in BUILTIN_OBJECTS else None

    def count(self, uid: str, robot: str = "franka", joint: str | None = None) -> int | None:
        got = super().count(uid, robot, joint)
        if got is None and self.has(uid, robot, joint):
            grasps = self.load(uid, robot, joint)
            return None if grasps is None else len(grasps)
        return got


def generate_builtin_grasps(out: str | os.PathLike | None = None, robot: str = "franka") -> list[Path]:
    """Write ``<out>/<robot>/<uid>.npz`` for every built-in object; returns the files written."""
    from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, HANDS, analytic_grasps

    if robot not in HANDS:
        raise GraspError(f"analytic built-in grasps exist for robots {sorted(HANDS)} only, not {robot!r}")
    root, base = (Path(out), Path(out)) if out is not None else (builtin_grasp_dir(), home_dir())
    return [save_grasp_file(root / robot / f"{uid}.npz", analytic_grasps(obj, HANDS[robot]), root=base)
            for uid, obj in sorted(BUILTIN_OBJECTS.items())]
