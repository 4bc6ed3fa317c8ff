"""`audit.query`: the one door through which the HMI and the remote CLI read the audit trail.

    name          permission   arguments
    audit.query   engineer     since, until, tag, command, user, source, peer, kind, result, limit, offset, plant

Engineers only: the trail names every user, the address each one works from and every attempt
that was refused — what an intruder would like to know — and anonymous OPC UA sessions are
viewers. Reading it is not itself recorded (an HMI page that refreshes would fill the trail).
Results are JSON-ready: a list of entries (`AuditEntry.to_dict`), newest first.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from softplc.core.clock import Clock
from softplc.core.commands import Commands, Permission
from softplc.core.tagdb import Origin
from softplc.storage.audit.queries import MAX_ROWS, AuditQuery, query_from_arguments
from softplc.storage.command_search import Searchable, search_for_command

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
