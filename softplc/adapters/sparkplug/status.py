"""The edge node's state as `_sys.sparkplug.*` tags (the HMI's Tasks page, OPC UA, alarms) and figures (/metrics)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from softplc.core.tagdb import Origin, TagDatabase

PREFIX = "_sys.sparkplug."
SOURCE = Origin("sparkplug", role=None)

OFF = "off"
CONNECTING = "connecting"
WAITING = "waiting for primary host"
ONLINE = "online"
STANDBY = "standby (the active publishes)"


@dataclass
class Status:
    """What the tags show; `publish` writes the values that changed since it last wrote."""

    running: bool = False
    state: str = OFF
    connected: bool = False
    primary_host_online: bool = False
    bdseq: int = 0
    births: int = 0
    messages: int = 0
    metrics: int = 0
    stored: int = 0
    dropped: int = 0
    commands: int = 0
    refused: int = 0
    last_refusal: str = ""

    def __post_init__(self) -> None:
        self._written: dict[str, Any] = {}

    def publish(self, tags: TagDatabase) -> None:
        """Journal the changed values (applied at the next scan boundary, like any write)."""
        values = {PREFIX + key: value for key, value in asdict(self).items()}
        changed = [(name, value) for name, value in values.items() if self._written.get(name, not value) != value and name in tags]
        if changed:
            # Counters wrap like a PLC's: a uint32 tag holds the low 32 bits.
            tags.submit([(name, value % 2**32 if isinstance(value, int) and not isinstance(value, bool) else value) for name, value in changed], SOURCE)
            self._written.update(changed)

    def figures(self) -> dict[str, Any]:
        return {
            "connected": int(self.connected), "online": int(self.state == ONLINE), "births": self.births,
            "messages": self.messages, "metrics": self.metrics, "stored": self.stored, "dropped": self.dropped,
            "commands": {"accepted": self.commands, "refused": self.refused},
        }
