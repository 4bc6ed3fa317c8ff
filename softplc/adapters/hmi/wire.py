"""JSON for the browser: command results and alarm snapshots as data `JSON.parse` accepts.

Python's `json` writes NaN and Infinity, which no browser parses: a float that is not finite
travels as the text "NaN", "Infinity" or "-Infinity" (as tag values do, `fanout.wire_value`).
Enums travel as their value, dataclasses as dicts, tuples and sets as lists; anything else a
command returns becomes its text rather than a failed answer.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Mapping
from typing import Any

from aiohttp import web

from softplc.adapters.hmi.fanout import wire_value


def json_ready(value: Any) -> Any:
    """`value` with every part JSON can carry as it is, the rest converted (see the module docstring)."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else wire_value(value)
    if isinstance(value, Mapping):
        return {str(key.value if isinstance(key, enum.Enum) else key): json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [json_ready(item) for item in value]
    if isinstance(value, enum.Enum):
        return json_ready(value.value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        to_dict = getattr(value, "to_dict", None)
        return json_ready(to_dict() if callable(to_dict) else dataclasses.asdict(value))
    return str(value)


def dumps(value: Any) -> str:
    """Compact JSON of `json_ready(value)`; never NaN or Infinity."""
    try:  # most values need no conversion but of enums and dataclasses: json's C encoder, 20-50x faster
        return json.dumps(value, separators=(",", ":"), ensure_ascii=False, allow_nan=False, default=_default)
    except (ValueError, TypeError):  # a non-finite float, or a key json cannot take: convert everything
        return json.dumps(json_ready(value), separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def _default(value: Any) -> Any:
    """What json's encoder cannot write itself (enums, dataclasses, sets...), converted."""
    return json_ready(value)


def json_response(value: Any, *, status: int = 200) -> web.Response:
    return web.Response(text=dumps(value), status=status, content_type="application/json")
