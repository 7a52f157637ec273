"""MolmoSpaces' assets-dir layout: where each scene dataset, object library and grasp library lives.

The mapping ``(scene_dataset, data_split, house_index) → scene XML`` follows MolmoSpaces'
``get_scenes`` exactly:

* ``ithor``: ``scenes/ithor/FloorPlan<i>_physics.xml``; the split comes from ``i % 100``
  (0–12 train, 13–24 val, 25–30 test), so an episode whose ``data_split`` disagrees has no scene;
* ``procthor-10k``: ``scenes/procthor-10k-<split>/``; ``procthor-objaverse`` (and
  ``procthor-100k-debug``): ``scenes/procthor-objaverse-<split>/``; ``holodeck-objaverse``:
  ``scenes/holodeck-objaverse-<split>/``; ``procthor-objaverse-debug``:
  ``scenes/procthor-objaverse-debug/``; in each, ``<split>_<i>_ceiling.xml`` (the default
  ``house_variant``) or ``<split>_<i>.xml`` (``base``);
* ``user``: ``scene_xml_paths[i]`` of the run config.

A scene's metadata (body name → ``asset_id`` …) is the JSON beside it: ``X_ceiling.xml`` →
``X_metadata.json``, ``X.xml`` → ``X_metadata.json``, else the name shortened one ``_`` part at
a time (``FloorPlan1_physics.xml`` → ``FloorPlan1_metadata.json``).
"""

from __future__ import annotations

import json
from pathlib import Path

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.resources import molmospaces as ms_resources

#: The versions MolmoSpaces pins (the resource manager's table; install hints and on-demand installs).
VERSIONS = ms_resources.VERSIONS
OBJECT_VERSIONS = VERSIONS["objects"]
GRASP_VERSIONS = VERSIONS["grasps"]

#: Asset library → its grasp libraries, highest priority first (MolmoSpaces' order).
OBJECT_LIBRARY_TO_GRASP_LIBRARIES = {"thor": ("droid",), "objaverse": ("droid_objaverse",)}

#: Scene dataset name → scene directory under ``scenes/`` (``{split}`` filled per episode).
SCENE_DIRS = {
    "ithor": "ithor",
    "procthor-10k": "procthor-10k-{split}",
    "procthor-objaverse": "procthor-objaverse-{split}",
    "procthor-100k-debug": "procthor-objaverse-{split}",
    "holodeck-objaverse": "holodeck-objaverse-{split}",
    "procthor-objaverse-debug": "procthor-objaverse-debug",
}
SPLITS = ("train", "val", "test")
USER = "user"


class SceneLookupError(MolmoError, LookupError):
    """No scene for an episode's ``(scene_dataset, data_split, house_index)``; says why and where."""


def ithor_split(house_index: int) -> str | None:
    """The split MolmoSpaces assigns to iTHOR ``FloorPlan<house_index>``."""
    k = house_index % 100
    return "train" if k <= 12 else "val" if k <= 24 else "test" if k <= 30 else None


def scene_dir(assets: Path, dataset: str, split: str) -> Path:
    """The directory holding ``dataset``'s scenes of ``split``."""
    if dataset not in SCENE_DIRS:
        raise SceneLookupError(f"unknown MolmoSpaces scene dataset {dataset!r} (known: {', '.join(SCENE_DIRS)})")
    pattern = SCENE_DIRS[dataset]
    if "{split}" in pattern and split not in SPLITS:
        raise SceneLookupError(f"scene dataset {dataset!r}: data_split must be one of {', '.join(SPLITS)}, "
                               f"got {split!r}")
    return assets / "scenes" / pattern.format(split=split)


def scene_xml(assets: Path, dataset: str, split: str, house_index: int, variant: str = "ceiling") -> Path:
    """Where MolmoSpaces keeps the scene XML (it may not be installed: check ``is_file()``)."""
    root = scene_dir(assets, dataset, split)
    if dataset == "ithor":
        want = ithor_split(house_index)
        if house_index < 0 or want is None:
            raise SceneLookupError(f"ithor has no FloorPlan{house_index} (house_index % 100 must be 0..30)")
        if want != split:
            raise SceneLookupError(f"ithor FloorPlan{house_index} belongs to split {want!r}, not data_split {split!r}")
        return root / f"FloorPlan{house_index}_physics.xml"
    if house_index < 0:
        raise SceneLookupError(f"house_index must be >= 0, got {house_index}")
    suffix = "_ceiling" if variant == "ceiling" else ""
    return root / f"{split}_{house_index}{suffix}.xml"


def install_source(dataset: str, split: str) -> str:
    """The resource ``scenes/<source>@<version>`` that holds ``dataset``'s ``split``."""
    source = SCENE_DIRS[dataset].format(split=split)
    version = VERSIONS["scenes"].get(source)
    return f"scenes/{source}@{version}" if version else f"scenes/{source}"


def install_command(resource: str, assets: Path) -> str:
    """The ``molmo-resources`` command that installs ``resource`` on demand into ``assets`` from MolmoSpaces' bucket."""
    return (f"molmo-resources install {resource} --on-demand --remote {ms_resources.BUCKET_URL} "
            f"--cache-dir {ms_resources.cache_dir()} --install-dir {assets}")


def expected_metadata_name(xml: Path) -> str:
    """The metadata file name MolmoSpaces looks for first beside scene ``xml``."""
    name = xml.name
    if "ceiling" in name:
        return name.replace("_ceiling.xml", "_metadata.json")
    return name.replace(".xml", "_metadata.json")


def metadata_path(xml: Path) -> Path | None:
    """The scene metadata JSON that MolmoSpaces reads for scene ``xml``, if one exists."""
    name = xml.name
    direct = xml.with_name(expected_metadata_name(xml))
    if direct.is_file():
        return direct
    parts = name.removesuffix(".xml").split("_")
    while parts:
        candidate = xml.with_name("_".join([*parts, "metadata.json"]))
        if candidate.is_file():
            return candidate
        parts.pop()
    return None


def read_scene_metadata(xml: Path) -> dict:
    """The scene's metadata (``{"objects": {...}}`` at least); empty when it has none."""
    path = metadata_path(xml)
    if path is None:
        return {"objects": {}}
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SceneLookupError(f"{path}: cannot read scene metadata ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("objects", {}), dict):
        raise SceneLookupError(f"{path}: field 'objects' must map body names to objects")
    data.setdefault("objects", {})
    return data
