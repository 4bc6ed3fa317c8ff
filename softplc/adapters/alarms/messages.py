"""Alarm messages with placeholders: `"Input buffer of t01 at {t01_iBL:.0f} %"`.

`{NAME}` or `{NAME:SPEC}` is replaced by a tag's value (formatted with Python's format SPEC) or
by one of the alarm's own fields (`{value}`, `{limit}`, `{level}`, `{name}`); `{{` and `}}` are
literal braces. Tag names may contain dots (`{_sys.plant.overruns}`), so this is not str.format.
The engine parses each message once (`Template`) and renders it at every transition.
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


class Template:
    """A message parsed once: literal text and placeholders, rendered many times (an alarm flood renders thousands a second)."""

    __slots__ = ("parts",)

    def __init__(self, text: str) -> None:
        # (literal, None, "") or ("", name, spec, whole) in order; literal braces already unescaped.
        self.parts: list[tuple[str, str | None, str, str]] = []
        position = 0
        for match in _PLACEHOLDER.finditer(text):
            self._literal(text[position:match.start()])
            position = match.end()
            whole = match.group(0)
            if whole in ("{{", "}}"):
                self._literal(whole[0])
            else:
                self.parts.append(("", match.group(1).strip(), match.group(2) or "", whole))
        self._literal(text[position:])

    def _literal(self, text: str) -> None:
        if not text:
            return
        if self.parts and self.parts[-1][1] is None:
            text = self.parts.pop()[0] + text
        self.parts.append((text, None, "", ""))

    def render(self, value_of: Callable[[str], Any], fields: Mapping[str, Any]) -> str:
        """The text with each placeholder replaced; a value that does not fit its format spec is shown plainly."""
        out: list[str] = []
        for literal, name, spec, whole in self.parts:
            if name is None:
                out.append(literal)
                continue
            try:
                value = fields[name] if name in fields else value_of(name)
            except KeyError:
                out.append(whole)
                continue
            if value is None:
                continue
            try:
                out.append(format(value, spec))
            except (ValueError, TypeError):
                out.append(str(value))
        return "".join(out)


def render(text: str, value_of: Callable[[str], Any], fields: Mapping[str, Any]) -> str:
    """`text` with each placeholder replaced (see `Template`)."""
    return Template(text).render(value_of, fields)
