"""A store writer's own process (`python -m softplc.storage.child`), started by `ProcessWriter` (softplc/storage/process.py).

It reads a setup frame (the store's settings and the sinks, pickled), runs a `BatchWriter`, and
then takes rows, flush requests and the stop request from stdin until it ends; it reports its
statistics (when they changed), flush replies and log lines on stdout. It ignores SIGINT and
SIGTERM and runs at normal priority: the runtime stops it, by the end of its input — after a
kill -9 of the runtime too, when it commits what it had received and exits.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
from dataclasses import asdict
from typing import IO, Any

from softplc.storage.database import Database
from softplc.storage.frames import receive, send
from softplc.storage.writer import BatchWriter, normal_priority

STATS_PERIOD = 0.1  # s: how often the statistics are reported (when they changed)


class _Forward(logging.Handler):
    """Sends the child's log records to the runtime's process, which logs them again."""

    def __init__(self, out: _Out) -> None:
        super().__init__()
        self.out = out

    def emit(self, record: logging.LogRecord) -> None:
        arguments = record.args if isinstance(record.args, tuple) else ()
        plain = tuple(value if isinstance(value, (str, int, float)) else str(value) for value in arguments)
        self.out.send(("log", record.levelno, record.name, str(record.msg), plain))


class _Out:
    """The child's stdout, shared by its threads."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.stream = stream
        self.lock = threading.Lock()

    def send(self, message: Any) -> None:
        with self.lock:
            try:
                send(self.stream, message)
            except OSError:  # the runtime is gone: nobody reads any more
                pass


def main() -> int:
    """The child: set up from the first frame, then rows, flushes and stop until the end of stdin."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the runtime stops us (the end of stdin), not the terminal
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    normal_priority()  # started by a thread at SCHED_FIFO (--rt-priority): writing must not take a CPU from the plant
    source, out = sys.stdin.buffer, _Out(sys.stdout.buffer)
    sys.stdout = sys.stderr  # nothing else may write into the frames
    message = receive(source)
    if not (isinstance(message, tuple) and message[0] == "setup"):
        return 2
    setup = message[1]
    logging.basicConfig(level=setup["level"], handlers=[_Forward(out)], force=True)
    writer = BatchWriter(Database(setup["settings"]), flush_period=setup["flush_period"], name=setup["name"],
                         max_pending=setup["max_pending"], maintain_period=setup["maintain_period"])
    for sink in setup["sinks"]:
        writer.register(sink)
    error = writer.start()
    reason = None if error is None else (str(error).strip() or type(error).__name__)
    out.send(("ready", reason))  # with the reason the store cannot be used now (the writer keeps trying)
    done = threading.Event()
    # Figures are taken and sent under one lock: a report taken before a flush and sent after its
    # reply would leave the runtime with figures older than the flush it was answered.
    reporting = threading.Lock()
    reporter = threading.Thread(target=_report, args=(writer, out, done, reporting), name="stats", daemon=True)
    reporter.start()
    while (message := receive(source)) is not None and message[0] != "stop":
        if message[0] == "rows":
            writer.put(message[1], message[2])
        elif message[0] == "flush":
            _, request, maintain, timeout = message
            ok = writer.flush(timeout, maintain=maintain)
            with reporting:
                out.send(("stats", asdict(writer.stats)))
                out.send(("flushed", request, ok))
    writer.stop()
    done.set()
    reporter.join()
    out.send(("stats", asdict(writer.stats)))
    return 0


def _report(writer: BatchWriter, out: _Out, done: threading.Event, reporting: threading.Lock) -> None:
    last: dict[str, Any] = {}
    while not done.wait(STATS_PERIOD):
        with reporting:
            figures = asdict(writer.stats)
            if figures != last:
                out.send(("stats", figures))
                last = figures


if __name__ == "__main__":
    sys.exit(main())
