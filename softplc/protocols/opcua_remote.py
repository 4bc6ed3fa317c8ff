"""Another server's nodes as tags: which node DataTypes a tag can be bound to, and values both ways.

A link (softplc/adapters/links) binds a tag to a node of a remote OPC UA server. The remote's
DataType decides the Variant written to it (servers check types strictly), so the binding is
checked once at connect (`binding_problem`) and every value is converted on the way:

- in (`tag_value`): Boolean → bool tag, String → string tag, any integer → integer tag (it must
  fit the tag's type), any integer or float → float tag (a float32 tag rounds to single precision).
  Anything else (a null, an array, a DateTime...) raises ValueError with what was sent;
- out (`remote_variant`): the tag's value as the node's own VariantType, range-checked (an Int32
  tag into a Byte node must be 0..255), or ValueError.
"""

from __future__ import annotations

import math
from typing import Any

from asyncua import ua

from softplc.core.datatypes import DataType, TypeMismatch

INTEGER_VARIANTS: dict[ua.VariantType, tuple[int, int]] = {
    ua.VariantType.SByte: (-(2**7), 2**7 - 1),
    ua.VariantType.Byte: (0, 2**8 - 1),
    ua.VariantType.Int16: (-(2**15), 2**15 - 1),
    ua.VariantType.UInt16: (0, 2**16 - 1),
    ua.VariantType.Int32: (-(2**31), 2**31 - 1),
    ua.VariantType.UInt32: (0, 2**32 - 1),
    ua.VariantType.Int64: (-(2**63), 2**63 - 1),
    ua.VariantType.UInt64: (0, 2**64 - 1),
}
FLOAT_VARIANTS = (ua.VariantType.Float, ua.VariantType.Double)


def variant_type_of(data_type: ua.NodeId) -> ua.VariantType | None:
    """The VariantType of a built-in DataType NodeId (i=1 Boolean … i=12 String), else None."""
    if data_type.NamespaceIndex != 0 or not isinstance(data_type.Identifier, int) or not 1 <= data_type.Identifier <= 12:
        return None
    return ua.VariantType(data_type.Identifier)


def accepts(tag_type: DataType, variant_type: ua.VariantType) -> bool:
    """Whether a tag of `tag_type` can be bound to a node of `variant_type` (both ways)."""
    if tag_type is DataType.BOOL:
        return variant_type == ua.VariantType.Boolean
    if tag_type is DataType.STRING:
        return variant_type == ua.VariantType.String
    if tag_type.is_integer:
        return variant_type in INTEGER_VARIANTS
    return variant_type in INTEGER_VARIANTS or variant_type in FLOAT_VARIANTS


def binding_problem(tag_type: DataType, data_type: ua.NodeId, type_name: str = "") -> str | None:
    """Why a tag of `tag_type` cannot be bound to a node whose DataType is `data_type`, or None."""
    variant_type = variant_type_of(data_type)
    shown = type_name or (variant_type.name if variant_type is not None else data_type.to_string())
    if variant_type is None:
        return f"the remote node's DataType is {shown}, not a type a tag can have (Boolean, integers, Float, Double, String)"
    if not accepts(tag_type, variant_type):
        wanted = {DataType.BOOL: "Boolean", DataType.STRING: "String"}.get(tag_type)
        if wanted is None:
            wanted = "an integer type" if tag_type.is_integer else "an integer, Float or Double"
        return f"the remote node is {shown}, the tag is {tag_type.value} (which needs {wanted})"
    return None


def tag_value(tag_type: DataType, variant: ua.Variant | None) -> Any:
    """The tag value a remote Variant stands for; ValueError says why there is none."""
    if variant is None or variant.VariantType == ua.VariantType.Null or variant.Value is None:
        raise ValueError("the remote sent no value (null)")
    if variant.is_array or isinstance(variant.Value, (list, tuple)):
        raise ValueError(f"the remote sent an array of {variant.VariantType.name}, not one value")
    if not accepts(tag_type, variant.VariantType):
        raise ValueError(f"the remote sent {variant.VariantType.name} {variant.Value!r} for a {tag_type.value} tag")
    try:
        return tag_type.coerce(variant.Value)
    except TypeMismatch as error:
        raise ValueError(f"the remote sent {variant.VariantType.name} {variant.Value!r}: {error}") from None


def remote_variant(value: Any, variant_type: ua.VariantType) -> ua.Variant:
    """`value` as a Variant of the node's own type; ValueError when it does not fit."""
    if variant_type in INTEGER_VARIANTS:
        if isinstance(value, float):
            if not math.isfinite(value) or not value.is_integer():
                raise ValueError(f"{value!r} is not a whole number: the remote node is {variant_type.name}")
            value = int(value)
        low, high = INTEGER_VARIANTS[variant_type]
        if not low <= value <= high:
            raise ValueError(f"{value} does not fit the remote node's {variant_type.name} ({low}..{high})")
        return ua.Variant(int(value), variant_type)
    if variant_type in FLOAT_VARIANTS:
        return ua.Variant(float(value), variant_type)
    return ua.Variant(value, variant_type)


def status_text(status: ua.StatusCode) -> str:
    """A StatusCode's name, e.g. BadOutOfRange (its number when the name is unknown)."""
    try:
        return status.name
    except Exception:  # an unknown code from a third-party server
        return f"0x{status.value:08X}"
