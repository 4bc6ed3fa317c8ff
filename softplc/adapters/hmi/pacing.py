"""How the HMI's work shares the event loop with the scan: one short step at a time, scan cycles first.

Every piece of HMI work that can take a while (sorting a batch of changes into groups, encoding
a chunk of an update, writing a frame to a client) is one *turn*. Turns run one at a time, and
each starts only when no scan cycle is due within MARGIN (2 ms, at most 0.4 of the shortest
task's period), so a cycle is delayed by one turn at most (~0.5 ms), never by the HMI's whole
burst. Without the single queue, a dozen client tasks woken together when a cycle ends each ran
a step after checking the guard once, and together ran into the next cycle (8-13 ms late,
bench/hmi_live.py).

The margin is the HMI's own, not the clock's 5 ms guard (`RealClock`, for sleepers of any
length): with two 10 ms tasks whose scans took 3-5 ms, the clock's guard left the HMI one turn
per cycle (a turn is allowed right after a cycle ends), fewer than 5,000 tags changing at 10 Hz
need (bench/hmi_live.py: 3 of 10 values a second delivered). A turn is short: it may start
until 2 ms before the next release.

Waits (the rate limit, heartbeats) are real seconds also under `--sim` (see live.py), on a loop timer: never spun.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from softplc.core.clock import Clock

if TYPE_CHECKING:
    from softplc.core.plant import Plant

MARGIN = 0.002  # s: a turn starts only this long before the next release, or more
LOOKS = 3  # times a turn looks at the clock before it goes anyway (a task that never runs must not stop the HMI)


def pacer_for(plant: Plant) -> Pacer:
    """A pacer that knows the plant's scan releases (on the real clock, with tasks)."""
    tasks, clock = plant.tasks, plant.clock
    if clock.simulated or not tasks:
        return Pacer(clock)

    def remaining() -> float:
        return plant.until_release() or 0.0  # None only on a simulated clock or without tasks: not here

    # Leave the HMI most of each period even with a 1 ms task.
    return Pacer(clock, remaining, min(MARGIN, 0.4 * min(task.interval for task in tasks)))


class Pacer:
    """Turns for HMI work, and real-time waits."""

    def __init__(self, clock: Clock, until_release: Callable[[], float] | None = None, margin: float = MARGIN) -> None:
        self.clock = clock
        self.until_release = until_release
        self.margin = margin
        self.waits = 0  # how often a turn waited for a cycle (diagnostics)
        self._lock = asyncio.Lock()

    @asynccontextmanager
    async def turn(self) -> AsyncIterator[None]:
        """Hold the HMI's one turn; entered when no scan cycle is due within the margin."""
        async with self._lock:
            await self.ready()
            yield

    async def ready(self) -> None:
        """Yield to the loop; on the real clock a scan cycle due within the margin runs first (no turn)."""
        if self.clock.simulated:
            await asyncio.sleep(0)
            return
        if self.until_release is None:
            await self.clock.sleep(0)
            return
        await asyncio.sleep(0)
        await self.clear()

    async def clear(self) -> None:
        """Return at once unless a scan cycle is due within the margin; then once it has run (no yield otherwise)."""
        if self.until_release is None:
            await self.ready()
            return
        for _ in range(LOOKS):
            if self.until_release() > self.margin:
                return
            self.waits += 1
            await self.clock.sleep(0)  # RealClock: returns once the due cycle has run

    async def sleep(self, seconds: float) -> None:
        """Wait `seconds` of real time on a loop timer, then let a scan cycle due within the margin go first.

        Real time also under `--sim`, where the clock's sleep is simulated. (The clock's sleep once
        spun its last 0.5-4 ms; the rate limit's waits of a few ms between frames were then mostly
        spinning, ~4 % of a core for two groups at 100 frames a second: bench/hmi_live.py, py-spy.)
        A timer a millisecond late costs a frame a millisecond.
        """
        await asyncio.sleep(seconds)
        if not self.clock.simulated:
            await self.clear()
