"""A robot agent runs until SIGTERM or SIGINT: announced, its session closed, the signal's number returned."""

from __future__ import annotations

import asyncio
import signal
import sys
from typing import Any


async def drive_until_signal(agent: Any, name: str, what_stopping_does: str = "") -> int:
    """Run `agent.run()` until SIGTERM or SIGINT; the signal's number (0 when the agent ended by itself)."""
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    assert task is not None
    received: list[int] = []

    def stop(signum: int) -> None:
        if not received:
            note = f" ({what_stopping_does})" if what_stopping_does else ""
            print(f"{name}: {signal.Signals(signum).name} received, stopping{note}", file=sys.stderr)
            task.cancel()
        received.append(signum)

    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, stop, signum)
    try:
        await agent.run()
    except asyncio.CancelledError:
        if not received:
            raise
    return received[0] if received else 0
