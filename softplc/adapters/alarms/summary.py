"""Alarm summary tags for Modbus and legacy SCADA, and the acknowledge-all command tag.

    _sys.alarms.active            uint32  annunciated alarms whose condition is active
    _sys.alarms.unacknowledged    uint32  alarms waiting for an acknowledgement (active, returned or latched)
    _sys.alarms.highest_priority  uint16  most urgent active alarm: 0 none, 1 low, 2 medium, 3 high, 4 critical
    _sys.alarms.shelved           uint32  shelved alarms
    _sys.alarms.rate              uint32  alarms annunciated within the last 10 minutes
    _sys.alarms.flood             bool    an alarm flood (ISA-18.2: more than 10 within 10 minutes; flood.py)
    _sys.alarms.acknowledge_all   bool rw write true: acknowledge every alarm, as the writer (operator or engineer)

They are tags like any other (OPC UA under Diagnostics, Modbus in the `_sys.` block), so a PLC or
an old SCADA that knows nothing of alarm events can show a horn and an acknowledge button.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from typing import Any

from softplc.core.datatypes import DataType
from softplc.core.tagdb import Origin, TagDatabase, WriteEvent
from softplc.core.tags import Access, TagDef

log = logging.getLogger(__name__)

PREFIX = "_sys.alarms."
ACTIVE = PREFIX + "active"
UNACKNOWLEDGED = PREFIX + "unacknowledged"
HIGHEST_PRIORITY = PREFIX + "highest_priority"
SHELVED = PREFIX + "shelved"
RATE = PREFIX + "rate"
FLOOD = PREFIX + "flood"
ACKNOWLEDGE_ALL = PREFIX + "acknowledge_all"
GROUP = "_sys/alarms"


def summary_tag_definitions() -> list[TagDef]:
    """The summary tags a plant with an `alarms:` section has."""

    def counter(name: str, data_type: DataType, description: str) -> TagDef:
        return TagDef(name=name, type=data_type, initial=0, description=description, access=Access.RO, group=GROUP, runtime_only=True)

    return [
        counter(ACTIVE, DataType.UINT32, "alarms active (unacknowledged or acknowledged), not shelved or suppressed"),
        counter(UNACKNOWLEDGED, DataType.UINT32, "alarms waiting for an acknowledgement"),
        counter(HIGHEST_PRIORITY, DataType.UINT16, "most urgent active alarm: 0 none, 1 low, 2 medium, 3 high, 4 critical"),
        counter(SHELVED, DataType.UINT32, "shelved alarms"),
        counter(RATE, DataType.UINT32, "alarms annunciated within the last 10 minutes"),
        TagDef(name=FLOOD, type=DataType.BOOL, initial=False, access=Access.RO, group=GROUP, runtime_only=True,
               description="an alarm flood: more than 10 alarms within 10 minutes (ISA-18.2), until fewer than 5"),
        TagDef(name=ACKNOWLEDGE_ALL, type=DataType.BOOL, initial=False, access=Access.RW, group=GROUP,
               description="write true to acknowledge every alarm (operator or engineer)"),
    ]


class SummaryTags:
    """Keeps the summary tags current and carries out writes of the acknowledge-all tag."""

    def __init__(self, db: TagDatabase, acknowledge_all: Callable[[Origin], Any]) -> None:
        self.db = db
        self._acknowledge_all = acknowledge_all  # a coroutine function: the command, with the writer's origin
        self._requests: list[Origin] = []
        self._tasks: set[asyncio.Task[Any]] = set()
        self.enabled = all(name in db for name in (ACTIVE, UNACKNOWLEDGED, HIGHEST_PRIORITY, SHELVED, RATE, FLOOD, ACKNOWLEDGE_ALL))

    def note_writes(self, events: Sequence[WriteEvent]) -> None:
        """A `db.on_write` listener: remember who asked to acknowledge all (the role is checked again by the command)."""
        for event in events:
            if event.tag == ACKNOWLEDGE_ALL and event.accepted and event.new is True:
                self._requests.append(event.origin)

    def requested(self) -> bool:
        """Whether a client wrote true to the acknowledge-all tag since the last boundary."""
        return self.enabled and self.db.value(ACKNOWLEDGE_ALL) is True

    def publish(self, active: int, unacknowledged: int, highest: int, shelved: int, rate: int, flood: bool) -> None:
        """At a scan boundary: write the counts; run the acknowledge-all requests the last writes made."""
        if not self.enabled:
            return
        values: dict[str, Any] = {ACTIVE: active, UNACKNOWLEDGED: unacknowledged, HIGHEST_PRIORITY: highest, SHELVED: shelved,
                                  RATE: rate, FLOOD: flood}
        if self.db.value(ACKNOWLEDGE_ALL):
            values[ACKNOWLEDGE_ALL] = False  # a command tag: back to false once seen
            requests, self._requests = self._requests, []
            for origin in requests:
                task = asyncio.get_running_loop().create_task(self._acknowledge_all(origin))
                self._tasks.add(task)
                task.add_done_callback(self._done)
        self.db.commit(values)

    def _done(self, task: asyncio.Task[Any]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.warning("acknowledge-all from %s was refused: %s", ACKNOWLEDGE_ALL, task.exception())

    def cancel(self) -> None:
        for task in self._tasks:
            task.cancel()
