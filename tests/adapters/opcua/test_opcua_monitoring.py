"""Monitored items against a real asyncua client: deadbands against the last reported value,
filters refused per item, queue sizes revised, and subscriptions of vanished clients that cost nothing.
One plant (real time, 10 ms task: `count` +1 per scan, `ramp` = count % 1000 with EURange 0..1000)."""

from __future__ import annotations

import asyncio
import contextlib
import logging

import pytest
import pytest_asyncio
from asyncua import ua

from softplc.adapters.opcua import subscriptions
from softplc.adapters.opcua.subscriptions import TagSubscription
from softplc.core.tags import Quality
from tests.opcua_support import client_for, running_plant, wait_until

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with running_plant(tmp_path_factory.mktemp("opcua-monitoring"), security=("None",)) as (runtime, server):
        yield runtime, server


@pytest_asyncio.fixture(loop_scope="module")
async def operator(plant):
    async with client_for(plant[1], "operator") as client:
        yield client


class Values:
    def __init__(self) -> None:
        self.by_tag: dict[str, list] = {}

    def datachange_notification(self, node, value, data) -> None:
        self.by_tag.setdefault(node.nodeid.Identifier, []).append(value)

    def of(self, tag: str) -> list:
        return self.by_tag.get(tag, [])


def _deadband(kind: ua.DeadbandType, amount: float, trigger: ua.DataChangeTrigger = ua.DataChangeTrigger.StatusValue) -> ua.DataChangeFilter:
    return ua.DataChangeFilter(Trigger=trigger, DeadbandType=kind, DeadbandValue=amount)


def _request(node_id: ua.NodeId, handle: int, flt=None, queue_size: int = 1) -> ua.MonitoredItemCreateRequest:
    return ua.MonitoredItemCreateRequest(
        ItemToMonitor=ua.ReadValueId(NodeId=node_id, AttributeId=ua.AttributeIds.Value),
        MonitoringMode=ua.MonitoringMode.Reporting,
        RequestedParameters=ua.MonitoringParameters(ClientHandle=handle, SamplingInterval=0, Filter=flt, QueueSize=queue_size,
                                                    DiscardOldest=True),
    )


async def test_absolute_and_percent_deadbands_compare_with_the_last_reported_value(plant, operator, caplog) -> None:
    # count and ramp drift by 1 per scan: compared with the previous sample (asyncua) a deadband of
    # 10 (or 1 % of 0..1000) is never exceeded; compared with the last reported value, every ~11 scans.
    _, server = plant
    caplog.set_level(logging.WARNING)
    values = Values()
    subscription = await operator.create_subscription(5, values)
    absolute = await subscription.deadband_monitor(operator.get_node(server.node_id("count")), 10, ua.DeadbandType.Absolute, queuesize=10)
    percent = await subscription.deadband_monitor(operator.get_node(server.node_id("ramp")), 1, ua.DeadbandType.Percent, queuesize=10)
    assert isinstance(absolute, int) and isinstance(percent, int)
    await wait_until(lambda: len(values.of("count")) >= 8 and len(values.of("ramp")) >= 8)
    for tag in ("count", "ramp"):
        reported = values.of(tag)
        assert all(abs(later - earlier) > 10 for earlier, later in zip(reported, reported[1:])), (tag, reported)
        # ...and not much more than the deadband apart: the drift is reported as it passes it.
        steps = [later - earlier for earlier, later in zip(reported, reported[1:]) if later > earlier]
        assert sorted(steps)[len(steps) // 2] <= 20, (tag, reported)
    await subscription.delete()
    # A percent deadband is implemented, not ignored with a warning per sample.
    assert [record.getMessage() for record in caplog.records if record.levelno >= logging.WARNING and "eadband" in record.getMessage()] == []


async def test_a_status_trigger_reports_only_quality_changes(plant, operator) -> None:
    runtime, server = plant
    values = Values()
    subscription = await operator.create_subscription(5, values)
    status_only = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.Status)
    results = await subscription.create_monitored_items([
        _request(server.node_id("f64"), 1, status_only, 10),
        _request(server.node_id("count"), 2, None, 10),  # a heartbeat: publishes keep coming
    ])
    assert all(isinstance(result, int) for result in results)
    await wait_until(lambda: len(values.of("f64")) == 1)  # the first value
    node = operator.get_node(server.node_id("f64"))
    for number in (1.5, 2.5):
        await operator.write_values([node], [ua.Variant(number, ua.VariantType.Double)])
        await wait_until(lambda number=number: runtime.db.value("f64") == number)
    heartbeat = len(values.of("count"))
    await wait_until(lambda: len(values.of("count")) > heartbeat + 10)
    assert len(values.of("f64")) == 1  # new values, same quality: nothing reported
    for quality, expected in ((Quality.UNCERTAIN, 2), (Quality.GOOD, 3)):
        runtime.db.submit_quality(["f64"], quality, "test")
        await wait_until(lambda expected=expected: len(values.of("f64")) == expected)
    await subscription.delete()


