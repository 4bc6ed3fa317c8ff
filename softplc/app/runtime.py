"""The composition root: builds the core from a PlantConfig and runs it with its adapters.

The core (tag database, scan engine, clock) knows nothing of protocols or robots; adapters
(found by `softplc.app.adapters` from their manifests) are handed the plant API when they
start — `runtime.plant`, a `softplc.core.plant.Plant`: the tags (snapshot, subscribe to
changes, submit writes with an origin), the commands, the events, the clock, a state directory,
the tasks' figures — and never the Runtime itself.
"""

from __future__ import annotations

import asyncio
import enum
import gc
import logging
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

from softplc.app.plant import RuntimePlant
from softplc.config import PlantConfig
from softplc.config.system_tags import runtime_tag_definitions
from softplc.config.yamlsource import ConfigError, Location, Problem
from softplc.core.clock import Clock, PlantTime, RealClock, SimClock
from softplc.core.commands import Commands
from softplc.core.events import EventBus
from softplc.core.expression import Condition
from softplc.core.plant import Adapter, AdapterError
from softplc.core.plant_role import RoleHolder
from softplc.core.program import ProgramContext
from softplc.core.tagdb import TagDatabase
from softplc.engine.online_change.change import OnlineChange
from softplc.engine.program_control import register_program_commands
from softplc.engine.retained_values import RetainedValues
from softplc.engine.runtime_commands import register_runtime_commands
from softplc.engine.scan import ProgramInstance, ProgramState, ScanEngine, Task
from softplc.engine.stall import StallDetector
from softplc.engine.systags import SystemTags
from softplc.util.durations import parse_duration
from softplc.util.plurals import plural
from softplc.util.tasks import cancel_and_wait

__all__ = ["Adapter", "AdapterError", "Runtime", "RuntimeState"]

log = logging.getLogger(__name__)


class RuntimeState(enum.Enum):
    STARTING = "STARTING"
    RUNNING = "RUNNING"
    ERROR = "ERROR"
    STOPPING = "STOPPING"
    STOPPED = "STOPPED"


