"""Storage shared by the historian and the alarm journal: one backend choice, one batching writer.

The contract (stable; the alarm journal builds on it):

- `StorageSettings.from_section(section, state_dir, default_file)` reads the storage keys of a
  YAML section (`backend: sqlite|postgresql`, `path`, `dsn`, `flush_period`);
  `storage_problems(section, where, source)` lists their mistakes as located `Problem`s and
  `STORAGE_PROPERTIES` is their JSON Schema fragment, to merge into a section's schema.
- `Database(settings)` opens connections of the chosen backend (`connect()`), and writes SQL
  with `?` placeholders that it adapts (`database.sql(text)`): SQLite in WAL mode, PostgreSQL
  through psycopg 3.
- `BatchWriter(database, flush_period=...)` is ONE thread that owns a write connection: each
  `Sink` registered with it creates its tables (`prepare`), and receives the rows `put` for it
  in one transaction per flush period (`write`), then `maintain`s itself (retention) now and then.
  `put()` is cheap and thread-safe (call it on the event loop); `flush()` waits until what was
  put is committed; `stop()` flushes and closes. A transaction the store fails keeps its rows
  for the next flush (bounded by `max_pending`), so a PostgreSQL restart loses nothing; one a
  row fails (`unwritable.py`: text no store can encode, a number too large) is written again
  with its text escaped, and a row that still cannot be written is set aside and reported.
- `ProcessWriter` (`process.py`) has the same interface and runs a `BatchWriter` in a child
  process (`python -m softplc.storage.child`), so the runtime's event loop never waits for a
  writer thread's interpreter lock; its sinks are pickled to the child. The historian uses it on
  the real clock.
- `PartitionCatalogue(prefix, lock_key)` names, lists and drops a store's time partitions (one
  table per period, retention drops whole tables); `insert_rows` writes rows into one (COPY on
  PostgreSQL). The historian and the audit trail keep their rows this way.
- `sql.py`: name patterns as LIKE (`like_pattern`) and a shared store's plant and time
  conditions (`plant_and_time`), for the searches of the audit trail and the alarm journal.

Tests get a real PostgreSQL server from the `postgres_dsn` fixture (tests/postgres_server.py)
and both backends from `storage_database` (see tests/conftest.py).
"""

from softplc.storage.database import Backend, Database, StorageError, remove_sqlite_store
from softplc.storage.partitions import PartitionCatalogue, insert_rows
from softplc.storage.settings import STORAGE_PROPERTIES, StorageSettings, parse_span, storage_problems
from softplc.storage.sql import escape_like, like_pattern, plant_and_time
from softplc.storage.writer import BatchWriter, Sink, WriterStats

__all__ = [
    "Backend",
    "BatchWriter",
    "Database",
    "PartitionCatalogue",
    "STORAGE_PROPERTIES",
    "Sink",
    "StorageError",
    "StorageSettings",
    "WriterStats",
    "escape_like",
    "insert_rows",
    "like_pattern",
    "parse_span",
    "plant_and_time",
    "remove_sqlite_store",
    "storage_problems",
]
