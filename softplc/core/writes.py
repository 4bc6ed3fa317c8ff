"""What a write is and what it may break: the journal's entries, the events listeners see, the rules.

Shared by the tag database (which journals and validates writes, `softplc/core/tagdb.py`) and
every adapter that maps a refused write to its protocol's status (OPC UA, Modbus, the HMI).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

from softplc.core.origin import Origin
from softplc.core.tags import Quality


class Rule(enum.Enum):
    """The rule a rejected write broke. Adapters map these to their protocol's status codes."""

    UNKNOWN_TAG = "unknown tag"
    READ_ONLY = "read-only"
    TYPE_MISMATCH = "type mismatch"
    OUT_OF_RANGE = "out of range"
    ACCESS_DENIED = "access denied"  # the writer's role may not write at all (a viewer)
    INVALID_REQUEST = "invalid request"  # refused by the protocol before any tag rule (e.g. a quality, an index range)
    FORCED = "forced"  # the tag is forced by an engineer: unforce it first
    NOT_ACTIVE = "not active"  # this runtime is the standby (or fenced) of a redundant pair: write to the active


class WriteRejected(Exception):
    """A write that broke a rule; nothing of it was applied."""

    def __init__(self, tag: str, rule: Rule, detail: str) -> None:
        super().__init__(f"{tag}: {rule.value}: {detail}")
        self.tag = tag
        self.rule = rule
        self.detail = detail


KEEP_VALUE: Any = object()  # a journaled quality change: the tag keeps the value it has when applied


@dataclass(frozen=True, slots=True)
class Write:
    """One journaled write: a new value (and optionally a quality) for a tag."""

    tag: str
    value: Any
    origin: Origin
    quality: Quality = Quality.GOOD


@dataclass(frozen=True, slots=True)
class WriteEvent:
    """A client's write of one tag, accepted (journaled) or refused, as `on_write` listeners see it."""

    time: float  # wall-clock seconds of the runtime clock (simulated under --sim)
    origin: Origin
    tag: str
    old: Any  # the tag's value when the write arrived (None for an unknown tag)
    new: Any  # the value asked for (coerced to the tag's type when accepted)
    rule: Rule | None = None  # the rule broken; None when accepted
    detail: str = ""

    @property
    def accepted(self) -> bool:
        return self.rule is None
