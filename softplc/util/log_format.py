"""How a log line looks: text for people, one JSON object per line for log shippers.

    2026-11-24T10:49:03.123Z softplc: ERROR: program fill_t01 FAULTED: ZeroDivisionError: ... [softplc.core.program.fill_t01]
    {"time": "2026-11-24T10:49:03.123Z", "level": "ERROR", "logger": "softplc.core.program.fill_t01", "message": "...", "exception": "Traceback ..."}

Times are UTC (ISO 8601, milliseconds). Under `softplc run --sim` they are the runtime clock's
wall time (simulated, from 2026-01-01T00:00:00Z), so a simulated run's log lines up with its
tag timestamps; `PlantTime` stamps each record with it as it is handled.

A program fault carries its traceback (`exc_info`) and the mark `BRIEF_TRACEBACK`: the text
format shows that traceback only with `-v` (otherwise the one-line error says where), the
JSON format always carries it in `exception`. Every other traceback is always shown.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from datetime import datetime, timezone

BRIEF_TRACEBACK = "softplc_brief_traceback"  # record attribute: show the traceback only when verbose
_TIME_ATTRIBUTE = "softplc_time"


class PlantTime(logging.Filter):
    """Stamps each record with the time to show: the runtime clock's wall time under --sim, else the record's own."""

    def __init__(self) -> None:
        super().__init__()
        self.source: Callable[[], float] | None = None  # None: real time (record.created)

    def filter(self, record: logging.LogRecord) -> bool:
        if self.source is not None and not hasattr(record, _TIME_ATTRIBUTE):
            setattr(record, _TIME_ATTRIBUTE, self.source())
        return True


def record_time(record: logging.LogRecord) -> str:
    """The record's time as ISO 8601 UTC with milliseconds: 2026-11-24T10:49:03.123Z."""
    seconds = getattr(record, _TIME_ATTRIBUTE, record.created)
    stamp = datetime.fromtimestamp(seconds, timezone.utc)
    return stamp.strftime("%Y-%m-%dT%H:%M:%S.") + f"{stamp.microsecond // 1000:03d}Z"


class TextFormatter(logging.Formatter):
    """`TIME softplc: LEVEL: message [logger]`, then the traceback if there is one to show."""

    def __init__(self, verbose: bool = False) -> None:
        super().__init__()
        self.verbose = verbose

    def format(self, record: logging.LogRecord) -> str:
        line = f"{record_time(record)} softplc: {record.levelname}: {record.getMessage()} [{record.name}]"
        if record.exc_info and (self.verbose or not getattr(record, BRIEF_TRACEBACK, False)):
            line += "\n" + self.formatException(record.exc_info).rstrip("\n")
        if record.stack_info:
            line += "\n" + self.formatStack(record.stack_info)
        return line


class JsonFormatter(logging.Formatter):
    """One JSON object per line: time, level, logger, message, and exception (the traceback) when there is one."""

    def format(self, record: logging.LogRecord) -> str:
        entry = {"time": record_time(record), "level": record.levelname, "logger": record.name, "message": record.getMessage()}
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        if record.stack_info:
            entry["stack"] = self.formatStack(record.stack_info)
        # ensure_ascii keeps every line one line of plain ASCII, whatever a message contains.
        return json.dumps(entry, ensure_ascii=True)
