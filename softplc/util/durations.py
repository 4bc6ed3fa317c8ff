"""Durations as written in configuration: `10ms`, `1.5s`, `2min`, `250us`, or plain seconds."""

from __future__ import annotations

import math
import re
from typing import Any

_UNITS = {"us": 1e-6, "ms": 1e-3, "s": 1.0, "min": 60.0, "h": 3600.0}
_PATTERN = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(us|ms|s|min|h)\s*$")
DURATION_REGEX = r"^\s*(\d+(\.\d*)?|\.\d+)\s*(us|ms|s|min|h)\s*$"


def parse_duration(text: str | int | float) -> float:
    """Seconds from `10ms`-style text or a number of seconds; raises ValueError otherwise."""
    if isinstance(text, bool):
        raise ValueError(f"not a duration: {text!r}")
    if isinstance(text, (int, float)):
        if not math.isfinite(text):
            raise ValueError(f"not a duration: {text!r} (write e.g. 10ms, 1s, 2min)")
        if text < 0:
            raise ValueError(f"a duration cannot be negative: {text}")
        return float(text)
    match = _PATTERN.match(text)
    if match is None:
        raise ValueError(f"not a duration: {text!r} (write e.g. 10ms, 1s, 2min)")
    return float(match.group(1)) * _UNITS[match.group(2)]


def check_duration(value: Any, what: str) -> tuple[float | None, str]:
    """(seconds, "") for a positive duration, or (None, the message saying what is wrong)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None, f"bad {what} {value!r}: must be a finite duration such as 10ms, 100ms or 1s"
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value <= 0:
        return None, f"bad {what} {value!r}: must be greater than zero"
    try:
        seconds = parse_duration(value)
    except (ValueError, TypeError):
        return None, f"bad {what} {value!r}: write a duration such as 10ms, 100ms or 1s"
    if seconds <= 0:
        return None, f"bad {what} {value!r}: must be greater than zero"
    return seconds, ""


def format_duration(seconds: float) -> str:
    """Short human form: 0.01 → '10ms', 1.5 → '1.5s'."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:g}us"
    if seconds < 1.0:
        return f"{seconds * 1e3:g}ms"
    return f"{seconds:g}s"
