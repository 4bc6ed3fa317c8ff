"""`softplc forces | force | unforce`: forcing a running softplc over OPC UA.

They call the runtime's commands (`tags.forces`, `tags.force`, `tags.unforce` in
softplc/engine/runtime_commands.py) through the server's door to them, `Objects/Commands`
(`Call(name, argumentsJSON) -> resultJSON`; client side softplc/clients/door_client.py), which checks the
session's role like every other path: listing is for any role, forcing for engineers.

A server without that door (an older softplc) still shows its forced tags: they are served with
the StatusCode GoodLocalOverride, and their SourceTimestamp is when the force took effect; who
forced them is then unknown.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

from softplc.clients.door_client import CommandError, call_command
from softplc.clients.session import LiveSession, Reading

READ_CHUNK = 5000  # tags per Read request (the server takes up to 20,000)
FORCES_HEADER = ("tag", "value", "since (UTC)", "by")
UNKNOWN_BY = "?"


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


async def list_forces(session: LiveSession) -> list[ForcedTag]:
    """Every forced tag of the server: from the runtime's `tags.forces`, else from GoodLocalOverride."""
    try:
        forces = await call_command(session.client, session.ns, "tags.forces")
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
