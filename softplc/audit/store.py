"""The audit trail's tables, and the sink that writes entries into them (on the storage writer's thread).

Tables (the same on SQLite and PostgreSQL; times are Unix seconds as double precision):

- `audit_partitions(start, stop, name)`: one row per time partition;
- per partition `audit_YYYYMMDD_HHMMSS` (the columns of `SQL_COLUMNS`) with indexes on
  (time) and (tag, time): the entries. Rows carry the plant's name, so several runtimes can
  share one PostgreSQL store.

Retention drops whole partitions (a table and a catalogue row), never DELETEs rows: a store
taking 10,000 entries a second stays bounded without a vacuum.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from typing import Any

from softplc.audit.entry import row_of
from softplc.storage import Database

log = logging.getLogger(__name__)

SINK_NAME = "audit"
CHUNK = 200  # entries written between two steps: ~1 ms of the writer thread's time, well under a ScanGate's margin
CATALOGUE = "audit_partitions"
_LOCK_KEY = 17_005  # PostgreSQL advisory lock: runtimes sharing a server create partitions one at a time
# Column names in SQL (USER is reserved in PostgreSQL); `sequence` orders entries of the same instant.
SQL_COLUMNS = ("time", "plant", "kind", "source", "user_name", "peer", "role", "name", "tag", "arguments",
               "old", "new", "accepted", "rule", "detail", "sequence")
_TYPES = {"time": "DOUBLE PRECISION NOT NULL", "accepted": "SMALLINT NOT NULL", "sequence": "BIGINT NOT NULL",
          "arguments": "TEXT", "old": "TEXT", "new": "TEXT"}


def partition_name(start: float) -> str:
    return "audit_" + time.strftime("%Y%m%d_%H%M%S", time.gmtime(start))  # lower case: PostgreSQL folds names


def create_catalogue(connection: Any, database: Database) -> None:
    connection.cursor().execute(f"CREATE TABLE IF NOT EXISTS {CATALOGUE} (start DOUBLE PRECISION PRIMARY KEY, "
                                "stop DOUBLE PRECISION NOT NULL, name TEXT NOT NULL)")


class AuditSink:
    """Writes queued writes and command calls as rows of time partitions; drops partitions past retention."""

    name = SINK_NAME

    def __init__(self, plant: str, *, partition: float, retention: float | None, now: Callable[[], float],
                 steps: Callable[[], AbstractContextManager[Callable[[], None]]] | None = None) -> None:
        self.plant = plant
        self.partition = partition
        self.retention = retention
        self._now = now  # the runtime clock's wall time: retention counts back from it (simulated under --sim)
        # `steps()` yields a step() to call between chunks of rows: a ScanGate's (softplc/scan_gate.py) waits
        # there while a scan cycle is due, so the rows and the SQL never hold the interpreter lock when one starts.
        self._steps = steps or _no_steps
        self.stepping = steps is not None  # cleared when the scan stops: no cycle would come to wait for
        self._partitions: set[float] = set()
        self._sequence = 0

    def prepare(self, connection: Any, database: Database) -> None:
        create_catalogue(connection, database)
        self._partitions.clear()

    def write(self, connection: Any, database: Database, items: list[Any]) -> None:
        with self._steps() as step:
            for first in range(0, len(items), CHUNK):
                if self.stepping:
                    step()
                self._write_chunk(connection, database, items[first:first + CHUNK])

    def _write_chunk(self, connection: Any, database: Database, items: list[Any]) -> None:
        size = self.partition
        plant = self.plant
        sequence = self._sequence
        by_partition: dict[float, list[tuple[Any, ...]]] = {}
        current_start, current_stop, current = math.inf, -math.inf, None
        for item in items:
            sequence += 1
            row = row_of(item, plant, sequence)
            when = row[0]
            if not current_start <= when < current_stop:
                current_start = math.floor(when / size) * size
                current_stop = current_start + size
                current = by_partition.setdefault(current_start, [])
            current.append(row)  # type: ignore[union-attr]
        for start, rows in by_partition.items():
            _insert(connection, database, self._partition(connection, database, start), rows)
        self._sequence = sequence

    def maintain(self, connection: Any, database: Database) -> None:
        if self.retention is None:
            return
        drop_partitions_before(connection, database, self._now() - self.retention)
        self._partitions.clear()

    def _partition(self, connection: Any, database: Database, start: float) -> str:
        name = partition_name(start)
        if start in self._partitions:
            return name
        cursor = connection.cursor()
        if database.postgresql:
            cursor.execute("SELECT pg_advisory_xact_lock(%s)", (_LOCK_KEY,))
        columns = ", ".join(f"{column} {_TYPES.get(column, 'TEXT NOT NULL')}" for column in SQL_COLUMNS)
        cursor.execute(f"CREATE TABLE IF NOT EXISTS {name} ({columns})")
        cursor.execute(f"CREATE INDEX IF NOT EXISTS {name}_time ON {name} (time)")
        cursor.execute(f"CREATE INDEX IF NOT EXISTS {name}_tag ON {name} (tag, time)")
        cursor.execute(database.sql(f"INSERT INTO {CATALOGUE} (start, stop, name) VALUES (?, ?, ?) ON CONFLICT (start) DO NOTHING"),
                       (start, start + self.partition, name))
        self._partitions.add(start)
        return name


def _insert(connection: Any, database: Database, table: str, rows: list[tuple[Any, ...]]) -> None:
    cursor = connection.cursor()
    if database.postgresql:
        # COPY streams the rows in one statement: several times faster than INSERTs.
        with cursor.copy(f"COPY {table} ({', '.join(SQL_COLUMNS)}) FROM STDIN") as copy:
            for row in rows:
                copy.write_row(row)
    else:
        placeholders = ", ".join("?" for _ in SQL_COLUMNS)
        cursor.executemany(f"INSERT INTO {table} ({', '.join(SQL_COLUMNS)}) VALUES ({placeholders})", rows)


def drop_partitions_before(connection: Any, database: Database, cutoff: float) -> list[str]:
    """Drop every partition that ends at or before `cutoff` (whole tables); return their names."""
    cursor = connection.cursor()
    cursor.execute(database.sql(f"SELECT start, name FROM {CATALOGUE} WHERE stop <= ? ORDER BY start"), (cutoff,))
    dropped = []
    for start, name in cursor.fetchall():
        cursor.execute(f"DROP TABLE IF EXISTS {name}")
        cursor.execute(database.sql(f"DELETE FROM {CATALOGUE} WHERE start = ?"), (start,))
        dropped.append(name)
    if dropped:
        log.info("audit retention: dropped %d partition(s) up to %s", len(dropped), dropped[-1])
    return dropped


@contextlib.contextmanager
def _no_steps() -> Iterator[Callable[[], None]]:
    yield lambda: None
