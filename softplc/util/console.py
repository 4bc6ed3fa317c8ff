"""What commands print for people: aligned plain-text tables (shared by every command module)."""

from __future__ import annotations

import sys
from typing import TextIO


def print_table(rows: list[list[str]], header: tuple[str, ...] | list[str], stream: TextIO | None = None) -> None:
    """Print rows as an aligned plain-text table."""
    stream = stream or sys.stdout
    widths = [max([len(h)] + [len(row[i]) for row in rows]) for i, h in enumerate(header)]
    print("  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip(), file=stream)
    print("  ".join("-" * w for w in widths), file=stream)
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip(), file=stream)
