"""The scenario's link to the robot fleet (`softplc.adapters.fleet`): compatibility and simulated robots.

Robots are specified in a scenario with the thesis's Table 6/7 values, which decide what
they may serve. They are *driven* as the thesis's Stage robots were: TurtleBots (0.255 m
square, SPEC §4) on the factory map, at the floor's limits of 0.2 m/s and 0.4 rad/s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from softplc.adapters.fleet.adapter import FleetAdapter
from softplc.app.runtime import Adapter
from softplc.config import PlantConfig
from softplc.robotics.compat import compatible_tasks as compatible
from softplc.robotics.floor import Floor
from softplc.robotics.gridmap import load_map
from softplc.robotics.robots import NO_TEAM_LIMIT, Hardware, Point, Pose, RobotFile, RobotSpec, TaskSpec
from softplc.scenarios.spec import PROJECT, RobotParams, Scenario, TaskParams

MAP = PROJECT / "robots" / "maps" / "factory.yaml"
TURTLEBOT_MM = (255.0, 255.0, 400.0)
ALL_HARDWARE = [item.value for item in Hardware]
_floors: dict[Path, Floor] = {}


def factory_floor(path: Path = MAP) -> Floor:
    """The factory floor with its planners (built once per process: runs share them)."""
    if path not in _floors:
        _floors[path] = Floor(load_map(path))
    return _floors[path]


def robot_spec(robot: RobotParams, *, driven: bool = False) -> RobotSpec:
    """The fleet's RobotSpec: as configured (for compatibility), or as driven (a TurtleBot)."""
    spec: dict[str, Any] = robot.spec
    length, width, height = TURTLEBOT_MM
    if not driven:
        length, width, height = (float(spec.get(key, default)) for key, default in
                                 zip(("length_mm", "width_mm", "height_mm"), TURTLEBOT_MM))
    return RobotSpec(
        id=robot.id,
        name=str(spec.get("name", robot.id)),
        length_mm=length,
        width_mm=width,
        height_mm=height,
        load_capacity=float(spec.get("load_capacity", robot.loadcap)),
        max_linear_speed=0.2 if driven else float(spec.get("max_linear_speed", 0.2)),
        max_angular_speed=0.4 if driven else float(spec.get("max_angular_speed", 0.4)),
        hardware=frozenset(Hardware(name) for name in spec.get("hardware", ALL_HARDWARE)),
        start=Pose(*robot.start),
    )


def task_spec(task: TaskParams) -> TaskSpec:
    """The fleet's TaskSpec; a task that states no requirement accepts any robot."""
    spec: dict[str, Any] = task.spec
    unlimited = float("inf")
    return TaskSpec(
        id=task.id,
        name=str(spec.get("name", task.id)),
        max_length_mm=float(spec.get("max_length_mm", unlimited)),
        max_width_mm=float(spec.get("max_width_mm", unlimited)),
        max_height_mm=float(spec.get("max_height_mm", unlimited)),
        min_load_capacity=float(spec.get("min_load_capacity", 0.0)),
        min_linear_speed=float(spec.get("min_linear_speed", 0.0)),
        min_angular_speed=float(spec.get("min_angular_speed", 0.0)),
        max_team_size=int(spec.get("max_team_size", NO_TEAM_LIMIT)),
        requires=frozenset(Hardware(name) for name in spec.get("requires", [])),
        source=Point(*task.source),
        destination=Point(*task.destination),
    )


def team_sizes(scenario: Scenario) -> list[int]:
    """Per task, the most robots that may serve it at once (NO_TEAM_LIMIT, 0: no limit, when it states none)."""
    return [task_spec(task).max_team_size for task in scenario.tasks]


def compatible_tasks(scenario: Scenario) -> list[list[int]]:
    """Per robot, the numbers (1-based) of the tasks it may serve (the fleet's compatibility check)."""
    tasks = [task_spec(task) for task in scenario.tasks]
    numbers = {task.id: number for number, task in enumerate(tasks, 1)}
    return [[numbers[task.id] for task in compatible(robot_spec(robot), tasks)] for robot in scenario.robots]


def build_fleet_adapter(scenario: Scenario, config: PlantConfig) -> Adapter:
    """The fleet adapter driving the scenario's robots on the factory map."""
    robots = RobotFile(scenario.path, [robot_spec(robot, driven=True) for robot in scenario.robots])
    return FleetAdapter(robots, factory_floor())

