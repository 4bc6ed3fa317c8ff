"""Small programs used by the configuration tests (loaded by file path from the YAML files)."""

from __future__ import annotations

from softplc import InOut, Input, Output, Param, Program


class Mixer(Program):
    """Copies a scaled input to an output; has every kind of parameter."""

    source = Input("value to scale")
    target = Output("scaled value")
    spare = Input("an optional extra input", optional=True)
    gain = Param(1.0, "multiplier")
    label = Param("mix", "a name")
    steps = Param(3, "an integer")
    recipe = Param(description="required: the recipe name")
    hold = Param(0.5, "a duration", duration=True)

    def scan(self) -> None:
        self.target = self.source * self.gain


class Summer(Program):
    """Adds up a list of inputs into one output; counts scans in an InOut."""

    parts = Input("values to add (bind a list of tags)")
    total = Output("their sum")
    scans = InOut("scan counter")

    def scan(self) -> None:
        self.total = sum(self.parts)
        self.scans += 1



class Filler(Program):
    """A buffer filler with the same variables as programs/buffer_filler.py (one item per scan)."""

    items = InOut("items in the buffer")
    capacity = Input("buffer capacity")
    fill_rate = Input("items per minute")
    level = Output("fill level, %")

    def scan(self) -> None:
        if self.items < self.capacity and self.fill_rate > 0:
            self.items += 1
        self.level = 100.0 * self.items / self.capacity


NOT_A_PROGRAM = 42


class BrokenOnCreation(Program):
    """A program whose constructor raises (a bug in user code): reported where it is named."""

    def __init__(self, context: object) -> None:
        raise ValueError("calibration table missing")

    def scan(self) -> None:
        pass
