"""The two responses on the latency client's timed path — Publish and Write — decoded the short way.

Between the PublishResponse carrying Ready and the answer's Write lies the decoding of that
PublishResponse, and the WriteResponse's decoding ends the timed part; asyncua's generic decoder
runs both cold, once every 100-500 ms (see `softplc/protocols/opcua_binary.py`). The common
shapes are read here into the same asyncua objects:

- a PublishResponse whose notifications are data changes of scalar values (what a client
  monitoring tags receives), and
- a WriteResponse's results.

Anything else — diagnostics, a string table, an additional header, events, status changes,
arrays, strings, picoseconds, a damaged message — is decoded by asyncua, the whole response, so
the result (or the error) is always asyncua's (tests/latency/test_latency_response_decoding.py checks
both against `struct_from_binary`, damaged responses included).
"""

from __future__ import annotations

import struct
from typing import Any

from asyncua import ua
from asyncua.common.utils import Buffer
from asyncua.ua.ua_binary import nodeid_to_binary, struct_from_binary

from softplc.protocols.opcua_binary import (
    DATA_CHANGE_TYPE,
    INT32,
    MESSAGE_HEAD,
    NULL_EXTENSION,
    UINT32,
    Unusual,
    check_length,
    read_counters,
    read_data_value,
    read_no_diagnostics,
    read_status_codes,
)

# The TypeIds as asyncua decodes them (one object serves every response).
_PUBLISH_TYPE_ID = ua.NodeId(ua.ObjectIds.PublishResponse_Encoding_DefaultBinary, 0, ua.NodeIdType.FourByte)
_WRITE_TYPE_ID = ua.NodeId(ua.ObjectIds.WriteResponse_Encoding_DefaultBinary, 0, ua.NodeIdType.FourByte)
_PUBLISH_TYPE = nodeid_to_binary(_PUBLISH_TYPE_ID)
_WRITE_TYPE = nodeid_to_binary(_WRITE_TYPE_ID)
_HEADER = struct.Struct("<qIIBi")  # Timestamp, RequestHandle, ServiceResult, diagnostics mask, StringTable length
_FAILED = (Unusual, struct.error, IndexError)


def decode_publish_response(data: Buffer) -> ua.PublishResponse:
    """A PublishResponse (its TypeId first) as `struct_from_binary` gives it."""
    try:
        return _publish_response(bytes(data))
    except _FAILED:
        return struct_from_binary(ua.PublishResponse, data)


def decode_write_response(data: Buffer) -> ua.WriteResponse:
    """A WriteResponse (its TypeId first) as `struct_from_binary` gives it."""
    raw = bytes(data)
    try:
        if not raw.startswith(_WRITE_TYPE):
            raise Unusual
        header, pos = _response_header(raw, len(_WRITE_TYPE))
        results, pos = read_status_codes(raw, pos)
        diagnostics, pos = read_no_diagnostics(raw, pos)
        return ua.WriteResponse(TypeId=_WRITE_TYPE_ID, ResponseHeader=header, Results=results, DiagnosticInfos=diagnostics)
    except _FAILED:
        return struct_from_binary(ua.WriteResponse, data)


def _publish_response(raw: bytes) -> ua.PublishResponse:
    if not raw.startswith(_PUBLISH_TYPE):
        raise Unusual
    header, pos = _response_header(raw, len(_PUBLISH_TYPE))
    subscription = UINT32.unpack_from(raw, pos)[0]
    available, pos = read_counters(raw, pos + 4)
    more, sequence, published, count = MESSAGE_HEAD.unpack_from(raw, pos)
    pos += MESSAGE_HEAD.size
    check_length(count)
    notifications: list[Any] | None = None if count < 0 else []
    for _ in range(count):
        if not raw.startswith(DATA_CHANGE_TYPE, pos):
            raise Unusual  # events, status changes
        pos += len(DATA_CHANGE_TYPE)
        end = pos + 4 + INT32.unpack_from(raw, pos)[0]  # the body's length, then the body
        notification, pos = _data_change(raw, pos + 4)
        if pos != end:
            raise Unusual
        notifications.append(notification)  # type: ignore[union-attr]
    results, pos = read_status_codes(raw, pos)
    diagnostics, pos = read_no_diagnostics(raw, pos)
    message = ua.NotificationMessage(SequenceNumber=sequence, PublishTime=ua.win_epoch_to_datetime(published),
                                     NotificationData=notifications)
    result = ua.PublishResult(SubscriptionId=subscription, AvailableSequenceNumbers=available, MoreNotifications=more,
                              NotificationMessage=message, Results=results, DiagnosticInfos=diagnostics)
    return ua.PublishResponse(TypeId=_PUBLISH_TYPE_ID, ResponseHeader=header, Parameters=result)


def _response_header(raw: bytes, pos: int) -> tuple[ua.ResponseHeader, int]:
    stamp, handle, result, diagnostics, table = _HEADER.unpack_from(raw, pos)
    pos += _HEADER.size
    if diagnostics or table > 0 or table < -1 or raw[pos:pos + 3] != NULL_EXTENSION:
        raise Unusual
    header = ua.ResponseHeader(Timestamp=ua.win_epoch_to_datetime(stamp), RequestHandle=handle,
                               ServiceResult=ua.StatusCode(result), ServiceDiagnostics=ua.DiagnosticInfo(),
                               StringTable=None if table < 0 else [], AdditionalHeader=ua.ExtensionObject())
    return header, pos + 3


def _data_change(raw: bytes, pos: int) -> tuple[ua.DataChangeNotification, int]:
    count = INT32.unpack_from(raw, pos)[0]
    pos += 4
    check_length(count)
    items: list[ua.MonitoredItemNotification] = []  # asyncua decodes a null array of structures as empty
    for _ in range(count):
        handle = UINT32.unpack_from(raw, pos)[0]
        value, pos = read_data_value(raw, pos + 4)
        items.append(ua.MonitoredItemNotification(ClientHandle=handle, Value=value))
    diagnostics, pos = read_no_diagnostics(raw, pos)
    return ua.DataChangeNotification(MonitoredItems=items, DiagnosticInfos=diagnostics), pos
