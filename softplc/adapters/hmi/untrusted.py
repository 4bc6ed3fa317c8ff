"""What a client sends, read within bounds: JSON however deeply nested, and names or values however long.

A request body may hold up to 1 MB and a live-channel message 2 MB, which is room for a JSON
array nested 100,000 deep (Python's parser gives up with a RecursionError, not a ValueError) or
for a "tag name" of a million characters. Whatever is parsed here answers with a clear message,
and whatever is echoed into an answer, a log line or the audit trail is shown clipped.
"""

from __future__ import annotations

import json
from typing import Any

MAX_SHOWN = 200  # characters of a client's value in a log line, an answer or a refused audit entry
MAX_NAME_SHOWN = 100  # characters of a name a client gave (no tag or command is named at such length)


class BadJson(ValueError):
    """A body or message that is not JSON we can read; the text says why, for the client."""


def loads(data: str | bytes) -> Any:
    """The JSON value of `data`, or BadJson saying what it is: "not JSON" (or not UTF-8), "JSON nested too deeply"."""
    try:
        return json.loads(data)
    except RecursionError:
        raise BadJson("JSON nested too deeply") from None
    except ValueError:  # UnicodeDecodeError included
        raise BadJson("not JSON") from None


def clip(text: str, limit: int = MAX_SHOWN) -> str:
    """`text`, or its first `limit` characters and how long it was."""
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"


def shown(value: Any, limit: int = MAX_SHOWN) -> Any:
    """A client's value as it may be logged, echoed or audited: numbers and booleans as they are, text clipped,
    anything else (arrays, objects) as its JSON text, clipped."""
    if value is None or isinstance(value, (bool, int, float)):
        return value
    if isinstance(value, str):
        return clip(value, limit)
    try:
        text = json.dumps(value, ensure_ascii=False, default=str)
    except (RecursionError, ValueError, TypeError):
        text = f"({type(value).__name__} that cannot be shown)"
    return clip(text, limit)


def shown_name(name: Any) -> str:
    """A name a client gave (a tag, a command), as text that may be logged or audited."""
    return clip(name, MAX_NAME_SHOWN) if isinstance(name, str) else str(shown(name, MAX_NAME_SHOWN))
