"""Server/ServerStatus as clients see it: CurrentTime that tells the time, on every read and to subscribers.

asyncua keeps ServerStatus (i=2256) and its CurrentTime (i=2258) up to date with a task that
writes both every second; softplc turns that task off (server.stop() would wait up to a second
for it). Here instead:

- a Read of either node computes the value at that moment (a value callback on the node);
- every `period` seconds the fresh values are handed to the nodes' monitored items, so a
  client watchdog that subscribes to CurrentTime sees it advance (Part 5: CurrentTime
  changes; a watchdog that finds it frozen declares the server dead).

Time base: the runtime clock's wall time (`Clock.wall()`), the same as every tag's
SourceTimestamp, so `CurrentTime − SourceTimestamp` is a value's age. On the real clock that is
UTC now; under `softplc run --sim` it is the simulated time (it starts at 2026-01-01T00:00:00Z and
runs as fast as the simulation), and StartTime is set on the same base so CurrentTime never
precedes it. The periodic push waits on the runtime clock too (once per simulated second).
"""

from __future__ import annotations

import asyncio
import copy
import logging
from datetime import datetime, timezone

from asyncua import ua
from asyncua.server.address_space import AddressSpace, AttributeValue

from softplc.core.clock import Clock

log = logging.getLogger(__name__)

SERVER_STATUS = ua.NodeId(ua.ObjectIds.Server_ServerStatus)
CURRENT_TIME = ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime)
START_TIME = ua.NodeId(ua.ObjectIds.Server_ServerStatus_StartTime)
_VALUE = ua.AttributeIds.Value


class ServerStatusClock:
    """Makes ServerStatus and ServerStatus/CurrentTime tell the runtime clock's time."""

    def __init__(self, aspace: AddressSpace, clock: Clock, period: float = 1.0) -> None:
        self.aspace = aspace
        self.clock = clock
        self.period = period
        self._task: asyncio.Task[None] | None = None
        self._status: AttributeValue | None = None
        self._current: AttributeValue | None = None

    def now(self) -> datetime:
        return datetime.fromtimestamp(self.clock.wall(), timezone.utc)

    async def install(self) -> None:
        """Take over both nodes (call after the server started: asyncua's start writes ServerStatus)."""
        started = self.now()
        # StartTime on the same time base as CurrentTime (asyncua wrote the system time).
        await self.aspace.write_attribute_value(START_TIME, _VALUE, _date_value(started))
        status = self.aspace.read_attribute_value(SERVER_STATUS, _VALUE).Value
        stored = copy.copy(status.Value) if status is not None and status.Value is not None else ua.ServerStatusDataType()
        stored.StartTime = started
        await self.aspace.write_attribute_value(SERVER_STATUS, _VALUE, ua.DataValue(ua.Variant(stored, ua.VariantType.ExtensionObject)))
        # A value callback answers every Read; a later write_attribute_value would drop it (asyncua
        # clears the callback on write), and nothing writes these nodes after this point.
        self._status = self.aspace[SERVER_STATUS].attributes[_VALUE]
        self._current = self.aspace[CURRENT_TIME].attributes[_VALUE]
        self._template = stored
        self._status.value_callback = self._read_status
        self._current.value_callback = self._read_current_time

    def run(self) -> asyncio.Task[None]:
        self._task = asyncio.create_task(self._notify_forever(), name="opcua-server-clock")
        return self._task

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None

    def _read_current_time(self, node_id: ua.NodeId, attribute: ua.AttributeIds) -> ua.DataValue:
        return _date_value(self.now())

    def _read_status(self, node_id: ua.NodeId, attribute: ua.AttributeIds) -> ua.DataValue:
        now = self.now()
        status = copy.copy(self._template)
        status.CurrentTime = now
        return ua.DataValue(ua.Variant(status, ua.VariantType.ExtensionObject), SourceTimestamp=now, ServerTimestamp=now)

    async def _notify_forever(self) -> None:
        while True:
            await self.clock.sleep(self.period)
            for attribute, read in ((self._current, self._read_current_time), (self._status, self._read_status)):
                if attribute is None or not attribute.datachange_callbacks:
                    continue
                value = read(CURRENT_TIME, _VALUE)
                for handle, callback in list(attribute.datachange_callbacks.items()):
                    try:
                        await callback(handle, value)
                    except Exception:  # one broken monitored item must not stop the clock
                        log.exception("notifying a monitored item of the server's CurrentTime failed")


def _date_value(moment: datetime) -> ua.DataValue:
    return ua.DataValue(ua.Variant(moment, ua.VariantType.DateTime), SourceTimestamp=moment, ServerTimestamp=moment)
