"""Plant simulator of the material-handling plant (the thesis's matHand_sim).

Every task has an input buffer that fills by one item every 60 / iFr seconds while below
100 %, and an output storage. A robot standing at a task's source (`tcurr` = the task's
number, `currloc` = 2) is loaded with min(iBM, room on the robot) and gets `loadstat`; at the
destination (`currloc` = 4) it is unloaded into the output storage and gets `loadstat`. The
motion sequencer (programs/motion_sequencer.py) clears `loadstat` when it moves the robot on.

Tasks and robots are bound as lists, so one instance serves any number of each; a task's
number is its position in the lists (1, 2, ...), as in the thesis's `tcurr`.

`handling_time` is how long a robot stands at a station before it is loaded or unloaded. The
thesis's robots paused 5 s after reaching every goal before taking the next (its robot code,
Appendix B), which is the same thing seen from the plant; the default is 0 (instantaneous).

Two deliberate differences from matHand_sim, both to keep every item accounted for:
- a robot is loaded or unloaded once per visit (matHand_sim repeated it on every pass while
  the robot stood there, overwriting `load`);
- an output storage never overfills: what does not fit stays on the robot (matHand_sim let
  qSM pass qSC, but the run ends at 100 % anyway).
"""

from __future__ import annotations

from programs.bindings import check_lengths
from programs.buffer_filler import ItemArrivals
from softplc import TON, InOut, Input, Output, Param, Program

AT_SOURCE = 2
AT_DESTINATION = 4


def percent(items: int, capacity: int) -> float:
    """Level in % (tNN_iBL = tNN_iBM / tNN_iBC * 100); 0 for a zero capacity."""
    return 100.0 * items / capacity if capacity > 0 else 0.0


class MaterialHandlingPlant(Program):
    # per task (lists, task number = position + 1)
    iBM = InOut("input buffer items (tNN_iBM)")
    iBC = Input("input buffer capacity (tNN_iBC)")
    iFr = Input("input fill rate, items per minute (tNN_iFr)")
    iBL = Output("input buffer level in % (tNN_iBL)")
    qSM = InOut("output storage items (tNN_qSM)")
    qSC = Input("output storage capacity (tNN_qSC)")
    qSL = Output("output storage level in % (tNN_qSL)")
    qFr = Output("output fill rate, % per minute since the start (tNN_qFr)")
    # per robot (lists)
    tcurr = Input("task the robot works for (rNN_tcurr)")
    currloc = Input("motion state of the robot (rNN_currloc)")
    loadcap = Input("load capacity of the robot (rNN_loadcap)")
    load = InOut("items on the robot (rNN_load)")
    loadstat = InOut("loading/unloading done (rNN_loadstat)")
    handling_time = Param(0.0, "seconds a robot stands at a station before it is loaded or unloaded", duration=True)

    def setup(self) -> None:
        self.start = self.now
        self.arrivals: list[ItemArrivals] = []
        self.handling: list[TON] = []
        self.exchanged: list[bool] = []

    def scan(self) -> None:
        if not self.arrivals:  # first scan: the bindings are known now
            check_lengths(self, "iBM", "iBC", "iFr", "iBL", "qSM", "qSC", "qSL", "qFr")
            check_lengths(self, "tcurr", "currloc", "loadcap", "load", "loadstat")
        tasks = len(self.iBM)
        while len(self.arrivals) < tasks:
            self.arrivals.append(ItemArrivals(self.clock))
        for task in range(tasks):
            self.iBM[task] = self.arrivals[task](self.iBM[task], self.iBC[task], self.iFr[task])
        self.exchange_loads()
        elapsed_ms = (self.now - self.start) * 1000.0
        self.iBL = [percent(items, capacity) for items, capacity in zip(self.iBM, self.iBC)]
        self.qSL = [percent(items, capacity) for items, capacity in zip(self.qSM, self.qSC)]
        # qFr = (60000 / sim_ms) * qSL: the storage level gained per minute, on average
        self.qFr = [60000.0 / elapsed_ms * level if elapsed_ms > 0 else 0.0 for level in self.qSL]

    def exchange_loads(self) -> None:
        """Load robots standing at a source, unload those standing at a destination."""
        tasks = len(self.iBM)
        while len(self.handling) < len(self.tcurr):
            self.handling.append(TON(self.clock))
            self.exchanged.append(False)
        for robot, task_number in enumerate(self.tcurr):
            task = task_number - 1
            at_station = 0 <= task < tasks and not self.loadstat[robot] and self.currloc[robot] in (AT_SOURCE, AT_DESTINATION)
            if at_station and not self.exchanged[robot]:
                self.exchange(robot, task)
                self.exchanged[robot] = True
            # loadstat once the robot has stood there for the handling time
            if self.handling[robot](IN=at_station, PT=self.handling_time) and at_station:
                self.loadstat[robot] = True
                self.exchanged[robot] = False

    def exchange(self, robot: int, task: int) -> None:
        if self.currloc[robot] == AT_SOURCE:
            taken = max(0, min(self.iBM[task], self.loadcap[robot] - self.load[robot]))
            self.iBM[task] -= taken
            self.load[robot] += taken
        else:
            stored = max(0, min(self.load[robot], self.qSC[task] - self.qSM[task]))
            self.qSM[task] += stored
            self.load[robot] -= stored
