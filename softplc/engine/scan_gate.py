"""A worker thread that keeps off the interpreter lock while a scan cycle is due (online change's check).

Python threads share one interpreter lock. A thread doing CPU work (an online change parsing the
file, checking it, importing modules) holds it for up to `sys.getswitchinterval()` at a time, and
on a busy machine the OS may even preempt it *while it holds the lock*: the scan's thread, woken
for its release, then waits for a thread that is not running — a late or missed cycle. Inside
`gate.worker()`, the worker looks at the clock at every Python call and return (`sys.setprofile`):
from shortly before any task's release (the clock's spin margin plus 1 ms) until that cycle has
run, it waits on an event the scan engine sets after each cycle, without the lock. The work
takes longer; the scan does not wait for it. Real clock only (on the simulated clock, blocking
work runs inline on the event loop and no cycle can be due meanwhile).
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

from softplc.core.clock import Clock
from softplc.engine.scan import ScanEngine, Task

MARGIN = 0.002  # at least this long before a release the worker steps aside
LONGEST_WAIT = 0.05  # a cycle that does not come (the engine stopping) never holds the worker longer


class ScanGate:
    """One per runtime: `with gate.worker(): work()` in a worker thread pauses the work around every release.

    Several threads may use it at once (the audit writer, an online change's check): each waits on
    the same event; one that misses a wake-up waits at most LONGEST_WAIT, never the scan.
    """

    def __init__(self, engine: ScanEngine, clock: Clock) -> None:
        self.engine = engine
        self.clock = clock
        self.pauses = 0  # how many times a worker stepped aside
        self._ran = threading.Event()
        self._watching = 0  # threads inside worker() or stepping()
        self._open_until = 0.0  # time.monotonic() until which no release is near
        self._not_coming = math.nan  # a release waited for in vain: not waited for again
        engine.after_cycle(self._cycle_ran)  # registered on the loop's thread, once

    def _cycle_ran(self, task: Task) -> None:
        if self._watching:  # a plain attribute read on every cycle otherwise
            self._ran.set()

    @contextlib.contextmanager
    def worker(self) -> Iterator[None]:
        """Run the body (in a worker thread) so that it steps aside around the scan's releases."""
        self._open_until = 0.0
        self._watching += 1
        sys.setprofile(self._event)  # this thread only
        try:
            yield
        finally:
            sys.setprofile(None)
            self._watching -= 1

    @contextlib.contextmanager
    def stepping(self) -> Iterator[Callable[[], None]]:
        """Like `worker()`, for work done in small steps that calls the yielded `step()` between them.

        No profile hook, so no cost on every call: the work (e.g. the audit trail's writer,
        softplc/storage/audit/store.py) keeps each step well under the margin (2 ms) itself.
        """
        self._open_until = 0.0
        self._watching += 1
        try:
            yield self.step
        finally:
            self._watching -= 1

    def step(self) -> None:
        """Between two steps of `stepping()` work: return at once, or wait until the cycle now due has run."""
        self._event(None, "step", None)  # type: ignore[arg-type]

    def _margin(self) -> float:
        # The real clock wakes the scan up to its (adaptive) spin margin early and spins: step aside before.
        return max(MARGIN, getattr(self.clock, "spin", 0.0) + 0.001)

    def _next_release(self) -> float:
        return min((task.next_release for task in self.engine.tasks), default=float("inf"))

    def _event(self, frame: FrameType, event: str, arg: Any, monotonic: Callable[[], float] = time.monotonic) -> None:
        # Called at every Python call and return of the worker: the common case is one comparison.
        if monotonic() < self._open_until:
            return
        now = self.clock.now()
        release = self._next_release()
        if release == self._not_coming:
            # That cycle did not come (the engine stopped, or a cycle is stalled): do not wait for it
            # at every call again — an import of a module would take minutes. Looked at anew a
            # LONGEST_WAIT later: a scan that runs again moves the release, and the gate works again.
            self._open_until = monotonic() + LONGEST_WAIT
            return
        margin = self._margin()
        if release - now > margin:
            self._open_until = monotonic() + (release - now - margin)  # the worker's own time base
            return
        # A cycle is due: wait (Event.wait releases the lock) until it has run, i.e. until no task
        # is due at that release any more and no cycle is under way. Woken by the engine, not polling.
        self.pauses += 1
        give_up = time.monotonic() + LONGEST_WAIT
        while True:
            self._ran.clear()
            if self._next_release() > release and self.engine.current is None:
                break
            left = give_up - time.monotonic()
            if left <= 0:
                self._not_coming = release
                break
            self._ran.wait(left)
        self._open_until = 0.0