async def test_filters_that_do_not_fit_are_refused_per_item_and_the_others_keep_working(plant, operator, caplog) -> None:
    runtime, server = plant
    caplog.set_level(logging.INFO)
    values = Values()
    subscription = await operator.create_subscription(5, values)
    requests = [
        _request(server.node_id("s1"), 1, _deadband(ua.DeadbandType.Absolute, 1)),  # String
        _request(server.node_id("b1"), 2, _deadband(ua.DeadbandType.Absolute, 1)),  # Boolean
        _request(server.node_id("s1"), 3, _deadband(ua.DeadbandType.Percent, 1)),
        _request(server.node_id("f64"), 4, _deadband(ua.DeadbandType.Percent, 5)),  # no EURange
        _request(server.node_id("i16"), 5, _deadband(ua.DeadbandType.Percent, 150)),  # outside 0..100
        _request(server.node_id("count"), 6, _deadband(ua.DeadbandType.Absolute, -1)),
        _request(server.node_id("count"), 7, ua.EventFilter()),
        _request(server.node_id("s1"), 8, ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValue)),  # no deadband: fine
        _request(server.node_id("count"), 9),
        _request(ua.NodeId("no_such_tag", server.namespace_index), 10, _deadband(ua.DeadbandType.Absolute, 1)),
        ua.MonitoredItemCreateRequest(  # events of the Server object, without the EventFilter they need
            ItemToMonitor=ua.ReadValueId(NodeId=ua.NodeId(ua.ObjectIds.Server), AttributeId=ua.AttributeIds.EventNotifier),
            MonitoringMode=ua.MonitoringMode.Reporting, RequestedParameters=ua.MonitoringParameters(ClientHandle=11, QueueSize=1)),
    ]
    results = await subscription.create_monitored_items(requests)
    codes = [result.value if isinstance(result, ua.StatusCode) else "ok" for result in results]
    assert codes == [
        ua.StatusCodes.BadFilterNotAllowed, ua.StatusCodes.BadFilterNotAllowed, ua.StatusCodes.BadFilterNotAllowed,
        ua.StatusCodes.BadDeadbandFilterInvalid, ua.StatusCodes.BadDeadbandFilterInvalid, ua.StatusCodes.BadDeadbandFilterInvalid,
        ua.StatusCodes.BadFilterNotAllowed, "ok", "ok", ua.StatusCodes.BadNodeIdUnknown, ua.StatusCodes.BadMonitoredItemFilterInvalid,
    ]
    # The accepted items deliver, including after the refused ones' tags change.
    async with client_for(server, "operator") as writer:
        for text in ("first", "second"):
            await writer.write_values([writer.get_node(server.node_id("s1"))], [ua.Variant(text, ua.VariantType.String)])
            await wait_until(lambda text=text: text in values.of("s1"))
    count = len(values.of("count"))
    await wait_until(lambda: len(values.of("count")) > count + 5)
    await subscription.delete()
    # No traceback per change (asyncua logged a TypeError for each change of a string under a deadband).
    assert not [record for record in caplog.records if record.exc_info]


