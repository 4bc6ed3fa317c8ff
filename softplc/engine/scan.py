"""The scan engine: cyclic tasks on absolute deadlines, each cycle on one consistent image.

A cycle of a task:
1. apply the journal of external writes (protocols, robots, HMI) — the only place they land;
2. take the input image: the current values of every tag the task's programs bind;
3. run the programs in order; each sees the image plus the outputs of the programs before it;
4. commit all outputs to the tag database at once.

Releases are at `origin + k * interval` on the runtime clock. A cycle that ends after its next
release skips the missed releases and counts them as overruns; it never bursts to catch up.

A plant that is not the active one of a redundant pair (`softplc/core/plant_role.py`) runs no
cycle at all: each release passes without a scan, without applying the journal and without
committing anything, until it is active again; the role is asked at every release.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from softplc.core.clock import Clock
from softplc.core.plant_role import RoleHolder
from softplc.core.stats import TimingSeries
from softplc.core.tagdb import TagDatabase
from softplc.engine.program_instance import NEVER, ProgramInstance, ProgramState, RestartPolicy

__all__ = ["NEVER", "CurrentScan", "ProgramInstance", "ProgramState", "RestartPolicy", "ScanEngine", "Task", "TaskStats"]



@dataclass
class TaskStats:
    """Per-task timing: scan time, cycle time, start latency (seconds), overruns."""

    scan: TimingSeries = field(default_factory=TimingSeries)
    cycle: TimingSeries = field(default_factory=TimingSeries)
    latency: TimingSeries = field(default_factory=TimingSeries)
    cycles: int = 0
    overruns: int = 0
    watchdog_trips: int = 0
    resets: int = 0  # how many times reset (readers that accumulate, e.g. /metrics, see one happened)

    def reset(self) -> None:
        self.resets += 1
        self.scan.reset()
        self.cycle.reset()
        self.latency.reset()
        self.cycles = 0
        self.overruns = 0
        self.watchdog_trips = 0


class Task:
    """A cyclic PLC task: an interval, a priority (0 = highest), a watchdog and programs."""

    def __init__(
        self,
        name: str,
        interval: float,
        programs: Sequence[ProgramInstance],
        *,
        priority: int = 10,
        watchdog: float | None = None,
    ) -> None:
        if interval <= 0:
            raise ValueError(f"task {name}: interval must be positive")
        self.name = name
        self.interval = interval
        self.priority = priority
        self.watchdog = watchdog if watchdog is not None else interval
        self.programs: list[ProgramInstance] = []
        self.tag_names: list[str] = []
        self.replace_programs(programs)
        self.stats = TaskStats()
        self.next_release = 0.0
        # Read by the stall detector (another thread) while a cycle or a setup is under way:
        # the program running now, and whether it is in its setup() rather than its scan().
        self.running_program = ""
        self.running_setup = False
        self._origin = 0.0
        self._k = 0
        self._last_start: float | None = None

    def replace_programs(self, programs: Sequence[ProgramInstance]) -> None:
        """Scan these programs from the next cycle on (an online change swaps them between two cycles)."""
        names: dict[str, None] = {}
        for instance in programs:
            names.update(dict.fromkeys(instance.tag_names))
        # Two assignments, no cycle in between: the scan runs on the same event loop as the caller.
        self.tag_names = list(names)
        self.programs = list(programs)

    def schedule_from(self, origin: float) -> None:
        self._origin = origin
        self._k = 0
        self.next_release = origin
        self._last_start = None

    def run_cycle(self, db: TagDatabase, now: float) -> list[str]:
        """One cycle (journal already applied): image → programs → commit. Returns changed tag names."""
        image = db.snapshot(self.tag_names)
        outputs: dict[str, Any] = {}
        for instance in self.programs:
            # Named before anything of it runs: a restart's setup() that blocks is blamed on it.
            self.running_program = instance.name
            if instance.state is not ProgramState.RUNNING:
                if not instance.restart_due(now):
                    continue
                self.running_setup = True
                try:
                    instance.maybe_restart(now)
                finally:
                    self.running_setup = False
                if instance.state is not ProgramState.RUNNING:
                    produced = instance.reaction_values(db)  # its setup() failed again
                    image.update(produced)
                    outputs.update(produced)
                    continue
            # A fault's reaction comes back instead of the scan's outputs, committed by this cycle.
            produced = instance.scan(image, db, now)
            if produced:
                image.update(produced)
                outputs.update(produced)
        self.running_program = ""
        return [tag.name for tag in db.commit(outputs)]

    def pass_release(self, now: float) -> None:
        """Let the due release go by without a cycle (a standby): the next one on the grid after `now`."""
        self._k = max(self._k + 1, math.floor((now - self._origin) / self.interval) + 1)
        self.next_release = self._origin + self._k * self.interval
        self._last_start = None  # the next cycle's cycle time would span the pause

    def record(self, release: float, start: float, end: float) -> None:
        """Account for a cycle and compute the next release (skipping missed ones)."""
        stats = self.stats
        stats.cycles += 1
        stats.latency.add(max(0.0, start - release))
        stats.scan.add(end - start)
        if self._last_start is not None:
            stats.cycle.add(start - self._last_start)
        self._last_start = start
        if end - start > self.watchdog:
            stats.watchdog_trips += 1
        self._k += 1
        next_release = self._origin + self._k * self.interval
        if end > next_release:
            missed = math.floor((end - next_release) / self.interval) + 1
            self._k += missed
            stats.overruns += missed
            next_release = self._origin + self._k * self.interval
        self.next_release = next_release


@dataclass
class CurrentScan:
    """The cycle (or out-of-cycle setup) under way; read by the stall detector from another thread."""

    task: Task
    real_start: float  # time.monotonic() as it began
    cpu_start: float  # time.thread_time() of the loop's thread as it began (judged under a simulated clock)


class ScanEngine:
    """Runs tasks on one clock, the due task with the highest priority first."""

    def __init__(self, clock: Clock, db: TagDatabase, tasks: Sequence[Task]) -> None:
        self.clock = clock
        self.db = db
        self.tasks = sorted(tasks, key=lambda task: task.priority)
        self.current: CurrentScan | None = None
        self._after_cycle: list[Callable[[Task], None]] = []
        self._last_after_cycle = 0  # the callbacks at the end of _after_cycle registered `last`
        self._stopping = False
        self.role: RoleHolder | None = None  # None: alone, always active
        self.passed = 0  # releases passed without a cycle (not active)

    def active(self) -> bool:
        """Whether cycles run now (alone, or the active of a redundant pair)."""
        return self.role is None or self.role.is_active()

    def after_cycle(self, callback: Callable[[Task], None], *, last: bool = False) -> Callable[[], None]:
        """Call `callback(task)` after every cycle (e.g. to evaluate a stop condition); returns an undo.

        `last`: after every other callback, whenever registered (a capture of the state the others left).
        """
        if last:
            self._last_after_cycle += 1
            self._after_cycle.append(callback)
        else:
            self._after_cycle.insert(len(self._after_cycle) - self._last_after_cycle, callback)

        def undo() -> None:
            if callback in self._after_cycle:
                if self._after_cycle.index(callback) >= len(self._after_cycle) - self._last_after_cycle:
                    self._last_after_cycle -= 1
                self._after_cycle.remove(callback)

        return undo

    def stop(self) -> None:
        self._stopping = True

    def start_programs(self) -> None:
        """Run every program's setup() (at start-up), each watched for stalls like a scan."""
        for task in self.tasks:
            for instance in task.programs:
                self.run_setup(task, instance, instance.start)

    def commit_reactions(self) -> list[str]:
        """Commit the fault reactions due outside a cycle (a setup() at start-up or reset, a stall, a stop)."""
        if not self.active():
            return []  # a standby drives nothing: the active's outputs are mirrored here
        values: dict[str, Any] = {}
        for task in self.tasks:
            for instance in task.programs:
                values.update(instance.reaction_values(self.db))
        return [tag.name for tag in self.db.commit(values)] if values else []

    def run_setup(self, task: Task, instance: ProgramInstance, setup: Callable[[], None]) -> None:
        """Run `setup` (a program's start or reset) outside a cycle, seen by the stall detector as that program's."""
        self.current = CurrentScan(task, time.monotonic(), time.thread_time())
        task.running_program = instance.name
        task.running_setup = True
        try:
            setup()
        finally:
            task.running_setup = False
            task.running_program = ""
            self.current = None

    async def run(self) -> None:
        """Scan until `stop()`. With no tasks, apply the write journal every 10 ms instead."""
        clock = self.clock
        origin = clock.now()
        for task in self.tasks:
            task.schedule_from(origin)
        if not self.tasks:
            while not self._stopping:
                if self.active():
                    self.db.apply_journal()
                await clock.sleep(0.01)
            return
        try:
            while not self._stopping:
                now = clock.now()
                due = [task for task in self.tasks if task.next_release <= now]
                if not due:
                    await clock.sleep_until_release(min(task.next_release for task in self.tasks))
                    continue
                # Of the tasks due (several after a long scan), the highest priority goes first,
                # even if a lower-priority task has waited longer.
                task = min(due, key=lambda t: (t.priority, t.next_release))
                if self.role is not None and not self.role.is_active():
                    for passed in due:
                        passed.pass_release(now)
                    self.passed += len(due)
                    clock.cycle_done()
                    await asyncio.sleep(0)
                    continue
                self.cycle(task, task.next_release)
                now = clock.now()
                if not any(t.next_release <= now for t in self.tasks):
                    clock.cycle_done()  # background work held back for this instant may run now
                # Let adapters run between cycles even when the next task is already due (an
                # overloaded engine must not starve the protocol servers).
                await asyncio.sleep(0)
        finally:
            clock.cycle_done()

    def cycle(self, task: Task, release: float) -> None:
        clock = self.clock
        start = clock.now()
        self.current = CurrentScan(task, time.monotonic(), time.thread_time())
        try:
            self.db.apply_journal()
            task.run_cycle(self.db, start)
        finally:
            self.current = None
        end = clock.now()
        task.record(release, start, end)
        for callback in self._after_cycle:
            callback(task)
