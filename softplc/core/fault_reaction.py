"""A program's fault reaction: what its outputs do in the scan in which it faults (`on_fault:`), and its restart policy (`restart:`).

Like a PLC output module's reaction to a CPU fault, per program:

- `hold` (the default): every output keeps the last value the program committed;
- `initial`: every tag bound to an `Output` variable goes back to its declared `initial` value
  (`InOut` variables are the program's state as much as its outputs — counters, handshakes —
  and keep theirs unless named in `safe`);
- `{safe: {TAG: VALUE, ...}, others: hold|initial}`: the named tags (Outputs or InOuts of the
  program, checked at load time) take the given safe values, the others hold (or go initial).

The reaction's values are committed by the very cycle in which the program faults (instead of
that scan's outputs, which are discarded), so the first values any protocol, robot or other
program sees after the fault are the safe ones. A fault outside a cycle (a failing setup() at
start-up or at a reset, a stall) commits them at once. A forced tag stays forced.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from softplc.core.tags import TagDef

HOLD = "hold"
INITIAL = "initial"


class _Definitions(Protocol):
    def __getitem__(self, name: str) -> Any: ...  # a Tag (with .definition), as in TagDatabase


@dataclass(frozen=True)
class FaultReaction:
    """The values a faulted program's outputs take: `safe` ones, and `others` held or set to their initial."""

    safe: Mapping[str, Any] = field(default_factory=dict)  # tag → value, validated at load time
    others: str = HOLD  # HOLD | INITIAL

    @property
    def holds(self) -> bool:
        """Whether the reaction leaves every output as it is (nothing to commit)."""
        return not self.safe and self.others == HOLD

    def values(self, output_tags: Iterable[str], tags: _Definitions) -> dict[str, Any]:
        """The tag values of the reaction for a program whose Output variables are bound to `output_tags`."""
        if self.holds:
            return {}
        values: dict[str, Any] = {}
        if self.others == INITIAL:
            for name in output_tags:
                definition: TagDef = tags[name].definition
                values[name] = definition.initial
        values.update(self.safe)  # InOuts change only when named here (see the module's docstring)
        return values

    def describe(self) -> str | dict[str, Any]:
        """As written in the configuration: 'hold', 'initial' or {'safe': {...}, 'others': ...}."""
        if not self.safe:
            return self.others
        return {"safe": dict(self.safe), "others": self.others}


@dataclass(frozen=True)
class RestartPolicy:
    """Whether a faulted program is restarted by itself: `delay` s after the fault, at most `max_restarts` times."""

    automatic: bool = False  # False: `restart: never` (the default), it stays FAULTED until a reset
    delay: float = 1.0
    max_restarts: int = 3

    def describe(self) -> str | dict[str, Any]:
        """As written in the configuration: 'never' or {'delay': seconds, 'max': n}."""
        return {"delay": self.delay, "max": self.max_restarts} if self.automatic else "never"


NEVER = RestartPolicy()