class Runtime:
    """One plant: its tags, tasks and adapters, on one clock."""

    def __init__(
        self,
        config: PlantConfig,
        clock: Clock | None = None,
        *,
        state_dir: Path | None = None,
        retain: bool = True,
        corrupt_retain: str = "refuse",
    ) -> None:
        """`retain=False`: start from the initial values and leave the retained ones alone (a simulated run).

        `corrupt_retain`: what `start()` does when `retain.sqlite` is corrupt — `refuse` (raise
        RetainError, leaving the file as it is) or `initial` (set it aside, start from initial values).
        """
        if corrupt_retain not in ("refuse", "initial"):
            raise ValueError(f"corrupt_retain must be 'refuse' or 'initial', not {corrupt_retain!r}")
        self.config = config
        self.clock = clock or RealClock()
        self.state_dir = state_dir or config.state_dir
        self.db = TagDatabase([*config.tags, *runtime_tag_definitions(config)], self.clock.wall)
        # The plant's role in a redundant pair (ACTIVE alone): the engine scans and the tag
        # database accepts writes only while it is active (softplc/core/plant_role.py).
        self.role = RoleHolder(self.clock.now)
        self.db.role = self.role
        self.program_clock = PlantTime(self.clock)  # what programs and their timers read (softplc/core/clock.py)
        self.tasks = [self._build_task(task) for task in config.tasks]
        self.engine = ScanEngine(self.clock, self.db, self.tasks)
        self.engine.role = self.role
        self._replication: Any = None
        self._replicated_parts: dict[str, Any] = {}  # adapters' parts (Plant.replicate), handed to the replication when made
        self.engine.after_cycle(self._after_cycle)
        self.system_tags = SystemTags(self.db, self.engine, self._state_for_tags, self.reset_faults)
        self.commands = Commands(self.clock.wall)
        self.commands.refusal = self.role.refusal  # a standby carries out no action (queries only)
        self.events = EventBus()
        register_runtime_commands(self)
        register_program_commands(self)
        self._scan_gate: Any = None
        self.online_change = OnlineChange(self)
        self.plant = RuntimePlant(self)  # what adapters are handed (softplc/core/plant.py)
        self.adapters: list[Adapter] = []
        self.state = RuntimeState.STARTING
        self.error = ""
        self.stop_reason = ""
        self._stop_event: asyncio.Event | None = None
        self._background: list[asyncio.Task[Any]] = []
        self._stall: tuple[Task, str, str] | None = None
        self._stall_detector: StallDetector | None = None
        self.retained = RetainedValues(self.db, self.clock, self.state_dir / "retain.sqlite", corrupt_retain) if retain else None
        self.running = asyncio.Event()  # set once every adapter has started and scanning begins
        self.started_at: float | None = None  # clock time when scanning began
        self._started = False
        self._drive: asyncio.Task[Any] | None = None

    def _build_task(self, task: Any) -> Task:
        instances = []
        for program in task.programs:
            try:
                created = program.cls(ProgramContext(program.name, self.program_clock, dict(program.params), self.role))
            except Exception as error:  # user code: say which program and where, never a traceback
                where = program.location or Location(str(self.config.path), 1, 1)
                message = f"program '{program.name}' ({program.reference}) cannot be created: {type(error).__name__}: {error}"
                raise ConfigError([Problem(where, message)]) from error
            instance = ProgramInstance(program.name, created, program.bindings, program.restart, program.on_fault,
                                       reference=program.reference, params=program.params)
            if not program.enabled:
                instance.state = ProgramState.STOPPED
            instances.append(instance)
        return Task(task.name, task.interval, instances, priority=task.priority, watchdog=task.watchdog)

    # -- public API -----------------------------------------------------------------------

    def program(self, name: str) -> ProgramInstance:
        for task in self.tasks:
            for instance in task.programs:
                if instance.name == name:
                    return instance
        raise KeyError(name)

    @property
    def scan_gate(self) -> Any:
        """The runtime's one ScanGate (softplc/engine/scan_gate.py) for worker threads; None on a simulated clock or without tasks."""
        if self._scan_gate is None and not self.clock.simulated and self.tasks:
            from softplc.engine.scan_gate import ScanGate

            self._scan_gate = ScanGate(self.engine, self.clock)
        return self._scan_gate

    @property
    def replication(self) -> Any:
        """The plant's state for a standby (softplc/engine/replication_wire.py), made on first use: it follows every change."""
        if self._replication is None:
            from softplc.engine.replication import Replication
            from softplc.engine.replication_wire import ReplicationDoor

            self._replication = ReplicationDoor(Replication(self.db, self.tasks, self.program_clock, self.clock, self._replicated_parts))
        return self._replication

    def add_replicated_part(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                            apply: Callable[[Any], None]) -> Callable[[], None]:
        """An adapter's own state for a standby (`Plant.replicate`); kept aside until a redundant pair makes the replication."""
        from softplc.engine.replication import Part

        part = Part(capture, check, apply)
        self._replicated_parts[name] = part
        return lambda: self._replicated_parts.pop(name, None) if self._replicated_parts.get(name) is part else None

    @property
    def stopping(self) -> bool:
        """Whether the runtime is stopping or stopped (an online change then applies nothing)."""
        return self.state in (RuntimeState.STOPPING, RuntimeState.STOPPED)

    @property
    def shared_outputs(self) -> set[str]:
        """Tags several programs may write (`shared_output: true`)."""
        return self.config.shared_outputs

    def run_setup(self, task: Task, instance: ProgramInstance, setup: Callable[[], None]) -> None:
        """Run a program's setup() outside a cycle (a reset, a command), watched for stalls like a scan."""
        self.engine.run_setup(task, instance, setup)
        self._apply_stall()
        self.programs_changed()

    def programs_changed(self) -> None:
        """After a change outside a cycle (a failed setup(), a stall, a command): commit the fault
        reactions due and publish the programs' states now, not at the next publication."""
        self.engine.commit_reactions()
        self.system_tags.publish_state()

    def add_adapter(self, adapter: Adapter) -> None:
        self.adapters.append(adapter)

    def spawn(self, coroutine: Coroutine[Any, Any, Any], name: str) -> asyncio.Task[Any]:
        """Run a background coroutine for the runtime's lifetime; its crash is logged, not lost."""
        task = asyncio.create_task(coroutine, name=name)
        task.add_done_callback(self._background_done)
        self._background.append(task)
        return task

    def request_stop(self, reason: str) -> None:
        if not self.stop_reason:
            self.stop_reason = reason
        if self._stop_event is not None:
            self._stop_event.set()

    def reset_faults(self) -> None:
        """Clear the ERROR state and restart every FAULTED program (`_sys.reset_faults`)."""
        # Cleared first: a setup() that stalls during this very reset puts the runtime back in ERROR.
        if self.state is RuntimeState.ERROR:
            self.state = RuntimeState.RUNNING
            self.error = ""
        now = self.clock.now()
        for task in self.tasks:
            for instance in task.programs:
                if instance.state is ProgramState.FAULTED:
                    # Outside any cycle, yet watched like one: a setup() that blocks is named.
                    self.run_setup(task, instance, lambda instance=instance: instance.reset(now))

    # -- lifecycle ------------------------------------------------------------------------

    async def start(self) -> None:
        """Load retained values, start programs, the scan engine and every adapter."""
        if self._started:
            raise RuntimeError("runtime already started")
        self._started = True
        self._stop_event = asyncio.Event()
        if self.stop_reason:  # a stop requested before the start (an early Ctrl-C) still counts
            self._stop_event.set()
        if self.retained is not None:
            self.retained.load()
        # Watching from before the first setup(): one that blocks at start-up is named too.
        self._stall_detector = StallDetector(self.engine, self._on_stall, stall_after=self._stall_after(), simulated=self.clock.simulated)
        self._stall_detector.start()
        self.engine.start_programs()
        self._apply_stall()
        self.programs_changed()  # of a setup() that failed at start-up
        self.system_tags.publish(self.clock.now())
        started: list[Adapter] = []
        try:
            for adapter in self.adapters:
                await adapter.start(self.plant)
                started.append(adapter)
        except BaseException:
            for adapter in reversed(started):
                await _quietly(adapter.stop(), adapter.name)
            await self._cancel_background()
            if self._stall_detector is not None:
                self._stall_detector.stop()
            raise
        if self.state is RuntimeState.STARTING:  # not ERROR: a stalled setup() stays visible
            self.state = RuntimeState.RUNNING
        if not self.clock.simulated:
            # What exists now (tags, programs, servers' address spaces, maps) lives as long as
            # the runtime. A full collection walks every object it tracks — 10-20 ms with the
            # servers and robots loaded, i.e. a late 10 ms cycle; frozen objects are never walked.
            gc.collect()
            gc.freeze()
        if isinstance(self.clock, SimClock):
            # Simulated time starts only now: adapters take real time to start (OPC UA ~2 s),
            # and robots started meanwhile must not run ahead of the plant.
            self._drive = self.spawn(self.clock.drive(), "sim-clock")
        self.spawn(self.engine.run(), "scan-engine")
        self.spawn(self._housekeeping(), "housekeeping")
        self.started_at = self.clock.now()
        self.running.set()

    async def stop(self) -> None:
        """Stop scanning, stop adapters, save retained values. Safe to call twice."""
        if self.state is RuntimeState.STOPPED:
            return
        self.state = RuntimeState.STOPPING
        self.engine.stop()
        if self._drive is not None:
            # Simulated time ends here: while adapters stop (real I/O, ~1 s for OPC UA) the idle
            # clock would otherwise race ahead and keep robots and housekeeping going.
            self._drive.cancel()
        if self._stall_detector is not None:
            self._stall_detector.stop()
        for adapter in reversed(self.adapters):
            await _quietly(adapter.stop(), adapter.name)
            # Its clients were told their writes were accepted (journaled), up to its very last
            # answer: apply them now, no scan will, while the adapters still running (historian,
            # alarms, audit) see them; the last save below keeps the retained ones.
            self._apply_accepted_writes()
        await self._cancel_background()
        self._apply_accepted_writes()
        if self.db.forces:
            log.warning("%s released by the stop (forces are not retained): %s",
                        plural(len(self.db.forces), "forced tag"), ", ".join(force.tag for force in self.db.forces.active()))
        if self.retained is not None:
            self.retained.close()  # saves what changed since the last save first
        self.state = RuntimeState.STOPPED

    async def run(self, duration: float | None = None, until: Condition | None = None) -> str:
        """Start, run until `duration` (clock seconds), `until` holds or `request_stop()`, stop."""
        if until is not None:
            self.engine.after_cycle(lambda task: self._check_until(until))
        await self.start()
        try:
            if duration is not None:
                self.spawn(self._stop_after(duration), "duration")
            assert self._stop_event is not None
            await self._stop_event.wait()
        finally:
            await self.stop()
        return self.stop_reason

    # -- internals ------------------------------------------------------------------------

    def _stall_after(self) -> float | None:
        value = self.config.runtime.get("stall_after")
        return parse_duration(value) if value is not None else None

    def _state_for_tags(self) -> tuple[str, str]:
        return self.state.value, self.error

    def _check_until(self, condition: Condition) -> None:
        if not self.stop_reason and condition.evaluate(self.db.value):
            self.request_stop(f"condition met: {condition.text}")

    async def _stop_after(self, duration: float) -> None:
        await self.clock.sleep(duration)
        self.request_stop(f"duration of {duration:g} s reached")

    async def _housekeeping(self) -> None:
        """Publish system tags twice a second and save retained values once a second."""
        tick = 0
        while True:
            await self.clock.sleep(0.5)
            self.system_tags.publish(self.clock.now())
            tick += 1
            if tick % 2 == 0 and self.retained is not None:
                await self.retained.save()

    def _after_cycle(self, task: Task) -> None:
        if self._stall is not None:
            self._apply_stall()

    def _apply_stall(self) -> None:
        """Fault the program a stall was reported for, once the loop runs again, and say so at once."""
        if self._stall is None:
            return
        stalled_task, program, message = self._stall
        self._stall = None
        for instance in stalled_task.programs:
            if instance.name == program and instance.state is ProgramState.RUNNING:
                instance.fault(message, self.clock.now())
        # The stuck cycle has committed; the reaction follows at once. Clients could not be answered
        # while the loop was blocked; the first answers after it must already say ERROR, not wait
        # for the next publication (up to 0.5 s).
        self.programs_changed()

    def _on_stall(self, task: Task, program: str, message: str) -> None:
        # Called from the stall detector's thread while the loop is blocked: only plain
        # attribute writes here; the loop picks them up when the scan returns.
        self.state = RuntimeState.ERROR
        self.error = message
        self._stall = (task, program, message)

    def _background_done(self, task: asyncio.Task[Any]) -> None:
        if task.cancelled():
            return
        error = task.exception()
        if error is not None:
            log.error("background task %s crashed: %r", task.get_name(), error, exc_info=error)
            self.state = RuntimeState.ERROR
            self.error = f"{task.get_name()} crashed: {error!r}"

    async def _cancel_background(self) -> None:
        await cancel_and_wait(self._background)
        self._background.clear()

    def _apply_accepted_writes(self) -> None:
        """At stop: apply the writes still journaled (the scan that would have applied them has ended)."""
        try:
            applied = self.db.apply_journal()
        except Exception:  # a listener's failure must not cost the shutdown (and the save after it)
            log.exception("applying the writes accepted before the stop failed")
            return
        if applied:
            log.info("stop: %s accepted before the stop applied", plural(applied, "write"))


async def _quietly(coroutine: Coroutine[Any, Any, Any], name: str) -> None:
    try:
        await coroutine
    except Exception:
        log.exception("stopping %s failed", name)
