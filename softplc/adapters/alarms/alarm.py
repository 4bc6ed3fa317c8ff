"""One alarm as the engine keeps it: its definition, its compiled check and message, its mutable state.

The engine (`engine.py`) alone changes an `Alarm`; adapters get `AlarmSnapshot`s of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from softplc.adapters.alarms.evaluation import Check, DiscreteCheck, IncreaseCheck, LimitCheck
from softplc.adapters.alarms.messages import Template
from softplc.adapters.alarms.settings import AlarmDefinition
from softplc.core.alarms import AlarmSnapshot, AlarmState, Priority, Shelving, effective_state
from softplc.core.tags import Tag


class Alarm:
    """One alarm's definition and mutable state (the engine's alone; adapters get snapshots)."""

    __slots__ = ("index", "definition", "check", "suppress", "plain", "fast", "watched", "low_edge", "high_edge", "alarm_values", "holds",
                 "level", "priority_level", "priority", "rank", "severity", "level_limit", "levels", "template", "constant",
                 "active", "pending_due", "delay_generation", "annunciation",
                 "shelving", "shelve_generation", "shelve_due", "suppressed", "out_of_service", "since", "active_since", "last_transition",
                 "sequence", "message", "value", "comment", "comment_user")

    def __init__(self, index: int, definition: AlarmDefinition, check: Check, suppress: Callable[[], object] | None) -> None:
        self.index = index
        self.definition = definition
        self.check = check
        self.suppress = suppress  # the compiled suppress_when
        # No suppression and no counting window: evaluated inline by AlarmEngine.evaluate.
        self.plain = definition.suppress_when is None and not isinstance(check, IncreaseCheck)
        # A plain limit alarm that is normal stays normal while its tag is between its edges, a
        # plain discrete one while its tag is none of its alarm values: the engine tests that
        # inline, without calling the check (most alarms, most scans). fast: 1 limit, 2 discrete,
        # 3 a condition (its compiled expression called inline).
        self.fast = 0
        self.holds: Callable[[], object] | None = getattr(check, "holds", None)
        self.watched: Tag | None = None
        self.low_edge, self.high_edge, self.alarm_values = math.inf, -math.inf, frozenset[object]()
        if self.plain and isinstance(check, LimitCheck):
            self.fast, self.watched, self.low_edge, self.high_edge = 1, check.tag, check.low_edge, check.high_edge
        elif self.plain and isinstance(check, DiscreteCheck) and check.mode == "value":
            self.fast, self.watched, self.alarm_values = 2, check.tag, frozenset(check.values)
        elif self.plain and self.holds is not None:
            self.fast = 3
        self.level = ""  # "" while the process is normal (after delays)
        # The level whose priority, severity and limit the alarm has: the last it was active in,
        # kept when it returns to normal (ISA-18.2: an alarm's priority does not change as it clears).
        self.priority_level = ""
        self.priority: Priority = definition.priority
        self.rank = definition.priority.rank
        self.severity: int = definition.severity
        self.level_limit: float | None = None  # the limit of priority_level
        self.levels = {level.name: level for level in definition.levels}
        self.template = Template(definition.message)
        # What every snapshot of this alarm shares (made once: a flood makes thousands a second).
        self.constant = {"name": definition.name, "kind": definition.kind, "tag": definition.source, "group": definition.group,
                         "description": definition.description, "latching": definition.latching, "tags": definition.reads,
                         "limits": definition.limits}
        self.active = False
        self.pending_due: float | None = None  # an on/off delay running until then (clock time)
        self.delay_generation = 0
        self.annunciation = AlarmState.NORMAL
        self.shelving: Shelving | None = None
        self.shelve_generation = 0
        self.shelve_due: float | None = None  # clock time the current shelving expires (its timer)
        self.suppressed = False
        self.out_of_service = False
        self.since = 0.0
        self.active_since: float | None = None
        self.last_transition = ""
        self.sequence = 0
        self.message = ""
        self.value: object = None
        self.comment = ""
        self.comment_user = ""

    @property
    def name(self) -> str:
        return self.definition.name

    @property
    def hidden(self) -> bool:
        return self.shelving is not None or self.suppressed or self.out_of_service

    @property
    def state(self) -> AlarmState:
        if not (self.out_of_service or self.suppressed or self.shelving is not None):
            return self.annunciation  # the usual case, without a call
        return effective_state(self.annunciation, shelved=self.shelving is not None, suppressed=self.suppressed,
                               out_of_service=self.out_of_service)

    @property
    def limit(self) -> float | None:
        """The limit of the level the alarm is in (None while normal)."""
        return self.level_limit if self.level else None

    def enter_level(self, level: str) -> None:
        """Be in `level` ("" back to normal: the priority, severity and limit of the last level stay)."""
        self.level = level
        if level:
            self.priority_level = level
            found = self.levels.get(level)
            if found is not None:
                self.priority, self.severity, self.level_limit = found.priority, found.severity, found.limit
                self.rank = found.priority.rank

    def snapshot(self) -> AlarmSnapshot:
        """The alarm as adapters see it, now."""
        fields = self.constant.copy()
        fields.update(
            priority=self.priority, severity=self.severity, state=self.state, annunciation=self.annunciation, active=self.active,
            message=self.message or self.name, value=self.value, level=self.level, limit=self.level_limit if self.level else None,
            shelving=self.shelving, suppressed=self.suppressed, out_of_service=self.out_of_service, since=self.since,
            active_since=self.active_since, last_transition=self.last_transition, sequence=self.sequence, comment=self.comment,
            comment_user=self.comment_user,
        )
        return AlarmSnapshot.from_fields(fields)
