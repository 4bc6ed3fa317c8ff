"""Programs whose state a standby must carry on exactly: a timer, an edge counter, a random draw (replication tests)."""

from __future__ import annotations

import random

from softplc import R_TRIG, TON, InOut, Input, Output, Program


class Stateful(Program):
    """Counts scans and rising edges, times a 0.35 s delay from the first scan, and draws random numbers."""

    part = Input("photo eye (high from the start)")
    scans = InOut("scans counted")
    edges = Output("rising edges of part")
    done = Output("the delay has elapsed")
    draw = Output("the last random draw")

    def setup(self) -> None:
        self.edge = R_TRIG()
        self.edge_count = 0
        self.delay = TON(self.clock)
        self.started = self.now
        self.done_at: float | None = None
        self.random = random.Random(7)

    def scan(self) -> None:
        if self.edge(CLK=self.part):
            self.edge_count += 1
        self.edges = self.edge_count
        self.scans += 1
        if self.delay(IN=True, PT=0.35) and self.done_at is None:
            self.done_at = self.now
        self.done = self.delay.Q
        self.draw = self.random.random()


class Unpicklable(Program):
    """Holds a lock: its state cannot be copied (the standby starts it from its own setup())."""

    scans = InOut("scans counted")

    def setup(self) -> None:
        import threading

        self.lock = threading.Lock()

    def scan(self) -> None:
        self.scans += 1
