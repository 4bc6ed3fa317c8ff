"""Server services against a real asyncua client: ServerStatus/CurrentTime, HistoryRead (with and
without a history provider) and Call, with the statuses of OPC UA Part 4."""

from __future__ import annotations

import asyncio
import logging
import struct
import time
from datetime import datetime, timedelta, timezone

import pytest
import pytest_asyncio
from asyncua import ua

from softplc.adapters.opcua.history import HistoryPage, Sample
from softplc.core.clock import SimClock
from softplc.core.tags import Quality
from tests.opcua_support import client_for, running_plant, wait_until

pytestmark = pytest.mark.asyncio(loop_scope="module")

CURRENT_TIME = ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime)
SERVER_STATUS = ua.NodeId(ua.ObjectIds.Server_ServerStatus)


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with running_plant(tmp_path_factory.mktemp("opcua-services"), security=("None",)) as (runtime, server):
        yield runtime, server


@pytest_asyncio.fixture(loop_scope="module")
async def viewer(plant):
    async with client_for(plant[1], "viewer") as client:
        yield client


# -- Server/ServerStatus/CurrentTime ----------------------------------------------------------

async def test_current_time_tells_the_time_on_every_read(plant, viewer) -> None:
    node = viewer.get_node(CURRENT_TIME)
    first = await node.read_data_value()
    assert first.Value.VariantType == ua.VariantType.DateTime  # not Null
    assert abs(first.Value.Value.timestamp() - datetime.now(timezone.utc).timestamp()) < 2

    async def advanced() -> bool:
        return (await node.read_value()) - first.Value.Value >= timedelta(seconds=1)

    await wait_until(advanced, timeout=5, interval=0.1)
    # The ServerStatus structure too: its CurrentTime moves, and never precedes StartTime.
    status = viewer.get_node(SERVER_STATUS)
    before = await status.read_value()
    assert before.CurrentTime >= before.StartTime

    async def status_advanced() -> bool:
        return (await status.read_value()).CurrentTime > before.CurrentTime

    await wait_until(status_advanced, timeout=2, interval=0.05)
    assert await viewer.get_node(ua.NodeId(ua.ObjectIds.Server_ServerStatus_StartTime)).read_value() == before.StartTime


async def test_a_watchdog_subscribed_to_current_time_sees_it_advance(plant, viewer) -> None:
    seen: list[datetime] = []

    class Handler:
        def datachange_notification(self, node, value, data) -> None:
            seen.append(value)

    subscription = await viewer.create_subscription(50, Handler())
    await subscription.subscribe_data_change([viewer.get_node(CURRENT_TIME)])
    await wait_until(lambda: len(seen) >= 3, timeout=5)
    # The value when the item was created, then one a second.
    assert seen == sorted(seen) and seen[-1] - seen[-2] >= timedelta(seconds=0.99)
    await subscription.delete()


async def test_under_a_simulated_clock_current_time_is_the_simulated_time_of_the_tags(tmp_path) -> None:
    clock = SimClock(speed=20)  # 20 simulated seconds per real second
    async with running_plant(tmp_path, security=("None",), clock=clock) as (runtime, server):
        async with client_for(server, "viewer") as client:
            await wait_until(lambda: clock.now() > 1)
            count = await client.get_node(server.node_id("count")).read_data_value()
            now = await client.get_node(CURRENT_TIME).read_value()
            status = await client.get_node(SERVER_STATUS).read_value()
    start = datetime.fromtimestamp(clock.wall() - clock.now(), timezone.utc)  # the simulation's epoch
    assert start <= status.StartTime <= status.CurrentTime
    assert count.SourceTimestamp <= now <= datetime.fromtimestamp(clock.wall(), timezone.utc)
    assert now - start < timedelta(hours=1)  # simulated time, not today's date


