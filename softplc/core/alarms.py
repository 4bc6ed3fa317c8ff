"""The alarm model: ISA-18.2 states, the table of their transitions, and what adapters see of an alarm.

Plain data and pure functions only, in the core: the alarm engine (softplc/adapters/alarms) and
every adapter that shows alarms (OPC UA conditions, the HMI, the CLI) share this vocabulary; none
of them imports the engine. An alarm's *annunciation* follows ISA-18.2 (figure 5 of the standard):

    NORMAL ──activate──▶ UNACKNOWLEDGED ──acknowledge──▶ ACKNOWLEDGED
       ▲                      │ clear                         │ clear
       │                      ▼                               ▼
       └──acknowledge── RETURNED (unacknowledged)           NORMAL      (non-latching)
                        LATCHED ◀── clear (latching: from either active state)

A latched alarm stays annunciated after the process returns to normal until an operator
acknowledges it (which is the reset). Three *administrative* states hide the annunciation:
shelved (by an operator, timed or one-shot, with a reason), suppressed by design (a condition
of the configuration) and out of service (by an engineer). While any of them holds, the alarm is
not annunciated (its annunciation is NORMAL) but its process condition is still followed; when
the last one is lifted the alarm comes back UNACKNOWLEDGED if its condition is active, else
NORMAL — an operator who unshelves an alarm that is still active is told again.
"""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass, field
from typing import Any

from softplc.core.commands import CommandRefused


class Priority(enum.Enum):
    """How urgently the operator must respond (ISA-18.2); its rank orders them, 1 lowest."""

    LOW = "low"
    MEDIUM = "medium"
    HIGH = "high"
    CRITICAL = "critical"

    @property
    def rank(self) -> int:
        return _RANKS[self]

    @property
    def severity(self) -> int:
        """The OPC UA Severity (1..1000) an alarm of this priority has unless it says otherwise."""
        return _SEVERITIES[self]


_RANKS = {Priority.LOW: 1, Priority.MEDIUM: 2, Priority.HIGH: 3, Priority.CRITICAL: 4}
_SEVERITIES = {Priority.LOW: 300, Priority.MEDIUM: 500, Priority.HIGH: 700, Priority.CRITICAL: 900}


class AlarmState(enum.Enum):
    """An alarm's state as the operator sees it (the annunciation, or what hides it)."""

    NORMAL = "normal"
    UNACKNOWLEDGED = "unacknowledged"  # active, not yet acknowledged
    ACKNOWLEDGED = "acknowledged"  # active, acknowledged
    RETURNED = "returned"  # returned to normal, not yet acknowledged
    LATCHED = "latched"  # returned to normal, held until acknowledged (latching alarms)
    SHELVED = "shelved"
    SUPPRESSED = "suppressed"  # suppressed by design
    OUT_OF_SERVICE = "out_of_service"

    @property
    def annunciated(self) -> bool:
        """Shown to the operator (in the summary, the banner)."""
        return self in _ANNUNCIATED

    @property
    def needs_acknowledgement(self) -> bool:
        return self in _UNACKNOWLEDGED


_ANNUNCIATED = frozenset({AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED, AlarmState.RETURNED, AlarmState.LATCHED})
_UNACKNOWLEDGED = frozenset({AlarmState.UNACKNOWLEDGED, AlarmState.RETURNED, AlarmState.LATCHED})


class Trigger(enum.Enum):
    """What moves the annunciation: the process condition, or the operator."""

    ACTIVATE = "activate"  # the process condition became active (after its on-delay)
    REALARM = "realarm"  # an active limit alarm crossed into a more severe level
    CLEAR = "clear"  # the process condition returned to normal (after its off-delay)
    ACKNOWLEDGE = "acknowledge"


N, U, A, R, L = (AlarmState.NORMAL, AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED,
                 AlarmState.RETURNED, AlarmState.LATCHED)

# (state, trigger) → (next state of a non-latching alarm, next state of a latching one).
# A pair missing from the table is no transition (e.g. acknowledging an acknowledged alarm).
TRANSITIONS: dict[tuple[AlarmState, Trigger], tuple[AlarmState, AlarmState]] = {
    (N, Trigger.ACTIVATE): (U, U),
    (U, Trigger.ACKNOWLEDGE): (A, A),
    (U, Trigger.CLEAR): (R, L),
    (A, Trigger.CLEAR): (N, L),
    (A, Trigger.REALARM): (U, U),  # a new, more severe level must be acknowledged anew
    (R, Trigger.ACTIVATE): (U, U),
    (R, Trigger.ACKNOWLEDGE): (N, N),
    (L, Trigger.ACTIVATE): (U, U),
    (L, Trigger.ACKNOWLEDGE): (N, N),  # the operator's reset of a latched alarm
}
del N, U, A, R, L


def next_state(state: AlarmState, trigger: Trigger, *, latching: bool) -> AlarmState | None:
    """The annunciation after `trigger`, or None when the trigger changes nothing in `state`."""
    targets = TRANSITIONS.get((state, trigger))
    if targets is None:
        return None
    return targets[1] if latching else targets[0]


def released_state(active: bool) -> AlarmState:
    """The annunciation once the last of shelved / suppressed / out of service is lifted."""
    return AlarmState.UNACKNOWLEDGED if active else AlarmState.NORMAL


