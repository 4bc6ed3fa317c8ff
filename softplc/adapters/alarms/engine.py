"""The alarm engine: owns every alarm's state, evaluates at scan boundaries, publishes each transition.

    engine = AlarmEngine(settings, plant.tags, plant.clock, plant.events.publish)
    plant.tags.on_change(engine.note_changed)      # which alarms must be looked at
    plant.after_cycle(lambda task: engine.evaluate())

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
from collections.abc import Callable, Iterable, Sequence

from softplc.adapters.alarms.alarm import Alarm
from softplc.adapters.alarms.evaluation import ON, IncreaseCheck, compile_condition, make_check
from softplc.adapters.alarms.flood import FLOOD_ABOVE, FLOOD_ENDS_BELOW, WINDOW, FloodWatch
from softplc.adapters.alarms.settings import AlarmSettings
from softplc.core.alarms import (
    AlarmSnapshot,
    AlarmState,
    ShelveKind,
    Transition,
    Trigger,
    UnknownAlarm,
    next_state,
    released_state,
)
from softplc.core.clock import Clock
from softplc.core.events import Event
from softplc.core.tagdb import Origin, TagDatabase
from softplc.core.tags import Tag
from softplc.util.suggest import did_you_mean

__all__ = ["Alarm", "AlarmEngine"]

log = logging.getLogger(__name__)

_DELAY, _SHELVE, _WINDOW = "delay", "shelve", "window"
# Compared by identity in the hot path (an Enum's hash is computed in Python).
_UNACKNOWLEDGED, _ACKNOWLEDGED, _RETURNED, _LATCHED, _SHELVED = (
    AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED, AlarmState.RETURNED, AlarmState.LATCHED, AlarmState.SHELVED)
_SEVERER = {("hi", "hihi"), ("lo", "lolo")}  # (from, to) pairs that escalate on the same side


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
        # Alarms whose state changed since a redundant pair's last capture (replication.py): each
        # transition, delay started or ended, shelving scheduled, counting window moved.
        self.touched: set[int] = set()
        self.evaluations = 0
        self.flood = FloodWatch()

    # -- what to evaluate -----------------------------------------------------------------

    def note_changed(self, tags: Sequence[Tag]) -> None:
        """A `db.on_change` callback: mark the alarms that read these tags."""
        # Keyed by the Tag objects themselves (no name lookup per change), all in C: map, filter, update.
        self._dirty.update(*filter(None, map(self._index.get, tags)))

    def next_due(self) -> float | None:
        """Clock time of the earliest pending timer (delays, shelving, windows), if any."""
        return self._timers[0][0] if self._timers else None

    def evaluate(self) -> None:
        """At a scan boundary: fire due timers, evaluate every marked alarm, then look at the alarm rate (floods)."""
        now = self.clock.now()
        self._evaluate_due(now)
        self._watch_flood(now)

    def _evaluate_due(self, now: float) -> None:
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
            self.touched.add(alarm.index)  # its counting window moves
            due = alarm.check.next_change(now)
            if due is not None:
                self._push(due, alarm, -1, _WINDOW)
        if raw == level:
            if alarm.pending_due is not None:  # the condition flipped back before its delay ran out
                alarm.pending_due = None
                alarm.delay_generation += 1
                self.touched.add(alarm.index)
            return
        if level and raw:  # still active, at another limit: no delay
            self._change_level(alarm, raw)
            return
        delay = definition.off_delay if level else definition.on_delay
        if delay > 0:
            if alarm.pending_due is None:
                self.schedule_delay(alarm, now + delay)
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
        alarm.active, alarm.active_since = True, self.clock.wall()
        alarm.enter_level(level)
        self._render(alarm)
        self._annunciate(alarm, Trigger.ACTIVATE)
        self.recount(alarm, before)
        self.emit(alarm, Transition.ACTIVATED, before[4])

    def _clear(self, alarm: Alarm) -> None:
        before = self.counted(alarm)
        alarm.active, alarm.active_since = False, None
        alarm.enter_level("")
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
        alarm.enter_level(level)
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
            if state is _UNACKNOWLEDGED and trigger is not Trigger.ACKNOWLEDGE:
                self.flood.annunciated(self.clock.now())  # an alarm the operator is shown (activated or re-alarmed)

    def _watch_flood(self, now: float) -> None:
        flood = self.flood
        rate = flood.rate
        if flood.update(now, self.clock.wall()):
            if flood.flooding:
                log.warning("alarm flood: %s annunciated within %s (ISA-18.2: more than %d is a flood); "
                            "_sys.alarms.flood is true until fewer than %d come within it",
                            _alarms(flood.rate), _minutes(WINDOW), FLOOD_ABOVE, FLOOD_ENDS_BELOW)
            else:
                log.info("alarm flood over: %s annunciated within %s", _alarms(flood.rate), _minutes(WINDOW))
            self.changed = True
        elif flood.rate != rate:
            self.changed = True

    def hide_or_release(self, alarm: Alarm, was_hidden: bool) -> None:
        if alarm.hidden:
            alarm.annunciation = AlarmState.NORMAL
        elif was_hidden:
            alarm.annunciation = released_state(alarm.active)

    def counted(self, alarm: Alarm) -> tuple[bool, bool, bool, int, AlarmState]:
        state = alarm.state
        active = state is _UNACKNOWLEDGED or state is _ACKNOWLEDGED
        waiting = state is _UNACKNOWLEDGED or state is _RETURNED or state is _LATCHED
        return active, waiting, state is _SHELVED, alarm.rank if active else 0, state

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
        alarm.value = value = alarm.watched.value if alarm.watched is not None else self._watched_value(alarm)
        fields = {"value": value, "limit": alarm.level_limit, "level": alarm.priority_level, "name": alarm.definition.name,
                  "tag": alarm.definition.tag}
        alarm.message = alarm.template.render(self.db.value, fields)

    def emit(self, alarm: Alarm, transition: Transition, previous: AlarmState, origin: Origin | None = None, comment: str = "") -> None:
        """Publish one transition or action of `alarm` as an `alarm` event."""
        alarm.sequence += 1
        alarm.last_transition = transition._value_
        self.touched.add(alarm.index)
        now = self.clock.wall()
        if transition is not Transition.COMMENTED:  # a comment changes no state
            alarm.since = now
        self.changed = True
        data = {
            "transition": transition._value_,  # an Enum's .value is a descriptor call; _value_ a plain attribute
            "alarm": self.snapshot(alarm),
            "previous": previous._value_,
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
        return alarm.snapshot()

    def snapshots(self, alarms: Iterable[Alarm] | None = None) -> list[AlarmSnapshot]:
        return [self.snapshot(alarm) for alarm in (self.alarms if alarms is None else alarms)]

    def schedule_shelving(self, alarm: Alarm, due: float) -> None:
        """Expire `alarm`'s current shelving at clock time `due`."""
        alarm.shelve_generation += 1
        alarm.shelve_due = due
        self.touched.add(alarm.index)
        self._push(due, alarm, alarm.shelve_generation, _SHELVE)

    def schedule_delay(self, alarm: Alarm, due: float | None) -> None:
        """Run `alarm`'s on/off delay until clock time `due` (None: no delay runs)."""
        alarm.pending_due = due
        alarm.delay_generation += 1
        self.touched.add(alarm.index)
        if due is not None:
            self._push(due, alarm, alarm.delay_generation, _DELAY)

    def prune_timers(self) -> None:
        """Drop the timers of shelvings and delays replaced since (a standby's heap never fires, only grows)."""
        alarms = self.alarms
        self._timers = [timer for timer in self._timers
                        if timer[4] == _WINDOW or timer[3] == (alarms[timer[2]].shelve_generation if timer[4] == _SHELVE
                                                               else alarms[timer[2]].delay_generation)]
        heapq.heapify(self._timers)

    @property
    def timers(self) -> int:
        return len(self._timers)


def _alarms(count: int) -> str:
    return f"{count} alarm" if count == 1 else f"{count} alarms"


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:g} minutes"
