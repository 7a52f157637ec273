"""Render profiles: how a benchmark's scenes look, part of the trial a run evaluates.

A profile names the lighting knobs that change every frame a policy sees: whether lights cast
shadows and at what shadow-map size, whether materials reflect, the offscreen multisampling,
the largest texture side and an exposure (a factor on every light, the headlight included).
:meth:`RenderProfile.apply` sets them on a compiled model; a knob left ``None`` keeps what the
scene built. A benchmark names its profile in ``benchmark_metadata.json`` (``render_profile``);
one that names none runs :data:`DEFAULT_PROFILE` (``v2``: every scene exactly as it builds, the
look of every benchmark published before profiles existed).

The environment variables that changed the look before profiles (``MOLMO_SCENE_SHADOWS``,
``MOLMO_SCENE_TEXTURE_SIZE``) are overrides of the profile: :func:`resolve_profile` applies them
and lists them in :attr:`RenderProfile.overrides`, so a run records them (``results.json``
``render_profile``) and ``resume`` / ``molmo-compare`` see them.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot.errors import MolmoError

#: the profile of a benchmark whose metadata names none
DEFAULT_PROFILE = "v2"
#: MuJoCo's own offscreen multisampling (``visual/quality/offsamples``)
MUJOCO_OFFSAMPLES = 4
#: largest texture side scenes read (pixels; 0 = as shipped); every named profile keeps it, and only
#: ``MOLMO_SCENE_TEXTURE_SIZE`` changes it (scenes read that variable at build)
DEFAULT_TEXTURE_SIZE = 512
_OFF = ("0", "false", "no", "off")


@dataclass(frozen=True)
class RenderProfile:
    """A named look. ``None`` knobs keep what the scene builds (see the module docstring)."""

    name: str
    #: lights cast shadows as the scene says (``None``) or none do (``False``)
    shadows: bool | None = None
    #: shadow-map side in pixels where shadows are cast (``None``: the scene's)
    shadow_size: int | None = None
    #: materials reflect as authored (``None``) or none do (``False``)
    reflections: bool | None = None
    #: offscreen multisamples (``None``: the scene's, MuJoCo's default 4; ``0``: none)
    multisample: int | None = None
    #: largest texture side in pixels (0: as shipped)
    texture_size: int = DEFAULT_TEXTURE_SIZE
    #: factor on every light's ambient, diffuse and specular colour and on the headlight's
    exposure: float = 1.0
    #: environment variables that changed this profile, ``{name: value}``
    overrides: Mapping[str, str] = field(default_factory=dict)

    def apply(self, model: mujoco.MjModel) -> None:
        """Set this profile's knobs on ``model`` (before any renderer is made for it)."""
        if self.shadows is False:
            model.light_castshadow[:] = 0
        if self.shadow_size is not None:
            model.vis.quality.shadowsize = self.shadow_size
        if self.reflections is False:
            model.mat_reflectance[:] = 0.0
        if self.multisample is not None:
            model.vis.quality.offsamples = self.multisample
        if self.exposure != 1.0:
            e = self.exposure
            model.light_ambient[:] *= e
            model.light_diffuse[:] *= e
            model.light_specular[:] *= e
            head = model.vis.headlight
            head.ambient, head.diffuse, head.specular = (np.asarray(head.ambient) * e, np.asarray(head.diffuse) * e,
                                                         np.asarray(head.specular) * e)

    def record(self) -> dict[str, Any]:
        """The JSON a run records and a resume or comparison checks; the environment's overrides come right
        after the name, so a refusal names the variable that changed the look rather than a setting it set."""
        out = dataclasses.asdict(self)
        return {"name": out.pop("name"), "overrides": dict(out.pop("overrides")), **out}

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> RenderProfile:
        return cls(**{**record, "overrides": dict(record.get("overrides") or {})})


#: the named profiles; ``v2`` is every scene as it builds, ``v3`` the cheap look of the ``*_v3`` benchmarks
PROFILES: Mapping[str, RenderProfile] = {
    "v2": RenderProfile("v2"),
    "v3": RenderProfile("v3", shadows=False, reflections=False, multisample=0, exposure=0.9),
}


class RenderProfileError(MolmoError, ValueError):
    """An unknown profile name; the message names it."""


def resolve_profile(name: str | None, environ: Mapping[str, str] | None = None) -> RenderProfile:
    """The profile ``name`` (``None``: :data:`DEFAULT_PROFILE`) with the environment's overrides applied."""
    environ = os.environ if environ is None else environ
    key = DEFAULT_PROFILE if name is None else name
    if key not in PROFILES:
        raise RenderProfileError(f"render_profile: unknown profile {key!r} (known: {', '.join(PROFILES)})")
    profile = PROFILES[key]
    changes: dict[str, Any] = {}
    overrides: dict[str, str] = {}
    raw = environ.get("MOLMO_SCENE_SHADOWS")
    if raw is not None:
        overrides["MOLMO_SCENE_SHADOWS"] = raw
        if raw.strip().lower() in _OFF:
            changes["shadows"] = False
    raw = environ.get("MOLMO_SCENE_TEXTURE_SIZE")
    if raw is not None:
        overrides["MOLMO_SCENE_TEXTURE_SIZE"] = raw
        changes["texture_size"] = parse_texture_size(raw)
    return dataclasses.replace(profile, **changes, overrides=overrides) if overrides else profile


def parse_texture_size(raw: str) -> int:
    """``MOLMO_SCENE_TEXTURE_SIZE``: 0 (as shipped) or a side of at least 16 pixels."""
    try:
        size = int(raw)
    except ValueError:
        raise ValueError(f"MOLMO_SCENE_TEXTURE_SIZE must be an integer, got {raw!r}") from None
    if size < 0 or (0 < size < 16):
        raise ValueError(f"MOLMO_SCENE_TEXTURE_SIZE must be 0 (full size) or at least 16, got {size}")
    return size
