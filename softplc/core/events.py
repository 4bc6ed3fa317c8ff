"""Events: things that happen in a running plant, published once and heard by every adapter.

An event is not a tag value: an alarm that becomes active, is acknowledged or shelved; later,
whatever else an owner module has to announce. The module that owns the event publishes it
(`runtime.events.publish(Event(...))`); adapters subscribe (OPC UA turns alarm events into
AlarmConditionType events, the HMI pushes them to its banner, a journal stores them), so no
adapter reaches into another. Subscribers are called synchronously on the event loop: queue work,
don't do I/O in the callback.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Event:
    """One event: its kind (e.g. 'alarm'), when (wall-clock seconds of the runtime clock), its
    source (e.g. the alarm's name) and kind-specific data."""

    kind: str
    time: float
    source: str
    data: Mapping[str, Any] = field(default_factory=dict)


EventListener = Callable[[Event], None]


class EventBus:
    """Publish events to the subscribers of their kind."""

    def __init__(self) -> None:
        self._listeners: list[tuple[EventListener, frozenset[str] | None]] = []

    def subscribe(self, listener: EventListener, kinds: Collection[str] | None = None) -> Callable[[], None]:
        """Call `listener(event)` for each event (of the given kinds only, if given); returns an unsubscribe."""
        entry = (listener, frozenset(kinds) if kinds is not None else None)
        self._listeners.append(entry)
        return lambda: self._listeners.remove(entry)

    def publish(self, event: Event) -> None:
        for listener, kinds in list(self._listeners):
            if kinds is not None and event.kind not in kinds:
                continue
            try:
                listener(event)
            except Exception:  # a broken subscriber must never stop the publisher (the scan)
                log.exception("event subscriber %r failed on %s event", listener, event.kind)
