"""Calling a runtime command from a client, through the OPC UA commands door (`Objects/Commands.Call`).

    result = await call_command(client, namespace_index, "tags.force", {"tag": "t01_iFr", "value": "0"})

The door is served by softplc/adapters/opcua/commands.py: `Call(name, argumentsJSON) -> resultJSON`, where
resultJSON is {"ok": true, "result": ...} or {"ok": false, "error": "the runtime's reason"}. Every
client command (read/write/force..., apply, alarms, audit --endpoint) calls the runtime this way,
and gets one error type back whatever went wrong: `CommandError`, whose `kind` says why.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # asyncua is imported when a command runs: `softplc --help` must not load it
    from asyncua import Client

from softplc.protocols.opcua_names import COMMANDS_OBJECT

NOT_ALLOWED = "not_allowed"  # the session's role may not call it (BadUserAccessDenied)
NO_DOOR = "no_door"  # the server has no Objects/Commands: no softplc, or one older than the door
REFUSED = "refused"  # the runtime refused it, in its own words (or the server answered another bad status)
_NO_DOOR_CODES = ("BadNodeIdUnknown", "BadNodeIdInvalid", "BadMethodInvalid", "BadNotImplemented")


class CommandError(Exception):
    """A runtime command that was not carried out; `kind` is NOT_ALLOWED, NO_DOOR or REFUSED, the message the reason."""

    def __init__(self, name: str, message: str, kind: str = REFUSED) -> None:
        super().__init__(message)
        self.name = name
        self.kind = kind

    @property
    def not_allowed(self) -> bool:
        return self.kind == NOT_ALLOWED

    @property
    def no_door(self) -> bool:
        return self.kind == NO_DOOR


async def call_command(client: Client, namespace_index: int, name: str, arguments: dict[str, Any] | None = None) -> Any:
    """The result of runtime command `name`; raises CommandError (a lost connection raises what asyncua raises)."""
    from asyncua import ua

    door = client.get_node(ua.NodeId(COMMANDS_OBJECT, namespace_index))
    try:
        reply = await door.call_method(ua.NodeId(f"{COMMANDS_OBJECT}.Call", namespace_index), name, json.dumps(arguments or {}))
    except ua.UaStatusCodeError as error:
        code = ua.StatusCode(error.code).name
        if code == "BadUserAccessDenied":
            raise CommandError(name, f"{name}: this session's role may not do that (BadUserAccessDenied)", NOT_ALLOWED) from None
        if code in _NO_DOOR_CODES:
            raise CommandError(name, "this server has no OPC UA door to the runtime's commands (Objects/Commands)", NO_DOOR) from None
        raise CommandError(name, f"{name}: refused by the server: {code}") from None
    try:
        answer = json.loads(reply)
    except (TypeError, ValueError):
        raise CommandError(name, f"{name}: the server's answer is not the door's JSON: {str(reply)[:80]!r}") from None
    if not isinstance(answer, dict):
        raise CommandError(name, f"{name}: the server's answer is not the door's JSON: {str(reply)[:80]!r}")
    if not answer.get("ok"):
        raise CommandError(name, str(answer.get("error", "refused")))
    return answer.get("result")


async def call_pages(client: Client, namespace_index: int, name: str, query: dict[str, Any], wanted: float, page: int) -> list[Any]:
    """Up to `wanted` rows of a listing command that takes `limit` and `offset`, `page` rows per call."""
    rows: list[Any] = []
    while len(rows) < wanted:
        got = await call_command(client, namespace_index, name, {**query, "limit": int(min(page, wanted - len(rows))), "offset": len(rows)})
        rows += got
        if len(got) < page:
            break
    return rows
