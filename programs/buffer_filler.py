"""Input buffer filler: one item arrives every 60 / fill_rate seconds while the buffer has room.

This is the input side of the thesis's plant simulator (matHand_sim, `inTask1`): the fill rate
is in items per minute, which is what the thesis's simulator effectively did although its
tables label it "pr/hr". `ItemArrivals` is the timer on its own, reused by the full plant
simulator (`programs/plant_simulator.py`).
"""

from __future__ import annotations

from softplc import TON, Clock, InOut, Input, Output, Program


class ItemArrivals:
    """Arrival timer of one buffer: call once per scan, get the new item count back."""

    def __init__(self, clock: Clock) -> None:
        self.timer = TON(clock)

    def __call__(self, items: int, capacity: int, fill_rate: float) -> int:
        arriving = items < capacity and fill_rate > 0
        period = 60.0 / fill_rate if fill_rate > 0 else 0.0
        if self.timer(IN=arriving, PT=period):
            items += 1
            self.timer(IN=False)  # restart the timer for the next item
            self.timer(IN=arriving)
        return items


class InputBufferFiller(Program):
    items = InOut("items in the buffer (tNN_iBM)")
    capacity = Input("buffer capacity in items (tNN_iBC)")
    fill_rate = Input("arrival rate in items per minute (tNN_iFr)")
    level = Output("fill level in % (tNN_iBL)")

    def setup(self) -> None:
        self.arrivals = ItemArrivals(self.clock)

    def scan(self) -> None:
        self.items = self.arrivals(self.items, self.capacity, self.fill_rate)
        self.level = 100.0 * self.items / self.capacity if self.capacity > 0 else 0.0