async def test_under_a_racing_simulated_clock_the_address_space_follows_in_real_time_not_every_change(tmp_path) -> None:
    clock = SimClock()  # as fast as possible: the 10 ms task runs thousands of cycles a second
    async with running_plant(tmp_path, security=("None",), clock=clock) as (runtime, server):
        aspace = server.server.iserver.aspace
        count = server.node_id("count")
        await wait_until(lambda: clock.now() > 20)
        publisher = server.publisher
        pushed, started = publisher.pushed, time.perf_counter()
        cycles_before = runtime.db.value("count")
        await asyncio.sleep(0.5)
        seen = runtime.db.value("count")
        await asyncio.sleep(0.1)  # more than the pace: the latest value has been pushed since
        shown = aspace.read_attribute_value(count, ua.AttributeIds.Value).Value.Value
        elapsed = time.perf_counter() - started
        pushes = publisher.pushed - pushed
        cycles = runtime.db.value("count") - cycles_before
    assert shown >= seen  # never more than one period behind
    # Every cycle changes count and ramp; pushed at every change that is two values a cycle.
    # Paced by real time (a push per period of the changes gathered), it is a few per period.
    assert cycles > 500, f"only {cycles} cycles in {elapsed:.2f} s: the clock did not race"
    assert pushes * 10 < cycles, f"{pushes} values pushed for {cycles} cycles in {elapsed:.2f} s"


# -- HistoryRead -------------------------------------------------------------------------------

NOT_GIVEN = datetime(1601, 1, 1, tzinfo=timezone.utc)  # the minimum DateTime: a bound left open


def _raw(start: datetime = NOT_GIVEN, end: datetime = NOT_GIVEN, count: int = 0) -> ua.ReadRawModifiedDetails:
    return ua.ReadRawModifiedDetails(IsReadModified=False, StartTime=start, EndTime=end, NumValuesPerNode=count, ReturnBounds=False)


def _history(details, *node_ids: ua.NodeId, points: list[bytes] | None = None, release: bool = False,
             timestamps: ua.TimestampsToReturn = ua.TimestampsToReturn.Both) -> ua.HistoryReadParameters:
    points = points or [b""] * len(node_ids)
    return ua.HistoryReadParameters(
        HistoryReadDetails=details, TimestampsToReturn=timestamps, ReleaseContinuationPoints=release,
        NodesToRead=[ua.HistoryReadValueId(NodeId=node_id, ContinuationPoint=point) for node_id, point in zip(node_ids, points)])


async def test_history_read_says_which_nodes_have_no_history_without_logging(plant, viewer, caplog) -> None:
    _, server = plant
    caplog.set_level(logging.INFO)
    nodes = [ua.NodeId("no_such_tag", server.namespace_index), server.node_id("count"), ua.NodeId("/Plant", server.namespace_index),
             ua.NodeId(ua.ObjectIds.Server)]
    for _ in range(3):
        results = await viewer.uaclient.history_read(_history(_raw(datetime.now(timezone.utc) - timedelta(hours=1)), *nodes))
        assert [result.StatusCode.value for result in results] == [
            ua.StatusCodes.BadNodeIdUnknown, ua.StatusCodes.BadHistoryOperationUnsupported,
            ua.StatusCodes.BadHistoryOperationUnsupported, ua.StatusCodes.BadHistoryOperationUnsupported]
    assert [record.getMessage() for record in caplog.records if record.levelno >= logging.WARNING] == []
    assert await viewer.get_node(server.node_id("count")).read_attribute(ua.AttributeIds.Historizing) is not None
    assert (await viewer.get_node(server.node_id("count")).read_attribute(ua.AttributeIds.AccessLevel)).Value.Value & 4 == 0


class ListHistory:
    """A HistoryProvider over a list (what a historian adapter implements for real): `count` has history."""

    def __init__(self, samples: list[Sample]) -> None:
        self.samples = samples

    def historized(self, tag: str) -> bool:
        return tag == "count"

    async def read_raw(self, tag: str, start: float | None, end: float | None, limit: int, resume: bytes | None) -> HistoryPage:
        chosen = [s for s in self.samples if (start is None or s.time >= start) and (end is None or s.time <= end)]
        offset = 0
        if resume is not None:
            if len(resume) != 4:
                raise ValueError("not one of ours")
            offset = struct.unpack("<I", resume)[0]
        page = chosen[offset:offset + limit] if limit else chosen[offset:]
        more = limit and offset + limit < len(chosen)
        return HistoryPage(page, struct.pack("<I", offset + limit) if more else None)


