"""The historian adapter: listens to tag changes, filters them, hands the rows to the store's writer.

Each recorded tag has a `TagFilter`: an exception deadband (a value is kept only when it moved
more than the deadband since the last kept one), then swinging-door compression when the rule
asks for it. A quality change is always recorded (the held value first, so the shape is kept).
Filtering runs on the event loop inside the change notification (under a microsecond a value);
the rows go to the writer, which runs in a process of its own on the real clock
(softplc/storage/process.py) and in a thread under --sim. Timestamps are the tags' own (the
runtime clock's wall time: simulated under --sim).
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from softplc.adapters.history.columns import QUALITY_CODES
from softplc.adapters.history.commands import register_history_commands
from softplc.adapters.history.queries import HistoryReader
from softplc.adapters.history.settings import HistorySettings, TagPolicy
from softplc.adapters.history.store import SINK_NAME, HistorySink, TagInfo
from softplc.adapters.history.swinging_door import SwingingDoor
from softplc.core.plant_role import RoleTerm
from softplc.core.tags import Quality, Tag
from softplc.storage import BatchWriter, Database, StorageSettings, remove_sqlite_store
from softplc.storage.process import ProcessWriter
from softplc.util.plurals import plural
from softplc.util.realtime import shorten_switch_interval

if TYPE_CHECKING:
    from softplc.core.plant import Plant

log = logging.getLogger(__name__)

# A row to store: (tag name, time, value, quality code: 0 good, 1 uncertain, 2 bad). Only atomic values,
# so the collector stops tracking the tuple at its first pass: rows queued for a flush period never
# reach the older generations, whose collections would otherwise hold the event loop for milliseconds.
Row = tuple[str, float, Any, int]
HEARTBEAT_TICK = 1.0  # s of runtime clock between two heartbeat checks


class TagFilter:
    """Decides which values of one tag are stored (deadband, then compression)."""

    __slots__ = ("name", "deadband", "door", "numeric", "last", "quality", "code")

    def __init__(self, name: str, policy: TagPolicy, numeric: bool) -> None:
        self.name = name
        self.deadband = policy.deadband
        self.door = SwingingDoor(*policy.compression) if policy.compression else None
        self.numeric = numeric
        self.last: Any = None  # the last value passed on (deadband reference)
        self.quality: Quality | None = None
        self.code = 0  # the quality's code in rows

    def offer(self, when: float, value: Any, quality: Quality) -> list[Row]:
        """The rows to store for a new value of the tag."""
        name = self.name
        if quality is not self.quality or self.last is None:
            rows: list[Row] = []
            code = QUALITY_CODES[quality]
            door = self.door
            if door is not None:
                held = self.code if self.quality is not None else code
                rows = [(name, t, v, held) for t, v in door.release()]
                door.restart()
                if quality is not Quality.BAD:
                    door.offer(when, value)
            self.last, self.quality, self.code = value, quality, code
            rows.append((name, when, value, code))
            return rows
        if not self.numeric:
            self.last = value
            return [(name, when, value, self.code)]
        if self.deadband and abs(value - self.last) <= self.deadband:
            return []
        self.last = value
        door = self.door
        if door is None or quality is Quality.BAD:
            return [(name, when, value, self.code)]
        code = self.code
        return [(name, t, v, code) for t, v in door.offer(when, value)]

    def heartbeat(self, now: float) -> list[Row]:
        """Store the held value, or repeat the current one, when max_interval has passed."""
        door = self.door
        if door is None or not door.due(now) or self.quality is None:
            return []
        rows = [(self.name, t, v, self.code) for t, v in door.release()]
        if not rows and self.quality is not Quality.BAD:
            door.restart()
            rows = [(self.name, t, v, self.code) for t, v in door.offer(now, self.last)]
        return rows

    def release(self) -> list[Row]:
        """The held value, stored now (the end of recording)."""
        if self.door is None or self.quality is None:
            return []
        return [(self.name, t, v, self.code) for t, v in self.door.release()]


class HistoryRecorder:
    """The historian: `start(plant)`, `stop()`, `describe()` (see module docstring)."""

    name = "history"

    def __init__(self, settings: HistorySettings, plant: str, policies: dict[str, TagPolicy], types: dict[str, tuple[str, str]]) -> None:
        """`types`: tag name → (type, unit) of every recorded tag."""
        self.settings = settings
        self.plant = plant
        self.policies = policies
        self.types = types
        self.storage: StorageSettings | None = None
        self.writer: BatchWriter | ProcessWriter | None = None
        self.filters: dict[str, TagFilter] = {}
        self._unsubscribe: Any = None
        self._due: list[tuple[float, str]] = []  # heartbeat deadlines (runtime wall time), a heap
        self._scheduled: set[str] = set()  # tags with an entry in _due (one each, so the heap stays small)
        self._plant: Plant | None = None
        self._reader: HistoryReader | None = None
        self._unregister: Any = None
        self._undo_role: Any = None
        self._recording = True  # this member is active: it records (a standby of a redundant pair does not)

    async def start(self, plant: Plant) -> None:
        from softplc.core.plant import AdapterError

        self._plant = plant
        simulated = plant.clock.simulated
        self.storage = self.settings.storage(plant.state_dir, simulated=simulated)
        if simulated and self.storage.path is not None:
            # A simulated run starts at the same simulated instant every time: its history
            # replaces the previous run's instead of overlapping it.
            try:
                remove_sqlite_store(self.storage.path)
            except OSError as error:
                raise AdapterError(f"history: cannot open SQLite {self.storage.path}: {error}") from None
        infos = [TagInfo(name, kind, unit, self.policies[name].stepped) for name, (kind, unit) in self.types.items()]
        sink = HistorySink(self.plant, infos, partition=self.settings.partition, retention=self.settings.retention)
        database = Database(self.storage)
        writer: BatchWriter | ProcessWriter
        if simulated:
            # On the simulated clock no cycle can be late: a thread, no process to start.
            writer = BatchWriter(database, name="softplc-history-writer")
            shorten_switch_interval()  # the writer thread holds the interpreter lock between its SQL calls
        else:
            # On the real clock the writer runs in a process of its own: a thread would hold the event
            # loop's interpreter lock now and then, and keep it while the machine preempts it.
            writer = ProcessWriter(database, name="softplc-history-writer")
        writer.register(sink)
        error = await plant.clock.run_blocking(writer.start)
        if error is not None:
            if not database.postgresql:
                await plant.clock.run_blocking(writer.stop)
                raise AdapterError(f"history: cannot open {database.describe()}: {error}")
            log.warning("history: %s is unreachable (%s); recording continues in memory and is written when it is back", database.describe(), error)
        self.writer = writer
        # Reads for other adapters (OPC UA HistoryRead, trends) go through plant.commands.
        self._reader = HistoryReader(database, self.plant)
        self._unregister = register_history_commands(plant, self._reader, {info.name: info for info in infos if info.name in plant.tags},
                                                     {name for name, policy in self.policies.items() if policy.compression})
        db = plant.tags
        self.filters = {name: TagFilter(name, policy, self.types[name][0] != "string" and not self.types[name][0] == "bool")
                        for name, policy in self.policies.items() if name in db}
        self._changed([db[name] for name in self.filters])  # the starting values
        self._unsubscribe = db.on_change(self._changed)
        self._recording = plant.role.is_active()
        self._undo_role = plant.role.on_change(self._role_changed)
        if any(f.door is not None and math.isfinite(f.door.max_interval) for f in self.filters.values()):
            plant.spawn(self._heartbeats(), "history-heartbeat")

    async def stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._undo_role is not None:
            self._undo_role()
            self._undo_role = None
        if self._unregister is not None:
            self._unregister()
            self._unregister = None
        if self._reader is not None and self._plant is not None:
            await self._plant.clock.run_blocking(self._reader.close)
            self._reader = None
        writer = self.writer
        if writer is None:
            return
        rows: list[Row] = []
        assert self._plant is not None
        if self._recording and self._plant.role.is_active():
            for tag_filter in self.filters.values():
                rows += tag_filter.release()
            # The end of recording: a BAD sample without a value for every tag (as PI's shutdown
            # events), so a reader knows nothing was recorded until the next run — a trend draws a
            # gap over the outage, not a line across it. Not from a standby: the active records on.
            end = max([self._plant.clock.wall(), *(row[1] for row in rows)])
            rows += [(name, end, math.nan, QUALITY_CODES[Quality.BAD]) for name in self.filters]
        if rows:
            writer.put(SINK_NAME, rows)
        await self._plant.clock.run_blocking(writer.stop)
        self.writer = None

    def describe(self) -> str:
        where = self.storage.describe() if self.storage else "?"
        sim = " (simulated time)" if self._plant is not None and self._plant.clock.simulated else ""
        period = self.storage.flush_period if self.storage else 0.0
        return f"history: recording {plural(len(self.filters), 'tag')} to {where}{sim}, flushed every {period:g} s"

    def metrics(self) -> dict[str, Any]:
        """Figures for /metrics (named in manifest.py): rows written, the queue's depth, drops, failed commits."""
        writer = self.writer
        if writer is None:
            return {}
        stats = writer.stats
        return {"tags": len(self.filters), "rows_written": stats.rows_written, "queue": stats.pending,
                "rows_dropped": stats.dropped, "errors": stats.errors}

    def flush(self, timeout: float = 30.0) -> bool:
        """Commit what was recorded so far (blocking: tests, the export of a running plant)."""
        return self.writer.flush(timeout) if self.writer is not None else False

    # -- internals ------------------------------------------------------------------------

    def _role_changed(self, term: RoleTerm) -> None:
        """A member of a redundant pair that becomes active records every tag's value now, as at a start.

        The old active may have ended its recording with BAD samples (a clean stop): a tag that does
        not change after the takeover would read BAD until it did.
        """
        plant = self._plant
        if plant is None:
            return
        active = plant.role.is_active()
        if active and not self._recording:
            self._recording = True
            now = plant.clock.wall()
            rows: list[Row] = []
            db = plant.tags
            for name, tag_filter in list(self.filters.items()):
                fresh = TagFilter(name, self.policies[name], tag_filter.numeric)  # what it held as a standby is stale
                self.filters[name] = fresh
                tag = db[name]
                rows += fresh.offer(now, tag.value, tag.quality)
            self._scheduled.clear()
            self._due.clear()
            for name, tag_filter in self.filters.items():
                door = tag_filter.door
                if door is not None and door.archived is not None and math.isfinite(door.max_interval):
                    self._scheduled.add(name)
                    heapq.heappush(self._due, (door.archived[0] + door.max_interval, name))
            if rows and self.writer is not None:
                self.writer.put(SINK_NAME, rows)
        elif not active:
            self._recording = False

    def _changed(self, tags: Sequence[Tag]) -> None:
        role = self._plant.tags.role if self._plant is not None else None
        if role is not None and not role.is_active():
            return  # the standby of a redundant pair mirrors the active's values: the active records them (docs/redundancy.md)
        filters = self.filters
        rows: list[Row] = []
        for tag in tags:
            tag_filter = filters.get(tag.definition.name)
            if tag_filter is None:
                continue
            new = tag_filter.offer(tag.timestamp, tag.value, tag.quality)
            if new:
                rows += new
                door = tag_filter.door
                if door is not None and door.archived is not None and tag_filter.name not in self._scheduled and math.isfinite(door.max_interval):
                    self._scheduled.add(tag_filter.name)
                    heapq.heappush(self._due, (door.archived[0] + door.max_interval, tag_filter.name))
        if rows and self.writer is not None:
            self.writer.put(SINK_NAME, rows)

    async def _heartbeats(self) -> None:
        assert self._plant is not None
        clock = self._plant.clock
        while True:
            await clock.sleep(HEARTBEAT_TICK)
            now = clock.wall()
            if not self._recording:
                continue  # a standby repeats nothing: the active records
            rows: list[Row] = []
            due = self._due
            while due and due[0][0] <= now:
                _, name = heapq.heappop(due)
                tag_filter = self.filters[name]
                rows += tag_filter.heartbeat(now)
                door = tag_filter.door
                if door is not None and door.archived is not None:  # due again max_interval after its last archived point
                    deadline = door.archived[0] + door.max_interval
                    # Nothing to archive (a bad value): look again later, not in this same loop.
                    heapq.heappush(due, (deadline if deadline > now else now + door.max_interval, name))
                else:
                    self._scheduled.discard(name)
            if rows and self.writer is not None:
                self.writer.put(SINK_NAME, rows)
