"""Subscriptions as softplc serves them: clear of the scan, cheap per change, bounded when clients vanish.

asyncua 2.1.0's (pinned) subscription service is kept; every subscription a client creates is a
`TagSubscription` and its monitored items a `TagMonitoredItems`:

- publishing (on the subscription's timer or when a Publish request arrives) waits for
  `ScanGuard.clear()`, so encoding a big PublishResponse never delays a scan cycle;
- a data change is judged by `monitoring.ChangeFilter` against the value last *reported*
  (deadbands per Part 4/8); a filter that does not fit its node is refused per item at
  CreateMonitoredItems; queue sizes are revised by `monitoring.revise_queue_size` (0 → 1, at
  most 100) and a full queue drops its oldest notification in O(1) (asyncua: a list's pop(0));
- a tag change (a `TagDataValue`, never changed after it is made) is queued without asyncua's
  deep copy.

Clients that vanish without CloseSession: asyncua keeps their session (and subscriptions) until
the session times out (at most 60 s here), and every tag change still costs each of their
monitored items a sample. A subscription that cannot deliver goes *dormant*: its monitored items
are detached from the address space (a tag change then costs it nothing), and the notifications
already queued stay (at most queue size × items). It goes dormant

- at once when its session's connection is lost (the client can only come back on a new
  connection, with ActivateSession), and
- when no Publish request was available for it for `STARVED_SECONDS` (and 3 publishing
  intervals): a client that keeps its connection open but stopped asking (hung, or a cable
  pulled without a TCP reset).

The next Publish request that reaches a dormant subscription wakes it: its items are attached
again and each reports its current value (the samples in between are not kept). Starvation is
measured on the system's monotonic clock, like asyncua's publishing timers: it is about real
clients' requests, not plant time (under --sim the runtime clock runs far faster).
"""

from __future__ import annotations

import asyncio
import copy
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from asyncua import ua
from asyncua.common import utils
from asyncua.server.address_space import AddressSpace
from asyncua.server.internal_subscription import InternalSubscription
from asyncua.server.monitored_item_service import MonitoredItemData, MonitoredItemService
from asyncua.server.subscription_service import SubscriptionService

from softplc.adapters.opcua.monitoring import (
    NO_FILTER,
    ChangeFilter,
    FilterRefused,
    change_filter,
    revise_event_queue_size,
    revise_queue_size,
)
from softplc.adapters.opcua.scheduling import ScanGuard
from softplc.protocols.opcua_variants import TagDataValue

STARVED_SECONDS = 5.0
_CREATE_SLICE = 0.0005  # seconds of CreateMonitoredItems work between two turns of the event loop


