"""Input buffer filler: one item arrives every 60 / fill_rate seconds while the buffer has room.

This is the input side of the thesis's plant simulator (matHand_sim, `inTask1`): the fill rate
is in items per minute, which is what the thesis's simulator effectively did although its
tables label it "pr/hr".
"""

from __future__ import annotations

from softplc import TON, InOut, Input, Output, Program


class InputBufferFiller(Program):
    items = InOut("items in the buffer (tNN_iBM)")
    capacity = Input("buffer capacity in items (tNN_iBC)")
    fill_rate = Input("arrival rate in items per minute (tNN_iFr)")
    level = Output("fill level in % (tNN_iBL)")

    def setup(self) -> None:
        self.arrival = TON(self.clock)

    def scan(self) -> None:
        has_room = self.items < self.capacity
        arriving = has_room and self.fill_rate > 0
        period = 60.0 / self.fill_rate if self.fill_rate > 0 else 0.0
        if self.arrival(IN=arriving, PT=period):
            self.items += 1
            self.arrival(IN=False)  # restart the timer for the next item
            self.arrival(IN=arriving)
        self.level = 100.0 * self.items / self.capacity if self.capacity > 0 else 0.0
