"""The one writer thread of a store: rows queued from the event loop, committed in batches.

A `Sink` is one kind of record (history samples, alarm journal entries): it creates its tables
and writes its rows with the writer's connection. Every flush period the writer takes all rows
queued for every sink and commits them in ONE transaction, off the event loop. A commit that
fails because of the store (disk full, server restarting) keeps its rows queued for the next
flush, up to `max_pending` rows; beyond that the oldest are dropped and counted. A commit that
fails because of what a row holds (softplc/storage/unwritable.py: text that is not Unicode, a
number too large) never stops the store: the batch is written again with its text escaped, and
a row that still cannot be written is set aside and reported, the rows around it committed.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Protocol

from softplc.storage.database import Database, StorageError
from softplc.storage.unwritable import describe_row, escaped, rows_at_fault

log = logging.getLogger(__name__)

MAINTAIN_PERIOD = 60.0  # seconds between two retention passes
ERROR_LOG_PERIOD = 60.0  # a failing store is logged once, then at most once a minute
SET_ASIDE_LOGGED = 5  # rows set aside that are logged one by one per ERROR_LOG_PERIOD (then counted)
SET_ASIDE_KEPT = 100  # the last rows set aside, kept in memory for a look (`BatchWriter.set_aside_rows`)


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
    escaped: int = 0  # rows written with their text escaped
    set_aside: int = 0  # rows that could not be written at all
    reconnections: int = 0
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
        self._failing = False  # the store failed since the last good transaction: say so when it is back
        self._set_aside_logged: list[float] = []  # when rows set aside were logged (rate limit)
        self._set_aside_unlogged = 0
        self.set_aside_rows: deque[tuple[str, Any, str]] = deque(maxlen=SET_ASIDE_KEPT)  # (sink, row, why)

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
        normal_priority()
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
            self._prepare(connection)
        except BaseException:
            _close_quietly(connection)
            raise
        self._connection = connection
        if self._failing:
            self._failing = False
            with self._lock:
                self.stats.reconnections += 1
                pending = self.stats.pending
            log.warning("%s: reconnected to %s; writing the %d queued rows", self.name, self.database.describe(), pending)

    def _prepare(self, connection: Any) -> None:
        for sink in self._sinks.values():
            sink.prepare(connection, self.database)
            connection.commit()

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
        except Exception as error:  # noqa: BLE001 — a driver error, a full disk, a row the store refuses, or a bug in a sink
            _rollback_quietly(connection)
            if rows_at_fault(error):
                self._write_apart(taken, error)
            else:
                self._store_failed(error, taken)
            return
        self._committed(count, started)

    def _committed(self, count: int, started: float, *, transactions: int = 1) -> None:
        with self._settled_changed:
            self._settled += count
            self.stats.pending -= count
            self.stats.rows_written += count
            self.stats.transactions += transactions
            self.stats.last_commit_seconds = time.perf_counter() - started
            self._settled_changed.notify_all()
        self._failing = False

    def _store_failed(self, error: BaseException, unwritten: dict[str, list[Any]]) -> None:
        """The store failed (not the rows): keep `unwritten` in front of the queue, reconnect at the next flush."""
        self._failed(error)
        self._close()  # reconnect next time: the connection may be what broke
        with self._lock:
            for name, rows in unwritten.items():  # back in front of what arrived meanwhile
                self._pending[name][:0] = rows
            excess = self.stats.pending - self.max_pending
            if excess > 0:
                self._drop_oldest(excess)

    def _write_apart(self, taken: dict[str, list[Any]], first_error: BaseException) -> None:
        """A row of `taken` was refused: commit the batch with its text escaped, else in halves down to the rows that cannot be written."""
        started = time.perf_counter()
        nul = self.database.postgresql  # PostgreSQL's text cannot hold a NUL; SQLite's can
        clean = {name: [escaped(row, nul) for row in rows] for name, rows in taken.items()}
        changed_rows = {id(new) for name, rows in taken.items() for new, old in zip(clean[name], rows) if new is not old}
        changed = len(changed_rows)
        unwritten = dict(clean)
        current, stack = "", []  # the sink being written, and its chunks still to write (the next one last)
        try:
            self._prepare(self._connection)  # a rolled back transaction may have undone what a sink remembers (tables, ids)
            for name in list(unwritten):
                current, stack = name, [unwritten.pop(name)]
                while stack:
                    chunk = stack[-1]
                    try:
                        self._sinks[name].write(self._connection, self.database, chunk)
                        self._connection.commit()
                    except Exception as error:  # noqa: BLE001
                        _rollback_quietly(self._connection)
                        if not rows_at_fault(error):
                            raise
                        self._prepare(self._connection)
                        stack.pop()
                        if len(chunk) == 1:
                            self._set_aside(name, chunk[0], error)
                        else:
                            middle = len(chunk) // 2
                            stack += [chunk[middle:], chunk[:middle]]
                        continue
                    stack.pop()
                    if changed_rows:  # counted before the commit is told: a flush waiting on it sees the figure
                        with self._lock:
                            self.stats.escaped += sum(id(row) in changed_rows for row in chunk)
                    self._committed(len(chunk), started)
        except Exception as error:  # noqa: BLE001 — the store failed meanwhile: keep what was not committed
            _rollback_quietly(self._connection)
            if stack:
                unwritten[current] = [row for part in reversed(stack) for row in part]
            self._store_failed(error, unwritten)
        if changed:
            self._report(f"{changed} rows held text no store can encode ({_reason(first_error)}); written with it escaped", log.warning)

    def _set_aside(self, sink: str, row: Any, error: BaseException) -> None:
        why = _reason(error)
        self.set_aside_rows.append((sink, row, why))
        with self._settled_changed:
            self._settled += 1
            self.stats.pending -= 1
            self.stats.set_aside += 1
            self._settled_changed.notify_all()
        self._report(f"a {sink} row cannot be written and is set aside ({why}): {describe_row(row)}", log.error)

    def _report(self, message: str, method: Any) -> None:
        # At most SET_ASIDE_LOGGED lines per ERROR_LOG_PERIOD: a client sending poison cannot flood the log.
        now = time.monotonic()
        self._set_aside_logged = [when for when in self._set_aside_logged if now - when < ERROR_LOG_PERIOD]
        if len(self._set_aside_logged) >= SET_ASIDE_LOGGED:
            self._set_aside_unlogged += 1
            return
        self._set_aside_logged.append(now)
        more = f" ({self._set_aside_unlogged} more such reports not logged)" if self._set_aside_unlogged else ""
        self._set_aside_unlogged = 0
        method("%s: %s%s", self.name, message, more)

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
            if not rows_at_fault(error):
                self._close()  # a connection that died while idle (a server restart): reconnect at the next flush
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
        self._failing = True
        with self._settled_changed:
            self.stats.errors += 1
            self.stats.last_error = _reason(error)
            self._settled_changed.notify_all()
        now = time.monotonic()
        if now - self._last_logged >= ERROR_LOG_PERIOD:
            self._last_logged = now
            kept = "keeping" if self.stats.dropped == 0 else "dropping the oldest beyond"
            log.error("%s: cannot write to %s: %s (%s %d queued rows, retrying every %.3g s)",
                      self.name, self.database.describe(), self.stats.last_error, kept, self.stats.pending, self.flush_period)


def normal_priority() -> None:
    """Run this thread under the normal policy even if it inherited the loop's SCHED_FIFO (`softplc run --rt-priority`)."""
    # A writer at real-time priority would take a CPU from everything else for as long as it has rows to write.
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR):
        try:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass


def _reason(error: BaseException) -> str:
    return str(error).strip() or type(error).__name__


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