class GuardedSubscriptionService(SubscriptionService):
    """asyncua's subscription service whose client subscriptions are `TagSubscription`s."""

    def __init__(self, *args: Any, guard: ScanGuard, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.guard = guard

    async def create_subscription(self, params: ua.CreateSubscriptionParameters, callback: Any, session_id: ua.NodeId,
                                  request_callback: Any = None) -> ua.CreateSubscriptionResult:
        # As SubscriptionService.create_subscription (asyncua 2.1.0), with our subscription class.
        iserver = self.iserver
        max_subscriptions = iserver.max_subscriptions if iserver else 1_000
        if len(self.subscriptions) >= max_subscriptions:
            raise utils.ServiceError(ua.StatusCodes.BadTooManySubscriptions)
        result = ua.CreateSubscriptionResult()
        result.RevisedPublishingInterval = params.RequestedPublishingInterval
        result.RevisedLifetimeCount = self._clamp_lifetime_count(params.RequestedLifetimeCount)
        result.RevisedMaxKeepAliveCount = self._clamp_keep_alive_count(params.RequestedMaxKeepAliveCount)
        self._sub_id_counter += 1
        result.SubscriptionId = self._sub_id_counter
        subscription = TagSubscription(
            result, self.aspace, callback, session_id, request_callback=request_callback,
            delete_callback=lambda: self.subscriptions.pop(result.SubscriptionId, None),
            no_acks_limit=iserver.max_unacked_messages_per_subscription if iserver else 5_000,
            publishing_enabled=params.PublishingEnabled, guard=self.guard,
        )
        await subscription.start()
        self.subscriptions[result.SubscriptionId] = subscription
        return result

    async def put_to_sleep(self, session_id: ua.NodeId) -> None:
        """Make every subscription of a session dormant (its connection was lost)."""
        for subscription in list(self.subscriptions.values()):
            if subscription.session_id == session_id and isinstance(subscription, TagSubscription):
                # Many clients may vanish at once (a switch, a killed process): one at a time,
                # clear of the scan.
                await self.guard.clear()
                subscription.sleep()


class TagSubscription(InternalSubscription):
    """A client's subscription: publishes clear of the scan, O(1) queues, dormant while it cannot deliver."""

    def __init__(self, data: ua.CreateSubscriptionResult, aspace: AddressSpace, callback: Any, session_id: ua.NodeId, *,
                 guard: ScanGuard, **kwargs: Any) -> None:
        self._request_callback: Callable[[int], Any] | None = None
        super().__init__(data, aspace, callback, session_id, **kwargs)
        self.guard = guard
        self.monitored_item_srv: TagMonitoredItems = TagMonitoredItems(self, aspace)
        self.dormant = False
        self._starved_since: float | None = None
        self._waking: asyncio.Task[None] | None = None

    # asyncua sets pub_request_callback here and again when a session is activated on a new
    # connection; every call goes through _request_publish, which notices starvation.
    @property  # type: ignore[override]
    def pub_request_callback(self) -> Callable[[int], Any] | None:
        return self._request_publish if self._request_callback is not None else None

    @pub_request_callback.setter
    def pub_request_callback(self, callback: Callable[[int], Any] | None) -> None:
        self._request_callback = callback

    def _request_publish(self, subscription_id: int) -> Any:
        assert self._request_callback is not None
        request = self._request_callback(subscription_id)
        if request is not None:
            self._starved_since = None
            self.wake()
            return request
        now = time.monotonic()
        if self._starved_since is None:
            self._starved_since = now
        elif not self.dormant and now - self._starved_since > self.patience:
            self.sleep()
        return None

    @property
    def patience(self) -> float:
        """Seconds without a Publish request before the subscription goes dormant."""
        return max(STARVED_SECONDS, 3 * self.data.RevisedPublishingInterval / 1000.0)

    async def publish_results(self, requestdata: Any = None) -> bool:
        await self.guard.clear()
        if requestdata is not None:  # a Publish request arrived for this subscription
            self._starved_since = None
            self.wake()
        return await super().publish_results(requestdata)

    def sleep(self) -> None:
        """Stop sampling: detach every data-change item from the address space."""
        if not self.dormant:
            self.dormant = True
            self.monitored_item_srv.detach()

    def wake(self) -> None:
        """Sample again; each item reports its current value (if it differs from the last reported)."""
        if self.dormant:
            self.dormant = False
            items = self.monitored_item_srv.attach()
            if items:
                self._waking = asyncio.create_task(self.monitored_item_srv.refresh(items))

    async def stop(self) -> None:
        if self._waking is not None:
            self._waking.cancel()
        await super().stop()

    async def _enqueue_event(self, mid: int, eventdata: Any, size: int, queue: dict[int, Any]) -> None:
        items = queue.get(mid)
        if items is None:
            queue[mid] = deque((eventdata,), maxlen=size or None)
            await self._trigger_publish()
            return
        if items.maxlen != (size or None):  # ModifyMonitoredItems changed the queue size
            items = queue[mid] = deque(items, maxlen=size or None)
        items.append(eventdata)  # a full queue drops its oldest


class TagMonitoredItem(MonitoredItemData):
    """asyncua's monitored item data, with its change filter and the value it last reported."""

    def __init__(self) -> None:
        super().__init__()
        self.change_filter: ChangeFilter = NO_FILTER
        self.last_reported: ua.DataValue | None = None


class TagMonitoredItems(MonitoredItemService):
    """asyncua's monitored items with Part 4 deadbands, revised queue sizes and a short path for tags."""

    def __init__(self, isub: InternalSubscription, aspace: AddressSpace) -> None:
        super().__init__(isub, aspace)
        self._detached: list[int] = []

    def _revise_queue_size(self, requested: int) -> int:
        return revise_queue_size(requested)

    async def create_monitored_items(self, params: ua.CreateMonitoredItemsParameters) -> list[ua.MonitoredItemCreateResult]:
        # As asyncua's, yielding to the scan every slice: a SCADA subscribing to thousands of tags
        # in one request (each item is sampled at once) must not hold a cycle back.
        guard = self.isub.guard if isinstance(self.isub, TagSubscription) else None
        results: list[ua.MonitoredItemCreateResult] = []
        slice_end = time.perf_counter() + _CREATE_SLICE
        for item in params.ItemsToCreate:
            if item.ItemToMonitor.AttributeId == ua.AttributeIds.EventNotifier:
                results.append(self._create_events_monitored_item(item))
            else:
                results.append(await self._create_data_change_monitored_item(item))
            if guard is not None and time.perf_counter() > slice_end:
                await asyncio.sleep(0)
                await guard.clear()
                slice_end = time.perf_counter() + _CREATE_SLICE
        return results

    def _make_monitored_item_common(self, params: ua.MonitoredItemCreateRequest) -> tuple[ua.MonitoredItemCreateResult, MonitoredItemData]:
        # As asyncua's, with our item class.
        result = ua.MonitoredItemCreateResult()
        result.RevisedSamplingInterval = self.isub.data.RevisedPublishingInterval
        requested = params.RequestedParameters.QueueSize
        events = params.ItemToMonitor.AttributeId == ua.AttributeIds.EventNotifier
        result.RevisedQueueSize = revise_event_queue_size(requested) if events else self._revise_queue_size(requested)
        self._monitored_item_counter += 1
        result.MonitoredItemId = self._monitored_item_counter
        mdata = TagMonitoredItem()
        mdata.mode = params.MonitoringMode
        mdata.read_value_id = params.ItemToMonitor
        mdata.client_handle = params.RequestedParameters.ClientHandle
        mdata.monitored_item_id = result.MonitoredItemId
        mdata.queue_size = result.RevisedQueueSize
        mdata.filter = params.RequestedParameters.Filter
        return result, mdata

    def _create_events_monitored_item(self, params: ua.MonitoredItemCreateRequest) -> ua.MonitoredItemCreateResult:
        if not isinstance(params.RequestedParameters.Filter, ua.EventFilter):  # asyncua would fail on it (AttributeError)
            return ua.MonitoredItemCreateResult(StatusCode=ua.StatusCode(ua.StatusCodes.BadMonitoredItemFilterInvalid))
        return super()._create_events_monitored_item(params)

    async def _create_data_change_monitored_item(self, params: ua.MonitoredItemCreateRequest) -> ua.MonitoredItemCreateResult:
        item = params.ItemToMonitor
        if item.NodeId not in self.aspace:
            return ua.MonitoredItemCreateResult(StatusCode=ua.StatusCode(ua.StatusCodes.BadNodeIdUnknown))
        try:
            accepted = change_filter(self.aspace, item, params.RequestedParameters.Filter)
        except FilterRefused as refused:
            return ua.MonitoredItemCreateResult(StatusCode=ua.StatusCode(refused.code))
        result, mdata = self._make_monitored_item_common(params)
        assert isinstance(mdata, TagMonitoredItem)
        mdata.change_filter = accepted
        result.StatusCode, handle = self.aspace.add_datachange_callback(item.NodeId, item.AttributeId, self.datachange_callback)
        mdata.callback_handle = handle
        self._commit_monitored_item(result, mdata)
        if result.StatusCode.is_good():
            self._monitored_datachange[handle] = result.MonitoredItemId
            if mdata.mode != ua.MonitoringMode.Disabled:
                await self.trigger_datachange(handle, item.NodeId, item.AttributeId)
        return result

    def _modify_monitored_item(self, params: ua.MonitoredItemModifyRequest) -> ua.MonitoredItemModifyResult:
        result = ua.MonitoredItemModifyResult()
        mdata = self._monitored_items.get(params.MonitoredItemId)
        if mdata is None:
            result.StatusCode = ua.StatusCode(ua.StatusCodes.BadMonitoredItemIdInvalid)
            return result
        requested = params.RequestedParameters
        if isinstance(mdata, TagMonitoredItem) and mdata.read_value_id is not None:
            try:
                mdata.change_filter = change_filter(self.aspace, mdata.read_value_id, requested.Filter)
            except FilterRefused as refused:
                result.StatusCode = ua.StatusCode(refused.code)
                return result
        mdata.filter = requested.Filter
        mdata.client_handle = requested.ClientHandle
        mdata.queue_size = result.RevisedQueueSize = self._revise_queue_size(requested.QueueSize)
        result.RevisedSamplingInterval = self.isub.data.RevisedPublishingInterval
        return result

    async def datachange_callback(self, handle: int, value: ua.DataValue, error: ua.StatusCode | None = None) -> None:
        if error is not None:
            return await super().datachange_callback(handle, value, error)
        mid = self._monitored_datachange.get(handle)
        if mid is None:
            return  # detached meanwhile
        mdata = self._monitored_items[mid]
        if mdata.mode == ua.MonitoringMode.Disabled or not isinstance(mdata, TagMonitoredItem):
            return
        if not mdata.change_filter.reports(mdata.last_reported, value):
            return
        if type(value) is not TagDataValue:
            value = copy.deepcopy(value)  # asyncua's own values may change after this; a tag's never does
        mdata.last_reported = value
        notification = ua.MonitoredItemNotification(ClientHandle=mdata.client_handle, Value=value)
        await self.isub.enqueue_datachange_event(mid, notification, mdata.queue_size)

    def detach(self) -> None:
        """Stop receiving data changes (the items and their queued notifications stay)."""
        for handle, mid in list(self._monitored_datachange.items()):
            self.aspace.delete_datachange_callback(handle)
            self._monitored_items[mid].callback_handle = None
            self._detached.append(mid)
        self._monitored_datachange.clear()

    def attach(self) -> list[int]:
        """Receive data changes again; returns the callback handles to refresh."""
        handles = []
        for mid in self._detached:
            mdata = self._monitored_items.get(mid)
            if mdata is None or mdata.read_value_id is None:
                continue  # deleted while detached
            status, handle = self.aspace.add_datachange_callback(
                mdata.read_value_id.NodeId, mdata.read_value_id.AttributeId, self.datachange_callback)
            if status.is_good():
                mdata.callback_handle = handle
                self._monitored_datachange[handle] = mid
                handles.append(handle)
        self._detached = []
        return handles

    async def refresh(self, handles: list[int]) -> None:
        """Sample the current value of each (re-attached) item."""
        for handle in handles:
            mid = self._monitored_datachange.get(handle)
            mdata = self._monitored_items.get(mid) if mid is not None else None
            if mdata is not None and mdata.read_value_id is not None and mdata.mode != ua.MonitoringMode.Disabled:
                await self.trigger_datachange(handle, mdata.read_value_id.NodeId, mdata.read_value_id.AttributeId)
