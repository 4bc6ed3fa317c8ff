"""A storage writer in a process of its own, so the event loop's process never waits for its interpreter lock.

A writer thread in the runtime's process holds the interpreter lock now and then, however little
Python it runs between its SQL calls; when the operating system preempts it there (a busy
machine), the event loop waits until it runs again — even under `softplc run --rt-priority`, a
priority inversion no thread priority fixes (measured: a 10 ms task's p99 start latency went from
0.07 ms to 14.7 ms beside an in-process history writer at load 16, with the loop at SCHED_FIFO).
`ProcessWriter` has the `BatchWriter` interface (softplc/storage/writer.py) and runs one in a
child process (`python -m softplc.storage.child`): `put()` only pickles the rows on the caller's
thread (~0.1 µs a row) and queues the bytes; a sender thread writes them to the child's stdin
(the lock released while it blocks), a reader thread takes the child's statistics, flush
replies and log lines from its stdout (frames both ways: softplc/storage/frames.py).

- Durable as the thread: the child commits once per flush period. When the runtime is killed
  (kill -9) the child reads the end of its input, commits everything it received and exits —
  it never outlives its parent. It ignores SIGINT and SIGTERM (a Ctrl-C reaches the whole
  process group): the runtime's orderly stop flushes it.
- A child that dies is replaced (at most once a second); the rows it held are counted as
  dropped and logged. Rows not yet sent wait for the new one (at most `max_pending`).
- Its log lines are logged again in the runtime's process, under the same logger and template
  (rate limits and formats apply as to any line).
"""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from softplc.storage.database import Database, StorageError
from softplc.storage.frames import frame, receive, send
from softplc.storage.writer import MAINTAIN_PERIOD, Sink, WriterStats, normal_priority

log = logging.getLogger(__name__)

RESTART_DELAY = 1.0  # s between two starts of a child
STOP = -1  # the outbox's mark of the stop request
COUNTERS = ("rows_written", "transactions", "errors", "dropped", "escaped", "set_aside", "reconnections")


