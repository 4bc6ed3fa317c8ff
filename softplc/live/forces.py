"""`softplc forces`: the forced tags of a running softplc, read over OPC UA.

A forced tag is served with the StatusCode GoodLocalOverride (softplc/forcing.py), and its
SourceTimestamp is when the force took effect (a forced tag's value changes only by a new force).
Who forced it is known to the runtime (`tags.forces` in softplc/runtime_commands.py) but not
published over OPC UA yet: the `by` column waits for the OPC UA door to the runtime's commands.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from softplc.live.session import LiveSession, Reading

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
    single: bool = False

    @classmethod
    def from_reading(cls, reading: Reading) -> ForcedTag:
        return cls(reading.tag, reading.value, reading.timestamp, single=reading.single)


async def list_forces(session: LiveSession) -> list[ForcedTag]:
    """Every forced tag of the server, in address-space order."""
    names = await session.tag_names()
    forced = []
    for start in range(0, len(names), READ_CHUNK):
        for reading in await session.read(names[start:start + READ_CHUNK]):
            if reading.forced:
                forced.append(ForcedTag.from_reading(reading))
    return forced
