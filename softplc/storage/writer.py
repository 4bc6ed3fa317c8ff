"""The one writer thread of a store: rows queued from the event loop, committed in batches.

A `Sink` is one kind of record (history samples, alarm journal entries): it creates its tables
and writes its rows with the writer's connection. Every flush period the writer takes all rows
queued for every sink and commits them in ONE transaction, off the event loop. A commit that
fails (disk full, server restarting) keeps its rows queued for the next flush, up to
`max_pending` rows; beyond that the oldest are dropped and counted.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Protocol

from softplc.storage.database import Database, StorageError

log = logging.getLogger(__name__)

MAINTAIN_PERIOD = 60.0  # seconds between two retention passes
ERROR_LOG_PERIOD = 60.0  # a failing store is logged once, then at most once a minute


class Sink(Protocol):
    """One kind of record kept in a store (see module docstring)."""

    name: str

    def prepare(self, connection: Any, database: Database) -> None:
        """Create tables if needed and forget cached state (called after every (re)connection)."""

    def write(self, connection: Any, database: Database, rows: list[Any]) -> None:
        """Insert `rows` inside the writer's open transaction (the writer commits)."""

    def maintain(self, connection: Any, database: Database) -> None:
        """Housekeeping such as retention, inside its own transaction (the writer commits)."""


@dataclass
class WriterStats:
    """What the writer did so far (read from any thread; figures may be one flush old)."""

    rows_written: int = 0
    transactions: int = 0
    errors: int = 0
    dropped: int = 0
    pending: int = 0
    last_error: str = ""
    last_commit_seconds: float = 0.0  # wall time of the last transaction


