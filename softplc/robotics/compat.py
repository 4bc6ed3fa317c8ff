"""Robot–task compatibility (thesis §4.7.2, Appendix E; SPEC §3), as a library for programs.

A robot can serve a task when its length, width and height are each at most the task's maximum,
its load capacity, linear and angular speed each at least the task's minimum, and it carries
every hardware item the task requires.

    compat = Compatibility.load("robots/robots.yaml", "robots/tasks.yaml")
    compat.check("r01", "t02")          # the thesis's checkRobTaskCompat
    compat.tasks_for("r01")             # getCompatTasks → ["t01", "t02"]
    compat.robots_for("t01")            # getCompatRobots → ["r01", "r03"]
    compat.matrix()                     # {"r01": {"t01": True, "t02": True}, ...}
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from softplc.robotics.robots import (
    RobotFile,
    RobotSpec,
    TaskFile,
    TaskSpec,
    load_robots,
    load_tasks,
    unknown_id_message,
)


def incompatibilities(robot: RobotSpec, task: TaskSpec) -> list[str]:
    """Why `robot` cannot serve `task` (empty when it can)."""
    reasons = []
    for what, have, limit in (
        ("length", robot.length_mm, task.max_length_mm),
        ("width", robot.width_mm, task.max_width_mm),
        ("height", robot.height_mm, task.max_height_mm),
    ):
        if have > limit:
            reasons.append(f"{what} {have:g} mm > {limit:g} mm")
    for what, have, need, unit in (
        ("load capacity", robot.load_capacity, task.min_load_capacity, ""),
        ("linear speed", robot.max_linear_speed, task.min_linear_speed, " m/s"),
        ("angular speed", robot.max_angular_speed, task.min_angular_speed, " rad/s"),
    ):
        if have < need:
            reasons.append(f"{what} {have:g}{unit} < {need:g}{unit}")
    for item in sorted(task.requires - robot.hardware, key=lambda hardware: hardware.value):
        reasons.append(f"no {item.value.replace('_', ' ')}")
    return reasons


def compatible(robot: RobotSpec, task: TaskSpec) -> bool:
    """True when `robot` can serve `task`."""
    return not incompatibilities(robot, task)


def compatible_tasks(robot: RobotSpec, tasks: Iterable[TaskSpec]) -> list[TaskSpec]:
    """The tasks `robot` can serve, in the given order."""
    return [task for task in tasks if compatible(robot, task)]


def compatible_robots(task: TaskSpec, robots: Iterable[RobotSpec]) -> list[RobotSpec]:
    """The robots that can serve `task`, in the given order."""
    return [robot for robot in robots if compatible(robot, task)]


def compatibility_matrix(robots: Iterable[RobotSpec], tasks: Iterable[TaskSpec]) -> dict[str, dict[str, bool]]:
    """{robot id: {task id: compatible}} for every pair."""
    task_list = list(tasks)
    return {robot.id: {task.id: compatible(robot, task) for task in task_list} for robot in robots}


@dataclass
class Compatibility:
    """Compatibility queries by id over a robots file and a tasks file."""

    robots: RobotFile
    tasks: TaskFile

    @classmethod
    def load(cls, robots: str | Path = "robots/robots.yaml", tasks: str | Path = "robots/tasks.yaml") -> Compatibility:
        """Load both files (ConfigError with FILE:LINE:COL on mistakes)."""
        return cls(load_robots(robots), load_tasks(tasks))

    def robot(self, robot_id: str) -> RobotSpec:
        try:
            return self.robots[robot_id]
        except KeyError:
            raise KeyError(unknown_id_message("robot", robot_id, self.robots.ids)) from None

    def task(self, task_id: str) -> TaskSpec:
        try:
            return self.tasks[task_id]
        except KeyError:
            raise KeyError(unknown_id_message("task", task_id, self.tasks.ids)) from None

    def check(self, robot_id: str, task_id: str) -> bool:
        """Can robot `robot_id` serve task `task_id`? (KeyError for an unknown id.)"""
        return compatible(self.robot(robot_id), self.task(task_id))

    def why_not(self, robot_id: str, task_id: str) -> list[str]:
        return incompatibilities(self.robot(robot_id), self.task(task_id))

    def tasks_for(self, robot_id: str) -> list[str]:
        """Ids of the tasks robot `robot_id` can serve."""
        return [task.id for task in compatible_tasks(self.robot(robot_id), self.tasks)]

    def robots_for(self, task_id: str) -> list[str]:
        """Ids of the robots that can serve task `task_id`."""
        return [robot.id for robot in compatible_robots(self.task(task_id), self.robots)]

    def matrix(self) -> dict[str, dict[str, bool]]:
        return compatibility_matrix(self.robots, self.tasks)
