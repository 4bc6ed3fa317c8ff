"""OPC UA binary pieces for the messages on a handshake's path, read and written without asyncua's generic codec.

asyncua 2.1.0 (pinned) encodes and decodes a message field by field through a closure per field
and type. A request that comes once every 100-500 ms runs that code with cold CPU caches, 4-11
times slower than the same code run again at once (`bench/cold_path.py`): decoding a
PublishResponse of one value took ~0.25-0.34 ms. The encoders and decoders built on this module
(`adapters/opcua/response_encoding.py`, `latency/response_decoding.py`) read and write the common shapes of a few messages with
precompiled `struct`s into the same asyncua objects, and leave anything else to asyncua (they
raise `Unusual` internally and hand the whole message over), so their result is always asyncua's.

Covered here: scalar Variants of the fixed-size types, DataValues of such a Variant with status
and time stamps (no picoseconds), array lengths, and the null ExtensionObject.
"""

from __future__ import annotations

import struct
from typing import Any

from asyncua import ua
from asyncua.ua.ua_binary import nodeid_to_binary

INT32 = struct.Struct("<i")
UINT32 = struct.Struct("<I")
INT64 = struct.Struct("<q")
NULL_EXTENSION = b"\x00\x00\x00"  # a null NodeId, no body
NULL_LIST = INT32.pack(-1)
EMPTY_LIST = INT32.pack(0)
MAX_COUNT = 1 << 20  # an array length beyond any real message: left to asyncua
# A PublishResult's NotificationMessage after its SubscriptionId and AvailableSequenceNumbers:
# MoreNotifications, SequenceNumber, PublishTime, the NotificationData array's length.
MESSAGE_HEAD = struct.Struct("<?Iqi")
# A DataChangeNotification as an ExtensionObject: its binary encoding's TypeId and the "body follows" byte.
DATA_CHANGE_TYPE = nodeid_to_binary(ua.NodeId(ua.ObjectIds.DataChangeNotification_Encoding_DefaultBinary)) + b"\x01"

# The fixed-size scalar types: VariantType → struct format.
SCALAR_FORMATS: dict[ua.VariantType, str] = {
    ua.VariantType.Boolean: "<?", ua.VariantType.SByte: "<b", ua.VariantType.Byte: "<B",
    ua.VariantType.Int16: "<h", ua.VariantType.UInt16: "<H", ua.VariantType.Int32: "<i",
    ua.VariantType.UInt32: "<I", ua.VariantType.Int64: "<q", ua.VariantType.UInt64: "<Q",
    ua.VariantType.Float: "<f", ua.VariantType.Double: "<d",
}
# By the Variant's encoding byte (a scalar: no array or dimension bits).
_SCALARS: dict[int, tuple[ua.VariantType, struct.Struct]] = {
    vtype.value: (vtype, struct.Struct(fmt)) for vtype, fmt in SCALAR_FORMATS.items()
}
DATA_VALUE_VALUE, DATA_VALUE_STATUS, DATA_VALUE_SOURCE_TIME, DATA_VALUE_SERVER_TIME = 0x01, 0x02, 0x04, 0x08
_DATA_VALUE_BITS = DATA_VALUE_VALUE | DATA_VALUE_STATUS | DATA_VALUE_SOURCE_TIME | DATA_VALUE_SERVER_TIME


class Unusual(Exception):
    """A part the short way does not cover: asyncua decodes or encodes the whole message."""


def check_length(count: int) -> None:
    """An array's length: -1 (null), 0 or more, and no more than any real message holds."""
    if count < -1 or count > MAX_COUNT:
        raise Unusual  # asyncua's decoding decides what it makes of it


def read_data_value(raw: bytes, pos: int) -> tuple[ua.DataValue, int]:
    """The DataValue at `pos` (its mask byte first) and the position after it."""
    mask = raw[pos]
    pos += 1
    if not mask & DATA_VALUE_VALUE or mask & ~_DATA_VALUE_BITS:
        raise Unusual  # no value, picoseconds, or bits no DataValue has
    scalar = _SCALARS.get(raw[pos])  # arrays, dimensions and other types fail the lookup
    if scalar is None:
        raise Unusual
    vtype, unpack = scalar
    variant = ua.Variant(unpack.unpack_from(raw, pos + 1)[0], vtype, None, False)
    pos += 1 + unpack.size
    fields: dict[str, Any] = {}
    if mask & DATA_VALUE_STATUS:
        fields["StatusCode"] = ua.StatusCode(UINT32.unpack_from(raw, pos)[0])
        pos += 4
    if mask & DATA_VALUE_SOURCE_TIME:
        fields["SourceTimestamp"] = ua.win_epoch_to_datetime(INT64.unpack_from(raw, pos)[0])
        pos += 8
    if mask & DATA_VALUE_SERVER_TIME:
        fields["ServerTimestamp"] = ua.win_epoch_to_datetime(INT64.unpack_from(raw, pos)[0])
        pos += 8
    return ua.DataValue(variant, **fields), pos


def read_counters(raw: bytes, pos: int) -> tuple[list[int] | None, int]:
    """An array of UInt32 at `pos` (its length first) and the position after it; None if null."""
    count = INT32.unpack_from(raw, pos)[0]
    pos += 4
    check_length(count)
    if count < 0:
        return None, pos
    return list(struct.unpack_from(f"<{count}I", raw, pos)), pos + 4 * count


def read_status_codes(raw: bytes, pos: int) -> tuple[list[ua.StatusCode] | None, int]:
    codes, pos = read_counters(raw, pos)
    return (None if codes is None else [ua.StatusCode(code) for code in codes]), pos


def read_no_diagnostics(raw: bytes, pos: int) -> tuple[list[ua.DiagnosticInfo] | None, int]:
    """A null or empty array of DiagnosticInfo (any other: Unusual)."""
    count = INT32.unpack_from(raw, pos)[0]
    if count > 0 or count < -1:
        raise Unusual
    return (None if count < 0 else []), pos + 4
