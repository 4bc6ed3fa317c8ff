"""Time partitions of a store: one table per period, named by its start, listed in a catalogue.

The historian and the audit trail keep their rows this way (`PREFIX_YYYYMMDD_HHMMSS` tables in
`PREFIX_partitions(start, stop, name)`), so that retention drops whole tables and never DELETEs
rows: a store taking thousands of rows a second stays bounded without a vacuum.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from typing import Any

from softplc.storage.database import Database

log = logging.getLogger(__name__)


class PartitionCatalogue:
    """The partitions of one store: their names, their catalogue table, and dropping them by age.

    `lock_key` is a PostgreSQL advisory lock: runtimes sharing a server create partitions one at a
    time. `suffixes` name the tables kept beside each partition (`NAME_SUFFIX`), dropped with it.
    """

    def __init__(self, prefix: str, lock_key: int, suffixes: Sequence[str] = ()) -> None:
        self.prefix = prefix
        self.table = f"{prefix}_partitions"
        self.lock_key = lock_key
        self.suffixes = tuple(suffixes)

    def name(self, start: float) -> str:
        """The table of the partition that starts at `start` (Unix seconds)."""
        return f"{self.prefix}_" + time.strftime("%Y%m%d_%H%M%S", time.gmtime(start))  # lower case: PostgreSQL folds names

    def create(self, cursor: Any) -> None:
        """Create the catalogue table if needed."""
        cursor.execute(f"CREATE TABLE IF NOT EXISTS {self.table} (start DOUBLE PRECISION PRIMARY KEY, "
                       "stop DOUBLE PRECISION NOT NULL, name TEXT NOT NULL)")

    def lock(self, cursor: Any, database: Database) -> None:
        """Take the advisory lock until the transaction ends (PostgreSQL; SQLite has one writer anyway)."""
        if database.postgresql:
            cursor.execute("SELECT pg_advisory_xact_lock(%s)", (self.lock_key,))

    def register(self, cursor: Any, database: Database, start: float, size: float) -> None:
        """List the partition [start, start + size) in the catalogue (once: a second time changes nothing)."""
        cursor.execute(database.sql(f"INSERT INTO {self.table} (start, stop, name) VALUES (?, ?, ?) ON CONFLICT (start) DO NOTHING"),
                       (start, start + size, self.name(start)))

    def ensure(self, connection: Any, database: Database, start: float, size: float, known: set[float],
               create: Callable[[Any, str], None]) -> str:
        """The table of the partition [start, start + size); unless `start` is `known`, made by `create(cursor, name)` and listed."""
        name = self.name(start)
        if start in known:
            return name
        cursor = connection.cursor()
        self.lock(cursor, database)
        create(cursor, name)
        self.register(cursor, database, start, size)
        known.add(start)
        return name

    def drop_before(self, connection: Any, database: Database, cutoff: float) -> list[str]:
        """Drop every partition that ends at or before `cutoff` (whole tables); return their names."""
        cursor = connection.cursor()
        cursor.execute(database.sql(f"SELECT start, name FROM {self.table} WHERE stop <= ? ORDER BY start"), (cutoff,))
        dropped = []
        for start, name in cursor.fetchall():
            for table in (name, *(f"{name}_{suffix}" for suffix in self.suffixes)):
                cursor.execute(f"DROP TABLE IF EXISTS {table}")
            cursor.execute(database.sql(f"DELETE FROM {self.table} WHERE start = ?"), (start,))
            dropped.append(name)
        if dropped:
            log.info("%s retention: dropped %d partition(s) up to %s", self.prefix, len(dropped), dropped[-1])
        return dropped


def insert_rows(connection: Any, database: Database, table: str, columns: Sequence[str], rows: list[tuple[Any, ...]]) -> None:
    """Insert `rows` (tuples in the order of `columns`) into `table`: COPY on PostgreSQL, executemany on SQLite."""
    cursor = connection.cursor()
    names = ", ".join(columns)
    if database.postgresql:
        # COPY streams the rows in one statement: several times faster than INSERTs.
        with cursor.copy(f"COPY {table} ({names}) FROM STDIN") as copy:
            for row in rows:
                copy.write_row(row)
    else:
        placeholders = ", ".join("?" for _ in columns)
        cursor.executemany(f"INSERT INTO {table} ({names}) VALUES ({placeholders})", rows)
