"""The alarms' states as a part of a redundant pair's replicated state (`Plant.replicate`, docs/redundancy.md).

The active sends, with each cycle's state, the alarms whose state changed since the previous
capture (every alarm in a full state); the standby checks every field against its own alarm
definitions, then takes them as they are — it evaluates nothing and journals nothing — so the
member that takes over goes on from the same states: an acknowledged alarm stays acknowledged,
a shelving expires when it was due, an on-delay ends when it would have. One alarm is a list:

    [name, active, level, priority_level, annunciation, shelving | None, shelve_in | None, suppressed,
     out_of_service, since, active_since | None, last_transition, sequence, message, value, comment,
     comment_user, pending_in | None, counting | None]
        shelving: [kind, until (wall s), reason, user]
        shelve_in, pending_in: seconds until the shelving expires, until the on/off delay ends
        counting: an increase alarm's window: [last value, [[age s, growth], ...]]

Times that drive timers travel as seconds from the capture, so two machines' clocks need not agree.
What stays each member's own: the alarm flood's rate (it restarts on the new active).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from softplc.adapters.alarms.alarm import Alarm
from softplc.adapters.alarms.engine import AlarmEngine
from softplc.adapters.alarms.evaluation import ON, IncreaseCheck
from softplc.core.alarms import AlarmState, ShelveKind, Shelving, Transition
from softplc.core.plant import StateRefused

FIELDS = 19
_ANNUNCIATIONS = {state.value: state for state in
                  (AlarmState.NORMAL, AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED, AlarmState.RETURNED, AlarmState.LATCHED)}
_KINDS = {kind.value: kind for kind in ShelveKind}
_TRANSITIONS = {"", *(transition.value for transition in Transition)}


class AlarmReplica:
    """Captures (active) and checks and applies (standby) an engine's alarm states (see the module docstring)."""

    def __init__(self, engine: AlarmEngine) -> None:
        self.engine = engine

    # -- the active ---------------------------------------------------------------------------

    def capture(self, full: bool) -> list[list[Any]] | None:
        engine = self.engine
        touched = engine.touched
        if not full and not touched:
            return None
        indices = range(len(engine.alarms)) if full else sorted(touched)
        engine.touched = set()
        now = engine.clock.now()
        return [_record(engine.alarms[index], now) for index in indices]

    # -- the standby --------------------------------------------------------------------------

    def check(self, data: Any) -> list[tuple[Alarm, list[Any]]]:
        """Each alarm and its checked fields; StateRefused names the first field that is wrong."""
        items = _list(data, None, "alarms")
        return [self._check_one(item, index) for index, item in enumerate(items)]

    def _check_one(self, item: Any, index: int) -> tuple[Alarm, list[Any]]:
        fields = _list(item, FIELDS, f"alarms: item {index}")
        name = fields[0]
        alarm = self.engine.by_name.get(name) if isinstance(name, str) else None
        if alarm is None:
            raise StateRefused(f"alarms: no alarm {name!r} in this plant")
        what = f"alarms: {name}"
        (_, active, level, priority_level, annunciation, shelving, shelve_in, suppressed, out_of_service, since, active_since,
         last_transition, sequence, message, value, comment, comment_user, pending_in, counting) = fields
        levels = set(alarm.levels) if alarm.levels else {ON}
        for field, text in (("level", level), ("priority_level", priority_level)):
            if text != "" and text not in levels:
                raise StateRefused(f"{what}: {field} {text!r} is none of its levels ({', '.join(sorted(levels))})")
        if annunciation not in _ANNUNCIATIONS:
            raise StateRefused(f"{what}: unknown annunciation state {annunciation!r}")
        if shelving is not None:
            kind, until, reason, user = _list(shelving, 4, f"{what}: shelving")
            if kind not in _KINDS:
                raise StateRefused(f"{what}: unknown shelving kind {kind!r}")
            shelving = Shelving(_KINDS[kind], _number(until, f"{what}: shelving until"), _text(reason, f"{what}: shelving reason"),
                                _text(user, f"{what}: shelving user"))
            shelve_in = _number(shelve_in, f"{what}: shelve_in")
        if last_transition not in _TRANSITIONS:
            raise StateRefused(f"{what}: unknown transition {last_transition!r}")
        if isinstance(sequence, bool) or not isinstance(sequence, int) or sequence < 0:
            raise StateRefused(f"{what}: sequence must be a whole number ≥ 0, not {sequence!r}")
        if value is not None and not isinstance(value, (bool, int, float, str)):
            raise StateRefused(f"{what}: value must be a number, text or none, not {type(value).__name__}")
        if counting is not None:
            last, growth = _list(counting, 2, f"{what}: counting")
            counting = (_number(last, f"{what}: counting"),
                        [(_number(age, f"{what}: counting"), _number(amount, f"{what}: counting"))
                         for age, amount in (_list(entry, 2, f"{what}: counting") for entry in _list(growth, None, f"{what}: counting"))])
        return alarm, [
            _flag(active, f"{what}: active"), level, priority_level, _ANNUNCIATIONS[annunciation], shelving, shelve_in,
            _flag(suppressed, f"{what}: suppressed"), _flag(out_of_service, f"{what}: out_of_service"), _number(since, f"{what}: since"),
            None if active_since is None else _number(active_since, f"{what}: active_since"), last_transition, sequence,
            _text(message, f"{what}: message"), value, _text(comment, f"{what}: comment"), _text(comment_user, f"{what}: comment_user"),
            None if pending_in is None else _number(pending_in, f"{what}: pending_in"), counting,
        ]

    def apply(self, checked: list[tuple[Alarm, list[Any]]]) -> None:
        engine = self.engine
        now = engine.clock.now()
        for alarm, fields in checked:
            (active, level, priority_level, annunciation, shelving, shelve_in, suppressed, out_of_service, since, active_since,
             last_transition, sequence, message, value, comment, comment_user, pending_in, counting) = fields
            before = engine.counted(alarm)
            alarm.active = active
            if priority_level:
                alarm.enter_level(priority_level)
            else:  # never active yet: the definition's priority
                definition = alarm.definition
                alarm.priority_level, alarm.priority, alarm.rank = "", definition.priority, definition.priority.rank
                alarm.severity, alarm.level_limit = definition.severity, None
            alarm.level = level
            alarm.annunciation = annunciation
            alarm.shelving = shelving
            if shelving is not None:
                engine.schedule_shelving(alarm, now + shelve_in)
            else:
                alarm.shelve_generation += 1
                alarm.shelve_due = None
            alarm.suppressed, alarm.out_of_service = suppressed, out_of_service
            alarm.since, alarm.active_since, alarm.last_transition, alarm.sequence = since, active_since, last_transition, sequence
            alarm.message, alarm.value, alarm.comment, alarm.comment_user = message, value, comment, comment_user
            engine.schedule_delay(alarm, None if pending_in is None else now + pending_in)
            if counting is not None and isinstance(alarm.check, IncreaseCheck):
                alarm.check.last = counting[0]
                alarm.check.growth = deque((now - age, amount) for age, amount in counting[1])
            engine.recount(alarm, before)
        engine.touched = set()  # a standby captures nothing; a full state comes when it is active
        if engine.timers > 4 * len(engine.alarms) + 64:
            engine.prune_timers()


