"""How the HMI's work shares the event loop with the scan: one short step at a time, scan cycles first.

Every piece of HMI work that can take a while (sorting a batch of changes into groups, encoding
a chunk of an update, writing a frame to a client) is one *turn*. Turns run one at a time, and
each starts only when no scan cycle is due within the clock's guard (`RealClock`: 5 ms), so a
cycle is delayed by one turn at most (~0.5 ms), never by the HMI's whole burst. Without the
single queue, a dozen client tasks woken together when a cycle ends each ran a step after
checking the guard once, and together ran into the next cycle (8-13 ms late, bench/hmi_live.py).

Waits (the rate limit, heartbeats) are real seconds also under `--sim` (see live.py).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from softplc.core.clock import Clock


class Pacer:
    """Turns for HMI work, and real-time waits."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self._lock = asyncio.Lock()

    @asynccontextmanager
    async def turn(self) -> AsyncIterator[None]:
        """Hold the HMI's one turn; entered when no scan cycle is due within the guard."""
        async with self._lock:
            await self.ready()
            yield

    async def ready(self) -> None:
        """Yield to the loop; on the real clock a scan cycle due within the guard runs first (no turn)."""
        if self.clock.simulated:
            await asyncio.sleep(0)
        else:
            await self.clock.sleep(0)

    async def sleep(self, seconds: float) -> None:
        """Wait `seconds` of real time (RealClock: also letting a due scan cycle go first)."""
        if self.clock.simulated:
            await asyncio.sleep(seconds)
        else:
            await self.clock.sleep(seconds)
