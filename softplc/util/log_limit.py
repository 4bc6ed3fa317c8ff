"""A log that no client can flood: at most a few lines per logger and message per interval.

Every line a client can cause — a refused write, a failed login, a refused certificate, a bad
Modbus frame, a robot agent's bad report, asyncua's own complaints — goes through the handlers
`softplc.util.logs` installs, and each handler has a `FloodFilter`: the first `burst` lines of one
*kind* (logger name + message template, e.g. `softplc.adapters.opcua.writes` + `"%s: write %s refused:
%s"`) within `interval` seconds are written, the others counted, and when the interval is over
one summary line says how many were left out. A steady flood thus writes `burst` + 1 lines per
interval and kind. One logger may write at most `logger_burst` lines per interval whatever
their kinds, so messages made unique by what a client sent (a node id in an f-string) cannot
get round the limit. With `-vv` debug lines are not limited: whoever asks for them wants them all.

The pacing is by wall-clock time (`time.monotonic`), not the runtime clock: a flood is about how
many lines reach a disk or a terminal per real second, and under `--sim` the runtime clock runs
hundreds of times faster than that.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

DEFAULT_BURST = 5
DEFAULT_LOGGER_BURST = 50
DEFAULT_INTERVAL = 10.0
MAX_KINDS = 1000  # distinct kinds tracked at once; beyond that the oldest windows are closed early
SUMMARY_ATTRIBUTE = "softplc_flood_summary"  # set on the summary records, which pass unlimited


@dataclass
class _Window:
    """One kind of line within its current interval."""

    start: float
    written: int = 0
    suppressed: int = 0
    level: int = logging.NOTSET  # the highest level among the suppressed lines
    example: str = ""  # the first suppressed line, as written


class FloodFilter(logging.Filter):
    """A handler filter: `burst` lines per (logger, message template) and `logger_burst` per logger
    per `interval` seconds, then a summary; records below `unlimited_below` pass (debug with -vv)."""

    def __init__(
        self,
        emit: Callable[[logging.LogRecord], object],
        *,
        burst: int = DEFAULT_BURST,
        logger_burst: int = DEFAULT_LOGGER_BURST,
        interval: float = DEFAULT_INTERVAL,
        unlimited_below: int = logging.NOTSET,
        now: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self._emit = emit  # where summaries go: the handler's `handle`
        self.burst = burst
        self.logger_burst = logger_burst
        self.interval = interval
        self.unlimited_below = unlimited_below
        self._now = now
        self._windows: dict[tuple[str, str | None], _Window] = {}  # (logger, kind); kind None: the whole logger
        self._lock = threading.RLock()  # re-entrant: a summary is handed to the handler while it is held
        self._next_close = float("inf")

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < self.unlimited_below or getattr(record, SUMMARY_ATTRIBUTE, False):
            return True
        with self._lock:  # the stall detector logs from its own thread
            return self._limit(record)

    def _limit(self, record: logging.LogRecord) -> bool:
        now = self._now()
        if now >= self._next_close:
            self._close_windows(now)
        kind = self._window((record.name, kind_of(record)), now)
        everything = self._window((record.name, None), now)
        if kind.written >= self.burst:
            return self._suppress(kind, record)
        if everything.written >= self.logger_burst:
            return self._suppress(everything, record)
        kind.written += 1
        everything.written += 1
        return True

    def _window(self, key: tuple[str, str | None], now: float) -> _Window:
        window = self._windows.get(key)
        if window is None:
            if len(self._windows) >= MAX_KINDS:
                self._close_windows(float("inf"))
            window = self._windows[key] = _Window(now)
            self._next_close = min(self._next_close, now + self.interval)
        return window

    @staticmethod
    def _suppress(window: _Window, record: logging.LogRecord) -> bool:
        if not window.suppressed:
            window.example = _first_line(record)
        window.suppressed += 1
        window.level = max(window.level, record.levelno)
        return False

    def close_windows(self, now: float | None = None) -> None:
        """Close every window older than the interval (all of them for `now=inf`), summarising what each left out."""
        with self._lock:
            self._close_windows(self._now() if now is None else now)

    def _close_windows(self, now: float) -> None:
        closing = [key for key, window in self._windows.items() if now - window.start >= self.interval]
        for key in closing:
            window = self._windows.pop(key)
            if window.suppressed:
                self._emit(_summary(key[0], window, key[1] is None, self.logger_burst if key[1] is None else self.burst, self.interval))
        self._next_close = min((w.start + self.interval for w in self._windows.values()), default=float("inf"))


def kind_of(record: logging.LogRecord) -> str:
    """The message template: the format string, or for a preformatted message its text with numbers blanked."""
    template = record.msg if isinstance(record.msg, str) else type(record.msg).__name__
    if not record.args:
        # An f-string or a formatted message (asyncua writes many): the numbers are what varies.
        template = re.sub(r"\d+", "N", template[:200])
    return template


def _first_line(record: logging.LogRecord) -> str:
    try:
        text = record.getMessage()
    except Exception:  # a broken format string: logging reports it when the line is written
        text = str(record.msg)
    line = text.split("\n", 1)[0]
    return line if len(line) <= 160 else line[:157] + "..."


def _summary(logger: str, window: _Window, whole_logger: bool, burst: int, interval: float) -> logging.LogRecord:
    plural = "s" if window.suppressed != 1 else ""
    what = f"line{plural} of this logger" if whole_logger else f"line{plural} like this"
    limit = "lines of one logger" if whole_logger else "of a kind"
    record = logging.LogRecord(
        logger, max(window.level, logging.INFO), __file__, 0,
        "%d more %s left out in the last %g s (at most %d %s per %g s): %s",
        (window.suppressed, what, interval, burst, limit, interval, window.example), None,
    )
    setattr(record, SUMMARY_ATTRIBUTE, True)
    return record
