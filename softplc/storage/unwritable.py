"""Rows a store refuses: is it the rows' fault or the store's, and the rows' text made writable.

A transaction can fail because the store failed (a full disk, a PostgreSQL restart: keep the
rows, write them later) or because a row holds something the driver or the server refuses — a
string with lone surrogates (what Python makes of invalid UTF-8 received over OPC UA: bytes
`ff fe` become '\\udcff\\udcfe', which neither SQLite nor PostgreSQL can encode), a NUL character
(PostgreSQL's text refuses it), a number too large for an integer column. Retrying such a row
forever would stop the store for everything behind it: the writer (softplc/storage/writer.py)
escapes the rows' text instead (`escaped`), and sets aside a row that still cannot be written.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from collections.abc import Mapping
from typing import Any

# Errors of the rows, not of the store: raised while a value is adapted or checked. Anything
# else (sqlite3.OperationalError, psycopg.OperationalError, a full disk...) is the store's.
_ROW_ERRORS: tuple[type[BaseException], ...] = (UnicodeError, ValueError, TypeError, OverflowError, sqlite3.InterfaceError,
                                               sqlite3.ProgrammingError, sqlite3.IntegrityError, sqlite3.DataError)
# PostgreSQL's SQLSTATE classes that are about the data: 22 data exception, 23 integrity violation.
_ROW_SQLSTATE_CLASSES = ("22", "23")


def rows_at_fault(error: BaseException) -> bool:
    """Whether `error` (from writing a batch) may come from what one row holds rather than from the store."""
    if isinstance(error, _ROW_ERRORS):
        return True
    try:
        import psycopg
    except ImportError:
        return False
    if isinstance(error, psycopg.DataError):  # raised before the server sees it too (a NUL in a string)
        return True
    if isinstance(error, psycopg.Error) and not isinstance(error, (psycopg.OperationalError, psycopg.InterfaceError)):
        state = error.sqlstate or ""
        return state[:2] in _ROW_SQLSTATE_CLASSES
    return False


def escape_text(text: str, nul: bool = True) -> str:
    """`text` with what a store cannot keep written out: lone surrogates as \\xNN (invalid UTF-8 bytes) or \\uNNNN;
    with `nul` (PostgreSQL), NUL as \\x00."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        pass
    else:
        if not nul or "\x00" not in text:
            return text
    parts = []
    for character in text:
        code = ord(character)
        if 0xDC80 <= code <= 0xDCFF:  # a byte that was not UTF-8, as Python's surrogateescape keeps it
            parts.append(f"\\x{code - 0xDC00:02x}")
        elif 0xD800 <= code <= 0xDFFF:
            parts.append(f"\\u{code:04x}")
        elif code == 0 and nul:
            parts.append("\\x00")
        else:
            parts.append(character)
    return "".join(parts)


def escaped(row: Any, nul: bool = True) -> Any:
    """`row` with every string inside it (tuples, lists, mappings, dataclasses) escaped; the same object when nothing changed."""
    kind = type(row)
    if kind is str:
        return escape_text(row, nul)
    if kind is tuple or kind is list:
        items = [escaped(item, nul) for item in row]
        return row if all(new is old for new, old in zip(items, row)) else kind(items)
    if isinstance(row, Mapping):
        pairs = [(escaped(key, nul), escaped(value, nul)) for key, value in row.items()]
        return row if all(k is old_k and v is old_v for (k, v), (old_k, old_v) in zip(pairs, row.items())) else dict(pairs)
    if dataclasses.is_dataclass(row) and not isinstance(row, type):
        changes = {}
        for field in dataclasses.fields(row):
            if not field.init:
                continue
            value = getattr(row, field.name)
            new = escaped(value, nul)
            if new is not value:
                changes[field.name] = new
        return dataclasses.replace(row, **changes) if changes else row
    return row


def describe_row(row: Any, limit: int = 300) -> str:
    """A row as one line of a log (clipped, escaped: the row may hold anything)."""
    text = escape_text(repr(row))
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"