async def test_queue_sizes_are_revised_per_the_spec_and_capped(plant, operator) -> None:
    runtime, server = plant
    subscription = await operator.create_subscription(1000, Values())
    asked = [0, 1, 7, 100, 101, 10_000]
    params = ua.CreateMonitoredItemsParameters(
        SubscriptionId=subscription.subscription_id, TimestampsToReturn=ua.TimestampsToReturn.Both,
        ItemsToCreate=[_request(server.node_id("count"), 100 + index, None, size) for index, size in enumerate(asked)])
    results = await operator.uaclient.create_monitored_items(params)
    assert [result.RevisedQueueSize for result in results] == [1, 1, 7, 100, 100, 100]
    # Event items: 0 is the server's default, a real queue (a ConditionRefresh is a burst of events).
    events = ua.CreateMonitoredItemsParameters(
        SubscriptionId=subscription.subscription_id, TimestampsToReturn=ua.TimestampsToReturn.Both,
        ItemsToCreate=[ua.MonitoredItemCreateRequest(
            ItemToMonitor=ua.ReadValueId(NodeId=ua.NodeId(ua.ObjectIds.Server), AttributeId=ua.AttributeIds.EventNotifier),
            MonitoringMode=ua.MonitoringMode.Reporting,
            RequestedParameters=ua.MonitoringParameters(ClientHandle=200 + index, QueueSize=size, Filter=ua.EventFilter(
                SelectClauses=[ua.SimpleAttributeOperand(TypeDefinitionId=ua.NodeId(ua.ObjectIds.BaseEventType),
                                                         BrowsePath=[ua.QualifiedName("Message", 0)], AttributeId=ua.AttributeIds.Value)])))
            for index, size in enumerate((0, 5, 50_000))])
    assert [result.RevisedQueueSize for result in await operator.uaclient.create_monitored_items(events)] == [1000, 5, 10_000]
    # A queue of 3 behind a slow publishing interval keeps the 3 newest samples.
    service = server.server.iserver.subscription_service.subscriptions[subscription.subscription_id]
    ids = [result.MonitoredItemId for result in results]
    modify = ua.ModifyMonitoredItemsParameters(SubscriptionId=subscription.subscription_id, ItemsToModify=[
        ua.MonitoredItemModifyRequest(MonitoredItemId=ids[2], RequestedParameters=ua.MonitoringParameters(ClientHandle=102, QueueSize=3))])
    modified = await operator.uaclient.modify_monitored_items(modify)
    assert modified[0].StatusCode.is_good() and modified[0].RevisedQueueSize == 3

    def queued() -> list[int]:
        return [notification.Value.Value.Value for notification in service._triggered_datachanges.get(ids[2], [])]

    await wait_until(lambda: len(queued()) == 3)
    start = runtime.db.value("count")
    await wait_until(lambda: runtime.db.value("count") > start + 10)
    newest = queued()
    # Still 3, in order, and the newest ones: the oldest were dropped (unless a publish just took them).
    assert len(newest) <= 3 and newest == sorted(newest) and (not newest or newest[-1] > start)
    await subscription.delete()


async def _vanishing_subscriber(server, tag: str = "count"):
    """A viewer that subscribes to `tag` (queue 10); returns (client, its TagSubscription on the server)."""
    client = client_for(server, "viewer")
    await client.connect()
    values = Values()
    subscription = await client.create_subscription(10, values)
    await subscription.subscribe_data_change([client.get_node(server.node_id(tag))], queuesize=10)
    await wait_until(lambda: values.of(tag))
    served = server.server.iserver.subscription_service.subscriptions[subscription.subscription_id]
    assert isinstance(served, TagSubscription)
    return client, served, values


