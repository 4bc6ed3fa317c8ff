"""Whether an alarm's process condition holds now: one small check object per alarm.

A check returns the *raw* level — "" when the process is normal, else the level it is in
("hihi", "hi", "lo", "lolo" for limit alarms, "on" for the others) — before on/off delays,
which the engine applies. Checks read the `Tag` objects directly (they live as long as the
database): a limit alarm that stays normal costs two comparisons.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from softplc.alarms.settings import AlarmDefinition
from softplc.tagdb import TagDatabase
from softplc.tags import Quality

ON = "on"


class LimitCheck:
    """hihi/hi active at or above their limit, lo/lolo at or below; back to normal only past the deadband."""

    __slots__ = ("tag", "high", "low", "deadband", "high_edge", "low_edge", "severer")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        self.tag = db[definition.tag]
        self.deadband = definition.deadband
        order = {"hihi": 0, "hi": 1, "lolo": 0, "lo": 1}
        self.high = sorted((level for level in definition.levels if level.high), key=lambda level: order[level.name])
        self.low = sorted((level for level in definition.levels if not level.high), key=lambda level: order[level.name])
        # Between the edges (less the deadband) a normal alarm stays normal: the fast path.
        self.high_edge = min((level.limit for level in self.high), default=float("inf"))
        self.low_edge = max((level.limit for level in self.low), default=float("-inf"))
        # The levels at least as severe as each level, on its side (which keep it with the deadband).
        self.severer = {level.name: {other.name for other in side[: index + 1]}
                        for side in (self.high, self.low) for index, level in enumerate(side)}

    def __call__(self, level: str, now: float) -> str:
        value = self.tag.value
        if not level and self.low_edge < value < self.high_edge:
            return ""
        if value != value:  # NaN: no information, keep what we had
            return level
        deadband = self.deadband
        severer = self.severer
        for candidate in self.high:
            if value >= candidate.limit or (level in severer[candidate.name] and value > candidate.limit - deadband):
                return candidate.name
        for candidate in self.low:
            if value <= candidate.limit or (level in severer[candidate.name] and value < candidate.limit + deadband):
                return candidate.name
        return ""


class DiscreteCheck:
    """A tag in an alarm value, off its normal value, or of bad quality."""

    __slots__ = ("tag", "values", "mode")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        self.tag = db[definition.tag]
        self.values = definition.values
        self.mode = definition.discrete

    def __call__(self, level: str, now: float) -> str:
        tag = self.tag
        if self.mode == "value":
            holds = tag.value in self.values
        elif self.mode == "normal":
            holds = tag.value not in self.values
        else:
            holds = tag.quality is not Quality.GOOD
        return ON if holds else ""


class ConditionCheck:
    """An expression over tags (the language of `run --until`)."""

    __slots__ = ("condition", "value_of")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        assert definition.condition is not None
        self.condition = definition.condition
        self.value_of = db.value

    def __call__(self, level: str, now: float) -> str:
        try:
            return ON if self.condition.evaluate(self.value_of) else ""
        except (TypeError, ValueError, ArithmeticError):  # e.g. a string compared with a number
            return level


class IncreaseCheck:
    """A counter that grew by at least `by` within the last `within` seconds (e.g. scan overruns).

    Only growth counts: a counter reset to 0 starts afresh. `next_change(now)` tells the engine
    when the window will have dropped the oldest growth, so it re-evaluates then.
    """

    __slots__ = ("tag", "by", "within", "last", "growth")

    def __init__(self, definition: AlarmDefinition, db: TagDatabase) -> None:
        self.tag = db[definition.tag]
        self.by = definition.increase_by
        self.within = definition.increase_within
        self.last = self.tag.value
        self.growth: deque[tuple[float, float]] = deque()

    def __call__(self, level: str, now: float) -> str:
        value = self.tag.value
        if value > self.last:
            self.growth.append((now, value - self.last))
        self.last = value
        growth = self.growth
        while growth and growth[0][0] <= now - self.within:
            growth.popleft()
        return ON if sum(amount for _, amount in growth) >= self.by else ""

    def next_change(self, now: float) -> float | None:
        return self.growth[0][0] + self.within if self.growth else None


Check = Callable[[str, float], str]
_CHECKS: dict[str, Callable[[AlarmDefinition, TagDatabase], Any]] = {
    "limit": LimitCheck, "discrete": DiscreteCheck, "condition": ConditionCheck, "increase": IncreaseCheck,
}


def make_check(definition: AlarmDefinition, db: TagDatabase) -> Check:
    """The check of an alarm's kind, bound to the database's tags."""
    return _CHECKS[definition.kind](definition, db)
