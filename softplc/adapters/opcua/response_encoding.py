"""The responses a server sends most — Publish, Write, Read — encoded the short way.

asyncua's generic encoder builds the bytes of every value again for every subscriber, and runs
cold on a sparse path (see `softplc/protocols/opcua_binary.py`): a PublishResponse of one value
took ~0.25 ms to encode, ~0.03 ms when encoded again at once. Here

- the fixed parts of these three responses are packed with a few precompiled `struct`s, and
- a tag's value is encoded once per change: a `TagDataValue` (one object per change, shared by
  every monitored item and the address space) keeps its own bytes, so ten subscribers of a tag,
  and every Read of it until it changes, reuse one encoding.

Anything these shapes do not cover — diagnostics, a string table, an additional header, event
or status-change notifications — is encoded by asyncua as before, the whole response. The bytes
are the same as asyncua's in every case (tests/adapters/opcua/test_opcua_response_encoding.py checks
them against `struct_to_binary` for generated responses).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

from asyncua import ua
from asyncua.ua.ua_binary import create_dataclass_serializer, get_string_encoding, nodeid_to_binary, struct_to_binary

from softplc.protocols.opcua_binary import (
    DATA_CHANGE_TYPE,
    EMPTY_LIST,
    INT32,
    MESSAGE_HEAD,
    NULL_LIST,
    SCALAR_FORMATS,
    UINT32,
    Unusual,
)
from softplc.protocols.opcua_variants import TagDataValue

_HEADER = struct.Struct("<qII")  # Timestamp, RequestHandle, ServiceResult
# ServiceDiagnostics empty (mask 0), StringTable of none, AdditionalHeader a null ExtensionObject.
_HEADER_TAIL_EMPTY = b"\x00" + struct.pack("<i", 0) + b"\x00\x00\x00"
_HEADER_TAIL_NULL_TABLE = b"\x00" + struct.pack("<i", -1) + b"\x00\x00\x00"
_RESULT_HEAD = struct.Struct("<I")  # SubscriptionId
_TYPE_IDS: dict[type, bytes] = {
    kind: nodeid_to_binary(kind().TypeId) for kind in (ua.PublishResponse, ua.WriteResponse, ua.ReadResponse)
}
_EMPTY_DIAGNOSTICS = ua.DiagnosticInfo()
_NULL_NODE = ua.NodeId()
_DATA_VALUE = create_dataclass_serializer(ua.DataValue)
# A tag's DataValue: Value, StatusCode, SourceTimestamp and ServerTimestamp present (mask 0x0F).
_TAG_VALUE_MASK = b"\x0f"
_TAG_VALUE_TAIL = struct.Struct("<Iqq")
_SCALARS: dict[ua.VariantType, tuple[bytes, struct.Struct]] = {
    vtype: (bytes([vtype.value]), struct.Struct(fmt)) for vtype, fmt in SCALAR_FORMATS.items()
}
_STRING = bytes([ua.VariantType.String.value])


def encode_response(response: Any) -> bytes:
    """The binary encoding of a service response (the same bytes as asyncua's `struct_to_binary`)."""
    kind = type(response)
    try:
        if kind is ua.PublishResponse:
            body = _publish_result(response.Parameters)
        elif kind is ua.WriteResponse:
            body = _status_codes(response.Results) + _no_diagnostics(response.DiagnosticInfos)
        elif kind is ua.ReadResponse:
            body = _data_values(response.Results) + _no_diagnostics(response.DiagnosticInfos)
        else:
            return struct_to_binary(response)
        return _TYPE_IDS[kind] + _response_header(response.ResponseHeader) + body
    except Unusual:
        return struct_to_binary(response)


def data_value_binary(value: ua.DataValue) -> bytes:
    """A DataValue's encoding; a tag's (`TagDataValue`) is made once and kept with it."""
    if type(value) is not TagDataValue:
        return _DATA_VALUE(value)
    try:
        return value.binary
    except AttributeError:  # not encoded yet
        encoded = value.binary = _tag_value(value)
        return encoded


def _tag_value(value: TagDataValue) -> bytes:
    """A tag's DataValue as the publisher makes it (a scalar, a status, one time stamp twice)."""
    variant, status, source, server = value.Value, value.StatusCode, value.SourceTimestamp, value.ServerTimestamp
    if (variant is None or status is None or source is None or server is None or variant.is_array
            or variant.Dimensions is not None or value.SourcePicoseconds is not None or value.ServerPicoseconds is not None):
        return _DATA_VALUE(value)
    vtype, scalar = variant.VariantType, variant.Value
    packer = _SCALARS.get(vtype)
    if packer is not None and not isinstance(scalar, (list, tuple)):
        head = packer[0] + packer[1].pack(scalar)
    elif vtype is ua.VariantType.String and isinstance(scalar, str):
        encoded = scalar.encode(get_string_encoding(), errors="surrogateescape")  # as asyncua: a client's bad bytes kept
        head = _STRING + INT32.pack(len(encoded)) + encoded
    else:
        return _DATA_VALUE(value)
    stamp = ua.datetime_to_win_epoch(source)
    return b"".join([_TAG_VALUE_MASK, head, _TAG_VALUE_TAIL.pack(
        status.value, stamp, stamp if server is source else ua.datetime_to_win_epoch(server))])


def _response_header(header: ua.ResponseHeader) -> bytes:
    table = header.StringTable
    if table:
        raise Unusual
    if header.ServiceDiagnostics != _EMPTY_DIAGNOSTICS:
        raise Unusual
    extra = header.AdditionalHeader
    if extra is None or extra.Body is not None or extra.TypeId != _NULL_NODE:
        raise Unusual
    head = _HEADER.pack(ua.datetime_to_win_epoch(header.Timestamp), header.RequestHandle, header.ServiceResult.value)
    return head + (_HEADER_TAIL_EMPTY if table is not None else _HEADER_TAIL_NULL_TABLE)


def _publish_result(result: ua.PublishResult) -> bytes:
    message = result.NotificationMessage
    notifications = message.NotificationData
    parts = [_RESULT_HEAD.pack(result.SubscriptionId), _counters(result.AvailableSequenceNumbers),
             MESSAGE_HEAD.pack(result.MoreNotifications, message.SequenceNumber,
                                ua.datetime_to_win_epoch(message.PublishTime), len(notifications))]
    for notification in notifications:
        if type(notification) is not ua.DataChangeNotification:
            raise Unusual  # events, status changes: asyncua's encoding
        items = notification.MonitoredItems
        body = b"".join([INT32.pack(len(items)),
                         *[UINT32.pack(item.ClientHandle) + data_value_binary(item.Value) for item in items],
                         _no_diagnostics(notification.DiagnosticInfos)])
        parts.append(DATA_CHANGE_TYPE + INT32.pack(len(body)) + body)
    parts.append(_status_codes(result.Results))
    parts.append(_no_diagnostics(result.DiagnosticInfos))
    return b"".join(parts)


def _counters(values: Sequence[int] | None) -> bytes:
    if values is None:
        return NULL_LIST
    return INT32.pack(len(values)) + struct.pack(f"<{len(values)}I", *values)


def _status_codes(codes: Sequence[ua.StatusCode] | None) -> bytes:
    if codes is None:
        return NULL_LIST
    return INT32.pack(len(codes)) + struct.pack(f"<{len(codes)}I", *[code.value for code in codes])


def _data_values(values: Sequence[ua.DataValue] | None) -> bytes:
    if values is None:
        return NULL_LIST
    return INT32.pack(len(values)) + b"".join([data_value_binary(value) for value in values])


def _no_diagnostics(diagnostics: Sequence[ua.DiagnosticInfo] | None) -> bytes:
    if diagnostics is None:
        return NULL_LIST
    if diagnostics:
        raise Unusual
    return EMPTY_LIST
