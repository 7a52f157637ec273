"""Load a benchmark (either MolmoSpaces layout, or one JSON file) and hash its content.

Layouts of a directory (a directory holding both is refused as ambiguous):

* ``benchmark.json``: a list of episode objects (+ optional ``benchmark_metadata.json``);
* legacy ``house_<id>/episode_<n>.json`` (any integer ``n``; MolmoSpaces writes 8 digits):
  one episode per file, in MolmoSpaces' order (house directories sorted by name, then episode
  files sorted by name), so episode indices match theirs.

A path to a ``.json`` file is read as a list of episodes or as a single episode.

Every problem in every episode is collected before failing; :class:`BenchmarkError` lists
them one per line as ``<file>: episode <i>: field <path>: <what is wrong>``. Only regular
files are read (a FIFO or device never blocks loading), JSON nested deeper than
:data:`MAX_JSON_DEPTH` is refused, and two episodes with the same content are refused (the
same trial would count twice).
"""

from __future__ import annotations

import json
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from molmo_lerobot.benchmark.schema import BenchmarkMetadata, EpisodeSpec
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.errors import MolmoError
from molmo_lerobot.hashing import canonical_json, content_sha256

if TYPE_CHECKING:
    from molmo_lerobot.plugins import Plugins

BENCHMARK_FILE = "benchmark.json"
METADATA_FILE = "benchmark_metadata.json"
_HOUSE_DIR = re.compile(r"house_(-?\d+)")
_EPISODE_FILE = re.compile(r"episode_-?\d+\.json")
_UNREADABLE = object()  # stands for a file already reported as unreadable
#: Deepest JSON nesting accepted (MolmoSpaces episodes nest about 6 levels).
MAX_JSON_DEPTH = 64
#: Tags the camera union inserts into error locations.
_CAMERA_TAGS = frozenset({"robot_mounted", "exocentric"})


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a benchmark: where (file, episode index, field) and what."""

    file: str
    message: str
    episode_index: int | None = None
    field: str | None = None
    #: the file is valid (MolmoSpaces accepts it) but cannot run here as it stands
    warning: bool = False

    def __str__(self) -> str:
        parts = ["warning: " + self.file] if self.warning else [self.file]
        if self.episode_index is not None:
            parts.append(f"episode {self.episode_index}")
        if self.field:
            parts.append(f"field {self.field}")
        return ": ".join([*parts, self.message])


class BenchmarkError(MolmoError, ValueError):
    """A benchmark that cannot be loaded or used; ``problems`` lists every reason."""

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))


@dataclass(frozen=True)
class Origin:
    """Where an episode was read from: its file and, in a list file, its position there."""

    file: str
    position: int | None = None


@dataclass
class Benchmark:
    """A loaded benchmark. ``episodes[i]`` came from ``origins[i]``."""

    name: str
    episodes: list[EpisodeSpec]
    metadata: BenchmarkMetadata | None
    sha256: str
    path: Path
    origins: list[Origin] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.episodes)

    def where(self, index: int) -> str:
        """``"<file>: episode <index>"``, for messages about one episode."""
        return f"{self.origins[index].file}: episode {index}"


# Hashing -----------------------------------------------------------------------------------


def benchmark_sha256(episodes: list[EpisodeSpec]) -> str:
    """SHA-256 of the canonical JSON of the validated episodes, in order.

    Computed on the parsed models, so key order, whitespace, ``1`` vs ``1.0``, omitted
    defaults and the file layout do not change it; any change of content does.
    """
    data = [ep.model_dump(mode="json") for ep in episodes]
    return content_sha256(data).hex()


# Loading -----------------------------------------------------------------------------------


def load_benchmark(path: str | Path, plugins: Plugins) -> Benchmark:
    """Load and schema-validate a benchmark directory or JSON file; raise :class:`BenchmarkError`.

    Each task is validated with the spec model of the plugin that owns it (see
    :mod:`.task_specs`).
    """
    path = Path(path)
    problems: list[Problem] = []
    raw: list[tuple[Origin, Any]] = []
    metadata: BenchmarkMetadata | None = None

    if path.is_dir():
        bench_file = path / BENCHMARK_FILE
        if bench_file.exists() and _has_legacy_episodes(path):
            problems.append(Problem(str(path), f"ambiguous layout: holds both {BENCHMARK_FILE} and "
                                               "house_<id>/episode_*.json files; keep only one"))
        elif bench_file.exists():
            raw = _read_list_file(bench_file, problems)
        else:
            raw = _read_legacy_dir(path, problems)
            if not raw and not problems:
                problems.append(
                    Problem(str(path), f"no {BENCHMARK_FILE} and no house_<id>/episode_<n>.json files")
                )
        meta_file = path / METADATA_FILE
        if meta_file.is_file():
            metadata = _read_metadata(meta_file, problems)
    elif path.is_file():
        data = _read_json(path, problems)
        if isinstance(data, dict):
            raw = [(Origin(str(path)), data)]
        elif data is not _UNREADABLE:
            raw = _episode_list(path, data, problems)
        meta_file = path.with_name(METADATA_FILE)
        if path.name == BENCHMARK_FILE and meta_file.is_file():
            metadata = _read_metadata(meta_file, problems)
    elif path.exists():
        problems.append(Problem(str(path), "not a regular file or directory"))
    else:
        problems.append(Problem(str(path), "no such benchmark file or directory"))

    episodes: list[EpisodeSpec] = []
    origins: list[Origin] = []
    positions: list[int] = []
    for index, (origin, data) in enumerate(raw):
        if data is _UNREADABLE:
            continue
        if not isinstance(data, dict):
            problems.append(Problem(origin.file, f"expected an episode object, got {_json_type(data)}", index))
            continue
        try:
            episodes.append(parse_episode(data, plugins))
            origins.append(origin)
            positions.append(index)
        except ValidationError as exc:
            problems.extend(Problem(origin.file, msg, index, loc) for loc, msg in validation_messages(exc))
    problems.extend(_duplicates(episodes, origins, positions))
    if not raw and not problems:
        problems.append(Problem(str(path), "benchmark has no episodes"))
    if problems:
        raise BenchmarkError(problems)
    return Benchmark(
        name=_benchmark_name(path, metadata),
        episodes=episodes,
        metadata=metadata,
        sha256=benchmark_sha256(episodes),
        path=path,
        origins=origins,
    )


def _benchmark_name(path: Path, metadata: BenchmarkMetadata | None) -> str:
    if metadata is not None and metadata.name:
        return metadata.name
    if path.is_file():
        return path.parent.name if path.name == BENCHMARK_FILE else path.stem
    return path.resolve().name


def _read_json(file: Path, problems: list[Problem]) -> Any:
    try:
        text = read_regular_file(file)
    except (OSError, UnicodeDecodeError) as exc:
        problems.append(Problem(str(file), f"cannot read: {exc}"))
        return _UNREADABLE
    too_deep = Problem(str(file), f"JSON nested deeper than {MAX_JSON_DEPTH} levels")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        problems.append(Problem(str(file), f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"))
        return _UNREADABLE
    except RecursionError:
        problems.append(too_deep)
        return _UNREADABLE
    if json_depth(data) > MAX_JSON_DEPTH:
        problems.append(too_deep)
        return _UNREADABLE
    return data


def read_regular_file(file: Path) -> str:
    """The UTF-8 text of ``file``; ``OSError`` if it is not a regular file (a FIFO never blocks)."""
    fd = os.open(file, os.O_RDONLY | os.O_NONBLOCK)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError("not a regular file (a FIFO, device or socket)")
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read().decode("utf-8")
    finally:
        os.close(fd)


def json_depth(data: Any) -> int:
    """Nesting depth of parsed JSON (a scalar is 0), computed without recursion."""
    depth, stack = 0, [(data, 1)]
    while stack:
        node, level = stack.pop()
        children = node.values() if isinstance(node, dict) else node if isinstance(node, list) else None
        if children is not None:
            depth = max(depth, level)
            stack.extend((child, level + 1) for child in children)
    return depth


def _has_legacy_episodes(root: Path) -> bool:
    return any(house.is_dir() and any(house.glob("episode_*.json")) for house in root.glob("house_*"))


def _duplicates(episodes: list[EpisodeSpec], origins: list[Origin], positions: list[int]) -> list[Problem]:
    """A problem per episode whose content equals an earlier episode's (``positions``: benchmark indices)."""
    seen: dict[str, int] = {}
    out = []
    for episode, origin, index in zip(episodes, origins, positions, strict=True):
        key = canonical_json(episode)
        if key in seen:
            out.append(Problem(origin.file, f"duplicate of episode {seen[key]} (same content: the same trial "
                                            "would count twice)", index))
        seen.setdefault(key, index)
    return out


