"""Heterogeneous cooperative dispatcher (thesis case study II).

A robot compatible with one task only (a dedicated robot) always stays on it; a multi-skilled
robot goes where the task weighting of case I says it is needed most, among the tasks it can
serve. Which robot can serve which task comes from the robot and task specifications through
the fleet's compatibility check (size, load capacity, speeds, hardware — thesis Tables 6–7):
the `compatible` parameter lists, per robot, the task numbers it may serve (the scenario runner
fills it in from the fleet's check), or `robots_file`, `tasks_file`, `robot_ids` and `task_ids`
name the fleet's files and the check runs at start-up (see programs/compatibility.py); the
tasks file's `max_team_size` then caps each task's team too, unless `max_team` is given
(programs/teams.py).
"""

from __future__ import annotations

from programs.compatibility import compatible_numbers, team_sizes
from programs.task_weighting import TaskWeighting, lowest_weight
from softplc import Param


class CooperativeDispatcher(TaskWeighting):
    compatible = Param([[1, 2]], "task numbers each robot may serve, one list per robot, e.g. [[1, 2], [2]]")
    robots_file = Param("", "instead of compatible: the fleet's robots file (robots/robots.yaml)")
    tasks_file = Param("", "... and tasks file (robots/tasks.yaml)")
    robot_ids = Param([], "robot ids in the order the robots are bound")
    task_ids = Param([], "task ids in the order the tasks are bound")

    def setup(self) -> None:
        super().setup()
        if self.robots_file:
            self.compatible = compatible_numbers(self.robots_file, self.tasks_file, self.robot_ids, self.task_ids)
            if not self.max_team:
                self.max_team = team_sizes(self.tasks_file, self.task_ids)

    def choose(self, robot: int, weights: list[float], room: list[int]) -> int:
        allowed = self.compatible[robot] if robot < len(self.compatible) else []
        open_tasks = [task for task in self.open_tasks() if task in room]
        if len(allowed) == 1:
            return allowed[0] if allowed[0] in open_tasks else 0  # dedicated: stays on its only task
        return lowest_weight(weights, [task for task in allowed if task in open_tasks])
