"""Optimal-assignment dispatcher: Hungarian assignment of idle robots to tasks (a baseline
none of the thesis's algorithms had).

Each scan, every idle robot (`currloc` 0) gets a task by `scipy.optimize.linear_sum_assignment`
over a cost matrix of robots × task slots (each task once per idle robot, so several robots may
share a task). The cost of robot r on task t is the expected seconds of driving per item
delivered, divided by the share of the task's output storage still to fill:

    drive  = (|robot → source| + |source → destination|) / speed
    items  = what the robot can expect to load: the buffer now, plus what arrives while it
             drives there, minus what robots already heading there (or earlier slots) take,
             at most its free capacity and the storage's room (at least 0.5, so an empty
             buffer is costly but not impossible)
    cost   = drive / items / (room / capacity)

Incompatible pairs (the fleet's compatibility check, parameter `compatible`) and full
storages are masked out (`robots_file`/`tasks_file` instead of `compatible`: see
programs/compatibility.py). A task has as many slots as its team has room for (`max_team`, one
number per task, 0 = no limit; from the tasks file's `max_team_size` with `tasks_file`; see
programs/teams.py). Robots already on a trip keep `tnext` = 0.
"""

from __future__ import annotations

import math

import numpy as np

from programs.bindings import check_lengths
from programs.compatibility import compatible_numbers, team_sizes
from programs.teams import NO_LIMIT, members
from softplc import Input, Output, Param, Program
from softplc.util.assignment import linear_sum_assignment  # scipy.optimize's, without the rest of scipy.optimize

IDLE = 0
HEADING_TO_SOURCE = (1, 2)
MASKED = 1e12  # a finite "impossible", so the solver always finds an assignment


class OptimalAssignment(Program):
    # per task
    iBM = Input("input buffer items (tNN_iBM)")
    iFr = Input("input fill rate, items per minute (tNN_iFr)")
    qSM = Input("output storage items (tNN_qSM)")
    qSC = Input("output storage capacity (tNN_qSC)")
    src_x = Input("source x (tNN_src_x)")
    src_y = Input("source y (tNN_src_y)")
    dest_x = Input("destination x (tNN_dest_x)")
    dest_y = Input("destination y (tNN_dest_y)")
    cost = Output("lowest assignment cost per task at the last decision, s per item, 0 = masked (tNN_Tw)", optional=True)
    # per robot
    xpos = Input("robot x (rNN_xpos)")
    ypos = Input("robot y (rNN_ypos)")
    loadcap = Input("load capacity (rNN_loadcap)")
    load = Input("items on the robot (rNN_load)")
    currloc = Input("motion state (rNN_currloc)")
    tcurr = Input("task being served (rNN_tcurr)")
    tnext = Output("task assigned for the next trip, 0 = none (rNN_tnext)")
    compatible = Param([[1, 2]], "task numbers each robot may serve, one list per robot")
    robots_file = Param("", "instead of compatible: the fleet's robots file (programs/compatibility.py)")
    tasks_file = Param("", "... and tasks file")
    robot_ids = Param([], "robot ids in the order the robots are bound")
    task_ids = Param([], "task ids in the order the tasks are bound")
    speed = Param(0.2, "robot speed used to estimate driving time, m/s")
    max_team = Param([], "most robots serving each task at once, one number per task (0 or none: no limit)")

    def setup(self) -> None:
        self.checked = False
        if self.robots_file:
            self.compatible = compatible_numbers(self.robots_file, self.tasks_file, self.robot_ids, self.task_ids)
            if not self.max_team:
                self.max_team = team_sizes(self.tasks_file, self.task_ids)

    def scan(self) -> None:
        if not self.checked:
            check_lengths(self, "iBM", "iFr", "qSM", "qSC", "src_x", "src_y", "dest_x", "dest_y", "cost")
            check_lengths(self, "currloc", "xpos", "ypos", "loadcap", "load", "tcurr", "tnext")
            if len(self.max_team) > len(self.iBM):
                raise ValueError(f"'max_team' has {len(self.max_team)} numbers for {len(self.iBM)} tasks: give one per task")
            self.checked = True
        tasks, robots = len(self.iBM), len(self.currloc)
        idle = [r for r in range(robots) if self.currloc[r] == IDLE]
        team = members(self.tcurr, self.currloc, tasks)
        limits = [int(limit) for limit in self.max_team] + [NO_LIMIT] * (tasks - len(self.max_team))
        # each task once per idle robot, or as often as its team has room
        places = [len(idle) if limits[t] <= NO_LIMIT else max(0, min(len(idle), limits[t] - team[t])) for t in range(tasks)]
        claimed = [0.0] * tasks  # items robots already heading to a source will take
        in_flight = [0.0] * tasks  # items on their way to a storage
        for r in range(robots):
            task = self.tcurr[r] - 1
            if self.currloc[r] != IDLE and 0 <= task < tasks:
                if self.currloc[r] in HEADING_TO_SOURCE:
                    claimed[task] += self.loadcap[r] - self.load[r]
                in_flight[task] += self.load[r]
        assigned = [0] * robots
        costs = [math.inf] * tasks
        if idle:
            slots = [(t, k) for t in range(tasks) for k in range(places[t])]
            matrix = np.full((len(idle), len(slots)), MASKED)
            for row, r in enumerate(idle):
                for column, (t, k) in enumerate(slots):
                    value = self.pair_cost(r, t, k, claimed[t], in_flight[t])
                    if value is not None:
                        matrix[row, column] = value
                        costs[t] = min(costs[t], value) if k == 0 else costs[t]
            rows, columns = linear_sum_assignment(matrix)
            for row, column in zip(rows, columns):
                if matrix[row, column] < MASKED:
                    assigned[idle[row]] = slots[column][0] + 1
        self.tnext = assigned
        if self.cost is not None and idle:  # held between decisions, so the record shows the last one
            self.cost = [c if math.isfinite(c) else 0.0 for c in costs]

    def pair_cost(self, r: int, t: int, slot: int, claimed: float, in_flight: float) -> float | None:
        """Expected driving seconds per delivered item, urgency-weighted; None when masked."""
        allowed = self.compatible[r] if r < len(self.compatible) else []
        room = self.qSC[t] - self.qSM[t] - in_flight
        if t + 1 not in allowed or room <= 0 or self.qSC[t] <= 0:
            return None
        to_source = math.hypot(self.src_x[t] - self.xpos[r], self.src_y[t] - self.ypos[r])
        carry = math.hypot(self.dest_x[t] - self.src_x[t], self.dest_y[t] - self.src_y[t])
        drive = (to_source + carry) / self.speed
        free = self.loadcap[r] - self.load[r]
        arriving = self.iFr[t] / 60.0 * to_source / self.speed
        available = self.iBM[t] + arriving - claimed - slot * free
        items = max(0.5, min(available, free, room))
        return drive / items / (room / self.qSC[t])
