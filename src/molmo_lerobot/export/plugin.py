"""Built-in plugin: the report's per-episode glance (thumbnails, first success) on every run, and
``record=true`` subscribes the LeRobot dataset recorder to the rollout loop."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from molmo_lerobot import hookimpl

if TYPE_CHECKING:
    from molmo_lerobot.dataset_layout import DatasetLayout
    from molmo_lerobot.run_config import RunConfig


@hookimpl
def molmo_recorders(config: RunConfig, dataset_layout: DatasetLayout | None) -> list[Any]:
    from molmo_lerobot.export.glance import GlanceRecorderFactory

    factories: list[Any] = [GlanceRecorderFactory()]
    if config.record:
        from molmo_lerobot.export.recorder import LeRobotRecorderFactory

        factories.append(LeRobotRecorderFactory.from_config(config, dataset_layout))
    return factories
