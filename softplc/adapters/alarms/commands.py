"""The `alarms.*` commands: the one door through which every adapter reads alarms and acts on them.

    name                   permission   arguments
    alarms.list            view         state, name (pattern), priority (lowest shown)
    alarms.summary         view         —  (counts, the flood, the most severe unacknowledged alarm: the HMI banner)
    alarms.journal         view         alarm, since, until, text, user, transition, limit, offset, plant
    alarms.acknowledge     acknowledge  alarm, comment
    alarms.acknowledge_all acknowledge  comment
    alarms.shelve          acknowledge  alarm, reason, duration (s or "30min") | one_shot: true
    alarms.unshelve        acknowledge  alarm, reason
    alarms.comment         acknowledge  alarm, comment
    alarms.out_of_service  engineer     alarm, reason
    alarms.in_service      engineer     alarm, reason

Results are JSON-ready (dicts, lists, strings). The registry checks the caller's role and
reports every call; a refusal is a `CommandRefused` (an `AlarmRefused`) saying why.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from fnmatch import fnmatchcase
from typing import Any

from softplc.adapters.alarms.actions import AlarmActions
from softplc.adapters.alarms.engine import AlarmEngine
from softplc.core.alarms import AlarmState, Priority
from softplc.core.clock import Clock
from softplc.core.commands import CommandRefused, Commands, Permission
from softplc.core.tagdb import Origin
from softplc.storage.alarm_journal import AlarmJournal, JournalQuery
from softplc.storage.command_search import search_for_command
from softplc.util.durations import parse_duration
from softplc.util.timestamps import format_shown, parse_utc

STATE_FILTERS = ("all", "annunciated", "active", "unacknowledged", "shelved", "suppressed", "out_of_service", "normal")


def register_alarm_commands(commands: Commands, engine: AlarmEngine, actions: AlarmActions, journal: AlarmJournal | None,
                            clock: Clock) -> list[Callable[[], None]]:
    """Register every `alarms.*` command; returns their unregisters."""
    name_argument = {"alarm": "alarm name"}

    def listing(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        state = _text(arguments, "state", "all")
        if state not in STATE_FILTERS:
            raise CommandRefused(f"alarms.list: state must be one of {', '.join(STATE_FILTERS)}, not {state!r}")
        pattern = _text(arguments, "name", "")
        lowest = _priority(arguments)
        chosen = [alarm for alarm in engine.alarms
                  if _state_matches(alarm.state, alarm.active, state) and (not pattern or fnmatchcase(alarm.name, pattern))
                  and alarm.priority.rank >= lowest]
        return [snapshot.to_dict() for snapshot in engine.snapshots(chosen)]

    def summary(arguments: Mapping[str, Any], origin: Origin) -> dict[str, Any]:
        waiting = [alarm for alarm in engine.alarms if alarm.state.needs_acknowledgement]
        worst = max(waiting, key=lambda alarm: (alarm.severity, alarm.since), default=None)
        return {
            "alarms": len(engine.alarms), "active": engine.active_count, "unacknowledged": engine.unacknowledged_count,
            "shelved": engine.shelved_count, "highest_priority": engine.highest_active_priority,
            "shelve_max": engine.settings.shelve_max,
            "rate": engine.flood.rate, "flood": engine.flood.flooding, "flood_since": engine.flood.since,
            "most_severe_unacknowledged": engine.snapshot(worst).to_dict() if worst is not None else None,
        }

    def acknowledge(arguments: Mapping[str, Any], origin: Origin) -> str:
        snapshot = actions.acknowledge(_required(arguments, "alarm"), origin, _text(arguments, "comment", ""))
        return f"acknowledged {snapshot.name} (now {snapshot.state.value})"

    def acknowledge_all(arguments: Mapping[str, Any], origin: Origin) -> str:
        names = actions.acknowledge_all(origin, _text(arguments, "comment", ""))
        return f"acknowledged {len(names)} alarm(s)" + (": " + ", ".join(names) if names else "")

    def shelve(arguments: Mapping[str, Any], origin: Origin) -> str:
        one_shot = arguments.get("one_shot", False)
        if not isinstance(one_shot, bool):
            raise CommandRefused("alarms.shelve: one_shot must be true or false")
        duration = _duration(arguments.get("duration")) if arguments.get("duration") is not None else None
        snapshot = actions.shelve(_required(arguments, "alarm"), origin, _text(arguments, "reason", ""), duration, one_shot)
        assert snapshot.shelving is not None
        until = format_shown(snapshot.shelving.until)
        how = "until it returns to normal" if one_shot else "for " + _format_seconds(duration or 0.0)
        return f"shelved {snapshot.name} {how} (at the latest {until})"

    def unshelve(arguments: Mapping[str, Any], origin: Origin) -> str:
        snapshot = actions.unshelve(_required(arguments, "alarm"), origin, _text(arguments, "reason", ""))
        return f"unshelved {snapshot.name} (now {snapshot.state.value})"

    def comment(arguments: Mapping[str, Any], origin: Origin) -> str:
        snapshot = actions.comment(_required(arguments, "alarm"), origin, _text(arguments, "comment", ""))
        return f"commented {snapshot.name}"

    def out_of_service(arguments: Mapping[str, Any], origin: Origin) -> str:
        snapshot = actions.remove_from_service(_required(arguments, "alarm"), origin, _text(arguments, "reason", ""))
        return f"took {snapshot.name} out of service"

    def in_service(arguments: Mapping[str, Any], origin: Origin) -> str:
        snapshot = actions.return_to_service(_required(arguments, "alarm"), origin, _text(arguments, "reason", ""))
        return f"returned {snapshot.name} to service (now {snapshot.state.value})"

    async def journal_rows(arguments: Mapping[str, Any], origin: Origin) -> list[dict[str, Any]]:
        if journal is None:
            raise CommandRefused("this runtime keeps no alarm journal")
        rows = await search_for_command(clock, journal, _journal_query(arguments), "the alarm journal")
        return [row.to_dict() for row in rows]

    table: list[tuple[str, Callable[..., Any], Permission, str, dict[str, str]]] = [
        ("alarms.list", listing, Permission.VIEW, "list alarms",
         {"state": "all, annunciated, active, unacknowledged, shelved, suppressed, out_of_service or normal",
          "name": "name pattern (* and ?)", "priority": "lowest priority shown: low, medium, high, critical"}),
        ("alarms.summary", summary, Permission.VIEW, "see the alarm summary", {}),
        ("alarms.journal", journal_rows, Permission.VIEW, "read the alarm journal",
         {"alarm": "name or pattern", "since": "from (epoch s or ISO 8601, UTC unless a zone is given)", "until": "to, excluded (epoch s or ISO 8601)",
          "text": "text in the message, comment or user", "user": "who acted", "transition": "a transition or a list of them",
          "limit": "most rows (default 1000)", "offset": "rows to skip", "plant": "another plant's rows (shared journal), * for all"}),
        ("alarms.acknowledge", acknowledge, Permission.ACKNOWLEDGE, "acknowledge alarms", {**name_argument, "comment": "optional comment"}),
        ("alarms.acknowledge_all", acknowledge_all, Permission.ACKNOWLEDGE, "acknowledge alarms", {"comment": "optional comment"}),
        ("alarms.shelve", shelve, Permission.ACKNOWLEDGE, "shelve alarms",
         {**name_argument, "reason": "why (required)", "duration": "seconds or e.g. 30min", "one_shot": "true: until it returns to normal"}),
        ("alarms.unshelve", unshelve, Permission.ACKNOWLEDGE, "unshelve alarms", {**name_argument, "reason": "optional reason"}),
        ("alarms.comment", comment, Permission.ACKNOWLEDGE, "comment alarms", {**name_argument, "comment": "the comment"}),
        ("alarms.out_of_service", out_of_service, Permission.ENGINEER, "take alarms out of service", {**name_argument, "reason": "why (required)"}),
        ("alarms.in_service", in_service, Permission.ENGINEER, "return alarms to service", {**name_argument, "reason": "optional reason"}),
    ]
    return [commands.register(name, handler, permission=permission, description=description, arguments=arguments)
            for name, handler, permission, description, arguments in table]


def _state_matches(state: AlarmState, active: bool, wanted: str) -> bool:
    if wanted == "all":
        return True
    if wanted == "annunciated":
        return state.annunciated
    if wanted == "active":
        return state in (AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED)
    if wanted == "unacknowledged":
        return state.needs_acknowledgement
    return state.value == wanted


def _text(arguments: Mapping[str, Any], key: str, default: str) -> str:
    value = arguments.get(key, default)
    if not isinstance(value, str):
        raise CommandRefused(f"'{key}' must be text, not {type(value).__name__}")
    return value


def _required(arguments: Mapping[str, Any], key: str) -> str:
    value = _text(arguments, key, "")
    if not value:
        raise CommandRefused(f"'{key}' is required")
    return value


def _priority(arguments: Mapping[str, Any]) -> int:
    text = _text(arguments, "priority", "low")
    try:
        return Priority(text).rank
    except ValueError:
        raise CommandRefused(f"priority must be low, medium, high or critical, not {text!r}") from None


def _duration(value: Any) -> float:
    try:
        seconds = parse_duration(value)
    except (TypeError, ValueError) as error:
        raise CommandRefused(f"bad duration {value!r}: {error}") from None
    return seconds


def _time(value: Any, key: str) -> float | None:
    if value is None or value == "":
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    if isinstance(value, str):
        try:
            return parse_utc(value)  # UTC unless it gives a zone: never the runtime host's zone (softplc/util/timestamps.py)
        except ValueError:
            pass
    raise CommandRefused(f"'{key}' must be epoch seconds or an ISO 8601 time such as 2026-11-24T08:00 (UTC unless a zone is given), not {value!r}")


def _journal_query(arguments: Mapping[str, Any]) -> JournalQuery:
    transitions = arguments.get("transition", ())
    if isinstance(transitions, str):
        transitions = (transitions,)
    if not isinstance(transitions, (list, tuple)) or not all(isinstance(item, str) for item in transitions):
        raise CommandRefused("'transition' must be a transition name or a list of them")
    numbers = {}
    for key, default in (("limit", 1000), ("offset", 0)):
        value = arguments.get(key, default)
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise CommandRefused(f"'{key}' must be a whole number ≥ 0")
        numbers[key] = value
    plant = arguments.get("plant")
    if plant is not None and not isinstance(plant, str):
        raise CommandRefused("'plant' must be text")
    return JournalQuery(alarm=_text(arguments, "alarm", ""), since=_time(arguments.get("since"), "since"),
                        until=_time(arguments.get("until"), "until"), text=_text(arguments, "text", ""),
                        user=_text(arguments, "user", ""), transitions=tuple(transitions), plant=plant, **numbers)


def _format_seconds(seconds: float) -> str:
    if seconds >= 3600 and seconds % 60 == 0:
        return f"{seconds / 3600:g} h"
    if seconds >= 60:
        return f"{seconds / 60:g} min"
    return f"{seconds:g} s"
