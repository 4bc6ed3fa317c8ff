"""Counts in messages: "1 write", "2 writes" — never "1 writes"."""

from __future__ import annotations


def plural(count: int, noun: str, many: str | None = None) -> str:
    """`count` and `noun`, the noun in the plural unless the count is one ('1 item', '3 items', '0 items')."""
    return f"{count} {noun if count == 1 else many or noun + 's'}"
