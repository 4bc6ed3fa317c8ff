"""Stall detection: a thread that notices when one scan blocks the event loop far too long.

A program that blocks (an endless loop, a `time.sleep`, a network call) stalls every task and
every protocol served by the same event loop. The detector runs outside the loop, so it can
still report: it logs the task, the program and where it is stuck, and puts the runtime into
its ERROR state. When the scan finally returns, the program is faulted. A program's setup()
run outside a cycle (at start-up, or by an operator's reset) is watched the same way.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
import traceback
from collections.abc import Callable

from softplc.engine.scan import ScanEngine, Task

log = logging.getLogger(__name__)


class StallDetector:
    def __init__(
        self,
        engine: ScanEngine,
        on_stall: Callable[[Task, str, str], None],
        *,
        stall_after: float | None = None,
        poll: float = 0.05,
    ) -> None:
        self.engine = engine
        self.on_stall = on_stall
        self.stall_after = stall_after
        self.poll = poll
        self._stop = threading.Event()
        self._loop_thread_id = threading.get_ident()
        self._thread = threading.Thread(target=self._watch, name="softplc-stall-detector", daemon=True)

    def limit(self, task: Task) -> float:
        """How long one scan may block before it counts as a stall: 10 watchdogs, at least 1 s."""
        if self.stall_after is not None:
            return self.stall_after
        return max(10 * task.watchdog, 1.0)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)

    def _watch(self) -> None:
        reported_start: float | None = None
        last_report = 0.0
        while not self._stop.wait(self.poll):
            current = self.engine.current
            if current is None:
                reported_start = None
                continue
            blocked = time.monotonic() - current.real_start
            limit = self.limit(current.task)
            if blocked < limit:
                continue
            now = time.monotonic()
            if reported_start == current.real_start and now - last_report < 5.0:
                continue
            task = current.task
            program, in_setup = task.running_program, task.running_setup
            frame = sys._current_frames().get(self._loop_thread_id)
            if self.engine.current is not current:
                continue  # it returned while we looked: the names may belong to the next cycle
            where = "".join(traceback.format_stack(frame, limit=3)).strip() if frame is not None else "unknown"
            culprit = f"setup() of program {program}" if in_setup else f"program {program or '(between programs)'}"
            message = (
                f"task {task.name} is stuck in {culprit} for {blocked:.1f} s "
                f"(watchdog {task.watchdog * 1e3:g} ms): the event loop is blocked"
            )
            log.error("%s; the runtime is in ERROR state. Stuck at:\n%s", message, where)
            if reported_start != current.real_start:
                self.on_stall(task, program, message)
            reported_start = current.real_start
            last_report = now
