"""Forcing: an engineer pins a tag to a value, whatever programs, clients or robots write.

The CODESYS semantics: a forced value is in the image the programs read, and whatever a program
writes to a forced tag is dropped when the cycle commits (as if the force were applied again
after the programs ran), so the forced value is what every protocol, the HMI and the robots see.
Client writes to a forced tag are refused (rule FORCED); a robot driver's writes to it are
dropped. Forces and unforces take effect at the next cycle boundary, like client writes.

- **unforce** leaves the tag at the forced value until its owner (a program, a driver, a client)
  writes it again;
- **unforce and restore** puts back the value the tag had when it was forced.

Forces are not retained: a restart starts with nothing forced (the runtime says how many forces
a stop removed). Forced tags carry `Tag.forced`; adapters show it (OPC UA GoodLocalOverride,
the HMI's "F").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from softplc.core.origin import Origin


@dataclass(frozen=True, slots=True)
class Force:
    """One forced tag: the value, who forced it and when, and the value it had before."""

    tag: str
    value: Any
    origin: Origin
    since: float  # wall-clock seconds of the runtime clock
    previous: Any


@dataclass(frozen=True, slots=True)
class ForceChange:
    """A force (`value` given) or an unforce waiting in the write journal for the next cycle boundary."""

    tag: str
    force: bool
    value: Any = None
    origin: Origin | None = None
    since: float = 0.0
    restore: bool = False


class Forces:
    """The forces in effect in one tag database (changes wait in its write journal, in arrival order)."""

    def __init__(self) -> None:
        self._active: dict[str, Force] = {}
        self._requested: dict[str, int] = {}  # tag → changes waiting in the journal
        self.changes = 0  # forces set or released so far (a standby's copy is refreshed when it grows)

    def __contains__(self, name: object) -> bool:
        return name in self._active

    def __len__(self) -> int:
        return len(self._active)

    def get(self, name: str) -> Force | None:
        return self._active.get(name)

    def active(self) -> list[Force]:
        """The forces in effect, in the order they were set."""
        return list(self._active.values())

    def requested(self, name: str) -> bool:
        """Whether a force or unforce of the tag waits for the next cycle boundary."""
        return name in self._requested

    def note_request(self, name: str) -> None:
        self._requested[name] = self._requested.get(name, 0) + 1

    def forget_requests(self) -> None:
        """The journal was discarded: no change waits any more."""
        self._requested.clear()

    def replace(self, forces: list[Force]) -> None:
        """The forces in effect are exactly these (a standby mirroring its active)."""
        self._active = {force.tag: force for force in forces}
        self.changes += 1

    def apply(self, change: ForceChange, current: Any) -> Force | None:
        """Carry out a journaled change; returns the force it released (an unforce), else None."""
        self.changes += 1
        left = self._requested.get(change.tag, 1) - 1
        if left:
            self._requested[change.tag] = left
        else:
            self._requested.pop(change.tag, None)
        if change.force:
            held = self._active.get(change.tag)
            assert change.origin is not None
            previous = held.previous if held is not None else current
            self._active[change.tag] = Force(change.tag, change.value, change.origin, change.since, previous)
            return None
        return self._active.pop(change.tag, None)
