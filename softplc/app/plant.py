"""The runtime's side of the plant API (softplc/core/plant.py): what adapters are handed instead of the Runtime."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine, Sequence
from pathlib import Path
from typing import Any, Protocol

from softplc.config.plant import PlantConfig
from softplc.core.clock import Clock
from softplc.core.commands import Commands
from softplc.core.events import EventBus
from softplc.core.plant import StateReplication, TaskView, ThreadGate
from softplc.core.plant_role import RoleHolder
from softplc.core.tagdb import TagDatabase

log = logging.getLogger(__name__)


class _Runtime(Protocol):
    """What the plant API reads of `softplc.app.runtime.Runtime` (which imports this module)."""

    config: PlantConfig
    clock: Clock
    db: TagDatabase
    commands: Commands
    events: EventBus
    state_dir: Path
    role: RoleHolder
    engine: Any
    adapters: list[Any]
    state: Any
    error: str

    @property
    def scan_gate(self) -> ThreadGate | None: ...

    @property
    def replication(self) -> StateReplication: ...

    def spawn(self, coroutine: Coroutine[Any, Any, Any], name: str) -> asyncio.Task[Any]: ...

    def add_replicated_part(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                            apply: Callable[[Any], None]) -> Callable[[], None]: ...


class RuntimePlant:
    """A `Plant` over one runtime: its tags, commands, events, clock and state directory, and nothing else."""

    def __init__(self, runtime: _Runtime) -> None:
        self._runtime = runtime
        self.name = runtime.config.name
        self.clock = runtime.clock
        self.tags = runtime.db
        self.commands = runtime.commands
        self.events = runtime.events
        self.state_dir = runtime.state_dir
        self.role = runtime.role
        self._failing: set[str] = set()  # adapters whose metrics() raised (logged once)

    @property
    def tasks(self) -> Sequence[TaskView]:
        return self._runtime.engine.tasks

    @property
    def state(self) -> str:
        return self._runtime.state.value

    @property
    def error(self) -> str:
        return self._runtime.error

    @property
    def gate(self) -> ThreadGate | None:
        return self._runtime.scan_gate

    @property
    def replication(self) -> StateReplication:
        return self._runtime.replication

    def spawn(self, coroutine: Coroutine[Any, Any, Any], name: str) -> asyncio.Task[Any]:
        return self._runtime.spawn(coroutine, name)

    def after_cycle(self, callback: Callable[[TaskView], None], *, last: bool = False) -> Callable[[], None]:
        return self._runtime.engine.after_cycle(callback, last=last)

    def replicate(self, name: str, capture: Callable[[bool], Any], check: Callable[[Any], Any],
                  apply: Callable[[Any], None]) -> Callable[[], None]:
        return self._runtime.add_replicated_part(name, capture, check, apply)

    def until_release(self) -> float | None:
        tasks = self._runtime.engine.tasks
        if self.clock.simulated or not tasks:
            return None
        return min(task.next_release for task in tasks) - self.clock.now()

    def figures(self) -> dict[str, dict[str, Any]]:
        found: dict[str, dict[str, Any]] = {}
        for adapter in self._runtime.adapters:
            report = getattr(adapter, "metrics", None)
            if not callable(report):
                continue
            name = str(getattr(adapter, "name", type(adapter).__name__))
            try:
                found[name] = dict(report())
            except Exception:  # one adapter's bug must not take the other figures down
                if name not in self._failing:
                    self._failing.add(name)
                    log.exception("metrics: the %s adapter's metrics() failed; its figures are left out", name)
        return found
