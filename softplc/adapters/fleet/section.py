"""The `fleet:` section of tagdb.yaml: its schema and the checks a schema cannot make."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.config.schema import DURATION, NAME_PATTERN, Section

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

SCHEMA: dict[str, Any] = {
    "description": "Mobile robots driven by the runtime (softplc.adapters.fleet; docs/robots.md).",
    "type": "object",
    "properties": {
        "enabled": {"type": "boolean", "description": "false: no robot is driven (default true)."},
        "robots": {"type": "string", "description": "Robots file, relative to this one (default robots/robots.yaml)."},
        "tasks": {"type": "string", "description": "Tasks file (default robots/tasks.yaml)."},
        "map": {"type": "string", "description": "Occupancy map YAML, ROS map_server format (default robots/maps/factory.yaml)."},
        "template": {"type": "string", "pattern": NAME_PATTERN, "description": "Template whose instances are the robots' tags (default robot)."},
        "cycle": DURATION,
        "max_linear_speed": {"type": "number", "exclusiveMinimum": 0, "description": "Floor speed limit, m/s (default 0.2)."},
        "max_angular_speed": {"type": "number", "exclusiveMinimum": 0, "description": "Floor turn-rate limit, rad/s (default 0.4)."},
        "planning_resolution": {"type": "number", "exclusiveMinimum": 0, "description": "Cell size of the A* grid, m (default 0.1)."},
        "heartbeat_timeout": DURATION,
    },
    "additionalProperties": False,
}


def problems(config: PlantConfig) -> list[Problem]:
    """Files that do not exist and durations that are not positive (the files' contents are the adapter's)."""
    if config.section("fleet") is None:
        return []
    from softplc.adapters.fleet.settings import FleetSettings
    from softplc.config.yamlsource import ConfigError

    try:
        FleetSettings.from_config(config)
    except ConfigError as error:
        return list(error.problems)
    return []


SECTION = Section(path=("fleet",), schema=SCHEMA, problems=problems)
