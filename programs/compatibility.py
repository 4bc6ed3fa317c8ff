"""Which tasks each robot may serve, for dispatchers: from a `compatible` list, or from the fleet's files.

A dispatcher binds its robots and tasks as lists; `compatible` gives, per robot (in that
order), the numbers of the tasks (1-based, in the task order) it may serve. Instead, name the
fleet's robots and tasks files and the ids in binding order, and the fleet's compatibility
check (size, load capacity, speeds, hardware; thesis §4.7.2) works it out, and the tasks'
`max_team_size` gives the dispatcher's team limits (programs/teams.py):

    params:
      robots_file: robots/robots.yaml
      tasks_file: robots/tasks.yaml
      robot_ids: [r01, r02, r03]
      task_ids: [t01, t02]
"""

from __future__ import annotations

from pathlib import Path

from softplc.robotics.compat import Compatibility
from softplc.robotics.robots import load_tasks

PROJECT = Path(__file__).resolve().parent.parent


def _find(path: str) -> Path:
    candidate = Path(path)
    return candidate if candidate.is_absolute() or candidate.exists() else PROJECT / candidate


def compatible_numbers(robots_file: str, tasks_file: str, robot_ids: list[str], task_ids: list[str]) -> list[list[int]]:
    """Per robot id, the numbers of the tasks (position in `task_ids` + 1) it can serve."""
    compat = Compatibility.load(_find(robots_file), _find(tasks_file))  # ConfigError / KeyError say what is wrong
    numbers = {task_id: number for number, task_id in enumerate(task_ids, 1)}
    for task_id in task_ids:
        compat.task(task_id)  # an unknown id raises KeyError with the known ones
    return [sorted(numbers[task] for task in compat.tasks_for(robot) if task in numbers) for robot in robot_ids]


def team_sizes(tasks_file: str, task_ids: list[str]) -> list[int]:
    """Per task id (in `task_ids` order), its `max_team_size` from the tasks file."""
    tasks = load_tasks(_find(tasks_file))  # ConfigError / KeyError say what is wrong
    return [tasks[task_id].max_team_size for task_id in task_ids]
