"""The `fleet:` section of tagdb.yaml: which robots, tasks and map, and how fast they are driven."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.config.yamlsource import ConfigError
from softplc.robotics.layout import DEFAULT_MAP, DEFAULT_ROBOTS, DEFAULT_TASKS, fleet_files, fleet_section, has_fleet
from softplc.util.durations import parse_duration

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig

__all__ = ["DEFAULT_MAP", "DEFAULT_ROBOTS", "DEFAULT_TASKS", "FleetSettings"]


@dataclass(frozen=True)
class FleetSettings:
    """Resolved fleet settings (paths absolute, durations in seconds)."""

    robots: Path
    tasks: Path
    map: Path
    enabled: bool = True
    template: str = "robot"
    cycle: float = 0.1
    max_linear_speed: float = 0.2  # floor speed limit (thesis §3.7)
    max_angular_speed: float = 0.4
    planning_resolution: float = 0.1
    heartbeat_timeout: float = 3.0

    @classmethod
    def from_config(cls, config: PlantConfig) -> FleetSettings:
        """Settings from `config.raw['fleet']` (defaults when the section is missing)."""
        section: dict[str, Any] = fleet_section(config)
        source = config.source

        def duration(key: str, default: float) -> float:
            if key not in section:
                return default
            try:
                seconds = parse_duration(section[key])
            except (TypeError, ValueError) as error:
                seconds = -1.0
                message = str(error)
            else:
                message = "must be greater than zero"
            if seconds <= 0:
                where = source.problem(("fleet", key), f"bad {key} {section[key]!r}: {message}") if source else None
                raise ConfigError([where] if where else [])
            return seconds

        files = fleet_files(config)
        missing = [
            source.problem(("fleet", key) if key in section else ("fleet",), f"{key} file not found: {file}", at_key=key not in section)
            for key, file in files.items()
            # The adapter reads robots and map; the tasks file is for compatibility and dispatchers.
            if not file.is_file() and source is not None and (key != "tasks" or key in section)
        ]
        if missing:
            raise ConfigError(missing)
        return cls(
            robots=files["robots"],
            tasks=files["tasks"],
            map=files["map"],
            enabled=bool(section.get("enabled", True)),
            template=section.get("template", "robot"),
            cycle=duration("cycle", 0.1),
            max_linear_speed=float(section.get("max_linear_speed", 0.2)),
            max_angular_speed=float(section.get("max_angular_speed", 0.4)),
            planning_resolution=float(section.get("planning_resolution", 0.1)),
            heartbeat_timeout=duration("heartbeat_timeout", 3.0),
        )

    @classmethod
    def configured(cls, config: PlantConfig) -> bool:
        """True when the plant has a `fleet:` section (the adapter is started only then)."""
        return has_fleet(config)
