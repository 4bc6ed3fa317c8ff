"""The scan engine: cyclic tasks on absolute deadlines, each cycle on one consistent image.

A cycle of a task:
1. apply the journal of external writes (protocols, robots, HMI) — the only place they land;
2. take the input image: the current values of every tag the task's programs bind;
3. run the programs in order; each sees the image plus the outputs of the programs before it;
4. commit all outputs to the tag database at once.

Releases are at `origin + k * interval` on the runtime clock. A cycle that ends after its next
release skips the missed releases and counts them as overruns; it never bursts to catch up.
"""

from __future__ import annotations

import asyncio
import enum
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from softplc.clock import Clock
from softplc.log_format import BRIEF_TRACEBACK
from softplc.program import Direction, Program, program_log
from softplc.stats import TimingSeries
from softplc.tagdb import Rule, TagDatabase, WriteRejected


class ProgramState(enum.Enum):
    RUNNING = "RUNNING"
    FAULTED = "FAULTED"
    STOPPED = "STOPPED"


@dataclass(frozen=True)
class RestartPolicy:
    """What to do when a program raises: stay FAULTED (`stop`) or restart after a delay."""

    on_fault: str = "stop"  # "stop" | "restart"
    delay: float = 1.0
    max_restarts: int = 3


Binding = str | list[str]


class ProgramInstance:
    """A program object with its tag bindings, its state and its fault record."""

    def __init__(
        self,
        name: str,
        program: Program,
        bindings: dict[str, Binding],
        restart: RestartPolicy = RestartPolicy(),
    ) -> None:
        self.name = name
        self.program = program
        self.bindings = bindings
        self.restart = restart
        self.state = ProgramState.RUNNING
        self.error = ""
        self.faults = 0
        self.restarts = 0
        self._retry_at = math.inf
        variables = type(program).variables
        self.outputs = {var: tag for var, tag in bindings.items() if variables[var].direction.writes}
        # Optional variables left unbound read as None and are never written.
        for var, variable in variables.items():
            if var not in bindings:
                setattr(program, var, None)

    @property
    def tag_names(self) -> list[str]:
        names: list[str] = []
        for binding in self.bindings.values():
            names.extend([binding] if isinstance(binding, str) else binding)
        return names

    def start(self, now: float = 0.0) -> None:
        """Run the program's setup; a setup that raises faults the program."""
        try:
            self.program.setup()
        except (Exception, SystemExit) as error:  # sys.exit() in a program must not end the runtime
            self.fault(error, now)

    def fault(self, error: BaseException | str, now: float) -> None:
        self.state = ProgramState.FAULTED
        self.faults += 1
        if isinstance(error, BaseException):
            frame = traceback.extract_tb(error.__traceback__)[-1:] if error.__traceback__ else []
            where = f" at {frame[0].filename}:{frame[0].lineno}" if frame else ""
            self.error = f"{type(error).__name__}: {error}{where}"
        else:
            self.error = error
        # Under the program's own logger; the traceback is shown with -v (softplc.log_format).
        program_log(self.name).error("program %s FAULTED: %s", self.name, self.error,
                                     exc_info=error if isinstance(error, BaseException) else None,
                                     extra={BRIEF_TRACEBACK: True})
        if self.restart.on_fault == "restart" and self.restarts < self.restart.max_restarts:
            self._retry_at = now + self.restart.delay
        else:
            self._retry_at = math.inf

    def reset(self, now: float = 0.0) -> None:
        """Clear a fault and start again (an operator's reset)."""
        self.restarts = 0
        self.state = ProgramState.RUNNING
        self.error = ""
        self._retry_at = math.inf
        self.start(now)

    def restart_due(self, now: float) -> bool:
        """Whether a FAULTED program's restart delay has passed (see `maybe_restart`)."""
        return self.state is ProgramState.FAULTED and now >= self._retry_at

    def maybe_restart(self, now: float) -> None:
        if self.restart_due(now):
            self.restarts += 1
            program_log(self.name).warning("restarting program %s (restart %d of %d)", self.name, self.restarts, self.restart.max_restarts)
            self.state = ProgramState.RUNNING
            self._retry_at = math.inf
            self.start(now)  # a setup that fails again waits the full delay before the next try

    def scan(self, image: dict[str, Any], db: TagDatabase, now: float) -> dict[str, Any]:
        """Run one scan against `image`; return the validated outputs (empty if it faulted)."""
        program = self.program
        attributes = program.__dict__
        for var, binding in self.bindings.items():
            attributes[var] = image[binding] if isinstance(binding, str) else [image[t] for t in binding]
        try:
            program.scan()
        except (Exception, SystemExit) as error:  # sys.exit() in a program must not end the runtime
            self.fault(error, now)
            return {}
        outputs: dict[str, Any] = {}
        try:
            for var, binding in self.outputs.items():
                value = attributes[var]
                if isinstance(binding, str):
                    if value != image[binding] or type(value) is not type(image[binding]):
                        outputs[binding] = db.validate(binding, value, role=None)
                    continue
                if not isinstance(value, list) or len(value) != len(binding):
                    raise WriteRejected(var, Rule.TYPE_MISMATCH, f"must stay a list of {len(binding)} values")
                for tag, item in zip(binding, value):
                    if item != image[tag] or type(item) is not type(image[tag]):
                        outputs[tag] = db.validate(tag, item, role=None)
        except WriteRejected as rejected:
            self.fault(f"wrote an invalid value: {rejected}", now)
            return {}
        return outputs


