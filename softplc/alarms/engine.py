"""The alarm engine: owns every alarm's state, evaluates at scan boundaries, publishes each transition.

    engine = AlarmEngine(settings, runtime.db, runtime.clock, runtime.events.publish)
    runtime.db.on_change(engine.note_changed)      # which alarms must be looked at
    runtime.engine.after_cycle(lambda task: engine.evaluate())

Only alarms whose tags changed are evaluated (an index tag → alarms), plus those whose on/off
delay, shelving or counting window falls due (a heap of timers on the runtime clock), so a
simulated run gives the same alarm history every time. Each transition — the process's or an
operator's (`actions.py`) — is published as `Event("alarm", time, name, data)` with
`data = {"transition", "alarm" (an AlarmSnapshot), "previous", "user", "origin", "role", "comment"}`.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
from collections.abc import Callable, Iterable, Sequence

from softplc.alarms.evaluation import ON, Check, DiscreteCheck, IncreaseCheck, LimitCheck, compile_condition, make_check
from softplc.alarms.messages import render
from softplc.alarms.model import (
    AlarmSnapshot, AlarmState, Priority, Shelving, ShelveKind, Transition, Trigger, UnknownAlarm, effective_state, next_state, released_state,
)
from softplc.alarms.settings import AlarmDefinition, AlarmSettings, LimitLevel
from softplc.clock import Clock
from softplc.events import Event
from softplc.suggest import did_you_mean
from softplc.tagdb import Origin, TagDatabase
from softplc.tags import Tag

log = logging.getLogger(__name__)

_DELAY, _SHELVE, _WINDOW = "delay", "shelve", "window"
_ACTIVE_STATES = frozenset({AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED})
_WAITING = frozenset(state for state in AlarmState if state.needs_acknowledgement)
_SEVERER = {("hi", "hihi"), ("lo", "lolo")}  # (from, to) pairs that escalate on the same side


class Alarm:
    """One alarm's definition and mutable state (the engine's alone; adapters get snapshots)."""

    __slots__ = ("index", "definition", "check", "suppress", "plain", "fast", "watched", "low_edge", "high_edge", "alarm_values", "holds",
                 "level", "priority_level", "active", "pending_due", "delay_generation", "annunciation",
                 "shelving", "shelve_generation", "suppressed", "out_of_service", "since", "active_since", "last_transition",
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
        self.active = False
        self.pending_due: float | None = None  # an on/off delay running until then (clock time)
        self.delay_generation = 0
        self.annunciation = AlarmState.NORMAL
        self.shelving: Shelving | None = None
        self.shelve_generation = 0
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
    def priority(self) -> Priority:
        level = self.level_definition()
        return level.priority if level is not None else self.definition.priority

    @property
    def severity(self) -> int:
        level = self.level_definition()
        return level.severity if level is not None else self.definition.severity

    @property
    def limit(self) -> float | None:
        """The limit of the level the alarm is in (None while normal)."""
        level = self.level_definition() if self.level else None
        return level.limit if level is not None else None

    def level_definition(self) -> LimitLevel | None:
        """The configured level the alarm's priority comes from (None: the alarm's own priority)."""
        if self.priority_level and self.definition.levels:
            for level in self.definition.levels:
                if level.name == self.priority_level:
                    return level
        return None


class AlarmEngine:
    """Every alarm of a plant, evaluated on the runtime clock."""

    def __init__(self, settings: AlarmSettings, db: TagDatabase, clock: Clock, publish: Callable[[Event], None]) -> None:
        self.settings = settings
        self.db = db
        self.clock = clock
        self._publish = publish
        self.alarms = [
            Alarm(index, definition, make_check(definition, db),
                  compile_condition(definition.suppress_when, db) if definition.suppress_when is not None else None)
            for index, definition in enumerate(settings.definitions)
        ]
        self.by_name = {alarm.name: alarm for alarm in self.alarms}
        index: dict[str, list[int]] = {}
        for alarm in self.alarms:
            for tag in alarm.definition.reads:
                index.setdefault(tag, []).append(alarm.index)
        self._index = {db[tag]: tuple(alarms) for tag, alarms in index.items()}
        self._dirty: set[int] = set(range(len(self.alarms)))  # the first boundary looks at every alarm
        self._timers: list[tuple[float, int, int, int, str]] = []
        self._order = itertools.count()
        # Maintained on every change of state, so the summary never walks all alarms.
        self.active_count = 0
        self.unacknowledged_count = 0
        self.shelved_count = 0
        self._active_ranks = [0] * 5  # active alarms per priority rank (1..4)
        self.changed = False  # a transition since the summary last looked
        self.evaluations = 0

    # -- what to evaluate -----------------------------------------------------------------

    def note_changed(self, tags: Sequence[Tag]) -> None:
        """A `db.on_change` callback: mark the alarms that read these tags."""
        # Keyed by the Tag objects themselves (no name lookup per change), all in C: map, filter, update.
        self._dirty.update(*filter(None, map(self._index.get, tags)))

    def next_due(self) -> float | None:
        """Clock time of the earliest pending timer (delays, shelving, windows), if any."""
        return self._timers[0][0] if self._timers else None

    def evaluate(self) -> None:
        """At a scan boundary: fire due timers, then evaluate every marked alarm."""
        now = self.clock.now()
        timers = self._timers
        dirty = self._dirty
        while timers and timers[0][0] <= now:
            _, _, index, generation, kind = heapq.heappop(timers)
            alarm = self.alarms[index]
            if kind == _SHELVE:
                if alarm.shelve_generation == generation and alarm.shelving is not None:
                    self.end_shelving(alarm, Transition.SHELVING_EXPIRED, None, "")
            elif kind == _WINDOW or alarm.delay_generation == generation:
                dirty.add(index)
        if not dirty:
            return
        self._dirty = set()
        alarms = self.alarms
        evaluate = self._evaluate
        for index in dirty:
            alarm = alarms[index]
            fast = alarm.fast
            if fast == 3:
                level = alarm.level
                try:
                    raw = ON if alarm.holds() else ""  # type: ignore[misc]
                except Exception:  # noqa: BLE001 — the check itself says what an error means
                    raw = alarm.check(level, now)
                if raw == level and alarm.pending_due is None:
                    continue
                evaluate(alarm, now, raw)
                continue
            if fast and not alarm.level and alarm.pending_due is None:
                value = alarm.watched.value  # type: ignore[union-attr]
                if fast == 1:
                    if alarm.low_edge < value < alarm.high_edge:
                        continue
                elif value not in alarm.alarm_values:
                    continue
            if alarm.plain:  # no suppression, no window: the condition is where it was?
                level = alarm.level
                raw = alarm.check(level, now)
                if raw == level and alarm.pending_due is None:
                    continue
                evaluate(alarm, now, raw)
            else:
                evaluate(alarm, now, None)
        self.evaluations += len(dirty)

    def _evaluate(self, alarm: Alarm, now: float, raw: str | None) -> None:
        definition = alarm.definition
        if alarm.suppress is not None:
            try:
                suppressed = bool(alarm.suppress())
            except (TypeError, ValueError, ArithmeticError):
                suppressed = alarm.suppressed
            if suppressed != alarm.suppressed:
                self._set_suppressed(alarm, suppressed)
        level = alarm.level
        if raw is None:
            raw = alarm.check(level, now)
        if isinstance(alarm.check, IncreaseCheck):
            due = alarm.check.next_change(now)
            if due is not None:
                self._push(due, alarm, -1, _WINDOW)
        if raw == level:
            if alarm.pending_due is not None:  # the condition flipped back before its delay ran out
                alarm.pending_due = None
                alarm.delay_generation += 1
            return
        if level and raw:  # still active, at another limit: no delay
            self._change_level(alarm, raw)
            return
        delay = definition.off_delay if level else definition.on_delay
        if delay > 0:
            if alarm.pending_due is None:
                alarm.pending_due = now + delay
                alarm.delay_generation += 1
                self._push(alarm.pending_due, alarm, alarm.delay_generation, _DELAY)
                return
            if now < alarm.pending_due:
                return
        alarm.pending_due = None
        alarm.delay_generation += 1
        if raw:
            self._activate(alarm, raw)
        else:
            self._clear(alarm)

    def _push(self, due: float, alarm: Alarm, generation: int, kind: str) -> None:
        heapq.heappush(self._timers, (due, next(self._order), alarm.index, generation, kind))

    # -- process transitions --------------------------------------------------------------

    def _activate(self, alarm: Alarm, level: str) -> None:
        before = self.counted(alarm)
        alarm.active, alarm.level, alarm.priority_level, alarm.active_since = True, level, level, self.clock.wall()
        self._render(alarm)
        self._annunciate(alarm, Trigger.ACTIVATE)
        self.recount(alarm, before)
        self.emit(alarm, Transition.ACTIVATED, before[4])

    def _clear(self, alarm: Alarm) -> None:
        before = self.counted(alarm)
        alarm.active, alarm.level, alarm.active_since = False, "", None
        self._render(alarm)  # the values at the clear; priority_level (priority, {level}, {limit}) stays
        self._annunciate(alarm, Trigger.CLEAR)
        self.recount(alarm, before)
        self.emit(alarm, Transition.CLEARED, before[4])
        shelving = alarm.shelving
        if shelving is not None and shelving.kind is ShelveKind.ONE_SHOT:
            self.end_shelving(alarm, Transition.SHELVING_EXPIRED, None, "")

    def _change_level(self, alarm: Alarm, level: str) -> None:
        before = self.counted(alarm)
        escalates = (alarm.level, level) in _SEVERER or alarm.level[:2] != level[:2]
        alarm.level = alarm.priority_level = level
        self._render(alarm)
        if escalates:
            self._annunciate(alarm, Trigger.REALARM)
        self.recount(alarm, before)
        self.emit(alarm, Transition.REALARMED if escalates else Transition.LEVEL_CHANGED, before[4])

    def _set_suppressed(self, alarm: Alarm, suppressed: bool) -> None:
        before = self.counted(alarm)
        was_hidden = alarm.hidden
        alarm.suppressed = suppressed
        self.hide_or_release(alarm, was_hidden)
        self.recount(alarm, before)
        self.emit(alarm, Transition.SUPPRESSED if suppressed else Transition.UNSUPPRESSED, before[4])

    def end_shelving(self, alarm: Alarm, transition: Transition, origin: Origin | None, reason: str) -> None:
        """Unshelve (an operator) or let the shelving expire (its time, or a one-shot's return to normal)."""
        before = self.counted(alarm)
        alarm.shelving = None
        alarm.shelve_generation += 1
        self.hide_or_release(alarm, True)
        self.recount(alarm, before)
        self.emit(alarm, transition, before[4], origin, reason)

    # -- state bookkeeping (used by actions.py too) -----------------------------------------

    def _annunciate(self, alarm: Alarm, trigger: Trigger) -> None:
        if alarm.hidden:
            return  # shelved, suppressed or out of service: the process is followed, not annunciated
        state = next_state(alarm.annunciation, trigger, latching=alarm.definition.latching)
        if state is not None:
            alarm.annunciation = state

    def hide_or_release(self, alarm: Alarm, was_hidden: bool) -> None:
        if alarm.hidden:
            alarm.annunciation = AlarmState.NORMAL
        elif was_hidden:
            alarm.annunciation = released_state(alarm.active)

    def counted(self, alarm: Alarm) -> tuple[bool, bool, bool, int, AlarmState]:
        state = alarm.state
        active = state in _ACTIVE_STATES
        return active, state in _WAITING, state is AlarmState.SHELVED, alarm.priority.rank if active else 0, state

    def recount(self, alarm: Alarm, before: tuple[bool, bool, bool, int, AlarmState]) -> None:
        after = self.counted(alarm)
        if after == before:
            return
        self.active_count += after[0] - before[0]
        self.unacknowledged_count += after[1] - before[1]
        self.shelved_count += after[2] - before[2]
        self._active_ranks[before[3]] -= 1
        self._active_ranks[after[3]] += 1
        self.changed = True

    @property
    def highest_active_priority(self) -> int:
        """Rank (1 low .. 4 critical) of the most urgent active alarm; 0 when none is active."""
        ranks = self._active_ranks
        for rank in (4, 3, 2, 1):
            if ranks[rank]:
                return rank
        return 0

    def _watched_value(self, alarm: Alarm) -> object:
        return self.db.value(alarm.definition.tag)

    def _render(self, alarm: Alarm) -> None:
        """The message with the values at this transition; {level} and {limit} of the level it is in, or returned from."""
        definition = alarm.definition
        alarm.value = self._watched_value(alarm)
        level = alarm.level_definition()
        fields = {"value": alarm.value, "limit": level.limit if level is not None else None, "level": alarm.priority_level,
                  "name": alarm.name, "tag": definition.tag}
        alarm.message = render(definition.message, self.db.value, fields)

    def emit(self, alarm: Alarm, transition: Transition, previous: AlarmState, origin: Origin | None = None, comment: str = "") -> None:
        """Publish one transition or action of `alarm` as an `alarm` event."""
        alarm.sequence += 1
        alarm.last_transition = transition.value
        now = self.clock.wall()
        if transition is not Transition.COMMENTED:  # a comment changes no state
            alarm.since = now
        self.changed = True
        data = {
            "transition": transition.value,
            "alarm": self.snapshot(alarm),
            "previous": previous.value,
            "user": origin.user if origin is not None else "",
            "origin": str(origin) if origin is not None else "",
            "role": origin.role.value if origin is not None and origin.role is not None else "",
            "comment": comment,
        }
        self._publish(Event("alarm", now, alarm.name, data))

    # -- reading --------------------------------------------------------------------------

    def get(self, name: str) -> Alarm:
        alarm = self.by_name.get(name)
        if alarm is None:
            raise UnknownAlarm(f"no alarm named {name!r}{did_you_mean(name, self.by_name)}")
        return alarm

    def snapshot(self, alarm: Alarm) -> AlarmSnapshot:
        definition = alarm.definition
        return AlarmSnapshot(
            name=alarm.name, kind=definition.kind, tag=definition.source, group=definition.group,
            description=definition.description, priority=alarm.priority, severity=alarm.severity, state=alarm.state,
            annunciation=alarm.annunciation, active=alarm.active, message=alarm.message or alarm.name, value=alarm.value,
            level=alarm.level, limit=alarm.limit, latching=definition.latching, shelving=alarm.shelving,
            suppressed=alarm.suppressed, out_of_service=alarm.out_of_service, since=alarm.since,
            active_since=alarm.active_since, last_transition=alarm.last_transition, sequence=alarm.sequence,
            comment=alarm.comment, comment_user=alarm.comment_user, tags=definition.reads,
            limits=definition.limits,
        )

    def snapshots(self, alarms: Iterable[Alarm] | None = None) -> list[AlarmSnapshot]:
        return [self.snapshot(alarm) for alarm in (self.alarms if alarms is None else alarms)]

    def schedule_shelving(self, alarm: Alarm, due: float) -> None:
        """Expire `alarm`'s current shelving at clock time `due`."""
        alarm.shelve_generation += 1
        self._push(due, alarm, alarm.shelve_generation, _SHELVE)
