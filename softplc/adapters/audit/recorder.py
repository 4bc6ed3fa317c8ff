"""The audit adapter: listens to every client write and every command call, and keeps them durably.

Two hooks of the core carry everything with its origin (`softplc/core/origin.py`), whichever adapter
it came through: `db.on_write` (each client write, accepted or refused, with the old and new
value and the rule broken) and `commands.on_call` (each call of a command that acts: forcing,
program control, alarm actions, resetting faults...). The listeners only queue the core's own
objects (a list append under a lock); the storage writer's thread turns them into rows and
commits them once per flush period (`softplc.storage`), so the scan never waits for a disk,
and a kill -9 loses at most one flush period. No protocol adapter keeps a log of its own.

Under `run --sim` the trail is a SQLite file of its own (STATE_DIR/audit-sim.sqlite, emptied at
each start, timestamps in simulated time), never the real plant's trail.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from softplc.adapters.audit.commands import register_audit_commands
from softplc.core.clock import Clock
from softplc.core.commands import CommandCall, Commands
from softplc.core.tagdb import TagDatabase, WriteEvent
from softplc.storage import BatchWriter, Database, StorageSettings, remove_sqlite_store
from softplc.storage.audit.entry import AuditEntry, CallRecord
from softplc.storage.audit.queries import AuditQuery, search
from softplc.storage.audit.settings import AuditSettings
from softplc.storage.audit.store import SINK_NAME, AuditSink
from softplc.util.realtime import shorten_switch_interval

if TYPE_CHECKING:
    from softplc.core.plant import Plant, ThreadGate

log = logging.getLogger(__name__)

# Entries kept in memory while the store cannot be written (a PostgreSQL restart): ~150 MB at most.
MAX_PENDING = 1_000_000


class AuditRecorder:
    """The audit trail around the core: `start(plant)`, `stop()`, `describe()` (see the module docstring)."""

    name = "audit"

    def __init__(self, settings: AuditSettings, plant: str) -> None:
        self.settings = settings
        self.plant = plant
        self.storage: StorageSettings | None = None
        self.database: Database | None = None
        self.writer: BatchWriter | None = None
        self.recorded = 0
        self.gate: ThreadGate | None = None
        self._sink: AuditSink | None = None
        self._db: TagDatabase | None = None
        self._commands: Commands | None = None
        self._simulated = False
        self._clock: Clock | None = None
        self._undo: list[Callable[[], None]] = []

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        self._clock = plant.clock
        self._simulated = simulated = plant.clock.simulated
        self.storage = storage = self.settings.storage(plant.state_dir, simulated=simulated)
        if simulated and storage.path is not None:
            # A simulated run starts at the same simulated instant every time: its trail
            # replaces the previous run's instead of overlapping it.
            try:
                remove_sqlite_store(storage.path)
            except OSError as error:
                raise AdapterError(f"audit: cannot open SQLite {storage.path}: {error}") from None
        self.database = database = Database(storage)
        writer = BatchWriter(database, name="softplc-audit-writer", max_pending=MAX_PENDING)
        # On the real clock the writer steps aside while a scan cycle is due (softplc/engine/scan_gate.py).
        self.gate = gate = plant.gate  # None on a simulated clock
        self._sink = AuditSink(self.plant, partition=self.settings.partition, retention=self.settings.retention, now=plant.clock.wall,
                               steps=gate.stepping if gate is not None else None)
        writer.register(self._sink)
        shorten_switch_interval()  # the writer thread builds rows and JSON in Python between its SQL calls
        error = await plant.clock.run_blocking(writer.start)
        if error is not None:
            if not database.postgresql:
                # A plant that runs without its audit trail must be a decision, not an accident.
                await plant.clock.run_blocking(writer.stop)
                raise AdapterError(f"audit: cannot open {database.describe()}: {error} "
                                   "(to run without an audit trail: audit: {enabled: false} in the configuration)")
            log.error("audit: %s is unreachable (%s); entries are kept in memory (at most %d) and written when it is back",
                      database.describe(), error, MAX_PENDING)
        self.writer = writer
        self._db, self._commands = plant.tags, plant.commands
        self._undo = [plant.tags.on_write(self._note_writes), plant.commands.on_call(self._note_call)]
        self._undo += register_audit_commands(plant.commands, self, plant.clock)

    async def stop(self) -> None:
        for undo in reversed(self._undo):
            try:
                undo()
            except (ValueError, KeyError):  # already gone
                pass
        self._undo.clear()
        writer, self.writer = self.writer, None
        if self._sink is not None:
            self._sink.stepping = False  # the scan has stopped (adapters stop after it): write the rest at once
        if writer is not None:
            assert self._clock is not None
            await self._clock.run_blocking(writer.stop)
            if writer.stats.dropped:
                log.error("audit: %d entries were dropped: the store could not be written for too long", writer.stats.dropped)

    def describe(self) -> str:
        where = self.storage.describe() if self.storage is not None else "the state directory"
        sim = " (simulated time)" if self._simulated else ""
        kept = f"kept {self.settings.retention / 86400:g} d" if self.settings.retention is not None else "kept forever"
        return f"audit trail: every client write and command to {where}{sim}, {kept}"

    # -- the listeners (on the event loop: queue, nothing more) ----------------------------

    def _note_writes(self, events: Sequence[WriteEvent]) -> None:
        writer = self.writer
        if writer is not None:
            writer.put(SINK_NAME, events)
            self.recorded += len(events)

    def _note_call(self, call: CommandCall) -> None:
        writer = self.writer
        if writer is None:
            return
        arguments = call.arguments
        name = arguments.get("tag")
        tag = self._db.get(name) if isinstance(name, str) and self._db is not None else None
        if tag is None:
            record = CallRecord(call, "", None, None, self._rule(call))
        else:
            new = arguments.get("value")
            if isinstance(new, str):
                try:
                    new = tag.definition.type.parse(new)
                except ValueError:  # TypeMismatch: kept as the text given (the call was refused for it)
                    pass
            record = CallRecord(call, tag.name, tag.value, new, self._rule(call))
        writer.put(SINK_NAME, [record])
        self.recorded += 1

    def _rule(self, call: CommandCall) -> str:
        if call.accepted:
            return ""
        command = self._commands.get(call.command) if self._commands is not None else None
        if command is None:
            return "unknown command"
        if not command.permission.allows(call.origin.role):
            return "access denied"
        return "refused"

    # -- reading (blocking: off the event loop) --------------------------------------------

    def flush(self, timeout: float = 30.0) -> bool:
        """Wait until every entry recorded so far is committed."""
        return self.writer.flush(timeout) if self.writer is not None else False

    def search(self, query: AuditQuery) -> list[AuditEntry]:
        """The committed entries matching `query`, newest first."""
        if self.database is None:
            return []
        return search(self.database, query, self.plant)