@dataclass
class TaskStats:
    """Per-task timing: scan time, cycle time, start latency (seconds), overruns."""

    scan: TimingSeries = field(default_factory=TimingSeries)
    cycle: TimingSeries = field(default_factory=TimingSeries)
    latency: TimingSeries = field(default_factory=TimingSeries)
    cycles: int = 0
    overruns: int = 0
    watchdog_trips: int = 0

    def reset(self) -> None:
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
        self.programs = list(programs)
        self.stats = TaskStats()
        names: dict[str, None] = {}
        for instance in self.programs:
            names.update(dict.fromkeys(instance.tag_names))
        self.tag_names = list(names)
        self.next_release = 0.0
        # Read by the stall detector (another thread) while a cycle or a setup is under way:
        # the program running now, and whether it is in its setup() rather than its scan().
        self.running_program = ""
        self.running_setup = False
        self._origin = 0.0
        self._k = 0
        self._last_start: float | None = None

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
                    continue
            produced = instance.scan(image, db, now)
            if produced:
                image.update(produced)
                outputs.update(produced)
        self.running_program = ""
        return [tag.name for tag in db.commit(outputs)]

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
    real_start: float


class ScanEngine:
    """Runs tasks on one clock, the due task with the highest priority first."""

    def __init__(self, clock: Clock, db: TagDatabase, tasks: Sequence[Task]) -> None:
        self.clock = clock
        self.db = db
        self.tasks = sorted(tasks, key=lambda task: task.priority)
        self.current: CurrentScan | None = None
        self._after_cycle: list[Callable[[Task], None]] = []
        self._stopping = False

    def after_cycle(self, callback: Callable[[Task], None]) -> None:
        """Call `callback(task)` after every cycle (e.g. to evaluate a stop condition)."""
        self._after_cycle.append(callback)

    def stop(self) -> None:
        self._stopping = True

    def start_programs(self) -> None:
        """Run every program's setup() (at start-up), each watched for stalls like a scan."""
        for task in self.tasks:
            for instance in task.programs:
                self.run_setup(task, instance, instance.start)

    def run_setup(self, task: Task, instance: ProgramInstance, setup: Callable[[], None]) -> None:
        """Run `setup` (a program's start or reset) outside a cycle, seen by the stall detector as that program's."""
        self.current = CurrentScan(task, time.monotonic())
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
        self.current = CurrentScan(task, time.monotonic())
        try:
            self.db.apply_journal()
            task.run_cycle(self.db, start)
        finally:
            self.current = None
        end = clock.now()
        task.record(release, start, end)
        for callback in self._after_cycle:
            callback(task)
