"""`softplc forces | force | unforce`: forcing a running softplc over OPC UA.

They call the runtime's commands (`tags.forces`, `tags.force`, `tags.unforce` in
softplc/runtime_commands.py) through the server's door to them, `Objects/Commands`
(`Call(name, argumentsJSON) -> resultJSON`, softplc/opcua/commands.py), which checks the
session's role like every other path: listing is for any role, forcing for engineers.

A server without that door (an older softplc) still shows its forced tags: they are served with
the StatusCode GoodLocalOverride, and their SourceTimestamp is when the force took effect; who
forced them is then unknown.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

from asyncua import ua

from softplc.live.session import LiveSession, Reading

READ_CHUNK = 5000  # tags per Read request (the server takes up to 20,000)
FORCES_HEADER = ("tag", "value", "since (UTC)", "by")
UNKNOWN_BY = "?"
COMMANDS_OBJECT = "Commands"
_NO_DOOR = ("BadNodeIdUnknown", "BadNodeIdInvalid", "BadMethodInvalid", "BadNotImplemented")


class CommandError(Exception):
    """A command the runtime refused (`not_allowed`: because of the session's role), or no door to call it through."""

    def __init__(self, message: str, *, not_allowed: bool = False, no_door: bool = False) -> None:
        super().__init__(message)
        self.not_allowed = not_allowed
        self.no_door = no_door


@dataclass(frozen=True)
class ForcedTag:
    """One forced tag as a client sees it."""

    tag: str
    value: Any
    since: datetime | None
    by: str = UNKNOWN_BY
    single: bool = False  # a float32 value (shown with a float32's digits)

    @classmethod
    def from_reading(cls, reading: Reading) -> ForcedTag:
        return cls(reading.tag, reading.value, reading.timestamp, single=reading.single)


async def call_command(session: LiveSession, name: str, arguments: dict[str, Any]) -> Any:
    """The result of runtime command `name`; raises CommandError with the runtime's reason."""
    commands = session.client.get_node(ua.NodeId(COMMANDS_OBJECT, session.ns))
    try:
        reply = await commands.call_method(ua.NodeId(f"{COMMANDS_OBJECT}.Call", session.ns), name, json.dumps(arguments))
    except ua.UaStatusCodeError as error:
        code = ua.StatusCode(error.code).name
        if code == "BadUserAccessDenied":
            raise CommandError(f"{name}: this session's role may not do that (BadUserAccessDenied)", not_allowed=True) from None
        if code in _NO_DOOR:
            raise CommandError("this server has no OPC UA door to the runtime's commands (Objects/Commands)", no_door=True) from None
        raise CommandError(f"{name}: refused by the server: {code}") from None
    answer = json.loads(reply)
    if not answer.get("ok"):
        raise CommandError(str(answer.get("error", "refused")))
    return answer.get("result")


async def list_forces(session: LiveSession) -> list[ForcedTag]:
    """Every forced tag of the server: from the runtime's `tags.forces`, else from GoodLocalOverride."""
    try:
        forces = await call_command(session, "tags.forces", {})
    except CommandError as error:
        if not error.no_door:
            raise
        return await _forces_by_status(session)
    readings = await session.read([force["tag"] for force in forces]) if forces else []
    singles = {reading.tag: reading.single for reading in readings}
    return [
        ForcedTag(force["tag"], force["value"], datetime.fromtimestamp(force["since"], timezone.utc), force["by"],
                  singles.get(force["tag"], False))
        for force in forces
    ]


async def _forces_by_status(session: LiveSession) -> list[ForcedTag]:
    names = await session.tag_names()
    forced = []
    for start in range(0, len(names), READ_CHUNK):
        for reading in await session.read(names[start:start + READ_CHUNK]):
            if reading.forced:
                forced.append(ForcedTag.from_reading(reading))
    return forced