class BatchWriter:
    """Commits the rows of its sinks in one transaction per flush period, in a thread of its own."""

    def __init__(self, database: Database, *, flush_period: float | None = None, name: str = "storage-writer",
                 max_pending: int = 2_000_000, maintain_period: float = MAINTAIN_PERIOD) -> None:
        self.database = database
        self.flush_period = flush_period if flush_period is not None else database.settings.flush_period
        self.name = name
        self.max_pending = max_pending
        self.maintain_period = maintain_period
        self.stats = WriterStats()
        self._sinks: dict[str, Sink] = {}
        self._lock = threading.Lock()
        self._settled_changed = threading.Condition(self._lock)
        self._pending: dict[str, list[Any]] = {}
        self._queued = 0  # rows ever put
        self._settled = 0  # rows committed or dropped
        self._wake = threading.Event()
        self._stopping = False
        self._maintain_requested = False
        self._thread: threading.Thread | None = None
        self._connection: Any = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._last_logged = -ERROR_LOG_PERIOD

    # -- the event loop's side --------------------------------------------------------------

    def register(self, sink: Sink) -> None:
        """Add a kind of record; before `start()`."""
        if self._thread is not None:
            raise RuntimeError("register sinks before starting the writer")
        self._sinks[sink.name] = sink
        self._pending[sink.name] = []

    def start(self, timeout: float = 30.0) -> BaseException | None:
        """Start the thread; wait until it connected and prepared its sinks; return the error if it could not.

        On an error the writer keeps trying every flush period and keeps what is put meanwhile.
        """
        if self._thread is not None:
            raise RuntimeError("writer already started")
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()
        self._ready.wait(timeout)
        return self._start_error

    def put(self, sink: str, rows: Iterable[Any]) -> None:
        """Queue rows for `sink`; cheap and thread-safe (no I/O)."""
        rows = list(rows)
        if not rows:
            return
        with self._lock:
            queue = self._pending[sink]
            queue.extend(rows)
            self._queued += len(rows)
            self.stats.pending += len(rows)
            excess = self.stats.pending - self.max_pending
            if excess > 0:
                self._drop_oldest(excess)

    def flush(self, timeout: float = 30.0, *, maintain: bool = False) -> bool:
        """Commit everything put so far now (and run retention if `maintain`); False on timeout or a failing store."""
        deadline = time.monotonic() + timeout
        with self._lock:
            target = self._queued
            errors = self.stats.errors
            if maintain:
                self._maintain_requested = True
        self._wake.set()
        with self._settled_changed:
            while self._settled < target or (maintain and self._maintain_requested):
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self.stats.errors > errors or self._thread is None or not self._thread.is_alive():
                    return False
                self._settled_changed.wait(min(remaining, 0.1))
        return True

    def stop(self, timeout: float = 30.0) -> None:
        """Commit what is queued, close the connection, end the thread."""
        if self._thread is None:
            return
        self._stopping = True
        self._wake.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.error("%s: still writing after %.0f s; %d rows may be lost", self.name, timeout, self.stats.pending)
        self._thread = None

    # -- the writer thread ------------------------------------------------------------------

    def _run(self) -> None:
        last_maintain = time.monotonic()
        try:
            self._open()
        except BaseException as error:  # noqa: BLE001 — reported to start() and retried below
            self._start_error = error
            self._failed(error)
        self._ready.set()
        while True:
            self._wake.wait(self.flush_period)
            self._wake.clear()
            stopping = self._stopping
            if self._connection is None:
                try:
                    self._open()
                except BaseException as error:  # noqa: BLE001
                    self._failed(error)
                    if stopping:
                        break
                    continue
            self._flush_once()
            now = time.monotonic()
            if self._maintain_requested or now - last_maintain >= self.maintain_period:
                self._maintain()
                last_maintain = now
            if stopping:
                break
        self._close()

    def _open(self) -> None:
        connection = self.database.connect()
        try:
            for sink in self._sinks.values():
                sink.prepare(connection, self.database)
                connection.commit()
        except BaseException:
            _close_quietly(connection)
            raise
        self._connection = connection

    def _close(self) -> None:
        if self._connection is not None:
            _close_quietly(self._connection)
            self._connection = None

    def _flush_once(self) -> None:
        with self._lock:
            taken = {name: rows for name, rows in self._pending.items() if rows}
            if not taken:
                return
            for name in taken:
                self._pending[name] = []
        count = sum(len(rows) for rows in taken.values())
        started = time.perf_counter()
        connection = self._connection
        try:
            for name, rows in taken.items():
                self._sinks[name].write(connection, self.database, rows)
            connection.commit()
        except Exception as error:  # noqa: BLE001 — a driver error, a full disk, or a bug in a sink: rows kept, error logged
            _rollback_quietly(connection)
            self._failed(error)
            self._close()  # reconnect next time: the connection may be what broke
            with self._lock:
                for name, rows in taken.items():  # back in front of what arrived meanwhile
                    self._pending[name][:0] = rows
                excess = self.stats.pending - self.max_pending
                if excess > 0:
                    self._drop_oldest(excess)
            return
        with self._settled_changed:
            self._settled += count
            self.stats.pending -= count
            self.stats.rows_written += count
            self.stats.transactions += 1
            self.stats.last_commit_seconds = time.perf_counter() - started
            self._settled_changed.notify_all()

    def _maintain(self) -> None:
        connection = self._connection
        if connection is None:
            return
        try:
            for sink in self._sinks.values():
                sink.maintain(connection, self.database)
                connection.commit()
        except Exception as error:  # noqa: BLE001
            _rollback_quietly(connection)
            self._failed(error)
        finally:
            with self._settled_changed:
                self._maintain_requested = False
                self._settled_changed.notify_all()

    def _drop_oldest(self, count: int) -> None:
        # Called with the lock held: the oldest rows of the fullest queue go first.
        while count > 0:
            name = max(self._pending, key=lambda key: len(self._pending[key]))
            queue = self._pending[name]
            dropped = min(count, len(queue))
            if dropped == 0:
                return
            del queue[:dropped]
            count -= dropped
            self._settled += dropped
            self.stats.pending -= dropped
            self.stats.dropped += dropped
        self._settled_changed.notify_all()

    def _failed(self, error: BaseException) -> None:
        with self._settled_changed:
            self.stats.errors += 1
            self.stats.last_error = str(error).strip() or type(error).__name__
            self._settled_changed.notify_all()
        now = time.monotonic()
        if now - self._last_logged >= ERROR_LOG_PERIOD:
            self._last_logged = now
            kept = "keeping" if self.stats.dropped == 0 else "dropping the oldest beyond"
            log.error("%s: cannot write to %s: %s (%s %d queued rows, retrying every %.3g s)",
                      self.name, self.database.describe(), self.stats.last_error, kept, self.stats.pending, self.flush_period)


def _rollback_quietly(connection: Any) -> None:
    try:
        connection.rollback()
    except Exception:  # noqa: BLE001 — the connection is being dropped anyway
        pass


def _close_quietly(connection: Any) -> None:
    try:
        connection.close()
    except Exception:  # noqa: BLE001
        pass


__all__ = ["BatchWriter", "Sink", "StorageError", "WriterStats"]
