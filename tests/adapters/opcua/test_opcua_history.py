"""OPC UA HistoryRead over the historian (issue 16), with a real asyncua client, on a plant recorded on the simulated
clock (tests/opcua_history_support.py): raw with bounds and continuation points, processed (Part 13), at time,
the statuses of Part 4/11/13, and the capabilities a client discovers."""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

import pytest
import pytest_asyncio
from asyncua import ua

from tests.opcua_history_support import EPOCH, recorded_plant
from tests.opcua_support import client_for

pytestmark = pytest.mark.asyncio(loop_scope="module")

S = ua.StatusCodes
GOOD, CALC, INTERP = 0, 0x401, 0x402  # Good; Good + HistorianCalculated; Good + HistorianInterpolated
SUB = S.UncertainDataSubNormal
NOT_GIVEN = datetime(1601, 1, 1, tzinfo=timezone.utc)
F = ua.ObjectIds


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with recorded_plant(tmp_path_factory.mktemp("opcua-history")) as (runtime, server):
        yield runtime, server


@pytest_asyncio.fixture(loop_scope="module")
async def client(plant):
    async with client_for(plant[1], "viewer") as connected:
        yield connected


def at(seconds: float) -> datetime:
    return datetime.fromtimestamp(EPOCH + seconds, timezone.utc)


def raw(start: datetime = NOT_GIVEN, end: datetime = NOT_GIVEN, count: int = 0, bounds: bool = False) -> ua.ReadRawModifiedDetails:
    return ua.ReadRawModifiedDetails(IsReadModified=False, StartTime=start, EndTime=end, NumValuesPerNode=count, ReturnBounds=bounds)


def processed(start: float, end: float, interval_s: float, *aggregates: int, config: ua.AggregateConfiguration | None = None) -> ua.ReadProcessedDetails:
    return ua.ReadProcessedDetails(StartTime=at(start), EndTime=at(end), ProcessingInterval=interval_s * 1000,
                                   AggregateType=[ua.NodeId(a) for a in aggregates],
                                   AggregateConfiguration=config or ua.AggregateConfiguration(UseServerCapabilitiesDefaults=True))


async def read(client, server, details, *tags: str, points: list[bytes] | None = None, release: bool = False) -> list[ua.HistoryReadResult]:
    nodes = [server.node_id(tag) if isinstance(tag, str) else tag for tag in tags]
    points = points or [b""] * len(nodes)
    params = ua.HistoryReadParameters(
        HistoryReadDetails=details, TimestampsToReturn=ua.TimestampsToReturn.Both, ReleaseContinuationPoints=release,
        NodesToRead=[ua.HistoryReadValueId(NodeId=node, ContinuationPoint=point) for node, point in zip(nodes, points)])
    return await client.uaclient.history_read(params)


def seen(result: ua.HistoryReadResult) -> list[tuple[float, Any, int]]:
    """(seconds of the source timestamp, value, StatusCode) of each value."""
    rows = []
    for value in result.HistoryData.DataValues:
        number = value.Value.Value
        rows.append(((value.SourceTimestamp.replace(tzinfo=timezone.utc).timestamp() - EPOCH),
                     round(number, 6) if isinstance(number, float) else number, value.StatusCode.value))
    return rows


