"""Programs used by the scan and runtime tests (loaded by file path from test YAML)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from softplc import InOut, Input, Output, Param, Program


class PairChecker(Program):
    """Asserts that a client's pair of writes (a, b with b == -a) is never seen half-applied."""

    a = Input("first half")
    b = Input("second half, always -a")
    checks = InOut("scans that checked the pair")

    def setup(self) -> None:
        self.seen: list[tuple[float, float, float]] = []

    def scan(self) -> None:
        if self.a != -self.b:
            raise AssertionError(f"half-applied write: a={self.a} b={self.b}")
        self.seen.append((self.now, self.a, self.b))
        self.checks += 1


class Counter(Program):
    """Counts its scans into an InOut tag and remembers when it ran."""

    count = InOut("scan counter")

    def setup(self) -> None:
        self.times: list[float] = []

    def scan(self) -> None:
        self.times.append(self.now)
        self.count += 1


class Watcher(Program):
    """Records the value of one input at every scan: (time, value)."""

    value = Input("the watched tag")

    def setup(self) -> None:
        self.seen: list[tuple[float, Any]] = []

    def scan(self) -> None:
        self.seen.append((self.now, self.value))


class Overrider(Program):
    """Records what it sees in `value`, then forces it to `forced` while `force` is on."""

    value = InOut("the contested tag")
    force = Input("override on/off")
    forced = Param(100, "the value forced")

    def setup(self) -> None:
        self.seen: list[Any] = []

    def scan(self) -> None:
        self.seen.append(self.value)
        if self.force:
            self.value = self.forced


class Bomb(Program):
    """Raises while `armed` is true; counts setups and scans."""

    armed = Input("raise while true")
    scans = InOut("scans completed")

    setups = 0

    def setup(self) -> None:
        type(self).setups += 1
        self.setup_times = getattr(self, "setup_times", []) + [self.now]

    def scan(self) -> None:
        if self.armed:
            raise ZeroDivisionError("armed and dangerous")
        self.scans += 1


class BadSetup(Program):
    """A program whose setup() raises."""

    out = Output("never written")

    def setup(self) -> None:
        raise RuntimeError("cannot initialise the widget")

    def scan(self) -> None:
        self.out = 1


class Exiter(Program):
    """Calls sys.exit() in its scan: must fault, not end the runtime."""

    out = Output("never written")

    def scan(self) -> None:
        raise SystemExit(3)


class BadWriter(Program):
    """Writes a valid value to `good` and, when `mode` says so, an invalid one to `bad`."""

    mode = Input("0 ok, 1 out of range, 2 wrong type, 3 list of wrong length")
    good = Output("a valid output")
    bad = Output("the output that gets the invalid value")
    many = Output("a list-bound output", optional=True)

    def scan(self) -> None:
        self.good += 1
        if self.mode == 1:
            self.bad = 200
        elif self.mode == 2:
            self.bad = "two hundred"
        elif self.mode == 3 and self.many is not None:
            self.many = [1.0]


class Blocker(Program):
    """Blocks the event loop with time.sleep: `block` seconds on every scan while `armed`."""

    armed = Input("block while true")
    done = InOut("blocking scans finished")
    block = Param(0.035, "seconds to block each scan")
    once = Param(False, "block on one scan only")

    def scan(self) -> None:
        if self.armed and not (self.once and self.done):
            time.sleep(self.block)
            self.done += 1


class CpuBurner(Program):
    """Computes for `burn` seconds of its own thread's CPU time in one scan, after touching `marker`."""

    armed = Input("burn while true")
    done = InOut("burning scans finished")
    burn = Param(0.3, "seconds of CPU time to burn in one scan")
    marker = Param("", "a file created as the burning scan begins (empty: none)")

    def scan(self) -> None:
        if self.armed and not self.done:
            if self.marker:
                Path(self.marker).touch()
            end = time.thread_time() + self.burn
            while time.thread_time() < end:
                pass
            self.done += 1


class Follower(Program):
    """Copies `source` to `target` (a one-cycle-later image of another program's output)."""

    source = Input("followed tag")
    target = Output("copy")

    def scan(self) -> None:
        self.target = self.source


class NumpyWriter(Program):
    """Writes NumPy scalars, as code using numpy or scikit-learn naturally does."""

    label = Output("an integer from numpy")
    flag = Output("a bool from numpy")
    level = Output("a float from numpy")

    def scan(self) -> None:
        import numpy as np

        self.label = np.int64(1)
        self.flag = np.bool_(True)
        self.level = np.float32(0.25)


class SlowSetup(Program):
    """Raises on its first scan only; its `block_on`-th setup() blocks the event loop for `block` s."""

    scans = InOut("scans completed")
    block = Param(1.0, "seconds the blocking setup() takes")
    block_on = Param(2, "which setup() blocks: 1 at start-up, 2 at the first restart or reset")

    def setup(self) -> None:
        self.setups = getattr(self, "setups", 0) + 1
        if self.setups == self.block_on:
            time.sleep(self.block)

    def scan(self) -> None:
        if not getattr(self, "raised", False):
            self.raised = True
            raise RuntimeError("first scan fails")
        self.scans += 1


class FillValve(Program):
    """Opens a fill valve and runs its pump at a speed while `demand`; raises while `armed` (after setting them)."""

    demand = Input("level below setpoint")
    armed = Input("raise while true")
    overflow = Input("write an out-of-range speed while true", optional=True)
    valve = Output("fill valve open")
    pump = Output("pump on")
    speed = Output("pump speed, %")
    scans = InOut("scans completed")

    def scan(self) -> None:
        self.valve = bool(self.demand)
        self.pump = bool(self.demand)
        self.speed = 150.0 if self.overflow else 50.0 if self.demand else 0.0
        if self.armed:
            raise RuntimeError("level sensor lost")
        self.scans += 1


class EdgeCounter(Program):
    """Counts rising edges of `part` three ways (R_TRIG, CTU, TP pulses); raises while `armed`."""

    part = Input("photo eye")
    armed = Input("raise while true")
    edges = InOut("rising edges seen by R_TRIG")
    counted = InOut("counts made by a CTU counting part")
    pulses = InOut("pulses started by a TP")
    fails_setup = Param(False, "raise in every setup() after the first")

    def setup(self) -> None:
        self.setups = getattr(self, "setups", 0) + 1
        if self.fails_setup and self.setups > 1:
            raise RuntimeError("setup fails")
        from softplc import CTU, R_TRIG, TP

        self.rising = R_TRIG()
        self.counter = CTU(PV=1000)
        self.pulse = TP(self.clock, PT=0.005)
        self.pulse_edge = R_TRIG()
        self.last_cv = 0

    def scan(self) -> None:
        if self.armed:
            raise RuntimeError("jammed")
        if self.rising(CLK=self.part):
            self.edges += 1
        self.counter(CU=self.part)
        self.counted += self.counter.CV - self.last_cv
        self.last_cv = self.counter.CV
        if self.pulse_edge(CLK=self.pulse(IN=self.part)):
            self.pulses += 1
