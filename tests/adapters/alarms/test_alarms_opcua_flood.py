"""OPC UA alarm events in a flood: every event, or an EventQueueOverflow event where some were left out (Part 4, 5.12.1.5).

An asyncua client subscribes to the Server object's alarm events (OfType AlarmConditionType);
twelve alarms activate at one scan boundary. A queue too small for them, or a backlog longer than
the server delivers, must end in an overflow event at the place where events were left out —
never a silent loss — and ConditionRefresh must then show all twelve.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any

from asyncua import Client, ua

from tests.alarms_support import DRIVER, plant, running_alarm_plant
from tests.opcua_support import PASSWORDS

VALVES = [f"v{index:02d}" for index in range(1, 13)]
HEAD = f"""
version: 1
templates:
  valve:
    instances: [{", ".join(VALVES)}]
    tags:
      fault: {{type: bool}}
tasks:
  scan:
    interval: 100ms
"""
ALARMS = 'definitions:\n  - {name: "{valve}_fault", for_each: valve, discrete: {tag: "{valve}_fault", value: true}}'
OVERFLOW = ua.NodeId(ua.ObjectIds.EventQueueOverflowEventType)


class Events:
    def __init__(self) -> None:
        self.seen: list[dict[str, Any]] = []

    def event_notification(self, event: Any) -> None:
        self.seen.append({name: variant.Value for name, variant in event.get_event_props_as_fields_dict().items()})

    def kinds(self) -> list[str]:
        return ["overflow" if fields["EventType"] == OVERFLOW else fields["ConditionName"] for fields in self.seen]


async def _until(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "not within the timeout"
        await asyncio.sleep(0.01)


async def _subscribe(connection: Client, events: Events, *, queue_size: int, publishing: bool = True) -> Any:
    subscription = await connection.create_subscription(50, events, publishing=publishing)
    alarm_type = connection.get_node(ua.NodeId(ua.ObjectIds.AlarmConditionType))
    await subscription.subscribe_events(connection.nodes.server, [alarm_type], queuesize=queue_size)
    return subscription


async def _refresh(connection: Client, subscription: Any, events: Events) -> set[str]:
    events.seen.clear()
    refresh = ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh)
    await connection.get_node(ua.NodeId(ua.ObjectIds.ConditionType)).call_method(
        refresh, ua.Variant(subscription.subscription_id, ua.VariantType.UInt32))
    await _until(lambda: len([kind for kind in events.kinds() if kind.endswith("_fault")]) == len(VALVES))
    return {fields["ConditionName"] for fields in events.seen if fields.get("ActiveState/Id")}


def _client(server: Any) -> Client:
    connection = Client(server.endpoint, timeout=4)
    connection.set_user("viewer")
    connection.set_password(PASSWORDS["viewer"])
    return connection


async def test_a_full_event_queue_ends_in_an_overflow_event_where_events_were_left_out(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS, head=HEAD)) as (runtime, server):
        async with _client(server) as connection:
            events = Events()
            # Not published until the twelve events of one boundary have met a queue of five.
            subscription = await _subscribe(connection, events, queue_size=5, publishing=False)
            runtime.db.submit([(f"{valve}_fault", True) for valve in VALVES], DRIVER)
            delivery = server.conditions.delivery
            await _until(lambda: delivery.overflows == 1 and not delivery.queue)
            await subscription.set_publishing_mode(True)
            await _until(lambda: len(events.seen) >= 5)
            await asyncio.sleep(0.3)  # nothing more comes
            assert events.kinds() == ["v01_fault", "v02_fault", "v03_fault", "v04_fault", "overflow"]
            overflow = events.seen[-1]
            assert overflow["SourceNode"] == ua.NodeId(ua.ObjectIds.Server) and overflow["SourceName"] == "Internal/EventQueueOverflow"
            assert "ConditionRefresh" in overflow["Message"].Text
            # Once published the queue takes events again; a refresh (into a queue that holds them) shows every condition.
            runtime.db.submit([("v01_fault", False)], DRIVER)
            await _until(lambda: len(events.seen) >= 6)
            assert events.kinds()[5] == "v01_fault" and events.seen[5]["ActiveState/Id"] is False
            fresh = Events()
            roomy = await _subscribe(connection, fresh, queue_size=0)
            assert await _refresh(connection, roomy, fresh) == {f"{valve}_fault" for valve in VALVES[1:]}
            await subscription.delete()


async def test_a_backlog_the_server_cannot_deliver_is_coalesced_with_an_overflow_event(tmp_path) -> None:
    async with running_alarm_plant(tmp_path, plant(ALARMS, head=HEAD)) as (runtime, server):
        assert server.conditions is not None and server.conditions.delivery is not None
        server.conditions.delivery.max_backlog = 3  # as if the twelve came faster than the slices deliver them
        async with _client(server) as connection:
            events = Events()
            subscription = await _subscribe(connection, events, queue_size=0)
            runtime.db.submit([(f"{valve}_fault", True) for valve in VALVES], DRIVER)
            await _until(lambda: len(events.seen) >= 4)
            await asyncio.sleep(0.3)
            assert events.kinds() == ["overflow", "v10_fault", "v11_fault", "v12_fault"]
            assert server.conditions.delivery.coalesced == 9
            assert await _refresh(connection, subscription, events) == {f"{valve}_fault" for valve in VALVES}
