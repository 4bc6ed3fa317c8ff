"""Task-weighting dispatcher (thesis case study I, Figure 5.1 and matHand_algo's runTaskAlgo).

For every task, each scan:

    x1 = 1 / (iFr * (iBL / iBC))          0 when undefined (empty buffer, zero rate)
    x2 = 1 / sPPi                         0 when undefined (zero profit index)
    x3 = (qFr - sCDr) + (qSL - sPD) * 0.2 + 0.1
    Tw = x1 * x2 * x3

The task with the lowest (most negative) weight gets the next free robot; ties go to the
lower task number. Every robot's `tnext` gets that task; the motion sequencer takes it when
the robot is free. Tasks are bound as lists (task number = position + 1), robots too.

The thesis stopped its runs when the first output storage was full, and its formula does not
see a full storage (it would keep sending robots there). `skip_full: true` (not the thesis)
leaves tasks whose output storage is full out of the choice, for runs that go on until every
storage is full.

`max_team` (one number per task, 0 = no limit, the default) caps how many robots serve a task
at once; it needs the robots' `tcurr` and `currloc` bound to count them (programs/teams.py).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

from programs.bindings import check_lengths
from programs.teams import Teams, assign, make_teams
from softplc import Input, Output, Param, Program


def _ratio(numerator: float, denominator: float) -> float:
    """numerator / denominator, or 0 when that is undefined (the thesis's `except: x = 0`)."""
    try:
        result = numerator / denominator
    except ZeroDivisionError:
        return 0.0
    return result if math.isfinite(result) else 0.0


def task_weight(iFr: float, iBL: float, iBC: float, sPPi: float, qFr: float, qSL: float, sCDr: float, sPD: float) -> float:
    """The thesis's task weight Tw = x1 * x2 * x3 (lower means more urgent)."""
    x1 = _ratio(1.0, iFr * _ratio(iBL, iBC))
    x2 = _ratio(1.0, sPPi)
    x3 = (qFr - sCDr) + (qSL - sPD) * 0.2 + 0.1
    return x1 * x2 * x3


def lowest_weight(weights: Sequence[float], allowed: Iterable[int] | None = None) -> int:
    """Task number (1-based) with the lowest weight among `allowed` (all if None); 0 if none."""
    candidates = range(1, len(weights) + 1) if allowed is None else sorted(set(allowed))
    best, best_weight = 0, math.inf
    for number in candidates:
        if 1 <= number <= len(weights) and weights[number - 1] < best_weight:  # strict: ties keep the lower number
            best, best_weight = number, weights[number - 1]
    return best


class TaskWeighting(Program):
    iFr = Input("input fill rate per task (tNN_iFr)")
    iBL = Input("input buffer level % per task (tNN_iBL)")
    iBC = Input("input buffer capacity per task (tNN_iBC)")
    sPPi = Input("profit per product index per task (tNN_sPPi)")
    qFr = Input("output fill rate per task (tNN_qFr)")
    qSL = Input("output storage level % per task (tNN_qSL)")
    sCDr = Input("consumer demand rate per task (tNN_sCDr)")
    sPD = Input("current product demand % per task (tNN_sPD)")
    Tw = Output("task weight per task (tNN_Tw)")
    tnext = Output("task chosen for each robot's next trip (rNN_tnext)")
    tcurr = Input("task each robot is serving (rNN_tcurr), to count teams for max_team", optional=True)
    currloc = Input("motion state of each robot (rNN_currloc), to count teams for max_team", optional=True)
    skip_full = Param(False, "leave tasks whose output storage is full out of the choice (not the thesis)")
    max_team = Param([], "most robots serving each task at once, one number per task (0 or none: no limit)")

    def setup(self) -> None:
        self.checked = False
        self.teams: Teams | None = None

    def scan(self) -> None:
        if not self.checked:
            tasks = check_lengths(self, "iFr", "iBL", "iBC", "sPPi", "qFr", "qSL", "sCDr", "sPD", "Tw")
            check_lengths(self, "tnext", "tcurr", "currloc")
            self.teams = make_teams(self, tasks)
            self.checked = True
        weights = self.Tw = self.weights()
        self.tnext = assign(self.teams, self.now, len(self.tnext), self.tcurr, self.currloc,
                            lambda robot, room: self.choose(robot, weights, room), range(1, len(weights) + 1))

    def open_tasks(self) -> list[int]:
        """Numbers of the tasks a robot may be sent to (all, or those with room with skip_full)."""
        return [n for n, level in enumerate(self.qSL, 1) if not (self.skip_full and level >= 100.0)]

    def weights(self) -> list[float]:
        return [
            task_weight(*values)
            for values in zip(self.iFr, self.iBL, self.iBC, self.sPPi, self.qFr, self.qSL, self.sCDr, self.sPD)
        ]

    def choose(self, robot: int, weights: list[float], room: list[int]) -> int:
        """The task for robot number `robot` (0-based) among the tasks with `room` in their team: the lowest weight."""
        return lowest_weight(weights, [task for task in self.open_tasks() if task in room])
