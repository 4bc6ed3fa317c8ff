"""The tag changes waiting to be published: per device, in the order they happened, with their Quality property."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from softplc.adapters.sparkplug.settings import Device
from softplc.core.tagdb import TagDatabase
from softplc.core.tags import Quality, Tag
from softplc.protocols.sparkplug.datatypes import QUALITY_BAD, QUALITY_GOOD, QUALITY_STALE
from softplc.protocols.sparkplug.metrics import MetricDefinition
from softplc.protocols.sparkplug.payloads import Change

# softplc's qualities as Sparkplug's codes (§6.4.7): uncertain is sent as STALE, the closest.
QUALITY_CODES = {Quality.GOOD: QUALITY_GOOD, Quality.BAD: QUALITY_BAD, Quality.UNCERTAIN: QUALITY_STALE}

Noted = tuple[Any, Quality, float]  # value, quality, timestamp (seconds) of a change
Pending = dict[str, Noted]  # tag → its last change
Held = list[tuple[str, Noted]]  # every change, in order


class Changes:
    """What changed since the last data messages (`pending`), grouped into one batch per device on demand."""

    def __init__(self, devices: Sequence[Device]) -> None:
        self.metric_of: dict[str, tuple[Device, MetricDefinition]] = {
            tag: (device, definition) for device in devices for tag, definition in device.metrics.items()}
        self.devices = devices
        self.pending: Pending = {}
        self._not_good: set[str] = set()  # tags whose last published quality was not GOOD

    def note(self, tags: Iterable[Tag]) -> None:
        """A tag-change batch (on the loop, in the scan's path): each metric's last change, in order."""
        metric_of, pending = self.metric_of, self.pending
        for tag in tags:
            name = tag.definition.name
            if name in metric_of:
                pending.pop(name, None)  # moved to the end: a message lists changes in the order they happened
                pending[name] = (tag.value, tag.quality, tag.timestamp)

    def take(self) -> Pending:
        pending, self.pending = self.pending, {}
        return pending

    def batches(self, changes: Pending | Held) -> list[tuple[Device, list[Change]]]:
        """The changes as (device, its metrics' changes), devices in the order their first change came."""
        by_device: dict[str, tuple[Device, list[Change]]] = {}
        metric_of = self.metric_of
        for name, (value, quality, stamp) in changes.items() if isinstance(changes, dict) else changes:
            device, definition = metric_of[name]
            entry = by_device.get(device.id)
            if entry is None:
                entry = by_device[device.id] = (device, [])
            entry[1].append((definition, value, self.quality(name, quality), round(stamp * 1000)))
        return list(by_device.values())

    def births(self, tags: TagDatabase) -> list[tuple[Device, list[Change]]]:
        """Every metric of every device with its current value, for the DBIRTHs; nothing is pending any more."""
        self.pending.clear()
        self._not_good = set()
        found = []
        for device in self.devices:
            metrics = []
            for name, definition in device.metrics.items():
                tag = tags[name]
                metrics.append((definition, tag.value, self.quality(name, tag.quality, birth=True), round(tag.timestamp * 1000)))
            found.append((device, metrics))
        return found

    def quality(self, name: str, quality: Quality, *, birth: bool = False) -> int | None:
        """The Quality property to send with a value: when it is not GOOD, and once when it is GOOD again."""
        if quality is not Quality.GOOD:
            self._not_good.add(name)
            return QUALITY_CODES[quality]
        if not birth and name in self._not_good:
            self._not_good.discard(name)
            return QUALITY_GOOD
        return None
