"""The model behind the plant overview: map, stations, tasks, robots and their compatibility.

Built once at start from the configuration (the `fleet:` section's robots, tasks and map) and
the tags that exist, so it fits any plant: a task's buffer bars appear only for the tags it has
(`t01_iBM`, `t01_iBL`...), a robot is drawn from `rNN_xpos`/`rNN_ypos` and whatever else of
its tags exist. A plant without a fleet gets an overview of its tag groups instead.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from softplc.adapters.hmi.mapimage import MapImage, render_map
from softplc.config.yamlsource import ConfigError

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig
    from softplc.core.tagdb import TagDatabase

log = logging.getLogger(__name__)

ROBOT_FIELDS = ("xpos", "ypos", "heading", "speed", "navstate", "navreason", "route", "radius", "status", "tcurr",
                "tnext", "currloc", "prevloc", "load", "loadcap", "online", "xgoal", "ygoal")
TASK_FIELDS = ("iBM", "iBL", "iBC", "iFr", "qSM", "qSL", "qSC", "qFr", "Tw", "goals", "src_x", "src_y", "dest_x",
               "dest_y", "sCDr", "sPPi", "sPD")
GROUP_PREVIEW = 8  # tags shown per group on the overview of a plant without a fleet


class PlantModel:
    """What the overview and the robots page show, with the tag names behind each figure."""

    def __init__(self, config: PlantConfig, db: TagDatabase) -> None:
        self.name = config.name
        self.description = config.description
        self.map: MapImage | None = None
        self.robots: list[dict[str, Any]] = []
        self.tasks: list[dict[str, Any]] = []
        self.compatibility: dict[str, dict[str, dict[str, Any]]] = {}
        self.groups = _groups(db)
        names = set(db.names())
        try:
            self._load_fleet(config, names)
        except (ConfigError, OSError, ValueError, KeyError) as error:
            # `softplc check` reports fleet problems; the HMI still serves the rest of the plant.
            log.warning("HMI: the overview shows no fleet: %s", error)
            self.map, self.robots, self.tasks, self.compatibility = None, [], [], {}

    @property
    def has_fleet(self) -> bool:
        return bool(self.robots)

    def describe(self) -> dict[str, Any]:
        fleet = None
        if self.has_fleet:
            fleet = {
                "map": {**self.map.describe(), "url": "/api/plant/map.png"} if self.map else None,
                "robots": self.robots,
                "tasks": self.tasks,
                "compatibility": self.compatibility,
            }
        return {"name": self.name, "description": self.description, "fleet": fleet, "groups": self.groups}

    def _load_fleet(self, config: PlantConfig, names: set[str]) -> None:
        from softplc.robotics.compat import incompatibilities
        from softplc.robotics.layout import fleet_files, has_fleet
        from softplc.robotics.robots import load_robots, load_tasks

        if not has_fleet(config):
            return
        files = fleet_files(config)  # `softplc check` has told of a missing file already
        robots = load_robots(files["robots"])
        tasks = load_tasks(files["tasks"]) if files["tasks"].is_file() else None
        self.map = render_map(files["map"]) if files["map"].is_file() else None
        for robot in robots:
            self.robots.append({
                "id": robot.id,
                "name": robot.name,
                "driver": robot.driver.value,
                "address": robot.address,
                "hardware": sorted(item.value for item in robot.hardware),
                "size_mm": [robot.length_mm, robot.width_mm, robot.height_mm],
                "radius": robot.radius,
                "load_capacity": robot.load_capacity,
                "max_linear_speed": robot.max_linear_speed,
                "max_angular_speed": robot.max_angular_speed,
                "tags": _tags(robot.id, ROBOT_FIELDS, names),
            })
        for task in tasks or ():
            self.tasks.append({
                "id": task.id,
                "name": task.name,
                "number": _number(task.id),
                "source": {"x": task.source.x, "y": task.source.y} if task.source else None,
                "destination": {"x": task.destination.x, "y": task.destination.y} if task.destination else None,
                "max_team_size": task.max_team_size,
                "requires": sorted(item.value for item in task.requires),
                "limits": {"max_size_mm": [task.max_length_mm, task.max_width_mm, task.max_height_mm],
                           "min_load_capacity": task.min_load_capacity, "min_linear_speed": task.min_linear_speed,
                           "min_angular_speed": task.min_angular_speed},
                "tags": _tags(task.id, TASK_FIELDS, names),
            })
            for robot in robots:
                reasons = incompatibilities(robot, task)
                self.compatibility.setdefault(robot.id, {})[task.id] = {"ok": not reasons, "why": reasons}


def _tags(prefix: str, fields: tuple[str, ...], names: set[str]) -> dict[str, str]:
    """{field: tag name} for the fields whose tag `PREFIX_FIELD` exists."""
    return {field: f"{prefix}_{field}" for field in fields if f"{prefix}_{field}" in names}


def _number(task_id: str) -> int | None:
    """The task number a robot's `tcurr` holds for this task ('t02' → 2), if the id ends in one."""
    digits = "".join(ch for ch in task_id if ch.isdigit())
    return int(digits) if digits else None


def _groups(db: TagDatabase) -> list[dict[str, Any]]:
    """Tag groups (browse folders) in declaration order, with a few tags each; `_sys` last."""
    groups: dict[str, list[str]] = {}
    for tag in db:
        group = tag.definition.group or "(no group)"
        groups.setdefault(group, []).append(tag.name)
    ordered = sorted(groups.items(), key=lambda item: item[0].startswith("_sys"))
    return [{"name": name, "count": len(tags), "preview": tags[:GROUP_PREVIEW]} for name, tags in ordered]