async def test_historized_tags_say_so_and_the_server_advertises_its_history_capabilities(plant, client) -> None:
    _, server = plant
    for tag in ("level", "steps", "pressure", "note"):
        node = client.get_node(server.node_id(tag))
        assert (await node.read_attribute(ua.AttributeIds.Historizing)).Value.Value is True
        assert (await node.read_attribute(ua.AttributeIds.AccessLevel)).Value.Value & ua.AccessLevel.HistoryRead.mask
        assert (await node.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value & ua.AccessLevel.HistoryRead.mask
    spare = client.get_node(server.node_id("spare"))
    assert (await spare.read_attribute(ua.AttributeIds.Historizing)).Value.Value is False
    assert not (await spare.read_attribute(ua.AttributeIds.AccessLevel)).Value.Value & ua.AccessLevel.HistoryRead.mask
    offered = {"Interpolative", "Average", "TimeAverage2", "Minimum", "Maximum", "MinimumActualTime", "MaximumActualTime", "Count"}
    for folder in (F.Server_ServerCapabilities_AggregateFunctions, F.HistoryServerCapabilities_AggregateFunctions):
        children = await client.get_node(ua.NodeId(folder)).get_children(refs=ua.ObjectIds.Organizes)
        assert {(await child.read_browse_name()).Name for child in children} == offered
    capability = lambda node: client.get_node(ua.NodeId(node)).read_value()  # noqa: E731
    assert await capability(F.HistoryServerCapabilities_AccessHistoryDataCapability) is True
    assert await capability(F.HistoryServerCapabilities_AccessHistoryEventsCapability) is False
    assert await capability(F.HistoryServerCapabilities_InsertDataCapability) is False
    assert await capability(F.HistoryServerCapabilities_MaxReturnDataValues) == 1000
    assert await capability(F.Server_ServerCapabilities_OperationLimits_MaxNodesPerHistoryReadData) == 1000


async def test_raw_reads_with_bounds_continuation_points_and_either_direction(plant, client) -> None:
    _, server = plant
    pages, point = [], b""
    while True:  # [0.5, 10.5) holds 1..10; the bounds are 0 (before start) and 11 (after end); 4 values a page
        (result,) = await read(client, server, raw(at(0.5), at(10.5), 4, bounds=True), "level", points=[point])
        assert result.StatusCode.is_good()
        pages.append(seen(result))
        point = result.ContinuationPoint
        if not point:
            break
    assert [[t for t, _, _ in page] for page in pages] == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]]
    assert all(value == t and status == GOOD for page in pages for t, value, status in page)
    (backwards,) = await read(client, server, raw(at(5), at(0)), "level")
    assert [t for t, _, _ in seen(backwards)] == [5, 4, 3, 2, 1]  # start included, end not, newest first
    (first,) = await read(client, server, raw(end=at(5), count=3), "level")  # only an end: backwards from it
    (rest,) = await read(client, server, raw(end=at(5), count=3), "level", points=[first.ContinuationPoint])
    assert [t for t, _, _ in seen(first) + seen(rest)] == [5, 4, 3, 2, 1, 0] and not rest.ContinuationPoint
    (everything,) = await read(client, server, raw(at(0), at(60)), "level")
    assert len(everything.HistoryData.DataValues) == 41 and not everything.ContinuationPoint
    (qualities,) = await read(client, server, raw(at(0), at(60)), "pressure")
    assert seen(qualities) == [(0, 0.0, GOOD), (10, 10.0, GOOD), (20, 5.0, S.Bad), (30, 30.0, GOOD), (40, 20.0, S.Uncertain), (50, 50.0, GOOD)]
    (missing,) = await read(client, server, raw(at(-20), at(-10), bounds=True), "level")  # before the history began
    assert seen(missing) == [(-20, None, S.BadBoundNotFound), (0, 0.0, GOOD)]  # the end bound: the first value after
    (empty,) = await read(client, server, raw(at(100), at(200)), "level")
    assert empty.StatusCode.value == S.GoodNoData and not empty.HistoryData.DataValues


async def test_continuation_points_are_checked_and_released(plant, client) -> None:
    _, server = plant
    (first,) = await read(client, server, raw(at(0), at(60), 5), "level")
    point = first.ContinuationPoint
    for bogus, tag in ((b"made-up", "level"), (point[:-5], "level"), (point, "steps")):  # truncated; another tag's
        (refused,) = await read(client, server, raw(at(0), at(60), 5), tag, points=[bogus])
        assert refused.StatusCode.value == S.BadContinuationPointInvalid, (bogus, tag)
    (released,) = await read(client, server, raw(at(0), at(60), 5), "level", points=[point], release=True)
    assert released.StatusCode.is_good() and not released.HistoryData.DataValues


async def test_processed_reads_follow_part_13(plant, client) -> None:
    _, server = plant
    average, time_average, minimum, maximum, maximum_at, count = await read(
        client, server, processed(0, 20, 10, F.AggregateFunction_Average, F.AggregateFunction_TimeAverage2, F.AggregateFunction_Minimum,
                                  F.AggregateFunction_Maximum, F.AggregateFunction_MaximumActualTime, F.AggregateFunction_Count),
        *["level"] * 6)
    assert seen(average) == [(0, 4.5, CALC), (10, 14.5, CALC)]  # the mean of the raw values 0..9 and 10..19
    assert seen(time_average) == [(0, 5.0, CALC), (10, 15.0, CALC)]  # the area under the line, over 10 s
    assert seen(minimum) == [(0, 0.0, GOOD), (10, 10.0, GOOD)]  # raw values at the interval's start
    assert seen(maximum) == [(0, 9.0, CALC), (10, 19.0, CALC)]
    assert seen(maximum_at) == [(9, 9.0, GOOD), (19, 19.0, GOOD)]
    assert seen(count) == [(0, 10, CALC), (10, 10, CALC)]
    (interpolative,) = await read(client, server, processed(0, 10, 2.5, F.AggregateFunction_Interpolative), "level")
    assert seen(interpolative) == [(0, 0.0, GOOD), (2.5, 2.5, INTERP), (5, 5.0, GOOD), (7.5, 7.5, INTERP)]
    (partial,) = await read(client, server, processed(0, 25, 10, F.AggregateFunction_TimeAverage2), "level")
    assert seen(partial)[2] == (20, 22.5, CALC | 0x4)  # [20, 25): shorter than the interval → Partial
    (stepped,) = await read(client, server, processed(0, 12, 6, F.AggregateFunction_Average), "steps")
    assert seen(stepped) == [(0, 0.5, CALC), (6, 2.5, CALC)]
    # Bad and uncertain values: left out (server defaults treat uncertain as bad) and the result is Uncertain.
    (pressure,) = await read(client, server, processed(0, 60, 0, F.AggregateFunction_Average), "pressure")
    assert seen(pressure) == [(0, 22.5, SUB | CALC)]
    lenient = ua.AggregateConfiguration(UseServerCapabilitiesDefaults=False, TreatUncertainAsBad=False, PercentDataBad=100, PercentDataGood=100)
    (pressure,) = await read(client, server, processed(0, 60, 0, F.AggregateFunction_Average, config=lenient), "pressure")
    assert seen(pressure) == [(0, 22.0, SUB | CALC)]
    (nothing,) = await read(client, server, processed(100, 120, 10, F.AggregateFunction_Average), "level")
    assert seen(nothing) == [(100, None, S.BadNoData), (110, None, S.BadNoData)]


