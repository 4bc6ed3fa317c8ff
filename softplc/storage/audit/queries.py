"""Finding entries of the audit trail: by time, tag or command, user, source, peer, and result.

    rows = search(database, AuditQuery(since=..., tag="t01_*", accepted=False), plant="material-handling")
    write_csv(rows, sys.stdout)

Blocking (SQL): call it off the event loop. Newest entries first. A store that does not exist
yet, or holds no partition, simply has no entries.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import IO, Any

from softplc.core.commands import CommandRefused
from softplc.storage import Database, like_pattern, plant_and_time
from softplc.storage.audit.entry import COLUMNS, AuditEntry, entry_of, format_value
from softplc.storage.audit.store import CATALOGUE, SQL_COLUMNS
from softplc.util.timestamps import format_utc, parse_utc

MAX_ROWS = 10_000  # most rows one search returns
KINDS = ("write", "command")


@dataclass(frozen=True)
class AuditQuery:
    """What to find: every condition given must hold (`tag` and `command` together: either)."""

    since: float | None = None  # wall-clock seconds, inclusive
    until: float | None = None  # exclusive
    tag: str = ""  # a tag name or a pattern with * and ?: writes of it, and commands acting on it (a force)
    command: str = ""  # a command name or pattern (tags.force, alarms.*)
    user: str = ""  # exactly this user
    source: str = ""  # opcua, modbus, hmi, cli... (a pattern: fleet*)
    peer: str = ""  # a pattern over host:port (10.0.0.7:*)
    kind: str = ""  # write, command, or "" for both
    accepted: bool | None = None  # True: carried out only; False: refused only
    plant: str | None = None  # None: this plant's entries; "" or "*": every plant's
    limit: int = 1000
    offset: int = 0


def search(database: Database, query: AuditQuery, plant: str | None) -> list[AuditEntry]:
    """The entries of a store matching `query` (`plant` is whose entries `query.plant=None` means)."""
    where, values = _conditions(query, plant, database.postgresql)
    limit = max(0, min(int(query.limit), MAX_ROWS))
    wanted = limit + max(0, int(query.offset))
    if limit == 0:
        return []
    connection = database.connect(readonly=True)
    rows: list[tuple[Any, ...]] = []
    try:
        for name in _partitions(connection, database, query):
            statement = f"SELECT {', '.join(SQL_COLUMNS)} FROM {name}"
            if where:
                statement += " WHERE " + " AND ".join(where)
            statement += f" ORDER BY time DESC, sequence DESC LIMIT {wanted - len(rows)}"
            rows += connection.execute(database.sql(statement), values).fetchall()
            if len(rows) >= wanted:
                break
    finally:
        connection.close()
    return [entry_of(row) for row in rows[query.offset:wanted]]


def _conditions(query: AuditQuery, plant: str | None, postgresql: bool) -> tuple[list[str], list[Any]]:
    where, values = plant_and_time(query.plant, plant, query.since, query.until)
    targets: list[str] = []
    if query.tag:
        targets.append(_match("tag", query.tag, values, postgresql))
    if query.command:
        targets.append(f"(kind = 'command' AND {_match('name', query.command, values, postgresql)})")
    if targets:
        where.append("(" + " OR ".join(targets) + ")")
    if query.user:
        where.append("user_name = ?")
        values.append(query.user)
    if query.source:
        where.append(_match("source", query.source.lower(), values, postgresql))
    if query.peer:
        where.append(_match("peer", query.peer, values, postgresql))
    if query.kind:
        where.append("kind = ?")
        values.append(query.kind)
    if query.accepted is not None:
        where.append("accepted = ?")
        values.append(1 if query.accepted else 0)
    return where, values


def _match(column: str, pattern: str, values: list[Any], postgresql: bool) -> str:
    """`column` equal to `pattern`, or matching it when it has * or ? — case-sensitive on both backends."""
    if "*" not in pattern and "?" not in pattern:
        values.append(pattern)  # an exact name can use the index
        return f"{column} = ?"
    if not postgresql:
        values.append(pattern.replace("[", "[[]"))  # SQLite's GLOB: * and ?, case-sensitive like names
        return f"{column} GLOB ?"
    values.append(like_pattern(pattern))
    return f"{column} LIKE ? ESCAPE '\\'"


def _partitions(connection: Any, database: Database, query: AuditQuery) -> list[str]:
    """The partitions that may hold entries of the query's time range, newest first."""
    if not database.has_table(connection, CATALOGUE):
        return []
    statement = f"SELECT name FROM {CATALOGUE} WHERE stop > ? AND start < ? ORDER BY start DESC"
    since = query.since if query.since is not None else -1e300
    until = query.until if query.until is not None else 1e300
    return [name for (name,) in connection.execute(database.sql(statement), (since, until)).fetchall()]


def write_csv(entries: Iterable[AuditEntry], stream: IO[str]) -> int:
    """Write entries as CSV with a header (time as ISO 8601 UTC and as seconds); returns how many."""
    writer = csv.writer(stream)
    writer.writerow(["time_utc", *COLUMNS])
    count = 0
    for entry in entries:
        cells = [format_value(getattr(entry, name)) if name in ("arguments", "old", "new") else getattr(entry, name) for name in COLUMNS]
        writer.writerow([format_utc(entry.time), *cells])
        count += 1
    return count


# -- a query from a command's arguments (the audit.query command and the CLI) ------------------


def query_from_arguments(arguments: Mapping[str, Any]) -> AuditQuery:
    """The AuditQuery of a call's arguments; raises CommandRefused saying which argument is wrong."""
    numbers = {}
    for key, default in (("limit", 1000), ("offset", 0)):
        value = arguments.get(key, default)
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise CommandRefused(f"audit.query: '{key}' must be a whole number ≥ 0, not {value!r}")
        numbers[key] = value
    kind = _text(arguments, "kind")
    if kind and kind not in KINDS:
        raise CommandRefused(f"audit.query: 'kind' must be write or command, not {kind!r}")
    result = _text(arguments, "result")
    if result not in ("", "accepted", "refused"):
        raise CommandRefused(f"audit.query: 'result' must be accepted or refused, not {result!r}")
    plant = arguments.get("plant")
    if plant is not None and not isinstance(plant, str):
        raise CommandRefused("audit.query: 'plant' must be text")
    return AuditQuery(
        since=parse_time(arguments.get("since"), "since"), until=parse_time(arguments.get("until"), "until"),
        tag=_text(arguments, "tag"), command=_text(arguments, "command"), user=_text(arguments, "user"),
        source=_text(arguments, "source"), peer=_text(arguments, "peer"), kind=kind,
        accepted=None if not result else result == "accepted", plant=plant, **numbers,
    )


def parse_time(value: Any, key: str) -> float | None:
    """Epoch seconds from a number or an ISO 8601 text (UTC unless it gives a zone); None if absent."""
    if value is None or value == "":
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    if isinstance(value, str):
        try:
            return parse_utc(value)
        except ValueError:
            pass
    raise CommandRefused(f"audit.query: '{key}' must be epoch seconds or an ISO 8601 time such as 2026-11-24T08:00:00Z, not {value!r}")


def _text(arguments: Mapping[str, Any], key: str) -> str:
    value = arguments.get(key, "")
    if value is None:
        return ""
    if not isinstance(value, str):
        raise CommandRefused(f"audit.query: '{key}' must be text, not {type(value).__name__}")
    return value
