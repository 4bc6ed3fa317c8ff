"""Sparkplug B datatypes (specification §6.4.16), the tag types they carry, and how integers travel.

Metric values travel in a protobuf `oneof`: the 8–32-bit integers in `int_value` (uint32), the
64-bit ones and DateTime in `long_value` (uint64), so a negative number is sent as its two's
complement. The specification does not say at which width: Eclipse Tahu's Java and JavaScript
libraries sign-extend to 32 bits (Int16 −1 → 4294967295), pysparkplug uses the type's own width
(Int16 −1 → 65535). We send the type's own width, which both read back correctly, and accept
both forms when we read.
"""

from __future__ import annotations

import enum

from softplc.core.datatypes import DataType


class SparkplugType(enum.IntEnum):
    """The datatypes of the specification's DataType enum that softplc sends or reads."""

    INT8 = 1
    INT16 = 2
    INT32 = 3
    INT64 = 4
    UINT8 = 5
    UINT16 = 6
    UINT32 = 7
    UINT64 = 8
    FLOAT = 9
    DOUBLE = 10
    BOOLEAN = 11
    STRING = 12
    DATETIME = 13
    TEXT = 14

    @property
    def field(self) -> str:
        """The `Metric.value` field a value of this type travels in."""
        return VALUE_FIELDS[self]

    @property
    def label(self) -> str:
        """The specification's name of the type (Int16, Float, Boolean...)."""
        return _LABELS[self]


# A tag's type → the metric's datatype.
FOR_TAG_TYPE: dict[DataType, SparkplugType] = {
    DataType.BOOL: SparkplugType.BOOLEAN,
    DataType.INT16: SparkplugType.INT16,
    DataType.UINT16: SparkplugType.UINT16,
    DataType.INT32: SparkplugType.INT32,
    DataType.UINT32: SparkplugType.UINT32,
    DataType.FLOAT32: SparkplugType.FLOAT,
    DataType.FLOAT64: SparkplugType.DOUBLE,
    DataType.STRING: SparkplugType.STRING,
}

VALUE_FIELDS: dict[SparkplugType, str] = {
    **dict.fromkeys((SparkplugType.INT8, SparkplugType.INT16, SparkplugType.INT32,
                     SparkplugType.UINT8, SparkplugType.UINT16, SparkplugType.UINT32), "int_value"),
    **dict.fromkeys((SparkplugType.INT64, SparkplugType.UINT64, SparkplugType.DATETIME), "long_value"),
    SparkplugType.FLOAT: "float_value",
    SparkplugType.DOUBLE: "double_value",
    SparkplugType.BOOLEAN: "boolean_value",
    SparkplugType.STRING: "string_value",
    SparkplugType.TEXT: "string_value",
}

# bits, signed
INTEGER_WIDTHS: dict[SparkplugType, tuple[int, bool]] = {
    SparkplugType.INT8: (8, True), SparkplugType.INT16: (16, True), SparkplugType.INT32: (32, True),
    SparkplugType.INT64: (64, True), SparkplugType.UINT8: (8, False), SparkplugType.UINT16: (16, False),
    SparkplugType.UINT32: (32, False), SparkplugType.UINT64: (64, False), SparkplugType.DATETIME: (64, False),
}

_LABELS = {
    SparkplugType.INT8: "Int8", SparkplugType.INT16: "Int16", SparkplugType.INT32: "Int32", SparkplugType.INT64: "Int64",
    SparkplugType.UINT8: "UInt8", SparkplugType.UINT16: "UInt16", SparkplugType.UINT32: "UInt32", SparkplugType.UINT64: "UInt64",
    SparkplugType.FLOAT: "Float", SparkplugType.DOUBLE: "Double", SparkplugType.BOOLEAN: "Boolean",
    SparkplugType.STRING: "String", SparkplugType.DATETIME: "DateTime", SparkplugType.TEXT: "Text",
}

# The `Quality` property (§6.4.7, "Quality Codes"): sent with a metric whose quality is not GOOD,
# and with the change back to GOOD.
QUALITY_BAD = 0
QUALITY_GOOD = 192
QUALITY_STALE = 500


def wire_integer(datatype: SparkplugType, value: int) -> int:
    """`value` as it travels: a negative number as its two's complement at the type's width."""
    bits, signed = INTEGER_WIDTHS[datatype]
    return value + (1 << bits) if signed and value < 0 else value


def read_integer(datatype: SparkplugType, raw: int) -> int:
    """The number a received `int_value`/`long_value` stands for; ValueError when it cannot be one of the type."""
    bits, signed = INTEGER_WIDTHS[datatype]
    if not signed:
        if raw >= 1 << bits:
            raise ValueError(f"{raw} does not fit in {datatype.label}")
        return raw
    if bits < 32 and raw >= 1 << bits:
        # Sign-extended to 32 bits (Tahu): only the upper range that is a negative number of this width.
        if raw >= (1 << 32) or raw < (1 << 32) - (1 << (bits - 1)):
            raise ValueError(f"{raw} does not fit in {datatype.label}")
        return raw - (1 << 32)
    return raw - (1 << bits) if raw >= 1 << (bits - 1) else raw
