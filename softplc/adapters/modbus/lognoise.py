"""Keep pymodbus's reports about misbehaving clients short and rare.

pymodbus logs every malformed frame at ERROR and appends a dump of the last 20 frames, so a
client spraying garbage floods the log. This filter (installed on pymodbus's logger while the
adapter runs) drops the frame dump, lets one message of each kind through per interval (with a
count of the suppressed ones), and reports client mistakes as warnings, not server errors.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable

PYMODBUS_LOGGER = "pymodbus.logging"
# Messages that describe what a client did wrong, not a failure of the server.
_CLIENT_MISTAKES = ("Invalid Modbus protocol id", "Unable to decode frame", "Cancel send, because not connected")
_MAX_KINDS = 200


class ClientNoiseFilter(logging.Filter):
    """Rate-limits and shortens pymodbus warnings and errors (debug records pass untouched)."""

    def __init__(self, interval: float = 60.0, now: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.interval = interval
        self._now = now  # log rate limiting only: wall-clock pacing, not plant logic
        self._seen: dict[str, tuple[float, int]] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        message = record.getMessage().split("\n>>>>>", 1)[0]
        kind = re.sub(r"\d+", "N", message)[:120]
        now = self._now()
        last, suppressed = self._seen.get(kind, (None, 0))
        if last is not None and now - last < self.interval:
            self._seen[kind] = (last, suppressed + 1)
            return False
        if len(self._seen) >= _MAX_KINDS:
            self._seen.clear()
        self._seen[kind] = (now, 0)
        if suppressed:
            message += f" ({suppressed} similar messages suppressed in the last {self.interval:g} s)"
        if message.startswith(_CLIENT_MISTAKES):
            message = f"Modbus client misbehaved (ignored): {message}"
            if record.levelno > logging.WARNING:
                record.levelno, record.levelname = logging.WARNING, "WARNING"
        record.msg, record.args = message, ()
        return True


def install(interval: float = 60.0) -> Callable[[], None]:
    """Attach a filter to pymodbus's logger; returns the function that removes it."""
    logger = logging.getLogger(PYMODBUS_LOGGER)
    noise = ClientNoiseFilter(interval)
    logger.addFilter(noise)
    return lambda: logger.removeFilter(noise)
