"""Stop signals of `softplc run`: the first SIGINT or SIGTERM asks for a clean stop; later ones are
noted and ignored, so a shutdown under way (servers stopping, retained values being saved) always
finishes. SIGKILL remains the way to abandon it.

One Python-level handler serves the whole command, before, while and after the event loop runs:
the loop's own `add_signal_handler` would hand the signals back to their default action (death)
when the loop closes, with the statistics still to be printed.
"""

from __future__ import annotations

import asyncio
import os
import signal
from collections.abc import Callable
from types import FrameType
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def describe(signum: int) -> str:
    """The stop reason for a signal, as `softplc run` reports it."""
    if signum == signal.SIGINT:
        return "interrupted (SIGINT, Ctrl-C)"
    if signum == signal.SIGTERM:
        return "terminated (SIGTERM)"
    return f"stopped by {signal.Signals(signum).name}"


class StopSignals:
    """Handles SIGINT and SIGTERM from `install()` to `restore()`.

    `on_stop(signum)` runs on the event loop for the first signal (at `attach()` if it came
    before); `on_again(signum)` runs on the loop for the second one, if the loop still runs.
    Further signals are only counted; after `detach()` the first one is noted on stderr.
    """

    def __init__(self, on_stop: Callable[[int], None], on_again: Callable[[int], None]) -> None:
        self.received: list[int] = []
        self._on_stop = on_stop
        self._on_again = on_again
        self._loop: asyncio.AbstractEventLoop | None = None
        self._previous: dict[int, Any] = {}
        self._detached = False
        self._noted = False

    @property
    def first(self) -> int | None:
        """The signal that asked for the stop, if any came."""
        return self.received[0] if self.received else None

    def install(self) -> None:
        for signum in STOP_SIGNALS:
            self._previous[signum] = signal.signal(signum, self._handle)

    def restore(self) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)
        self._previous.clear()

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        """Deliver to `loop` from now on (call on the loop); a signal that came earlier is delivered now."""
        self._loop = loop
        if self.received:
            self._on_stop(self.received[0])

    def detach(self) -> None:
        """The loop is about to close: later signals are only noted (the run is over, or nearly)."""
        self._loop = None
        self._detached = True

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        # A signal handler may interrupt the main thread anywhere, print() included: it only
        # records, and hands the rest to the loop (call_soon_threadsafe is safe from here).
        self.received.append(signum)
        count = len(self.received)
        loop = self._loop
        if loop is not None and not loop.is_closed():
            if count <= 2:
                self._noted = count == 2
                loop.call_soon_threadsafe(self._on_stop if count == 1 else self._on_again, signum)
        elif self._detached and not self._noted:
            self._noted = True  # once: a burst of signals must not flood the console
            name = signal.Signals(signum).name
            os.write(2, f"softplc: {name} received while stopping: ignored, the shutdown finishes first\n".encode())
