"""How the live commands show tag values: aligned columns, values as a person would type them back."""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from datetime import datetime
from typing import Any

from softplc.clients.session import Reading

READING_HEADER = ("tag", "value", "quality", "F", "changed (UTC)")


def format_value(value: Any, single: bool = False) -> str:
    """A value as `softplc write` accepts it back: true/false, 42, 0.5, text as it is."""
    if value is None:
        return "(null)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value) or math.isinf(value):
            return str(value)
        return _single_text(value) if single else repr(value)  # the shortest text that reads back the same
    return str(value)


def _single_text(value: float) -> str:
    """The shortest text of a float32 value that reads back as the same float32 (0.1, not 0.10000000149011612)."""
    exact = struct.pack("f", value)
    for digits in range(6, 10):
        text = f"{value:.{digits}g}"
        if struct.pack("f", float(text)) == exact:
            return text if any(c in text for c in ".en") else text + ".0"
    return repr(value)


def format_time(stamp: datetime | None) -> str:
    """2026-11-24 10:49:03.123 (UTC), as in the log."""
    if stamp is None:
        return "-"
    return stamp.strftime("%Y-%m-%d %H:%M:%S.") + f"{stamp.microsecond // 1000:03d}"


def reading_row(reading: Reading | None, tag: str) -> list[str]:
    if reading is None:
        return [tag, "…", "", "", ""]
    quality = reading.quality.value if reading.status in ("Good", "GoodLocalOverride") else f"{reading.quality.value} ({reading.status})"
    return [tag, format_value(reading.value, reading.single), quality, "F" if reading.forced else "", format_time(reading.timestamp)]


def table_lines(rows: Sequence[Sequence[str]], header: Sequence[str]) -> list[str]:
    """Rows as aligned text lines under a header and a rule."""
    widths = [max([len(h)] + [len(row[i]) for row in rows]) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip(), "  ".join("-" * w for w in widths)]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    return lines


def reading_json(reading: Reading) -> dict[str, Any]:
    value = reading.value
    if isinstance(value, float) and not math.isfinite(value):
        value = str(value)  # JSON has no NaN or Infinity
    return {
        "tag": reading.tag, "value": value, "quality": reading.quality.value, "forced": reading.forced,
        "status": reading.status, "timestamp": reading.timestamp.isoformat() if reading.timestamp else None,
    }
