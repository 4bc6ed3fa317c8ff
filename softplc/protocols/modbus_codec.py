"""How one tag value becomes Modbus words (16-bit registers) and back: for the Modbus server and links.

Bytes inside a register are always big-endian (the Modbus rule); the order of the registers
of a 32/64-bit value is configurable: "big" puts the most significant word first (ABCD, the
Modicon convention), "little" the least significant word first (CDAB).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any

from softplc.core.datatypes import DataType

REGISTER_TYPES: tuple[DataType, ...] = (
    DataType.INT16,
    DataType.UINT16,
    DataType.INT32,
    DataType.UINT32,
    DataType.FLOAT32,
    DataType.FLOAT64,
)
_STRUCT = {
    DataType.INT16: "h",
    DataType.UINT16: "H",
    DataType.INT32: "i",
    DataType.UINT32: "I",
    DataType.FLOAT32: "f",
    DataType.FLOAT64: "d",
}
WORD_ORDERS = ("big", "little")


class CodecError(ValueError):
    """Registers (written by a client, or read from a remote server) do not hold a value of the tag's encoding."""


def register_words(register_type: DataType) -> int:
    """Registers one value of a numeric register type takes."""
    return struct.calcsize(_STRUCT[register_type]) // 2


@dataclass(frozen=True, slots=True)
class RegisterCodec:
    """Encoding of one tag in registers: a numeric register type (optionally scaled) or a string.

    `tag_type` is the tag's own type; `register_type` the type carried on the wire (None for
    strings). With `scale`, register = round(value * scale) and value = register / scale.
    """

    tag_type: DataType
    register_type: DataType | None
    words: int
    scale: float | None = None
    word_order: str = "big"

    def encode(self, value: Any) -> list[int]:
        """The registers that carry `value` (numbers saturate at the register type's limits)."""
        if self.register_type is None:
            return _encode_string(value, self.words)
        register_type = self.register_type
        if register_type.is_integer:
            number = float(value) * self.scale if self.scale is not None else value
            raw: Any = _saturate(number, register_type)
        else:
            raw = float(value)
            if register_type is DataType.FLOAT32 and math.isfinite(raw) and abs(raw) > 3.4028234663852886e38:
                raw = math.copysign(math.inf, raw)
        data = struct.pack(">" + _STRUCT[register_type], raw)
        words = [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
        if self.word_order == "little":
            words.reverse()
        return words

    def decode(self, words: list[int]) -> Any:
        """The value that registers (a client's write, a remote's answer) stand for; raises CodecError."""
        if len(words) != self.words:
            raise CodecError(f"expected {self.words} registers, got {len(words)}")
        if self.register_type is None:
            return _decode_string(words)
        ordered = list(reversed(words)) if self.word_order == "little" else words
        data = b"".join(word.to_bytes(2, "big") for word in ordered)
        (raw,) = struct.unpack(">" + _STRUCT[self.register_type], data)
        if self.scale is None:
            if self.tag_type.is_float and isinstance(raw, int):
                return float(raw)
            return raw
        value = raw / self.scale
        if self.tag_type.is_integer or self.tag_type is DataType.BOOL:
            # 3 / 0.1 is 30.000000000000004: snap what is integral up to rounding noise.
            nearest = round(value)
            if abs(value - nearest) <= 1e-9 * max(1.0, abs(value)):
                return nearest
        return value

    def describe(self) -> str:
        """Short text for the map listing, e.g. 'int16 x100' or 'string'."""
        if self.register_type is None:
            return "string"
        text = self.register_type.value
        if self.scale is not None:
            text += f" x{self.scale:g}"
        return text


def _saturate(number: Any, register_type: DataType) -> int:
    """Round to the register's integer type, clamping at its limits (NaN reads as 0)."""
    low, high = register_type.limits  # type: ignore[misc]
    if isinstance(number, bool):
        number = int(number)
    if isinstance(number, float):
        if math.isnan(number):
            return 0
        if math.isinf(number):
            return int(high if number > 0 else low)
        number = round(number)
    return int(min(max(number, low), high))


def _encode_string(value: Any, words: int) -> list[int]:
    """UTF-8, two bytes per register (first byte high), cut at a character boundary, NUL-padded."""
    data = str(value).encode("utf-8")
    limit = words * 2
    if len(data) > limit:
        data = data[:limit].decode("utf-8", errors="ignore").encode("utf-8")
    data = data.ljust(limit, b"\0")
    return [int.from_bytes(data[i : i + 2], "big") for i in range(0, limit, 2)]


def _decode_string(words: list[int]) -> str:
    data = b"".join(word.to_bytes(2, "big") for word in words).rstrip(b"\0")
    if b"\0" in data:
        raise CodecError("a string may not contain NUL before its end")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise CodecError(f"not valid UTF-8: {error.reason}") from None