async def test_reads_refused_and_nodes_without_history_get_the_spec_statuses(plant, client) -> None:
    _, server = plant
    (total,) = await read(client, server, processed(0, 20, 10, F.AggregateFunction_Total), "level")
    assert total.StatusCode.value == S.BadAggregateNotSupported
    (text,) = await read(client, server, processed(0, 20, 10, F.AggregateFunction_Average), "note")
    assert text.StatusCode.value == S.BadAggregateNotSupported  # no average of a string
    (text_count,) = await read(client, server, processed(0, 20, 20, F.AggregateFunction_Count), "note")
    assert seen(text_count) == [(0, 1, CALC)]
    mismatch = await read(client, server, processed(0, 20, 10, F.AggregateFunction_Average, F.AggregateFunction_Maximum), "level")
    assert [r.StatusCode.value for r in mismatch] == [S.BadAggregateListMismatch]
    (same,) = await read(client, server, processed(5, 5, 10, F.AggregateFunction_Average), "level")
    assert same.StatusCode.value == S.BadInvalidArgument
    rejected = ua.AggregateConfiguration(UseServerCapabilitiesDefaults=False, PercentDataBad=10, PercentDataGood=10)
    (refused,) = await read(client, server, processed(0, 20, 10, F.AggregateFunction_Average, config=rejected), "level")
    assert refused.StatusCode.value == S.BadAggregateConfigurationRejected
    # Beside a historized tag: a tag without history, an unknown node, a standard node; reads not offered.
    nodes = ["level", "spare", ua.NodeId("no_such_tag", server.namespace_index), ua.NodeId(ua.ObjectIds.Server)]
    unsupported = [S.BadHistoryOperationUnsupported, S.BadNodeIdUnknown, S.BadHistoryOperationUnsupported]
    for details in (raw(at(0), at(10)), processed(0, 10, 5, *[F.AggregateFunction_Average] * 4),
                    ua.ReadAtTimeDetails(ReqTimes=[at(1)], UseSimpleBounds=False)):
        first, *others = await read(client, server, details, *nodes)
        assert first.StatusCode.is_good() and first.HistoryData.DataValues and [r.StatusCode.value for r in others] == unsupported
    for details in (ua.ReadRawModifiedDetails(IsReadModified=True, StartTime=at(0), EndTime=at(10)),
                    ua.ReadEventDetails(StartTime=at(0), EndTime=at(10))):
        (result,) = await read(client, server, details, "level")
        assert result.StatusCode.value == S.BadHistoryOperationUnsupported


async def test_values_at_times_are_interpolated_or_use_simple_bounds(plant, client) -> None:
    _, server = plant
    (level,) = await read(client, server, ua.ReadAtTimeDetails(ReqTimes=[at(2.5), at(7), at(45), at(-10)], UseSimpleBounds=False), "level")
    assert seen(level) == [(2.5, 2.5, INTERP), (7, 7.0, GOOD), (45, 40.0, SUB | INTERP), (-10, None, S.BadNoData)]
    (steps,) = await read(client, server, ua.ReadAtTimeDetails(ReqTimes=[at(4)], UseSimpleBounds=False), "steps")
    assert seen(steps) == [(4, 1, INTERP)]  # stepped: the value before holds
    times = [at(15), at(20), at(25), at(45)]
    (interpolated,) = await read(client, server, ua.ReadAtTimeDetails(ReqTimes=times, UseSimpleBounds=False), "pressure")
    # The bad value at 20 s and the uncertain one at 40 s are skipped: lines 10 → 30 and 30 → 50, Uncertain.
    assert seen(interpolated) == [(15, 15.0, SUB | INTERP), (20, 20.0, SUB | INTERP), (25, 25.0, SUB | INTERP), (45, 45.0, SUB | INTERP)]
    (simple,) = await read(client, server, ua.ReadAtTimeDetails(ReqTimes=times, UseSimpleBounds=True), "pressure")
    # Simple bounds: the value before; a bad one (or a bad one at the time) gives Bad_NoData.
    assert seen(simple) == [(15, 10.0, SUB | INTERP), (20, None, S.BadNoData), (25, None, S.BadNoData), (45, None, S.BadNoData)]
