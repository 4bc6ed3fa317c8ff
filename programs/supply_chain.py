"""Supply-chain demand: each task's current product demand (tNN_sPD) drawn at random.

The thesis's case III simulation 2 drew task 1's demand between 0 and 50 % and task 2's
between 50 and 100 %. Here every task gets a new whole-number demand, uniformly in
[low, high], every `period` seconds; the generator is seeded so a run repeats exactly.
A task whose low equals its high keeps a constant demand.
"""

from __future__ import annotations

import random

from softplc import Output, Param, Program


class DemandGenerator(Program):
    sPD = Output("current product demand in % per task (tNN_sPD)")
    low = Param([0], "lowest demand per task, %")
    high = Param([100], "highest demand per task, %")
    period = Param(10.0, "seconds between new demand values", duration=True)
    seed = Param(1, "random seed")

    def setup(self) -> None:
        self.random = random.Random(self.seed)
        self.next_draw = self.now

    def scan(self) -> None:
        if self.now < self.next_draw:
            return
        self.next_draw = self.now + self.period
        demand = list(self.sPD)
        for task in range(len(demand)):
            low = self.low[min(task, len(self.low) - 1)]
            high = self.high[min(task, len(self.high) - 1)]
            demand[task] = float(self.random.randint(int(low), int(high)))
        self.sPD = demand