def _read_list_file(file: Path, problems: list[Problem]) -> list[tuple[Origin, Any]]:
    data = _read_json(file, problems)
    return [] if data is _UNREADABLE else _episode_list(file, data, problems)


def _episode_list(file: Path, data: Any, problems: list[Problem]) -> list[tuple[Origin, Any]]:
    if not isinstance(data, list):
        problems.append(Problem(str(file), f"expected a list of episode objects, got {_json_type(data)}"))
        return []
    return [(Origin(str(file), i), ep) for i, ep in enumerate(data)]


def _read_legacy_dir(root: Path, problems: list[Problem]) -> list[tuple[Origin, Any]]:
    out: list[tuple[Origin, Any]] = []
    for house_dir in sorted(p for p in root.glob("house_*") if p.is_dir()):
        if not _HOUSE_DIR.fullmatch(house_dir.name):
            problems.append(Problem(str(house_dir), "directory name is not house_<integer>"))
            continue
        for ep_file in sorted(house_dir.glob("episode_*.json")):
            if not _EPISODE_FILE.fullmatch(ep_file.name):
                problems.append(Problem(str(ep_file), "file name is not episode_<integer>.json"))
                continue
            # An unreadable file is already reported; it keeps its slot so later indices stay true.
            out.append((Origin(str(ep_file)), _read_json(ep_file, problems)))
    return out



