"""Alarm events to OPC UA subscribers: off the scan, in paced slices; every event, or an overflow event where some were left out.

The alarm engine publishes each transition inside the scan; `conditions.py` only queues it
here. A task of its own delivers the queue:

- in slices of at most `SLICE` seconds of work, each started when no scan cycle is due
  (`ScanGuard`) and followed by a rest, so that while events wait the delivery takes at most
  `DUTY` of the event loop: the scan, reads and writes go on through an alarm flood;
- every event is *noted* (the condition's latest state, cheap); the condition's event object is
  filled, and an EventFieldList made, only for the event monitored items that watch one of its
  notifiers (the Server object, the tag's folder) and pass their where clause — nobody
  subscribed, nothing is encoded. The field lists are made without asyncua's deep copy of every
  field (`fill` gives a changed field a new object; it never changes one in place), and a field
  that did not change keeps its Variant;
- a monitored item whose queue is full (its client publishes less often than events come) gets
  one EventQueueOverflowEventType event (OPC UA Part 4, 5.12.1.5: SourceNode the Server object,
  SourceName "Internal/EventQueueOverflow"; it bypasses the where clause) in the queue's last
  place, and no events until its queue has been published — the newest events are left out
  (as DiscardOldest = false would; the queue never drops what it holds);
- events that come faster than the slices deliver them (more than `max_backlog` waiting) are
  coalesced: the oldest are only noted, not delivered, and every event monitored item gets an
  overflow event where they were left out.

After an overflow event, a client that wants the current state calls ConditionRefresh: the
conditions follow every event, delivered or not, so the refresh shows the truth.
"""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from collections import deque
from collections.abc import Iterable
from datetime import datetime, timezone
from typing import Any

from asyncua import ua
from asyncua.common import event_objects

from softplc.adapters.opcua.condition_events import fill, fix_types, note
from softplc.core.events import Event

log = logging.getLogger(__name__)

SLICE = 0.002  # seconds of delivery between two turns of the event loop
DUTY = 0.3  # the most of the loop's time the delivery takes while events wait
MAX_BACKLOG = 2_000  # events waiting beyond this are coalesced (about a second of delivery to one client)
OVERFLOW_SOURCE = "Internal/EventQueueOverflow"
_SERVER = ua.NodeId(ua.ObjectIds.Server)
_TYPE_ONLY = frozenset({ua.FilterOperator.OfType, ua.FilterOperator.And, ua.FilterOperator.Or, ua.FilterOperator.Not})

Target = tuple[Any, int, Any]  # (subscription, monitored item id, its MonitoredItemData)


