"""The alarm journal: every transition and every action, with who and when; searchable, exportable.

It listens to `alarm` events (`journal.record` on `plant.events`) and hands each one as a row to
the shared storage writer (`softplc.storage`: SQLite in the state directory by default, a
PostgreSQL server when `alarms.journal.backend: postgresql`), which commits them in batches off
the event loop. Rows carry the plant's name, so several runtimes can share one PostgreSQL journal.

    rows = journal.search(JournalQuery(alarm="t01_*", since=..., text="blocked"))
    write_csv(rows, sys.stdout)
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields
from typing import IO, Any

from softplc.core.events import Event
from softplc.storage import BatchWriter, Database, escape_like, like_pattern, plant_and_time
from softplc.util.timestamps import format_utc

TABLE = "alarm_journal"
MAX_ROWS = 10_000  # most rows one search returns


@dataclass(frozen=True)
class JournalEntry:
    """One row of the journal."""

    time: float  # wall-clock seconds of the runtime clock (simulated time under --sim)
    plant: str
    alarm: str
    transition: str  # softplc.core.alarms.Transition values
    state: str  # the state after it
    previous: str
    priority: str
    severity: int
    message: str
    value: str  # the watched tag's value, as text
    user: str  # who acted ("" for the process)
    origin: str  # how (opcua:otto@127.0.0.1:50122, cli:..., hmi:...)
    role: str
    comment: str  # the comment or reason given
    sequence: int

    @classmethod
    def from_event(cls, event: Event, plant: str) -> JournalEntry:
        return cls(*row_of(event, plant))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def row_of(event: Event, plant: str) -> tuple[Any, ...]:
    """An `alarm` event as a row of the journal's columns, in COLUMNS order."""
    data = event.data
    alarm = data["alarm"]
    # Enum members' _value_ (a plain attribute) rather than .value (a descriptor call): thousands a second in a flood.
    return (event.time, plant, event.source, data["transition"], alarm.state._value_, data.get("previous", ""), alarm.priority._value_,
            alarm.severity, alarm.message, _text(alarm.value), data.get("user", ""), data.get("origin", ""), data.get("role", ""),
            data.get("comment", ""), alarm.sequence)


COLUMNS = tuple(field.name for field in fields(JournalEntry))
_SQL_COLUMNS = tuple("user_name" if name == "user" else name for name in COLUMNS)  # USER is reserved in PostgreSQL


@dataclass(frozen=True)
class JournalQuery:
    """What to find: every condition given must hold; newest first."""

    alarm: str = ""  # a name, or a pattern with * and ?
    since: float | None = None  # wall-clock seconds, inclusive
    until: float | None = None  # exclusive
    text: str = ""  # found in the message, comment or user (any case)
    user: str = ""
    transitions: tuple[str, ...] = ()
    plant: str | None = None  # None: this plant's rows only; "" or "*": every plant's
    limit: int = 1000
    offset: int = 0


class JournalSink:
    """The journal's table in the shared store (a `softplc.storage.Sink`)."""

    name = TABLE

    def __init__(self, retention: float | None, now: Callable[[], float]) -> None:
        self.retention = retention
        self._now = now

    def prepare(self, connection: Any, database: Database) -> None:
        key = "id BIGSERIAL PRIMARY KEY" if database.postgresql else "id INTEGER PRIMARY KEY AUTOINCREMENT"
        real = "DOUBLE PRECISION" if database.postgresql else "REAL"
        connection.execute(
            f"CREATE TABLE IF NOT EXISTS {TABLE} ({key}, time {real} NOT NULL, plant TEXT NOT NULL, alarm TEXT NOT NULL, "
            "transition TEXT NOT NULL, state TEXT NOT NULL, previous TEXT NOT NULL, priority TEXT NOT NULL, severity INTEGER NOT NULL, "
            "message TEXT NOT NULL, value TEXT NOT NULL, user_name TEXT NOT NULL, origin TEXT NOT NULL, role TEXT NOT NULL, "
            "comment TEXT NOT NULL, sequence INTEGER NOT NULL)"
        )
        connection.execute(f"CREATE INDEX IF NOT EXISTS {TABLE}_time ON {TABLE} (plant, time)")
        connection.execute(f"CREATE INDEX IF NOT EXISTS {TABLE}_alarm ON {TABLE} (alarm, time)")

    def write(self, connection: Any, database: Database, rows: list[tuple[Any, ...]]) -> None:
        """Insert rows made by `row_of` (tuples in COLUMNS order)."""
        placeholders = ", ".join("?" for _ in _SQL_COLUMNS)
        statement = database.sql(f"INSERT INTO {TABLE} ({', '.join(_SQL_COLUMNS)}) VALUES ({placeholders})")
        cursor = connection.cursor()
        cursor.executemany(statement, rows)

    def maintain(self, connection: Any, database: Database) -> None:
        if self.retention is None:
            return
        connection.execute(database.sql(f"DELETE FROM {TABLE} WHERE time < ?"), (self._now() - self.retention,))


