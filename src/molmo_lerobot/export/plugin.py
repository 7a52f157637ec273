"""Built-in plugin: the report's per-episode glance (thumbnails, first success) on every run, and
``record=true`` subscribes the LeRobot dataset recorder to the rollout loop."""

from __future__ import annotations

from typing import Any

from molmo_lerobot import hookimpl


@hookimpl
def molmo_recorders(config: dict[str, Any]) -> list[Any]:
    from molmo_lerobot.export.glance import GlanceRecorderFactory

    factories: list[Any] = [GlanceRecorderFactory()]
    if config.get("record"):
        from molmo_lerobot.export.recorder import LeRobotRecorderFactory

        factories.append(LeRobotRecorderFactory.from_config(config))
    return factories
