"""The audit trail's tables, and the sink that writes entries into them (on the storage writer's thread).

Tables (the same on SQLite and PostgreSQL; times are Unix seconds as double precision):

- `audit_partitions(start, stop, name)`: one row per time partition;
- per partition `audit_YYYYMMDD_HHMMSS` (the columns of `SQL_COLUMNS`) with indexes on
  (time) and (tag, time): the entries. Rows carry the plant's name, so several runtimes can
  share one PostgreSQL store.

Retention drops whole partitions (a table and a catalogue row: softplc/storage/partitions.py),
never DELETEs rows: a store taking 10,000 entries a second stays bounded without a vacuum.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from typing import Any

from softplc.storage import Database
from softplc.storage.audit.entry import row_of
from softplc.storage.partitions import PartitionCatalogue, insert_rows

SINK_NAME = "audit"
CHUNK = 200  # entries written between two steps: ~1 ms of the writer thread's time, well under a ScanGate's margin
PARTITIONS = PartitionCatalogue("audit", lock_key=17_005)
CATALOGUE = PARTITIONS.table
# Column names in SQL (USER is reserved in PostgreSQL); `sequence` orders entries of the same instant.
SQL_COLUMNS = ("time", "plant", "kind", "source", "user_name", "peer", "role", "name", "tag", "arguments",
               "old", "new", "accepted", "rule", "detail", "sequence")
_TYPES = {"time": "DOUBLE PRECISION NOT NULL", "accepted": "SMALLINT NOT NULL", "sequence": "BIGINT NOT NULL",
          "arguments": "TEXT", "old": "TEXT", "new": "TEXT"}


class AuditSink:
    """Writes queued writes and command calls as rows of time partitions; drops partitions past retention."""

    name = SINK_NAME

    def __init__(self, plant: str, *, partition: float, retention: float | None, now: Callable[[], float],
                 steps: Callable[[], AbstractContextManager[Callable[[], None]]] | None = None) -> None:
        self.plant = plant
        self.partition = partition
        self.retention = retention
        self._now = now  # the runtime clock's wall time: retention counts back from it (simulated under --sim)
        # `steps()` yields a step() to call between chunks of rows: a ScanGate's (softplc/engine/scan_gate.py) waits
        # there while a scan cycle is due, so the rows and the SQL never hold the interpreter lock when one starts.
        self._steps = steps or _no_steps
        self.stepping = steps is not None  # cleared when the scan stops: no cycle would come to wait for
        self._partitions: set[float] = set()
        self._sequence = 0

    def prepare(self, connection: Any, database: Database) -> None:
        PARTITIONS.create(connection.cursor())
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
            insert_rows(connection, database, self._partition(connection, database, start), SQL_COLUMNS, rows)
        self._sequence = sequence

    def maintain(self, connection: Any, database: Database) -> None:
        if self.retention is None:
            return
        PARTITIONS.drop_before(connection, database, self._now() - self.retention)
        self._partitions.clear()

    def _partition(self, connection: Any, database: Database, start: float) -> str:
        return PARTITIONS.ensure(connection, database, start, self.partition, self._partitions, _create_partition)


def _create_partition(cursor: Any, name: str) -> None:
    columns = ", ".join(f"{column} {_TYPES.get(column, 'TEXT NOT NULL')}" for column in SQL_COLUMNS)
    cursor.execute(f"CREATE TABLE IF NOT EXISTS {name} ({columns})")
    cursor.execute(f"CREATE INDEX IF NOT EXISTS {name}_time ON {name} (time)")
    cursor.execute(f"CREATE INDEX IF NOT EXISTS {name}_tag ON {name} (tag, time)")


@contextlib.contextmanager
def _no_steps() -> Iterator[Callable[[], None]]:
    yield lambda: None