async def test_a_history_provider_serves_raw_reads_page_by_page(tmp_path) -> None:
    origin = datetime(2026, 1, 1, tzinfo=timezone.utc)
    samples = [Sample(origin.timestamp() + i, i, Quality.GOOD if i != 3 else Quality.UNCERTAIN) for i in range(7)]
    async with running_plant(tmp_path, security=("None",), history=ListHistory(samples)) as (_, server):
        async with client_for(server, "viewer") as client:
            count = server.node_id("count")
            node = client.get_node(count)
            assert (await node.read_attribute(ua.AttributeIds.AccessLevel)).Value.Value & 4  # HistoryRead
            assert (await node.read_attribute(ua.AttributeIds.Historizing)).Value.Value is True
            assert (await client.get_node(server.node_id("i32")).read_attribute(ua.AttributeIds.Historizing)).Value.Value is False
            details = _raw(origin, origin + timedelta(hours=1), 3)
            pages, point = [], b""
            while True:
                result = (await client.uaclient.history_read(_history(details, count, points=[point])))[0]
                assert result.StatusCode.is_good()
                pages.append([(v.Value.Value, v.SourceTimestamp, v.StatusCode.value) for v in result.HistoryData.DataValues])
                point = result.ContinuationPoint
                if not point:
                    break
            assert [len(page) for page in pages] == [3, 3, 1]
            values = [entry for page in pages for entry in page]
            assert [value for value, _, _ in values] == list(range(7))
            assert values[1][1] == origin + timedelta(seconds=1) and values[3][2] == ua.StatusCodes.Uncertain
            everything = (await client.uaclient.history_read(_history(_raw(origin), count)))[0]  # end left open, no limit
            assert len(everything.HistoryData.DataValues) == 7 and not everything.ContinuationPoint
            # Server timestamps only; a released point; a point that is not ours; kinds of read not offered.
            result = (await client.uaclient.history_read(_history(details, count, timestamps=ua.TimestampsToReturn.Server)))[0]
            assert result.HistoryData.DataValues[0].SourceTimestamp is None and result.HistoryData.DataValues[0].ServerTimestamp
            first = (await client.uaclient.history_read(_history(details, count)))[0]
            released = (await client.uaclient.history_read(_history(details, count, points=[first.ContinuationPoint], release=True)))[0]
            assert released.StatusCode.is_good() and not released.HistoryData.DataValues
            for bogus in (b"made-up", first.ContinuationPoint + b"x"):
                refused = (await client.uaclient.history_read(_history(details, count, points=[bogus])))[0]
                assert refused.StatusCode.value == ua.StatusCodes.BadContinuationPointInvalid
            processed = ua.ReadProcessedDetails(StartTime=origin, EndTime=origin + timedelta(hours=1), ProcessingInterval=1000)
            at_time = ua.ReadAtTimeDetails(ReqTimes=[origin])
            for other in (processed, at_time, ua.ReadRawModifiedDetails(IsReadModified=True, StartTime=origin)):
                result = (await client.uaclient.history_read(_history(other, count)))[0]
                assert result.StatusCode.value == ua.StatusCodes.BadHistoryOperationUnsupported
            with pytest.raises(ua.UaStatusCodeError) as neither:
                await client.uaclient.history_read(_history(details, count, timestamps=ua.TimestampsToReturn.Neither))
            assert neither.value.code == ua.StatusCodes.BadTimestampsToReturnInvalid


# -- Call ----------------------------------------------------------------------------------------

async def test_calls_that_cannot_be_made_get_the_spec_statuses(plant, viewer) -> None:
    _, server = plant
    server_object = ua.NodeId(ua.ObjectIds.Server)
    get_monitored_items = ua.NodeId(ua.ObjectIds.Server_GetMonitoredItems)
    calls = [
        ua.CallMethodRequest(ObjectId=server_object, MethodId=ua.NodeId("no_such_method", server.namespace_index)),
        ua.CallMethodRequest(ObjectId=ua.NodeId("no_such_object", server.namespace_index), MethodId=get_monitored_items),
        ua.CallMethodRequest(ObjectId=server_object, MethodId=server.node_id("count")),  # a Variable, not a Method
        ua.CallMethodRequest(ObjectId=server_object, MethodId=ua.NodeId(ua.ObjectIds.Server_ResendData),  # not implemented
                             InputArguments=[ua.Variant(1, ua.VariantType.UInt32)]),
    ]
    results = await viewer.uaclient.call(calls)
    assert [result.StatusCode.value for result in results] == [
        ua.StatusCodes.BadMethodInvalid, ua.StatusCodes.BadNodeIdUnknown, ua.StatusCodes.BadMethodInvalid,
        ua.StatusCodes.BadNotImplemented]