class ConditionDelivery:
    """Delivers the queued alarm events of `conditions` (name → condition) to the server's event subscribers."""

    def __init__(self, server: Any, conditions: dict[str, Any], shelve_max: float) -> None:
        self.service = server.iserver.subscription_service
        self.aspace = server.iserver.aspace
        self.guard = getattr(self.service, "guard", None)  # softplc's subscription service has one
        self.conditions = conditions
        self.shelve_max = shelve_max
        self.max_backlog = MAX_BACKLOG
        self.queue: deque[Event] = deque()
        self._wake = asyncio.Event()
        self._names: dict[int, tuple[Any, list[str]]] = {}  # id(EventFilter) → (it, the attribute name of each select clause)
        self._types: dict[tuple[int, str], bool] = {}  # (id(where clause evaluator), condition) → passes; for OfType-only clauses
        self._variants: dict[tuple[int, str], tuple[Any, ua.Variant]] = {}  # (id(event object), field) → (value, its Variant)
        self._overflowed: dict[tuple[int, int], Any] = {}  # (subscription, item) → the last overflow event queued for it
        self.delivered = 0  # EventFieldLists queued for clients (diagnostics)
        self.coalesced = 0  # events noted but not delivered because of a backlog
        self.overflows = 0  # overflow events queued

    def put(self, event: Event) -> None:
        """Queue an `alarm` event (called inside the scan: nothing more)."""
        self.queue.append(event)
        self._wake.set()

    async def run(self) -> None:
        """Deliver the queue for ever, in paced slices (see the module docstring)."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            while self.queue:
                if self.guard is not None:
                    await self.guard.clear()
                started = time.perf_counter()
                await self.deliver_slice(started + SLICE)
                # Pacing CPU share, hence real time (like ScanGuard), not the runtime clock.
                await asyncio.sleep((time.perf_counter() - started) * (1.0 - DUTY) / DUTY if self.queue else 0)

    async def deliver_slice(self, deadline: float) -> None:
        """Deliver queued events until `deadline` (perf_counter seconds) or the queue is empty."""
        targets = self._targets()
        queue = self.queue
        if len(queue) > self.max_backlog:
            for _ in range(len(queue) - self.max_backlog):
                self._note(queue.popleft())
                self.coalesced += 1
            for node_targets in targets.values():
                for target in node_targets:
                    await self._overflow(target)
        while queue:
            event = queue.popleft()
            try:
                await self._deliver(event, targets)
            except Exception:  # one bad event must not end the alarm events of the server
                log.exception("OPC UA: cannot deliver the alarm event of %s", event.source)
            if time.perf_counter() > deadline:
                break

    def _note(self, event: Event) -> Any:
        condition = self.conditions.get(event.source)
        if condition is not None:
            note(condition, event)
        return condition

    async def _deliver(self, event: Event, targets: dict[Any, list[Target]]) -> None:
        condition = self._note(event)
        if condition is None:
            return
        for node in condition.emitting:
            node_targets = targets.get(node)
            if not node_targets:
                continue
            condition.event.emitting_node = node
            for target in node_targets:
                await self.offer(condition, target)

    async def offer(self, condition: Any, target: Target) -> bool:
        """Queue the condition's latest event for one monitored item if it passes its filter (an overflow event if its queue is full)."""
        subscription, mid, item = target
        if not self._passes(item, condition):
            return False
        queue = subscription._triggered_events.get(mid)  # asyncua 2.1 (pinned): the item's queue until published
        if queue is not None and item.queue_size and len(queue) >= item.queue_size - 1:
            await self._overflow(target)  # the last place: an overflow event, once; the newest events are left out
            return False
        fill(condition, self.shelve_max)
        await self._enqueue(subscription, mid, item, self._fields(condition.event, item))
        self.delivered += 1
        return True

    def _passes(self, item: Any, condition: Any) -> bool:
        evaluator = item.where_clause_evaluator
        if evaluator is None or item.mode == ua.MonitoringMode.Disabled:
            return False
        if not evaluator.elements:
            return True
        key = (id(evaluator), condition.name)
        known = self._types.get(key)
        if known is not None:
            return known
        fill(condition, self.shelve_max)  # the clause may read any field
        passes = bool(evaluator.eval(condition.event))
        if all(element.FilterOperator in _TYPE_ONLY for element in evaluator.elements):
            self._types[key] = passes  # a condition's EventType never changes
        return passes

    def _fields(self, event: Any, item: Any) -> list[ua.Variant]:
        """The item's select clauses of `event` (as asyncua's Event.to_event_fields, without the deep copies)."""
        names = self._select_names(item.filter)
        variants = self._variants
        data_types = event.data_types
        fields: list[ua.Variant] = []
        for name in names:
            value = getattr(event, name, None)
            if value is None:
                fields.append(ua.Variant(None))
                continue
            key = (id(event), name)
            known = variants.get(key)
            if known is None or known[0] is not value:
                known = (value, ua.Variant(value, data_types[name]))
                variants[key] = known
            fields.append(known[1])
        return fields

    def _select_names(self, event_filter: Any) -> list[str]:
        known = self._names.get(id(event_filter))
        if known is not None and known[0] is event_filter:
            return known[1]
        names = []
        for clause in event_filter.SelectClauses:
            if not clause.BrowsePath:
                names.append(ua.AttributeIds(clause.AttributeId).name)
            else:
                names.append("/".join(element.Name for element in clause.BrowsePath))
        self._names[id(event_filter)] = (event_filter, names)
        return names

    async def _enqueue(self, subscription: Any, mid: int, item: Any, fields: list[ua.Variant]) -> None:
        await subscription.enqueue_event(mid, ua.EventFieldList(ClientHandle=item.client_handle, EventFields=fields), item.queue_size)

    async def _overflow(self, target: Target) -> None:
        """Put an EventQueueOverflow event at the end of the item's queue, unless one is there already."""
        subscription, mid, item = target
        key = (subscription.data.SubscriptionId, mid)
        queue = subscription._triggered_events.get(mid)
        marker = self._overflowed.get(key)
        if queue and marker is not None and queue[-1] is marker:
            return
        overflow = event_objects.EventQueueOverflowEvent(sourcenode=_SERVER)
        fix_types(overflow)
        overflow.EventId = uuid.uuid4().bytes
        overflow.SourceName = OVERFLOW_SOURCE
        overflow.Time = overflow.ReceiveTime = datetime.now(timezone.utc)
        overflow.Message = ua.LocalizedText("alarm events were left out: the client did not keep up (call ConditionRefresh for the current state)")
        fields = [ua.Variant(getattr(overflow, name, None), overflow.data_types[name]) if getattr(overflow, name, None) is not None
                  else ua.Variant(None) for name in self._select_names(item.filter)]
        if queue is not None and item.queue_size and len(queue) >= item.queue_size:
            queue.pop()  # the newest gives way: the overflow event marks where events were left out
        marker = ua.EventFieldList(ClientHandle=item.client_handle, EventFields=fields)
        await subscription.enqueue_event(mid, marker, item.queue_size)
        self._overflowed[key] = marker
        self.overflows += 1

    def _targets(self) -> dict[Any, list[Target]]:
        """Every event monitored item of every subscription, by the notifier it watches."""
        targets: dict[Any, list[Target]] = {}
        live = set()
        for subscription in list(self.service.subscriptions.values()):
            items = subscription.monitored_item_srv
            for node, mids in items._monitored_events.items():  # asyncua 2.1 (pinned)
                for mid in mids:
                    item = items._monitored_items.get(mid)
                    if item is not None:
                        targets.setdefault(node, []).append((subscription, mid, item))
                        live.add((subscription.data.SubscriptionId, mid))
        for key in [key for key in self._overflowed if key not in live]:
            del self._overflowed[key]
        return targets

    def targets_of(self, subscription: Any, monitored_item: int | None) -> Iterable[tuple[Any, Target]]:
        """(notifier, target) of one subscription's event monitored items (or only `monitored_item`)."""
        items = subscription.monitored_item_srv
        for node, mids in items._monitored_events.items():
            for mid in mids:
                item = items._monitored_items.get(mid)
                if item is not None and (monitored_item is None or mid == monitored_item):
                    yield node, (subscription, mid, item)
