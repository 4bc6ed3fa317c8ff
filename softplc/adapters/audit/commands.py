"""`audit.query`: the one door through which the HMI and the remote CLI read the audit trail.

    name          permission   arguments
    audit.query   engineer     since, until, tag, command, user, source, peer, kind, result, limit, offset, plant

Engineers only: the trail names every user, the address each one works from and every attempt
that was refused — what an intruder would like to know — and anonymous OPC UA sessions are
viewers. Reading it is not itself recorded (an HMI page that refreshes would fill the trail).
Results are JSON-ready: a list of entries (`AuditEntry.to_dict`), newest first.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from softplc.adapters.audit.queries import KINDS, MAX_ROWS, AuditQuery
from softplc.core.clock import Clock
from softplc.core.commands import CommandRefused, Commands, Permission
from softplc.storage.command_search import Searchable, search_for_command
from softplc.core.tagdb import Origin
from softplc.util.timestamps import parse_utc

ARGUMENTS = {
    "since": "from (epoch s or ISO 8601, UTC unless a zone is given)", "until": "to, excluded (epoch s or ISO 8601)",
    "tag": "tag name or pattern (* and ?): its writes, and commands acting on it", "command": "command name or pattern (tags.*)",
    "user": "who", "source": "opcua, modbus, hmi, cli... (or a pattern)", "peer": "client address pattern (10.0.0.7:*)",
    "kind": "write or command", "result": "accepted or refused", "limit": f"most rows (default 1000, at most {MAX_ROWS})",
    "offset": "rows to skip", "plant": "another plant's entries (shared store), * for all",
}


def register_audit_commands(commands: Commands, recorder: Searchable[AuditQuery], clock: Clock) -> list[Callable[[], None]]:
    """Register `audit.query`; returns its unregister."""

    async def query(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        rows = await search_for_command(clock, recorder, query_from_arguments(arguments), "the audit trail")
        return [row.to_dict() for row in rows]

    return [commands.register("audit.query", query, permission=Permission.ENGINEER, description="read the audit trail",
                              arguments=ARGUMENTS, audited=False)]


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
