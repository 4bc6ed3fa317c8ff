"""Times as people write and read them in exports, CSV files and command arguments: ISO 8601, UTC."""

from __future__ import annotations

from datetime import datetime, timezone


def format_utc(seconds: float) -> str:
    """Unix seconds as ISO 8601 in UTC with milliseconds: 2026-11-24T08:00:00.000Z."""
    return datetime.fromtimestamp(seconds, timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def parse_utc(text: str) -> float:
    """Unix seconds of an ISO 8601 time, UTC unless it gives a zone; raises ValueError."""
    moment = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    return moment.timestamp()
