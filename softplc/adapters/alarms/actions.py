"""What operators and engineers do to alarms: acknowledge, shelve, unshelve, comment, out of service.

Each action checks that it makes sense (an `AlarmRefused` says why not), changes the alarm's
state through the engine and is published like any transition, with the person's origin and
their reason or comment. Who may do what is not checked here but by the command registry
(`commands.py` registers these as `alarms.*` commands with their `Permission`).
"""

from __future__ import annotations

from softplc.adapters.alarms.engine import Alarm, AlarmEngine
from softplc.core.alarms import (
    AlarmRefused,
    AlarmSnapshot,
    NothingToAcknowledge,
    NotShelved,
    ServiceUnchanged,
    ShelveKind,
    Shelving,
    ShelvingTimeOutOfRange,
    Transition,
    Trigger,
    next_state,
)
from softplc.core.tagdb import Origin
from softplc.util.durations import format_duration


class AlarmActions:
    """The operator's actions on an engine's alarms."""

    def __init__(self, engine: AlarmEngine) -> None:
        self.engine = engine

    def acknowledge(self, name: str, origin: Origin, comment: str = "") -> AlarmSnapshot:
        engine = self.engine
        alarm = engine.get(name)
        state = alarm.state
        target = None if alarm.hidden else next_state(alarm.annunciation, Trigger.ACKNOWLEDGE, latching=alarm.definition.latching)
        if target is None:
            raise NothingToAcknowledge(f"alarm {name} needs no acknowledgement: it is {state.value.replace('_', ' ')}")
        before = engine.counted(alarm)
        alarm.annunciation = target
        self._note_comment(alarm, origin, comment)
        engine.recount(alarm, before)
        engine.emit(alarm, Transition.ACKNOWLEDGED, state, origin, comment)
        return engine.snapshot(alarm)

    def acknowledge_all(self, origin: Origin, comment: str = "") -> list[str]:
        """Acknowledge every alarm that waits for it; the names acknowledged."""
        names = [alarm.name for alarm in self.engine.alarms if alarm.state.needs_acknowledgement]
        for name in names:
            self.acknowledge(name, origin, comment)
        return names

    def shelve(self, name: str, origin: Origin, reason: str, duration: float | None = None, one_shot: bool = False) -> AlarmSnapshot:
        """Shelve for `duration` seconds, or one-shot (until it next returns to normal); both at most shelve_max."""
        engine = self.engine
        alarm = engine.get(name)
        longest = engine.settings.shelve_max
        if not reason.strip():
            raise AlarmRefused(f"shelving {name} needs a reason")
        if alarm.out_of_service:
            raise AlarmRefused(f"alarm {name} is out of service: it cannot be shelved")
        if one_shot == (duration is not None):
            raise AlarmRefused("shelve either for a duration or one-shot (until it returns to normal), not both or neither")
        if duration is not None and not 0 < duration <= longest:
            raise ShelvingTimeOutOfRange(f"cannot shelve {name} for {format_duration(duration)}: the longest shelving is {format_duration(longest)} (alarms.shelve_max)")
        seconds = longest if one_shot else float(duration or 0.0)
        before = engine.counted(alarm)
        was_hidden = alarm.hidden
        alarm.shelving = Shelving(ShelveKind.ONE_SHOT if one_shot else ShelveKind.TIMED, engine.clock.wall() + seconds, reason, origin.user)
        engine.schedule_shelving(alarm, engine.clock.now() + seconds)
        engine.hide_or_release(alarm, was_hidden)
        engine.recount(alarm, before)
        engine.emit(alarm, Transition.SHELVED, before[4], origin, reason)
        return engine.snapshot(alarm)

    def unshelve(self, name: str, origin: Origin, reason: str = "") -> AlarmSnapshot:
        alarm = self.engine.get(name)
        if alarm.shelving is None:
            raise NotShelved(f"alarm {name} is not shelved")
        self.engine.end_shelving(alarm, Transition.UNSHELVED, origin, reason)
        return self.engine.snapshot(alarm)

    def comment(self, name: str, origin: Origin, text: str) -> AlarmSnapshot:
        engine = self.engine
        alarm = engine.get(name)
        if not text.strip():
            raise AlarmRefused("a comment needs some text")
        self._note_comment(alarm, origin, text)
        engine.emit(alarm, Transition.COMMENTED, alarm.state, origin, text)
        return engine.snapshot(alarm)

    def remove_from_service(self, name: str, origin: Origin, reason: str) -> AlarmSnapshot:
        return self._service(name, origin, reason, out=True)

    def return_to_service(self, name: str, origin: Origin, reason: str = "") -> AlarmSnapshot:
        return self._service(name, origin, reason, out=False)

    def _service(self, name: str, origin: Origin, reason: str, *, out: bool) -> AlarmSnapshot:
        engine = self.engine
        alarm = engine.get(name)
        if alarm.out_of_service == out:
            raise ServiceUnchanged(f"alarm {name} is {'out of' if out else 'in'} service already")
        if out and not reason.strip():
            raise AlarmRefused(f"taking {name} out of service needs a reason")
        before = engine.counted(alarm)
        was_hidden = alarm.hidden
        alarm.out_of_service = out
        if out and alarm.shelving is not None:  # out of service supersedes the shelving
            alarm.shelving = None
            alarm.shelve_generation += 1
        engine.hide_or_release(alarm, was_hidden)
        engine.recount(alarm, before)
        engine.emit(alarm, Transition.REMOVED_FROM_SERVICE if out else Transition.RETURNED_TO_SERVICE, before[4], origin, reason)
        return engine.snapshot(alarm)

    @staticmethod
    def _note_comment(alarm: Alarm, origin: Origin, text: str) -> None:
        if text.strip():
            alarm.comment, alarm.comment_user = text, origin.user
