"""Pieces of SQL both backends understand, for the stores' searches: name patterns as LIKE, and
the plant and time range of rows in a store several runtimes may share."""

from __future__ import annotations

from typing import Any


def escape_like(text: str) -> str:
    """`text` with LIKE's wildcards taken literally (for `LIKE ? ESCAPE '\\'`)."""
    return text.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_")


def like_pattern(pattern: str) -> str:
    """A name pattern with * and ? as a LIKE pattern (for `LIKE ? ESCAPE '\\'`; other characters literal)."""
    return escape_like(pattern).replace("*", "%").replace("?", "_")


def plant_and_time(wanted: str | None, own: str | None, since: float | None, until: float | None) -> tuple[list[str], list[Any]]:
    """Conditions (with their values) for rows of plant `wanted` (None: `own`; "" or "*": every plant's) in [since, until)."""
    where: list[str] = []
    values: list[Any] = []
    plant = own if wanted is None else wanted
    if plant not in (None, "", "*"):
        where.append("plant = ?")
        values.append(plant)
    if since is not None:
        where.append("time >= ?")
        values.append(since)
    if until is not None:
        where.append("time < ?")
        values.append(until)
    return where, values
