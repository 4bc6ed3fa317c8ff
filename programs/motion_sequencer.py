"""Robot motion sequencer (the thesis's robMotion): one instance per robot.

`currloc` walks 0 → 1 → 2 → 3 → 4 → 0:

    0 waiting for a command      the dispatcher's task (`tnext`) → goal = its source
    1 on the way to the source   arrived → 2
    2 at the source              the plant loaded the robot (`loadstat`) → goal = destination
    3 on the way to destination  arrived → 4
    4 at the destination         the plant unloaded it (`loadstat`) → 0

It sets `status` (busy) with every new goal; the robot itself clears `status` when it arrives.
A robot has arrived when it has cleared `status` within 0.5 m of its goal: one rule, shared with
the robot's driver (softplc/robotics/arrival.py). The thesis's robMotion waited for 0.3 m while its
robots stopped at 0.5 m; two robots sent to one station then stood still for good. A robot
that cleared `status` farther out gave up on the trip (its navigation failed): after
`retry_after` seconds the sequencer asks it again (status busy, same goal). Task coordinates
are bound as lists, task number = position + 1.

Beyond the thesis: with `park_after` > 0, a robot left without a task (`tnext` 0) for that
long drives back to where it started, so it does not stand on a station other robots need
(the thesis's dispatchers always had a task for every robot). A task arriving meanwhile
takes over at once.

With `navstate` bound (rNN_navstate), a robot whose driver reports it `offline` (a VDA 5050
vehicle the master control lost, which gave its task back) takes no new trip until it is back.
"""

from __future__ import annotations

from programs.bindings import check_lengths
from softplc import TON, InOut, Input, Output, Param, Program
from softplc.robotics.arrival import has_arrived, has_given_up, within_goal

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
    navstate = Input("the driver's navigation state (rNN_navstate): offline robots take no new trip", optional=True)
    retry_after = Param(10.0, "seconds before a trip the robot gave up on is asked again", duration=True)
    park_after = Param(0.0, "seconds without a task before the robot drives back to its start (0: never)", duration=True)

    def setup(self) -> None:
        self.home: tuple[float, float] | None = None
        self.idle = TON(self.clock)
        self.gave_up = TON(self.clock)

    def scan(self) -> None:
        if self.home is None:
            check_lengths(self, "src_x", "src_y", "dest_x", "dest_y", "goals")
            self.home = (self.xpos, self.ypos)  # where the robot started: its parking place
        tasks = len(self.src_x)
        has_task = 1 <= self.tnext <= tasks
        waiting = self.currloc == WAITING
        parking = waiting and self.status and (self.xgoal, self.ygoal) == self.home
        # Without a task a stopped robot is free wherever it stands; on a trip, only once it arrived.
        available = parking or (not self.status and (waiting or has_arrived(self.xpos, self.ypos, self.xgoal, self.ygoal, self.status)))
        without_work = available and not parking and waiting and not has_task
        park_now = self.idle(IN=without_work and self.park_after > 0, PT=self.park_after)
        failed = not waiting and has_given_up(self.xpos, self.ypos, self.xgoal, self.ygoal, self.status)
        if self.gave_up(IN=failed, PT=self.retry_after):
            self.status = True  # ask again: the robot retries the same goal
            return
        if not available or (self.navstate == "offline" and self.currloc == WAITING):
            return  # travelling (or waiting to retry), or away
        before = self.currloc
        if self.currloc == WAITING:
            task = self.tnext
            if has_task:
                self.go(self.src_x[task - 1], self.src_y[task - 1], TO_SOURCE)
                self.tcurr = task
                if self.goals is not None:
                    self.goals[task - 1] += 1
            elif park_now and not self.at(*self.home):
                self.go(*self.home, WAITING)  # out of the way until there is work
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

    def at(self, x: float, y: float) -> bool:
        return within_goal(self.xpos, self.ypos, x, y)

    def go(self, x: float, y: float, state: int) -> None:
        """Send the robot to (x, y): new goal, new motion state, busy."""
        self.xgoal, self.ygoal = x, y
        self.currloc = state
        self.status = True
