"""The alarms adapter: runs the engine at scan boundaries, keeps the journal and the summary tags.

Built by `softplc.app.adapters` from the `alarms:` section. Under `run --sim` the journal is a
SQLite file of its own (STATE_DIR/alarms-sim.sqlite, emptied at each start, timestamps in
simulated time), never the real plant's journal.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.adapters.alarms.actions import AlarmActions
from softplc.adapters.alarms.commands import register_alarm_commands
from softplc.adapters.alarms.engine import AlarmEngine
from softplc.adapters.alarms.replication import AlarmReplica
from softplc.adapters.alarms.settings import AlarmSettings
from softplc.adapters.alarms.summary import SummaryTags
from softplc.core.tagdb import Origin
from softplc.storage import BatchWriter, Database, StorageSettings, remove_sqlite_store
from softplc.storage.alarm_journal import AlarmJournal, JournalSink

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

JOURNAL_FILE = "alarms.sqlite"
SIM_JOURNAL_FILE = "alarms-sim.sqlite"
IDLE_TICK = 0.1  # evaluation period of a plant without tasks (no scan boundaries)


class AlarmsAdapter:
    """The alarm engine around the core (see the module docstring)."""

    name = "alarms"

    def __init__(self, settings: AlarmSettings) -> None:
        self.settings = settings
        self.engine: AlarmEngine | None = None
        self.actions: AlarmActions | None = None
        self.journal: AlarmJournal | None = None
        self.storage: StorageSettings | None = None
        self._writer: BatchWriter | None = None
        self._summary: SummaryTags | None = None
        self._undo: list[Callable[[], None]] = []
        self._running = False
        self._plant: Plant | None = None

    async def start(self, plant: Plant) -> None:
        engine = AlarmEngine(self.settings, plant.tags, plant.clock, plant.events.publish)
        self.engine, self.actions = engine, AlarmActions(engine)
        self.journal = await self._open_journal(plant)
        undo = self._undo
        undo.append(plant.events.subscribe(self.journal.record, kinds=("alarm",)))
        undo.extend(register_alarm_commands(plant.commands, engine, self.actions, self.journal, plant.clock))
        commands = plant.commands

        async def acknowledge_all(origin: Origin) -> Any:
            return await commands.call("alarms.acknowledge_all", {"comment": "acknowledge-all tag"}, origin)

        self._summary = SummaryTags(plant.tags, acknowledge_all)
        undo.append(plant.tags.on_change(engine.note_changed))
        undo.append(plant.tags.on_write(self._summary.note_writes))
        # In a redundant pair the states travel to the standby, which takes them as they are
        # (docs/redundancy.md): a successor goes on with them instead of annunciating anew.
        replica = AlarmReplica(engine)
        undo.append(plant.replicate("alarms", replica.capture, replica.check, lambda checked: self._mirror(replica, checked)))
        self._plant = plant
        self._running = True
        if plant.tasks:
            undo.append(plant.after_cycle(self._after_cycle))
        else:
            plant.spawn(self._tick(plant), "alarms")
        log.info("alarms: %d defined; journal in %s", len(engine.alarms), self.storage.describe() if self.storage else "-")

    async def _open_journal(self, plant: Plant) -> AlarmJournal:
        if plant.clock.simulated:
            path = Path(plant.state_dir) / SIM_JOURNAL_FILE
            remove_sqlite_store(path)
            storage = StorageSettings.sqlite(path)
        else:
            storage = StorageSettings.from_section(self.settings.journal, Path(plant.state_dir), JOURNAL_FILE)
        self.storage = storage
        database = Database(storage)
        writer = BatchWriter(database, name="alarm-journal")
        writer.register(JournalSink(self.settings.retention, plant.clock.wall))
        error = await asyncio.to_thread(writer.start)
        if error is not None:  # the writer keeps the rows and retries: alarms work without the store
            log.error("alarm journal: cannot open %s: %s; retrying, rows are kept meanwhile", storage.describe(), error)
        self._writer = writer
        return AlarmJournal(database, writer, plant.name)

    def _after_cycle(self, task: Any) -> None:
        if self._running:
            self.evaluate()

    def _mirror(self, replica: AlarmReplica, checked: Any) -> None:
        """A standby takes the active's alarm states, and shows their counts in its summary tags."""
        replica.apply(checked)
        engine, summary = self.engine, self._summary
        if engine is not None and summary is not None and engine.changed:
            engine.changed = False
            summary.publish(engine.active_count, engine.unacknowledged_count, engine.highest_active_priority, engine.shelved_count,
                            engine.flood.rate, engine.flood.flooding)

    def evaluate(self) -> None:
        """Evaluate the alarms and refresh the summary tags (at a scan boundary)."""
        engine = self.engine
        summary = self._summary
        assert engine is not None and summary is not None and self.journal is not None
        with self.journal.batch():  # the rows of this boundary's transitions, to the writer at once
            engine.evaluate()
        if engine.changed or summary.requested():
            engine.changed = False
            summary.publish(engine.active_count, engine.unacknowledged_count, engine.highest_active_priority, engine.shelved_count,
                            engine.flood.rate, engine.flood.flooding)

    async def _tick(self, plant: Plant) -> None:
        while self._running:
            await plant.clock.sleep(IDLE_TICK)
            if plant.role.is_active():  # a standby evaluates nothing: it takes the active's states
                self.evaluate()

    async def stop(self) -> None:
        self._running = False
        for undo in reversed(self._undo):
            try:
                undo()
            except ValueError:  # already gone
                pass
        self._undo.clear()
        if self._summary is not None:
            self._summary.cancel()
        if self._writer is not None:
            await asyncio.to_thread(self._writer.stop)
            self._writer = None

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py): alarms active, unacknowledged, shelved."""
        engine = self.engine
        if engine is None:
            return {}
        return {"active": engine.active_count, "unacknowledged": engine.unacknowledged_count, "shelved": engine.shelved_count}

    def describe(self) -> str:
        count = len(self.engine.alarms) if self.engine is not None else len(self.settings.definitions)
        where = self.storage.describe() if self.storage is not None else "the state directory"
        return f"alarms: {count} defined, journal in {where}"
