"""Counters fed by the core's listeners: client writes by source and result, command calls by name and result.

`db.on_write` hands every client write, accepted or refused, with its origin (the audit trail's
hook); `commands.on_call` every call of a command that acts. Each event costs one dictionary
increment on the event loop — never in the scan: writes are reported where adapters submit them.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

from softplc.core.commands import CommandCall, Commands
from softplc.core.tagdb import WriteEvent

ACCEPTED = "accepted"


def rule_label(rule: str) -> str:
    """A refusal's rule as a label value: 'out of range' → 'out_of_range'."""
    return rule.replace(" ", "_").replace("-", "_")


class WriteCounts:
    """`db.on_write` listener: writes[(source, result)] where result is 'accepted' or the rule broken."""

    def __init__(self) -> None:
        self.writes: Counter[tuple[str, str]] = Counter()

    def __call__(self, events: Sequence[WriteEvent]) -> None:
        writes = self.writes
        for event in events:
            rule = event.rule
            writes[event.origin.source, ACCEPTED if rule is None else rule_label(rule.value)] += 1


class CommandCounts:
    """`commands.on_call` listener: calls[(command, 'accepted' | 'refused')]."""

    def __init__(self, commands: Commands) -> None:
        self.commands = commands
        self.calls: Counter[tuple[str, str]] = Counter()

    def __call__(self, call: CommandCall) -> None:
        # A client may call any name: unknown ones share one label, so the series stay few.
        name = call.command if call.command in self.commands else "unknown"
        self.calls[name, ACCEPTED if call.accepted else "refused"] += 1
