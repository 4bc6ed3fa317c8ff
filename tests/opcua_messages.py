"""Generated OPC UA responses of every shape, for the tests of our encoder (server) and decoder
(latency client) against asyncua's own codec."""

from __future__ import annotations

import random
from datetime import UTC, datetime, timedelta
from typing import Any

from asyncua import ua

from softplc.core.datatypes import DataType
from softplc.core.tags import Quality
from softplc.protocols.opcua_variants import VARIANT_TYPES, tag_data_value

SAMPLES = {
    DataType.BOOL: [True, False],
    DataType.INT16: [-32768, 0, 32767],
    DataType.UINT16: [0, 65535],
    DataType.INT32: [-2**31, 7, 2**31 - 1],
    DataType.UINT32: [0, 2**32 - 1],
    DataType.FLOAT32: [0.0, -1.5, float("inf")],
    DataType.FLOAT64: [3.141592653589793, float("-inf"), 1e300],
    DataType.STRING: ["", "Förderband <3>", "x" * 300, b"bad \xff bytes".decode("utf-8", "surrogateescape")],
}
STAMP = datetime(2026, 11, 27, 12, 0, 0, 123456, tzinfo=UTC)


def tag_values(rng: random.Random, *, scalars_only: bool = False) -> list[ua.DataValue]:
    """DataValues as the publisher makes them (every type, quality, forced) and as asyncua does;
    `scalars_only`: tags of fixed-size types only (what the client decodes itself)."""
    values: list[ua.DataValue] = []
    for data_type, samples in SAMPLES.items():
        if scalars_only and data_type is DataType.STRING:
            continue
        for value in samples:
            quality = rng.choice(list(Quality))
            values.append(tag_data_value(value, VARIANT_TYPES[data_type], quality, 1_795_000_000 + rng.random(), rng.random() < 0.2))
    if scalars_only:
        return values
    values += [
        ua.DataValue(ua.Variant(5, ua.VariantType.Int64)),
        ua.DataValue(ua.Variant([1, 2, 3], ua.VariantType.UInt16)),
        ua.DataValue(ua.Variant(None, ua.VariantType.Null), ua.StatusCode(ua.StatusCodes.BadNodeIdUnknown)),
        ua.DataValue(ua.Variant(ua.LocalizedText("Motor"), ua.VariantType.LocalizedText), SourceTimestamp=STAMP,
                     SourcePicoseconds=17),
        ua.DataValue(),
    ]
    return values


def status_codes(rng: random.Random) -> list[ua.StatusCode] | None:
    return rng.choice([None, [], [ua.StatusCode(rng.choice([0, ua.StatusCodes.BadTooManyOperations]))
                                  for _ in range(rng.randint(1, 3))]])


def header(rng: random.Random, unusual: bool) -> ua.ResponseHeader:
    head = ua.ResponseHeader(Timestamp=STAMP + timedelta(microseconds=rng.randint(0, 10**9)),
                             RequestHandle=rng.randint(0, 2**32 - 1),
                             ServiceResult=ua.StatusCode(rng.choice([0, ua.StatusCodes.BadTimeout])),
                             StringTable=rng.choice([[], None]))
    if unusual:
        kind = rng.randrange(3)
        if kind == 0:
            head.StringTable = ["a", "b"]
        elif kind == 1:
            head.ServiceDiagnostics = ua.DiagnosticInfo(SymbolicId=1)
        else:
            head.AdditionalHeader = ua.ExtensionObject(ua.NodeId(5, 1), b"\x01")
    return head


def publish_response(rng: random.Random, unusual: bool, *, scalars_only: bool = False) -> ua.PublishResponse:
    pool = tag_values(rng, scalars_only=scalars_only)
    notifications: list[Any] = []
    for _ in range(rng.randint(0, 3)):
        items = [ua.MonitoredItemNotification(ClientHandle=rng.randint(0, 2**32 - 1), Value=rng.choice(pool))
                 for _ in range(rng.randint(0, 5))]
        notifications.append(ua.DataChangeNotification(MonitoredItems=items, DiagnosticInfos=rng.choice([[], None])))
    if unusual and rng.random() < 0.5:
        notifications.insert(rng.randint(0, len(notifications)), rng.choice([
            ua.StatusChangeNotification(Status=ua.StatusCode(ua.StatusCodes.BadTimeout)),
            ua.EventNotificationList(Events=[ua.EventFieldList(ClientHandle=3, EventFields=[ua.Variant(1.5)])])]))
        unusual = False
    message = ua.NotificationMessage(SequenceNumber=rng.randint(0, 2**32 - 1), PublishTime=STAMP, NotificationData=notifications)
    result = ua.PublishResult(SubscriptionId=rng.randint(1, 2**32 - 1),
                              AvailableSequenceNumbers=rng.choice([None, [], [rng.randint(0, 2**32 - 1) for _ in range(4)]]),
                              MoreNotifications=rng.random() < 0.5, NotificationMessage=message, Results=status_codes(rng))
    if unusual and rng.random() < 0.5:
        result.DiagnosticInfos = [ua.DiagnosticInfo(InnerStatusCode=ua.StatusCode(ua.StatusCodes.BadTimeout))]
        unusual = False
    return ua.PublishResponse(ResponseHeader=header(rng, unusual), Parameters=result)


def write_response(rng: random.Random, unusual: bool) -> ua.WriteResponse:
    diagnostics = [ua.DiagnosticInfo(SymbolicId=2)] if unusual and rng.random() < 0.5 else rng.choice([[], None])
    return ua.WriteResponse(ResponseHeader=header(rng, unusual and not diagnostics), Results=status_codes(rng),
                            DiagnosticInfos=diagnostics)


def read_response(rng: random.Random, unusual: bool) -> ua.ReadResponse:
    pool = tag_values(rng)
    return ua.ReadResponse(ResponseHeader=header(rng, unusual), Results=rng.choice([None, rng.sample(pool, rng.randint(0, 6))]))


def generated(make: Any, seed: str, unusual: bool, count: int = 200) -> list[Any]:
    """`count` messages from `make` (one of the makers above), the same for the same seed."""
    rng = random.Random(seed)
    return [make(rng, unusual) for _ in range(count)]
