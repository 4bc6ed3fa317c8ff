"""Subscriptions as softplc serves them: published clear of the scan, and cheap per change.

Two subclasses of asyncua 2.1.0's own (pinned), installed on every subscription a client creates:

- publishing (on the subscription's timer or when a Publish request arrives) waits for
  `ScanGuard.clear()`, so encoding a big PublishResponse never delays a scan cycle;
- a data change of a tag (a `TagDataValue`, never changed after it is made) is queued without
  asyncua's deep copy and without building a throw-away default DataValue first: about a third
  of asyncua's cost per monitored change. Anything else (deadband filters, other nodes) takes
  asyncua's own path.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

from asyncua import ua
from asyncua.server.monitored_item_service import MonitoredItemService
from asyncua.server.subscription_service import SubscriptionService

from softplc.opcua.scheduling import ScanGuard
from softplc.opcua.variants import TagDataValue


class GuardedSubscriptionService(SubscriptionService):
    """asyncua's subscription service whose subscriptions publish only when clear of the scan."""

    def __init__(self, *args: Any, guard: ScanGuard, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.guard = guard

    async def create_subscription(self, params: ua.CreateSubscriptionParameters, callback: Any, session_id: ua.NodeId,
                                  request_callback: Any = None) -> ua.CreateSubscriptionResult:
        result = await super().create_subscription(params, callback, session_id, request_callback=request_callback)
        subscription = self.subscriptions[result.SubscriptionId]
        # Both the subscription's own timer and an arriving Publish request call publish_results.
        # Its publishing loop has not run yet (it starts at the next loop turn), so no publish
        # escapes the guard.
        subscription.publish_results = _guarded(subscription.publish_results, self.guard)  # type: ignore[method-assign]
        # No monitored item exists yet: swap in the lean data change path.
        subscription.monitored_item_srv = LeanMonitoredItemService(subscription, self.aspace)
        return result


def _guarded(publish: Callable[..., Any], guard: ScanGuard) -> Callable[..., Any]:
    @functools.wraps(publish)
    async def publish_results(*args: Any, **kwargs: Any) -> bool:
        await guard.clear()
        return await publish(*args, **kwargs)

    return publish_results


class LeanMonitoredItemService(MonitoredItemService):
    """asyncua's monitored items with a short path for tag changes (same queueing and filtering)."""

    async def datachange_callback(self, handle: int, value: ua.DataValue, error: ua.StatusCode | None = None) -> None:
        if error is not None or type(value) is not TagDataValue:
            return await super().datachange_callback(handle, value, error)
        mid = self._monitored_datachange[handle]
        mdata = self._monitored_items[mid]
        if mdata.mode == ua.MonitoringMode.Disabled:
            return
        if mdata.filter:  # deadbands and triggers: asyncua's rules
            return await super().datachange_callback(handle, value, error)
        values = mdata.mvalue
        old = values.current_dvalue
        values.old_dvalue = old
        values.current_dvalue = value  # a TagDataValue never changes: no copy needed
        if old is None or old.StatusCode != value.StatusCode or old.Value != value.Value:
            notification = ua.MonitoredItemNotification(ClientHandle=mdata.client_handle, Value=value)
            await self.isub.enqueue_datachange_event(mid, notification, mdata.queue_size)
