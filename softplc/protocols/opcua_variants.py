"""Tag types and values as OPC UA sees them: DataTypes, Variants, StatusCodes, and write conversions.

Conversion rule for client writes (`value_from_variant`): the Variant's type must be the tag's
type, except for these lossless numeric conversions, which are accepted:

- any integer type (SByte … UInt64) → an integer tag, when the value fits the tag's type
  (a value that does not fit is BadOutOfRange);
- any integer or floating-point type → a float tag, when the value is represented exactly
  (Int64 3 → Double 3.0; Double 0.5 → Float 0.5; Double 0.1 → Float is *not* exact:
  BadTypeMismatch, write a Float instead);
- Float or Double → an integer tag, when the value is integral (3.0 → 3), range-checked as above.

Booleans and strings convert from nothing else (Int32 1 → Boolean is BadTypeMismatch).
"""

from __future__ import annotations

import math
import struct
from datetime import datetime, timezone
from typing import Any

from asyncua import ua

from softplc.core.datatypes import DataType
from softplc.core.tags import Quality, TagDef

VARIANT_TYPES: dict[DataType, ua.VariantType] = {
    DataType.BOOL: ua.VariantType.Boolean,
    DataType.INT16: ua.VariantType.Int16,
    DataType.UINT16: ua.VariantType.UInt16,
    DataType.INT32: ua.VariantType.Int32,
    DataType.UINT32: ua.VariantType.UInt32,
    DataType.FLOAT32: ua.VariantType.Float,
    DataType.FLOAT64: ua.VariantType.Double,
    DataType.STRING: ua.VariantType.String,
}

# The built-in DataType NodeIds have the same numbers as the VariantTypes (Boolean = i=1 …).
DATA_TYPE_IDS: dict[DataType, ua.NodeId] = {t: ua.NodeId(v.value, 0) for t, v in VARIANT_TYPES.items()}

_INTEGER_VARIANTS = frozenset({
    ua.VariantType.SByte, ua.VariantType.Byte, ua.VariantType.Int16, ua.VariantType.UInt16,
    ua.VariantType.Int32, ua.VariantType.UInt32, ua.VariantType.Int64, ua.VariantType.UInt64,
})
_FLOAT_VARIANTS = frozenset({ua.VariantType.Float, ua.VariantType.Double})

STATUS_CODES: dict[Quality, ua.StatusCode] = {
    Quality.GOOD: ua.StatusCode(ua.StatusCodes.Good),
    Quality.UNCERTAIN: ua.StatusCode(ua.StatusCodes.Uncertain),
    Quality.BAD: ua.StatusCode(ua.StatusCodes.Bad),
}


class WriteStatus(Exception):
    """A client write refused with an OPC UA status code (e.g. BadTypeMismatch)."""

    def __init__(self, code: int, detail: str) -> None:
        super().__init__(detail)
        self.code = code
        self.detail = detail


class TagDataValue(ua.DataValue):
    """A DataValue made for one push and never changed afterwards, so copying it is pointless.

    asyncua deep-copies every DataValue it hands to a monitored item (~40 µs, most of the cost
    of a subscribed change); for these the "copy" is the object itself. Its binary encoding is
    made once, when first sent, and kept in `binary` (adapters/opcua/response_encoding.py).
    """

    __slots__ = ("binary",)
    binary: bytes  # unset until first encoded

    def __copy__(self) -> TagDataValue:
        return self

    def __deepcopy__(self, memo: dict[int, Any]) -> TagDataValue:
        return self


def variant_for(definition: TagDef, value: Any) -> ua.Variant:
    """The Variant a client should write to set `definition`'s tag to `value`."""
    return ua.Variant(value, VARIANT_TYPES[definition.type])


_last_stamp: tuple[float, datetime] = (0.0, datetime.fromtimestamp(0, timezone.utc))


def timestamp(epoch_seconds: float) -> datetime:
    """A tag timestamp (epoch seconds) as the UTC datetime OPC UA carries."""
    global _last_stamp
    # The tags changed by one scan share one timestamp: convert it once.
    if _last_stamp[0] != epoch_seconds:
        _last_stamp = (epoch_seconds, datetime.fromtimestamp(epoch_seconds, timezone.utc))
    return _last_stamp[1]


