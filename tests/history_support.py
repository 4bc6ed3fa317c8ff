"""Programs that give the historian something to record (loaded by file path from test YAML)."""

from __future__ import annotations

import math

from softplc import Output, Param, Program


class Wave(Program):
    """A sine wave, a step counter and a text state, from the runtime clock."""

    wave = Output("sin(t / period), -1..1")
    steps = Output("whole seconds since start")
    state = Output("'low' or 'high'")
    period = Param(10.0, "s")

    def scan(self) -> None:
        self.wave = math.sin(self.now / self.period)
        self.steps = int(self.now)
        self.state = "high" if self.wave > 0 else "low"


class Flood(Program):
    """Every tag of `values` changes at every scan (heavy recording), `tick` counts the scans."""

    values = Output("tags that all change every scan")
    tick = Output("scan counter")

    def setup(self) -> None:
        self.count = 0

    def scan(self) -> None:
        self.count += 1
        self.tick = self.count
        base = self.count * 0.001
        self.values = [base + index for index in range(len(self.values))]


class Ramp(Program):
    """`level` = the time in seconds up to 40 s, then 40 for ever; `steps` = whole thirds of it."""

    level = Output("min(t, 40)")
    steps = Output("int(min(t, 40)) // 3")

    def scan(self) -> None:
        held = min(self.now, 40.0)
        self.level = held
        self.steps = int(held) // 3
