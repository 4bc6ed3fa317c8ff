"""Stall detection: a thread that notices when one scan blocks the event loop far too long.

A program that blocks (an endless loop, a `time.sleep`, a network call) stalls every task and
every protocol served by the same event loop. The detector runs outside the loop, so it can
still report: it logs the task, the program and where it is stuck, and puts the runtime into
its ERROR state. When the scan finally returns, the program is faulted. A program's setup()
run outside a cycle (at start-up, or by an operator's reset) is watched the same way.

What "too long" means depends on the clock:
- Real time: wall time. Whatever held the loop, nothing was served meanwhile.
- Simulated time: a slow scan costs no simulated time, only a slower run, and wall time there
  mostly measures the machine (a busy CI host, a paused VM stalled a scenario for 1.5 s in the
  middle of a scan and failed it). So a simulated run judges the CPU time the loop's thread spent
  in the scan — a program computing past the limit is stuck on any machine, one paused by the
  machine never is — and a scan blocked without computing (a sleep, a hung socket) only past
  `SIMULATED_WALL_LIMIT`, long enough for no machine to reach it by being busy.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
import traceback
from collections.abc import Callable

from softplc.engine.scan import CurrentScan, ScanEngine, Task

log = logging.getLogger(__name__)

SIMULATED_WALL_LIMIT = 120.0  # seconds of wall time a simulated scan may block without computing


class StallDetector:
    def __init__(
        self,
        engine: ScanEngine,
        on_stall: Callable[[Task, str, str], None],
        *,
        stall_after: float | None = None,
        poll: float = 0.05,
        simulated: bool = False,
        wall_limit: float = SIMULATED_WALL_LIMIT,
    ) -> None:
        """`simulated`: judge by the loop thread's CPU time (and `wall_limit` of wall time), not wall time."""
        self.engine = engine
        self.on_stall = on_stall
        self.stall_after = stall_after
        self.poll = poll
        self.simulated = simulated
        self.wall_limit = wall_limit
        self._stop = threading.Event()
        self._loop_thread_id = threading.get_ident()
        self._loop_cpu_clock = _thread_cpu_clock(self._loop_thread_id) if simulated else None
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

    def _blocked(self, current: CurrentScan) -> tuple[float, str] | None:
        """(how long, in what) the scan under way has blocked past its limit, else None."""
        wall = time.monotonic() - current.real_start
        limit = self.limit(current.task)
        if not self.simulated:
            return (wall, "s") if wall >= limit else None
        if self._loop_cpu_clock is not None:
            computed = time.clock_gettime(self._loop_cpu_clock) - current.cpu_start
            if computed >= limit:
                return computed, "s of CPU time"
        elif wall >= limit:  # no per-thread CPU clock on this system: wall time, as in real time
            return wall, "s"
        if wall >= max(self.wall_limit, limit):
            return wall, "s of wall time without computing (simulated clock)"
        return None

    def _watch(self) -> None:
        reported_start: float | None = None
        last_report = 0.0
        while not self._stop.wait(self.poll):
            current = self.engine.current
            if current is None:
                reported_start = None
                continue
            blocked = self._blocked(current)
            if blocked is None:
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
            seconds, unit = blocked
            message = (
                f"task {task.name} is stuck in {culprit} for {seconds:.1f} {unit} "
                f"(watchdog {task.watchdog * 1e3:g} ms): the event loop is blocked"
            )
            log.error("%s; the runtime is in ERROR state. Stuck at:\n%s", message, where)
            if reported_start != current.real_start:
                self.on_stall(task, program, message)
            reported_start = current.real_start
            last_report = now


def _thread_cpu_clock(thread_id: int) -> int | None:
    """The clock of a thread's CPU time (read from any thread), or None where there is none."""
    try:
        return time.pthread_getcpuclockid(thread_id)
    except (AttributeError, OSError):
        return None
