"""Tags: a declared, typed value with a quality and a timestamp."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

from softplc.core.datatypes import DataType


class Quality(enum.Enum):
    """OPC-style quality of a tag's value."""

    GOOD = "good"
    UNCERTAIN = "uncertain"
    BAD = "bad"


class Access(enum.Enum):
    """Who may write a tag. `ro` is read-only for clients; programs may always write."""

    RW = "rw"
    RO = "ro"


@dataclass(frozen=True, slots=True)
class TagDef:
    """The declaration of a tag, as written in `tagdb.yaml` (after template expansion)."""

    name: str
    type: DataType
    initial: Any
    unit: str = ""
    description: str = ""
    access: Access = Access.RW
    min: float | None = None
    max: float | None = None
    retain: bool = False
    group: str = ""
    # Written by the runtime alone (diagnostic `_sys.` tags): no client may write it, whatever its role.
    runtime_only: bool = False
    # Adapter-specific options (e.g. `modbus: {address: 100, scale: 10}`), validated by the
    # configuration schema and interpreted only by the adapter they belong to.
    options: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def writable_by_clients(self) -> bool:
        return self.access is Access.RW


class Tag:
    """A tag's declaration and its current state. Only TagDatabase changes the state."""

    __slots__ = ("definition", "value", "quality", "timestamp", "forced")

    def __init__(self, definition: TagDef, timestamp: float) -> None:
        self.definition = definition
        self.value: Any = definition.initial
        self.quality = Quality.GOOD
        self.timestamp = timestamp
        self.forced = False  # pinned by an engineer (softplc/core/forcing.py): adapters show it

    @property
    def name(self) -> str:
        return self.definition.name

    def __repr__(self) -> str:
        return f"<Tag {self.name}={self.value!r} {self.quality.value}{' forced' if self.forced else ''}>"
