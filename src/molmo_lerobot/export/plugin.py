"""Built-in plugin: ``record=true`` subscribes the LeRobot dataset recorder to the rollout loop."""

from __future__ import annotations

from typing import Any

from molmo_lerobot import hookimpl


@hookimpl
def molmo_recorders(config: dict[str, Any]) -> list[Any]:
    if not config.get("record"):
        return []
    from molmo_lerobot.export.recorder import LeRobotRecorderFactory

    return [LeRobotRecorderFactory.from_config(config)]
