"""Background asyncio tasks ended together: what every adapter's stop() does with the tasks it spawned."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Iterable
from typing import Any, TypeVar

T = TypeVar("T")


async def cancel_and_wait(tasks: Iterable[asyncio.Task[Any]]) -> None:
    """Cancel every task, then wait until each has ended; what they raised on the way out is not ours to report."""
    tasks = list(tasks)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


async def within(seconds: float, awaitable: Awaitable[T]) -> T:
    """`await awaitable`, or TimeoutError after `seconds` (what it awaited is cancelled).

    Use it instead of `asyncio.wait_for`, which on Python 3.11 loses a cancel that arrives as the
    awaited thing finishes: the task asked to stop carries on, and whoever waits for it waits for
    ever (seen: a standby's sync loop, receiving a state every 10 ms, outlived its runtime's stop).
    """
    async with asyncio.timeout(seconds):
        return await awaitable
