"""Robot and task configuration (`robots/robots.yaml`, `robots/tasks.yaml`), loaded and checked.

A robot states what it is (size, load capacity, speeds, hardware), where it starts and how it is
driven (`driver: sim` in-process, or `driver: remote` for a robot agent over OPC UA). A task
states what a robot needs to serve it (thesis Tables 6 and 7) and where its stations are.
Every mistake is reported as `FILE:LINE:COL: message`, like `tagdb.yaml`.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from softplc.config import did_you_mean, schema_problems
from softplc.config.schema import NAME_PATTERN
from softplc.config.yamlsource import ConfigError, Problem, SourceMap, load_yaml, parse_yaml


class Hardware(enum.Enum):
    """Hardware a robot carries and a task may require (thesis Table 6 columns)."""

    LASER_RANGE_FINDER = "laser_range_finder"
    CAMERA = "camera"
    TWO_WHEEL_DRIVE = "two_wheel_drive"
    SONAR = "sonar"
    GRIPPER = "gripper"


class DriverKind(enum.Enum):
    """How a robot is driven: inside the runtime (`sim`), by its own agent process (`remote`), or as a VDA 5050 vehicle."""

    SIM = "sim"
    REMOTE = "remote"
    VDA5050 = "vda5050"  # a vehicle the VDA 5050 master control drives over MQTT (softplc/adapters/vda5050)


HARDWARE_NAMES = [item.value for item in Hardware]


@dataclass(frozen=True)
class Pose:
    """A planar pose: metres and radians (heading 0 = +x, counter-clockwise)."""

    x: float
    y: float
    heading: float = 0.0


@dataclass(frozen=True)
class Point:
    x: float
    y: float


@dataclass(frozen=True)
class VehicleIdentity:
    """How a VDA 5050 vehicle is addressed: its topics are …/MANUFACTURER/SERIAL_NUMBER/…"""

    manufacturer: str
    serial_number: str
    instant_actions_key: str = "actions"  # "instantActions" for vda-5050-lib's 2.0 vehicles (a 2020 draft's key)


@dataclass(frozen=True)
class RobotSpec:
    """One robot as configured."""

    id: str
    name: str
    length_mm: float
    width_mm: float
    height_mm: float
    load_capacity: float
    max_linear_speed: float  # m/s
    max_angular_speed: float  # rad/s
    hardware: frozenset[Hardware]
    start: Pose
    driver: DriverKind = DriverKind.SIM
    address: str = ""
    vehicle: VehicleIdentity | None = None  # driver: vda5050 only

    @property
    def radius(self) -> float:
        """Radius (m) of the circle around the footprint: what must clear walls and robots."""
        return 0.5 * math.hypot(self.length_mm, self.width_mm) / 1000.0

    def has(self, item: Hardware) -> bool:
        return item in self.hardware


NO_TEAM_LIMIT = 0  # a task's max_team_size when it states none (scenarios; tasks.yaml requires one)


@dataclass(frozen=True)
class TaskSpec:
    """One task (a transport job between two stations) and what it demands of a robot."""

    id: str
    name: str
    max_length_mm: float
    max_width_mm: float
    max_height_mm: float
    min_load_capacity: float
    min_linear_speed: float
    min_angular_speed: float
    max_team_size: int  # most robots serving it at once; NO_TEAM_LIMIT (0): any number
    requires: frozenset[Hardware]
    source: Point | None = None
    destination: Point | None = None


@dataclass
class RobotFile:
    """The robots of a file, in file order, with where each was written."""

    path: Path
    robots: list[RobotSpec]
    source: SourceMap | None = None
    paths: dict[str, tuple[Any, ...]] = field(default_factory=dict)  # robot id → YAML path

    def __getitem__(self, robot_id: str) -> RobotSpec:
        for robot in self.robots:
            if robot.id == robot_id:
                return robot
        raise KeyError(robot_id)

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.robots)

    def __len__(self) -> int:
        return len(self.robots)

    @property
    def ids(self) -> list[str]:
        return [robot.id for robot in self.robots]

    def location(self, robot_id: str, *keys: str) -> str:
        """`FILE:LINE:COL` of a robot (or one of its keys), for messages."""
        if self.source is None or robot_id not in self.paths:
            return str(self.path)
        return str(self.source.value((*self.paths[robot_id], *keys)))


@dataclass
class TaskFile:
    """The tasks of a file, in file order."""

    path: Path
    tasks: list[TaskSpec]

    def __getitem__(self, task_id: str) -> TaskSpec:
        for task in self.tasks:
            if task.id == task_id:
                return task
        raise KeyError(task_id)

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.tasks)

    def __len__(self) -> int:
        return len(self.tasks)

    @property
    def ids(self) -> list[str]:
        return [task.id for task in self.tasks]


# -- schemas ----------------------------------------------------------------------------------

_POSITIVE = {"type": "number", "exclusiveMinimum": 0}
_NON_NEGATIVE = {"type": "number", "minimum": 0}
_HARDWARE_LIST = {"type": "array", "items": {"enum": HARDWARE_NAMES}, "uniqueItems": True}
_POINT = {
    "type": "object",
    "properties": {"x": {"type": "number"}, "y": {"type": "number"}},
    "required": ["x", "y"],
    "additionalProperties": False,
}

ROBOT_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "id": {"type": "string", "pattern": NAME_PATTERN, "description": "Tag prefix, e.g. r01."},
        "name": {"type": "string"},
        "address": {"type": "string", "description": "Network address (informational; remote robots register themselves)."},
        "driver": {"enum": [kind.value for kind in DriverKind],
                   "description": "sim: in-process; remote: robot-agent over OPC UA; vda5050: a VDA 5050 vehicle over MQTT."},
        "vda5050": {
            "type": "object",
            "description": "driver: vda5050 only: the vehicle's topic names (docs/vda5050.md).",
            "properties": {
                "manufacturer": {"type": "string", "pattern": r"^[A-Za-z0-9_.:-]+$"},
                "serial_number": {"type": "string", "pattern": r"^[A-Za-z0-9_.:-]+$"},
                "instant_actions_key": {"enum": ["actions", "instantActions"],
                                        "description": "instantActions for vda-5050-lib's 2.0 vehicles (default actions)."},
            },
            "required": ["manufacturer", "serial_number"],
            "additionalProperties": False,
        },
        "length_mm": _POSITIVE,
        "width_mm": _POSITIVE,
        "height_mm": _POSITIVE,
        "load_capacity": _NON_NEGATIVE,
        "max_linear_speed": _POSITIVE,
        "max_angular_speed": _POSITIVE,
        "hardware": _HARDWARE_LIST,
        "start": {
            "type": "object",
            "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "heading": {"type": "number"}},
            "required": ["x", "y"],
            "additionalProperties": False,
        },
    },
    "required": ["id", "length_mm", "width_mm", "height_mm", "load_capacity", "max_linear_speed", "max_angular_speed", "start"],
    "additionalProperties": False,
}

TASK_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "id": {"type": "string", "pattern": NAME_PATTERN, "description": "Tag prefix, e.g. t01."},
        "name": {"type": "string"},
        "max_length_mm": _POSITIVE,
        "max_width_mm": _POSITIVE,
        "max_height_mm": _POSITIVE,
        "min_load_capacity": _NON_NEGATIVE,
        "min_linear_speed": _NON_NEGATIVE,
        "min_angular_speed": _NON_NEGATIVE,
        "max_team_size": {"type": "integer", "minimum": 1},
        "requires": _HARDWARE_LIST,
        "source": _POINT,
        "destination": _POINT,
    },
    "required": ["id", "max_length_mm", "max_width_mm", "max_height_mm", "min_load_capacity",
                 "min_linear_speed", "min_angular_speed", "max_team_size"],
    "additionalProperties": False,
}


def _file_schema(key: str, item: dict[str, Any]) -> dict[str, Any]:
    return {
        "type": "object",
        "properties": {key: {"type": "array", "items": item, "minItems": 1}},
        "required": [key],
        "additionalProperties": False,
    }


ROBOTS_FILE_SCHEMA = _file_schema("robots", ROBOT_SCHEMA)
TASKS_FILE_SCHEMA = _file_schema("tasks", TASK_SCHEMA)


# -- loading ----------------------------------------------------------------------------------


def load_robots(path: str | Path) -> RobotFile:
    """Load and check a robots file; raise ConfigError listing every problem."""
    data, source = load_yaml(path)
    return _robots_from(Path(path), data, source)


def parse_robots(text: str, path: str | Path = "<robots>") -> RobotFile:
    data, source = parse_yaml(text, str(path))
    return _robots_from(Path(path), data, source)


def load_tasks(path: str | Path) -> TaskFile:
    """Load and check a tasks file; raise ConfigError listing every problem."""
    data, source = load_yaml(path)
    return _tasks_from(Path(path), data, source)


def parse_tasks(text: str, path: str | Path = "<tasks>") -> TaskFile:
    data, source = parse_yaml(text, str(path))
    return _tasks_from(Path(path), data, source)


def _check_structure(data: Any, source: SourceMap, schema: dict[str, Any], key: str) -> list[Any]:
    if not isinstance(data, dict):
        raise ConfigError([source.problem((), f"the file must be a mapping with a '{key}:' list")])
    problems = schema_problems(data, source, schema)
    if problems:
        raise ConfigError(problems)
    return list(data[key])


def _duplicate_ids(items: Sequence[dict[str, Any]], key: str, source: SourceMap) -> list[Problem]:
    seen: dict[str, int] = {}
    problems = []
    for index, item in enumerate(items):
        item_id = item["id"]
        if item_id in seen:
            first = source.value((key, seen[item_id], "id"))
            problems.append(source.problem((key, index, "id"), f"duplicate id '{item_id}' (first used at line {first.line})"))
        else:
            seen[item_id] = index
    return problems


def _vehicle_problems(items: Sequence[dict[str, Any]], source: SourceMap) -> list[Problem]:
    """A VDA 5050 vehicle needs its topic names, no other robot has them, and no two vehicles share them."""
    problems = []
    seen: dict[tuple[str, str], str] = {}
    for index, item in enumerate(items):
        vehicle = item.get("vda5050")
        if item.get("driver") == DriverKind.VDA5050.value and vehicle is None:
            problems.append(source.problem(("robots", index, "driver"), f"robot {item['id']} is a VDA 5050 vehicle: it needs "
                                           "'vda5050: {manufacturer: ..., serial_number: ...}'"))
        elif vehicle is not None and item.get("driver") != DriverKind.VDA5050.value:
            problems.append(source.problem(("robots", index, "vda5050"), f"robot {item['id']} has a vda5050: section but "
                                           f"'driver: {item.get('driver', 'sim')}' (say 'driver: vda5050')", at_key=True))
        elif vehicle is not None:
            key = (vehicle["manufacturer"], vehicle["serial_number"])
            if key in seen:
                problems.append(source.problem(("robots", index, "vda5050", "serial_number"),
                                               f"vehicle {key[0]}/{key[1]} is robot {seen[key]} already"))
            seen.setdefault(key, item["id"])
    return problems


def _hardware(names: Sequence[str]) -> frozenset[Hardware]:
    return frozenset(Hardware(name) for name in names)


def _robots_from(path: Path, data: Any, source: SourceMap) -> RobotFile:
    items = _check_structure(data, source, ROBOTS_FILE_SCHEMA, "robots")
    problems = _duplicate_ids(items, "robots", source) + _vehicle_problems(items, source)
    if problems:
        raise ConfigError(problems)
    robots = []
    paths: dict[str, tuple[Any, ...]] = {}
    for index, item in enumerate(items):
        start = item["start"]
        robots.append(
            RobotSpec(
                id=item["id"],
                name=item.get("name", item["id"]),
                length_mm=float(item["length_mm"]),
                width_mm=float(item["width_mm"]),
                height_mm=float(item["height_mm"]),
                load_capacity=float(item["load_capacity"]),
                max_linear_speed=float(item["max_linear_speed"]),
                max_angular_speed=float(item["max_angular_speed"]),
                hardware=_hardware(item.get("hardware", [])),
                start=Pose(float(start["x"]), float(start["y"]), float(start.get("heading", 0.0))),
                driver=DriverKind(item.get("driver", "sim")),
                address=item.get("address", ""),
                vehicle=VehicleIdentity(item["vda5050"]["manufacturer"], item["vda5050"]["serial_number"],
                                        item["vda5050"].get("instant_actions_key", "actions")) if "vda5050" in item else None,
            )
        )
        paths[item["id"]] = ("robots", index)
    return RobotFile(path, robots, source, paths)


def _tasks_from(path: Path, data: Any, source: SourceMap) -> TaskFile:
    items = _check_structure(data, source, TASKS_FILE_SCHEMA, "tasks")
    problems = _duplicate_ids(items, "tasks", source)
    if problems:
        raise ConfigError(problems)
    tasks = []
    for item in items:
        source_point, destination = item.get("source"), item.get("destination")
        tasks.append(
            TaskSpec(
                id=item["id"],
                name=item.get("name", item["id"]),
                max_length_mm=float(item["max_length_mm"]),
                max_width_mm=float(item["max_width_mm"]),
                max_height_mm=float(item["max_height_mm"]),
                min_load_capacity=float(item["min_load_capacity"]),
                min_linear_speed=float(item["min_linear_speed"]),
                min_angular_speed=float(item["min_angular_speed"]),
                max_team_size=int(item["max_team_size"]),
                requires=_hardware(item.get("requires", [])),
                source=Point(float(source_point["x"]), float(source_point["y"])) if source_point else None,
                destination=Point(float(destination["x"]), float(destination["y"])) if destination else None,
            )
        )
    return TaskFile(path, tasks)


def unknown_id_message(kind: str, wanted: str, known: Sequence[str]) -> str:
    """'no robot 'r9' (did you mean 'r09'?); known: r01, r02' for lookups by id."""
    return f"no {kind} '{wanted}'{did_you_mean(wanted, known)}; known: {', '.join(known) or 'none'}"
