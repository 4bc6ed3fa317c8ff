"""A storage backend: opens connections to a SQLite file (WAL) or a PostgreSQL server (psycopg 3)."""

from __future__ import annotations

import enum
import sqlite3
from pathlib import Path
from typing import Any

from softplc.storage.settings import StorageSettings


class Backend(enum.Enum):
    SQLITE = "sqlite"
    POSTGRESQL = "postgresql"


class StorageError(RuntimeError):
    """The store cannot be opened or used (missing driver, server down, not a store); the message says why."""


# Errors of either driver that mean "the store failed", for callers that must not import psycopg.
def driver_errors() -> tuple[type[BaseException], ...]:
    errors: list[type[BaseException]] = [sqlite3.Error, StorageError]
    try:
        import psycopg
    except ImportError:
        pass
    else:
        errors.append(psycopg.Error)
    return tuple(errors)


def remove_sqlite_store(path: Path) -> None:
    """Delete a SQLite store with its WAL and shared-memory files (a simulated run starts afresh); raises OSError."""
    # The WAL with the file: a new database at `path` must never replay the old file's journal.
    for suffix in ("", "-wal", "-shm"):
        path.with_name(path.name + suffix).unlink(missing_ok=True)


class Database:
    """Where records are kept; `connect()` opens a DB-API connection, `sql()` adapts `?` placeholders."""

    def __init__(self, settings: StorageSettings) -> None:
        self.settings = settings
        self.backend = Backend(settings.backend)
        if self.backend is Backend.SQLITE and settings.path is None:
            raise StorageError("a SQLite store needs a file path")
        if self.backend is Backend.POSTGRESQL and not settings.dsn:
            raise StorageError("a PostgreSQL store needs a dsn")

    @property
    def path(self) -> Path | None:
        return self.settings.path

    @property
    def postgresql(self) -> bool:
        return self.backend is Backend.POSTGRESQL

    def describe(self) -> str:
        return self.settings.describe()

    def exists(self) -> bool:
        """Whether there is anything to read (a SQLite file must exist; a server is assumed to)."""
        return self.postgresql or (self.path is not None and self.path.is_file())

    def sql(self, text: str) -> str:
        """`text` with `?` placeholders in the backend's own style."""
        return text.replace("?", "%s") if self.postgresql else text

    def has_table(self, connection: Any, name: str) -> bool:
        """Whether table `name` exists yet (a reader may come before the writer's first transaction)."""
        if self.postgresql:
            found = connection.execute("SELECT to_regclass(%s)", (name,)).fetchone()
            return bool(found and found[0])
        return connection.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)).fetchone() is not None

    def lost(self, connection: Any, error: BaseException) -> bool:
        """Whether `error` means `connection` is gone (a server restarted) and a new connection may succeed."""
        if not self.postgresql:
            return False  # a SQLite file's connection does not go away
        import psycopg

        return isinstance(error, (psycopg.OperationalError, psycopg.InterfaceError)) or bool(connection.closed or connection.broken)

    def connect(self, *, readonly: bool = False) -> Any:
        """A new connection (not thread-safe: use it from one thread). Raises StorageError."""
        if self.postgresql:
            return self._connect_postgresql(readonly)
        return self._connect_sqlite(readonly)

    def _connect_sqlite(self, readonly: bool) -> sqlite3.Connection:
        assert self.path is not None
        if readonly and not self.path.is_file():
            raise StorageError(f"no store at {self.path}")
        if not readonly:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            # check_same_thread=False: a reader may be opened on the loop and used in an executor,
            # one thread at a time.
            connection = sqlite3.connect(self.path, timeout=10.0, check_same_thread=False)
            # WAL: readers (the export command, queries) never block the writer, and a commit
            # is one append to the log. synchronous=NORMAL keeps every commit across a crash of
            # the process (kill -9); only a power cut may lose the last commits, never corrupt.
            mode = connection.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if mode != "wal":
                raise StorageError(f"{self.path}: cannot use WAL mode (got {mode})")
            connection.execute("PRAGMA synchronous=NORMAL")
            # 64 MB of page cache (allocated as used): the indexes of a busy store stay in memory,
            # which more than halves the cost of a batch once a table holds millions of rows.
            connection.execute("PRAGMA cache_size=-65536")
            if readonly:
                connection.execute("PRAGMA query_only=1")
        except sqlite3.DatabaseError as error:
            raise StorageError(f"{self.path}: {error}") from error
        return connection

    def _connect_postgresql(self, readonly: bool) -> Any:
        try:
            import psycopg
        except ImportError:
            raise StorageError("backend postgresql needs psycopg 3: pip install 'softplc[postgresql]'") from None
        try:
            connection = psycopg.connect(self.settings.dsn, connect_timeout=10)
            if readonly:
                connection.read_only = True
        except psycopg.Error as error:
            raise StorageError(f"{self.describe()}: {str(error).strip()}") from error
        return connection