class AlarmJournal:
    """Records alarm events through a batch writer; searches what was committed.

    Each row is made at once (a tuple: the values at the transition). Inside `batch()` — the
    adapter opens one around each scan boundary's evaluation — the rows go to the writer together
    at its end: an alarm flood's thousand transitions at one boundary take the writer's lock once.
    """

    def __init__(self, database: Database, writer: BatchWriter, plant: str) -> None:
        self.database = database
        self.writer = writer
        self.plant = plant
        self.recorded = 0
        self._batch: list[tuple[Any, ...]] | None = None

    def record(self, event: Event) -> None:
        """An `alarm` event listener: queue its row (no I/O on the event loop)."""
        row = row_of(event, self.plant)
        self.recorded += 1
        if self._batch is not None:
            self._batch.append(row)
        else:
            self.writer.put(TABLE, [row])

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Rows recorded inside go to the writer together, at the end."""
        self._batch = rows = []
        try:
            yield
        finally:
            self._batch = None
            self.writer.put(TABLE, rows)

    def flush(self, timeout: float = 30.0) -> bool:
        """Wait until every recorded row is committed (blocking: call it off the event loop)."""
        return self.writer.flush(timeout)

    def search(self, query: JournalQuery) -> list[JournalEntry]:
        """The committed rows matching `query`, newest first (blocking: call it off the event loop)."""
        return search(self.database, query, self.plant)


def search(database: Database, query: JournalQuery, plant: str | None) -> list[JournalEntry]:
    """Rows of a journal store matching `query` (`plant` is whose rows `query.plant=None` means)."""
    where, values = plant_and_time(query.plant, plant, query.since, query.until)
    if query.alarm:
        where.append("lower(alarm) LIKE ? ESCAPE '\\'")
        values.append(like_pattern(query.alarm.lower()))
    if query.text:
        where.append("(lower(message) LIKE ? ESCAPE '\\' OR lower(comment) LIKE ? ESCAPE '\\' OR lower(user_name) LIKE ? ESCAPE '\\')")
        pattern = "%" + escape_like(query.text.lower()) + "%"
        values.extend([pattern] * 3)
    if query.user:
        where.append("user_name = ?")
        values.append(query.user)
    if query.transitions:
        where.append(f"transition IN ({', '.join('?' for _ in query.transitions)})")
        values.extend(query.transitions)
    limit = max(0, min(int(query.limit), MAX_ROWS))
    statement = f"SELECT {', '.join(_SQL_COLUMNS)} FROM {TABLE}"
    if where:
        statement += " WHERE " + " AND ".join(where)
    statement += f" ORDER BY time DESC, id DESC LIMIT {limit} OFFSET {max(0, int(query.offset))}"
    connection = database.connect(readonly=True)
    try:
        if not database.has_table(connection, TABLE):
            return []
        rows = connection.execute(database.sql(statement), values).fetchall()
    finally:
        connection.close()
    return [JournalEntry(*row) for row in rows]


def write_csv(entries: Iterable[JournalEntry], stream: IO[str]) -> int:
    """Write rows as CSV with a header (time as ISO 8601 UTC and as seconds); returns how many."""
    writer = csv.writer(stream)
    writer.writerow(["time_utc", *COLUMNS])
    count = 0
    for entry in entries:
        writer.writerow([format_utc(entry.time), *(getattr(entry, name) for name in COLUMNS)])
        count += 1
    return count


def entries_from_dicts(rows: Sequence[dict[str, Any]]) -> list[JournalEntry]:
    """Rows received as JSON (the OPC UA commands door) back into entries."""
    return [JournalEntry(**{name: row[name] for name in COLUMNS}) for row in rows]


def _text(value: Any) -> str:
    if isinstance(value, float) and math.isfinite(value):
        return repr(round(value, 6))
    return "" if value is None else str(value)
