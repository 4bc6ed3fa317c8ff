"""Alarm messages with placeholders: `"Input buffer of t01 at {t01_iBL:.0f} %"`.

`{NAME}` or `{NAME:SPEC}` is replaced by a tag's value (formatted with Python's format SPEC) or
by one of the alarm's own fields (`{value}`, `{limit}`, `{level}`, `{name}`); `{{` and `}}` are
literal braces. Tag names may contain dots (`{_sys.plant.overruns}`), so this is not str.format.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Any

FIELDS = ("value", "limit", "level", "name", "tag")
_PLACEHOLDER = re.compile(r"\{\{|\}\}|\{([^{}:]*)(?::([^{}]*))?\}")


class MessageError(ValueError):
    """A message whose placeholders cannot be filled."""


def placeholders(text: str) -> list[tuple[str, str]]:
    """The (name, format spec) of every placeholder in `text`; raises MessageError on a stray brace."""
    found: list[tuple[str, str]] = []
    position = 0
    for match in _PLACEHOLDER.finditer(text):
        _check_literal(text[position:match.start()])
        position = match.end()
        if match.group(0) in ("{{", "}}"):
            continue
        name = match.group(1).strip()
        if not name:
            raise MessageError("empty placeholder {} in message: write {TAG} or {value}")
        found.append((name, match.group(2) or ""))
    _check_literal(text[position:])
    return found


def _check_literal(text: str) -> None:
    if "{" in text or "}" in text:
        raise MessageError("unmatched brace in message: write {{ or }} for a literal brace")


def render(text: str, value_of: Callable[[str], Any], fields: Mapping[str, Any]) -> str:
    """`text` with each placeholder replaced; a value that does not fit its format spec is shown plainly."""

    def replace(match: re.Match[str]) -> str:
        whole = match.group(0)
        if whole == "{{":
            return "{"
        if whole == "}}":
            return "}"
        name, spec = match.group(1).strip(), match.group(2) or ""
        try:
            value = fields[name] if name in fields else value_of(name)
        except KeyError:
            return whole
        if value is None:
            return ""
        try:
            return format(value, spec)
        except (ValueError, TypeError):
            return str(value)

    return _PLACEHOLDER.sub(replace, text)