def data_value(definition: TagDef, value: Any, quality: Quality, epoch_seconds: float, forced: bool = False) -> ua.DataValue:
    """The DataValue served for a tag: value, StatusCode from quality, source = server timestamp."""
    return tag_data_value(value, VARIANT_TYPES[definition.type], quality, epoch_seconds, forced)


_GOOD = STATUS_CODES[Quality.GOOD]
# A forced tag (softplc/core/forcing.py) whose value is good: the status OPC UA has for a local override.
FORCED_STATUS = ua.StatusCode(ua.StatusCodes.GoodLocalOverride)


def tag_data_value(value: Any, variant_type: ua.VariantType, quality: Quality, epoch_seconds: float, forced: bool = False) -> TagDataValue:
    """`data_value` for the hot path: the variant type looked up once per tag by the caller."""
    stamp = timestamp(epoch_seconds)
    status = (FORCED_STATUS if forced else _GOOD) if quality is Quality.GOOD else STATUS_CODES[quality]
    # Positional, with is_array given: skips the Variant's type guessing (~1 µs of ~2).
    return TagDataValue(ua.Variant(value, variant_type, None, False), status, stamp, stamp)


def value_from_variant(definition: TagDef, variant: ua.Variant | None) -> Any:
    """The Python value a client's Variant sets on the tag, or raise WriteStatus (rules above)."""
    if variant is None or variant.VariantType == ua.VariantType.Null:
        raise WriteStatus(ua.StatusCodes.BadTypeMismatch, "a null value cannot be written to a tag")
    if variant.is_array or isinstance(variant.Value, (list, tuple)):
        raise WriteStatus(ua.StatusCodes.BadTypeMismatch, "an array cannot be written to a scalar tag")
    tag_type = definition.type
    vtype = variant.VariantType
    value = variant.Value
    expected = VARIANT_TYPES[tag_type]
    if tag_type is DataType.BOOL or tag_type is DataType.STRING:
        if vtype != expected:
            raise WriteStatus(ua.StatusCodes.BadTypeMismatch, f"expected {expected.name}, got {vtype.name}")
        return value
    if tag_type.is_integer:
        if vtype in _FLOAT_VARIANTS:
            if not math.isfinite(value) or not float(value).is_integer():
                raise WriteStatus(ua.StatusCodes.BadTypeMismatch, f"{vtype.name} {value!r} is not an integral value for {expected.name}")
            value = int(value)
        elif vtype not in _INTEGER_VARIANTS:
            raise WriteStatus(ua.StatusCodes.BadTypeMismatch, f"expected {expected.name}, got {vtype.name}")
        low, high = tag_type.limits  # type: ignore[misc]
        if not low <= value <= high:
            raise WriteStatus(ua.StatusCodes.BadOutOfRange, f"{value} does not fit {expected.name} ({int(low)}..{int(high)})")
        return int(value)
    # Float tags.
    if vtype in _INTEGER_VARIANTS:
        result = float(value)
        if int(result) != value:
            raise WriteStatus(ua.StatusCodes.BadTypeMismatch, f"{vtype.name} {value} is not exactly representable as {expected.name}")
    elif vtype in _FLOAT_VARIANTS:
        result = float(value)
    else:
        raise WriteStatus(ua.StatusCodes.BadTypeMismatch, f"expected {expected.name}, got {vtype.name}")
    if tag_type is DataType.FLOAT32 and math.isfinite(result):
        low, high = tag_type.limits  # type: ignore[misc]
        if not low <= result <= high:
            raise WriteStatus(ua.StatusCodes.BadOutOfRange, f"{result} does not fit Float")
        single = struct.unpack("f", struct.pack("f", result))[0]
        if single != result:
            detail = f"{vtype.name} {result!r} is not exactly representable as Float; write a Float"
            raise WriteStatus(ua.StatusCodes.BadTypeMismatch, detail)
        result = single
    return result
