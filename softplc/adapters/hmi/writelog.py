"""The HMI's write log: every write and command made from a browser or the JSON API, accepted or refused, with its user.

It listens on the tag database's write listeners (`db.on_write`), the hook the durable audit
trail uses as well, and keeps only the writes whose origin is the HMI. A script that writes in
a loop must not flood the log: each user gets `burst` lines per `interval` seconds, then one
summary line per interval for the rest (real time, like every network-facing limit).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from softplc.adapters.hmi.untrusted import clip, shown
from softplc.core.tagdb import Origin, WriteEvent

log = logging.getLogger("softplc.adapters.hmi")

SOURCE = "hmi"
NAME_SHOWN = 200  # characters of a tag or command name in a line (the HMI's own refusals come clipped to 100 already)


def _repr(value: Any) -> str:
    """A value as the log shows it: repr, at most a few hundred characters."""
    if isinstance(value, str):
        return repr(clip(value))
    return repr(value) if isinstance(value, (bool, int, float)) or value is None else repr(shown(value))


@dataclass
class _Budget:
    lines: int = 0
    suppressed: int = 0
    refused: int = 0
    tags: dict[str, None] = field(default_factory=dict)


class WriteLog:
    """`db.on_write` listener that logs the HMI's writes (and, told by the commands door, its commands), rate-limited per user."""

    def __init__(self, interval: float = 10.0, burst: int = 5) -> None:
        self.interval = interval
        self.burst = burst
        self._budgets: dict[str, _Budget] = {}

    def __call__(self, events: Sequence[WriteEvent]) -> None:
        for event in events:
            if event.origin.source == SOURCE:
                self._log(event)

    def command(self, origin: Origin, name: str, accepted: bool, detail: str) -> None:
        """Log a state-changing command called through the HMI (the same budget per user as writes)."""
        budget = self._budget(str(origin)) or _Budget()
        budget.lines += 1
        if budget.lines > self.burst:
            budget.suppressed += 1
            budget.refused += not accepted
            if len(budget.tags) < 5:
                budget.tags[f"command {clip(name, NAME_SHOWN)}"] = None
            return
        role = origin.role.value if origin.role is not None else "runtime"
        if accepted:
            log.info("HMI command by %s (%s): %s%s", origin, role, name, f": {clip(detail)}" if detail else "")
        else:
            log.warning("HMI command by %s (%s) refused: %s: %s", origin, role, clip(name, NAME_SHOWN), clip(detail))

    def _budget(self, who: str) -> _Budget | None:
        """This interval's budget of `who` (None without an event loop: log every line)."""
        budget = self._budgets.get(who)
        if budget is None:
            budget = self._budgets[who] = _Budget()
            try:
                asyncio.get_running_loop().call_later(self.interval, self._summarise, who)
            except RuntimeError:  # no loop: nothing to summarise later
                del self._budgets[who]
                return None
        return budget

    def _log(self, event: WriteEvent) -> None:
        who = str(event.origin)
        budget = self._budget(who) or _Budget()
        budget.lines += 1
        if budget.lines > self.burst:
            budget.suppressed += 1
            budget.refused += not event.accepted
            if len(budget.tags) < 5:
                budget.tags[clip(event.tag, NAME_SHOWN)] = None
            return
        role = event.origin.role.value if event.origin.role is not None else "runtime"
        # A line holds at most a few hundred characters of what the client sent (a value may be 1 MB of text).
        if event.accepted:
            log.info("HMI write by %s (%s): %s = %s (was %s)", who, role, event.tag, _repr(event.new), _repr(event.old))
        else:
            log.warning("HMI write by %s (%s) refused: %s = %s: %s: %s", who, role, clip(event.tag, NAME_SHOWN), _repr(event.new),
                        event.rule.value if event.rule else "refused", clip(event.detail))

    def _summarise(self, who: str) -> None:
        budget = self._budgets.pop(who, None)
        if budget is None or not budget.suppressed:
            return
        log.warning("HMI: %d more writes by %s in the last %g s (%d refused; tags %s)", budget.suppressed, who,
                    self.interval, budget.refused, ", ".join(budget.tags))