def effective_state(annunciation: AlarmState, *, shelved: bool, suppressed: bool, out_of_service: bool) -> AlarmState:
    """What the operator sees: out of service hides everything, then suppression, then shelving."""
    if out_of_service:
        return AlarmState.OUT_OF_SERVICE
    if suppressed:
        return AlarmState.SUPPRESSED
    if shelved:
        return AlarmState.SHELVED
    return annunciation


class Transition(enum.Enum):
    """What happened to an alarm: the `transition` of its events and journal rows."""

    ACTIVATED = "activated"
    REALARMED = "realarmed"  # escalated to a more severe limit (acknowledge again)
    LEVEL_CHANGED = "level_changed"  # moved to a less severe limit, still active
    CLEARED = "cleared"  # process back to normal (the state says whether it still needs an acknowledgement)
    ACKNOWLEDGED = "acknowledged"
    SHELVED = "shelved"
    UNSHELVED = "unshelved"
    SHELVING_EXPIRED = "shelving_expired"
    SUPPRESSED = "suppressed"
    UNSUPPRESSED = "unsuppressed"
    REMOVED_FROM_SERVICE = "removed_from_service"
    RETURNED_TO_SERVICE = "returned_to_service"
    COMMENTED = "commented"

    @property
    def action(self) -> bool:
        """Done by a person (journaled with their name) rather than by the process."""
        return self in _ACTIONS


_ACTIONS = frozenset({Transition.ACKNOWLEDGED, Transition.SHELVED, Transition.UNSHELVED, Transition.REMOVED_FROM_SERVICE,
                      Transition.RETURNED_TO_SERVICE, Transition.COMMENTED})


class ShelveKind(enum.Enum):
    TIMED = "timed"  # until a time
    ONE_SHOT = "one_shot"  # until the alarm's condition next returns to normal (or the longest shelving time)


@dataclass(frozen=True)
class Shelving:
    """How an alarm is shelved: kind, when it unshelves itself at the latest (wall-clock s), why, by whom."""

    kind: ShelveKind
    until: float
    reason: str
    user: str


@dataclass(frozen=True)
class AlarmSnapshot:
    """One alarm as adapters see it (an event's `data["alarm"]`, an item of `alarms.list`)."""

    name: str
    kind: str  # limit, discrete, condition, increase
    tag: str  # the tag it watches (for a condition: its source tag); its folder gets the OPC UA events
    group: str  # that tag's group (browse folder)
    description: str
    priority: Priority
    severity: int  # OPC UA Severity 1..1000
    state: AlarmState  # what the operator sees
    annunciation: AlarmState  # NORMAL .. LATCHED, under any shelving/suppression
    active: bool  # the process condition (after its delays)
    message: str  # rendered with the tag values of the last transition
    value: Any  # the watched tag's value at the last transition
    level: str = ""  # limit alarms: hihi, hi, lo, lolo ("" when normal)
    limit: float | None = None  # limit alarms: the limit of `level`
    latching: bool = False
    shelving: Shelving | None = None
    suppressed: bool = False
    out_of_service: bool = False
    since: float = 0.0  # wall-clock s of the last change of state
    active_since: float | None = None  # wall-clock s the condition became active (None: normal)
    last_transition: str = ""
    sequence: int = 0  # transitions of this alarm so far (for telling events apart)
    comment: str = ""  # the last comment, with its author in `comment_user`
    comment_user: str = ""
    tags: tuple[str, ...] = field(default=())  # every tag the alarm reads
    limits: tuple[tuple[str, float], ...] = ()  # limit alarms: (level, limit) of each level configured

    @classmethod
    def from_fields(cls, fields: dict[str, Any]) -> AlarmSnapshot:
        """The same as `AlarmSnapshot(**fields)` with every field given, made at once.

        The engine's hot path (an alarm flood makes thousands a second): a frozen dataclass's
        __init__ sets each of its 26 fields through object.__setattr__, three times slower.
        """
        snapshot = object.__new__(cls)
        snapshot.__dict__.update(fields)
        return snapshot

    @property
    def acknowledged(self) -> bool:
        return not self.annunciation.needs_acknowledgement

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (enums as their values) for the HMI's API and the OPC UA commands door."""
        # The fields are immutable (numbers, text, tuples, enums, a frozen Shelving): a shallow copy
        # is what dataclasses.asdict's deep copy gives, ten times faster (the HMI sends a flood's alarms).
        data = dict(self.__dict__)
        data["priority"] = self.priority.value
        data["state"] = self.state.value
        data["annunciation"] = self.annunciation.value
        data["acknowledged"] = self.acknowledged
        data["tags"] = list(self.tags)
        data["limits"] = dict(self.limits)
        if self.shelving is not None:
            data["shelving"] = {**asdict(self.shelving), "kind": self.shelving.kind.value}
        return data


class AlarmRefused(CommandRefused):
    """An operator action on an alarm that was not carried out; the message says why."""


class UnknownAlarm(AlarmRefused):
    """No alarm of that name."""


class NothingToAcknowledge(AlarmRefused):
    """The alarm is acknowledged already, or normal (OPC UA: BadConditionBranchAlreadyAcked)."""


class NotShelved(AlarmRefused):
    """Unshelving an alarm that is not shelved (OPC UA: BadConditionNotShelved)."""


class ShelvingTimeOutOfRange(AlarmRefused):
    """A shelving time of zero or beyond shelve_max (OPC UA: BadShelvingTimeOutOfRange)."""


class ServiceUnchanged(AlarmRefused):
    """Out of service (or in service) already (OPC UA: BadConditionAlreadyDisabled / ...Enabled)."""
