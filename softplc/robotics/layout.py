"""Where a plant's fleet is described: the robots, tasks and map files named by its `fleet:` section.

The fleet adapter drives the robots from these files; the HMI draws them, and the scenarios
read them. The section itself (its schema and checks) belongs to the fleet adapter
(softplc/adapters/fleet/section.py); this is only where its files are, with their defaults.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig

DEFAULT_ROBOTS = "robots/robots.yaml"
DEFAULT_TASKS = "robots/tasks.yaml"
DEFAULT_MAP = "robots/maps/factory.yaml"
FILES = (("robots", DEFAULT_ROBOTS), ("tasks", DEFAULT_TASKS), ("map", DEFAULT_MAP))


def has_fleet(config: PlantConfig) -> bool:
    """True when the plant has a `fleet:` section."""
    return isinstance(config.raw.get("fleet"), dict)


def fleet_section(config: PlantConfig) -> dict[str, Any]:
    """The `fleet:` mapping (empty when there is none)."""
    section = config.raw.get("fleet")
    return section if isinstance(section, dict) else {}


def fleet_files(config: PlantConfig) -> dict[str, Path]:
    """{"robots", "tasks", "map"} → the file's path (relative names resolved beside the plant file)."""
    section = fleet_section(config)
    return {key: config.base_dir / str(section.get(key, default)) for key, default in FILES}
