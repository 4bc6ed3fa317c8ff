"""Times as people write and read them — one rule everywhere: a time written without a zone is UTC.

Every command line option and command argument that takes a time (`softplc audit --since`,
`softplc alarms journal --since`, `softplc history export --from`, the `audit.query` and
`alarms.journal` commands) reads it with `parse_time` or `parse_utc`: ISO 8601, UTC unless it
gives a zone (`2026-11-24T08:00`, `2026-11-24T08:00Z`, `2026-11-24T09:00+01:00`), or how long
ago (`30min`, `8h`, `7d`). Neither the user's zone nor the runtime host's ever changes what a
time means, so the same text gives the same rows on every machine. Every time shown — tables,
CSV, JSON — carries its zone (`Z`), so a time copied from a table can be pasted back as it is.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone

from softplc.util.durations import parse_duration

TIME_HELP = "how long ago (30min, 8h, 7d) or ISO 8601, UTC unless a zone is given (2026-11-24T08:00, 2026-11-24T09:00+01:00)"
_SPAN = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(d|w)\s*$")


def format_utc(seconds: float) -> str:
    """Unix seconds as ISO 8601 in UTC with milliseconds: 2026-11-24T08:00:00.000Z."""
    return datetime.fromtimestamp(seconds, timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def format_shown(seconds: float, *, milliseconds: bool = False) -> str:
    """Unix seconds for a table cell, in UTC with its zone: 2026-11-24 08:00:00Z (with `milliseconds`: 08:00:00.000Z)."""
    moment = datetime.fromtimestamp(seconds, timezone.utc)
    return moment.isoformat(sep=" ", timespec="milliseconds" if milliseconds else "seconds").replace("+00:00", "Z")


def parse_utc(text: str) -> float:
    """Unix seconds of an ISO 8601 time, UTC unless it gives a zone; raises ValueError."""
    moment = datetime.fromisoformat(text.strip())
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    return moment.timestamp()


def parse_span(text: str | int | float) -> float:
    """Seconds from a duration that may also be written in days or weeks (`30d`, `1w`); raises ValueError."""
    if isinstance(text, str):
        match = _SPAN.match(text)
        if match is not None:
            return float(match.group(1)) * (86400.0 if match.group(2) == "d" else 604800.0)
    return parse_duration(text)


def parse_time(text: str, now: float) -> float:
    """Unix seconds of `text`: how long before `now` (8h, 30min, 7d) or ISO 8601 (UTC unless a zone is given); raises ValueError."""
    try:
        return now - parse_span(text)
    except ValueError:
        pass
    try:
        return parse_utc(text)
    except ValueError:
        raise ValueError(f"{text!r}: write how long ago (30min, 8h, 7d) or an ISO 8601 time such as 2026-11-24T08:00 "
                         "(UTC unless a zone is given, e.g. 2026-11-24T09:00+01:00)") from None
