"""Robot motion sequencer (the thesis's robMotion): one instance per robot.

`currloc` walks 0 → 1 → 2 → 3 → 4 → 0:

    0 waiting for a command      the dispatcher's task (`tnext`) → goal = its source
    1 on the way to the source   arrived → 2
    2 at the source              the plant loaded the robot (`loadstat`) → goal = destination
    3 on the way to destination  arrived → 4
    4 at the destination         the plant unloaded it (`loadstat`) → 0

The sequencer only acts while the robot is available: within `reach` (0.3 m) of its goal and
not busy. It sets `status` (busy) with every new goal; the robot itself clears `status` when
it arrives. Task coordinates are bound as lists, task number = position + 1.
"""

from __future__ import annotations

import math

from softplc import InOut, Input, Output, Param, Program

WAITING, TO_SOURCE, AT_SOURCE, TO_DESTINATION, AT_DESTINATION = range(5)


class MotionSequencer(Program):
    xpos = Input("robot x position, m (rNN_xpos)")
    ypos = Input("robot y position, m (rNN_ypos)")
    xgoal = InOut("goal x, m (rNN_xgoal)")
    ygoal = InOut("goal y, m (rNN_ygoal)")
    status = InOut("busy; the robot clears it at its goal (rNN_status)")
    currloc = InOut("motion state 0..4 (rNN_currloc)")
    prevloc = Output("previous motion state (rNN_prevloc)", optional=True)
    tcurr = InOut("task being served (rNN_tcurr)")
    loadstat = InOut("loading/unloading done, set by the plant (rNN_loadstat)")
    tnext = Input("task chosen by the dispatcher for the next trip, 0 = none (rNN_tnext)")
    src_x = Input("source x of every task (tNN_src_x)")
    src_y = Input("source y of every task (tNN_src_y)")
    dest_x = Input("destination x of every task (tNN_dest_x)")
    dest_y = Input("destination y of every task (tNN_dest_y)")
    goals = InOut("goals issued per task, counted here (tNN_goals)", optional=True)
    reach = Param(0.3, "distance to the goal at which the robot counts as there, m")

    def scan(self) -> None:
        if self.status or math.hypot(self.xgoal - self.xpos, self.ygoal - self.ypos) > self.reach:
            return  # travelling
        before = self.currloc
        tasks = len(self.src_x)
        if self.currloc == WAITING:
            task = self.tnext
            if 1 <= task <= tasks:
                self.go(self.src_x[task - 1], self.src_y[task - 1], TO_SOURCE)
                self.tcurr = task
                if self.goals is not None:
                    self.goals[task - 1] += 1
        elif self.currloc in (TO_SOURCE, AT_SOURCE):
            self.currloc = AT_SOURCE
            if self.loadstat and 1 <= self.tcurr <= tasks:
                self.go(self.dest_x[self.tcurr - 1], self.dest_y[self.tcurr - 1], TO_DESTINATION)
                self.loadstat = False
        elif self.currloc in (TO_DESTINATION, AT_DESTINATION):
            self.currloc = AT_DESTINATION
            if self.loadstat:
                self.currloc = WAITING
                self.loadstat = False
        if self.currloc != before and self.prevloc is not None:
            self.prevloc = before

    def go(self, x: float, y: float, state: int) -> None:
        """Send the robot to (x, y): new goal, new motion state, busy."""
        self.xgoal, self.ygoal = x, y
        self.currloc = state
        self.status = True
