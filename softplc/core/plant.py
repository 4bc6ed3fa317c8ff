"""The plant API: the one door through which every adapter reaches the core.

An adapter (a protocol server, the HMI, the historian, the alarms, the fleet...) is handed a
`Plant` when it starts, and nothing else of the runtime:

    class MyAdapter:
        name = "mine"

        async def start(self, plant: Plant) -> None:
            values = plant.tags.snapshot(["t01_iBL"])               # read one consistent image
            self._undo = plant.tags.on_change(self.changed)          # be told of changes (a batch per cycle)
            plant.tags.submit([("t01_iFr", 20.0)], origin)           # write, validated now, applied at the next cycle
            plant.commands.register("mine.status", self.status, permission=Permission.VIEW)
            await plant.clock.sleep(1.0)                             # every wait on the plant's clock

        async def stop(self) -> None: ...
        def describe(self) -> str: return "mine on ..."

What one adapter offers another (the alarm journal, audit queries, the fleet's map, a metrics
scrape) is a registered command or query (`plant.commands`), never an import of the other
adapter's modules. The composition root (`softplc.app.runtime`) implements this protocol;
tests/app/test_imports.py keeps adapters from importing anything else of the runtime.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from softplc.core.clock import Clock
from softplc.core.commands import Commands
from softplc.core.events import EventBus
from softplc.core.plant_role import RoleHolder
from softplc.core.tagdb import TagDatabase


class AdapterError(RuntimeError):
    """An adapter could not start (port in use, bad certificate...); the message says why."""


class StateRefused(ValueError):
    """A replicated state or journal entry that is malformed or cannot be applied; nothing of it was applied."""


class ProgramView(Protocol):
    """A program of a task, as adapters see it (read only)."""

    name: str
    reference: str  # module:Class, as configured
    error: str  # the last fault's message ("" when none)
    faults: int  # faults since the plant started

    @property
    def state(self) -> Any: ...  # an enum whose .value is RUNNING, FAULTED or STOPPED


class TaskView(Protocol):
    """A task, as adapters see it (read only): its timing statistics and its programs."""

    name: str
    interval: float  # seconds
    priority: int  # lower runs first when two are due
    watchdog: float  # seconds a scan may take before it counts as a watchdog trip
    stats: Any  # cycles, overruns, watchdog_trips and the scan / cycle / latency timing series
    programs: Sequence[ProgramView]
    next_release: float  # clock time of the next cycle


class ThreadGate(Protocol):
    """Lets a worker thread step aside while a scan cycle is due (the engine's ScanGate)."""

    def worker(self) -> AbstractContextManager[Any]:
        """`with gate.worker(): work()` in a thread: the work pauses around every release."""
        ...

    def stepping(self) -> AbstractContextManager[Callable[[], None]]:
        """`with gate.stepping() as step:` work in small steps, calling `step()` between them."""
        ...


class StateReplication(Protocol):
    """A plant's state at cycle boundaries as plain data, for a redundant pair (softplc/engine/replication_wire.py)."""

    @property
    def sequence(self) -> int: ...  # of the last state captured (active) or applied (standby)

    @property
    def held(self) -> int: ...  # the active's journal entries a standby holds, not yet applied there

    def capture(self, task: TaskView | None) -> list[Any]:
        """What changed since the previous capture, at the end of `task`'s cycle (call from `after_cycle`; None: a heartbeat)."""
        ...

    def capture_full(self) -> list[Any]:
        """The whole state: every tag but `_sys.`, the forces, every program's state, every part."""
        ...

    def apply(self, state: Any) -> None:
        """Make this (standby) plant's state the captured one; raises StateRefused, applying nothing."""
        ...

    def on_journal(self, callback: Callable[[list[Any]], None]) -> Callable[[], None]:
        """Call `callback(message)` for every batch of writes journaled here, before the writer is answered."""
        ...

    def pending_journal(self) -> list[Any]:
        """The writes journaled and not yet applied, as one journal message (send it after a full state)."""
        ...

    def hold(self, message: Any) -> None:
        """Keep the active's journal entries until a state says they were applied; raises StateRefused."""
        ...

    def take_over(self) -> int:
        """This standby becomes active: resume the active's write journal; returns the writes resumed."""
        ...

    def add_part(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                 apply: Callable[[Any], None]) -> Callable[[], None]:
        """Replicate an adapter's state too (see `Plant.replicate`); returns an undo."""
        ...


@runtime_checkable
class Plant(Protocol):
    """What an adapter may use of a running plant (see the module docstring)."""

    name: str  # the plant's name (`plant.name` of tagdb.yaml)
    clock: Clock  # every wait and timestamp; simulated under --sim
    tags: TagDatabase  # snapshot, on_change, submit with an origin, on_write, refused, force
    commands: Commands  # register and call commands and queries with an origin
    events: EventBus  # what happened (alarm transitions...)
    state_dir: Path  # where adapters keep durable state (stores, certificates, tokens)
    role: RoleHolder  # ACTIVE alone; in a redundant pair set by its adapter (softplc/core/plant_role.py)

    @property
    def tasks(self) -> Sequence[TaskView]: ...

    @property
    def state(self) -> str: ...  # STARTING, RUNNING, ERROR, STOPPING or STOPPED

    @property
    def error(self) -> str: ...  # why the plant is in ERROR ("" otherwise)

    @property
    def gate(self) -> ThreadGate | None: ...  # None on a simulated clock or without tasks

    @property
    def replication(self) -> StateReplication: ...  # the plant's state for a standby (made on first use)

    def spawn(self, coroutine: Coroutine[Any, Any, Any], name: str) -> asyncio.Task[Any]:
        """Run a background coroutine for the plant's lifetime; its crash is logged, not lost."""
        ...

    def after_cycle(self, callback: Callable[[TaskView], None], *, last: bool = False) -> Callable[[], None]:
        """Call `callback(task)` at every scan boundary, after the task's outputs are committed; returns an undo.

        `last`: after every other adapter's callback (a redundant pair captures what they left at the boundary).
        """
        ...

    def replicate(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                  apply: Callable[[Any], None]) -> Callable[[], None]:
        """In a redundant pair, send an adapter's own state (e.g. the alarms') with the plant's at each boundary; returns an undo.

        On the active `capture(full)` returns the part's plain data (lists, numbers, text; None:
        unchanged since the previous capture). On the standby `check(data)` validates what came
        (raising StateRefused: then nothing of that whole state is applied) and returns what
        `apply` takes. A plant alone never calls them.
        """
        ...

    def until_release(self) -> float | None:
        """Real seconds until the next task's release; None when nothing is to be guarded (simulated clock, no task)."""
        ...

    def figures(self) -> dict[str, dict[str, Any]]:
        """Every started adapter's own figures (its optional `metrics()`), by adapter name: what /metrics shows."""
        ...


class Adapter(Protocol):
    """Something started around the core: a protocol server, a robot fleet, the HMI."""

    name: str

    async def start(self, plant: Plant) -> None: ...

    async def stop(self) -> None: ...

    def describe(self) -> str:
        """One line for the user: where it serves, e.g. 'OPC UA on opc.tcp://127.0.0.1:4840/'."""
        ...
