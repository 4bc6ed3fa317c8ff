"""Keeping OPC UA work out of the way of the scan: start a piece of work only when no cycle is due.

The server shares the event loop with the scan engine. A task's start latency grows by however
long the callback running at its release takes, and some OPC UA work cannot be cut short:
encoding a PublishResponse of 200 notifications takes ~1.5 ms, a big Read or Browse more.
`ScanGuard.clear()` is awaited before each such piece (a pushed slice of tag changes, an
incoming request bigger than 1 KB, a subscription's publish): if the next release of any task is less than
`guard_seconds` away, it sleeps through that release, so the cycle starts on time and the work
runs right after it. In the common case it returns at once without yielding.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from softplc.core.plant import Plant

DEFAULT_GUARD_SECONDS = 0.0015


class ScanGuard:
    """Answers "may a piece of work start now without delaying a scan cycle?"."""

    def __init__(self, until_release: Callable[[], float] | None = None, guard_seconds: float = DEFAULT_GUARD_SECONDS) -> None:
        self.until_release = until_release  # real seconds to the next release; None: nothing to guard
        self.guard_seconds = guard_seconds
        self.waits = 0  # how often work was held back (diagnostics)

    @classmethod
    def for_plant(cls, plant: Plant, guard_seconds: float = DEFAULT_GUARD_SECONDS) -> ScanGuard:
        """A guard for a plant's tasks (inactive on a simulated clock, where time waits for us)."""
        if plant.until_release() is None:
            return cls(None)

        def until_release() -> float:
            return plant.until_release() or 0.0

        # Leave the work most of each period even with a 1 ms task.
        shortest = min(task.interval for task in plant.tasks)
        return cls(until_release, min(guard_seconds, 0.4 * shortest))

    async def clear(self) -> None:
        """Return when the next release is far enough away (or has just been served)."""
        if self.until_release is None:
            return
        for _ in range(3):  # bounded: a task that never runs must not hold the server back
            remaining = self.until_release()
            if remaining > self.guard_seconds:
                return
            self.waits += 1
            # Sleep through the release (or just yield if it is due): the cycle runs first.
            await asyncio.sleep(max(0.0, remaining))