class ProcessWriter:
    """A `BatchWriter` in a child process (see the module docstring); the same methods and `stats`."""

    def __init__(self, database: Database, *, flush_period: float | None = None, name: str = "storage-writer",
                 max_pending: int = 2_000_000, maintain_period: float = MAINTAIN_PERIOD) -> None:
        self.database = database
        self.flush_period = flush_period if flush_period is not None else database.settings.flush_period
        self.name = name
        self.max_pending = max_pending
        self.maintain_period = maintain_period
        self.stats = WriterStats()
        self._sinks: list[Sink] = []
        self._lock = threading.Condition()
        self._outbox: deque[tuple[bytes, int, int]] = deque()  # frames not sent yet: (frame, rows in it, flush request or 0)
        self._waiting_rows = 0  # rows in the outbox
        self._put = 0  # rows ever put
        self._sent = 0  # rows sent to the current child
        self._child: dict[str, Any] = {}  # the current child's last statistics
        self._before: dict[str, int] = dict.fromkeys(COUNTERS, 0)  # counters of the children before it
        self._lost = 0  # rows dropped here: the outbox overflowed, or a child died holding them
        self._replies: dict[int, bool] = {}
        self._requests = 0
        self._asked: set[int] = set()  # flush requests the current child has received and not answered
        self._process: subprocess.Popen[bytes] | None = None
        self._stopping = False
        self._wake = threading.Event()
        self._started = False
        self._sender: threading.Thread | None = None
        self._reader: threading.Thread | None = None
        self._started_at = 0.0

    def register(self, sink: Sink) -> None:
        """Add a kind of record (pickled to the child: no references to the runtime); before `start()`."""
        if self._started:
            raise RuntimeError("register sinks before starting the writer")
        self._sinks.append(sink)

    def start(self, timeout: float = 30.0) -> BaseException | None:
        """Start the child; wait until it connected and prepared its sinks; return the error if it could not."""
        if self._started:
            raise RuntimeError("writer already started")
        self._started = True
        return self._spawn(timeout)

    def put(self, sink: str, rows: list[Any]) -> None:
        """Queue rows for `sink`: pickled here, sent by the sender thread."""
        if not rows or self._stopping:
            return
        data = frame(("rows", sink, rows))
        with self._lock:
            self._outbox.append((data, len(rows), 0))
            self._waiting_rows += len(rows)
            self._put += len(rows)
            if self._waiting_rows > self.max_pending:
                self._drop_oldest(self._waiting_rows - self.max_pending)
            self._update_pending()
        self._threads()
        self._wake.set()

    def flush(self, timeout: float = 30.0, *, maintain: bool = False) -> bool:
        """Commit everything put so far now (and run retention if `maintain`); False on timeout or a failing store."""
        deadline = time.monotonic() + timeout
        with self._lock:
            self._requests += 1
            request = self._requests
            self._outbox.append((frame(("flush", request, maintain, timeout)), 0, request))
        self._threads()
        self._wake.set()
        with self._lock:
            while request not in self._replies:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._lock.wait(min(remaining, 0.1))
            return self._replies.pop(request)

    def stop(self, timeout: float = 30.0) -> None:
        """Send what is queued, let the child commit it and end."""
        if not self._started or self._stopping:
            return
        with self._lock:
            self._stopping = True
            self._outbox.append((frame(("stop",)), 0, STOP))
        self._threads()
        self._wake.set()
        assert self._sender is not None
        self._sender.join(timeout)
        process = self._process
        if process is not None:
            try:
                process.wait(max(1.0, timeout))
            except subprocess.TimeoutExpired:
                log.error("%s: still writing after %.0f s; %d rows may be lost", self.name, timeout, self.stats.pending)
                process.kill()
                process.wait()
            if self._reader is not None:
                self._reader.join(5.0)
        self._sender = None

    def _threads(self) -> None:
        # Started by the first put() — on the event loop's thread — so they share its scheduling: under
        # `--rt-priority` (SCHED_FIFO) no other process preempts them while they hold the interpreter
        # lock or this writer's lock, which the loop may be waiting for. They only ever block or copy bytes.
        if self._sender is None:
            self._sender = threading.Thread(target=self._send_loop, name=f"{self.name}-sender", daemon=True)
            self._sender.start()
            if self._process is not None:
                self._reader = threading.Thread(target=self._read_loop, args=(self._process,), name=f"{self.name}-reader", daemon=True)
                self._reader.start()

    # -- the child ---------------------------------------------------------------------------

    def _spawn(self, timeout: float) -> BaseException | None:
        import softplc

        environment = dict(os.environ)
        package_root = str(Path(softplc.__file__).resolve().parent.parent)
        environment["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, environment.get("PYTHONPATH")]))
        self._started_at = time.monotonic()
        with _normal_scheduling():  # a replacement is started by the sender, which may run at SCHED_FIFO
            process = subprocess.Popen([sys.executable, "-m", "softplc.storage.child"], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, env=environment,
                                       process_group=0)  # Ctrl-C reaches the terminal's group, not it: it ends with its stdin
        assert process.stdin is not None and process.stdout is not None
        setup = {"settings": self.database.settings, "flush_period": self.flush_period, "name": self.name,
                 "max_pending": self.max_pending, "maintain_period": self.maintain_period, "sinks": self._sinks,
                 "level": logging.getLogger("softplc").getEffectiveLevel()}
        try:
            send(process.stdin, ("setup", setup))
        except OSError as error:
            return StorageError(f"{self.name}: cannot start its process: {error}")
        ready = _ready_within(process.stdout, timeout)
        if ready is None:
            process.kill()
            process.wait()
            return StorageError(f"{self.name}: its process did not start (exit status {process.returncode})")
        with self._lock:
            self._process, self._sent, self._child = process, 0, {}
        if self._sender is not None:  # a replacement: the threads run already (the first reader starts with them)
            self._reader = threading.Thread(target=self._read_loop, args=(process,), name=f"{self.name}-reader", daemon=True)
            self._reader.start()
        return StorageError(ready[1]) if ready[1] else None

    def _send_loop(self) -> None:
        while True:
            self._wake.wait(0.5)
            self._wake.clear()
            process = self._process
            if process is None or process.poll() is not None:
                if self._stopping and not any(count for _, count, _ in self._outbox):
                    return  # nothing left for a child to write
                if self._reader is not None:
                    self._reader.join()  # the dead child's figures are accounted for before another starts
                wait = RESTART_DELAY - (time.monotonic() - self._started_at)
                if wait > 0:
                    time.sleep(wait)
                error = self._spawn(30.0)
                if error is not None:
                    log.error("%s: %s", self.name, error)
                continue
            assert process.stdin is not None
            while True:
                with self._lock:
                    if not self._outbox:
                        break
                    data, count, request = self._outbox[0]
                try:
                    process.stdin.write(data)  # blocks while the child's pipe is full, the lock released
                    process.stdin.flush()
                except OSError:  # the child died: the reader thread accounts for it, the next turn starts another
                    break
                with self._lock:
                    if self._outbox and self._outbox[0][0] is data:
                        self._outbox.popleft()
                        self._waiting_rows -= count
                        self._sent += count
                        if request > 0:
                            self._asked.add(request)
                if request == STOP:
                    _close_quietly(process.stdin)
                    return

    def _read_loop(self, process: subprocess.Popen[bytes]) -> None:
        assert process.stdout is not None
        while (message := receive(process.stdout)) is not None:
            kind = message[0]
            if kind == "stats":
                with self._lock:
                    self._child = message[1]
                    self._update_pending()
                    self._lock.notify_all()
            elif kind == "flushed":
                with self._lock:
                    self._replies[message[1]] = message[2]
                    self._asked.discard(message[1])
                    self._lock.notify_all()
            elif kind == "log":
                _log(message)
        process.wait()
        with self._lock:
            child = self._child
            settled = child.get("rows_written", 0) + child.get("dropped", 0) + child.get("set_aside", 0)
            held = self._sent - settled
            for name in COUNTERS:
                self._before[name] += child.get(name, 0)
            self._child, self._sent = {}, 0
            self._lost += held
            stopping = self._stopping
            for request in self._asked:
                self._replies[request] = False  # no answer will come from this child
            self._asked.clear()
            self._update_pending()
            self._lock.notify_all()
        if not stopping or process.returncode != 0:
            log.error("%s: its process ended unexpectedly (exit status %s) holding %d rows, which are lost; starting another",
                      self.name, process.returncode, held)
            self._wake.set()

    def _drop_oldest(self, count: int) -> None:
        # Called with the lock held: whole frames of rows, the oldest first (flush and stop requests stay).
        kept: deque[tuple[bytes, int, int]] = deque()
        while self._outbox and count > 0:
            data, rows, request = self._outbox.popleft()
            if request:
                kept.append((data, rows, request))
                continue
            count -= rows
            self._waiting_rows -= rows
            self._lost += rows
        self._outbox.extendleft(reversed(kept))

    def _update_pending(self) -> None:
        # Called with the lock held: the figures of the children so far, this one's, and what waits here.
        child = self._child
        stats = self.stats
        for name in ("rows_written", "transactions", "errors", "escaped", "set_aside", "reconnections"):
            setattr(stats, name, self._before[name] + child.get(name, 0))
        stats.dropped = self._before["dropped"] + child.get("dropped", 0) + self._lost
        settled = child.get("rows_written", 0) + child.get("dropped", 0) + child.get("set_aside", 0)
        stats.pending = self._waiting_rows + max(0, self._sent - settled)
        stats.last_error = child.get("last_error", stats.last_error)
        stats.last_commit_seconds = child.get("last_commit_seconds", stats.last_commit_seconds)


@contextlib.contextmanager
def _normal_scheduling() -> Iterator[None]:
    """This thread at normal priority meanwhile, so a process it starts does not inherit SCHED_FIFO."""
    policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
    if policy not in (getattr(os, "SCHED_FIFO", None), getattr(os, "SCHED_RR", None)):
        yield
        return
    parameters = os.sched_getparam(0)
    normal_priority()
    try:
        yield
    finally:
        try:
            os.sched_setscheduler(0, policy, parameters)
        except OSError:
            pass


def _ready_within(stream: IO[bytes], timeout: float) -> tuple[Any, ...] | None:
    """The child's "ready" message (its log lines before it logged here), or None when none came within `timeout`."""
    result: list[Any] = [None]

    def read() -> None:
        while (message := receive(stream)) is not None:
            if message[0] == "ready":
                result[0] = message
                return
            if message[0] == "log":
                _log(message)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout)
    return result[0]


def _log(message: tuple[Any, ...]) -> None:
    """A log line of the child, logged here under its logger and template."""
    _, level, name, template, arguments = message
    logging.getLogger(name).log(level, template, *arguments)


def _close_quietly(stream: IO[bytes]) -> None:
    try:
        stream.close()
    except OSError:
        pass
