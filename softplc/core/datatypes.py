"""Tag data types: the eight IEC-style types a tag may have, their ranges and coercion rules."""

from __future__ import annotations

import enum
import math
import struct
from typing import Any


class TypeMismatch(ValueError):
    """A value cannot be represented by a tag's type without loss."""


class DataType(enum.Enum):
    """A tag's type. The value is the name used in `tagdb.yaml`."""

    BOOL = "bool"
    INT16 = "int16"
    UINT16 = "uint16"
    INT32 = "int32"
    UINT32 = "uint32"
    FLOAT32 = "float32"
    FLOAT64 = "float64"
    STRING = "string"

    @property
    def is_integer(self) -> bool:
        return self in _INT_RANGES

    @property
    def is_float(self) -> bool:
        return self in (DataType.FLOAT32, DataType.FLOAT64)

    @property
    def is_numeric(self) -> bool:
        return self.is_integer or self.is_float

    @property
    def limits(self) -> tuple[float, float] | None:
        """The representable range of a numeric type (None for bool and string)."""
        if self.is_integer:
            return _INT_RANGES[self]
        if self is DataType.FLOAT32:
            return (-3.4028234663852886e38, 3.4028234663852886e38)
        if self is DataType.FLOAT64:
            return (-math.inf, math.inf)
        return None

    @property
    def default(self) -> Any:
        """The value a tag of this type has when the configuration gives no `initial`."""
        if self is DataType.BOOL:
            return False
        if self is DataType.STRING:
            return ""
        if self.is_float:
            return 0.0
        return 0

    def coerce(self, value: Any) -> Any:
        """Return `value` as this type, or raise TypeMismatch if that would lose information.

        Accepted lossless conversions: bool ← bool or 0/1 integers; integers ← integers and
        floats with an integral value (3.0 → 3); floats ← integers and floats (float32 is
        rounded to single precision); string ← valid Unicode text only (see `_check_text`). NumPy scalars count as the Python
        value they hold, and the result is always a plain Python value.
        """
        value = _native(value)
        if self is DataType.BOOL:
            if isinstance(value, bool):
                return value
            if isinstance(value, int) and value in (0, 1):
                return bool(value)
            raise TypeMismatch(f"expected bool, got {_describe(value)}")
        if self is DataType.STRING:
            if not isinstance(value, str):
                raise TypeMismatch(f"expected string, got {_describe(value)}")
            _check_text(value)
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeMismatch(f"expected {self.value}, got {_describe(value)}")
        if self.is_integer:
            if isinstance(value, float):
                if not value.is_integer():
                    raise TypeMismatch(f"expected {self.value}, got non-integral number {value!r}")
                value = int(value)
            low, high = _INT_RANGES[self]
            if not low <= value <= high:
                raise TypeMismatch(f"{value} does not fit in {self.value} ({low}..{high})")
            return value
        result = float(value)
        if self is DataType.FLOAT32 and math.isfinite(result):
            low, high = self.limits  # type: ignore[misc]
            if not low <= result <= high:
                raise TypeMismatch(f"{value} does not fit in float32")
            result = struct.unpack("f", struct.pack("f", result))[0]
        return result


    def parse(self, text: str) -> Any:
        """A value of this type from text a person typed (CLI, a form): `true`/`off`, `42`, `0.5`, `1e3`.

        Raises TypeMismatch with what was expected. Strings are taken as they are.
        """
        if self is DataType.STRING:
            return self.coerce(text)
        word = text.strip()
        if self is DataType.BOOL:
            lowered = word.lower()
            if lowered in ("true", "1", "on", "yes"):
                return True
            if lowered in ("false", "0", "off", "no"):
                return False
            raise TypeMismatch(f"expected bool (true/false, 1/0, on/off), got {text!r}")
        try:
            number: int | float = int(word) if self.is_integer and word.lstrip("+-").isdigit() else float(word)
        except ValueError:
            raise TypeMismatch(f"expected {self.value}, got {text!r}") from None
        return self.coerce(number)


_INT_RANGES: dict[DataType, tuple[int, int]] = {
    DataType.INT16: (-(2**15), 2**15 - 1),
    DataType.UINT16: (0, 2**16 - 1),
    DataType.INT32: (-(2**31), 2**31 - 1),
    DataType.UINT32: (0, 2**32 - 1),
}

TYPE_NAMES: tuple[str, ...] = tuple(t.value for t in DataType)


def _native(value: Any) -> Any:
    """A NumPy scalar (what scikit-learn or numpy code returns) as its Python value."""
    if type(value) in (bool, int, float, str):
        return value
    if getattr(value, "shape", None) == () and hasattr(value, "item"):
        return value.item()  # np.int64(1) → 1, np.bool_(True) → True, np.float32(0.5) → 0.5
    return value


def _check_text(value: str) -> None:
    """Refuse a string that is not valid Unicode text (what every protocol can carry as UTF-8).

    A decoder with `surrogateescape` (asyncua's) turns invalid UTF-8 bytes into lone surrogates;
    such a string cannot be encoded again, so it would break every reader after the writer.
    """
    if value.isascii():
        return
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as error:
        raise TypeMismatch(f"not valid UTF-8 text: invalid character at position {error.start}") from None


def _describe(value: Any) -> str:
    return f"{type(value).__name__} {value!r}"