def _read_metadata(file: Path, problems: list[Problem]) -> BenchmarkMetadata | None:
    data = _read_json(file, problems)
    if data is _UNREADABLE:
        return None
    if not isinstance(data, dict):
        problems.append(Problem(str(file), f"expected an object, got {_json_type(data)}"))
        return None
    try:
        return BenchmarkMetadata.model_validate(data)
    except ValidationError as exc:
        problems.extend(Problem(str(file), msg, None, loc) for loc, msg in validation_messages(exc))
        return None


# Error formatting --------------------------------------------------------------------------


def validation_messages(exc: ValidationError) -> list[tuple[str, str]]:
    """(field path, message) per pydantic error, with union tags removed from the path."""
    out = []
    for err in exc.errors(include_url=False):
        loc = _strip_tags(tuple(err["loc"]))
        kind, msg, value = err["type"], err["msg"], err.get("input")
        if kind == "missing":
            msg = "missing"
        elif kind == "camera_type":
            loc = (*loc, "type")
            shown = value.get("type") if isinstance(value, dict) else value
            msg = f"unknown camera type {shown!r} (expected 'robot_mounted' or 'exocentric')"
        elif kind not in ("vector_length", "vector_finite", "zero_quaternion", "resolution"):
            msg = f"{msg} (got {_short(value)})"
        out.append((format_loc(loc), msg))
    return out


def _strip_tags(loc: tuple) -> tuple:
    """``loc`` without the tags that task and camera validation insert after ``task`` / ``cameras[i]``."""
    if len(loc) > 1 and loc[0] == "task":
        return (loc[0], *loc[2:])
    if len(loc) > 2 and loc[0] == "cameras" and isinstance(loc[1], int) and loc[2] in _CAMERA_TAGS:
        return (*loc[:2], *loc[3:])
    return loc


def format_loc(loc: tuple) -> str:
    """``("cameras", 0, "pos")`` -> ``"cameras[0].pos"``."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _short(value: Any, limit: int = 60) -> str:
    text = json.dumps(value) if isinstance(value, (dict, list, str, int, float, bool, type(None))) else repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _json_type(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean", type(None): "null"}.get(
        type(value), "a number"
    )