def _fed(server, served, tag: str = "count") -> bool:
    """Whether the address space feeds `tag`'s changes to a monitored item of subscription `served`."""
    callbacks = server.server.iserver.aspace[server.node_id(tag)].attributes[ua.AttributeIds.Value].datachange_callbacks
    return any(handle in callbacks for handle in served.monitored_item_srv._monitored_datachange) or \
        any(getattr(callback, "__self__", None) is served.monitored_item_srv for callback in callbacks.values())


async def _quietly_disconnect(client) -> None:
    with contextlib.suppress(Exception):  # stop the dead client's own tasks; the server hears nothing new
        await asyncio.wait_for(client.disconnect(), 2)


async def test_a_vanished_client_subscription_goes_dormant_at_once(plant) -> None:
    runtime, server = plant
    client, served, _ = await _vanishing_subscriber(server)
    assert _fed(server, served)
    client.uaclient.protocol.transport.abort()  # like a pulled cable with a TCP reset: no CloseSession
    # The session (and subscription) stay for a comeback until the session times out, but tag
    # changes no longer cost it anything, and what it had queued stays bounded by its queue size.
    await wait_until(lambda: not _fed(server, served), timeout=5)
    assert served.dormant
    assert served.session_id in {s.session_id for s in server.server.iserver.subscription_service.subscriptions.values()}
    start = runtime.tasks[0].stats.cycles
    await wait_until(lambda: runtime.tasks[0].stats.cycles > start + 30)
    assert all(len(queue) <= 10 for queue in served._triggered_datachanges.values())
    await _quietly_disconnect(client)


async def test_a_client_that_stops_asking_goes_dormant_and_wakes_when_it_asks_again(plant, monkeypatch) -> None:
    runtime, server = plant
    monkeypatch.setattr(subscriptions, "STARVED_SECONDS", 0.3)
    client, served, values = await _vanishing_subscriber(server)
    try:
        session = client.uaclient.session
        session._publish_task.cancel()  # the client hangs: its connection stays open, no more Publish requests
        await wait_until(lambda: not _fed(server, served), timeout=5)
        assert served.dormant and served in server.server.iserver.subscription_service.subscriptions.values()
        seen = len(values.of("count"))
        session.ensure_publish_loop()  # it asks again: the subscription samples and reports again
        await wait_until(lambda: not served.dormant and len(values.of("count")) > seen + 5, timeout=5)
        assert _fed(server, served)
        latest = values.of("count")[-1]
        assert abs(latest - runtime.db.value("count")) < 50  # current values, not a stale backlog
    finally:
        await client.disconnect()
    assert not _fed(server, served)


async def test_a_connection_whose_session_timed_out_while_open_is_closed(plant) -> None:
    # A frozen client (or a cable pulled without a TCP reset) leaves its connection open and silent:
    # once its session has timed out, nothing would ever close it.
    _, server = plant
    iserver = server.server.iserver
    shortest, iserver.min_session_timeout_ms = iserver.min_session_timeout_ms, 500
    client = client_for(server, "viewer")
    client.session_timeout = 1000  # ms
    try:
        await client.connect()
        subscription = await client.create_subscription(10, Values())
        await subscription.subscribe_data_change([client.get_node(server.node_id("count"))])
        port = client.uaclient.protocol.transport.get_extra_info("sockname")[1]

        def held() -> bool:
            return any(getattr(protocol, "peer_name", (None, None))[1] == port for protocol in server.server.bserver.clients)

        assert held()
        for task in (client._supervisor_task, client._stale_watchdog_task, client._renew_channel_task,
                     client.uaclient.session._publish_task):
            if task is not None:
                task.cancel()  # the client freezes; its socket stays open
        await wait_until(lambda: not held(), timeout=5)
    finally:
        iserver.min_session_timeout_ms = shortest
        await _quietly_disconnect(client)