def _record(alarm: Alarm, now: float) -> list[Any]:
    shelving = alarm.shelving
    shelved = None if shelving is None else [shelving.kind.value, shelving.until, shelving.reason, shelving.user]
    shelve_in = alarm.shelve_due - now if shelving is not None and alarm.shelve_due is not None else None
    if shelving is not None and shelve_in is None:
        shelve_in = 0.0
    check = alarm.check
    counting = None
    if isinstance(check, IncreaseCheck):
        counting = [check.last, [[now - at, amount] for at, amount in check.growth]]
    return [alarm.name, alarm.active, alarm.level, alarm.priority_level, alarm.annunciation.value, shelved, shelve_in, alarm.suppressed,
            alarm.out_of_service, alarm.since, alarm.active_since, alarm.last_transition, alarm.sequence, alarm.message,
            _plain(alarm.value), alarm.comment, alarm.comment_user, None if alarm.pending_due is None else alarm.pending_due - now, counting]


def _plain(value: Any) -> Any:
    """A value the link carries as it is (a numpy number as a Python one)."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    item = getattr(value, "item", None)
    return item() if callable(item) else str(value)


def _list(value: Any, length: int | None, what: str) -> list[Any]:
    if not isinstance(value, (list, tuple)) or (length is not None and len(value) != length):
        size = f" of {length}" if length is not None else ""
        raise StateRefused(f"{what}: expected a list{size}, got {type(value).__name__}")
    return list(value)


def _flag(value: Any, what: str) -> bool:
    if not isinstance(value, bool):
        raise StateRefused(f"{what}: expected true or false, got {value!r}")
    return value


def _text(value: Any, what: str) -> str:
    if not isinstance(value, str):
        raise StateRefused(f"{what}: expected text, got {type(value).__name__}")
    return value


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise StateRefused(f"{what}: expected a finite number, got {value!r}")
    return float(value)
